"""A batched vector environment: many reach tasks stepped by one parallel solver call.

``gym.make_vec("SoftArm/OctArmReach-v0", num_envs=1024, vectorization_mode="vector_entry_point")``
returns a :class:`BatchedReachVectorEnv`: all arms move together through
:func:`solver.step_batch` (numba ``prange`` over the copies), and observations, rewards and
resets are computed for the whole batch at once. Observations, actions and rewards are
those of :class:`softarm_gym.envs.ReachEnv` with ``observation="true"``, so a policy trained
on one runs on the other. Estimator observations, payloads and parameter randomisation need
the per-copy machinery of the single env: use ``vectorization_mode="sync"`` or ``"async"``
for those (a clear ``ValueError`` says so).
"""

from __future__ import annotations

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

import solver
from softarm_gym.envs import ReachEnv
from solver.jit import njit
from solver.rod import hermite_resample

__all__ = ["BatchedReachVectorEnv"]

_SUPPORTED = {"design", "base_angle_deg", "n_backbone", "action_mode", "delta_scale",
              "distance_weight", "control_weight", "success_bonus", "success_tolerance",
              "initial_pressure_fraction", "solver_failure_penalty", "max_solver_failures",
              "terminate_on_success", "observation", "planar", "model"}


@njit
def _fill_observations(shapes, section_ends, s_query, fraction, target, low, high, tip_slice,
                       ends_slice, backbone_slice, pressure_slice, goal_slice, obs, tips, tangent,
                       backbone):
    """Flat ReachEnv observations of every copy from its recorded backbone.

    ``shapes`` (n, N, 10) are :mod:`solver._planar` records (s, x, y, θ, m, n_x, n_y, v1, v3, u).
    The backbone is resampled by the same cubic Hermite rule as the ``true`` estimator.
    """
    n = shapes.shape[0]
    ns = section_ends.shape[0]
    for k in range(n):
        rec = shapes[k]
        rows = rec.shape[0]
        for r in range(rows):
            c = np.cos(rec[r, 3])
            sn = np.sin(rec[r, 3])
            # dr/ds = v3 d3 + v1 d1, d3 = (cos θ, sin θ), d1 = (−sin θ, cos θ)
            tangent[r, 0] = rec[r, 8] * c - rec[r, 7] * sn
            tangent[r, 1] = rec[r, 8] * sn + rec[r, 7] * c
        hermite_resample(rec[:, 0], rec[:, 1:3], tangent[:rows], s_query, backbone)
        tips[k, 0] = rec[rows - 1, 1]
        tips[k, 1] = rec[rows - 1, 2]
        backbone[backbone.shape[0] - 1, 0] = tips[k, 0]
        backbone[backbone.shape[0] - 1, 1] = tips[k, 1]
        o = obs[k]
        o[tip_slice[0]] = tips[k, 0]
        o[tip_slice[0] + 1] = tips[k, 1]
        for i in range(ns):
            r = section_ends[i]
            base = ends_slice[0] + 4 * i
            o[base] = rec[r, 1]
            o[base + 1] = rec[r, 2]
            o[base + 2] = np.cos(rec[r, 3])
            o[base + 3] = np.sin(rec[r, 3])
        for j in range(backbone.shape[0]):
            o[backbone_slice[0] + 2 * j] = backbone[j, 0]
            o[backbone_slice[0] + 2 * j + 1] = backbone[j, 1]
        for c in range(fraction.shape[1]):
            o[pressure_slice[0] + c] = 2.0 * fraction[k, c] - 1.0
        g = goal_slice[0]
        o[g] = target[k, 0]
        o[g + 1] = target[k, 1]
        o[g + 2] = target[k, 0] - tips[k, 0]
        o[g + 3] = target[k, 1] - tips[k, 1]
        for d in range(o.shape[0]):
            o[d] = min(max(o[d], low[d]), high[d])


class BatchedReachVectorEnv(VectorEnv):
    """``num_envs`` reach tasks (``true`` observations) advanced by one parallel solver call.

    Same spaces, rewards (``reward_distance + reward_control + reward_success +
    reward_solver``), targets (tips of cold equilibria at uniform random pressures), start
    states and failure policy as :class:`~softarm_gym.envs.ReachEnv` — see its env card.
    Episodes end by truncation after ``max_episode_steps`` or ``max_solver_failures``
    consecutive unconverged steps (or on success with ``terminate_on_success``); finished
    copies are reset in the same step (``AutoresetMode.SAME_STEP``), their last observation
    in ``infos["final_obs"]``.

    Args:
        num_envs: number of arms.
        max_episode_steps: truncation length (default 100, as registered).
        **kwargs: ReachEnv arguments; only those in ``_SUPPORTED`` with ``observation="true"``.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 64, max_episode_steps: int = 100, **kwargs):
        if isinstance(num_envs, bool) or int(num_envs) != num_envs or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1; got {num_envs!r}")
        unsupported = sorted(set(kwargs) - _SUPPORTED)
        if unsupported:
            raise ValueError(
                f"the batched vector env does not support {', '.join(unsupported)}; use "
                "gym.make_vec(..., vectorization_mode='sync') for those")
        if kwargs.get("observation", "true") != "true":
            raise ValueError("the batched vector env provides observation='true' only; use "
                             "vectorization_mode='sync' or 'async' for estimator observations")
        if kwargs.pop("model", "full") != "full":
            raise ValueError("the batched vector env simulates the full model only")
        self._template = ReachEnv(**kwargs)
        t = self._template
        self.num_envs = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self.single_observation_space = t.observation_space
        self.single_action_space = t.action_space
        self.observation_space = batch_space(t.observation_space, self.num_envs)
        self.action_space = batch_space(t.action_space, self.num_envs)
        self.arm = t.arm
        self.scene = solver.Scene(base_angle_deg=t.base_angle_deg)
        self.render_mode = None
        n = self.num_envs
        self._obs = np.zeros((n, t.observation_space.shape[0]))
        self._tips = np.zeros((n, 2))
        self._target = np.zeros((n, 2))
        self._fraction = np.zeros((n, t.n_inputs))
        self._steps = np.zeros(n, dtype=np.int64)
        self._failures = np.zeros(n, dtype=np.int64)
        self._state = None
        self._s_query = np.linspace(0.0, self.arm.length, t.n_backbone)
        self._slices = {name: np.array([sl.start], dtype=np.int64)
                        for name, sl in t.observation_slices.items()}

    @property
    def observation_slices(self) -> dict[str, slice]:
        """Where each block sits in one copy's flat observation (as the single env's)."""
        return self._template.observation_slices

    # ------------------------------------------------------------------ helpers

    def _solve(self, fraction, rows=None, cold=False):
        """Step (or cold-solve) the given rows to ``fraction`` · p_max; updates the batch state."""
        p = fraction * self._template.p_max
        if rows is None:
            self._state = solver.step_batch(self.arm, p, self.scene, None if cold else self._state,
                                            record=True)
            return self._state.converged
        sub = solver.step_batch(self.arm, p, self.scene, None, record=True)
        st = self._state
        for name in ("pressures", "tips", "converged", "shapes", "base_moment", "channel_pressures"):
            getattr(st, name)[rows] = getattr(sub, name)
        return sub.converged

    def _reset_rows(self, rows):
        """New targets and start states for ``rows`` (an index array)."""
        rng = self.np_random
        t = self._template
        k = rows.size
        target_fraction = rng.uniform(0.0, 1.0, (k, t.n_inputs))
        targets = solver.step_batch(self.arm, target_fraction * t.p_max, self.scene)
        # A target whose cold solve did not converge is replaced by the rest position's tip
        # of a fresh draw until all converge (rare: see softarm stress).
        for _ in range(20):
            bad = ~targets.converged
            if not bad.any():
                break
            target_fraction[bad] = rng.uniform(0.0, 1.0, (int(bad.sum()), t.n_inputs))
            retry = solver.step_batch(self.arm, target_fraction[bad] * t.p_max, self.scene)
            targets.tips[bad] = retry.tips
            targets.converged[bad] = retry.converged
        self._target[rows] = targets.tips
        start = rng.uniform(0.0, t.initial_pressure_fraction, (k, t.n_inputs))
        converged = self._solve(start, rows)
        start[~converged] = 0.0
        if not converged.all():
            self._solve(start, rows)
        self._fraction[rows] = start
        self._steps[rows] = 0
        self._failures[rows] = 0

    def _observe(self):
        t = self._template
        st = self._state
        rows = st.shapes.shape[1]
        _fill_observations(st.shapes, np.asarray(st.section_ends, dtype=np.int64), self._s_query,
                           self._fraction, self._target, t._low64, t._high64, self._slices["tip"],
                           self._slices["section_ends"], self._slices["backbone"],
                           self._slices["pressures"], self._slices["goal"], self._obs, self._tips,
                           np.empty((rows, 2)), np.empty((t.n_backbone, 2)))
        return self._obs.astype(np.float32)

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        n = self.num_envs
        self._state = solver.step_batch(self.arm, np.zeros((n, self._template.n_inputs)),
                                        self.scene, record=True)
        self._reset_rows(np.arange(n))
        obs = self._observe()
        return obs, {"target": self._target.copy(), "tip_true": self._tips.copy()}

    def step(self, actions):
        t = self._template
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.num_envs, t.n_inputs):
            raise ValueError(f"actions must have shape ({self.num_envs}, {t.n_inputs}); got {a.shape}")
        bad = ~np.isfinite(a)
        if bad.any():
            env, ch = np.argwhere(bad)[0]
            raise ValueError(f"action for env {env}, channel {t.input_names[ch]!r} is not finite: "
                             f"{a[env, ch]}")
        a = np.clip(a, -1.0, 1.0)
        if t.action_mode == "absolute":
            fraction = 0.5 * (a + 1.0)
        else:
            fraction = np.clip(self._fraction + t.delta_scale * a, 0.0, 1.0)
        ok = self._solve(fraction)
        self._fraction = np.where(ok[:, None], fraction, self._fraction)
        self._failures = np.where(ok, 0, self._failures + 1)
        self._steps += 1
        obs = self._observe()
        distance = np.hypot(*(self._tips - self._target).T)
        success = distance <= t.success_tolerance
        terms = {"reward_distance": -t.distance_weight * distance,
                 "reward_control": -t.control_weight * np.mean(self._fraction ** 2, axis=1),
                 "reward_success": np.where(success, t.success_bonus, 0.0),
                 "reward_solver": np.where(ok, 0.0, -t.solver_failure_penalty)}
        reward = terms["reward_distance"] + terms["reward_control"] + terms["reward_success"] \
            + terms["reward_solver"]
        terminated = success & t.terminate_on_success
        truncated = (self._steps >= self.max_episode_steps) | (self._failures >= t.max_solver_failures)
        infos = {**terms, "distance": distance, "is_success": success, "converged": ok,
                 "tip_true": self._tips.copy(), "target": self._target.copy()}
        done = terminated | truncated
        if done.any():
            infos["final_obs"] = obs.copy()  # meaningful where ``_final_obs`` is True
            infos["_final_obs"] = done.copy()
            self._reset_rows(np.flatnonzero(done))
            obs = self._observe()
        return obs, reward, terminated, truncated, infos

    def close_extras(self, **kwargs):
        self._template.close()
