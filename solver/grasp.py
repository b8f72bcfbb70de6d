"""A free rigid object held by the arm: its pose joins the quasi-static equilibrium.

The object is a rigid cylinder whose axis is normal to the arm's plane (a disc in the plane),
with mass, resting on a support until the arm lifts it. The arm touches it by the solver's
penalty contact (:class:`solver.Disc`), frictionless or with Coulomb friction
(``FreeObject.friction``: the object then also turns, and the friction's moment about its
axis must balance too); the object touches its support — two
forks open upwards (or V-blocks) under the cylinder's ends, where the arm, which wraps the
cylinder's middle, never reaches. Equilibrium of the object (docs/design.md §14):

    G(c) = F_arm(c) + W + F_ext + R(c) = 0,

with c the object's centre, F_arm the force of the arm on it (the contact forces' resultant,
read off the arm's global balance: F_arm = D − n(0), D the arm's dead loads and n(0) the
internal force at the base), W = (0, −m g) its weight, F_ext a disturbance and R the
support's penalty reaction. With friction the pose is (c, ψ), ψ its turn, and the arm's
moment on it about its axis, −Σ (r − c) × F over the friction impulses F at the contact
samples r (the normal forces pass through the axis), must vanish too: the supports are
frictionless, so it turns until it does. The arm is in equilibrium with the disc at c (a
contact solve; the samples' anchors turned with the object); the pose is found by Newton
with a finite-difference Jacobian, updated by Broyden steps and backtracking. The object is
*held* when it is in equilibrium clear of its support.

``grasp_margin`` is the thesis's stability requirement for a whole-arm grasp (§6.1): the
smallest disturbance force, over planar directions, that the grasp resists before the held
equilibrium is lost (no equilibrium nearby, or the object pushed back onto its support),
found per direction by continuation in the force's magnitude and bisection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from solver import layout as L
from solver.designs import ArmDesign
from solver.inputs import check_request, checked_pressures
from solver.kernels.homotopy import halved
from solver.paths.dispatch import dispatch
from solver.paths.friction import turn_anchors
from solver.paths.lean_contact import ContactRows, lean_contact_reason
from solver.problem import Problem, context, pack
from solver.results import Equilibrium
from solver.scene import MAX_EXTENT, Disc, Scene, check_friction
from solver.settings import DEFAULT_SETTINGS, MODELS, Settings
from solver.threads import CopyPool

__all__ = ["FreeObject", "Grasp", "Settler", "settle", "grasp_margin", "SUPPORTS"]

SUPPORTS = ("fork", "v_blocks")

# Newton on the object's pose: iterations, and the largest move per iteration as a fraction of
# the contact radius (the arm's contact solve is warm-started from the last pose, which a long
# move would make a jump).
MAX_ITER = 20
MAX_MOVE = 0.1
BACKTRACKS = 4
# The object's stiffness counts as positive definite (Newton's step) when its smallest
# eigenvalue exceeds this fraction of its largest (with friction after Jacobi scaling:
# _definite); below, the step is shifted (see _newton).
SHIFT = 1e-3
# Finite-difference step of the pose Jacobian (m), relative to the contact radius: far above
# the contact solve's own noise (its Newton tolerance), far below the contact decay length.
FD_STEP = 1e-3
# Force tolerance (N) of the object's balance: relative to the largest force acting on it.
FORCE_TOL = 1e-6
# Smallest pressure substep of :func:`settle`, as a fraction of the step.
MIN_SUBSTEP = 1.0 / 64.0
# Contact solves one call of :func:`settle` may spend before it reports the step unconverged
# (a wrap that snaps shut round a free object can cost seconds per solve).
MAX_SOLVES = 300

# Fraction of a fork's depth, at its top, over which its walls' hold fades (a chamfered rim).
RIM = 0.25
# Clearance (m) the base clamp keeps between the object's contact circle and the arm's base
# (so that its penalty's give never lets the disc cover the base: 75 N to close it).
CLAMP_GAP = 1e-3


class _Exhausted(Exception):
    """The contact-solve budget of one :func:`settle` call ran out."""


@dataclass(frozen=True)
class FreeObject:
    """A rigid cylinder (a disc in the arm's plane) the arm can grasp and lift.

    Attributes:
        radius: contact radius for the backbone curve (m): the object's radius plus the arm's
            half-thickness, as for :class:`solver.Disc`.
        mass_kg: the object's mass (kg).
        seat: (x, y) of the centre when the object rests on its support (m).
        stiffness: penalty k of the arm–object contact (N/m², finite: see :class:`solver.Disc`).
        support: what the cylinder's ends rest in. ``"fork"``: U-shaped forks open upwards,
            ``fork_depth`` deep — they hold the object against sideways pushes and weight
            until it is lifted out of them, then let it go. ``"v_blocks"``: V-blocks whose
            faces' normals are ``cradle_half_angle_deg`` from the vertical — a pushed object
            rides up a face (docs/design.md §14).
        fork_depth: depth of the forks (m).
        cradle_half_angle_deg: V-blocks' face angle (deg, in (0, 90)).
        support_stiffness: penalty of the support (N/m of penetration, both ends together).
        friction: Coulomb coefficient μ ≥ 0 between the arm and the object (0: frictionless;
            docs/design.md §9, §14).
    """

    radius: float
    mass_kg: float
    seat: tuple
    stiffness: float = 2.0e4
    support: str = "fork"
    fork_depth: float = 0.02
    cradle_half_angle_deg: float = 45.0
    support_stiffness: float = 1.0e5
    friction: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "friction", check_friction("FreeObject.friction", self.friction))
        Disc(center=self.seat, radius=self.radius, stiffness=self.stiffness)  # validates them
        if not math.isfinite(self.stiffness):
            raise ValueError("FreeObject.stiffness must be finite: a free object's pose is solved "
                             "with penalty contact (rigid contact has no force–pose law to balance)")
        object.__setattr__(self, "seat", tuple(float(v) for v in self.seat))
        if self.support not in SUPPORTS:
            raise ValueError(f"FreeObject.support must be one of {', '.join(SUPPORTS)}; "
                             f"got {self.support!r}")
        for name, low, high in (("mass_kg", 0.0, MAX_EXTENT), ("cradle_half_angle_deg", 0.0, 90.0),
                                ("support_stiffness", 0.0, math.inf), ("fork_depth", 0.0, MAX_EXTENT)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v) or not low < v < high:
                raise ValueError(f"FreeObject.{name} must be a finite number in ({low:g}, {high:g}); "
                                 f"got {v!r}")
            object.__setattr__(self, name, float(v))

    def disc(self, center) -> Disc:
        """The object at ``center`` as an obstacle of the arm's contact solve."""
        return Disc(center=(float(center[0]), float(center[1])), radius=self.radius,
                    stiffness=self.stiffness, friction=self.friction)

    def normals(self) -> np.ndarray:
        """(2, 2) the V-blocks' face normals (unit, pointing at the object), as rows."""
        b = math.radians(self.cradle_half_angle_deg)
        return np.array([[math.sin(b), math.cos(b)], [-math.sin(b), math.cos(b)]])

    def clear(self, center) -> bool:
        """Whether the object at ``center`` is clear of its support (out of the forks; off
        both V-block faces) and of the arm's base clamp."""
        rel = np.asarray(center, dtype=float) - self.seat
        if math.hypot(center[0], center[1]) <= self.radius + CLAMP_GAP:
            return False
        if self.support == "fork":
            return bool(rel[1] >= self.fork_depth)
        return bool(np.all(self.normals() @ rel > 0.0))

    def _clamp(self, center) -> tuple[np.ndarray, np.ndarray]:
        """The base clamp's reaction on the object and its Jacobian: the clamp is a boss round
        the arm's base (the origin) that keeps the object's centre ``radius + CLAMP_GAP``
        from it (a tight wrap pulls the object there), a penalty of ``support_stiffness``
        with a smooth onset: f(δ) = k δ²/2ε for a depth δ < ε = CLAMP_GAP/2, then k (δ − ε/2).
        Where a wrap presses the object against the clamp, a kink in f at first touch made
        Newton cycle between touching and not."""
        c = np.asarray(center, dtype=float)
        dist = math.hypot(c[0], c[1])
        depth = self.radius + CLAMP_GAP - dist
        if depth <= 0.0 or dist == 0.0:
            return np.zeros(2), np.zeros((2, 2))
        k = self.support_stiffness
        onset = 0.5 * CLAMP_GAP
        f, df = (0.5 * k * depth * depth / onset, k * depth / onset) if depth < onset else \
            (k * (depth - 0.5 * onset), k)
        u = c / dist
        # f u with δ = reach − |c|: ∂(f u)/∂c = −f'(δ) u uᵀ + (f/|c|)(I − u uᵀ).
        jac = -df * np.outer(u, u) + f / dist * (np.eye(2) - np.outer(u, u))
        return f * u, jac

    def support_reaction(self, center) -> tuple[np.ndarray, np.ndarray]:
        """The support's reaction (2,) on the object at ``center`` (N) and its Jacobian (2, 2)
        with respect to the centre (N/m), penalty k = ``support_stiffness``.

        Forks: floor k·max(0, seat_y − c_y) upwards; walls −k·(c_x − seat_x)·w while the
        centre is less than ``fork_depth`` above the seat, w fading from 1 to 0 over the top
        quarter of the fork (``RIM``). V-blocks: (k/2)·max(0, −gap_i)·n_i per
        face, gap_i = (c − seat)·n_i. A face just touching counts, for the one-sided
        derivative.
        """
        force, jac = self._clamp(center)
        rel = np.asarray(center, dtype=float) - self.seat
        if self.support == "fork":
            k = self.support_stiffness
            if rel[1] <= 0.0:
                force[1] -= k * rel[1]
                jac[1, 1] -= k
            # The walls' hold fades linearly over the top quarter of the fork (a chamfered
            # rim): a pushed object slides out over it instead of meeting a step in force.
            top = (1.0 - RIM) * self.fork_depth
            if rel[1] < self.fork_depth:
                w, dw = (1.0, 0.0) if rel[1] <= top else \
                    ((self.fork_depth - rel[1]) / (RIM * self.fork_depth), -1.0 / (RIM * self.fork_depth))
                force[0] -= k * rel[0] * w
                jac[0, 0] -= k * w
                jac[0, 1] -= k * rel[0] * dw
            return force, jac
        k = 0.5 * self.support_stiffness
        for n in self.normals():
            gap = float(rel @ n)
            if gap <= 0.0:
                force -= k * gap * n
                jac -= k * np.outer(n, n)
        return force, jac


@dataclass(frozen=True)
class Grasp:
    """The arm and a free object in equilibrium together (or the last attempt at it).

    Attributes:
        arm: the arm's equilibrium with the object's disc at ``center``.
        center: (2,) the object's centre (m).
        converged: the arm's solve converged and the object's balance met its tolerance.
        held: in equilibrium, clear of its support (:meth:`FreeObject.clear`): the arm alone
            carries the object.
        lift: height of the centre above its seat (m; negative when pressed into the support).
        arm_force: (2,) force of the arm on the object (N).
        support_force: (2,) reaction of the support and the base clamp on the object (N).
        residual: |G|, the object's force imbalance (N; with friction the moment's
            imbalance over the contact radius counts as a third component).
        stiffness: (2, 2) −∂G/∂c at the returned pose (N/m): the object's restoring stiffness;
            with friction (3, 3), of the pose (c, r·ψ) and the balance (G, moment / r), r the
            contact radius.
        stable: the arm's equilibrium is stable and ``stiffness`` is positive definite (the
            object sits in a potential well).
        iterations: Newton iterations on the pose; ``solves``: contact solves of the arm.
        turn: with friction, the object's turn ψ over the call (rad, counter-clockwise; 0
            without): the returned arm's anchors are in the turned object's place.
        arm_moment: the arm's moment on the object about its axis (N m; 0 without friction).
        snapped: with friction, the call passed a snap of the arm (a dynamic event): the arm
            landed without anchors, the object at the frictionless balance of arm and object,
            and the anchors formed there (no stick force; docs/design.md §9.1 "Free object").
            False without friction, whose snaps need no landing.
    """

    arm: Equilibrium
    center: np.ndarray
    converged: bool
    held: bool
    lift: float
    arm_force: np.ndarray
    support_force: np.ndarray
    residual: float
    stiffness: np.ndarray = field(repr=False)
    stable: bool
    iterations: int
    solves: int
    turn: float = 0.0
    arm_moment: float = 0.0
    snapped: bool = False


class Settler:
    """:func:`settle` for one arm, scene, object, model and settings, called again and again
    (an env's steps, a planner's rollouts, a margin's pushes): the request is checked, the arm
    packed and the lean contact rows built once, not at every call.

    ``Settler(arm, scene, obj).settle(pressures, ...)`` returns what ``settle(arm, pressures,
    scene, obj, ...)`` does, bit for bit: a call's result depends on its arguments only (the
    rows adopt each call's warm start afresh). Not for use from two threads at once (the rows
    are scratch).

    Args:
        arm: the design. scene: mounting and loads, without obstacles (the object is the only
            one). obj: the object. model, settings: as in :func:`solver.solve`.

    Raises:
        ValueError: a request :func:`settle` refuses (naming what is wrong).
    """

    def __init__(self, arm: ArmDesign, scene: Scene, obj: FreeObject, *, model: str = "full",
                 settings: Settings = DEFAULT_SETTINGS):
        if model not in MODELS:
            raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
        if not isinstance(obj, FreeObject):
            raise ValueError(f"obj must be a solver.grasp.FreeObject; got {type(obj).__name__}")
        check_request(arm, scene, model, True, settings)
        if model == "constant_curvature":
            raise ValueError("the constant-curvature model has no contact: a grasp needs 'full' "
                             "or 'unshearable'")
        if scene.obstacles:
            raise ValueError("the scene of a grasp must have no obstacles of its own: the object "
                             "is the only one (its contact force is read off the arm's balance)")
        self.arm, self.scene, self.obj, self.model, self.settings = arm, scene, obj, model, settings
        self.packed = pack(arm, model, settings)
        # D: the internal force at the base with no contact (weights and tip force).
        self.dead = context(arm, self.packed, scene, 2, settings).base_force[:2]
        # The lean contact path of the arm's solves: row 0 holds the warm start last adopted
        # (the list's second item), row 1 takes each step from a copy of it.
        template = replace(scene, obstacles=(obj.disc(obj.seat),))
        zeros = np.zeros(arm.n_inputs(True))
        problem = Problem(arm, self.packed, template, model, True, settings, zeros,
                          zeros[self.packed.spatial_of_planar])
        self.lean = [ContactRows(problem, 2, 1), None] if lean_contact_reason(problem) is None \
            else None
        self._frictionless = None

    @property
    def frictionless(self) -> Settler:
        """This settler with the object frictionless (a snap's landing, :func:`_land`)."""
        if self._frictionless is None:
            self._frictionless = Settler(self.arm, self.scene, replace(self.obj, friction=0.0),
                                         model=self.model, settings=self.settings)
        return self._frictionless

    def _balance(self, pressures, external_force=(0.0, 0.0)) -> _Balance:
        """The object's balance G at ``pressures`` under ``external_force`` (checked)."""
        return _Balance(self, pressures, external_force)

    def settle(self, pressures, *, center=None, warm_start: Equilibrium | None = None,
               external_force=(0.0, 0.0), max_solves: int = MAX_SOLVES) -> Grasp:
        """As :func:`settle` with this settler's arm, scene, object, model and settings."""
        if isinstance(max_solves, bool) or int(max_solves) != max_solves or max_solves < 1:
            raise ValueError(f"max_solves must be an integer >= 1; got {max_solves!r}")
        return _settle_path(self._balance(pressures, external_force), center, warm_start,
                            int(max_solves))


class _Balance:
    """G at a pose for one arm, pressures, scene, object and disturbance; counts the contact
    solves. A pose is the centre c (2,), and with friction (c, r·ψ) (3,), ψ the object's turn
    since the solve began (rad) and r its contact radius (so that every coordinate is a length
    and every component of G a force: the moment over r)."""

    def __init__(self, settler: Settler, pressures, external_force):
        f = np.asarray(external_force, dtype=float).ravel()
        if f.shape != (2,) or not np.all(np.isfinite(f)):
            raise ValueError(f"external_force must be two finite numbers (N); got {external_force!r}")
        self.settler = settler
        self.arm, self.scene, self.obj = settler.arm, settler.scene, settler.obj
        self.model, self.settings, self.packed = settler.model, settler.settings, settler.packed
        self.dead, self.lean = settler.dead, settler.lean
        self.dim = 3 if self.obj.friction > 0.0 else 2
        self.p_inputs, self.p_channel = checked_pressures(self.arm, pressures, True, self.packed)
        self.external = f
        self.load = np.array([0.0, -self.obj.mass_kg * self.scene.gravity]) + f
        self.counter = [0]  # contact solves, shared with the copies of at()
        self.budget = math.inf

    def at(self, p_inputs) -> _Balance:
        """This balance at other (valid) input pressures; the solve count is shared."""
        other = object.__new__(_Balance)
        other.__dict__.update(self.__dict__)
        other.p_inputs = p_inputs
        other.p_channel = p_inputs[self.packed.spatial_of_planar]
        other.counter = self.counter
        return other

    def frictionless(self) -> _Balance:
        """This balance with the object frictionless (a snap's landing, :func:`_land`); the
        solve count and budget are shared."""
        other = self.settler.frictionless._balance(self.p_inputs, self.external)
        other.counter, other.budget = self.counter, self.budget
        return other

    def pose(self, center) -> np.ndarray:
        """The pose of the object at ``center``, not turned."""
        return np.append(np.asarray(center, dtype=float), [0.0] * (self.dim - 2))

    def arm_at(self, pose, warm: Equilibrium, warm_pose) -> Equilibrium | None:
        """The arm's equilibrium at these pressures with the object moved from ``warm_pose``
        (where ``warm`` holds it) to ``pose``; None where the object would cover the arm's
        base (a pose the clamp forbids)."""
        center = pose[:2]
        if math.hypot(center[0], center[1]) <= self.obj.radius:
            return None
        if self.counter[0] >= self.budget:
            raise _Exhausted
        self.counter[0] += 1
        scene = self.scene.with_obstacles((self.obj.disc(center),))
        turn = float(pose[2] - warm_pose[2]) / self.obj.radius if self.dim == 3 else 0.0
        lean = self._lean_step(scene, warm, turn)
        if lean is not None:
            return lean
        if turn and warm is not None and warm.friction_samples.shape[0]:
            samples = warm.friction_samples.copy()
            turn_anchors(samples, 0, turn)
            warm = replace(warm, friction_samples=samples)
        return dispatch(Problem(self.arm, self.packed, scene, self.model, True, self.settings,
                                self.p_inputs, self.p_channel, warm), True, moving=True)

    def _lean_step(self, scene, warm: Equilibrium, turn: float) -> Equilibrium | None:
        """The arm's equilibrium in ``scene`` (the object's disc moved, and turned by ``turn``)
        by one lean contact step from ``warm`` (:mod:`solver.paths.lean_contact`), or None
        where that cannot take it (the general path's moving-obstacle ramp then does)."""
        if self.lean is None or warm is None:
            return None
        rows, adopted = self.lean
        if adopted is not warm:
            if warm.scene.has_friction and not rows.friction:
                # The object's friction turned off since the warm start: this batch keeps no
                # tangential state to adopt it with; the general path sets it aside.
                return None
            rows.set_scene(0, warm.scene)
            rows.adopt(0, warm)
            self.lean[1] = warm
        if not rows.on_contact_layout(0):
            return None
        rows.copy_rows(0, [1])
        if turn:
            rows.turn(1, 0, turn)
        report = rows.step_moved(1, self.p_channel, scene)
        if not report[0]:
            return None
        return rows.equilibrium(1, self.p_inputs, self.p_channel)

    def landing(self, eq: Equilibrium) -> bool:
        """Whether ``eq`` is a snap with friction: the arm landed without anchors, a state
        :func:`_land` takes on (not a point of the frictional balance's Newton)."""
        return self.dim == 3 and eq.converged and eq.snapped

    def arm_force(self, eq: Equilibrium) -> np.ndarray:
        """The force of the arm in ``eq`` on the object (N): D − n(0)."""
        return self.dead - eq.base_force[:2]

    def arm_moment(self, center, eq: Equilibrium) -> float:
        """The arm's moment on the object at ``center`` about its axis (N m): the reactions
        of the friction impulses at the contact samples (0 without friction)."""
        fs = eq.friction_samples
        if not fs.shape[0]:
            return 0.0
        at = fs[:, :, 0]
        rx = at[..., L.FS_R] - center[0]
        ry = at[..., L.FS_R + 1] - center[1]
        moment = -(rx * at[..., L.FS_F + 1] - ry * at[..., L.FS_F])
        return float(np.sum(moment[np.isfinite(moment)]))

    def forces(self, pose, eq: Equilibrium):
        """(G, arm force, supports' reaction) at ``pose`` with the arm in ``eq``: G has the
        pose's size, its third component (with friction) the arm's moment over the contact
        radius (the supports are frictionless)."""
        center = pose[:2]
        arm_force = self.arm_force(eq)
        support = self.obj.support_reaction(center)[0]
        g = arm_force + self.load + support
        if self.dim == 3:
            g = np.append(g, self.arm_moment(center, eq) / self.obj.radius)
        return g, arm_force, support

    def support_jacobian(self, pose) -> np.ndarray:
        """The supports' ∂G/∂(pose) (dim, dim): their reaction's (they exert no moment)."""
        jac = self.obj.support_reaction(pose[:2])[1]
        if self.dim == 2:
            return jac
        out = np.zeros((3, 3))
        out[:2, :2] = jac
        return out

    def tolerance(self, arm_force) -> float:
        return FORCE_TOL * (1.0 + float(np.abs(self.load).sum() + np.abs(arm_force).sum()))

    def arm_jacobian(self, pose, eq) -> np.ndarray | None:
        """∂G_arm/∂(pose) by forward differences (a contact solve per coordinate; zero when the
        arm does not touch the object), or None if a contact solve fails."""
        jac = np.zeros((self.dim, self.dim))
        if not eq.in_contact:
            return jac
        h = FD_STEP * self.obj.radius
        if self.dim == 3:
            # Within the stick cone's reach (μ times the deepest penetration): a larger step
            # slips every sample and sees the cone's force, not the grip's stiffness.
            h = min(h, 0.1 * self.obj.friction * float(np.max(eq.penetration)))
        arm_g = self.arm_part(pose, eq)
        for j in range(self.dim):
            moved_pose = pose.copy()
            moved_pose[j] += h
            moved = self.arm_at(moved_pose, eq, pose)
            if moved is None or not moved.converged or self.landing(moved):
                return None
            jac[:, j] = (self.arm_part(moved_pose, moved) - arm_g) / h
        return jac

    def arm_part(self, pose, eq) -> np.ndarray:
        """The arm's part of G at ``pose``: its force, and with friction its moment over the
        contact radius."""
        if self.dim == 2:
            return self.arm_force(eq)
        return np.append(self.arm_force(eq), self.arm_moment(pose[:2], eq) / self.obj.radius)


def _norm(v) -> float:
    """|v| of a pose or a balance (np.hypot in the plane, as before friction)."""
    return float(np.hypot(*v)) if v.size == 2 else float(np.linalg.norm(v))


def _definite(sym, values) -> bool:
    """Whether the object's stiffness K (its symmetric part ``sym``, eigenvalues ``values``
    ascending) is safely positive definite for a plain Newton step: its smallest eigenvalue
    above ``SHIFT`` times its largest.

    With friction (a 3 × 3 ``sym``) the ratio is taken after Jacobi scaling,
    K_ij/√(K_ii K_jj) (no positive diagonal: not definite). The pose then mixes the object's
    centre, which its forks hold at 1e5 N/m, with its turn, which only the grip's tangential
    springs hold (tens of N/m where an arm first touches it): the plain ratio takes that
    contrast for indefiniteness and shifts every step to 1e-3 of the forks' stiffness, so the
    turn creeps (docs/design.md §14). Frictionless poses keep the plain ratio: the fall of an
    object the arm lets go onto its seat follows the shifted steps it gives."""
    if sym.shape[0] == 2:
        return bool(values[0] > SHIFT * values[-1])
    diag = np.diag(sym)
    if not np.all(diag > 0.0):
        return False
    scaled = np.linalg.eigvalsh(sym / np.sqrt(np.outer(diag, diag)))
    return bool(scaled[0] > SHIFT * scaled[-1])


def _newton(bal: _Balance, pose, eq: Equilibrium):
    """Newton on the object's pose from ``pose`` with the arm in ``eq`` (solved there).

    The Jacobian is the support's, exact, plus the arm's: by finite differences, then
    Broyden-updated along the steps taken, rebuilt when a step fails. A step (halved up to
    ``BACKTRACKS`` times) is taken when the correction Newton would make from where it lands,
    K⁻¹G there with the same K, is shorter than its own (an affine-invariant test: G's force
    components span decades of stiffness, and a max |G| test refuses a good step along the
    soft direction for the small error it leaves in a stiff one; docs/design.md §14). Where the object's
    stiffness K = −∂G/∂(pose) is not positive definite (the arm pulls it the more, the further
    it goes), Newton's step would head for an unstable root against the net force; the step is
    then (K + μI)⁻¹G with μ making K + μI positive definite, its smallest eigenvalue at least
    |G| over the largest move — along the net force, as the object would move, a full move
    where nothing holds it (K = 0) — and taken without that test (pseudo-transient
    continuation), until a stable root is near. The same step is taken where Newton's step
    from a fresh Jacobian passes the test at no length.

    With friction, where the arm snaps (in ``eq`` or at a trial pose) the step is a snap's
    landing instead (:func:`_land`).

    Returns the :class:`_Pose` reached.
    """
    if bal.landing(eq):
        return _land(bal, np.array(pose, dtype=float), eq, 0)
    x = np.array(pose, dtype=float)
    # With friction the arm's state depends on its path: every trial pose is one quasi-static
    # increment from where Newton started (the object moved there at once), not the end of
    # a chain through Newton's earlier iterates, which would drag the anchors along it.
    origin = (x.copy(), eq) if bal.dim == 3 else None
    g, arm_force, support = bal.forces(x, eq)
    max_move = MAX_MOVE * bal.obj.radius
    arm_jac = None
    fresh = False
    move_on = False  # Newton's step failed: take the net force's way instead
    eye = np.eye(bal.dim)
    for it in range(MAX_ITER + 1):
        if np.abs(g).max() <= bal.tolerance(arm_force):
            return _Pose(x, eq, g, arm_force, support, True, it)
        if it == MAX_ITER:
            break
        if arm_jac is None:
            arm_jac = bal.arm_jacobian(x, eq)
            fresh = True
            if arm_jac is None:
                break
        stiffness = -(arm_jac + bal.support_jacobian(x))
        sym = 0.5 * (stiffness + stiffness.T)
        values = np.linalg.eigvalsh(sym)
        low, high = values[0], values[-1]
        shifted = move_on or not _definite(sym, values)
        move_on = False
        if shifted:
            # At least |G|/max_move: an object nothing holds (K = 0) falls a full move.
            floor = max(SHIFT * max(abs(high), abs(low)), _norm(g) / max_move)
            stiffness = stiffness + (floor - low) * eye
        step = _correction(stiffness, g)
        norm = _norm(step)
        if not math.isfinite(norm):
            break
        if norm > max_move:
            step *= max_move / norm
        accepted = False
        for _ in range(BACKTRACKS):  # backtracking on the size of Newton's next correction
            trial = x + step
            moved = bal.arm_at(trial, eq, x) if origin is None else bal.arm_at(trial, origin[1],
                                                                                origin[0])
            if moved is not None and bal.landing(moved):
                return _land(bal, trial, moved, it)
            if moved is not None and moved.converged:
                g_new, f_new, s_new = bal.forces(trial, moved)
                if shifted or _norm(_correction(stiffness, g_new)) < norm:
                    accepted = True
                    break
            step = 0.5 * step
        if not accepted:
            if fresh:
                if shifted:
                    break
                # Newton's step from a fresh Jacobian passes the test at no length: the nearest
                # root lies past a rise in |G| (the object climbing out of a fork's chamfer, say).
                move_on = True
                continue
            arm_jac = None  # a stale (Broyden) Jacobian: rebuild it and try again
            continue
        if shifted and np.abs(g_new).max() >= np.abs(g).max() and not fresh:
            arm_jac = None  # a shifted step that did not help: its Jacobian may be stale
        elif float(step @ step) > 0.0:
            # Broyden's update of the arm's part along the step taken.
            change = bal.arm_part(trial, moved) - bal.arm_part(x, eq)
            arm_jac = arm_jac + np.outer(change - arm_jac @ step, step) / float(step @ step)
        fresh = False
        x, eq, g, arm_force, support = trial, moved, g_new, f_new, s_new
    return _Pose(x, eq, g, arm_force, support, False, it)


def _correction(stiffness, g) -> np.ndarray:
    """Newton's correction K⁻¹G of the pose (least squares where K is singular)."""
    try:
        return np.linalg.solve(stiffness, g)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(stiffness, g, rcond=None)[0]


class _Pose(NamedTuple):
    """A state of :func:`_settle`: the object's pose (:class:`_Balance`), the arm's
    equilibrium there, the balance G, the arm's force, the supports' reaction, whether G met
    its tolerance, the Newton iterations spent and whether it is a snap's landing
    (:func:`_land`)."""

    pose: np.ndarray
    arm: Equilibrium
    g: np.ndarray
    arm_force: np.ndarray
    support: np.ndarray
    converged: bool
    iterations: int
    snapped: bool = False


def _land(bal: _Balance, pose, eq: Equilibrium, iterations: int) -> _Pose:
    """The landing of a snap with friction: the arm in ``eq`` snapped with the object at
    ``pose`` (a frictional balance's pose).

    A snap is a dynamic event: the arm lands without anchors, and they form where it comes
    to rest (docs/design.md §9.1). With fresh anchors no sample sticks, so friction carries
    nothing at the landing and the resting state is the frictionless balance of the arm and
    the object: the object's pose is solved frictionless (:func:`_newton` on
    :meth:`_Balance.frictionless`), then the arm is solved there with the object's friction and
    no anchors, which form at that state (zero stick force); friction builds from there on the
    later increments. The object keeps its turn.

    Returns:
        The :class:`_Pose` of ``bal`` landed on (``snapped``), converged where the frictionless
        pose solve converged and the balance with the fresh anchors meets its tolerance.
    """
    free = bal.frictionless()
    center = pose[:2]
    # The landed arm, its anchors dropped, in the frictionless scene.
    bare = replace(eq, scene=eq.scene.with_obstacles((free.obj.disc(center),)),
                   friction_samples=eq.friction_samples[:0])
    start = free.arm_at(center, bare, center)
    state = _Pose(pose, eq, *bal.forces(pose, eq), False, iterations, True)
    if start is None or not start.converged:
        return state
    rest = _newton(free, center, start)
    iterations += rest.iterations
    landed = np.append(rest.pose, pose[2:])
    arm = bal.arm_at(landed, rest.arm, landed) if rest.converged else None
    if arm is None or not arm.converged:
        return state._replace(iterations=iterations)
    g, arm_force, support = bal.forces(landed, arm)
    return _Pose(landed, arm, g, arm_force, support,
                 bool(np.abs(g).max() <= bal.tolerance(arm_force)), iterations, True)


def _result(bal: _Balance, state: _Pose, converged: bool, iterations: int,
            snapped: bool) -> Grasp:
    """The :class:`Grasp` of ``state``, with the object's stiffness (more contact solves)."""
    x, eq = state.pose, state.arm
    c = x[:2]
    stiffness = np.full((bal.dim, bal.dim), np.nan)
    stable = False
    if converged:
        bal.budget = math.inf  # the stiffness of a state reached is always worked out
        jac = bal.arm_jacobian(x, eq)
        if jac is not None:
            stiffness = -(jac + bal.support_jacobian(x))
            sym = 0.5 * (stiffness + stiffness.T)
            stable = bool(eq.stable and np.all(np.linalg.eigvalsh(sym) > 0.0))
    return Grasp(arm=eq, center=c, converged=bool(converged),
                 held=bool(converged and bal.obj.clear(c)),
                 lift=float(c[1] - bal.obj.seat[1]), arm_force=state.arm_force,
                 support_force=state.support, residual=_norm(state.g),
                 stiffness=stiffness, stable=stable, iterations=int(iterations),
                 solves=bal.counter[0],
                 turn=float(x[2] / bal.obj.radius) if bal.dim == 3 else 0.0,
                 arm_moment=bal.arm_moment(c, eq), snapped=bool(snapped))


def settle(arm: ArmDesign, pressures, scene: Scene, obj: FreeObject, *, center=None,
           warm_start: Equilibrium | None = None, external_force=(0.0, 0.0), model: str = "full",
           settings: Settings = DEFAULT_SETTINGS, max_solves: int = MAX_SOLVES) -> Grasp:
    """The arm at ``pressures`` and the free object in equilibrium together (planar).

    The quasi-static path from the previous state (``warm_start`` with the object at
    ``center``; cold: the unactuated arm with the object on its seat) to ``pressures`` is
    followed with the object free all along: pressures move in substeps (the whole step
    first, halved down to 1/64 of it where a substep fails, doubled again after a success up
    to 3/4 of the last that failed);
    in each the arm moves with the object held where it was, then the object's pose is solved
    by Newton from there, the equilibrium nearest the previous one. Where the smallest
    substep finds none — the object has slipped out of the arm's hold — it falls back onto its
    support, and the pose is solved from the seat. With friction the object's turn is part of
    its pose (counted from ``warm_start``, whose anchors stand where the object stood).

    Args:
        arm: the design. pressures: (n_inputs,) planar input pressures (Pa).
        scene: mounting and loads, without obstacles (the object is the only one).
        obj: the object. center: (2,) its centre before the step (m; default its seat).
        warm_start: the arm's equilibrium before the step with the object's disc at
            ``center``, e.g. the ``arm`` of the last :class:`Grasp` (default: a cold start).
        external_force: (2,) disturbance on the object (N).
        model, settings: as in :func:`solver.solve`.
        max_solves: contact solves the step may spend (each substep and Newton iteration
            costs one or more); beyond, the step is reported unconverged.

    Returns:
        The :class:`Grasp` at ``pressures``; where the path could not be followed to the end
        (or the budget ran out), the last state reached, with ``converged=False``.
    """
    return Settler(arm, scene, obj, model=model, settings=settings).settle(
        pressures, center=center, warm_start=warm_start, external_force=external_force,
        max_solves=max_solves)


def _settle_path(bal: _Balance, center, warm_start: Equilibrium | None, max_solves: int) -> Grasp:
    """The body of :func:`settle`: the quasi-static path to ``bal``'s pressures."""
    obj = bal.obj
    start = np.array(obj.seat if center is None else center, dtype=float)
    if start.shape != (2,) or not np.all(np.isfinite(start)):
        raise ValueError(f"center must be two finite numbers (m); got {center!r}")
    if math.hypot(*start) <= obj.radius:
        raise ValueError(f"the object at {tuple(start)} covers the arm's base at the origin")
    target = bal.p_inputs
    if warm_start is not None:
        origin = np.asarray(warm_start.pressures, dtype=float)
        if origin.shape != target.shape:
            raise ValueError("warm_start was solved with another number of input pressures")
    bal.budget = max_solves
    iterations = 0
    snapped = False
    x0 = bal.pose(start)
    try:
        if warm_start is None:
            origin = np.zeros_like(target)
            now = _settle(bal.at(origin), x0, None, fall_back=False)
            iterations += now.iterations
            snapped = now.snapped
            if not now.converged:
                return _result(bal, now, False, iterations, snapped)
        else:
            now = _Pose(x0, warm_start, *bal.forces(x0, warm_start), True, 0)
        t, dt, failed = 0.0, 1.0, math.inf
        while t < 1.0:
            t_new = min(1.0, t + dt)
            attempt = _settle(bal.at(origin + t_new * (target - origin)), now.pose, now.arm,
                              fall_back=dt <= MIN_SUBSTEP)
            iterations += attempt.iterations
            if attempt.converged:
                # Grow the substep again, but not back to one that failed (a failed substep
                # costs a Newton's worth of contact solves).
                now, t, dt = attempt, t_new, min(2.0 * dt, 0.75 * failed)
                snapped = snapped or attempt.snapped
            elif dt > MIN_SUBSTEP:
                dt = halved(dt, t_new - t, MIN_SUBSTEP)
                failed = 2.0 * dt  # (the last that failed, as plain halving's repeats leave it)
            else:
                return _result(bal, attempt, False, iterations, snapped)
    except _Exhausted:
        return _result(bal, now, False, iterations, snapped)
    return _result(bal, now, True, iterations, snapped)


def _settle(bal: _Balance, start, warm_start, fall_back: bool) -> _Pose:
    """The object's equilibrium at ``bal``'s pressures nearest the pose ``start`` (with the
    arm moved there from ``warm_start`` with the object held at ``start``), or from the
    seat."""
    eq = bal.arm_at(start, warm_start, start)
    if eq is None or not eq.converged:
        eq = warm_start if eq is None else eq
        return _Pose(start, eq, *bal.forces(start, eq), False, 0)
    state = _newton(bal, start, eq)
    seat = bal.pose(bal.obj.seat)
    seat[2:] = start[2:]  # (it falls without turning)
    if not state.converged and fall_back and np.any(start[:2] != seat[:2]):
        fallen = bal.arm_at(seat, eq, start)
        if fallen is not None and fallen.converged:
            more = _newton(bal, seat, fallen)
            state = more._replace(iterations=state.iterations + more.iterations)
    return state


class _Push:
    """A disturbance along ``unit`` on the object held in ``eq``'s arm (``settler``: its scene
    and object)."""

    def __init__(self, eq, settler, unit):
        self.eq, self.settler, self.unit = eq, settler, unit

    def holds(self, force, state):
        """Whether the object stays held under ``force`` (N) from ``state`` (pose, arm
        equilibrium), and the state it is held in."""
        bal = self.settler._balance(self.eq.pressures, force * self.unit)
        reached = _settle(bal, state[0], state[1], fall_back=False)
        return reached.converged and self.settler.obj.clear(reached.pose[:2]), (reached.pose, reached.arm)


def grasp_margin(grasp: Grasp, obj: FreeObject, *, directions: int = 8, max_force: float | None = None,
                 rel_tol: float = 0.05, settings: Settings = DEFAULT_SETTINGS) -> tuple[float, np.ndarray]:
    """The smallest disturbance force the grasp resists, over planar directions (N).

    For each of ``directions`` directions evenly spaced from straight up, a force on the
    object is increased from zero — doubling from a tenth of the object's weight, then
    bisected to ``rel_tol`` — while the object stays held: in equilibrium, nearest the last
    one, off its support. The largest force it stays held under is that direction's margin.
    Not held to begin with: every margin is 0. The directions are independent: they are
    worked out side by side on numba's thread count of Python threads (each on a settler of
    its own), each margin what it would be alone.

    Args:
        grasp: a converged result of :func:`settle` (its arm, pressures and scene are used).
        obj: the object it holds.
        directions: number of directions (≥ 1), the first straight up (+y).
        max_force: largest force tried (N; default 100 times the object's weight): a margin
            equal to it means "at least".
        rel_tol: relative resolution of each margin.

    Returns:
        (margin, per_direction): the smallest margin (N) and (directions,) the margin along
        each direction (unit vectors (−sin φ_k, cos φ_k), φ_k = 2πk/directions).
    """
    if isinstance(directions, bool) or int(directions) != directions or directions < 1:
        raise ValueError(f"directions must be an integer >= 1; got {directions!r}")
    if not 0 < rel_tol < 1:
        raise ValueError(f"rel_tol must be in (0, 1); got {rel_tol!r}")
    eq = grasp.arm
    weight = obj.mass_kg * eq.scene.gravity
    cap = 100.0 * weight if max_force is None else float(max_force)
    if not (math.isfinite(cap) and cap > 0):
        raise ValueError(f"max_force must be a finite number > 0 (N); got {max_force!r}")
    margins = np.zeros(int(directions))
    if not (grasp.converged and grasp.held):
        return 0.0, margins
    scene = replace(eq.scene, obstacles=())

    def along(k: int) -> float:
        """The margin along direction k, on a settler of its own (its lean rows are scratch):
        the directions are independent, so they run side by side (:class:`CopyPool`), each
        what it would be alone."""
        settler = Settler(eq.arm, scene, obj, model=eq.model, settings=settings)
        phi = 2.0 * math.pi * k / directions
        push = _Push(eq, settler, np.array([-math.sin(phi), math.cos(phi)]))
        state = (np.append(grasp.center, [0.0] * (obj.friction > 0.0)), eq)
        low, high = 0.0, None
        f = max(0.1 * weight, 1e-3)
        while f <= cap:
            ok, new = push.holds(f, state)
            if not ok:
                high = f
                break
            low, state = f, new
            f *= 2.0
        if high is None and low < cap:
            ok, new = push.holds(cap, state)
            if ok:
                low = cap
            else:
                high = cap
        if high is None:
            return low
        while high - low > rel_tol * high:
            mid = 0.5 * (low + high)
            ok, new = push.holds(mid, state)
            if ok:
                low, state = mid, new
            else:
                high = mid
        return low

    with CopyPool() as pool:
        margins = np.array(pool.map(along, range(int(directions))), dtype=float)
    return float(margins.min()), margins
