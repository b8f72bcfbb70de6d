"""What a solve returns: :class:`Equilibrium` and, for batches, :class:`BatchState`."""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields

import numpy as np

from solver.designs import ArmDesign
from solver.scene import Scene

__all__ = ["Equilibrium", "BatchState", "peak_penetration"]


def _empty(*shape):
    """A shared, read-only empty array: cheap defaults for fields a solve did not record."""
    arr = np.empty(shape)
    arr.flags.writeable = False
    return lambda: arr


@dataclass(frozen=True)
class Equilibrium:
    """A static equilibrium of the arm.

    Attributes:
        tip: tip position, (2,) planar or (3,) spatial (m).
        converged: Newton met the tolerance at the final load and pressure.
        stable: the equilibrium passed the conjugate-point (Jacobi) test.
        snapped: the quasi-static path passed a fold and jumped to another stable branch.
        iterations: total Newton iterations (continuation included).
        residual: |m(L) − M_tip| of the returned state (N m, norm in 3D).
        s: (N,) reference arc length of the samples (m); empty when not recorded.
        positions: (N, 2|3) backbone samples (m).
        angles: (N,) planar orientation θ of d3 from +x (rad); spatial: ``orientations``.
        orientations: (N, 3, 3) directors [d1 d2 d3] as columns (spatial only, else empty).
        shear_stretch: (N, 2|3) strains v in the body frame (planar: v1, v3).
        curvature: (N,) planar u2 (rad/m) or (N, 3) spatial u.
        internal_force: (N, 2|3) n in the world frame (N).
        internal_moment: (N,) planar m_z or (N, 3) spatial m in the world frame (N m).
        section_ends: indices of the samples at each section end.
        contact_force: (N, 2) penalty contact force per reference length (N/m, world frame);
            empty unless the scene has obstacles.
        penetration: (N,) depth of the backbone inside the nearest obstacle, or with
            self-contact inside another part of the arm, at each sample (m, ≥ 0); between
            samples it can be deeper: see :attr:`peak_penetration`.
        in_contact: the backbone presses on an obstacle somewhere (False without obstacles),
            read off the samples: a patch narrower than the steps (a stiff penalty's) can
            fall between them, which :attr:`peak_penetration` sees.
        base_force: internal force n(0) at the base (N, world frame).
        pressures: the pressures solved for (Pa), in the order of ``design.input_names``.
        penalty_stiffness: with rigid obstacles, the penalty stiffness (N/m²) that met
            ``Settings.gap_tol`` (NaN otherwise).
        friction_samples: with friction (an obstacle with μ > 0), the tangential state at the
            contact samples (rows, nodes, obstacles, ``layout.N_FS``): anchors, friction
            impulses (N, world frame), positions, slips and the work dissipated
            (``layout.FS_*``, docs/design.md §9); a warm start carries it on. Empty without.
        self_friction_samples: with self-contact friction (``Scene.self_friction`` > 0), the
            tangential state at the self-contact law's points (segments, nodes, SUBPOINTS,
            ``layout.N_FS``; ``layout.L_SELF_FRICTION``): anchors (the partner's arc length,
            m), friction impulses on the points (N), positions, slips and work; a warm start
            carries it on. Empty without.
        dissipated: energy dissipated by friction (J) along the quasi-static path to this
            state, from the cold start through every warm start it continues.
        model, planar: what was solved.
        arm, scene: the design and scene it was solved for (a warm start is checked
            against them).
    """

    tip: np.ndarray
    converged: bool
    stable: bool
    iterations: int
    residual: float
    snapped: bool = False
    s: np.ndarray = field(default_factory=_empty(0))
    positions: np.ndarray = field(default_factory=_empty(0, 2))
    angles: np.ndarray = field(default_factory=_empty(0))
    orientations: np.ndarray = field(default_factory=_empty(0, 3, 3))
    shear_stretch: np.ndarray = field(default_factory=_empty(0, 2))
    curvature: np.ndarray = field(default_factory=_empty(0))
    internal_force: np.ndarray = field(default_factory=_empty(0, 2))
    internal_moment: np.ndarray = field(default_factory=_empty(0))
    section_ends: tuple = ()
    contact_force: np.ndarray = field(default_factory=_empty(0, 2))
    penetration: np.ndarray = field(default_factory=_empty(0))
    in_contact: bool = False
    base_force: np.ndarray = field(default_factory=_empty(0))
    pressures: np.ndarray = field(default_factory=_empty(0))
    model: str = "full"
    planar: bool = True
    base_moment: np.ndarray = field(default_factory=_empty(0), repr=False)
    shooting_nodes: np.ndarray = field(default_factory=_empty(0), repr=False)
    scene: Scene | None = field(default=None, repr=False)
    channel_pressures: np.ndarray = field(default_factory=_empty(0), repr=False)
    penalty_stiffness: float = math.nan
    friction_samples: np.ndarray = field(default_factory=_empty(0, 0, 0, 0), repr=False)
    self_friction_samples: np.ndarray = field(default_factory=_empty(0, 0, 0, 0), repr=False)
    dissipated: float = 0.0
    arm: ArmDesign | None = field(default=None, repr=False, compare=False)

    @classmethod
    def _make(cls, **values) -> Equilibrium:
        """An Equilibrium of ``values`` (fields by name; the others default), built without
        the dataclass ``__init__`` — which costs more than a warm solve's kernel — for the
        solver's own results (nothing to validate: every field is set as given)."""
        if not (_FIELDS.issuperset(values) and _REQUIRED.issubset(values)):
            raise TypeError(f"Equilibrium fields: unknown {sorted(set(values) - _FIELDS)}, "
                            f"missing {sorted(_REQUIRED - set(values))}")
        eq = object.__new__(cls)
        eq.__dict__.update(_DEFAULTS, **values)
        return eq

    @property
    def peak_penetration(self) -> float:
        """The deepest penetration (m, ≥ 0) anywhere along the backbone — into an obstacle
        or, with self-contact, into another part of the arm — between the recorded samples
        as well as at them (:func:`peak_penetration`; docs/design.md §9, "Penetration").
        0 without contact; NaN where the samples were not recorded."""
        return peak_penetration(self)

    @property
    def tip_angle(self) -> float:
        """Planar tip orientation θ(L) (rad); NaN if not recorded or spatial."""
        return float(self.angles[-1]) if self.angles.size else math.nan


def peak_penetration(eq: Equilibrium, rigid_only: bool = False, scene: Scene | None = None) -> float:
    """The deepest penetration (m, ≥ 0) of ``eq``'s backbone anywhere along it, from its
    recorded samples and the geometry between them (docs/design.md §9, "Penetration").

    Between consecutive samples the backbone is the cubic Hermite curve through their
    positions with their slopes r' (from the recorded orientation and strains), whose
    deepest point in each obstacle (:func:`solver.kernels.obstacles.peak_depth`) and in another
    part of the arm farther along it than the self-contact exclusion
    (:func:`solver.kernels.self_contact.peak_overlap`) is found by Newton. The samples alone can
    miss a contact patch shorter than their spacing.

    Args:
        eq: a recorded equilibrium (``eq.scene`` and, with self-contact, ``eq.arm`` set).
        rigid_only: count only rigid contact (obstacles and self-contact of infinite
            stiffness): what the rigid continuation stiffens until it is below
            ``Settings.gap_tol``.
        scene: the scene whose obstacles and self-contact count (default ``eq.scene``; the
            rigid continuation passes the rigid scene its penalty stages are solved for).

    Returns:
        The depth (m); 0 where the scene has no contact (of that kind), NaN where the
        samples were not recorded.
    """
    from solver.kernels.obstacles import peak_depth
    from solver.kernels.self_contact import peak_overlap
    from solver.scene import obstacle_row, self_contact_exclusion

    scene = eq.scene if scene is None else scene
    if scene is None:
        return 0.0
    obstacles = [o for o in scene.obstacles if not rigid_only or o.stiffness == math.inf]
    self_contact = scene.self_contact is not None and (
        not rigid_only or scene.self_contact == math.inf)
    if not obstacles and not self_contact:
        return 0.0
    if eq.s.size < 2:
        return math.nan
    if eq.planar:
        v1, v3 = eq.shear_stretch[:, 0], eq.shear_stretch[:, 1]
        c, sn = np.cos(eq.angles), np.sin(eq.angles)
        slopes = np.column_stack([v3 * c - v1 * sn, v3 * sn + v1 * c])
    else:
        slopes = np.einsum("nij,nj->ni", eq.orientations, eq.shear_stretch)
    positions = np.ascontiguousarray(eq.positions, dtype=float)
    # The samples' own depths count too: with self-contact they are the law's, on the
    # solver's geometry, which carries the kinks of the point loads at loaded nodes that
    # the curves through the recorded slopes smooth over (by a micrometre or so).
    deepest = 0.0 if rigid_only or not eq.penetration.size else float(eq.penetration.max())
    if obstacles:
        array = np.array([obstacle_row(o) for o in obstacles], dtype=float)
        deepest = max(deepest, peak_depth(positions, slopes, np.ascontiguousarray(eq.s), array))
    if self_contact:
        half = np.array(eq.arm.half_thickness())
        section = np.minimum(np.searchsorted(np.asarray(eq.section_ends), np.arange(eq.s.size)),
                             half.size - 1)
        deepest = max(deepest, peak_overlap(positions, slopes, np.ascontiguousarray(eq.s),
                                            half[section], self_contact_exclusion(half)))
    return float(deepest)


_FIELDS = frozenset(f.name for f in fields(Equilibrium))
_DEFAULTS = {f.name: f.default if f.default_factory is MISSING else f.default_factory()
             for f in fields(Equilibrium) if f.default is not MISSING or f.default_factory is not MISSING}

_REQUIRED = _FIELDS - set(_DEFAULTS)

SAMPLED = {f.name: f.default_factory for f in fields(Equilibrium) if f.name in (
    "s", "positions", "angles", "orientations", "shear_stretch", "curvature", "internal_force",
    "internal_moment", "contact_force", "penetration")}
"""The per-sample fields of an :class:`Equilibrium` (first axis: the samples), with their
empty defaults."""


_NOT_RECORDED = {name: _DEFAULTS[name] for name in (*SAMPLED, "section_ends")}


def tip_only(eq: Equilibrium) -> Equilibrium:
    """``eq`` without its samples (what a solve with ``record=False`` returns)."""
    out = object.__new__(Equilibrium)
    out.__dict__.update(eq.__dict__)
    out.__dict__.update(_NOT_RECORDED)
    return out


# ----------------------------------------------------------------------------- packing


@dataclass
class BatchState:
    """Equilibria of n copies of one arm in one scene, stepped together by :func:`step_batch`.

    Attributes:
        pressures: (n, n_inputs) planar channel pressures of each copy (Pa).
        tips: (n, 2) tip positions (m).
        converged: (n,) whether the last step of each copy converged (a copy that did not
            kept its previous state).
        shapes: (n, N, ``layout.N_COLUMNS``) recorded backbones when stepped with
            ``record=True``: columns s, x, y, θ, m, n_x, n_y, v1, v3, u, then the solver's
            scratch columns, NaN (see :mod:`solver.layout`); else (n, 1, N_COLUMNS) scratch.
        section_ends: sample indices of the section ends in ``shapes``.
        arm, scene: the design and scene they were stepped for (a next step is checked
            against them).
    """

    pressures: np.ndarray
    tips: np.ndarray
    converged: np.ndarray
    shapes: np.ndarray
    section_ends: tuple
    base_moment: np.ndarray = field(repr=False, default=None)
    channel_pressures: np.ndarray = field(repr=False, default=None)
    arm: ArmDesign | None = field(repr=False, default=None)
    scene: Scene | None = field(repr=False, default=None)
