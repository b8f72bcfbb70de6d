"""Track: follow a moving target with the tip (``SoftArm/OctArmTrack-v0``, ``SoftArm/CTTrack-v0``)."""

from __future__ import annotations

import math

import numpy as np

import solver
from softarm_gym.envs.config import check_options
from softarm_gym.envs.reach import ReachEnv

__all__ = ["TrackEnv"]


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

    ## Version History

    * v0: initial version.
    """

    def __init__(self, design="octarm_v", *, segment_steps: int = 25, **kwargs):
        if isinstance(segment_steps, bool) or int(segment_steps) != segment_steps or segment_steps < 1:
            raise ValueError(f"segment_steps must be an integer >= 1; got {segment_steps!r}")
        self.segment_steps = int(segment_steps)
        super().__init__(design, **kwargs)
        self._velocity = np.zeros(self.dim)
        self._path = None

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
        self._errors = []
        return self._scene, start

    def path_fraction(self, step: int) -> np.ndarray:
        """The trajectory's pressures (fractions of p_max, (n_inputs,)) at episode step
        ``step`` >= 0 — for analysis and tests, not observed. Waypoints are drawn as the
        trajectory reaches them (so asking ahead draws them early, changing nothing else)."""
        if isinstance(step, bool) or int(step) != step or step < 0:
            raise ValueError(f"step must be an integer >= 0; got {step!r}")
        if self._path is None:
            raise RuntimeError("call reset() before path_fraction()")
        k, within = divmod(int(step), self.segment_steps)
        while len(self._waypoints) < k + 2:
            self._waypoints.append(self.np_random.uniform(0.0, 1.0, self.n_inputs))
        ease = 0.5 * (1.0 - math.cos(math.pi * within / self.segment_steps))
        return self._waypoints[k] + ease * (self._waypoints[k + 1] - self._waypoints[k])

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
        self._errors.append(info["distance"])
        errors = np.asarray(self._errors)
        info["tracking_rms_m"] = float(np.sqrt(np.mean(errors ** 2)))
        info["tracking_max_m"] = float(errors.max())
        return obs, reward, terminated, truncated, info

    def _fill_goal(self, obs):
        super()._fill_goal(obs)
        goal = self._slices["goal"]
        obs[goal.start + 2 * self.dim:goal.stop] = self._velocity

    def _task_reward(self, converged):
        terms, success, info = super()._task_reward(converged)
        info["target_velocity"] = self._velocity.copy()
        return terms, success, info
