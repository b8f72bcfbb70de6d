"""The validated configuration of a soft-arm environment, and the argument checks the tasks share.

:class:`EnvConfig` is what :class:`~softarm_gym.envs.base.SoftArmEnv` takes as keyword
arguments, checked and normalised in its ``__post_init__``: bad input raises ``ValueError``
with one line naming the argument. The tasks check their own arguments with
:func:`finite_number`, :func:`value_range` and (for ``reset(options=...)``) :func:`check_options`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

import solver
from softarm_gym.envs.randomization import coerce_randomization
from softarm_gym.sensing import ESTIMATORS, SensorNoise
from solver.scene import check_friction

__all__ = ["EnvConfig", "ACTION_MODES", "OBSERVATION_FORMATS", "ACTUATIONS", "RENDER_MODES",
           "finite_number", "value_range", "check_options"]

ACTION_MODES = ("absolute", "delta")
OBSERVATION_FORMATS = ("flat", "dict", "goal")
ACTUATIONS = ("ideal", "lag")
"""How channel pressures follow the command: at once, or through a first-order lag."""
RENDER_MODES = ("human", "rgb_array")
MIN_RENDER_SIZE, MAX_RENDER_SIZE = 16, 4096
"""Limits of ``render_size`` (px, the side of the square frame): 4096² RGB is 50 MB a frame."""


def finite_number(name: str, value, minimum: float | None = None) -> float:
    """``value`` as a float; raises naming ``name`` unless it is a finite number (>= ``minimum``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number; got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}; got {value!r}")
    return float(value)


def check_options(options, allowed: tuple[str, ...]) -> dict:
    """``reset(options=...)`` as a dict (None → empty); unknown keys raise instead of being ignored."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(f"reset options must be a dict; got {options!r}")
    unknown = sorted(map(repr, set(options) - set(allowed)))
    if unknown:
        raise ValueError(f"unknown reset option(s) {', '.join(unknown)}; this environment accepts "
                         f"{', '.join(map(repr, allowed))}")
    return options


def value_range(name: str, value) -> tuple[float, float]:
    """A number or a (low, high) pair of finite numbers >= 0, as (low, high)."""
    if isinstance(value, (tuple, list)):
        if len(value) != 2:
            raise ValueError(f"{name} must be a number or a (low, high) pair; got {value!r}")
        low = finite_number(f"{name} low", value[0], 0.0)
        high = finite_number(f"{name} high", value[1], 0.0)
        if high < low:
            raise ValueError(f"{name} range ({low}, {high}) has high < low")
        return low, high
    v = finite_number(name, value, 0.0)
    return v, v


def _design(design) -> solver.designs.ArmDesign:
    if isinstance(design, solver.designs.ArmDesign):
        arm = design
    elif isinstance(design, str):
        arm = solver.designs.get(design)
    else:
        raise ValueError(f"design must be a design name ({', '.join(solver.designs.DESIGN_NAMES)}) "
                         f"or a solver.designs.ArmDesign; got {design!r}")
    if not arm.tubes:
        raise ValueError(f"design {arm.name!r} has no channels to actuate")
    return arm


def _sensor_noise(value) -> SensorNoise:
    if isinstance(value, SensorNoise):
        return value
    if value is None or value == "off":
        return SensorNoise.off()
    if value == "thesis":
        return SensorNoise.thesis()
    if isinstance(value, dict):
        try:
            return SensorNoise(**value)
        except TypeError as exc:
            raise ValueError(f"sensor_noise has unknown fields: {exc}") from None
    raise ValueError("sensor_noise must be 'off', 'thesis', a dict of SensorNoise fields or a "
                     f"SensorNoise; got {value!r}")


def _self_contact_stiffness(value, arm, planar: bool, model: str) -> float | None:
    """The penalty (N/m²) of a ``self_contact`` argument: False → None (off); True → the
    ring stiffness of the arm's tubes (``TubeMaterial.ring_stiffness``, the smallest: the
    contact law of the wrap envs' discs); a number > 0 → itself."""
    if value is False or value is None:
        return None
    if not planar or model == "constant_curvature":
        raise ValueError("self_contact needs planar=True and model 'full' or 'unshearable' "
                         f"(got planar={planar}, model={model!r})")
    if value is True:
        return float(min(t.material.ring_stiffness for t in arm.tubes))
    k = finite_number("self_contact", value, 0.0)
    if k <= 0:
        raise ValueError(f"self_contact must be True, False or a penalty stiffness > 0 (N/m²); "
                         f"got {value!r}")
    return k


@dataclass(frozen=True)
class EnvConfig:
    """The keyword arguments of :class:`~softarm_gym.envs.base.SoftArmEnv` (documented on
    :class:`~softarm_gym.envs.reach.ReachEnv`), checked in ``__post_init__``; the fields keep
    what was passed, normalised (``planar`` a bool, numbers floats or ints, ``sensor_noise`` a
    :class:`SensorNoise`, ``randomization`` an :class:`ArmRandomization` checked against the
    arm).

    Attributes (derived):
        arm: the design (``design`` resolved by name).
        payload_range: ``payload_kg`` as (low, high) kg.
        self_contact_stiffness: the penalty of ``self_contact`` (N/m²), or None (off).
        lag_gain: 1 − e^(−dt/τ), the first-order lag's step towards the command.
    """

    design: object = "octarm_v"
    planar: bool = True
    observation: str = "true"
    sensor_noise: object = "off"
    base_angle_deg: float = 90.0
    payload_kg: object = 0.0
    gravity: float = 9.81
    randomization: object = None
    action_mode: str = "absolute"
    delta_scale: float = 0.1
    n_backbone: int = 8
    observation_format: str = "flat"
    initial_pressure_fraction: float = 0.1
    solver_failure_penalty: float = 1.0
    max_solver_failures: int = 5
    model: str = "full"
    synthesize_sensors: bool | None = None
    actuation: str = "ideal"
    pressure_time_constant_s: float = 0.2
    step_dt_s: float = 0.1
    self_contact: object = False
    self_friction: float = 0.0
    render_mode: str | None = None
    render_size: int = 400
    arm: solver.designs.ArmDesign = field(init=False, repr=False)
    payload_range: tuple[float, float] = field(init=False, repr=False)
    self_contact_stiffness: float | None = field(init=False, repr=False)
    lag_gain: float = field(init=False, repr=False)

    def __post_init__(self):
        arm = _design(self.design)
        self._set(arm=arm)
        self._check_choices()
        self._check_counts()
        self._set(sensor_noise=_sensor_noise(self.sensor_noise), planar=bool(self.planar),
                  base_angle_deg=finite_number("base_angle_deg", self.base_angle_deg),
                  payload_range=value_range("payload_kg", self.payload_kg),
                  gravity=finite_number("gravity", self.gravity, 0.0))
        randomization = coerce_randomization(self.randomization)
        randomization.check(arm)
        self._set(randomization=randomization)
        self._check_fractions()
        self._check_actuation()
        self._set(self_contact_stiffness=_self_contact_stiffness(self.self_contact, arm,
                                                                 self.planar, self.model),
                  self_friction=check_friction("self_friction", self.self_friction))
        if self.self_friction > 0.0 and self.self_contact_stiffness is None:
            raise ValueError(f"self_friction = {self.self_friction} needs self_contact (the "
                             "friction acts where parts of the arm press on each other)")
        if isinstance(self.render_size, bool) or not isinstance(self.render_size, (int, np.integer)) \
                or not MIN_RENDER_SIZE <= self.render_size <= MAX_RENDER_SIZE:
            raise ValueError(f"render_size must be an integer in [{MIN_RENDER_SIZE}, {MAX_RENDER_SIZE}] px; "
                             f"got {self.render_size!r}")
        self._set(render_size=int(self.render_size))

    def _set(self, **values) -> None:
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def _check_choices(self) -> None:
        """The arguments that name one of a few choices."""
        if not isinstance(self.planar, (bool, np.bool_)):
            raise ValueError(f"planar must be True or False; got {self.planar!r}")
        for name, value, choices in (("observation", self.observation, ESTIMATORS),
                                     ("action_mode", self.action_mode, ACTION_MODES)):
            if value not in choices:
                raise ValueError(f"unknown {name} {value!r}; choose one of {', '.join(choices)}")
        if self.observation_format not in OBSERVATION_FORMATS:
            raise ValueError(f"unknown observation_format {self.observation_format!r}; choose one of "
                             f"{', '.join(OBSERVATION_FORMATS)}")
        if self.model not in solver.MODELS:
            raise ValueError(f"unknown model {self.model!r}; choose one of {', '.join(solver.MODELS)}")
        if self.render_mode is not None and self.render_mode not in RENDER_MODES:
            raise ValueError(f"unknown render_mode {self.render_mode!r}; choose one of "
                             f"{', '.join(RENDER_MODES)} or None")

    def _check_counts(self) -> None:
        n, failures = self.n_backbone, self.max_solver_failures
        if isinstance(n, bool) or int(n) != n or n < 2:
            raise ValueError(f"n_backbone must be an integer >= 2; got {n!r}")
        if isinstance(failures, bool) or int(failures) != failures or failures < 1:
            raise ValueError(f"max_solver_failures must be an integer >= 1; got {failures!r}")
        self._set(n_backbone=int(n), max_solver_failures=int(failures))

    def _check_fractions(self) -> None:
        """Action scaling, the initial pressures and the failure penalty."""
        delta_scale = finite_number("delta_scale", self.delta_scale, 0.0)
        if not 0.0 < delta_scale <= 1.0:
            raise ValueError(f"delta_scale must lie in (0, 1] (fraction of p_max per step); "
                             f"got {self.delta_scale}")
        initial = finite_number("initial_pressure_fraction", self.initial_pressure_fraction, 0.0)
        if initial > 1.0:
            raise ValueError(f"initial_pressure_fraction must lie in [0, 1]; got "
                             f"{self.initial_pressure_fraction}")
        self._set(delta_scale=delta_scale, initial_pressure_fraction=initial,
                  solver_failure_penalty=finite_number("solver_failure_penalty",
                                                       self.solver_failure_penalty, 0.0))

    def _check_actuation(self) -> None:
        if self.actuation not in ACTUATIONS:
            raise ValueError(f"unknown actuation {self.actuation!r}; choose one of {', '.join(ACTUATIONS)}")
        tau = finite_number("pressure_time_constant_s", self.pressure_time_constant_s, 0.0)
        dt = finite_number("step_dt_s", self.step_dt_s, 0.0)
        if tau <= 0 or dt <= 0:
            raise ValueError(f"pressure_time_constant_s and step_dt_s must be > 0 (s); got "
                             f"{self.pressure_time_constant_s}, {self.step_dt_s}")
        # First-order lag sampled every step: p ← p + (1 − e^(−dt/τ))·(p_command − p).
        self._set(pressure_time_constant_s=tau, step_dt_s=dt, lag_gain=-math.expm1(-dt / tau))
