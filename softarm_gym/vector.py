"""Batched vector environments: many arms stepped by one parallel solver call.

``gym.make_vec(env_id, num_envs=1024, vectorization_mode="vector_entry_point")`` returns one
of these for the reach, track, obstacle-reach and (planar) wrap IDs: every arm moves through
a :class:`solver.BatchStepper` (numba ``prange`` over the copies; contact by the stepper's
lean contact kernel), and observations, rewards and infos are computed for the whole batch
by the batch-first functions of :mod:`softarm_gym.envs.terms` that the single environments
use for their batch of one. Copy i of an env reset with ``seed=s`` is, bit for bit, the
single env reset with ``seed=s + i`` (observations, rewards, flags and infos, as
``gym.make_vec(..., vectorization_mode="sync")`` gives them), so a policy trained on one
runs on the other.

* :class:`BatchedReachVectorEnv` (reach): resets in batch too (start states and targets by
  the batch's cold kernel).
* :class:`BatchedSelfContactReachVectorEnv` (reach with ``self_contact``),
  :class:`BatchedTrackVectorEnv`, :class:`BatchedObstacleReachVectorEnv`,
  :class:`BatchedWrapVectorEnv`: a reset draws the task (a target solved with the arm
  pressing on itself, a trajectory, discs and a target ramped through them, a placed disc)
  with solver calls and random draws of its own, so each
  copy keeps one single env for its resets — seeded as ``SyncVectorEnv`` seeds its envs,
  reset when the sync env would reset it — and its start state is adopted into the batch
  (:meth:`solver.BatchStepper.adopt`; with contact the copy takes that episode's discs).
  Steps, observations and rewards go through the batch. These take the single env's reset
  ``options`` (every copy gets the same, as ``SyncVectorEnv`` gives them).

They follow Gymnasium's vector API: ``NEXT_STEP`` autoreset by default (the step after an
episode ends resets that copy, returning its first observation, reward 0 and no
termination) or ``SAME_STEP`` (``autoreset_mode=AutoresetMode.SAME_STEP``: the step that
ends an episode resets the copy at once and returns its first observation, with the last
one in ``info["final_obs"]`` and that step's info in ``info["final_info"]`` — what SB3's
``VecEnv`` API needs, see :mod:`softarm_gym.sb3`), the single env's ``info`` keys as arrays
with ``_key`` masks. What needs per-copy machinery — estimator observations, payload ranges,
parameter randomisation, the Dict formats, sensor synthesis, pneumatic lag, rendering, 3D
contact, rigid contact — is refused with a ``ValueError`` naming it: use
``vectorization_mode="sync"`` or ``"async"``. With ``planar=False`` the reach copies are
stepped by :class:`solver.SpatialBatchStepper` (one spatial stepper per copy, on a thread
pool where that pays) and observed by the single env's ``true`` estimate: the same
conformance, not the planar batch's speed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

import solver
from softarm_gym.envs import ObstacleReachEnv, ReachEnv, TrackEnv, WrapEnv
from softarm_gym.envs.reach import TARGET_ATTEMPTS
from softarm_gym.envs.terms import (
    OBSTACLE_TERMS,
    REACH_TERMS,
    WRAP_TERMS,
    batch_contact,
    batch_wrap_rewards,
    clip_observations,
    contact_rewards,
    fill_pressures,
    fill_reach_goals,
    fill_shape,
    fill_true_shapes,
    fill_true_shapes_parallel,
    fractions_from_actions,
    obstacle_terms,
    reach_rewards,
    reward_sums,
    tracking_errors,
)
from softarm_gym.envs.track import path_easing
from solver import layout as L
from solver.threads import CopyPool

__all__ = ["BatchedReachVectorEnv", "BatchedSelfContactReachVectorEnv", "BatchedTrackVectorEnv",
           "BatchedObstacleReachVectorEnv", "BatchedWrapVectorEnv"]


def _unsupported(env) -> list[str]:
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


def _info_arrays(items: Sequence[tuple[str, object]], n: int, partial=()) -> dict:
    """Vector infos as Gymnasium builds them from n single infos: each ``key`` followed by its
    ``_key`` mask, all True for ``items``, ``mask`` for the (key, value, mask) triples of
    ``partial`` (keys only some copies' infos hold, after the others; left out where no
    copy holds them)."""
    infos = {}
    for key, value in items:
        infos[key] = value
        infos[f"_{key}"] = np.ones(n, dtype=bool)
    for key, value, mask in partial:
        if mask.any():
            infos[key] = np.where(mask.reshape(-1, *[1] * (value.ndim - 1)), value, 0).astype(value.dtype)
            infos[f"_{key}"] = mask.copy()
    return infos


def _checked_count(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1; got {value!r}")
    return int(value)


class _BatchedVectorEnv(VectorEnv):
    """What every batched env shares: spaces, seeding, the step and autoreset flow, the
    ``true`` shape observation of the batch's records. Subclasses set the task: resets
    (:meth:`_reset_rows`), steps (:meth:`_advance`), observations (:meth:`_observe`),
    rewards (:meth:`_rewards`) and infos (:meth:`_infos`)."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, env_class, num_envs, max_episode_steps, autoreset_mode, kwargs, extra=()):
        n = _checked_count("num_envs", num_envs)
        modes = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
        if autoreset_mode not in modes and autoreset_mode not in [m.value for m in modes]:
            raise ValueError(f"autoreset_mode must be one of {', '.join(m.value for m in modes)}; "
                             f"got {autoreset_mode!r}")
        self.metadata = {**self.metadata, "autoreset_mode": AutoresetMode(autoreset_mode)}
        self._same_step = self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
        self.max_episode_steps = _checked_count("max_episode_steps", max_episode_steps)
        self._template = t = env_class(**kwargs)
        reasons = _unsupported(t) + [reason for reason in extra if reason]
        if reasons:
            raise ValueError(f"the batched vector env does not support {' and '.join(reasons)}: use "
                             "gym.make_vec(..., vectorization_mode='sync' or 'async') for that")
        self.num_envs = n
        self.single_observation_space = t.observation_space
        self.single_action_space = t.action_space
        self.observation_space = batch_space(t.observation_space, n)
        self.action_space = batch_space(t.action_space, n)
        self.arm = t.arm
        self.render_mode = None
        self._obs = np.zeros((n, t.observation_space.shape[0]))
        self._low = t.observation_space.low.astype(np.float64)
        self._high = t.observation_space.high.astype(np.float64)
        self._tips = np.zeros((n, t.dim))
        self._fraction = np.zeros((n, t.n_inputs))
        self._steps = np.zeros(n, dtype=np.int64)
        self._failures = np.zeros(n, dtype=np.int64)
        self._autoreset = np.zeros(n, dtype=bool)
        self._success = np.zeros(n, dtype=bool)
        self._started = False
        slices = t.observation_slices
        self._shape_starts = np.array([slices[name].start for name in ("tip", "section_ends", "backbone")],
                                      dtype=np.int64)
        self._s_query = None
        self._backbone = np.empty((n, t.n_backbone, 2))
        self._recorded = np.ones(n, dtype=bool)  # copies whose batch rows hold a lean record
        # The observation kernel runs on the threads when that measures faster, as the
        # solver's batch kernels do.
        self._observe_policy = solver.ThreadPolicy(solver.BatchStepper.PARALLEL_MIN)

    def _batch_stepper(self, scene: solver.Scene, max_obstacles: int | None = None) -> solver.BatchStepper:
        """The planar batch of this env's arm in ``scene`` (its errors as the env's, naming
        the contact stiffness where the scene has obstacles)."""
        try:
            batch = solver.BatchStepper(self.arm, scene, self.num_envs, model=self._template.model,
                                        max_obstacles=max_obstacles)
            if batch.contact:
                batch.backbones()  # raises where the contact layout is not the settings' grid
        except ValueError as exc:
            setting = f" with contact_stiffness={scene.obstacles[0].stiffness:g} N/m²" \
                if scene.obstacles else ""
            raise ValueError(f"the batched vector env cannot step this arm and scene{setting}: {exc}; use "
                             "gym.make_vec(..., vectorization_mode='sync' or 'async')") from None
        self._tangent = np.empty((self.num_envs, batch.records.shape[1], 2))
        self._section_rows = np.asarray(batch.section_ends, dtype=np.int64)
        return batch

    @property
    def observation_slices(self) -> dict[str, slice]:
        """Where each block sits in one copy's flat observation (as the single env's)."""
        return self._template.observation_slices

    @property
    def template(self):
        """The single env whose configuration every copy shares (spaces, weights, ``p_max``);
        never stepped: per-copy state is in the batched arrays and the infos."""
        return self._template

    # ------------------------------------------------------------------ observations

    def _fill_shapes(self, batch: solver.BatchStepper) -> np.ndarray:
        """The shape blocks and true tips of every copy from the batch's backbones; with
        contact, copies without a lean record (a state the general path left on a grid of its
        own) from their equilibria, as a single env without a record observes them. Returns
        the backbones (n, N, N_COLUMNS)."""
        t = self._template
        records = batch.backbones()
        if self._s_query is None:
            self._s_query = np.linspace(0.0, float(records[0, -1, L.S]), t.n_backbone)
        self._observe_policy.run(fill_true_shapes_parallel, fill_true_shapes, self.num_envs, records,
                                 self._section_rows, self._s_query, self._shape_starts, self._obs,
                                 self._tips, self._tangent, self._backbone)
        if batch.contact:
            for k in np.flatnonzero(~self._recorded):
                eq = batch.equilibrium(k)
                shape = t.estimator.estimate(None, eq.pressures, truth=eq)
                fill_shape(self._obs[k], t.observation_slices, shape, True)
                self._tips[k] = shape.tip
        return records

    def _clipped(self) -> np.ndarray:
        """The pressure block, then every copy's observation clipped to the space (float32)."""
        fill_pressures(self._fraction, self.observation_slices["pressures"].start, self._obs)
        out = np.empty(self._obs.shape, dtype=np.float32)
        clip_observations(self._obs, self._low, self._high, out)
        return out

    # ------------------------------------------------------------------ task hooks

    def _seed(self, seed) -> None:
        raise NotImplementedError

    def _reset_rows(self, rows: np.ndarray, options) -> solver.BatchReport:
        """New episodes of ``rows``, as the single env's reset draws them."""
        raise NotImplementedError

    def _advance(self, fraction: np.ndarray, stepping: np.ndarray) -> tuple[solver.BatchReport, np.ndarray]:
        """Step the copies ``stepping`` to the pressure ``fraction`` (n, n_inputs): the
        report and which new states stand (the single env's ``_advance``)."""
        report = self._batch.step(fraction * self._template.p_max, active=stepping)
        return report, report.converged

    def _observe(self) -> np.ndarray:
        raise NotImplementedError

    def _rewards(self, converged: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _record_step(self, stepping: np.ndarray) -> None:
        """Per-episode statistics of the copies that took this step (once per step)."""

    def _infos(self, report: solver.BatchReport, stepped: np.ndarray) -> dict:
        """The single env's info keys, batched as ``SyncVectorEnv`` batches them; ``stepped``
        (n,): copies whose info is a step's (the others' a reset's)."""
        raise NotImplementedError

    def _base_items(self, report: solver.BatchReport, batch: solver.BatchStepper) -> list:
        """The items of :meth:`SoftArmEnv._info` (its keys in its order)."""
        n = self.num_envs
        solver_items = [("converged", report.converged.copy()), ("stable", report.stable.copy()),
                        ("snapped", report.snapped.copy()), ("iterations", report.iterations.copy()),
                        ("residual", report.residual.copy())]
        return [
            ("tip_true", self._tips.copy()),
            ("tip_estimated", self._tips.copy()),
            ("estimation_error", np.zeros(n)),
            ("sensors", {}),
            ("converged", report.converged.copy()),
            ("solver", _info_arrays(solver_items, n)),
            ("solver_failures", self._failures.copy()),
            ("pressures_pa", batch.pressures.copy()),
            ("payload_kg", np.full(n, self._template.payload_range[0])),
            ("is_success", self._success.copy()),
        ]

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed=None, options=None):
        """Reset every copy (copy i seeded ``seed + i``, or ``seed[i]`` for a sequence)."""
        self._seed(seed)
        report = self._reset_rows(np.arange(self.num_envs), options)
        self._started = True
        self._autoreset[:] = False
        obs = self._observe()
        self._rewards(np.ones(self.num_envs, dtype=bool))
        return obs, self._infos(report, np.zeros(self.num_envs, dtype=bool))

    def step(self, actions):
        if not self._started:
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
        report, accepted = self._advance(fraction, stepping)
        ok = report.converged | ~stepping
        self._fraction = np.where((accepted & stepping)[:, None], fraction, self._fraction)
        self._failures = np.where(ok, 0, self._failures + 1)
        self._steps += stepping
        if self._autoreset.any():
            report = self._reset_into(report, self._autoreset)
        obs = self._observe()
        reward = self._rewards(ok)
        reward[~stepping] = 0.0
        self._record_step(stepping)
        terminated = self._success & t.terminate_on_success & stepping
        truncated = ((self._steps >= self.max_episode_steps) | (self._failures >= t.max_solver_failures)) \
            & stepping
        infos = self._infos(report, stepping)
        done = terminated | truncated
        if not self._same_step:
            self._autoreset = done
        elif done.any():
            obs, infos = self._reset_finished(done, obs, infos, report, ok, stepping)
        return obs, reward, terminated, truncated, infos

    def _reset_into(self, report: solver.BatchReport, rows: np.ndarray) -> solver.BatchReport:
        """Reset the copies of the mask ``rows``; ``report`` with their rows replaced by the resets'."""
        spread = _scatter(self._reset_rows(np.flatnonzero(rows), None), rows)
        return solver.BatchReport(*(np.where(rows, r_reset, r_step)
                                    for r_reset, r_step in zip(spread, report)))

    def _reset_finished(self, done, obs, infos, report, ok, stepping) -> tuple[np.ndarray, dict]:
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
        infos = self._infos(report, stepping & ~done)
        # SyncVectorEnv adds keys as it meets them: the final ones first if copy 0 finished.
        return obs, ({**final, **infos} if done[0] else {**infos, **final})

    def close_extras(self, **kwargs):
        self._template.close()


class BatchedReachVectorEnv(_BatchedVectorEnv):
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
            the Dict format, sensor synthesis, pneumatic lag, rendering, and arms the lean
            planar solver does not step. With ``self_contact`` the env built is a
            :class:`BatchedSelfContactReachVectorEnv` (its start states and targets are solved
            with the arm pressing on itself, by one ReachEnv per copy).
    """

    def __new__(cls, *args, **kwargs):
        if cls is BatchedReachVectorEnv and kwargs.get("self_contact"):
            cls = BatchedSelfContactReachVectorEnv
        return super().__new__(cls)

    def __init__(self, num_envs: int = 64, max_episode_steps: int = 100,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, **kwargs):
        self._init_reach(ReachEnv, num_envs, max_episode_steps, autoreset_mode, kwargs)
        t = self._template
        self.scene = solver.Scene(base_angle_deg=t.base_angle_deg, payload_kg=t.payload_range[0],
                                  gravity=t.gravity)
        try:
            self._batch = self._batch_stepper(self.scene) if t.planar \
                else solver.SpatialBatchStepper(self.arm, self.scene, self.num_envs, model=t.model)
        except ValueError as exc:
            raise ValueError(f"the batched vector env cannot step this arm: {exc}") from None
        self._rngs: list[np.random.Generator] | None = None

    def _init_reach(self, env_class, num_envs, max_episode_steps, autoreset_mode, kwargs, extra=()):
        """The shared setup and the reach task's arrays (targets, reward terms)."""
        super().__init__(env_class, num_envs, max_episode_steps, autoreset_mode, kwargs, extra)
        n, t = self.num_envs, self._template
        self._target = np.zeros((n, t.dim))
        self._terms = np.zeros((n, len(REACH_TERMS)))
        self._distance = np.zeros(n)

    @property
    def np_random_seed(self):
        """The seed of each copy's generator (as ``SyncVectorEnv`` reports them)."""
        return None if self._rngs is None else tuple(self._seeds)

    def _seed(self, seed) -> None:
        seeds = _seeds(seed, self.num_envs)
        if seed is None and self._rngs is not None:
            return  # as a single env reset without a seed: keep drawing from the same streams
        pairs = [seeding.np_random(s) for s in seeds]
        self._rngs = [rng for rng, _ in pairs]
        self._seeds = [s for _, s in pairs]

    def _reset_rows(self, rows: np.ndarray, options) -> solver.BatchReport:
        """New start states and targets of ``rows``, drawn as ReachEnv.reset draws them."""
        if options:
            raise ValueError(f"the batched reach env takes no reset options; got {sorted(options)}")
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
        else:
            self._fill_shapes(self._batch)
        return self._finish_reach_observation()

    def _finish_reach_observation(self) -> np.ndarray:
        """The goal block (target, target − tip), then the pressures and the clipping."""
        fill_reach_goals(self._target, self._tips, self.observation_slices["goal"].start, self._obs)
        return self._clipped()

    def _rewards(self, converged: np.ndarray) -> np.ndarray:
        t = self._template
        reach_rewards(self._tips, self._target, self._fraction, converged, t.distance_weight,
                      t.control_weight, t.success_bonus, t.success_tolerance,
                      t.solver_failure_penalty, self._terms, self._distance, self._success)
        reward = np.empty(self.num_envs)
        reward_sums(self._terms, reward)
        return reward

    def _reach_items(self, report: solver.BatchReport) -> list:
        """The items of ReachEnv's info up to its task keys (``target``, ``distance``)."""
        return self._base_items(report, self._batch) + [("target", self._target.copy()),
                                                        ("distance", self._distance.copy())]

    def _infos(self, report: solver.BatchReport, stepped: np.ndarray) -> dict:
        items = self._reach_items(report)
        items += [(name, self._terms[:, j].copy()) for j, name in enumerate(REACH_TERMS)]
        return _info_arrays(items, self.num_envs)


class _CopyResets:
    """Resets by one single env per copy (mixed into a batched env): copy i's env is reset
    where ``SyncVectorEnv`` would reset its env i, with the same seed and options, and its
    start state adopted into the batch's row i (:meth:`_take`). The copies' envs share nothing,
    so the copies that reset together (every copy, where episodes end in step) reset side by
    side on a :class:`solver.threads.CopyPool` — their draws' solves and ramps are kernels that
    release the GIL — and are taken into the batch in order: the same rows as one after
    another, bit for bit."""

    def _make_copies(self, env_class, kwargs) -> None:
        self._copies = [env_class(**kwargs) for _ in range(self.num_envs)]
        self._next_seeds = [None] * self.num_envs
        self._measures = np.zeros((self.num_envs, 2))  # penetration (m), total contact force (N)
        self._reset_pool = CopyPool()

    @property
    def np_random_seed(self):
        """The seed of each copy's generator (as ``SyncVectorEnv`` reports them)."""
        return None if not self._started else tuple(env.np_random_seed for env in self._copies)

    def _seed(self, seed) -> None:
        self._next_seeds = _seeds(seed, self.num_envs)

    def _reset_rows(self, rows: np.ndarray, options) -> solver.BatchReport:
        report = np.zeros((rows.size, 5))
        infos = self._reset_pool.map(
            lambda i: self._copies[i].reset(seed=self._next_seeds[i], options=options)[1], rows)
        for j, (i, info) in enumerate(zip(rows, infos)):
            env = self._copies[i]
            self._next_seeds[i] = None
            self._batch.adopt(env.stepper.equilibrium, rows=[i])
            self._fraction[i] = env.pressure_fractions
            self._take(i, env, info)
            attempt = info["solver"]
            report[j] = (attempt["converged"], attempt["stable"], attempt["snapped"],
                         attempt["iterations"], attempt["residual"])
        self._steps[rows] = 0
        self._failures[rows] = 0
        return solver.BatchReport(report[:, 0] != 0, report[:, 1] != 0, report[:, 2] != 0,
                                  report[:, 3].astype(np.int64), report[:, 4].copy())

    def _take(self, i: int, env, info: dict) -> None:
        """Copy i's task (what its single env drew at reset, read from ``env`` and its reset
        ``info``) into the batched arrays."""
        raise NotImplementedError

    def _measure(self) -> None:
        """With contact, which copies hold a lean record (``_recorded``) and every copy's
        deepest penetration and total contact force (``_measures``, as the single env reads
        them: :func:`~softarm_gym.envs.terms.batch_contact`)."""
        if self._batch.contact:
            self._recorded = batch_contact(self._batch, self._measures)

    def _contact_scene(self, obstacles: int) -> solver.Scene:
        """The batch's scene: the template's law (mounting, loads, self-contact) and, for
        ``obstacles`` > 0, one disc of the env's contact stiffness (every copy takes its own)."""
        t = self._template
        scene = solver.Scene(base_angle_deg=t.base_angle_deg, payload_kg=t.payload_range[0],
                             gravity=t.gravity, self_contact=t.self_contact,
                             self_friction=t.self_friction)
        if not obstacles:
            return scene
        return replace(scene, obstacles=(solver.Disc((0.0, -t.reach), 0.1 * t.arm.length,
                                                     t.contact_stiffness, friction=t.friction),))

    def close_extras(self, **kwargs):
        for env in self._copies:
            env.close()
        self._template.close()


class BatchedSelfContactReachVectorEnv(_CopyResets, BatchedReachVectorEnv):
    """``num_envs`` reach tasks with ``self_contact`` (what ``BatchedReachVectorEnv(...,
    self_contact=...)`` builds): steps by one :class:`solver.BatchStepper` call whose contact
    rows hold the arm's self-contact, resets by one :class:`~softarm_gym.envs.ReachEnv` per
    copy (a target is the tip of a cold equilibrium at random pressures, which may press the
    arm on itself: the batch's contact-free cold kernel cannot solve it). Copy i equals
    ``SyncVectorEnv``'s env i bit for bit (module docstring).

    Args:
        num_envs, max_episode_steps (default 100), autoreset_mode, **kwargs: as
            :class:`BatchedReachVectorEnv`.
    """

    def __init__(self, num_envs: int = 64, max_episode_steps: int = 100,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, **kwargs):
        self._init_reach(ReachEnv, num_envs, max_episode_steps, autoreset_mode, kwargs)
        self._batch = self._batch_stepper(self._contact_scene(0))
        self._make_copies(ReachEnv, kwargs)

    def _take(self, i, env, info):
        self._target[i] = info["target"]

    def _observe(self):
        self._measure()
        self._fill_shapes(self._batch)
        return self._finish_reach_observation()


class BatchedTrackVectorEnv(_CopyResets, BatchedReachVectorEnv):
    """``num_envs`` track tasks (:class:`~softarm_gym.envs.TrackEnv`, ``true`` observations)
    advanced by parallel solver calls: the targets' trajectories by one
    :class:`solver.BatchStepper`, the arms by another. Copy i equals ``SyncVectorEnv``'s
    env i bit for bit (module docstring), its resets by a single TrackEnv per copy.

    Args:
        num_envs, max_episode_steps (default 200, as registered), autoreset_mode: as
            :class:`BatchedReachVectorEnv`.
        **kwargs: TrackEnv arguments; refused as there (``planar=False`` too).
    """

    def __init__(self, num_envs: int = 64, max_episode_steps: int = 200,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, **kwargs):
        self._init_reach(TrackEnv, num_envs, max_episode_steps, autoreset_mode, kwargs,
                         ("planar=False (3D tracking: use the sync vector env)"
                          if kwargs.get("planar", True) is not True else None,))
        n, t = self.num_envs, self._template
        scene = self._contact_scene(0)
        self._batch = self._batch_stepper(scene)
        self._path = self._batch_stepper(scene)
        self._make_copies(TrackEnv, kwargs)
        self._waypoints = np.zeros((n, 2, t.n_inputs))  # each copy's segment: from, to
        self._velocity = np.zeros((n, t.dim))
        self._tracking = (np.zeros(n), np.zeros(n), np.zeros(n))  # squares, largest, RMS

    def _take(self, i, env, info):
        self._path.adopt(env.target_stepper.equilibrium, rows=[i])
        self._target[i] = info["target"]
        self._velocity[i] = info["target_velocity"]
        start, end, _ = env.path_segment(0)
        self._waypoints[i] = start, end
        for value in self._tracking:
            value[i] = 0.0

    def _advance(self, fraction, stepping):
        """The targets move first (TrackEnv.step), then the arms."""
        t = self._template
        within = self._steps % t.segment_steps
        for i in np.flatnonzero(stepping & (within == t.segment_steps - 1)):
            # Copy i enters its next segment: the waypoints its env draws.
            start, end, _ = self._copies[i].path_segment(int(self._steps[i]) + 1)
            self._waypoints[i] = start, end
        values, inverse = np.unique((self._steps + 1) % t.segment_steps, return_inverse=True)
        ease = np.array([path_easing(int(v), t.segment_steps) for v in values])[inverse]
        start, end = self._waypoints[:, 0], self._waypoints[:, 1]
        path = start + ease[:, None] * (end - start)
        previous = self._target.copy()
        # An unconverged path step keeps the path's last state: the target pauses.
        self._path.step(path * t.p_max, active=stepping)
        self._target = np.where(stepping[:, None], self._path.tips, self._target)
        self._velocity = np.where(stepping[:, None], self._target - previous, self._velocity)
        return super()._advance(fraction, stepping)

    def _observe(self) -> np.ndarray:
        self._measure()
        self._fill_shapes(self._batch)
        goal = self.observation_slices["goal"]
        self._obs[:, goal.start + 2 * self._template.dim:goal.stop] = self._velocity
        return self._finish_reach_observation()

    def _record_step(self, stepping):
        squares, largest, rms = self._tracking
        rows = np.flatnonzero(stepping)
        sq, lg, out = squares[rows], largest[rows], rms[rows]
        tracking_errors(self._distance[rows], self._steps[rows], sq, lg, out)
        squares[rows], largest[rows], rms[rows] = sq, lg, out

    def _infos(self, report, stepped):
        items = self._reach_items(report) + [("target_velocity", self._velocity.copy())]
        items += [(name, self._terms[:, j].copy()) for j, name in enumerate(REACH_TERMS)]
        _, largest, rms = self._tracking
        return _info_arrays(items, self.num_envs, [("tracking_rms_m", rms.copy(), stepped),
                                                   ("tracking_max_m", largest.copy(), stepped)])


class BatchedObstacleReachVectorEnv(_CopyResets, BatchedReachVectorEnv):
    """``num_envs`` obstacle-reach tasks (:class:`~softarm_gym.envs.ObstacleReachEnv`,
    ``true`` observations) advanced by one contact :class:`solver.BatchStepper` call, each copy
    with the discs of its episode. Copy i equals ``SyncVectorEnv``'s env i bit for bit
    (module docstring), its resets (discs, the target ramped through them) by a single
    ObstacleReachEnv per copy. With ``contact="forbid"`` every step first records each
    copy's equilibrium (to restore it where the step touches), which costs about as much as
    the step.

    Args:
        num_envs, max_episode_steps (default 100, as registered), autoreset_mode: as
            :class:`BatchedReachVectorEnv`.
        **kwargs: ObstacleReachEnv arguments; refused as there, and ``contact_stiffness``
            ``"rigid"`` (hard contact has no lean step) or a stiffness whose contact layout
            is not the settings' grid.
    """

    def __init__(self, num_envs: int = 64, max_episode_steps: int = 100,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, **kwargs):
        self._init_reach(ObstacleReachEnv, num_envs, max_episode_steps, autoreset_mode, kwargs)
        n, t = self.num_envs, self._template
        self._batch = self._batch_stepper(self._contact_scene(t.max_obstacles), t.max_obstacles)
        self._make_copies(ObstacleReachEnv, kwargs)
        self._block = np.zeros((n, 3 * t.max_obstacles))  # the observation's obstacles block
        self._discs = np.zeros((n, t.max_obstacles, 3))
        self._radii = np.zeros((n, t.max_obstacles))
        self._counts = np.zeros(n, dtype=np.int64)
        self._rejected = np.zeros(n, dtype=bool)
        self._rejected_force = np.zeros(n)  # of the state a rejected step reached (N)
        self._contact = np.zeros(n)
        self._obstacle_terms = np.zeros((n, len(OBSTACLE_TERMS)))

    def _take(self, i, env, info):
        self._target[i] = info["target"]
        self._discs[i] = info["obstacles"]
        self._radii[i] = info["contact_radii"]
        self._counts[i] = info["n_obstacles"]
        block = self._block[i].reshape(-1, 3)
        block[:] = 0.0
        count = self._counts[i]
        block[:count, :2] = self._discs[i, :count, :2]
        block[:count, 2] = self._radii[i, :count]
        self._rejected[i] = False

    def _advance(self, fraction, stepping):
        if self._template.contact == "penalize":
            return super()._advance(fraction, stepping)
        # As ObstacleReachEnv._advance: a converged step that touches a disc is rejected and
        # the copy restored to the equilibrium it held before.
        previous = [self._batch.equilibrium(k) if stepping[k] else None for k in range(self.num_envs)]
        report, accepted = super()._advance(fraction, stepping)
        self._measure()
        self._rejected = accepted & stepping & (self._measures[:, 0] > 0.0)
        self._rejected_force = self._measures[:, 1].copy()
        for k in np.flatnonzero(self._rejected):
            self._batch.adopt(previous[k], rows=[k])
        return report, accepted & ~self._rejected

    def _observe(self):
        self._measure()
        self._fill_shapes(self._batch)
        block = self.observation_slices["obstacles"]
        self._obs[:, block] = self._block
        return self._finish_reach_observation()

    def _rewards(self, converged):
        t = self._template
        reach_rewards(self._tips, self._target, self._fraction, converged, t.distance_weight,
                      t.control_weight, t.success_bonus, t.success_tolerance,
                      t.solver_failure_penalty, self._terms, self._distance, self._success)
        touching = self._rejected | (self._measures[:, 0] > 0.0)
        forces = np.where(self._rejected, self._rejected_force, self._measures[:, 1])
        contact_rewards(forces, touching, t.contact == "forbid", t.contact_weight, t.contact_penalty,
                        self._contact)
        obstacle_terms(self._terms, self._contact, self._obstacle_terms)
        reward = np.empty(self.num_envs)
        reward_sums(self._obstacle_terms, reward)
        return reward

    def _infos(self, report, stepped):
        items = self._reach_items(report)
        forces = np.where(self._rejected, self._rejected_force, self._measures[:, 1])
        items += [("obstacles", self._discs.copy()), ("contact_radii", self._radii.copy()),
                  ("n_obstacles", self._counts.copy()), ("contact_force", forces),
                  ("penetration", self._measures[:, 0].copy()),
                  ("in_contact", self._measures[:, 0] > 0.0),
                  ("contact_rejected", self._rejected.copy())]
        items += [(name, self._obstacle_terms[:, j].copy()) for j, name in enumerate(OBSTACLE_TERMS)]
        return _info_arrays(items, self.num_envs)


class BatchedWrapVectorEnv(_CopyResets, _BatchedVectorEnv):
    """``num_envs`` planar wrap tasks (:class:`~softarm_gym.envs.WrapEnv`, ``true``
    observations) advanced by one contact :class:`solver.BatchStepper` call, each copy with
    the disc of its episode. Copy i equals ``SyncVectorEnv``'s env i bit for bit (module
    docstring), its resets (the disc placed within reach) by a single WrapEnv per copy.

    Args:
        num_envs, max_episode_steps (default 200, as registered), autoreset_mode: as
            :class:`BatchedReachVectorEnv`.
        **kwargs: WrapEnv arguments; refused as there, and ``planar=False`` (3D wrap),
            ``contact_stiffness="rigid"`` (hard contact has no lean step) or a stiffness whose
            contact layout is not the settings' grid.
    """

    def __init__(self, num_envs: int = 64, max_episode_steps: int = 200,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, **kwargs):
        super().__init__(WrapEnv, num_envs, max_episode_steps, autoreset_mode, kwargs,
                         ("planar=False (3D wrap: use the sync vector env)"
                          if kwargs.get("planar", True) is not True else None,))
        n = self.num_envs
        self._batch = self._batch_stepper(self._contact_scene(1), 1)
        self._make_copies(WrapEnv, kwargs)
        self._centers = np.zeros((n, 2))
        self._contact_radii = np.zeros(n)
        self._object_radii = np.zeros(n)
        self._terms = np.zeros((n, len(WRAP_TERMS)))
        self._wrap_deg = np.zeros(n)
        self._gap = np.zeros(n)

    def _take(self, i, env, info):
        self._centers[i] = info["object_center"]
        self._contact_radii[i] = info["contact_radius"]
        self._object_radii[i] = info["object_radius"]

    def _observe(self):
        self._measure()
        self._records = self._fill_shapes(self._batch)
        goal = self.observation_slices["goal"]
        self._obs[:, goal.start:goal.start + 2] = self._centers
        self._obs[:, goal.start + 2] = self._contact_radii
        return self._clipped()

    def _rewards(self, converged):
        batch_wrap_rewards(self._batch, self._records, self._recorded, self._centers, self._contact_radii,
                           self._measures[:, 0], self._fraction, converged, self._template.wrap_rule,
                           self._terms, self._wrap_deg, self._gap, self._success)
        reward = np.empty(self.num_envs)
        reward_sums(self._terms, reward)
        return reward

    def _infos(self, report, stepped):
        items = self._base_items(report, self._batch)
        items += [("wrap_angle_deg", self._wrap_deg.copy()), ("penetration", self._measures[:, 0].copy()),
                  ("gap", self._gap.copy()), ("object_center", self._centers.copy()),
                  ("object_radius", self._object_radii.copy()),
                  ("contact_radius", self._contact_radii.copy())]
        items += [(name, self._terms[:, j].copy()) for j, name in enumerate(WRAP_TERMS)]
        return _info_arrays(items, self.num_envs)


def _seeds(seed, n: int) -> list:
    """Per-copy seeds of a vector ``reset(seed=...)``: None, copy i seeded ``seed + i`` for
    an int, or a sequence of n seeds."""
    if seed is None:
        return [None] * n
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(n)]
    if isinstance(seed, Sequence) and len(seed) == n:
        return list(seed)
    raise ValueError(f"seed must be None, an int (copy i is seeded s + i) or {n} seeds; got {seed!r}")


def _masked(infos: dict, mask: np.ndarray) -> dict:
    """Vector infos of the copies ``mask`` selects, as ``SyncVectorEnv`` gathers them: other
    rows zero, every ``_key`` mask equal to ``mask`` (and its own where the key has one)."""
    out = {}
    for key, value in infos.items():
        if key.startswith("_"):
            continue
        held = mask & infos[f"_{key}"] if isinstance(infos.get(f"_{key}"), np.ndarray) else mask
        if isinstance(value, dict):
            out[key] = _masked(value, mask)
        else:
            kept = np.zeros_like(value)
            kept[held] = value[held]
            out[key] = kept
        out[f"_{key}"] = held.copy()
    return out


def _scatter(report: solver.BatchReport, mask: np.ndarray) -> list[np.ndarray]:
    """The fields of a report of the rows ``mask`` selects, spread to full-length arrays."""
    fields = []
    for values in report:
        full = np.zeros(mask.shape[0], dtype=values.dtype)
        full[mask] = values
        fields.append(full)
    return fields
