"""A batched vector environment: many reach tasks stepped by one parallel solver call.

``gym.make_vec("SoftArm/OctArmReach-v1", num_envs=1024, vectorization_mode="vector_entry_point")``
returns a :class:`BatchedReachVectorEnv`: all arms move together through a
:class:`solver.BatchStepper` (numba ``prange`` over the copies), and observations, rewards
and resets are computed for the whole batch by the batch-first functions of
:mod:`softarm_gym.envs.terms` that the single :class:`~softarm_gym.envs.ReachEnv` uses for
its batch of one. Copy i of an env reset with ``seed=s`` is, bit for bit, the single env
reset with ``seed=s + i`` (observations, rewards, flags and infos, as
``gym.make_vec(..., vectorization_mode="sync")`` gives them), so a policy trained on one
runs on the other.

It follows Gymnasium's vector API: ``NEXT_STEP`` autoreset by default (the step after an
episode ends resets that copy, returning its first observation, reward 0 and no
termination) or ``SAME_STEP`` (``autoreset_mode=AutoresetMode.SAME_STEP``: the step that
ends an episode resets the copy at once and returns its first observation, with the last
one in ``info["final_obs"]`` and that step's info in ``info["final_info"]`` — what SB3's
``VecEnv`` API needs, see :mod:`softarm_gym.sb3`), the single env's ``info`` keys as arrays
with ``_key`` masks. What needs per-copy machinery —
estimator observations, payload ranges, parameter randomisation, the wrap task — is
refused with a ``ValueError`` naming it: use ``vectorization_mode="sync"`` or ``"async"``.
With ``planar=False`` the copies are stepped by :class:`solver.SpatialBatchStepper` (one
spatial stepper per copy, on a thread pool where that pays) and observed by the single env's
``true`` estimate: the same conformance, not the planar batch's speed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

import solver
from softarm_gym.envs import ReachEnv
from softarm_gym.envs.reach import TARGET_ATTEMPTS
from softarm_gym.envs.terms import (
    REACH_TERMS,
    clip_observations,
    fill_pressures,
    fill_reach_goals,
    fill_shape,
    fill_true_shapes,
    fill_true_shapes_parallel,
    fractions_from_actions,
    reach_reward_sum,
    reach_rewards,
)
from solver import layout as L

__all__ = ["BatchedReachVectorEnv"]


def _unsupported(env: ReachEnv) -> list[str]:
    """What of a configured single env the batched env cannot simulate."""
    reasons = []
    if env.observation_name != "true":
        reasons.append(f"observation={env.observation_name!r} (estimators need per-copy sensing; "
                       "the batched env observes 'true')")
    if env.payload_range[0] != env.payload_range[1]:
        reasons.append(f"a payload_kg range {env.payload_range} (one scene serves every copy)")
    if env.randomization.active:
        reasons.append("randomization (one arm serves every copy)")
    if env.observation_format != "flat":
        reasons.append(f"observation_format={env.observation_format!r}")
    if env.synthesize_sensors and not env.estimator.reads_sensors:  # asked for, not implied
        reasons.append("synthesize_sensors=True")
    if env.actuation != "ideal":
        reasons.append(f"actuation={env.actuation!r}")
    if env.render_mode is not None:
        reasons.append(f"render_mode={env.render_mode!r}")
    return reasons


def _info_arrays(items: Sequence[tuple[str, object]], n: int) -> dict:
    """Vector infos as Gymnasium builds them from n single infos with every key present:
    each ``key`` followed by its all-True ``_key`` mask."""
    infos = {}
    for key, value in items:
        infos[key] = value
        infos[f"_{key}"] = np.ones(n, dtype=bool)
    return infos


class BatchedReachVectorEnv(VectorEnv):
    """``num_envs`` reach tasks (``true`` observations) advanced by one parallel solver call.

    Same spaces, rewards (``reward_distance + reward_control + reward_success +
    reward_solver``), targets (tips of cold equilibria at uniform random pressures), start
    states, failure policy and ``info`` as :class:`~softarm_gym.envs.ReachEnv` — see its env
    card. Episodes end by truncation after ``max_episode_steps`` or ``max_solver_failures``
    consecutive unconverged steps (or on success with ``terminate_on_success``); a finished
    copy is reset at its next step (``AutoresetMode.NEXT_STEP``, its action ignored), or in
    the step that finished it (``AutoresetMode.SAME_STEP``). In either mode copy i equals
    ``SyncVectorEnv`` in the same mode over single envs, bit for bit.

    Args:
        num_envs: number of arms.
        max_episode_steps: truncation length (default 100, as registered).
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``SAME_STEP`` (or their
            string values).
        **kwargs: ReachEnv arguments (``planar=False`` included). Refused with a
            ``ValueError`` naming them: estimator observations, payload ranges, randomisation,
            the Dict format,
            sensor synthesis, rendering, and arms the lean planar solver does not step.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 64, max_episode_steps: int = 100,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, **kwargs):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1; got {num_envs!r}")
        modes = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
        if autoreset_mode not in modes and autoreset_mode not in [m.value for m in modes]:
            raise ValueError(f"autoreset_mode must be one of {', '.join(m.value for m in modes)}; "
                             f"got {autoreset_mode!r}")
        self.metadata = {**self.metadata, "autoreset_mode": AutoresetMode(autoreset_mode)}
        self._same_step = self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
        if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, (int, np.integer)) \
                or max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be an integer >= 1; got {max_episode_steps!r}")
        self._template = t = ReachEnv(**kwargs)
        reasons = _unsupported(t)
        if reasons:
            raise ValueError(f"the batched vector env does not support {' and '.join(reasons)}: use "
                             "gym.make_vec(..., vectorization_mode='sync' or 'async') for that")
        self.num_envs = n = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self.single_observation_space = t.observation_space
        self.single_action_space = t.action_space
        self.observation_space = batch_space(t.observation_space, n)
        self.action_space = batch_space(t.action_space, n)
        self.arm = t.arm
        self.scene = solver.Scene(base_angle_deg=t.base_angle_deg, payload_kg=t.payload_range[0],
                                  gravity=t.gravity)
        self.render_mode = None
        try:
            self._batch = solver.BatchStepper(self.arm, self.scene, n, model=t.model) if t.planar \
                else solver.SpatialBatchStepper(self.arm, self.scene, n, model=t.model)
        except ValueError as exc:
            raise ValueError(f"the batched vector env cannot step this arm: {exc}") from None
        self._rngs: list[np.random.Generator] | None = None
        self._obs = np.zeros((n, t.observation_space.shape[0]))
        self._low = t.observation_space.low.astype(np.float64)
        self._high = t.observation_space.high.astype(np.float64)
        self._tips = np.zeros((n, t.dim))
        self._target = np.zeros((n, t.dim))
        self._fraction = np.zeros((n, t.n_inputs))
        self._steps = np.zeros(n, dtype=np.int64)
        self._failures = np.zeros(n, dtype=np.int64)
        self._autoreset = np.zeros(n, dtype=bool)
        self._terms = np.zeros((n, len(REACH_TERMS)))
        self._distance = np.zeros(n)
        self._success = np.zeros(n, dtype=bool)
        slices = t.observation_slices
        self._shape_starts = np.array([slices[name].start for name in ("tip", "section_ends", "backbone")],
                                      dtype=np.int64)
        self._s_query = None
        if t.planar:
            self._tangent = np.empty((n, self._batch.records.shape[1], 2))
            self._backbone = np.empty((n, t.n_backbone, 2))
            self._section_rows = np.asarray(self._batch.section_ends, dtype=np.int64)
            # The observation kernel runs on the threads when that measures faster, as the
            # solver's batch kernels do.
            self._observe_policy = solver.ThreadPolicy(solver.BatchStepper.PARALLEL_MIN)

    @property
    def observation_slices(self) -> dict[str, slice]:
        """Where each block sits in one copy's flat observation (as the single env's)."""
        return self._template.observation_slices

    @property
    def template(self) -> ReachEnv:
        """The single env whose configuration every copy shares (spaces, weights, ``p_max``);
        never stepped: per-copy state is in the batched arrays and the infos."""
        return self._template

    @property
    def np_random_seed(self):
        """The seed of each copy's generator (as ``SyncVectorEnv`` reports them)."""
        return None if self._rngs is None else tuple(self._seeds)

    # ------------------------------------------------------------------ helpers

    def _seed(self, seed) -> None:
        n = self.num_envs
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(n)]
        elif isinstance(seed, Sequence) and len(seed) == n:
            seeds = list(seed)
        else:
            raise ValueError(f"seed must be None, an int (copy i is seeded s + i) or {n} seeds; "
                             f"got {seed!r}")
        if seed is None and self._rngs is not None:
            return  # as a single env reset without a seed: keep drawing from the same streams
        pairs = [seeding.np_random(s) for s in seeds]
        self._rngs = [rng for rng, _ in pairs]
        self._seeds = [s for _, s in pairs]

    def _reset_rows(self, rows: np.ndarray) -> solver.BatchReport:
        """New start states and targets of ``rows``, drawn as ReachEnv.reset draws them."""
        t = self._template
        k = rows.size
        start = np.stack([self._rngs[i].uniform(0.0, t.initial_pressure_fraction, t.n_inputs)
                          for i in rows]) if k else np.zeros((0, t.n_inputs))
        report = self._batch.reset(start * t.p_max, rows)
        failed = ~report.converged
        if failed.any():
            # As ReachEnv: a start state that does not converge falls back to the rest state.
            start[failed] = 0.0
            retry = self._batch.reset(start[failed], rows[failed])
            report = solver.BatchReport(*(np.where(failed, r_retry, r_first)
                                          for r_retry, r_first in zip(_scatter(retry, failed), report)))
            if not retry.converged.all():
                raise RuntimeError(f"the unactuated {self.arm.name} arm has no converged equilibrium "
                                   f"in scene {self.scene}")
        self._fraction[rows] = start
        pending = np.arange(k)
        for _ in range(TARGET_ATTEMPTS):
            fraction = np.stack([self._rngs[rows[j]].uniform(0.0, 1.0, t.n_inputs) for j in pending])
            tips, target_report = self._batch.solve_tips(fraction * t.p_max)
            done = target_report.converged
            self._target[rows[pending[done]]] = tips[done]
            pending = pending[~done]
            if not pending.size:
                break
        else:
            raise RuntimeError(f"no converged target in {TARGET_ATTEMPTS} random pressure draws for "
                               f"{self.arm.name} in {self.scene}")
        self._steps[rows] = 0
        self._failures[rows] = 0
        return report

    def _observe(self) -> np.ndarray:
        t = self._template
        if not t.planar:
            # No lean record in 3D: the single env's own ``true`` estimate of each copy.
            for i in range(self.num_envs):
                eq = self._batch.equilibrium(i)
                fill_shape(self._obs[i], t.observation_slices,
                           t.estimator.estimate(None, eq.pressures, truth=eq), False)
                self._tips[i] = eq.tip
            return self._finish_observation()
        records = self._batch.records
        if self._s_query is None:
            self._s_query = np.linspace(0.0, float(records[0, -1, L.S]), t.n_backbone)
        self._observe_policy.run(fill_true_shapes_parallel, fill_true_shapes, self.num_envs, records,
                                 self._section_rows, self._s_query, self._shape_starts, self._obs,
                                 self._tips, self._tangent, self._backbone)
        return self._finish_observation()

    def _finish_observation(self) -> np.ndarray:
        """The pressure and goal blocks, then every copy's observation clipped to the space."""
        t = self._template
        slices = t.observation_slices
        fill_pressures(self._fraction, slices["pressures"].start, self._obs)
        fill_reach_goals(self._target, self._tips, slices["goal"].start, self._obs)
        out = np.empty(self._obs.shape, dtype=np.float32)
        clip_observations(self._obs, self._low, self._high, out)
        return out

    def _rewards(self, converged: np.ndarray) -> np.ndarray:
        t = self._template
        reach_rewards(self._tips, self._target, self._fraction, converged, t.distance_weight,
                      t.control_weight, t.success_bonus, t.success_tolerance,
                      t.solver_failure_penalty, self._terms, self._distance, self._success)
        return reach_reward_sum(self._terms)

    def _infos(self, report: solver.BatchReport) -> dict:
        """The single env's info keys, batched as ``SyncVectorEnv`` batches them."""
        n = self.num_envs
        solver_items = [("converged", report.converged.copy()), ("stable", report.stable.copy()),
                        ("snapped", report.snapped.copy()), ("iterations", report.iterations.copy()),
                        ("residual", report.residual.copy())]
        items = [
            ("tip_true", self._tips.copy()),
            ("tip_estimated", self._tips.copy()),
            ("estimation_error", np.zeros(n)),
            ("sensors", {}),
            ("converged", report.converged.copy()),
            ("solver", _info_arrays(solver_items, n)),
            ("solver_failures", self._failures.copy()),
            ("pressures_pa", self._batch.pressures.copy()),
            ("payload_kg", np.full(n, self.scene.payload_kg)),
            ("is_success", self._success.copy()),
            ("target", self._target.copy()),
            ("distance", self._distance.copy()),
        ]
        items += [(name, self._terms[:, j].copy()) for j, name in enumerate(REACH_TERMS)]
        return _info_arrays(items, n)

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed=None, options=None):
        """Reset every copy (copy i seeded ``seed + i``); ``options`` are not supported."""
        if options:
            raise ValueError(f"the batched vector env takes no reset options; got {sorted(options)}")
        self._seed(seed)
        report = self._reset_rows(np.arange(self.num_envs))
        self._autoreset[:] = False
        obs = self._observe()
        self._rewards(np.ones(self.num_envs, dtype=bool))
        return obs, self._infos(report)

    def step(self, actions):
        if self._rngs is None:
            raise RuntimeError("call reset() before step()")
        t = self._template
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.num_envs, t.n_inputs):
            raise ValueError(f"actions must have shape ({self.num_envs}, {t.n_inputs}); got {a.shape}")
        stepping = ~self._autoreset
        # Copies being reset ignore their actions (NEXT_STEP autoreset), as Sync/AsyncVectorEnv do.
        a = np.where(stepping[:, None], a, 0.0)
        fraction = np.empty_like(self._fraction)
        bad = fractions_from_actions(a, self._fraction, t.action_mode == "delta", t.delta_scale, fraction)
        if bad >= 0:
            env, channel = divmod(bad, t.n_inputs)
            raise ValueError(f"action for env {env}, channel {t.input_names[channel]!r} is not finite: "
                             f"{a[env, channel]}")
        fraction[~stepping] = self._fraction[~stepping]
        report = self._batch.step(fraction * t.p_max, active=stepping)
        ok = report.converged | ~stepping
        self._fraction = np.where(ok[:, None], fraction, self._fraction)
        self._failures = np.where(ok, 0, self._failures + 1)
        self._steps += stepping
        if self._autoreset.any():
            report = self._reset_into(report, self._autoreset)
        obs = self._observe()
        reward = self._rewards(ok)
        reward[~stepping] = 0.0
        terminated = self._success & t.terminate_on_success & stepping
        truncated = ((self._steps >= self.max_episode_steps) | (self._failures >= t.max_solver_failures)) \
            & stepping
        infos = self._infos(report)
        done = terminated | truncated
        if not self._same_step:
            self._autoreset = done
        elif done.any():
            obs, infos = self._reset_finished(done, obs, infos, report, ok)
        return obs, reward, terminated, truncated, infos

    def _reset_into(self, report: solver.BatchReport, rows: np.ndarray) -> solver.BatchReport:
        """Reset the copies of the mask ``rows``; ``report`` with their rows replaced by the resets'."""
        spread = _scatter(self._reset_rows(np.flatnonzero(rows)), rows)
        return solver.BatchReport(*(np.where(rows, r_reset, r_step)
                                    for r_reset, r_step in zip(spread, report)))

    def _reset_finished(self, done, obs, infos, report, ok) -> tuple[np.ndarray, dict]:
        """SAME_STEP: reset the copies whose episode ended in this step; their last observation
        and info go to ``final_obs`` and ``final_info``, as ``SyncVectorEnv`` puts them."""
        final_obs = np.full(self.num_envs, None, dtype=object)
        for i in np.flatnonzero(done):
            final_obs[i] = obs[i].copy()
        final = {"final_obs": final_obs, "_final_obs": done.copy(),
                 "final_info": _masked(infos, done), "_final_info": done.copy()}
        report = self._reset_into(report, done)
        obs = self._observe()
        self._rewards(ok | done)  # a reset copy's info holds the terms of its first state
        infos = self._infos(report)
        # SyncVectorEnv adds keys as it meets them: the final ones first if copy 0 finished.
        return obs, ({**final, **infos} if done[0] else {**infos, **final})

    def close_extras(self, **kwargs):
        self._template.close()


def _masked(infos: dict, mask: np.ndarray) -> dict:
    """Vector infos of the copies ``mask`` selects, as ``SyncVectorEnv`` gathers them: other
    rows zero, every ``_key`` mask equal to ``mask``."""
    out = {}
    for key, value in infos.items():
        if key.startswith("_"):
            continue
        if isinstance(value, dict):
            out[key] = _masked(value, mask)
        else:
            kept = np.zeros_like(value)
            kept[mask] = value[mask]
            out[key] = kept
        out[f"_{key}"] = mask.copy()
    return out


def _scatter(report: solver.BatchReport, mask: np.ndarray) -> list[np.ndarray]:
    """The fields of a report of the rows ``mask`` selects, spread to full-length arrays."""
    fields = []
    for values in report:
        full = np.zeros(mask.shape[0], dtype=values.dtype)
        full[mask] = values
        fields.append(full)
    return fields
