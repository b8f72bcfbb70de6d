"""Wrap: curl the arm around a rigid disc (``SoftArm/OctArmWrap-v0``, ``SoftArm/CTWrap-v0``)."""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

import solver
from softarm_gym.envs.base import SoftArmEnv
from softarm_gym.envs.config import check_options, finite_number, value_range
from softarm_gym.envs.terms import WRAP_TERMS, WrapRule, wrap_measures, wrap_rewards
from softarm_gym.render import Cylinder
from solver import layout as L
from solver.scene import check_friction

__all__ = ["WrapEnv", "wrap_angle", "arm_half_thickness", "check_contact_stiffness",
           "resolve_contact_stiffness"]

_PLACEMENT_ATTEMPTS = 20


def arm_half_thickness(arm: solver.designs.ArmDesign) -> float:
    """Distance from the backbone to the outer surface of the distal section (m).

    The largest ``tube.radius + Ro`` over the tubes that span the last section: the disc the
    backbone is pressed against is the object grown by this much.
    """
    last = len(arm.sections) - 1
    return max(t.radius + t.material.outer_radius for t in arm.tubes if t.last_section >= last)


def check_contact_stiffness(value) -> None:
    """Validate a ``contact_stiffness`` argument: ``"tube"``, ``"rigid"`` or a number > 0 (N/m²)."""
    if isinstance(value, str) and value in ("tube", "rigid"):
        return
    finite_number("contact_stiffness", value, 0.0)
    if value <= 0:
        raise ValueError(f"contact_stiffness must be > 0 (N/m²), 'tube' or 'rigid'; got {value}")


def resolve_contact_stiffness(arm: solver.designs.ArmDesign, value) -> float:
    """The penalty stiffness (N/m²) of a ``contact_stiffness`` argument for ``arm``.

    ``"tube"``: the ring stiffness of the distal section's tubes (``TubeMaterial.ring_stiffness``,
    the arm's own compliance); ``"rigid"``: ``math.inf`` (hard contact); a number: itself.
    """
    check_contact_stiffness(value)
    if value == "tube":
        last = len(arm.sections) - 1
        return min(t.material.ring_stiffness for t in arm.tubes if t.last_section >= last)
    return math.inf if value == "rigid" else float(value)


def _axial_coordinates(positions: np.ndarray, center, axis) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates (x, y) of backbone samples about an object's centre, in the plane normal
    to its ``axis`` (3D; None: the x–y plane of planar samples)."""
    rel = np.asarray(positions, dtype=float) - np.asarray(center, dtype=float)
    if axis is None:
        return rel[:, 0], rel[:, 1]
    e1, e2 = _axial_basis(tuple(float(c) for c in axis))
    return rel @ e1, rel @ e2


@functools.lru_cache(maxsize=256)
def _axial_basis(axis: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal (e1, e2) (3,) spanning the plane normal to ``axis``, (e1, e2, axis)
    right-handed. Cached: an episode's object keeps its axis, and two ``np.cross`` calls
    per step were most of a 3D wrap step's reward (read-only arrays)."""
    a = np.asarray(axis) / np.linalg.norm(axis)
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    e1.flags.writeable = e2.flags.writeable = False
    return e1, e2


def wrap_angle(positions: np.ndarray, center, contact_radius: float, margin: float,
               axis=None) -> float:
    """Angular extent of the arm's contact around a disc centre, or a cylinder's axis (rad).

    The backbone samples within ``contact_radius + margin`` of the centre (in 3D: of the
    axis) are in contact; their polar angles about it (in 3D: in the plane normal to the
    axis), taken in arc-length order and unwrapped, span the wrap angle (max − min). A spiral
    that passes a point twice counts beyond 2π. The rule of
    :func:`softarm_gym.envs.terms.wrap_measures`, which the environments use.

    Args:
        positions: (N, 2) planar or (N, 3) spatial backbone samples, base to tip (m).
        center: (2,) disc centre, or (3,) a point of the cylinder's axis (m).
        contact_radius: disc radius for the backbone curve (m).
        margin: gap still counted as contact (m).
        axis: (3,) the cylinder's axis direction (spatial samples), None for a disc.

    Returns:
        The wrap angle (rad), 0 with fewer than two contact samples.
    """
    points, center = _planar_points(positions, center, axis)
    wrap, gap = np.empty(1), np.empty(1)
    wrap_measures(points, center, np.array([float(contact_radius)]), float(margin), wrap, gap)
    return float(wrap[0])


def _planar_points(positions: np.ndarray, center, axis) -> tuple[np.ndarray, np.ndarray]:
    """A batch of one for :mod:`softarm_gym.envs.terms`' wrap rules: the samples (1, N, 2)
    and the centre (1, 2) in the plane of the measure (3D: the coordinates about the axis,
    centred on it)."""
    if axis is None:
        return np.asarray(positions, dtype=float)[None], np.asarray(center, dtype=float).reshape(1, 2)
    x, y = _axial_coordinates(positions, center, axis)
    return np.column_stack([x, y])[None], np.zeros((1, 2))


class WrapEnv(SoftArmEnv):
    """Wrap a multi-section pneumatic soft arm around a rigid disc (planar, quasi-static, contact).

    ## Description

    The arm of :class:`~softarm_gym.envs.reach.ReachEnv` (same designs, mounting, sensing,
    estimators, action and stepping) with a rigid disc — the cross-section of an object to
    grasp — in the plane. Contact is the solver's penalty contact (``solver.Disc``): the
    backbone is pushed out of a disc of radius ``object_radius + h`` (h the distal section's
    half-thickness, :func:`arm_half_thickness`) with ``contact_stiffness`` N/m² per metre of
    penetration. The task is the thesis's grasp by wrapping (§3.1, Fig. 3.2).

    ## Action Space

    As ReachEnv: ``Box(-1, 1, (n_inputs,), float32)`` normalised channel pressures,
    p = (a + 1)/2 · p_max (``absolute``) or increments of ``delta_scale`` · p_max (``delta``);
    p_max OctArm V 100 psi, OctArm VI 90 psi, CT 70 psi. Out-of-range values are clipped; NaN or
    inf raises ``ValueError`` naming the channel.

    ## Observation Space

    The ReachEnv blocks ``tip`` (2, m), ``section_ends`` (4·n_sections: x, y, cos θ, sin θ),
    ``backbone`` (2·n_backbone, m), ``pressures`` (n_inputs, 2p/p_max − 1), then ``goal`` (3):
    the disc centre (x, y) and its contact radius object_radius + h (m). Flat ``Box`` or
    ``Dict`` (``observation_format``); ``"goal"`` is refused (``ValueError``): the wrap
    reward has no goal point that hindsight relabelling could substitute.

    ## Rewards

    ``reward = reward_wrap + reward_approach + reward_penetration + reward_control +
    reward_success + reward_solver`` (each in ``info``), from the true equilibrium:
    ``reward_wrap = wrap_weight · min(wrap, 2π)/2π`` with ``wrap`` the wrap angle — the angular
    extent, about the disc centre, of the backbone within ``contact_margin`` of the contact
    circle (:func:`wrap_angle`); ``reward_approach = −approach_weight · gap``, gap the
    smallest distance from the backbone to the contact circle (m, 0 when touching);
    ``reward_penetration = −penetration_weight · max penetration / penetration_tolerance``;
    ``reward_control = −control_weight · mean((p/p_max)²)``; ``reward_success =
    success_bonus`` on success; ``reward_solver = −solver_failure_penalty`` on an unconverged step.
    Success: wrap ≥ ``success_wrap_deg`` (default 270°) with the deepest penetration below
    ``penetration_tolerance`` (default 5 mm).

    ## Starting State

    Per episode: the simulated arm, payload and start pressures as ReachEnv; an object radius
    uniform in ``object_radius``; a side (clockwise or counter-clockwise curl) at random; the
    disc is then placed within reach — tangent to the start backbone, ``placement_gap`` away
    from it on the chosen side, where the remaining reference length is
    ``placement_wrap_deg``/360 · 2π(object_radius + h) (clamped to the arm), so the distal
    part of the arm can curl around it. Placements overlapping the start backbone are redrawn.
    ``options={"object": (x, y, object_radius)}`` fixes the object.

    ## Episode End

    Truncated at ``max_episode_steps`` (registered default 200) or after
    ``max_solver_failures`` consecutive unconverged steps (the last converged state is kept,
    ``info["converged"] = False``). Terminated on success only with ``terminate_on_success=True``.

    ## Arguments

    All ReachEnv arguments except the reach-reward ones (``design``, ``planar`` (False: the 3D wrap
    round a cylinder, docs/environments.md "3D wrap"),
    ``observation``, ``sensor_noise``, ``base_angle_deg`` (default 0 here: hanging), ``payload_kg``,
    ``gravity``, ``randomization``,
    ``action_mode``, ``delta_scale``, ``n_backbone``, ``observation_format``,
    ``initial_pressure_fraction``, ``solver_failure_penalty``, ``max_solver_failures``,
    ``model``, ``actuation``, ``pressure_time_constant_s``, ``step_dt_s``, ``self_contact``,
    ``self_friction`` (0: the Coulomb coefficient μ ≥ 0 between parts of the arm in
    self-contact, with ``self_contact``; docs/design.md §9.1 — ``friction`` below is the arm
    on the object's and does not set it), ``render_mode``,
    ``render_size``), plus: ``object_radius`` (a number or
    ``(low, high)`` range, m; default (0.09, 0.11)), ``contact_stiffness`` (``"tube"``: the
    ring stiffness of the distal section's tubes, ``TubeMaterial.ring_stiffness``, 9.8e4 N/m²
    for OctArm V and CT — the arm's own compliance, see docs/design.md §9; a number in N/m²;
    or ``"rigid"`` for hard contact), ``friction`` (the Coulomb coefficient μ ≥ 0 between
    the arm and the object, 0: frictionless; docs/design.md §9),
    ``contact_margin`` (5 mm), ``placement_gap`` (1 cm), ``placement_wrap_deg`` (300),
    ``wrap_weight`` (1), ``approach_weight`` (1), ``penetration_weight`` (0.1),
    ``penetration_tolerance`` (5 mm), ``control_weight`` (0.01), ``success_bonus`` (1),
    ``success_wrap_deg`` (270; ``SoftArm/CTWrap-v0`` registers 90, see the docs),
    ``terminate_on_success`` (False).

    ## Info

    ReachEnv's solver/sensor keys (``tip_true``, ``tip_estimated``, ``estimation_error``,
    ``sensors``, ``converged``, ``solver``, ``solver_failures``, ``pressures_pa``,
    ``payload_kg``, ``is_success``), plus ``wrap_angle_deg``, ``penetration`` (m, deepest),
    ``gap`` (m), ``object_center``, ``object_radius``, ``contact_radius`` and the ``reward_*`` terms.

    ## Vector Environments

    ``gym.make_vec(id, N, vectorization_mode="vector_entry_point")`` on the planar IDs gives
    :class:`softarm_gym.vector.BatchedWrapVectorEnv`: N arms stepped by one contact
    :class:`solver.BatchStepper` call, each with its episode's disc, copy i bit for bit this
    env seeded s + i (resets by one WrapEnv per copy). It refuses ``planar=False``,
    ``contact_stiffness="rigid"`` and what the batched envs refuse (docs/environments.md,
    "Batched environment").

    ## Version History

    * v0: initial version (OctArm V disc 9–11 cm: beyond the arm's curl on most seeds;
      CT 15–20 cm). Kept; ``gym.make`` notes that v1 exists.
    * v1: object radius calibrated so that the planner wraps it (OctArm V 11–12.5 cm, CT
      11–13 cm; docs/environments.md, "Wrap calibration"); otherwise equal to v0. Kept;
      ``gym.make`` notes that v2 exists.
    * v2 (recommended): sequential and physically possible — ``self_contact=True`` (the arm
      presses on itself with its tubes' ring stiffness instead of passing its tip through
      its base section) and delta actions (``action_mode="delta"``, ``delta_scale=0.1``: at
      most 10 % of p_max per channel per step, ≥ 10 steps from rest to a full curl); v1's
      objects and success rule otherwise (docs/environments.md, "Sequential and
      self-contacting versions").

    3D (``SoftArm/OctArmWrap3D-*``, ``planar=False``):

    * v0: frictionless cylinder, absolute actions, success at 75° (the hanging arm's curl falls
      sideways past about a quarter turn). Kept; ``gym.make`` notes that v1 exists.
    * v1 (recommended): rubber on the cylinder, ``friction=0.7`` (Coulomb μ; rubber on common
      objects is 0.5–1), and sequential (``action_mode="delta"``, ``delta_scale=0.1``); no
      self-contact, which does not exist in 3D. Friction does not lift the ceiling: the curl
      still falls sideways under the arm's own weight (at a quarter of g it wraps 285–322° on
      7 of 8 seeds), so success stays at 75° (docs/environments.md, "3D wrap with friction
      (v1)").
    """

    def __init__(self, design="octarm_v", *, object_radius=(0.09, 0.11),
                 contact_stiffness="tube", friction: float = 0.0, contact_margin: float = 0.005,
                 placement_gap: float = 0.01,
                 placement_wrap_deg: float = 300.0, wrap_weight: float = 1.0,
                 approach_weight: float = 1.0, penetration_weight: float = 0.1,
                 penetration_tolerance: float = 0.005, control_weight: float = 0.01,
                 success_bonus: float = 1.0, success_wrap_deg: float = 270.0,
                 terminate_on_success: bool = False, **kwargs):
        self.object_radius_range = value_range("object_radius", object_radius)
        if self.object_radius_range[0] <= 0:
            raise ValueError(f"object_radius must be > 0 (m); got {object_radius!r}")
        check_contact_stiffness(contact_stiffness)
        self.friction = check_friction("friction", friction)
        self.contact_margin = finite_number("contact_margin", contact_margin, 0.0)
        self.placement_gap = finite_number("placement_gap", placement_gap, 0.0)
        self.placement_wrap_deg = finite_number("placement_wrap_deg", placement_wrap_deg, 0.0)
        self.wrap_weight = finite_number("wrap_weight", wrap_weight, 0.0)
        self.approach_weight = finite_number("approach_weight", approach_weight, 0.0)
        self.penetration_weight = finite_number("penetration_weight", penetration_weight, 0.0)
        self.penetration_tolerance = finite_number("penetration_tolerance", penetration_tolerance, 0.0)
        if self.penetration_tolerance <= 0:
            raise ValueError(f"penetration_tolerance must be > 0 (m); got {penetration_tolerance}")
        self.control_weight = finite_number("control_weight", control_weight, 0.0)
        self.success_bonus = finite_number("success_bonus", success_bonus, 0.0)
        self.success_wrap_deg = finite_number("success_wrap_deg", success_wrap_deg, 0.0)
        self.terminate_on_success = bool(terminate_on_success)
        self._object_radius = self.object_radius_range[0]
        self._contact_radius = self.object_radius_range[0]
        self.touch_arc_length = None
        kwargs.setdefault("base_angle_deg", 0.0)
        super().__init__(design, **kwargs)
        self._center = np.zeros(self.dim)
        self._axis = None if self.planar else np.array([0.0, 0.0, 1.0])
        if self.object_radius_range[1] >= self.arm.length:
            # Placement puts the disc tangent to the arm and within reach; a disc as large as
            # the arm is long cannot be wrapped (and cannot be placed clear of the start).
            raise ValueError(f"object_radius {self.object_radius_range[1]} m must be smaller than "
                             f"the arm's length {self.arm.length:.3f} m")
        self.half_thickness = arm_half_thickness(self.arm)
        self.contact_stiffness = resolve_contact_stiffness(self.arm, contact_stiffness)
        # One-row buffers of the batch-first reward (softarm_gym.envs.terms.wrap_rewards).
        self._terms = np.zeros((1, len(WRAP_TERMS)))
        # wrap (deg), gap, success; penetration, converged, contact radius
        self._measures = (np.zeros(1), np.zeros(1), np.zeros(1, dtype=np.bool_), np.zeros(1),
                          np.zeros(1, dtype=np.bool_), np.zeros(1))

    @property
    def wrap_rule(self) -> WrapRule:
        """The wrap measures' and rewards' settings (:class:`~softarm_gym.envs.terms.WrapRule`),
        from this env's arguments."""
        return WrapRule(self.contact_margin, self.wrap_weight, self.approach_weight,
                        self.penetration_weight, self.penetration_tolerance, self.control_weight,
                        self.success_bonus, self.success_wrap_deg, self.solver_failure_penalty)

    def _goal_bounds(self):
        r = self.reach
        if self.planar:
            return np.array([-r, -r, 0.0]), np.array([r, r, r])
        return np.array([-r, -r, -r, -1.0, -1.0, -1.0, 0.0]), np.array([r, r, r, 1.0, 1.0, 1.0, r])

    def _reset_task(self, options, start):
        options = check_options(options, ("object",))
        if "object" in options:
            obj = np.asarray(options["object"], dtype=float)
            size = 3 if self.planar else 7
            if obj.shape != (size,) or not np.all(np.isfinite(obj)) or obj[-1] <= 0 \
                    or np.any(np.abs(obj[:self.dim]) > self.reach) or obj[-1] > self.reach \
                    or (not self.planar and not np.linalg.norm(obj[3:6]) > 0):
                what = "(x, y, object_radius)" if self.planar else \
                    "(x, y, z, axis x, axis y, axis z, object_radius) with a nonzero axis"
                raise ValueError(f"options['object'] must be {what} in m with radius > 0, "
                                 f"centre and radius within ±{self.reach:.3f} m (twice the arm's length); "
                                 f"got {options['object']!r}")
            self.touch_arc_length = None
            axis = None if self.planar else obj[3:6] / np.linalg.norm(obj[3:6])
            placed = self._place(obj[:self.dim], float(obj[-1]), start, axis)
            if placed is None:
                raise RuntimeError(f"the start state has no converged equilibrium with the object "
                                   f"{tuple(obj)} of options['object']")
            return placed
        rng = self.np_random
        positions, s = start.positions, start.s
        for _ in range(_PLACEMENT_ATTEMPTS):
            radius = float(rng.uniform(*self.object_radius_range))
            contact = radius + self.half_thickness
            k = int(np.searchsorted(s, max(s[-1] - math.radians(self.placement_wrap_deg) * contact, 0.0)))
            axis = None
            if self.planar:
                side = 1.0 if rng.uniform() < 0.5 else -1.0
                normal = side * np.array([-math.sin(start.angles[k]), math.cos(start.angles[k])])
            else:
                # A side at a random heading about the arm; the axis normal to the curl towards it.
                heading = rng.uniform(0.0, 2.0 * math.pi)
                frame = start.orientations[k]
                normal = math.cos(heading) * frame[:, 0] + math.sin(heading) * frame[:, 1]
                axis = np.cross(frame[:, 2], normal)
            center = positions[k] + (contact + self.placement_gap) * normal
            clearance = np.hypot(*_axial_coordinates(positions, center, axis)).min() - contact
            if clearance >= 0.5 * self.placement_gap and np.all(np.abs(center) <= self.reach):
                placed = self._place(center, radius, start, axis)
                if placed is not None:
                    self.touch_arc_length = float(s[k])
                    return placed
        raise RuntimeError(f"no disc placement for {self.arm.name} clear of the start backbone in "
                           f"{_PLACEMENT_ATTEMPTS} draws (object_radius {self.object_radius_range} m)")

    def _place(self, center, radius: float, start: solver.Equilibrium, axis=None):
        """The scene with the object (a disc; in 3D a cylinder along ``axis``) and the start
        state in it, or None if that does not converge."""
        contact = radius + self.half_thickness
        goal = np.concatenate([center, [] if axis is None else axis, [contact]])
        scene = replace(self._scene, obstacles=(self.object_of_goal(goal),))
        # From the start state itself: the object is placed clear of it, so the state stands.
        eq = solver.solve(self._sim_arm, start.pressures, scene, model=self.model,
                          planar=self.planar, warm_start=start)
        if not eq.converged:
            return None
        self._center = np.array(center, dtype=float)
        self._axis = None if axis is None else np.array(axis, dtype=float)
        self._object_radius = radius
        self._contact_radius = contact
        return scene, eq

    def object_of_goal(self, goal: np.ndarray) -> solver.Disc | solver.Cylinder:
        """The solver's object for a goal block (planar (x, y, contact radius): a disc; 3D
        (point (3,), axis (3,), contact radius): a cylinder), at the env's contact stiffness."""
        if self.planar:
            return solver.Disc(center=(float(goal[0]), float(goal[1])), radius=float(goal[2]),
                               stiffness=self.contact_stiffness, friction=self.friction)
        return solver.Cylinder(point=tuple(goal[:3]), axis=tuple(goal[3:6]), radius=float(goal[6]),
                               stiffness=self.contact_stiffness, friction=self.friction)

    def _fill_goal(self, obs):
        out = obs[self._slices["goal"]]
        out[:self.dim] = self._center
        if not self.planar:
            out[3:6] = self._axis
        out[-1] = self._contact_radius

    def _task_reward(self, converged):
        stepper = self._stepper
        if self.planar and stepper.record is not None:
            # The lean path: the backbone and contact straight from the solver's record.
            points = stepper.record[None, :, L.X:L.Y + 1]
            center = self._center[None]
            penetration = stepper.contact_measures()[0]
        else:
            eq = self._eq
            points, center = _planar_points(eq.positions, self._center, self._axis)
            penetration = float(eq.penetration.max()) if eq.penetration.size else 0.0
        terms, success, info = self._wrap_row(points, center, self._contact_radius, penetration,
                                              self._fraction, converged)
        info.update({"object_center": self._center.copy(), "object_radius": self._object_radius,
                     "contact_radius": self._contact_radius})
        if not self.planar:
            info["object_axis"] = self._axis.copy()
        return terms, success, info

    def wrap_terms(self, positions: np.ndarray, penetration: float, fraction: np.ndarray,
                   center, contact_radius: float, axis=None) -> tuple[dict[str, float], bool, dict]:
        """The task's reward terms (all but ``reward_solver``), success and measures of a
        backbone: the rule of the env card's Rewards, for this env's weights
        (:func:`softarm_gym.envs.terms.wrap_rewards`).

        A pure function of its arguments (planners evaluate it on model rollouts).

        Args:
            positions: (N, 2|3) backbone samples (m). penetration: deepest penetration (m).
            fraction: (n_inputs,) pressures / p_max. center: (2,) disc centre or (3,) a
                point of the cylinder's axis (m).
            contact_radius: object radius + the arm's half-thickness (m).
            axis: (3,) the cylinder's axis (3D), None for a disc.

        Returns:
            (terms, success, {"wrap_angle_deg", "penetration", "gap"}).
        """
        points, center = _planar_points(positions, center, axis)
        terms, success, info = self._wrap_row(points, center, contact_radius, penetration,
                                              np.asarray(fraction, dtype=float), True)
        del terms[WRAP_TERMS[-1]]
        return terms, success, info

    def _wrap_row(self, points, center, contact_radius, penetration, fraction, converged):
        """:func:`~softarm_gym.envs.terms.wrap_rewards` of a batch of one: (terms, success,
        measures) as dicts."""
        wrap_deg, gap, success, pen, ok, radius = self._measures
        pen[0] = penetration
        ok[0] = converged
        radius[0] = contact_radius
        wrap_rewards(points, center, radius, pen, fraction.reshape(1, -1), ok, self.wrap_rule,
                     self._terms, wrap_deg, gap, success)
        terms = dict(zip(WRAP_TERMS, self._terms[0].tolist()))
        return terms, bool(success[0]), {"wrap_angle_deg": wrap_deg.item(), "penetration": float(penetration),
                                         "gap": gap.item()}

    def _terminated(self, success):
        return self.terminate_on_success and success

    def _task_artists(self):
        if self.planar:
            return {"disc": (self._center, self._object_radius)}
        return {"objects": (Cylinder(center=tuple(self._center), axis=tuple(self._axis),
                                     radius=self._object_radius, length=2.0 * self.arm.length),)}

    def _caption(self):
        wrap = wrap_angle(self._eq.positions, self._center, self._contact_radius, self.contact_margin,
                          self._axis)
        return super()._caption() + f"\nwrap {math.degrees(wrap):.0f} deg"
