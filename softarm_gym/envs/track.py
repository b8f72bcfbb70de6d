"""Track: follow a moving target with the tip (``SoftArm/OctArmTrack-v0``, ``SoftArm/CTTrack-v0``)."""

from __future__ import annotations

import math

import numpy as np

import solver
from softarm_gym.envs.config import check_options
from softarm_gym.envs.reach import ReachEnv
from softarm_gym.envs.terms import tracking_errors

__all__ = ["TrackEnv", "path_easing"]


def path_easing(within: int, segment_steps: int) -> float:
    """The trajectory's progress from one waypoint to the next after ``within`` of its
    ``segment_steps`` steps: cosine easing, ½(1 − cos(π·within/segment_steps)) ∈ [0, 1), zero
    pressure rate at each waypoint."""
    return 0.5 * (1.0 - math.cos(math.pi * within / segment_steps))


class TrackEnv(ReachEnv):
    """Follow a target that moves along a smooth, reachable trajectory (quasi-static arm).

    ## Description

    The arm, sensing, actions and rewards of :class:`~softarm_gym.envs.ReachEnv`; the target
    moves every step. Its trajectory is the tip of this episode's arm (randomised, with its
    payload) driven along a smooth random pressure path — waypoints uniform in [0, p_max]
    per channel, ``segment_steps`` steps apart, joined by cosine easing (zero pressure rate
    at each waypoint) — and followed quasi-statically by a second solver, so every target is
    reachable by the arm itself, hysteresis included.

    ## Action Space

    As ReachEnv.

    ## Observation Space

    The ReachEnv blocks, with a ``goal`` of 3·dim values: the target (m), target − estimated
    tip (m) and the target's last displacement (m per step), from which its next position can
    be predicted.

    ## Rewards

    As ReachEnv, against the target of the current step: within a step the target moves
    first and the arm second, so the reward measures how well the action anticipated the
    target's motion (the displacement observed at the last step).

    ## Starting State

    As ReachEnv, with the trajectory's first waypoint drawn after the start pressures and
    the target at its tip.

    ## Episode End

    As ReachEnv (registered ``max_episode_steps`` 200).

    ## Arguments

    ReachEnv's, plus ``segment_steps`` (25): steps between waypoints — the trajectory's
    speed, a difficulty setting (smaller is faster). ``options`` are not supported (the
    trajectory is the task).

    ## Info

    ReachEnv's, plus ``target_velocity`` (m/step), ``tracking_rms_m`` and ``tracking_max_m``:
    the RMS and the largest tracking error (true tip) over the episode's steps so far.

    ## Vector Environments

    ``gym.make_vec(id, N, vectorization_mode="vector_entry_point")`` gives
    :class:`softarm_gym.vector.BatchedTrackVectorEnv`: the N targets' trajectories and the N
    arms each stepped by one :class:`solver.BatchStepper` call, copy i bit for bit this env
    seeded s + i (resets by one TrackEnv per copy). It refuses ``planar=False`` and what the
    batched envs refuse (docs/environments.md, "Batched environment").

    ## Version History

    * v0: initial version (absolute actions). Kept; ``gym.make`` notes that v1 exists.
    * v1 (recommended): delta actions (``action_mode="delta"``, ``delta_scale=0.1``: 10 % of
      p_max per step, above the trajectory's fastest pressure rate of π/(2·segment_steps) of
      the waypoint gap per step, 6.3 % at the default 25) and ``self_contact=True``
      (docs/environments.md, "Sequential and self-contacting versions").
    """

    def __init__(self, design="octarm_v", *, segment_steps: int = 25, **kwargs):
        if isinstance(segment_steps, bool) or int(segment_steps) != segment_steps or segment_steps < 1:
            raise ValueError(f"segment_steps must be an integer >= 1; got {segment_steps!r}")
        self.segment_steps = int(segment_steps)
        super().__init__(design, **kwargs)
        self._velocity = np.zeros(self.dim)
        self._path = None
        # Running tracking statistics (softarm_gym.envs.terms.tracking_errors): steps,
        # sum of squared errors, largest error, RMS.
        self._tracking = (np.zeros(1, dtype=np.int64), np.zeros(1), np.zeros(1), np.zeros(1))

    def _goal_bounds(self):
        low, high = super()._goal_bounds()
        # One step of the target moves it by far less than the arm's reach.
        return np.concatenate([low, np.full(self.dim, -self.reach)]), \
            np.concatenate([high, np.full(self.dim, self.reach)])

    def _reset_task(self, options, start):
        check_options(options, ())
        rng = self.np_random
        self._waypoints = [rng.uniform(0.0, 1.0, self.n_inputs), rng.uniform(0.0, 1.0, self.n_inputs)]
        self._step_count = 0
        self._path = solver.Stepper(self._sim_arm, self._scene, model=self.model, planar=self.planar)
        report = self._path.reset(self._waypoints[0] * self.p_max)
        if not report.converged:
            raise RuntimeError(f"the trajectory's first waypoint has no converged equilibrium for "
                               f"{self.arm.name} in {self._scene}")
        self._target[:] = self._path.tip
        self.target_pressures_pa = self._path.pressures.copy()
        self._velocity = np.zeros(self.dim)
        for value in self._tracking:
            value[:] = 0
        return self._scene, start

    @property
    def target_stepper(self) -> solver.Stepper | None:
        """The second solver's :class:`solver.Stepper`, whose tip is the target (None before
        :meth:`reset`): for batched environments that take a copy's start from a single env."""
        return self._path

    def path_fraction(self, step: int) -> np.ndarray:
        """The trajectory's pressures (fractions of p_max, (n_inputs,)) at episode step
        ``step`` >= 0 — for analysis and tests, not observed. Waypoints are drawn as the
        trajectory reaches them (so asking ahead draws them early, changing nothing else)."""
        start, end, ease = self.path_segment(step)
        return start + ease * (end - start)

    def path_segment(self, step: int) -> tuple[np.ndarray, np.ndarray, float]:
        """The waypoints (fractions of p_max, (n_inputs,) each) the trajectory moves between at
        episode step ``step`` >= 0, and its progress between them (:func:`path_easing`):
        :meth:`path_fraction` is start + ease·(end − start). Draws waypoints as
        :meth:`path_fraction` does."""
        if isinstance(step, bool) or int(step) != step or step < 0:
            raise ValueError(f"step must be an integer >= 0; got {step!r}")
        if self._path is None:
            raise RuntimeError("call reset() before path_fraction() or path_segment()")
        k, within = divmod(int(step), self.segment_steps)
        while len(self._waypoints) < k + 2:
            self._waypoints.append(self.np_random.uniform(0.0, 1.0, self.n_inputs))
        return self._waypoints[k], self._waypoints[k + 1], path_easing(within, self.segment_steps)

    def _advance_target(self) -> None:
        """Move the target one step along the pressure path (the path's solver follows it)."""
        self._step_count += 1
        fraction = self.path_fraction(self._step_count)
        previous = self._target.copy()
        # An unconverged path step keeps the path's last state: the target pauses, still reachable.
        self._path.step(fraction * self.p_max)
        self._target[:] = self._path.tip
        self.target_pressures_pa = self._path.pressures.copy()
        self._velocity = self._target - previous

    def step(self, action):
        if self._stepper is None:
            raise RuntimeError("call reset() before step()")
        self._action_to_fraction(action)  # bad actions raise before the target moves
        self._advance_target()
        obs, reward, terminated, truncated, info = super().step(action)
        steps, squares, largest, rms = self._tracking
        steps += 1
        tracking_errors(self._distance, steps, squares, largest, rms)
        info["tracking_rms_m"] = float(rms[0])
        info["tracking_max_m"] = float(largest[0])
        return obs, reward, terminated, truncated, info

    def _fill_goal(self, obs):
        super()._fill_goal(obs)
        goal = self._slices["goal"]
        obs[goal.start + 2 * self.dim:goal.stop] = self._velocity

    def _task_reward(self, converged):
        terms, success, info = super()._task_reward(converged)
        info["target_velocity"] = self._velocity.copy()
        return terms, success, info
