"""A design unpacked for the kernels, everything the solver derives from it per scene, and
the request the solver's paths take.

:class:`PackedArm` holds a design's kernel arrays for one model and settings (or a contact
or multiple-shooting layout of them); :class:`SceneContext` the dead loads and numeric
parameters of one scene; :class:`Problem` one validated solve request (built by
:func:`solver.inputs.request`), the one argument of every path in :mod:`solver.paths`. The
first two, and the loading stages and layouts built from them, are
memoised in the design's :class:`solver.cache.DesignCache`; cache keys name their inputs
by value (``PackedArm.key``), never by object identity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from solver import layout as L
from solver.designs import ArmDesign
from solver.results import Equilibrium
from solver.rod import rest_strains_into
from solver.scene import Scene
from solver.settings import DEFAULT_SETTINGS, Settings

# Above this index single shooting fails on most arms (``softarm stress``, huge_arm and soft
# classes: 95 % of solves converge below 20, 5 % above 30), so dead-load solves go straight
# to multiple shooting.
MULTIPLE_SHOOTING_INDEX = 20.0

# RK4 step in contact, as a fraction of the decay length ℓ = (EI/k)^¼ (see contact_layout);
# the kernel refines steps that may reach a disc (solver.kernels.contact.NEAR_SUBSTEPS).
CONTACT_STEP = 0.5

# Steps per multiple-shooting segment: no segment amplifies errors much.
SEGMENT_STEPS = 4


@dataclass(frozen=True)
class PackedArm:
    """A design unpacked to the float/int arrays the kernels take (layouts:
    :mod:`solver.layout`), for one model and settings.

    Attributes:
        key: what the arrays depend on (model, settings, and for a contact layout the
            penalty stiffness): the cache key of everything derived from them.
        secf: (6, ns) section array. sec_steps: (ns,) RK4 steps per section.
        tubes_i, tubes_f: the tube arrays. c_j: (ns,) 1/GJ.
        mass_per_length, endplate: (ns,) kg/m, kg.
        moment_scale: the bending moment scale (N m) of the arm's residual tolerances,
            (Σ L_i/EI_i)⁻¹: each section's moment scale EI_i/L_i combined in series
            (:func:`series_moment_scale`).
        n_rows: recorded samples (Σ(steps + 1)); section_ends: their indices at section ends.
        spatial_of_planar: (n_channels,) the planar input feeding each spatial channel.
    """

    key: tuple
    secf: np.ndarray
    sec_steps: np.ndarray
    c_j: np.ndarray
    mass_per_length: np.ndarray
    endplate: np.ndarray
    tubes_i: np.ndarray
    tubes_f: np.ndarray
    moment_scale: float
    n_rows: int
    spatial_of_planar: np.ndarray
    section_ends: tuple

    @property
    def sec_len(self) -> np.ndarray:
        return self.secf[L.LEN]

    @property
    def c_a(self) -> np.ndarray:
        return self.secf[L.CA]

    @property
    def c_g(self) -> np.ndarray:
        return self.secf[L.CG]

    @property
    def c_i(self) -> np.ndarray:
        return self.secf[L.CI]

    @property
    def sec_ei(self) -> np.ndarray:
        return self.secf[L.EI]

    def with_steps(self, steps: np.ndarray, key: tuple) -> PackedArm:
        """The same arrays at another resolution (a contact layout)."""
        steps = np.asarray(steps, dtype=np.int64)
        return replace(self, key=key, sec_steps=steps, n_rows=int((steps + 1).sum()),
                       section_ends=tuple(int(v) for v in np.cumsum(steps + 1) - 1))


def pack(arm: ArmDesign, model: str, settings: Settings) -> PackedArm:
    """Kernel arrays of ``arm`` for ``model`` and ``settings`` (cached on the design); a
    design made by :meth:`ArmDesign.scaled` gets its nominal's, rescaled."""
    scaled_from = arm._solver_cache.scaled_from
    if scaled_from is None:
        build = lambda: build_pack(arm, model, settings)  # noqa: E731
    else:
        build = lambda: _scaled_pack(arm, pack(scaled_from[0], model, settings), scaled_from[1])  # noqa: E731
    return arm._solver_cache.get(("pack", model, settings), build)


def _scaled_pack(arm: ArmDesign, nominal: PackedArm, factor: float) -> PackedArm:
    """The kernel arrays of ``arm`` = ``nominal``'s design scaled by :meth:`ArmDesign.scaled`:
    stiffness columns times ``factor``, compliances divided by it, the braid cosines of
    ``arm``'s tubes (equal to :func:`build_pack` of ``arm`` to rounding)."""
    secf = nominal.secf.copy()
    secf[L.EA] *= factor
    secf[L.EI] *= factor
    secf[L.CA] = 1.0 / secf[L.EA]
    secf[L.CI] = 1.0 / secf[L.EI]
    secf[L.CG] /= factor
    tubes_f = nominal.tubes_f.copy()
    tubes_f[:, L.TF_EAT] *= factor
    tubes_f[:, L.TF_E] *= factor
    tubes_f[:, L.TF_COS_ALPHA] = [math.cos(math.radians(t.material.wind_angle_deg)) for t in arm.tubes]
    return replace(nominal, secf=secf, tubes_f=tubes_f, c_j=nominal.c_j / factor,
                   moment_scale=nominal.moment_scale * factor)


def build_pack(arm: ArmDesign, model: str, settings: Settings) -> PackedArm:
    secs = arm.sections
    ns = len(secs)
    steps = np.full(ns, int(settings.steps_per_section), dtype=np.int64)
    tubes_i = np.zeros((len(arm.tubes), 3), dtype=np.int64)
    tubes_f = np.zeros((len(arm.tubes), 6))
    for k, t in enumerate(arm.tubes):
        mat = t.material
        a, b = t.offset
        tubes_i[k, [L.T_CHANNEL, L.T_FIRST, L.T_LAST]] = (t.channel, t.first_section,
                                                         t.last_section)
        tubes_f[k, [L.TF_EAT, L.TF_E, L.TF_AREA_RATIO, L.TF_COS_ALPHA, L.TF_A, L.TF_B]] = (
            mat.youngs_modulus * mat.area, mat.youngs_modulus,
            (mat.outer_radius**2 - mat.inner_radius**2) / mat.inner_radius**2,
            math.cos(math.radians(mat.wind_angle_deg)), a, b)
    ei = np.array([s.EI for s in secs])
    ea = np.array([s.EA for s in secs])
    secf = np.empty((L.N_SECF, ns))
    secf[L.LEN] = [s.length for s in secs]
    secf[L.CA] = 1.0 / ea
    secf[L.CG] = 0.0 if model == "unshearable" else [1.0 / s.GA for s in secs]
    secf[L.CI] = 1.0 / ei
    secf[L.EA] = ea
    secf[L.EI] = ei
    in_plane = [next((k for k, (_, idx) in enumerate(arm.planar_channels) if c in idx), -1)
                for c in range(arm.n_channels)]
    return PackedArm(
        key=("pack", model, settings),
        secf=secf,
        sec_steps=steps,
        c_j=np.array([1.0 / s.GJ for s in secs]),
        mass_per_length=np.array([s.mass_per_length for s in secs]),
        endplate=np.array([s.endplate_mass for s in secs]),
        tubes_i=tubes_i,
        tubes_f=tubes_f,
        moment_scale=series_moment_scale(secf[L.LEN], ei),
        n_rows=int(steps.sum() + ns),
        spatial_of_planar=np.array(in_plane, dtype=np.int64),
        section_ends=tuple(int(v) for v in np.cumsum(steps + 1) - 1),
    )


def series_moment_scale(lengths, stiffness) -> float:
    """(Σ L_i/K_i)⁻¹ (N m): the section moment scales K_i/L_i (K_i a bending or torsional
    stiffness, N m²) combined in series, as a moment applied at the tip loads every section.

    A residual moment r left at the tip by the shooting solve (or between two shooting nodes)
    turns the tip by r·Σ L_i/K_i: measured against this scale, a tolerance bounds that turn
    however the stiffnesses differ. The largest section's EI/L (the scale used before) let a
    stiff base section hide residuals that bend a soft distal one by radians (docs/design.md
    §11).
    """
    return float(1.0 / np.sum(np.asarray(lengths) / np.asarray(stiffness)))


def dead_loads(arm: ArmDesign, packed: PackedArm, scene: Scene, dim: int):
    """Section-end internal forces and distributed loads from global equilibrium.

    n(s) = F_tip + ∫_s^L f + Σ (point loads distal to s); n_end[i] is n just proximal of
    the end of section i, so it includes that section's endplate. Returns
    (n_end (ns, dim), q (ns, dim), M_tip (scalar planar or (3,) spatial)).
    """
    ns = len(arm.sections)
    g = np.zeros(dim)
    g[1] = -scene.gravity
    tip = scene.tip_force_3d()[:dim] + scene.payload_kg * g
    n_end = np.zeros((ns, dim))
    q = packed.mass_per_length[:, None] * g[None, :]
    running = tip.copy()
    for i in range(ns - 1, -1, -1):
        running = running + packed.endplate[i] * g
        n_end[i] = running
        running = running + q[i] * packed.sec_len[i]
    moment = scene.tip_moment_3d()
    return n_end, q, (float(moment[2]) if dim == 2 else moment)


def rest_strains(arm: ArmDesign, channel_pressures: np.ndarray, packed: PackedArm | None = None):
    """Rest curvatures (u1*, u2*) (rad/m) and stretch v3* of every section
    (docs/design.md §4).

    Args:
        arm: the design.
        channel_pressures: (n_channels,) spatial-channel pressures (Pa).

    Returns:
        (u1, u2, v3), each (n_sections,).
    """
    packed = packed or pack(arm, "full", DEFAULT_SETTINGS)
    rest = np.empty((3, len(arm.sections)))
    rest_strains_into(np.ascontiguousarray(channel_pressures, dtype=float), packed.tubes_i,
                      packed.tubes_f, packed.secf, rest)
    return rest[L.REST_U1], rest[L.REST_U2], rest[L.REST_V3]


def has_load(arm: ArmDesign, scene: Scene) -> bool:
    """Whether anything loads the arm (weight with gravity, a tip force or moment)."""
    weight = scene.gravity > 0 and (arm.mass > 0 or scene.payload_kg > 0)
    return bool(weight or np.any(scene.tip_force_3d()) or np.any(scene.tip_moment_3d()))


@dataclass(frozen=True)
class SceneContext:
    """Scene-dependent kernel inputs of one packed design (cached).

    ``loads`` (ns, 4|6) packs ``n_end`` and ``q`` (``NEX``… or ``SL_*``); ``params`` is the
    numeric parameter array of the path-following kernels (:mod:`solver.layout`).
    ``shooting_index`` is L·√(N/EI_min), N the largest internal force: single shooting
    amplifies an error in the base moment by up to e^index along a rod in tension.
    """

    n_end: np.ndarray
    q: np.ndarray
    loads: np.ndarray
    m_tip: float | np.ndarray
    tol: float
    max_step: float
    params: np.ndarray
    has_load: bool
    base_force: np.ndarray
    shooting_index: float


def context(arm: ArmDesign, packed: PackedArm, scene: Scene, dim: int,
            settings: Settings) -> SceneContext:
    """The :class:`SceneContext` of ``scene`` for ``packed`` (cached). ``settings`` must be
    the ones ``packed`` was built with (they are part of its key). A design made by
    :meth:`ArmDesign.scaled` shares its nominal's loads (the masses are unchanged). Obstacles
    do not enter a context, so it is keyed by the scene without them: a scene whose disc moves
    every step (a grasped object) does not fill the design's cache with copies."""
    scene = scene.without_contact
    key = ("scene", packed.key, scene, dim)
    hit = arm._solver_cache.peek(key)
    if hit is not None:
        return hit

    def build():
        scaled_from = arm._solver_cache.scaled_from
        if scaled_from is not None and packed.key[0] == "pack":
            nominal = scaled_from[0]
            loads = context(nominal, pack(nominal, *packed.key[1:]), scene, dim, settings)
            return _build_context(arm, packed, scene, dim, settings, loads)
        return _build_context(arm, packed, scene, dim, settings)

    return arm._solver_cache.get(key, build)


def _build_context(arm, packed, scene, dim, settings, loads: SceneContext | None = None) -> SceneContext:
    """The context of ``scene``; with ``loads``, the context of a design of the same masses
    in the same scene, its dead loads are reused."""
    if loads is None:
        n_end, q, m_tip = dead_loads(arm, packed, scene, dim)
        load_array = np.ascontiguousarray(np.hstack([n_end, q]))
        base_force = n_end[0] + q[0] * packed.sec_len[0]
        base_force.flags.writeable = False  # shared by every Equilibrium of this scene
        loaded = has_load(arm, scene)
    else:
        n_end, q, m_tip, load_array = loads.n_end, loads.q, loads.m_tip, loads.loads
        base_force, loaded = loads.base_force, loads.has_load
    # In 3D a residual also twists the sections: torsion enters the tolerance's series too.
    # The Newton step limit and the branch-jump floor stay on the bending series: they size
    # changes of the bending response (a jump to another branch is a fold or buckle), and on
    # the torsional scale (GJ < EI on the thesis's arms) every small warm step "jumped".
    moment = packed.moment_scale if dim == 2 else series_moment_scale(
        packed.sec_len, np.minimum(packed.sec_ei, 1.0 / packed.c_j))
    load_moment = float(np.abs(n_end).max() * arm.length) if n_end.size else 0.0
    tol = settings.tol * moment * max(1.0, load_moment / moment)
    bending = packed.moment_scale
    max_step = 2.0 * bending * max(1.0, load_moment / bending)
    n_norm, q_norm = _row_norms(n_end), _row_norms(q)
    params = np.empty(L.N_PARAMS)
    params[L.TOL] = tol
    params[L.MAX_STEP] = max_step
    params[L.M_BOUND] = _moment_bound(arm, packed, scene, float(np.max(n_norm + q_norm * packed.sec_len)))
    params[L.DT0] = settings.dt0
    params[L.DT_MIN] = settings.dt_min
    params[L.MAX_ITER] = settings.max_iter
    params[L.N_SCAN] = settings.n_scan
    params[L.JUMP] = 0.25 * packed.moment_scale
    params[L.PREDICT_CAP] = math.inf
    n_max = float(np.max(n_norm + q_norm * arm.length))
    return SceneContext(n_end=n_end, q=q, loads=load_array, m_tip=m_tip, tol=tol,
                        max_step=max_step, params=params, has_load=loaded, base_force=base_force,
                        shooting_index=arm.length * math.sqrt(n_max / float(packed.sec_ei.min())))


def _row_norms(a: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of ``a`` (k, 2|3)."""
    return np.sqrt(np.einsum("ij,ij->i", a, a))


def _moment_bound(arm, packed, scene, force_bound: float) -> float:
    """A bound on |m0| for the fold scan: |M_tip| + ∫|r'||n| ds over any pressures, with
    ``force_bound`` the largest internal force |n| (N) of the dead loads."""
    bound = float(np.linalg.norm(scene.tip_moment_3d())) + force_bound * _stretch_bound(
        arm, packed, force_bound) * arm.length
    return 1.05 * bound + packed.moment_scale * 1e-6


def _stretch_bound(arm, packed, force_bound: float) -> float:
    """A bound on |r'| over any pressures: v*max + |n|max/min(EA, GA), v*max the stretch at
    the rated pressure and |n|max ``force_bound``."""
    full = np.full(max(arm.n_channels, 1), arm.max_pressure) if arm.n_channels else np.zeros(1)
    v3 = rest_strains(arm, full, packed)[2] if arm.n_channels else np.ones(1)
    return float(v3.max()) + force_bound * float(max(packed.c_a.max(), packed.c_g.max()))


def reach(arm, packed, scene) -> float:
    """A bound (m) on the distance of any backbone point from the base, over all pressures:
    ∫|r'| ds with |r'| ≤ the stretch bound."""
    n_end, q, _ = dead_loads(arm, packed, scene, 2)
    return _stretch_bound(arm, packed, float(np.max(_row_norms(n_end) + _row_norms(q) * packed.sec_len))) \
        * arm.length


def contact_layout(arm, packed, scene):
    """Resolution and segments for contact solves (cached per packed design and stiffness):
    (layout, segment table, section start arc lengths).

    In contact, deflections vary over ℓ_i = (EI_i/k)^¼; RK4 steps are refined to
    h ≤ CONTACT_STEP·ℓ_i (at least the setting's count, at most 1024 per section; steps
    near a disc are subdivided further by the kernel, see :mod:`solver.kernels.contact`) and
    multiple-shooting segments span SEGMENT_STEPS steps.
    """
    stiffness = max([d.stiffness for d in scene.obstacles]
                    + ([scene.self_contact] if scene.self_contact is not None else []))
    key = ("contact", packed.key, stiffness)

    def build():
        ell = (packed.sec_ei / stiffness) ** 0.25
        steps = np.minimum(np.maximum(packed.sec_steps,
                                      np.ceil(packed.sec_len / (CONTACT_STEP * ell))), 1024)
        return _segments(packed.with_steps(steps, key))

    return arm._solver_cache.get(key, build)


def refined(arm, packed, steps):
    """``packed`` with ``steps`` (ns,) RK4 steps per section (cached): the finer grid a solve
    takes where the step-size check fails (:mod:`solver.kernels.grid`)."""
    steps = tuple(int(v) for v in steps)
    key = (*packed.key, "steps", steps)
    return arm._solver_cache.get(key, lambda: packed.with_steps(np.array(steps), key))


def shooting_layout(arm, packed):
    """Multiple-shooting segments at the settings' resolution (cached per packed design)."""
    return arm._solver_cache.get(("multiple", packed.key), lambda: _segments(packed))


def _segments(layout):
    steps = layout.sec_steps
    row0 = np.concatenate([[0], np.cumsum(steps + 1)[:-1]])
    segs = np.zeros((0, 5), dtype=np.int64)
    rows = []
    for i, n in enumerate(steps):
        for first in range(0, n, SEGMENT_STEPS):
            count = min(SEGMENT_STEPS, n - first)
            row = np.empty(5, dtype=np.int64)
            row[[L.SEG_SECTION, L.SEG_FIRST, L.SEG_STEPS, L.SEG_END, L.SEG_ROW0]] = (
                i, first, count, int(first + count == n), row0[i])
            rows.append(row)
    segs = np.array(rows, dtype=np.int64)
    sec_start = np.concatenate([[0.0], np.cumsum(layout.sec_len)[:-1]])
    return layout, segs, sec_start


def shooting_terms(arm, layout, segs, scene, ctx, load_moments):
    """Loads and norms of the multiple-shooting system: endplate weights (ns, 2), tip
    target (n(L⁻), M_tip), state scales and the unknowns' and residuals' weights.

    Moments are scaled by EI/L, or with ``load_moments`` by the larger of that and the load's
    moment force·L: for long, heavy arms the loads' moments dwarf EI/L, and Newton steps
    measured in EI/L are clipped to a crawl.
    """
    g = np.array([0.0, -scene.gravity])
    plate = layout.endplate[:, None] * g[None, :]
    target = np.append(ctx.n_end[-1], ctx.m_tip)  # n(L⁻) includes the last endplate
    force = float(np.abs(ctx.n_end).max() + np.abs(ctx.q).max() * arm.length) + 1.0
    moment = max(layout.moment_scale, force * arm.length) if load_moments else layout.moment_scale
    state_w = np.array([arm.length, arm.length, 1.0, force, force, moment])
    weights = np.concatenate([state_w[3:], np.tile(state_w, segs.shape[0] - 1)])
    res_weights = np.concatenate([np.tile(state_w, segs.shape[0] - 1), state_w[3:]])
    return plate, target, state_w, weights, res_weights


@dataclass(frozen=True, eq=False)
class Problem:
    """One solve request, validated (:func:`solver.inputs.request`): what every path of
    :mod:`solver.paths` takes instead of loose arguments.

    Attributes:
        arm: the design. packed: its kernel arrays for ``model`` and ``settings`` (or a
            refinement or layout of them).
        scene: mounting, loads and obstacles. model: one of :data:`solver.settings.MODELS`.
        planar: a planar (x–y) or a spatial solve.
        settings: the numerical settings ``packed`` was built with.
        p_inputs: (n_inputs,) input pressures (Pa). p_channel: (n_channels,) the spatial
            channels' (Pa).
        warm_start: the equilibrium the path starts from, or None (a cold solve).
        ctx: the :class:`SceneContext` of ``scene`` for ``packed`` in 2 (planar) or 3
            dimensions, derived: a problem made by :meth:`on` or :meth:`in_scene` (or
            ``dataclasses.replace``) gets its own.
    """

    arm: ArmDesign
    packed: PackedArm
    scene: Scene
    model: str
    planar: bool
    settings: Settings
    p_inputs: np.ndarray
    p_channel: np.ndarray
    warm_start: Equilibrium | None = None
    ctx: SceneContext = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "ctx", context(self.arm, self.packed, self.scene,
                                                2 if self.planar else 3, self.settings))

    @property
    def p_target(self) -> np.ndarray:
        """The channel pressures the kernels ramp to: ``p_channel``, or the (1,) placeholder
        of a passive rod."""
        return self.p_channel if self.arm.n_channels else np.zeros(1)

    def on(self, packed: PackedArm, settings: Settings | None = None) -> Problem:
        """This request on another grid or layout (``packed``), with its ``settings``."""
        if packed is self.packed and settings in (None, self.settings):
            return self
        return replace(self, packed=packed, settings=self.settings if settings is None else settings)

    def with_inputs(self, p_inputs: np.ndarray, p_channel: np.ndarray,
                    warm_start: Equilibrium | None = None) -> Problem:
        """This request at other (validated) pressures, from ``warm_start``: the same arm,
        grid and scene, so the same context (not looked up again)."""
        other = object.__new__(Problem)
        other.__dict__.update(self.__dict__, p_inputs=p_inputs, p_channel=p_channel,
                              warm_start=warm_start)
        return other

    def in_scene(self, scene: Scene, warm_start: Equilibrium | None = None) -> Problem:
        """This request in another scene (and from another warm start). A scene that differs
        only in its obstacles keeps the context (obstacles do not enter one): a grasped
        object's disc moves at every trial pose."""
        if scene.without_contact is not self.scene.without_contact \
                and scene.without_contact != self.scene.without_contact:
            return replace(self, scene=scene, warm_start=warm_start)
        other = object.__new__(Problem)
        other.__dict__.update(self.__dict__, scene=scene, warm_start=warm_start)
        return other

    def equilibrium(self, **fields) -> Equilibrium:
        """An :class:`Equilibrium` of this request: its arm, scene, model, mode and pressures,
        and ``fields``."""
        return Equilibrium._make(arm=self.arm, scene=self.scene, model=self.model,
                                 planar=self.planar, pressures=self.p_inputs,
                                 channel_pressures=self.p_channel, **fields)
