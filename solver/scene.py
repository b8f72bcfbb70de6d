"""The loading and mounting of an arm: base angle, gravity, payload, tip force and moment."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from solver.layout import N_OBSTACLE

__all__ = ["Scene", "Disc", "Cylinder", "Sphere", "SELF_CONTACT_EXCLUSION"]

MAX_EXTENT = 1e4
"""Largest disc radius and centre coordinate (m): far beyond any arm (a design is at most
3.2 km long only on paper), and far from overflow in the contact arithmetic."""


SELF_CONTACT_EXCLUSION = 3.0
"""Parts of the arm touch each other only when farther apart along it than this many arm
thicknesses (twice the largest section half-thickness): nearer parts are neighbours, which
bending, not contact, keeps apart."""


def self_contact_exclusion(half_thickness) -> float:
    """The exclusion length (m) of an arm with these section half-thicknesses (m):
    ``SELF_CONTACT_EXCLUSION`` times its largest thickness."""
    return SELF_CONTACT_EXCLUSION * 2.0 * max(half_thickness)


@dataclass(frozen=True)
class Disc:
    """A rigid disc (planar obstacle) the arm's backbone is pressed against by penalty contact.

    Attributes:
        center: (x, y) of the centre (m).
        radius: contact radius for the backbone curve (m): the object's radius plus the
            arm's half-thickness if the arm's surface, not its axis, should touch.
        stiffness: penalty k (N/m²): force per unit reference length per metre of
            penetration. Larger is stiffer and harder for the solver; 2e4 gives ~1 mm
            penetration under ~20 N/m of contact load. ``math.inf``: a rigid disc (hard
            contact), solved by penalty continuation until the deepest penetration is
            below ``Settings.gap_tol``. A physical value for an arm's own compliance is
            :meth:`solver.designs.TubeMaterial.ring_stiffness` of its outer tubes.
        friction: Coulomb coefficient μ ≥ 0 between the arm and the disc (0: frictionless,
            the default). The arm sticks while the tangential force is within μ times the
            normal force and slips on that cone, the tangential state carried along the
            quasi-static path (docs/design.md §9).
    """

    center: tuple = (0.0, 0.0)
    radius: float = 0.05
    stiffness: float = 2.0e4
    friction: float = 0.0

    def __post_init__(self):
        try:
            c = np.asarray(self.center, dtype=float).ravel()
        except (TypeError, ValueError):
            c = np.empty(0)
        if c.size != 2 or not np.all(np.abs(c) <= MAX_EXTENT):
            raise ValueError(f"Disc.center must be two finite numbers within ±{MAX_EXTENT:g} m; "
                             f"got {self.center!r}")
        object.__setattr__(self, "center", (float(c[0]), float(c[1])))
        _radius_and_stiffness(self)
        _coulomb(self)


def _vector3(owner: str, name: str, value, unit: bool = False) -> tuple:
    """``value`` as three floats within ±MAX_EXTENT (``unit``: normalised, not zero)."""
    try:
        v = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        v = np.empty(0)
    if v.size != 3 or not np.all(np.abs(v) <= MAX_EXTENT):
        raise ValueError(f"{owner}.{name} must be three finite numbers within ±{MAX_EXTENT:g}; "
                         f"got {value!r}")
    if unit:
        norm = float(np.linalg.norm(v))
        if not norm > 1e-12:
            raise ValueError(f"{owner}.{name} must be a nonzero direction; got {value!r}")
        v = v / norm
    return tuple(float(c) for c in v)


def _radius_and_stiffness(obj) -> None:
    """Validate and store ``obj.radius`` (m) and ``obj.stiffness`` (N/m², or math.inf)."""
    owner = type(obj).__name__
    for name in ("radius", "stiffness"):
        v = getattr(obj, name)
        rigid_ok = name == "stiffness" and v == math.inf
        high = math.inf if name == "stiffness" else MAX_EXTENT
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                or not (math.isfinite(v) or rigid_ok) or not 0 < v <= high:
            what = "a number > 0 or math.inf (rigid)" if name == "stiffness" else \
                f"a finite number > 0 and <= {MAX_EXTENT:g} m"
            raise ValueError(f"{owner}.{name} must be {what}; got {v!r}")
        object.__setattr__(obj, name, float(v))


def check_friction(owner: str, value) -> float:
    """``value`` as a Coulomb coefficient μ: a finite number ≥ 0, else a ValueError naming
    ``owner`` (the field, e.g. ``"Disc.friction"``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not math.isfinite(value) or value < 0:
        raise ValueError(f"{owner} must be a finite number >= 0 (the Coulomb coefficient mu); "
                         f"got {value!r}")
    return float(value)


def _coulomb(obj) -> None:
    """Validate and store ``obj.friction`` (μ ≥ 0)."""
    object.__setattr__(obj, "friction", check_friction(f"{type(obj).__name__}.friction",
                                                       obj.friction))


@dataclass(frozen=True)
class Cylinder:
    """A rigid infinite cylinder (spatial obstacle) the backbone is pressed against by
    penalty contact, with the law of :class:`Disc` (force per reference length k·penetration
    along the normal to the axis). A :class:`Disc` in a spatial solve is the cylinder along
    z through its centre.

    Attributes:
        point: (x, y, z) of a point on the axis (m).
        axis: direction of the axis (normalised; any nonzero 3-vector).
        radius: contact radius for the backbone curve (m): object radius plus the arm's
            half-thickness for surface contact.
        stiffness: penalty k (N/m²), or ``math.inf`` (rigid), as for :class:`Disc`.
        friction: Coulomb coefficient μ ≥ 0, as for :class:`Disc`.
    """

    point: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    radius: float = 0.05
    stiffness: float = 2.0e4
    friction: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "point", _vector3("Cylinder", "point", self.point))
        object.__setattr__(self, "axis", _vector3("Cylinder", "axis", self.axis, unit=True))
        _radius_and_stiffness(self)
        _coulomb(self)


@dataclass(frozen=True)
class Sphere:
    """A rigid sphere (spatial obstacle), penalty contact with the law of :class:`Disc`.

    Attributes:
        center: (x, y, z) of the centre (m).
        radius: contact radius for the backbone curve (m).
        stiffness: penalty k (N/m²), or ``math.inf`` (rigid).
        friction: Coulomb coefficient μ ≥ 0, as for :class:`Disc`.
    """

    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.05
    stiffness: float = 2.0e4
    friction: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "center", _vector3("Sphere", "center", self.center))
        _radius_and_stiffness(self)
        _coulomb(self)


def core_distance(obstacle, points) -> np.ndarray:
    """Distance (m) of (N, 2|3) points from an obstacle's core: a disc's centre in the x–y
    plane (planar points, or the x, y of spatial ones), a cylinder's axis, a sphere's
    centre. A point is inside where this is below the radius."""
    p = np.atleast_2d(np.asarray(points, dtype=float))
    if isinstance(obstacle, Disc):
        return np.hypot(p[:, 0] - obstacle.center[0], p[:, 1] - obstacle.center[1])
    rel = p - np.array(obstacle.point if isinstance(obstacle, Cylinder) else obstacle.center)
    if isinstance(obstacle, Cylinder):
        axis = np.array(obstacle.axis)
        rel = rel - (rel @ axis)[:, None] * axis
    return np.linalg.norm(rel, axis=1)


def obstacle_row(obstacle) -> list:
    """An obstacle as a row (N_OBSTACLE,) of the spatial kernels' array (``layout.O_*``): a point, an axis
    (zero for a sphere), radius and stiffness; a :class:`Disc` is the cylinder along z."""
    if isinstance(obstacle, Disc):
        return [*obstacle.center, 0.0, 0.0, 0.0, 1.0, obstacle.radius, obstacle.stiffness]
    if isinstance(obstacle, Cylinder):
        return [*obstacle.point, *obstacle.axis, obstacle.radius, obstacle.stiffness]
    return [*obstacle.center, 0.0, 0.0, 0.0, obstacle.radius, obstacle.stiffness]


def _checked_obstacles(obstacles) -> tuple:
    """``obstacles`` as a tuple, each a :class:`Disc`, :class:`Cylinder` or :class:`Sphere`
    clear of the arm's base (ValueError naming the first that is not)."""
    checked = tuple(obstacles) if isinstance(obstacles, (tuple, list)) else None
    if checked is None or not all(isinstance(o, (Disc, Cylinder, Sphere)) for o in checked):
        raise ValueError("Scene.obstacles must be a tuple of solver.Disc, solver.Cylinder or "
                         f"solver.Sphere; got {obstacles!r}")
    for k, d in enumerate(checked):
        if core_distance(d, np.zeros(3))[0] <= d.radius:
            raise ValueError(f"Scene.obstacles[{k}] ({d}) covers the arm's base at the origin: "
                             "the clamp cannot sit inside an obstacle")
    return checked


@dataclass(frozen=True)
class Scene:
    """Everything outside the arm that sets its equilibrium (docs/design.md §1–4 conventions).

    Frame: base at the origin, ``x`` horizontal, ``y`` vertical up, ``z`` out of plane;
    gravity acts along −y.

    Attributes:
        base_angle_deg: angle of the unactuated arm axis from the downward vertical,
            towards +x: 0 hangs down, 90 points along +x, 180 points up.
        payload_kg: point mass at the tip (kg).
        gravity: magnitude of gravitational acceleration (m/s²); 0 switches gravity off.
        tip_force: extra dead force at the tip, (Fx, Fy) or (Fx, Fy, Fz) in N.
        tip_moment: extra dead moment at the tip, Mz (N m) or (Mx, My, Mz).
        obstacles: rigid obstacles in contact with the arm: :class:`Disc` s (planar and
            spatial solves; in 3D a disc is the cylinder along z through its centre),
            :class:`Cylinder` s and :class:`Sphere` s (spatial solves only).
        self_contact: penalty stiffness (N/m², the discs' law) between parts of the arm
            farther apart along it than ``SELF_CONTACT_EXCLUSION`` arm thicknesses, which
            then cannot pass through each other (planar solves only; docs/design.md §9). A
            physical value is the outer tubes' :meth:`~solver.designs.TubeMaterial.ring_stiffness`;
            ``math.inf``: rigid (hard contact, by penalty continuation as for rigid discs).
            None (the default): no self-contact — parts of an arm curled past a full turn
            pass through each other.
        self_friction: Coulomb coefficient μ ≥ 0 between parts of the arm pressed on each
            other by ``self_contact`` (0, the default: frictionless; docs/design.md §9.1).
            Needs ``self_contact``.
    """

    base_angle_deg: float = 0.0
    payload_kg: float = 0.0
    gravity: float = 9.81
    tip_force: tuple = (0.0, 0.0)
    tip_moment: float | tuple = 0.0
    obstacles: tuple = ()
    self_contact: float | None = None
    self_friction: float = 0.0

    def __post_init__(self):
        for name in ("base_angle_deg", "payload_kg", "gravity"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v):
                raise ValueError(f"Scene.{name} must be a finite number; got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.payload_kg < 0:
            raise ValueError(f"Scene.payload_kg must be >= 0; got {self.payload_kg}")
        if self.gravity < 0:
            raise ValueError(f"Scene.gravity must be >= 0 (it always acts along -y); got {self.gravity}")
        force = np.asarray(self.tip_force, dtype=float).ravel()
        if force.size not in (2, 3) or not np.all(np.isfinite(force)):
            raise ValueError(f"Scene.tip_force must be 2 or 3 finite numbers (N); got {self.tip_force!r}")
        moment = np.asarray(self.tip_moment, dtype=float).ravel()
        if moment.size not in (1, 3) or not np.all(np.isfinite(moment)):
            raise ValueError(
                f"Scene.tip_moment must be 1 (Mz) or 3 finite numbers (N m); got {self.tip_moment!r}")
        object.__setattr__(self, "obstacles", _checked_obstacles(self.obstacles))
        k = self.self_contact
        if k is not None:
            if isinstance(k, bool) or not isinstance(k, (int, float, np.floating, np.integer)) \
                    or math.isnan(k) or not k > 0:
                raise ValueError(f"Scene.self_contact must be None, a penalty stiffness > 0 (N/m²) "
                                 f"or math.inf (rigid); got {k!r}")
            object.__setattr__(self, "self_contact", float(k))
        object.__setattr__(self, "self_friction", check_friction("Scene.self_friction",
                                                                 self.self_friction))
        if self.self_friction > 0.0 and k is None:
            raise ValueError(f"Scene.self_friction = {self.self_friction} needs self-contact "
                             "(Scene.self_contact is None: no part of the arm presses on another)")
        object.__setattr__(self, "tip_force", tuple(float(f) for f in force))
        object.__setattr__(self, "tip_moment",
                           float(moment[0]) if moment.size == 1 else tuple(float(m) for m in moment))
        # Derived once (not fields: they follow from the fields above).
        object.__setattr__(self, "_is_planar", self._planar_with(self.obstacles))
        object.__setattr__(self, "_base_theta", math.radians(self.base_angle_deg - 90.0))

    def with_obstacles(self, obstacles) -> Scene:
        """This scene with ``obstacles`` instead of its own (checked as the constructor checks
        them), the rest taken as it is: ``replace(scene, obstacles=...)`` without checking the
        other fields again, and sharing :attr:`without_contact` — an object the arm carries
        moves its disc at every trial pose of a grasp's balance (:mod:`solver.grasp`)."""
        other = object.__new__(Scene)
        other.__dict__.update(self.__dict__)
        obstacles = _checked_obstacles(obstacles)
        object.__setattr__(other, "obstacles", obstacles)
        # (A planar scene with discs for discs stays planar: its loads are in the plane.)
        planar = self._is_planar and all(isinstance(o, Disc) for o in obstacles)
        object.__setattr__(other, "_is_planar", planar or self._planar_with(obstacles))
        object.__setattr__(other, "_without_contact", self.without_contact)
        return other

    def _planar_with(self, obstacles) -> bool:
        """Whether this scene's loads with ``obstacles`` stay in the x–y plane."""
        m3 = self.tip_moment_3d()
        return bool(self.tip_force_3d()[2] == 0.0 and m3[0] == 0.0 and m3[1] == 0.0
                    and all(isinstance(o, Disc) for o in obstacles))

    @property
    def base_theta(self) -> float:
        """Planar orientation θ0 of d3 at the base, from +x counter-clockwise (rad)."""
        return self._base_theta

    def tip_force_3d(self) -> np.ndarray:
        """Tip force as a 3-vector (N)."""
        f = np.zeros(3)
        f[: len(self.tip_force)] = self.tip_force
        return f

    def tip_moment_3d(self) -> np.ndarray:
        """Tip moment as a 3-vector (N m); a scalar is Mz."""
        if isinstance(self.tip_moment, float):
            return np.array([0.0, 0.0, self.tip_moment])
        return np.array(self.tip_moment, dtype=float)

    @property
    def has_rigid_obstacles(self) -> bool:
        """True when an obstacle or the self-contact is rigid (``math.inf``: hard contact)."""
        return any(d.stiffness == math.inf for d in self.obstacles) or self.self_contact == math.inf

    @property
    def has_contact(self) -> bool:
        """True when the solve has contact to resolve: obstacles or self-contact."""
        return bool(self.obstacles) or self.self_contact is not None

    @property
    def without_contact(self) -> Scene:
        """This scene without obstacles and self-contact (itself when it has neither): the
        scene of a contact solve's free stages and cache keys, built once per scene."""
        free = self.__dict__.get("_without_contact")
        if free is None:
            free = replace(self, obstacles=(), self_contact=None, self_friction=0.0) \
                if self.has_contact else self
            object.__setattr__(self, "_without_contact", free)
        return free

    @property
    def is_planar(self) -> bool:
        """True when no load leaves the x–y plane and every obstacle is a :class:`Disc`."""
        return self._is_planar

    def discs_array(self) -> np.ndarray:
        """Obstacles as an (n, 4) array: centre x, centre y, radius, stiffness."""
        return np.array([[*d.center, d.radius, d.stiffness] for d in self.obstacles],
                        dtype=float).reshape(-1, 4)

    def friction_array(self) -> np.ndarray:
        """(n,) every obstacle's Coulomb coefficient μ."""
        return np.array([o.friction for o in self.obstacles], dtype=float)

    @property
    def has_friction(self) -> bool:
        """True when an obstacle has a Coulomb coefficient μ > 0."""
        return any(o.friction > 0.0 for o in self.obstacles)

    def obstacles_array(self) -> np.ndarray:
        """Obstacles as the spatial kernels' (n, 8) array (:func:`obstacle_row`)."""
        return np.array([obstacle_row(o) for o in self.obstacles],
                        dtype=float).reshape(-1, N_OBSTACLE)
