"""Grasp: wrap a free object and lift it out of its support (``SoftArm/OctArmGrasp-v1``, ``-v0``)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

import solver
from softarm_gym.envs.config import check_options, finite_number, value_range
from softarm_gym.envs.wrap import WrapEnv
from solver.grasp import CLAMP_GAP, FreeObject, Grasp, Settler, grasp_margin

__all__ = ["GraspEnv"]


class GraspEnv(WrapEnv):
    """Grasp a free cylinder with a multi-section pneumatic soft arm and lift it (planar,
    quasi-static, contact).

    ## Description

    The wrap task of :class:`~softarm_gym.envs.wrap.WrapEnv` with a free object: a rigid
    cylinder of mass m whose ends rest in two forks open upwards (``fork_depth`` deep), the
    arm wrapping its middle. The object's pose is part of the quasi-static equilibrium
    (:func:`solver.grasp.settle`): the arm's contact forces, its weight and the forks'
    reaction balance. The forks hold it against sideways pushes until it is lifted out of
    them; the arm's base clamp stops it where a tight wrap pulls it up to the base. The task
    is the thesis's whole-arm grasp with its stability requirement (§6.1): lift the object
    out of its support and hold it there, in equilibrium, by the arm alone. Contact is
    penalty contact, frictionless by default (``friction`` = 0; v1 registers μ = 0.7, Coulomb
    friction between the arm and the object: docs/design.md §9.1, §14).

    ## Action Space

    As WrapEnv: ``Box(-1, 1, (n_inputs,), float32)`` normalised channel pressures,
    p = (a + 1)/2 · p_max (``absolute``, v0's default) or increments of
    ``delta_scale`` · p_max (``delta``, v1's default, ``delta_scale`` = 0.1). Out-of-range
    values are clipped; NaN or inf raises ``ValueError`` naming the channel.

    ## Observation Space

    The ReachEnv blocks ``tip`` (2, m), ``section_ends`` (4·n_sections), ``backbone``
    (2·n_backbone, m), ``pressures`` (n_inputs, 2p/p_max − 1), then ``goal`` (5): the object's
    centre (x, y, m; it moves), its contact radius object_radius + h (m) and its seat (x, y,
    m): the centre's place in the forks. Flat ``Box`` or ``Dict``; ``"goal"`` is refused.

    ## Rewards

    ``reward = reward_wrap + reward_approach + reward_penetration + reward_control +
    reward_lift + reward_margin + reward_success + reward_solver`` (each in ``info``): the wrap
    terms of WrapEnv (``wrap_weight`` default 0.5 here), plus ``reward_lift = lift_weight ·
    clip(lift/success_lift, 0, 1)`` with lift the centre's height above its seat (m), and
    ``reward_margin = margin_weight · min(margin/(m g), 1)``, the grasp margin in units of the
    object's weight (0 unless ``margin_weight`` > 0, which needs ``margin_directions`` > 0).
    ``reward_success = success_bonus`` on success: the object *held* — in equilibrium clear of
    the forks and of the base clamp, carried by the arm alone — at least ``success_lift``
    above its seat, with the deepest penetration below ``penetration_tolerance``.

    ## Starting State

    As WrapEnv (arm, start pressures, object radius, side, placement tangent to the start
    backbone); the placement is the object's seat, where it rests in its forks under its
    weight. The object's mass is drawn uniformly from ``object_mass_kg``.
    ``options={"object": (x, y, object_radius)}`` fixes the seat and radius.

    ## Episode End

    Truncated at ``max_episode_steps`` (registered default 100) or after
    ``max_solver_failures`` consecutive unconverged steps: a step whose path the solver could
    not follow to its end keeps the previous state (arm and object). Terminated on success
    only with ``terminate_on_success=True``.

    ## Arguments

    All WrapEnv arguments (``contact_stiffness`` must be a number or ``"tube"``: the object's
    pose is solved against a penalty law; ``model`` ``"full"`` or ``"unshearable"``), plus:
    ``object_mass_kg`` (a number or ``(low, high)`` range, kg; default (0.2, 0.4)),
    ``fork_depth`` (m, 0.02), ``success_lift`` (m, 0.03; at least ``fork_depth``),
    ``lift_weight`` (1), ``margin_directions`` (directions of the grasp margin, 4; 0 skips
    it; v1 registers 0), ``margin_weight`` (0).

    ## Info

    WrapEnv's keys (``wrap_angle_deg``, ``penetration``, ``gap``, ``object_center``, …), plus
    ``held`` (bool), ``lift`` (m), ``object_mass_kg``, ``arm_force`` (N, on the object),
    ``support_force`` (N, forks and clamp), ``object_stable`` (the object sits in a potential
    well and the arm's equilibrium is stable) and, with ``margin_directions`` > 0,
    ``grasp_margin_n``: the smallest disturbance force, over ``margin_directions`` planar
    directions from straight up, that the held grasp resists before the object is no longer
    held (:func:`solver.grasp.grasp_margin`; 0 when not held), and ``grasp_margins_n``, per
    direction. A margin costs tens of contact solves per direction: it is worked out only on
    held steps, once per state; with ``margin_directions=0`` it is not, and the two keys are
    absent.

    ## Version History

    * v0: initial version (the OctArmWrap-v1 geometry, 0.2–0.4 kg, 2 cm forks; frictionless,
      absolute actions, no self-contact). Kept; ``gym.make`` notes that v1 exists.
    * v1 (recommended): sequential, self-contacting and frictional — ``self_contact=True``
      (the arm presses on itself instead of closing a wrap through its own base), delta
      actions (``action_mode="delta"``, ``delta_scale=0.1``: at most 10 % of p_max per channel
      per step) and ``friction=0.7`` (Coulomb μ between the arm's rubber and the object; rubber
      on common dry objects lies around 0.5–1). v0's objects, forks and success rule otherwise
      (docs/environments.md, "Grasp"). Its grasp margin is off by default since 2026-12-06
      (``margin_directions=0``: no ``grasp_margin_n`` in ``info``; pass ``margin_directions=4``
      for it): an info field that cost seconds per held state, paid at every step by a policy
      that holds the object. Rewards, observations and dynamics are v1's as before.
    """

    def __init__(self, design="octarm_v", *, object_mass_kg=(0.2, 0.4), fork_depth: float = 0.02,
                 success_lift: float = 0.03, lift_weight: float = 1.0, margin_directions: int = 4,
                 margin_weight: float = 0.0, wrap_weight: float = 0.5, **kwargs):
        if kwargs.get("planar", True) is not True:
            raise ValueError("GraspEnv is planar only (the free object's equilibrium is planar); "
                             "use planar=True")
        self.object_mass_range = value_range("object_mass_kg", object_mass_kg)
        if self.object_mass_range[0] <= 0:
            raise ValueError(f"object_mass_kg must be > 0 (kg); got {object_mass_kg!r}")
        self.fork_depth = finite_number("fork_depth", fork_depth, 0.0)
        if self.fork_depth <= 0:
            raise ValueError(f"fork_depth must be > 0 (m); got {fork_depth!r}")
        self.success_lift = finite_number("success_lift", success_lift, 0.0)
        if self.success_lift < self.fork_depth:
            raise ValueError(f"success_lift ({success_lift} m) must be at least fork_depth "
                             f"({fork_depth} m): the object is held only once out of its forks")
        self.lift_weight = finite_number("lift_weight", lift_weight, 0.0)
        if isinstance(margin_directions, bool) or int(margin_directions) != margin_directions \
                or margin_directions < 0:
            raise ValueError(f"margin_directions must be an integer >= 0; got {margin_directions!r}")
        self.margin_directions = int(margin_directions)
        self.margin_weight = finite_number("margin_weight", margin_weight, 0.0)
        if self.margin_weight > 0 and self.margin_directions == 0:
            raise ValueError("margin_weight > 0 needs margin_directions > 0 (the margin is its reward)")
        if kwargs.get("contact_stiffness") == "rigid":
            raise ValueError("GraspEnv needs penalty contact (contact_stiffness 'tube' or a number): "
                             "the object's pose is solved against the penalty law")
        if kwargs.get("model", "full") == "constant_curvature":
            raise ValueError("GraspEnv needs model 'full' or 'unshearable': the constant-curvature "
                             "model has no contact")
        self._object = None
        self._grasp = None
        self._settler = None
        self._margin = (None, math.nan, np.zeros(0))
        super().__init__(design, wrap_weight=wrap_weight, **kwargs)

    @property
    def _seat(self) -> np.ndarray:
        """(2,) the object's seat (m)."""
        return np.array(self._object.seat)

    def _goal_bounds(self):
        r = self.reach
        return np.array([-r, -r, 0.0, -r, -r]), np.array([r, r, r, r, r])

    def _place(self, center, radius: float, start: solver.Equilibrium, axis=None):
        """The scene with the object resting in its forks at ``center`` and the start state, or
        None if that does not converge (planar: ``axis`` is None)."""
        obj = FreeObject(radius=radius + self.half_thickness, mass_kg=self._mass,
                         seat=(float(center[0]), float(center[1])), stiffness=self.contact_stiffness,
                         fork_depth=self.fork_depth, friction=self.friction)
        free = replace(self._scene, obstacles=())
        if math.hypot(*obj.seat) <= obj.radius + CLAMP_GAP:
            return None  # seated against the arm's base clamp
        settler = Settler(self._sim_arm, free, obj, model=self.model)
        # From the start state itself: the object is placed clear of it.
        grasp = settler.settle(start.pressures, center=obj.seat, warm_start=start)
        if not grasp.converged:
            return None
        self._object, self._grasp, self._settler = obj, grasp, settler
        self._center = grasp.center.copy()
        self._object_radius = radius
        self._contact_radius = obj.radius
        self._margin = (None, math.nan, np.zeros(0))
        return grasp.arm.scene, grasp.arm

    def _reset_task(self, options, start):
        options = check_options(options, ("object",))
        rng = self.np_random
        self._mass = float(rng.uniform(*self.object_mass_range)) \
            if self.object_mass_range[1] > self.object_mass_range[0] else self.object_mass_range[0]
        return super()._reset_task(options, start)

    def _advance(self, pressures):
        """Arm and object to ``pressures`` together (:func:`solver.grasp.settle`); an
        unconverged step keeps both where they were. Pressures equal to the current ones (a
        hold, or delta actions pushing against p_max or 0) move nothing: the state stands, no
        solve (settling from it returns that state to round-off: tests/envs/test_grasp.py)."""
        g = self._grasp
        if np.array_equal(pressures, g.arm.pressures):
            return solver.StepReport(True, g.stable, False, 0, g.arm.residual), True
        g = self._settler.settle(pressures, center=g.center, warm_start=g.arm)
        report = solver.StepReport(g.converged, g.stable, g.arm.snapped or g.snapped, g.solves,
                                   g.arm.residual if g.converged else g.residual)
        if not g.converged:
            return report, False
        self._grasp = g
        self._center = g.center.copy()
        self._stepper.adopt_moved(g.arm)
        return report, True

    def _fill_goal(self, obs):
        out = obs[self._slices["goal"]]
        out[:2] = self._center
        out[2] = self._contact_radius
        out[3:5] = self._seat

    def _grasp_margin(self) -> tuple[float, np.ndarray]:
        """The current grasp's margin (N) and per-direction margins, worked out once per state
        (pressures and object centre)."""
        g = self._grasp
        if self.margin_directions == 0:
            return math.nan, np.zeros(0)
        if not g.held:
            return 0.0, np.zeros(self.margin_directions)
        # Holding the pressures returns the same state: its margin is not worked out again.
        key = (g.arm.pressures.tobytes(), g.center.tobytes())
        if self._margin[0] != key:
            margin, per = grasp_margin(g, self._object, directions=self.margin_directions)
            self._margin = (key, margin, per)
        return self._margin[1], self._margin[2]

    def _task_reward(self, converged):
        g = self._grasp
        margin, per = self._grasp_margin()
        terms, success, info = self.grasp_terms(g, self._object, self._fraction, margin)
        terms["reward_solver"] = self._solver_term(converged)
        info.update({"object_center": g.center.copy(), "object_radius": self._object_radius,
                     "contact_radius": self._contact_radius, "object_mass_kg": self._object.mass_kg,
                     "held": g.held, "lift": g.lift, "arm_force": g.arm_force.copy(),
                     "support_force": g.support_force.copy(), "object_stable": g.stable})
        if self.margin_directions:
            info.update({"grasp_margin_n": margin, "grasp_margins_n": per.copy()})
        return terms, success, info

    def grasp_terms(self, grasp: Grasp, obj: FreeObject, fraction: np.ndarray,
                    margin: float = math.nan) -> tuple[dict[str, float], bool, dict]:
        """The task's reward terms (all but ``reward_solver``), success and the wrap measures of
        a grasp state: the rule of the env card's Rewards, for this env's weights.

        A pure function of its arguments (planners evaluate it on model rollouts).

        Args:
            grasp: arm and object in equilibrium (:func:`solver.grasp.settle`).
            obj: the object (its contact radius and mass).
            fraction: (n_inputs,) pressures / p_max.
            margin: the grasp margin (N), read only when ``margin_weight`` > 0.

        Returns:
            (terms, success, {"wrap_angle_deg", "penetration", "gap"}).
        """
        eq = grasp.arm
        penetration = float(eq.penetration.max()) if eq.penetration.size else 0.0
        terms, _, info = self.wrap_terms(eq.positions, penetration, fraction, grasp.center, obj.radius)
        success = bool(grasp.held and grasp.lift >= self.success_lift
                       and penetration <= self.penetration_tolerance)
        terms["reward_success"] = self.success_bonus if success else 0.0
        terms["reward_lift"] = self.lift_weight * min(max(grasp.lift / self.success_lift, 0.0), 1.0)
        weight = obj.mass_kg * self._scene.gravity
        terms["reward_margin"] = self.margin_weight * min(margin / weight, 1.0) \
            if self.margin_weight > 0 else 0.0
        return terms, success, info

    def _caption(self):
        g = self._grasp
        return super()._caption() + f", lift {1000 * g.lift:.0f} mm" + (" (held)" if g.held else "")
