"""The shared machinery of the soft-arm environments: arm, stepping, sensing, observations.

:class:`SoftArmEnv` owns everything the tasks share; :class:`~softarm_gym.envs.reach.ReachEnv`
and :class:`~softarm_gym.envs.wrap.WrapEnv` only add a goal, a reward and a picture. One
step is one quasi-static equilibrium, warm-started from the previous one (the physical
path, with its hysteresis), then synthesised sensor readings, then the chosen shape
estimator, then the observation assembled into preallocated arrays.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import solver
from softarm_gym.envs.config import (  # noqa: F401  (MIN/MAX_RENDER_SIZE: still importable here)
    ACTION_MODES,
    ACTUATIONS,
    MAX_RENDER_SIZE,
    MIN_RENDER_SIZE,
    OBSERVATION_FORMATS,
    RENDER_MODES,
    EnvConfig,
)
from softarm_gym.envs.terms import (
    clip_observations,
    fill_pressures,
    fill_shape,
    fill_true_shapes,
    fractions_from_actions,
)
from softarm_gym.render import ArmRenderer, ArmRenderer3D, HumanWindow
from softarm_gym.sensing import make_estimator, shape_from_equilibrium, synthesize
from solver import layout as L

__all__ = ["SoftArmEnv", "ACTION_MODES", "OBSERVATION_FORMATS", "ACTUATIONS"]


class SoftArmEnv(gym.Env):
    """Base class of the soft-arm environments (see :class:`ReachEnv` for the env card).

    Subclasses implement ``_goal_bounds``, ``_reset_task``,
    ``_fill_goal``, ``_task_reward`` and ``_task_artists``.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 10}

    def __init__(self, design="octarm_v", planar: bool = True, observation: str = "true",
                 sensor_noise="off", base_angle_deg: float = 90.0, payload_kg=0.0, gravity: float = 9.81,
                 randomization=None, action_mode: str = "absolute", delta_scale: float = 0.1,
                 n_backbone: int = 8, observation_format: str = "flat",
                 initial_pressure_fraction: float = 0.1, solver_failure_penalty: float = 1.0,
                 max_solver_failures: int = 5, model: str = "full", synthesize_sensors=None,
                 actuation: str = "ideal", pressure_time_constant_s: float = 0.2,
                 step_dt_s: float = 0.1, self_contact=False, self_friction: float = 0.0,
                 render_mode: str | None = None,
                 render_size: int = 400):
        config = EnvConfig(
            design=design, planar=planar, observation=observation, sensor_noise=sensor_noise,
            base_angle_deg=base_angle_deg, payload_kg=payload_kg, gravity=gravity,
            randomization=randomization, action_mode=action_mode, delta_scale=delta_scale,
            n_backbone=n_backbone, observation_format=observation_format,
            initial_pressure_fraction=initial_pressure_fraction,
            solver_failure_penalty=solver_failure_penalty, max_solver_failures=max_solver_failures,
            model=model, synthesize_sensors=synthesize_sensors, actuation=actuation,
            pressure_time_constant_s=pressure_time_constant_s, step_dt_s=step_dt_s,
            self_contact=self_contact, self_friction=self_friction, render_mode=render_mode,
            render_size=render_size)
        self.config = config
        self.arm = config.arm
        self.planar = config.planar
        self.dim = 2 if self.planar else 3
        self.observation_name = config.observation
        self.sensor_noise = config.sensor_noise
        self.base_angle_deg = config.base_angle_deg
        self.payload_range = config.payload_range
        self.gravity = config.gravity
        self.randomization = config.randomization
        self.action_mode = config.action_mode
        self.delta_scale = config.delta_scale
        self.initial_pressure_fraction = config.initial_pressure_fraction
        self.solver_failure_penalty = config.solver_failure_penalty
        self.max_solver_failures = config.max_solver_failures
        self.actuation = config.actuation
        self.pressure_time_constant_s = config.pressure_time_constant_s
        self.step_dt_s = config.step_dt_s
        self._lag_gain = config.lag_gain
        self.model = config.model
        self.self_contact = config.self_contact_stiffness
        self.self_friction = config.self_friction
        self.n_backbone = config.n_backbone
        self.observation_format = config.observation_format
        self.render_mode = config.render_mode
        self.render_size = config.render_size

        self.p_max = float(self.arm.max_pressure)
        self.input_names = self.arm.input_names(self.planar)
        self.n_inputs = len(self.input_names)
        self.n_sections = len(self.arm.sections)
        self.reach = 2.0 * self.arm.length
        self.estimator = make_estimator(observation, self.arm, planar=self.planar,
                                        scene=solver.Scene(base_angle_deg=self.base_angle_deg,
                                                           gravity=self.gravity),
                                        n_samples=self.n_backbone)
        # Skip what a scene doesn't need: the ``true`` and ``model`` estimators read no sensors.
        if synthesize_sensors is False and self.estimator.reads_sensors:
            raise ValueError(f"observation {observation!r} estimates from sensor readings; "
                             "synthesize_sensors cannot be False")
        self.synthesize_sensors = bool(self.estimator.reads_sensors or synthesize_sensors)

        self.action_space = spaces.Box(-1.0, 1.0, shape=(self.n_inputs,), dtype=np.float32)
        parts = self._observation_parts()
        self._slices = {}
        start = 0
        for name, (low, _) in parts.items():
            self._slices[name] = slice(start, start + low.size)
            start += low.size
        low = np.concatenate([lo for lo, _ in parts.values()]).astype(np.float32)
        high = np.concatenate([hi for _, hi in parts.values()]).astype(np.float32)
        self._low64, self._high64 = low.astype(np.float64), high.astype(np.float64)
        if observation_format == "flat":
            self.observation_space = spaces.Box(low, high, dtype=np.float32)
        elif observation_format == "goal":
            # Gymnasium-Robotics' goal layout: everything but the goal block, then the goals.
            achieved, desired = self._goal_spaces()
            end = self._slices["goal"].start
            self.observation_space = spaces.Dict([
                ("observation", spaces.Box(low[:end], high[:end], dtype=np.float32)),
                ("achieved_goal", achieved), ("desired_goal", desired)])
        else:
            # A sequence of pairs keeps the flat order (a plain dict would be sorted by key), so
            # FlattenObservation of the Dict format is the flat format and observation_slices apply.
            self.observation_space = spaces.Dict([
                (name, spaces.Box(low[sl], high[sl], dtype=np.float32)) for name, sl in self._slices.items()])
        self._obs = np.zeros(low.size)
        self._shape_starts = np.array([self._slices[name].start for name in
                                       ("tip", "section_ends", "backbone")], dtype=np.int64)
        self._sim_arm = self.arm
        self._scene = solver.Scene(base_angle_deg=self.base_angle_deg, gravity=self.gravity)
        self._stepper = None
        self._record_grid = None
        self._fraction = np.zeros(self.n_inputs)
        self._command = self._fraction
        self._failures = 0
        self._readings = None
        self._shape_estimate = None
        self._estimated_tip = np.zeros(self.dim)  # written in place (see _bind_rows)
        self._bind_rows()
        self._renderer = None
        self._window = None

    # ------------------------------------------------------------------ layout

    def _observation_parts(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Names and (low, high) bounds of the observation blocks, in flat order."""
        r = self.reach
        ends_low = np.tile([-r] * self.dim + [-1.0] * self.dim, self.n_sections)
        goal_low, goal_high = self._goal_bounds()
        return {
            "tip": (np.full(self.dim, -r), np.full(self.dim, r)),
            "section_ends": (ends_low, -ends_low),
            "backbone": (np.full(self.dim * self.n_backbone, -r), np.full(self.dim * self.n_backbone, r)),
            "pressures": (np.full(self.n_inputs, -1.0), np.full(self.n_inputs, 1.0)),
            **({"commanded": (np.full(self.n_inputs, -1.0), np.full(self.n_inputs, 1.0))}
               if self.actuation == "lag" else {}),
            "goal": (np.asarray(goal_low, dtype=float), np.asarray(goal_high, dtype=float)),
        }

    # ------------------------------------------------------------------ task hooks

    def _goal_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _goal_spaces(self) -> tuple[spaces.Box, spaces.Box]:
        """The ``achieved_goal`` and ``desired_goal`` spaces of ``observation_format="goal"``."""
        raise ValueError(f"{type(self).__name__} has no goal point to relabel: observation_format='goal' "
                         "is for the reach environments; use 'flat' or 'dict'")

    def _reset_task(self, options: dict | None, start: solver.Equilibrium
                    ) -> tuple[solver.Scene, solver.Equilibrium]:
        """Draw the episode's task given the start state ``start`` in the task-free scene.

        Returns the episode's scene (``self._scene`` or one with obstacles) and the start
        state in it (converged).
        """
        raise NotImplementedError

    def _fill_goal(self, obs: np.ndarray) -> None:
        """Write the goal block of the flat observation ``obs`` (D,) (float64)."""
        raise NotImplementedError

    def _task_reward(self, converged: bool) -> tuple[dict[str, float], bool, dict]:
        """Reward terms (``reward_*``, ``reward_solver`` last, summing to the reward), success
        and task info of the current state; ``converged``: whether the step converged."""
        raise NotImplementedError

    def _task_artists(self) -> dict:
        raise NotImplementedError

    def _initial_fraction(self) -> np.ndarray:
        """Pressures (fraction of p_max) the episode starts from."""
        return self.np_random.uniform(0.0, self.initial_pressure_fraction, self.n_inputs)

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        self._sim_arm = self.randomization.sample(self.arm, rng)
        payload = float(rng.uniform(*self.payload_range)) if self.payload_range[1] > self.payload_range[0] \
            else self.payload_range[0]
        self._scene = solver.Scene(base_angle_deg=self.base_angle_deg, payload_kg=payload,
                                   gravity=self.gravity, self_contact=self.self_contact,
                                   self_friction=self.self_friction)
        stepper = solver.Stepper(self._sim_arm, self._scene, model=self.model, planar=self.planar)
        fraction = self._initial_fraction()
        report = stepper.reset(fraction * self.p_max)
        if not report.converged:
            fraction = np.zeros(self.n_inputs)
            report = stepper.reset(fraction)
        if not report.converged:
            raise RuntimeError(f"the unactuated {self.arm.name} arm has no converged equilibrium in "
                               f"scene {self._scene}: residual {report.residual:.3g} N m")
        self._fraction = self._command = fraction
        scene, eq = self._reset_task(options, stepper.equilibrium)
        if scene != stepper.scene:
            stepper = stepper.with_scene(scene)
            stepper.adopt(eq)
        self._scene = scene
        self._stepper = stepper
        self._record_grid = None  # the lean ``true`` observation's scratch is for another grid
        self._failures = 0
        self.estimator.reset()
        self._sense()
        attempt = solver.StepReport(eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        terms, success, task_info = self._task_reward(True)
        info = self._info(terms, success, task_info, attempt)
        if self.render_mode == "human":
            self.render()
        return self._observation(), info

    def step(self, action):
        if self._stepper is None:
            raise RuntimeError("call reset() before step()")
        command = self._action_to_fraction(action)
        fraction = command
        if self.actuation == "lag":
            fraction = self._fraction + self._lag_gain * (command - self._fraction)
        report, accepted = self._advance(fraction * self.p_max)
        if accepted:
            self._fraction = fraction
            self._command = command
        self._failures = 0 if report.converged else self._failures + 1
        self._sense()
        terms, success, task_info = self._task_reward(report.converged)
        reward = 0.0
        for value in terms.values():
            reward += value
        truncated = self._failures >= self.max_solver_failures
        info = self._info(terms, success, task_info, report)
        if self.render_mode == "human":
            self.render()
        return self._observation(), reward, self._terminated(success), truncated, info

    def _terminated(self, success: bool) -> bool:
        return False

    def _advance(self, pressures: np.ndarray) -> tuple[solver.StepReport, bool]:
        """Step the simulated arm towards ``pressures`` (Pa): the solver's report and whether
        the new state stands (here: whenever the solve converged; an unconverged step keeps
        the previous equilibrium). A task may reject a converged state by restoring the
        previous one."""
        report = self._stepper.step(pressures)
        return report, report.converged

    # ------------------------------------------------------------------ internals

    @property
    def stepper(self) -> solver.Stepper | None:
        """The solver's stepper of the episode, holding the simulated arm's current (last
        accepted) state (None before the first reset): its path, record and profile
        (``last_path``, ``record``, ``pass_costs``) for benchmarks and tests, and its
        equilibrium for batched environments that take a copy's start state from a single
        env. Stepping it directly bypasses the env."""
        return self._stepper

    @property
    def pressure_fractions(self) -> np.ndarray:
        """(n_inputs,) the current channel pressures as fractions of p_max (a copy: the exact
        numbers the observation's ``pressures`` block and the rewards are made from)."""
        return self._fraction.copy()

    @property
    def _eq(self) -> solver.Equilibrium | None:
        """The current (last converged) equilibrium of the simulated arm."""
        return None if self._stepper is None else self._stepper.equilibrium

    @property
    def _shape(self):
        """The estimator's :class:`~softarm_gym.sensing.ShapeEstimate` of the current state
        (for the lean ``true`` path, built on first access)."""
        if self._shape_estimate is None and self._stepper is not None:
            self._shape_estimate = shape_from_equilibrium(self._eq, self.n_backbone)
        return self._shape_estimate

    def _solver_term(self, converged: bool) -> float:
        """The ``reward_solver`` term: minus the penalty for an unconverged step."""
        return 0.0 if converged else -self.solver_failure_penalty

    def _action_to_fraction(self, action) -> np.ndarray:
        """Validate and clip a normalised action; return channel pressures as fractions of p_max."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (self.n_inputs,):
            raise ValueError(f"action must have shape ({self.n_inputs},) for channels "
                             f"{', '.join(self.input_names)}; got shape {a.shape}")
        fraction = np.empty(self.n_inputs)
        bad = fractions_from_actions(a[None], self._command[None],
                                     self.action_mode == "delta", self.delta_scale,
                                     fraction[None])
        if bad >= 0:
            raise ValueError(f"action for channel {self.input_names[bad]!r} is not finite: {a[bad]}")
        return fraction

    def _sense(self) -> None:
        """Readings of the current equilibrium and the estimator's shape from them, written to
        the shape blocks of the observation (tip, section ends, backbone)."""
        stepper = self._stepper
        record = stepper.record
        if self.observation_name == "true" and record is not None and not self.synthesize_sensors:
            # The lean path: the true shape straight from the solver's record.
            self._readings = None
            self._shape_estimate = None
            ends = stepper.section_ends
            if self._record_grid is not ends:
                # Scratch for this grid (in contact a state moves between the settings' grid
                # and the contact layout, which may have other rows).
                self._record_grid = ends
                self._s_query = np.linspace(0.0, float(record[-1, L.S]), self.n_backbone)
                self._section_rows = np.array(ends, dtype=np.int64)
                self._tangent = np.empty((1, record.shape[0], 2))
                self._backbone = np.empty((1, self.n_backbone, 2))
            fill_true_shapes(record[None], self._section_rows, self._s_query, self._shape_starts,
                             self._obs_row, self._tip_row, self._tangent, self._backbone)
            return
        eq = self._eq
        self._readings = synthesize(eq, self._sim_arm, self.sensor_noise, self.np_random) \
            if self.synthesize_sensors else None
        shape = self._shape_estimate = self.estimator.estimate(self._readings, eq.pressures, truth=eq)
        self._estimated_tip[:] = shape.tip
        fill_shape(self._obs, self._slices, shape, self.planar)

    def _observation(self):
        obs = self._obs
        fill_pressures(self._fraction[None], self._slices["pressures"].start, self._obs_row)
        if self.actuation == "lag":
            fill_pressures(self._command[None], self._slices["commanded"].start, self._obs_row)
        self._fill_goal(obs)
        flat = np.empty(obs.size, dtype=np.float32)
        clip_observations(self._obs_row, self._low64, self._high64, flat[None])
        if self.observation_format == "flat":
            return flat
        if self.observation_format == "goal":
            achieved, desired = self._goals()
            return {"observation": flat[:self._slices["goal"].start], "achieved_goal": achieved,
                    "desired_goal": desired}
        return {name: flat[sl] for name, sl in self._slices.items()}

    def _info(self, terms: dict, success: bool, task_info: dict, attempt: solver.StepReport) -> dict:
        stepper = self._stepper
        tip = stepper.tip
        readings = self._readings
        info = {
            "tip_true": tip.copy(),
            "tip_estimated": self._estimated_tip.copy(),
            "estimation_error": math.dist(self._estimated_tip, tip),
            "sensors": {} if readings is None else {
                "encoder_lengths": readings.encoder_lengths,
                "inclinometers": readings.inclinometers,
                "base_wrench": readings.base_wrench,
                **({} if self.planar else {"imu": readings.imu})},
            "converged": attempt.converged,
            "solver": attempt._asdict(),
            "solver_failures": self._failures,
            "pressures_pa": stepper.pressures.copy(),
            "payload_kg": self._scene.payload_kg,
            "is_success": bool(success),
        }
        if self.actuation == "lag":
            info["commanded_pressures_pa"] = self._command * self.p_max
        info.update(task_info)
        info.update(terms)
        return info

    # ------------------------------------------------------------------ render

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or "
                            "'human' to gym.make")
            return None
        if self._stepper is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            renderer = ArmRenderer if self.planar else ArmRenderer3D
            self._renderer = renderer(extent=1.3 * self.arm.length, size=self.render_size)
        eq = self._eq
        artists = self._task_artists()
        frame = self._renderer.frame(
            eq.positions, eq.positions[list(eq.section_ends)], self._shape.backbone,
            self._shape.tip, caption=self._caption(), **artists)
        if self.render_mode == "rgb_array":
            return frame
        if self._window is None:
            self._window = HumanWindow(self.render_size, self.metadata["render_fps"], type(self).__name__)
        self._window.show(frame)
        return None

    def _caption(self) -> str:
        return (f"{self.arm.name}  obs={self.observation_name}\n"
                f"est. error {1000 * math.dist(self._shape.tip, self._eq.tip):.1f} mm")

    @property
    def simulated_arm(self) -> solver.designs.ArmDesign:
        """The design simulated this episode: the nominal ``arm``, perturbed by ``randomization``
        at the last reset."""
        return self._sim_arm

    @property
    def observation_slices(self) -> dict[str, slice]:
        """Where each block sits in a flat observation: name → slice, in flat order
        (``tip``, ``section_ends``, ``backbone``, ``pressures``, ``goal``)."""
        return dict(self._slices)

    def close(self):
        if self._window is not None:
            self._window.close()
            self._window = None
        self._renderer = None

    def _bind_rows(self) -> None:
        """Batch-of-one views of the arrays the shared batch-first rules
        (:mod:`softarm_gym.envs.terms`) write or read every step, made once (the arrays are
        written in place; a pickle copies views apart, so unpickling binds them again)."""
        self._obs_row = self._obs.reshape(1, -1)
        self._tip_row = self._estimated_tip.reshape(1, -1)

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_renderer"] = None
        state["_window"] = None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._bind_rows()
