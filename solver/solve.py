"""Public solver API: :func:`solve`, :func:`solve_batch` and the :class:`Equilibrium` result.

Thin validated wrappers around the numba kernels of :mod:`solver._planar` and
:mod:`solver._spatial`. What a scene does not need is skipped:

* no gravity acting on mass, no payload, no tip load → closed-form arcs (every model);
* planar-symmetric pressures and an in-plane scene with ``planar=False`` → the planar
  kernel, embedded in 3D;
* ``record=False`` → no backbone samples, just the tip.

Policy for an unconverged solve: :func:`solve` returns an :class:`Equilibrium` with
``converged=False`` and the residual of the last iterate; its shape is that iterate's
(always finite for finite inputs). Pass ``strict=True`` to raise :class:`SolverError`
instead. Bad input raises ``ValueError`` naming the problem before any kernel runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from solver import _contact, _planar, _relax, _rod, _spatial
from solver.designs import ArmDesign
from solver.scene import Disc, Scene

__all__ = ["Equilibrium", "SolverError", "solve", "solve_batch", "step_batch", "BatchState",
           "channel_pressures",
           "MODELS", "Settings", "Disc"]

MODELS = ("full", "unshearable", "constant_curvature")


class SolverError(RuntimeError):
    """Raised by ``solve(..., strict=True)`` when no converged equilibrium was found."""


@dataclass(frozen=True)
class Settings:
    """Numerical settings of the shooting solver.

    Attributes:
        steps_per_section: fixed RK4 steps per section (error ∝ steps⁻⁴).
        tol: Newton tolerance on the tip-moment residual, relative to EI_max / L.
        max_iter: Newton iterations per continuation step.
        dt0, dt_min: first and smallest continuation step (fraction of the ramp).
        contact_dt_min: smallest continuation step of solves with obstacles: a stiff
            penalty makes contact paths turn sharply, and the step that may not tunnel
            through a disc is short where the backbone sweeps past one.
        n_scan: grid points of the fold scan over the base moment (0: no scan).
        gap_tol: deepest penetration (m) a rigid obstacle (``Disc(stiffness=math.inf)``) may
            be left with: its penalty is stiffened tenfold until the solve meets it (up to
            ``RIGID_MAX_STIFFNESS``; 1e-7 m is reachable for OctArm-sized arms).
        shortcuts: skip what a scene does not need (closed-form arcs when unloaded, the
            planar kernel for in-plane spatial solves). False forces the general path; the
            tests use it to check that each shortcut agrees with it.
    """

    steps_per_section: int = 16
    tol: float = 1e-10
    max_iter: int = 12
    dt0: float = 1.0
    dt_min: float = 1.0 / 256.0
    contact_dt_min: float = 1.0 / 16384.0
    n_scan: int = 96
    gap_tol: float = 1e-4
    shortcuts: bool = True

    def __post_init__(self):
        if int(self.steps_per_section) != self.steps_per_section or self.steps_per_section < 1:
            raise ValueError(f"steps_per_section must be an integer >= 1; got {self.steps_per_section}")
        if not (self.tol > 0 and self.max_iter >= 1 and 0 < self.dt_min <= self.dt0 <= 1
                and 0 < self.contact_dt_min <= self.dt0 and 0 < self.gap_tol
                and (self.n_scan == 0 or self.n_scan >= 4)):
            raise ValueError(f"invalid solver settings: {self}")

    @classmethod
    def without_fallback(cls, **kwargs) -> Settings:
        """Plain Newton from the start state: no continuation, no step halving, no fold scan.

        The stress test compares this against the default to show what the fallbacks buy.
        """
        return cls(dt0=1.0, dt_min=1.0, contact_dt_min=1.0, n_scan=0, **kwargs)


DEFAULT_SETTINGS = Settings()


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
        penetration: (N,) depth of the backbone inside the nearest obstacle (m, ≥ 0).
        in_contact: the backbone presses on an obstacle somewhere (False without obstacles).
        base_force: internal force n(0) at the base (N, world frame).
        pressures: the pressures solved for (Pa), in the order of ``design.input_names``.
        penalty_stiffness: with rigid obstacles, the penalty stiffness (N/m²) that met
            ``Settings.gap_tol`` (NaN otherwise).
        model, planar: what was solved.
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

    @property
    def tip_angle(self) -> float:
        """Planar tip orientation θ(L) (rad); NaN if not recorded or spatial."""
        return float(self.angles[-1]) if self.angles.size else math.nan


# ----------------------------------------------------------------------------- packing


@dataclass(frozen=True)
class _Packed:
    """A design unpacked to the float/int arrays the kernels take."""

    secf: np.ndarray
    sec_len: np.ndarray
    sec_steps: np.ndarray
    c_a: np.ndarray
    c_g: np.ndarray
    c_i: np.ndarray
    c_j: np.ndarray
    sec_ea: np.ndarray
    sec_ei: np.ndarray
    mass_per_length: np.ndarray
    endplate: np.ndarray
    tubes_i: np.ndarray
    tubes_f: np.ndarray
    moment_scale: float
    n_rows: int
    spatial_of_planar: np.ndarray
    section_ends: tuple


def _pack(arm: ArmDesign, model: str, settings: Settings) -> _Packed:
    """Kernel arrays of ``arm`` for ``model`` and ``settings``, cached on the design."""
    key = ("pack", model, settings)
    packed = arm._solver_cache.get(key)
    if packed is None:
        packed = arm._solver_cache[key] = _build_pack(arm, model, settings)
    return packed


def _build_pack(arm: ArmDesign, model: str, settings: Settings) -> _Packed:
    secs = arm.sections
    ns = len(secs)
    steps = np.full(ns, int(settings.steps_per_section), dtype=np.int64)
    tubes_i = np.zeros((len(arm.tubes), 3), dtype=np.int64)
    tubes_f = np.zeros((len(arm.tubes), 6))
    for k, t in enumerate(arm.tubes):
        mat = t.material
        a, b = t.offset
        tubes_i[k] = (t.channel, t.first_section, t.last_section)
        tubes_f[k] = (mat.youngs_modulus * mat.area, mat.youngs_modulus,
                      (mat.outer_radius**2 - mat.inner_radius**2) / mat.inner_radius**2,
                      math.cos(math.radians(mat.wind_angle_deg)), a, b)
    ei = np.array([s.EI for s in secs])
    ea = np.array([s.EA for s in secs])
    secf = np.vstack([
        [s.length for s in secs], 1.0 / ea,
        np.zeros(ns) if model == "unshearable" else [1.0 / s.GA for s in secs],
        1.0 / ei, ea, ei])
    in_plane = [next((k for k, (_, idx) in enumerate(arm.planar_channels) if c in idx), -1)
                for c in range(arm.n_channels)]
    return _Packed(
        secf=secf,
        sec_len=secf[_rod.LEN],
        sec_steps=steps,
        c_a=secf[_rod.CA],
        c_g=secf[_rod.CG],
        c_i=secf[_rod.CI],
        c_j=np.array([1.0 / s.GJ for s in secs]),
        sec_ea=secf[_rod.EA],
        sec_ei=secf[_rod.EI],
        mass_per_length=np.array([s.mass_per_length for s in secs]),
        endplate=np.array([s.endplate_mass for s in secs]),
        tubes_i=tubes_i,
        tubes_f=tubes_f,
        moment_scale=float(ei.max() / arm.length),
        n_rows=int(steps.sum() + ns),
        spatial_of_planar=np.array(in_plane, dtype=np.int64),
        section_ends=tuple(int(v) for v in np.cumsum(steps + 1) - 1),
    )


def _loads(arm: ArmDesign, packed: _Packed, scene: Scene, dim: int):
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


def _channel_pressures(arm: ArmDesign, pressures, planar: bool,
                       packed: _Packed) -> tuple[np.ndarray, np.ndarray]:
    """Validate input pressures and expand planar inputs to spatial channels (Pa)."""
    n = arm.n_inputs(planar)
    try:
        # A copy: the result keeps these pressures, so later edits by the caller cannot leak in.
        p = np.array(pressures, dtype=float)
    except (TypeError, ValueError):
        p = None
    if p is None or p.ndim != 1 or p.shape[0] != n:
        names = arm.input_names(planar)
        raise ValueError(
            f"design {arm.name!r} expects {n} pressures in {'planar' if planar else 'spatial'} "
            f"mode ({', '.join(names) or 'none: a passive rod'}); got "
            f"{np.array2string(np.asarray(pressures, dtype=object), max_line_width=10**6)}")
    # min/max are NaN if any entry is: one comparison each catches NaN, negatives and excess.
    if n and not (p.min() >= 0.0 and p.max() <= arm.max_pressure * (1 + 1e-12)):
        _explain_bad_pressures(arm, p, planar)
    if not planar:
        return p, p
    return p, p[packed.spatial_of_planar]


def channel_pressures(arm: ArmDesign, pressures, planar: bool = True) -> np.ndarray:
    """Validated spatial-channel pressures (Pa) from the inputs of ``arm`` in the given mode.

    Args:
        arm: the design.
        pressures: (n_inputs,) pressures (Pa), ordered as ``arm.input_names(planar)``.
        planar: whether ``pressures`` are planar inputs (expanded to their channels).

    Returns:
        (n_channels,) pressures, one per spatial channel.

    Raises:
        ValueError: wrong count, non-finite, negative or over-rated pressures.
    """
    return _channel_pressures(arm, pressures, planar, _pack(arm, "full", DEFAULT_SETTINGS))[1].copy()


def _explain_bad_pressures(arm, p, planar):
    names = arm.input_names(planar)
    bad = ~np.isfinite(p)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"pressure for channel {names[k]!r} is not finite: {p[k]}")
    if (p < 0).any():
        k = int(np.argmax(p < 0))
        raise ValueError(f"pressure for channel {names[k]!r} is negative ({p[k]:.6g} Pa); "
                         "channel pressures are gauge pressures >= 0")
    k = int(np.argmax(p > arm.max_pressure))
    raise ValueError(f"pressure for channel {names[k]!r} ({p[k]:.6g} Pa) exceeds the design's "
                     f"rated maximum {arm.max_pressure:.6g} Pa")


def _check(arm, scene, model, planar):
    if not isinstance(arm, ArmDesign):
        raise ValueError(f"arm must be a solver.designs.ArmDesign; got {type(arm).__name__}")
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a solver.Scene; got {type(scene).__name__}")
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    if planar and not scene.is_planar:
        raise ValueError("scene has out-of-plane loads (tip_force z or tip_moment x/y); "
                         "use planar=False")
    if planar and not arm.planar_channels and arm.tubes:
        raise ValueError(f"design {arm.name!r} defines no planar channels; use planar=False")


def rest_strains(arm: ArmDesign, channel_pressures: np.ndarray, packed: _Packed | None = None):
    """Rest curvatures (u1*, u2*) (rad/m) and stretch v3* of every section (DESIGN §2).

    Args:
        arm: the design.
        channel_pressures: (n_channels,) spatial-channel pressures (Pa).

    Returns:
        (u1, u2, v3), each (n_sections,).
    """
    packed = packed or _pack(arm, "full", DEFAULT_SETTINGS)
    rest = np.empty((3, len(arm.sections)))
    _rod._rest_strains(np.ascontiguousarray(channel_pressures, dtype=float), packed.tubes_i,
                          packed.tubes_f, packed.secf, rest)
    return rest[0], rest[1], rest[2]


def _has_load_cached(arm: ArmDesign, scene: Scene) -> bool:
    key = ("has_load", scene)
    hit = arm._solver_cache.get(key)
    if hit is None:
        hit = arm._solver_cache[key] = _has_load(arm, scene)
    return hit


def _has_load(arm: ArmDesign, scene: Scene) -> bool:
    weight = scene.gravity > 0 and (arm.mass > 0 or scene.payload_kg > 0)
    return bool(weight or np.any(scene.tip_force_3d()) or np.any(scene.tip_moment_3d()))


def _section_ends(packed: _Packed) -> tuple[int, ...]:
    """Sample indices of each section's end (recorded shapes repeat junction samples)."""
    return packed.section_ends


# ----------------------------------------------------------------------------- solve


def solve(arm: ArmDesign, pressures, scene: Scene | None = None, model: str = "full",
          planar: bool = True, warm_start: Equilibrium | None = None, record: bool = True,
          settings: Settings = DEFAULT_SETTINGS, strict: bool = False) -> Equilibrium:
    """Static equilibrium of ``arm`` at channel ``pressures`` in ``scene``.

    Without ``warm_start`` the equilibrium reached quasi-statically is returned: the
    unactuated arm is loaded (gravity, endplates, payload, tip loads ramped from zero), then
    all pressures are ramped proportionally from zero, following the stable branch
    (DESIGN §2 "Which equilibrium"). With ``warm_start`` the path from that equilibrium is
    followed the same way (the hysteresis is physical).

    Args:
        arm: the design (:mod:`solver.designs`).
        pressures: (n_inputs,) channel pressures in Pa, ordered as
            ``arm.input_names(planar)``; ``[]`` for a passive rod.
        scene: mounting and loads (default: hanging, gravity, no payload).
        model: ``"full"``, ``"unshearable"`` (GA → ∞) or ``"constant_curvature"``.
        planar: solve in the x–y plane (inputs are planar channels) or in 3D.
        warm_start: a previous equilibrium of the same arm, model and mode.
        record: return backbone samples (False: tip only, faster).
        settings: numerical settings.
        strict: raise :class:`SolverError` instead of returning an unconverged result.

    Returns:
        The :class:`Equilibrium`.
    """
    scene = Scene() if scene is None else scene
    _check(arm, scene, model, planar)
    packed = _pack(arm, model, settings)
    p_inputs, p_channel = _channel_pressures(arm, pressures, planar, packed)
    if warm_start is not None:
        _check_warm_start(warm_start, scene, model, planar, p_channel)
    if scene.obstacles and model != "constant_curvature":
        if not planar:
            raise ValueError("obstacles (contact) are supported in planar solves only")
        contact = _solve_rigid if scene.has_rigid_obstacles else _solve_contact
        eq = contact(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings)
    elif model == "constant_curvature" or (settings.shortcuts and not _has_load(arm, scene)):
        eq = _closed_form(arm, packed, p_inputs, p_channel, scene, model, planar, record)
    elif planar:
        eq = _solve_planar(arm, packed, p_inputs, p_channel, scene, model, warm_start, record,
                           settings)
    else:
        eq = None
        if settings.shortcuts and scene.is_planar and _in_plane(arm, packed, p_channel) and (
                warm_start is None or _in_plane_state(warm_start)):
            eq = _in_plane_shortcut(arm, packed, p_inputs, p_channel, scene, model, warm_start,
                                    record, settings)
        if eq is None:
            eq = _solve_spatial(arm, packed, p_inputs, p_channel, scene, model, warm_start,
                                record, settings)
    if strict and not eq.converged:
        raise SolverError(f"no converged equilibrium (residual {eq.residual:.3g} N m after "
                          f"{eq.iterations} iterations)")
    return eq


def _check_warm_start(warm_start, scene, model, planar, p_channel):
    if not isinstance(warm_start, Equilibrium):
        raise ValueError("warm_start must be an Equilibrium returned by solve()")
    if warm_start.planar != planar or warm_start.model != model or \
            warm_start.channel_pressures.shape != p_channel.shape:
        raise ValueError("warm_start comes from a different arm, model or planar mode")
    if warm_start.scene is not None and warm_start.scene.base_angle_deg != scene.base_angle_deg:
        raise ValueError("warm_start was solved at a different base angle")


def _closed_form(arm, packed, p_inputs, p_channel, scene, model, planar, record):
    """Unloaded arm (or the constant-curvature model): each section a circular arc.

    With no external load the internal force and moment vanish everywhere, so each section
    takes its rest strains exactly: curvature u*, stretch v*, no shear. Exact for every
    model; the ``constant_curvature`` model applies it whatever the loads.
    """
    u1, u2, v3 = rest_strains(arm, p_channel, packed)
    rot = _spatial.base_rotation(scene.base_theta)
    pos, frames, s = _spatial.arc_chain(rot, packed.sec_len, packed.sec_steps, u1, u2, v3,
                                        record)
    tip = pos[-1]
    common = dict(converged=True, stable=True, iterations=0, residual=0.0, model=model,
                  planar=planar, scene=scene, pressures=p_inputs, channel_pressures=p_channel,
                  base_moment=np.zeros(1 if planar else 3), base_force=np.zeros(2 if planar else 3))
    if not record:
        return Equilibrium(tip=tip[:2].copy() if planar else tip.copy(), **common)
    seg = np.repeat(np.arange(len(arm.sections)), packed.sec_steps + 1)
    n = len(s)
    if planar:
        # Continuous θ, as the shooting kernels integrate it (an arc can turn past ±π).
        theta = np.unwrap(np.arctan2(frames[:, 1, 2], frames[:, 0, 2]))
        return Equilibrium(
            tip=tip[:2].copy(), s=s, positions=pos[:, :2].copy(), angles=theta,
            shear_stretch=np.column_stack([np.zeros(n), v3[seg]]), curvature=u2[seg].copy(),
            internal_force=np.zeros((n, 2)), internal_moment=np.zeros(n),
            section_ends=_section_ends(packed), **common)
    return Equilibrium(
        tip=tip.copy(), s=s, positions=pos, orientations=frames,
        shear_stretch=np.column_stack([np.zeros(n), np.zeros(n), v3[seg]]),
        curvature=np.column_stack([u1[seg], u2[seg], np.zeros(n)]),
        internal_force=np.zeros((n, 3)), internal_moment=np.zeros((n, 3)),
        section_ends=_section_ends(packed), **common)


@dataclass(frozen=True)
class _SceneContext:
    """Scene-dependent kernel inputs of one design, model and settings (cached).

    ``loads`` (ns, 4) packs ``n_end`` and ``q``; ``params`` is the numeric parameter array of
    :mod:`solver._planar` (tolerance, step limit, fold-scan bound, continuation steps).
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


def _context(arm: ArmDesign, packed: _Packed, scene: Scene, dim: int,
             settings: Settings) -> _SceneContext:
    key = ("scene", id(packed), scene, dim)
    ctx = arm._solver_cache.get(key)
    if ctx is None:
        n_end, q, m_tip = _loads(arm, packed, scene, dim)
        scale = float(np.abs(n_end).max() * arm.length / packed.moment_scale) if n_end.size else 0.0
        grow = max(1.0, scale)
        tol = settings.tol * packed.moment_scale * grow
        max_step = 2.0 * packed.moment_scale * grow
        params = np.empty(_rod.N_PARAMS)
        params[[_rod.TOL, _rod.MAX_STEP, _rod.M_BOUND, _rod.DT0, _rod.DT_MIN,
                _rod.MAX_ITER, _rod.N_SCAN, _rod.JUMP]] = (
            tol, max_step, _moment_bound(arm, packed, scene, n_end, q), settings.dt0,
            settings.dt_min, settings.max_iter, settings.n_scan, 0.25 * packed.moment_scale)
        ctx = _SceneContext(n_end=n_end, q=q, loads=np.ascontiguousarray(np.hstack([n_end, q])),
                            m_tip=m_tip, tol=tol,
                            max_step=max_step, params=params, has_load=_has_load(arm, scene),
                            base_force=n_end[0] + q[0] * packed.sec_len[0],
                            shooting_index=_shooting_index(arm, n_end, q))
        ctx.base_force.flags.writeable = False  # shared by every Equilibrium of this scene
        if len(arm._solver_cache) > 256:  # many scenes (randomised payloads): keep it bounded
            arm._solver_cache.clear()
        arm._solver_cache[key] = ctx
    return ctx


def _moment_bound(arm, packed, scene, n_end, q):
    """A bound on |m0| for the fold scan: |M_tip| + ∫|r'||n| ds over any pressures."""
    nmax = _force_bound(packed, n_end, q)
    bound = float(np.linalg.norm(scene.tip_moment_3d())) + nmax * _stretch_bound(
        arm, packed, n_end, q) * arm.length
    return 1.05 * bound + packed.moment_scale * 1e-6


def _force_bound(packed, n_end, q) -> float:
    """The largest internal force |n| (N) of dead loads ``n_end``, ``q`` (ns, 2|3)."""
    return float(np.max(np.linalg.norm(n_end, axis=1)
                        + np.linalg.norm(q, axis=1) * packed.sec_len))


def _stretch_bound(arm, packed, n_end, q) -> float:
    """A bound on |r'| over any pressures: v*max + |n|max/min(EA, GA), v*max the stretch at
    the rated pressure."""
    full = np.full(max(arm.n_channels, 1), arm.max_pressure) if arm.n_channels else np.zeros(1)
    v3 = rest_strains(arm, full, packed)[2] if arm.n_channels else np.ones(1)
    return float(v3.max()) + _force_bound(packed, n_end, q) * float(
        max(packed.c_a.max(), packed.c_g.max()))


def _follow(packed, scene, p_start, p_target, start_ctx, ctx, m0, out=None, guard_3d=False,
            guard_discs=_planar._NO_DISCS):
    """Run :func:`solver._planar._follow`; returns its tuple plus the scratch (rest, loads_now).

    With ``out`` ((n_rows, N_COLUMNS)) a converged result's backbone is recorded into it;
    with ``guard_3d`` every accepted state must be stable in 3D too (the in-plane shortcut
    of a spatial solve); with ``guard_discs`` ((k, 4)) the path must stay clear of them
    (the contact-free shortcut of a scene with obstacles).
    """
    ns = packed.secf.shape[1]
    rest, p_now, loads_now = np.empty((3, ns)), np.empty(p_target.shape[0]), np.empty((ns, 4))
    result = _planar._follow(m0, scene.base_theta, packed.secf, packed.sec_steps, packed.tubes_i,
                             packed.tubes_f, p_start, p_target, start_ctx.loads, ctx.loads,
                             start_ctx.m_tip, ctx.m_tip, ctx.params, rest, p_now, loads_now,
                             _DUMMY if out is None else out, out is not None,
                             packed.c_j if guard_3d else _planar._NO_GUARD, guard_discs)
    return result, rest, loads_now


_DUMMY = np.empty((1, _planar.N_COLUMNS))


def _loaded_base_moment(arm, packed, scene, ctx, settings, guard_3d=False,
                        guard_discs=_planar._NO_DISCS) -> tuple[float, int, bool, bool]:
    """Stage 1 of a cold solve: the unactuated arm under its loads ramped from zero (cached).

    Returns (m0, iterations, snapped, converged); with a guard (see :func:`_follow`)
    converged means also that the guard held all along.
    """
    key = ("loaded", id(ctx), settings, guard_3d, guard_discs.tobytes())
    hit = arm._solver_cache.get(key)
    if hit is None:
        zeros = np.zeros(max(arm.n_channels, 1))
        unloaded = _SceneContext(n_end=ctx.n_end * 0, q=ctx.q * 0, loads=ctx.loads * 0,
                                 m_tip=0.0, tol=ctx.tol, max_step=ctx.max_step,
                                 params=ctx.params, has_load=False, base_force=ctx.base_force * 0,
                                 shooting_index=0.0)
        out, _, _ = _follow(packed, scene, zeros, zeros, unloaded, ctx, 0.0, guard_3d=guard_3d,
                            guard_discs=guard_discs)
        hit = arm._solver_cache[key] = (float(out[0]), int(out[2]), bool(out[3]), bool(out[1]))
    return hit


def _solve_planar(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings):
    """Planar dead-load solve: single shooting, or multiple shooting where that is
    ill-conditioned or has failed (with the fallbacks on: ``settings.n_scan > 0``)."""
    fallbacks = settings.n_scan > 0 and model != "constant_curvature"
    ctx = _context(arm, packed, scene, 2, settings)
    methods = (_solve_single, _solve_multiple)
    if fallbacks and ctx.shooting_index > MULTIPLE_SHOOTING_INDEX:
        methods = methods[::-1]
    args = (arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings)
    eq = methods[0](*args)
    if fallbacks and not (eq.converged and eq.stable):
        # Each method covers the other's failures: multiple shooting the ill-conditioned
        # arms, single shooting (which has the fold scan) the buckled columns.
        other = methods[1](*args)
        if other.converged and other.stable:
            return replace(other, iterations=other.iterations + eq.iterations)
    return eq


def _solve_single(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings,
                  guard_3d=False, guard_discs=_planar._NO_DISCS):
    """Planar dead-load solve by single shooting on m0 (:func:`solver._planar._follow`).

    With ``guard_3d`` (the in-plane shortcut of a spatial solve) the result is unconverged
    as soon as the path leaves the states that are stable in 3D, loading stage included;
    with ``guard_discs`` (the contact-free shortcut) as soon as it comes within half an RK4
    step of a disc.
    """
    ctx = _context(arm, packed, scene, 2, settings)
    p_target = p_channel if arm.n_channels else np.zeros(1)
    iterations = 0
    snapped = False
    if warm_start is not None and warm_start.scene is not None:
        start_ctx = ctx if warm_start.scene == scene else \
            _context(arm, packed, warm_start.scene, 2, settings)
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        m0 = float(warm_start.base_moment[-1])  # planar m_z, or z of a spatial m0
    else:
        m0, iterations, snapped, loaded = _loaded_base_moment(arm, packed, scene, ctx, settings,
                                                              guard_3d, guard_discs)
        if (guard_3d or guard_discs.size) and not loaded:
            return Equilibrium(tip=np.full(2, np.nan), converged=False, stable=False,
                               iterations=iterations, residual=math.inf)
        start_ctx, p_start = ctx, np.zeros_like(p_target)
    out = np.empty((packed.n_rows, _planar.N_COLUMNS)) if record else None
    (m0, ok, its, snap, stab, res, x, y, th), rest, loads_now = _follow(
        packed, scene, p_start, p_target, start_ctx, ctx, m0, out, guard_3d, guard_discs)
    common_out = dict(converged=bool(ok), stable=bool(stab), iterations=int(iterations + its),
                      residual=float(res), snapped=bool(snapped or snap), model=model,
                      planar=True, scene=scene, pressures=p_inputs, channel_pressures=p_channel,
                      base_moment=np.array([m0]), base_force=ctx.base_force)
    if not record:
        return Equilibrium(tip=np.array([x, y]), **common_out)
    if not ok:  # the returned (last good) state was not recorded by a final Newton pass
        _planar._integrate(m0, scene.base_theta, packed.secf, packed.sec_steps, rest, loads_now,
                           True, out)
    P = _planar  # the result's arrays are views into this one record
    return Equilibrium(
        tip=out[-1, P.X:P.Y + 1].copy(), s=out[:, P.S], positions=out[:, P.X:P.Y + 1],
        angles=out[:, P.THETA], shear_stretch=out[:, P.V1:P.V3 + 1], curvature=out[:, P.U],
        internal_force=out[:, P.NX:P.NY + 1], internal_moment=out[:, P.M],
        section_ends=_section_ends(packed), **common_out)


def _batch_inputs(arm, pressures, scene, model, planar, settings):
    """Validated (packed, planar pressures (n, n_inputs), channel pressures) for batch calls."""
    scene = Scene() if scene is None else scene
    _check(arm, scene, model, planar)
    packed = _pack(arm, model, settings)
    p = np.asarray(pressures, dtype=float)
    if p.ndim != 2 or p.shape[1] != arm.n_inputs(planar):
        raise ValueError(f"pressures must have shape (n, {arm.n_inputs(planar)}); got {p.shape}")
    for row in p[~np.all((p >= 0) & (p <= arm.max_pressure * (1 + 1e-12)), axis=1)][:1]:
        _explain_bad_pressures(arm, row, planar)
    channel = p[:, packed.spatial_of_planar] if arm.n_channels else np.zeros((p.shape[0], 1))
    return scene, packed, p, np.ascontiguousarray(channel)


def solve_batch(arm: ArmDesign, pressures, scene: Scene | None = None, model: str = "full",
                planar: bool = True, settings: Settings = DEFAULT_SETTINGS):
    """Tip positions for many pressure vectors, in parallel over the cores.

    Every row gets the equilibrium :func:`solve` (cold) would return for it, so a sweep's
    result does not depend on its order.

    Args:
        arm, scene, model, planar, settings: as in :func:`solve`.
        pressures: (n, n_inputs) channel pressures (Pa).

    Returns:
        ``(tips, converged)``: (n, 2|3) tip positions (m) and (n,) bool.
    """
    scene, packed, p, channel = _batch_inputs(arm, pressures, scene, model, planar, settings)
    general = model != "constant_curvature" and (_has_load(arm, scene) or not settings.shortcuts)
    if planar and not general and not scene.obstacles:
        tips = np.empty((p.shape[0], 2))
        _planar._arc_tips(scene.base_theta, packed.secf, packed.tubes_i, packed.tubes_f, channel,
                          tips)
        return tips, np.ones(p.shape[0], dtype=bool)
    if not (general and planar) or scene.obstacles:
        dim = 2 if planar else 3
        tips = np.empty((p.shape[0], dim))
        ok = np.empty(p.shape[0], dtype=bool)
        for k in range(p.shape[0]):
            eq = solve(arm, p[k], scene, model, planar, record=False, settings=settings)
            tips[k] = eq.tip
            ok[k] = eq.converged
        return tips, ok
    ctx = _context(arm, packed, scene, 2, settings)
    m0 = _loaded_base_moment(arm, packed, scene, ctx, settings)[0]
    n = p.shape[0]
    tips, ok = np.empty((n, 2)), np.empty(n, dtype=bool)
    _planar._batch(np.full(n, m0), np.zeros_like(channel), scene.base_theta, packed.secf,
                   packed.sec_steps, packed.tubes_i, packed.tubes_f, channel, ctx.loads, ctx.m_tip,
                   ctx.params, False, tips, ok, np.empty(n, dtype=bool), np.empty(n),
                   np.empty((n, 1, _planar.N_COLUMNS)))
    return tips, ok


@dataclass
class BatchState:
    """Equilibria of n copies of one arm in one scene, stepped together by :func:`step_batch`.

    Attributes:
        pressures: (n, n_inputs) planar channel pressures of each copy (Pa).
        tips: (n, 2) tip positions (m).
        converged: (n,) whether the last step of each copy converged (a copy that did not
            kept its previous state).
        shapes: (n, N, 10) recorded backbones when stepped with ``record=True``: columns s, x,
            y, θ, m, n_x, n_y, v1, v3, u (see :mod:`solver._planar`); else (n, 1, 10) scratch.
        section_ends: sample indices of the section ends in ``shapes``.
    """

    pressures: np.ndarray
    tips: np.ndarray
    converged: np.ndarray
    shapes: np.ndarray
    section_ends: tuple
    base_moment: np.ndarray = field(repr=False, default=None)
    channel_pressures: np.ndarray = field(repr=False, default=None)


def step_batch(arm: ArmDesign, pressures, scene: Scene | None = None,
               state: BatchState | None = None, model: str = "full", record: bool = False,
               settings: Settings = DEFAULT_SETTINGS) -> BatchState:
    """Move n copies of an arm quasi-statically to new pressures, in parallel (planar).

    Each copy follows the path from its equilibrium in ``state`` (or, without a state, from
    the loaded unactuated arm — a cold solve, as :func:`solve` does). A copy whose step does
    not converge keeps its previous equilibrium and is flagged in ``converged``. This is the
    engine of the batched vector environment.

    Args:
        arm, scene, model, settings: as in :func:`solve` (no obstacles).
        pressures: (n, n_inputs) planar channel pressures (Pa).
        state: the copies' current equilibria (from a previous call), or None.
        record: also return every copy's backbone in ``shapes``.

    Returns:
        The new :class:`BatchState`.
    """
    scene, packed, p, channel = _batch_inputs(arm, pressures, scene, model, True, settings)
    if scene.obstacles:
        raise ValueError("step_batch does not model contact; use solve() for scenes with obstacles")
    ctx = _context(arm, packed, scene, 2, settings)
    n = p.shape[0]
    if state is None:
        m0 = _loaded_base_moment(arm, packed, scene, ctx, settings)[0]
        m_start, p_start, p_prev = np.full(n, m0), np.zeros_like(channel), np.zeros_like(p)
    else:
        if state.base_moment.shape != (n,):
            raise ValueError(f"state holds {state.base_moment.shape[0]} arms; pressures has {n} rows")
        m_start, p_start, p_prev = state.base_moment, state.channel_pressures, state.pressures
    tips, ok, m0_out = np.empty((n, 2)), np.empty(n, dtype=bool), np.empty(n)
    shapes = np.empty((n, packed.n_rows if record else 1, _planar.N_COLUMNS))
    _planar._batch(m_start, p_start, scene.base_theta, packed.secf, packed.sec_steps,
                   packed.tubes_i, packed.tubes_f, channel, ctx.loads, ctx.m_tip, ctx.params,
                   record, tips, ok, np.empty(n, dtype=bool), m0_out, shapes)
    keep = ~ok[:, None]
    return BatchState(pressures=np.where(keep, p_prev, p), tips=tips, converged=ok, shapes=shapes,
                      section_ends=packed.section_ends, base_moment=m0_out,
                      channel_pressures=np.where(keep, p_start, channel))


def _in_plane_shortcut(arm, packed, p_inputs, p_channel, scene, model, warm_start, record,
                       settings):
    """A spatial solve of an in-plane scene by the planar kernel, or None where that could
    differ from the spatial path: the planar path must stay stable in 3D at every accepted
    state (an arm curled in a vertical plane may buckle sideways), pass no fold, and single
    shooting must suit the arm; otherwise the spatial kernels solve it (None)."""
    ctx = _context(arm, packed, scene, 2, settings)
    if ctx.shooting_index > MULTIPLE_SHOOTING_INDEX:
        return None
    eq = _solve_single(arm, packed, p_inputs, p_channel, scene, model, warm_start, record,
                       settings, guard_3d=True)
    return _embed(eq) if eq.converged and eq.stable else None


def _in_plane_state(eq: Equilibrium) -> bool:
    """True when a spatial equilibrium lies in the x–y plane (base moment along z only)."""
    return bool(eq.base_moment.size == 3 and eq.base_moment[0] == 0.0
                and eq.base_moment[1] == 0.0)


def _in_plane(arm, packed, p_channel) -> bool:
    """True when the pressures bend every section in the x–y plane only (u1* = 0)."""
    u1, u2, v3 = rest_strains(arm, p_channel, packed)
    return bool(np.all(np.abs(u1) <= 1e-12 * (1.0 + np.abs(u2))))


def _embed(eq: Equilibrium) -> Equilibrium:
    """A planar equilibrium expressed in 3D (z = 0, d2 = +z)."""
    n = eq.s.size
    pad = np.zeros((n, 1))
    c, s = np.cos(eq.angles), np.sin(eq.angles)
    frames = np.zeros((n, 3, 3))
    frames[:, 0, 0], frames[:, 1, 0] = -s, c
    frames[:, 2, 1] = 1.0
    frames[:, 0, 2], frames[:, 1, 2] = c, s
    return replace(
        eq, tip=np.append(eq.tip, 0.0), planar=False,
        positions=np.hstack([eq.positions, pad]), angles=np.empty(0), orientations=frames,
        shear_stretch=np.column_stack([eq.shear_stretch[:, 0], pad[:, 0], eq.shear_stretch[:, 1]])
        if n else np.empty((0, 3)),
        curvature=np.column_stack([pad[:, 0], eq.curvature, pad[:, 0]]) if n else np.empty((0, 3)),
        internal_force=np.hstack([eq.internal_force, pad]) if n else np.empty((0, 3)),
        internal_moment=np.column_stack([pad[:, 0], pad[:, 0], eq.internal_moment])
        if n else np.empty((0, 3)),
        base_moment=np.array([0.0, 0.0, eq.base_moment[-1]]))


def _solve_spatial(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings):
    ctx = _context(arm, packed, scene, 3, settings)
    rot0 = _spatial.base_rotation(scene.base_theta)
    quat0 = np.empty(4)
    _spatial._rot_to_quat(rot0, quat0)
    p_target = p_channel if arm.n_channels else np.zeros(1)
    ns = len(arm.sections)
    rest, p_now, loads_now, m_tip = (np.empty((3, ns)), np.empty(p_target.shape[0]),
                                     np.empty((ns, 6)), np.empty(3))

    iterations = 0
    snap_load = False
    m0 = np.zeros(3)
    if warm_start is not None and warm_start.scene is not None:
        start = _context(arm, packed, warm_start.scene, 3, settings)
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        m0[-warm_start.base_moment.size:] = warm_start.base_moment
        start_loads, start_mtip = start.loads, start.m_tip
    else:
        # Stage 1: load the unactuated arm (loads ramped from zero, straight rod, m0 = 0).
        p_start = np.zeros_like(p_target)
        ok, its, stab, res, snap_load = _spatial._follow(
            m0, quat0, packed.secf, packed.sec_steps, packed.c_j, packed.tubes_i, packed.tubes_f,
            p_start, p_start, np.zeros_like(ctx.loads), ctx.loads, np.zeros(3), ctx.m_tip,
            ctx.params, rest, p_now, loads_now, m_tip)
        iterations += its
        start_loads, start_mtip = ctx.loads, ctx.m_tip
    ok, its, stab, res, snapped = _spatial._follow(
        m0, quat0, packed.secf, packed.sec_steps, packed.c_j, packed.tubes_i, packed.tubes_f,
        p_start, p_target, start_loads, ctx.loads, start_mtip, ctx.m_tip, ctx.params, rest, p_now,
        loads_now, m_tip)
    iterations += its
    rows = packed.n_rows if record else 1
    pos, rot, mom = np.zeros((rows, 3)), np.zeros((rows, 3, 3)), np.zeros((rows, 3))
    work = np.empty((6, _spatial.NSTATE))
    _spatial._integrate(m0, quat0, packed.secf, packed.sec_steps, packed.c_j, rest, loads_now,
                        record, pos, rot, mom, work)
    y = work[0]
    res = float(np.linalg.norm(y[7:10] - m_tip))
    # ``stab`` is _stability of the returned state, from the Newton pass that converged on it.
    common_out = dict(tip=y[0:3].copy(), converged=bool(ok and res <= 10 * ctx.tol),
                      stable=bool(stab), iterations=int(iterations), residual=res,
                      snapped=bool(snapped or snap_load), model=model, planar=False,
                      scene=scene, pressures=p_inputs, channel_pressures=p_channel, base_moment=m0.copy(),
                      base_force=ctx.base_force)
    if not record:
        return Equilibrium(**common_out)
    seg = np.repeat(np.arange(ns), packed.sec_steps + 1)
    starts = np.concatenate([[0.0], np.cumsum(packed.sec_len)[:-1]])
    s = np.concatenate([np.linspace(0, L, k + 1) + off for L, k, off in
                        zip(packed.sec_len, packed.sec_steps, starts)])
    local = s - starts[seg]
    force = ctx.n_end[seg] + ctx.q[seg] * (packed.sec_len[seg] - local)[:, None]
    nb = np.einsum("nji,nj->ni", rot, force)
    mb = np.einsum("nji,nj->ni", rot, mom)
    u1, u2, v3 = rest
    strain_v = np.column_stack([nb[:, 0] * packed.c_g[seg], nb[:, 1] * packed.c_g[seg],
                                v3[seg] + nb[:, 2] * packed.c_a[seg]])
    strain_u = np.column_stack([u1[seg] + mb[:, 0] * packed.c_i[seg],
                                u2[seg] + mb[:, 1] * packed.c_i[seg], mb[:, 2] * packed.c_j[seg]])
    return Equilibrium(s=s, positions=pos, orientations=rot, shear_stretch=strain_v,
                       curvature=strain_u, internal_force=force, internal_moment=mom,
                       section_ends=_section_ends(packed), **common_out)


# RK4 step in contact, as a fraction of the decay length ℓ = (EI/k)^¼ (see _contact_layout);
# the kernel refines steps that may reach a disc (solver._contact.NEAR_SUBSTEPS).
CONTACT_STEP = 0.5


def _contact_layout(arm, packed, scene):
    """Resolution and segments for contact solves (cached per design, settings, stiffness).

    In contact, deflections vary over ℓ_i = (EI_i/k)^¼; RK4 steps are refined to
    h ≤ CONTACT_STEP·ℓ_i (at least the setting's count, at most 1024 per section; steps
    near a disc are subdivided further by the kernel, see :mod:`solver._contact`) and
    multiple-shooting segments span 4 steps.
    """
    stiffness = max(d.stiffness for d in scene.obstacles)
    key = ("contact", id(packed), stiffness)
    hit = arm._solver_cache.get(key)
    if hit is None:
        ell = (packed.sec_ei / stiffness) ** 0.25
        steps = np.minimum(np.maximum(packed.sec_steps,
                                      np.ceil(packed.sec_len / (CONTACT_STEP * ell))),
                           1024).astype(np.int64)
        layout = replace(packed, sec_steps=steps, n_rows=int((steps + 1).sum()),
                         section_ends=tuple(int(v) for v in np.cumsum(steps + 1) - 1))
        hit = arm._solver_cache[key] = _segments(layout)
    return hit


def _segments(layout):
    """(layout, segment table, section start arc lengths): 4 RK4 steps per segment."""
    steps = layout.sec_steps
    row0 = np.concatenate([[0], np.cumsum(steps + 1)[:-1]])
    segs = []
    for i, n in enumerate(steps):
        for first in range(0, n, 4):
            count = min(4, n - first)
            segs.append((i, first, count, int(first + count == n), row0[i]))
    sec_start = np.concatenate([[0.0], np.cumsum(layout.sec_len)[:-1]])
    return layout, np.array(segs, dtype=np.int64), sec_start


def _ms_terms(arm, layout, segs, scene, ctx, load_moments):
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


def _shooting_index(arm, n_end, q) -> float:
    """L·√(N/EI_min), N the largest internal force (section-end forces ``n_end`` and
    distributed loads ``q``, (ns, 2|3)): single shooting amplifies an error in the base
    moment by up to e^index along a rod in tension."""
    n_max = float(np.max(np.linalg.norm(n_end, axis=1) + np.linalg.norm(q, axis=1) * arm.length))
    return arm.length * math.sqrt(n_max / min(s.EI for s in arm.sections))


# Above this index single shooting fails on most arms (``softarm stress``, huge_arm and soft
# classes: 95 % of solves converge below 20, 5 % above 30), so dead-load solves go straight
# to multiple shooting.
MULTIPLE_SHOOTING_INDEX = 20.0


def _solve_multiple(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings):
    """Planar dead-load solve by multiple shooting (the contact kernels, with no discs).

    For arms whose single shooting is ill-conditioned (:func:`_shooting_index`), and as the
    fallback of a failed single-shooting solve; see :func:`_solve_shooting`.
    """
    layout, segs, sec_start = _ms_layout(arm, packed)
    return _solve_shooting(arm, layout, segs, sec_start, p_inputs, p_channel, scene, model,
                           warm_start, record, settings, load_moments=True)


# Penalty continuation for rigid obstacles (Disc(stiffness=math.inf)): the first penalty
# makes the decay length (EI/k)^¼ a twentieth of the arm; each stage stiffens it tenfold, up
# to RIGID_MAX_STIFFNESS (OctArm V pressed into a disc: 1e-5 m of penetration at 1.2e8 N/m²,
# 2e-7 m at 1.2e10).
RIGID_GROWTH = 10.0
RIGID_MAX_STIFFNESS = 1e11


def _solve_rigid(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings):
    """A solve with rigid obstacles (hard contact) by penalty continuation.

    The rigid discs get a finite penalty k: from a warm start its final one, else the k
    at which the decay length (EI_min/k)^¼ is L/20. After each solve, while the deepest
    penetration exceeds ``settings.gap_tol``, k is multiplied by RIGID_GROWTH and the
    solve continues from the last state, the penalty ramped up along the path (the
    homotopy of :func:`_solve_shooting`). The penetration falls as 1/k and the state
    converges to the hard-contact limit (tested). If the penetration is still above
    ``gap_tol`` where the next stage would pass RIGID_MAX_STIFFNESS, or a stage does not
    converge (the last converged stage is then returned), the result is reported
    unconverged.
    """
    warm_k = warm_start.penalty_stiffness if warm_start is not None else math.nan
    stiffness = warm_k if math.isfinite(warm_k) else min(
        s.EI for s in arm.sections) * (20.0 / arm.length) ** 4
    eq = warm_start
    iterations = 0
    while True:
        stage = replace(scene, obstacles=tuple(
            replace(d, stiffness=stiffness) if d.stiffness == math.inf else d
            for d in scene.obstacles))
        attempt = _solve_contact(arm, packed, p_inputs, p_channel, stage, model, eq, True,
                                 settings)
        iterations += attempt.iterations
        if not attempt.converged:
            # Keep the last stage that converged (stiffness one step back), reported as not
            # meeting the tolerance; a first stage that fails is returned as it is.
            if eq is None or eq is warm_start:
                eq, met = attempt, False
            else:
                stiffness /= RIGID_GROWTH
                met = False
            break
        eq = attempt
        deepest = float(eq.penetration.max()) if eq.penetration.size else 0.0
        met = deepest <= settings.gap_tol
        if met or stiffness * RIGID_GROWTH > RIGID_MAX_STIFFNESS:
            break
        stiffness *= RIGID_GROWTH
    eq = replace(eq, scene=scene, penalty_stiffness=stiffness, iterations=iterations,
                 converged=bool(eq.converged and met))
    return eq if record else _unrecorded(eq)


def _unrecorded(eq):
    """``eq`` without its backbone samples (a solve with ``record=False``)."""
    return Equilibrium(**{f: getattr(eq, f) for f in (
        "tip", "converged", "stable", "iterations", "residual", "snapped", "in_contact",
        "base_force", "pressures", "model", "planar", "base_moment", "shooting_nodes", "scene",
        "channel_pressures", "penalty_stiffness")})


def _effective_discs(scene, stiffness):
    """The scene's discs as a kernel array, rigid ones at the penalty ``stiffness``."""
    discs = scene.discs_array()
    discs[discs[:, 3] == math.inf, 3] = stiffness
    return discs


def _solve_contact(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings):
    """Planar solve with penalty contact against the scene's discs (:mod:`solver._contact`).

    Multiple shooting at the contact resolution (:func:`_contact_layout`), obstacles present
    all along the quasi-static path (:func:`_solve_shooting`).

    Shortcuts (``settings.shortcuts``), each exact:

    * no disc within the arm's reach (:func:`_reach`): the contact-free solve;
    * a cold solve, or a warm step from a state that touched nothing: single shooting
      without contact, guarded — if the backbone stays clear of every disc by half an RK4
      step at every accepted state (loading stage included) and no sample passes through a
      disc between them (:func:`solver._planar._follow`), the contact-free path *is* the
      path with obstacles (every penalty force is zero along it), obtained in tens of
      microseconds instead of milliseconds. Otherwise the contact kernels follow the path.
      The shortcut solves at the settings' resolution, the contact kernels at the finer
      contact resolution; the two agree to the coarser one's discretisation error.
    """
    free_scene = replace(scene, obstacles=())
    if settings.shortcuts:
        discs = scene.discs_array()
        if np.all(np.hypot(discs[:, 0], discs[:, 1]) - discs[:, 2] > _reach(arm, packed, scene)):
            free = _solve_planar(arm, packed, p_inputs, p_channel, free_scene, model, warm_start,
                                 record, settings)
            return _free_contact_result(free, scene)
        if warm_start is None or not warm_start.in_contact:
            free = _solve_single(arm, packed, p_inputs, p_channel, free_scene, model, warm_start,
                                 True, settings, guard_discs=discs)
            if free.converged and free.stable:
                return _free_contact_result(free, scene)
    layout, segs, sec_start = _contact_layout(arm, packed, scene)
    return _solve_shooting(arm, layout, segs, sec_start, p_inputs, p_channel, scene, model,
                           warm_start, record, settings, load_moments=False)


def _free_contact_result(eq, scene):
    """A contact-free equilibrium as the result of a solve in ``scene`` (zero contact)."""
    n = eq.positions.shape[0]
    return replace(eq, scene=scene, contact_force=np.zeros((n, 2)), penetration=np.zeros(n))


def _reach(arm, packed, scene) -> float:
    """A bound (m) on the distance of any backbone point from the base, over all pressures:
    ∫|r'| ds with |r'| ≤ the stretch bound of :func:`_stretch_bound`."""
    ctx = _context(arm, packed, replace(scene, obstacles=()), 2, DEFAULT_SETTINGS)
    return _stretch_bound(arm, packed, ctx.n_end, ctx.q) * arm.length


def _solve_shooting(arm, layout, segs, sec_start, p_inputs, p_channel, scene, model, warm_start,
                    record, settings, load_moments):
    """Planar multiple-shooting solve along the quasi-static path, the scene's obstacles (if
    any) present all along it.

    Start state: a multiple-shooting ``warm_start`` at this resolution continues from its
    nodes; any other warm start from its own base moment, re-integrated at this resolution
    (corrected by Newton at the start of the ramp); a cold solve from the arm loaded with
    the obstacles in place (:func:`_loaded_nodes`). Then pressures and loads are ramped from
    the start's to the target's (:func:`solver._contact._follow`, which never lets the
    backbone tunnel through a disc).
    """
    free_scene = replace(scene, obstacles=())
    ctx = _context(arm, layout, free_scene, 2, settings)
    p_target = p_channel if arm.n_channels else np.zeros(1)
    plate, target, state_w, weights, res_weights = _ms_terms(arm, layout, segs, scene, ctx,
                                                             load_moments)
    goal = (p_target, ctx.q, plate, target, scene.discs_array())
    iterations = 0
    if warm_start is not None and warm_start.scene is not None:
        start_scene = replace(warm_start.scene, obstacles=())
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        start_ctx = ctx if start_scene == free_scene else \
            _context(arm, layout, start_scene, 2, settings)
        if warm_start.shooting_nodes.shape == weights.shape:
            nodes = warm_start.shooting_nodes.copy()
        elif warm_start.s.size:
            nodes = _nodes_from_record(warm_start, layout, segs, sec_start)
        else:
            free = np.empty((layout.n_rows, _planar.N_COLUMNS))
            _planar._integrate(float(warm_start.base_moment[-1]), scene.base_theta, layout.secf,
                               layout.sec_steps, np.vstack(rest_strains(arm, p_start, layout)),
                               start_ctx.loads, True, free)
            P = _planar
            nodes = _nodes_from_states(free[:, [P.X, P.Y, P.THETA, P.NX, P.NY, P.M]], segs)
        start_plate, start_target = _ms_terms(arm, layout, segs, start_scene, start_ctx,
                                              load_moments)[:2]
        # The same obstacles at the warm start's stiffness (a stiffer penalty is ramped in),
        # or the scene's where they differ.
        start_discs = _effective_discs(warm_start.scene, warm_start.penalty_stiffness)
        if start_discs.shape != goal[_contact.L_DISCS].shape or np.any(
                start_discs[:, :3] != goal[_contact.L_DISCS][:, :3]):
            start_discs = goal[_contact.L_DISCS]
        start = (p_start, start_ctx.q, start_plate, start_target, start_discs)
    else:
        nodes, iterations, loaded = _loaded_nodes(arm, layout, segs, sec_start, scene, ctx,
                                                  settings, load_moments)
        start = (np.zeros_like(p_target), *goal[1:])
        if not loaded:
            grid = (scene.base_theta, segs, layout.secf, layout.sec_steps, sec_start)
            return _shooting_result(nodes, scene, grid, layout, start, record,
                                    converged=False, stable=False, iterations=iterations,
                                    residual=math.inf, model=model, pressures=p_inputs,
                                    channel_pressures=p_channel)
    now = _contact._new_level(goal)
    rest = np.empty((3, len(arm.sections)))
    grid = (scene.base_theta, segs, layout.secf, layout.sec_steps, sec_start)
    snapped = False
    for _ in range(MAX_SNAPS + 1):
        ok, its, res, stable, t, dt = _contact._follow(
            nodes, grid, layout.tubes_i, layout.tubes_f, start, goal, weights, res_weights,
            settings.tol, settings.max_iter, 0.5, settings.dt0, _shooting_dt_min(scene, settings),
            rest, now, math.inf)
        iterations += its
        if ok or settings.n_scan == 0 or t >= 1.0:
            break
        # The path cannot go on past level t (a fold): the arm snaps. Find the stable
        # equilibrium it lands on a little further on and continue from there.
        landed, level = _snap_ahead(arm, nodes, grid, layout, start, goal, t, dt, now, weights,
                                    res_weights, settings, ctx.params)
        if landed is None:
            break
        nodes[:] = landed
        start = level
        snapped = True
    return _shooting_result(nodes, scene, grid, layout, now, record,
                            converged=bool(ok), stable=bool(stable), snapped=snapped,
                            iterations=int(iterations), residual=float(res), model=model,
                            pressures=p_inputs, channel_pressures=p_channel)


# Snaps per multiple-shooting solve before it gives up (each costs an energy minimisation).
MAX_SNAPS = 8
# How far past a fold a snap looks, tried in turn: fractions of the rated pressure (or of
# the loads being ramped in).
SNAP_AHEAD = (0.0025, 0.01, 0.04, 0.16)


def _level_span(start, goal, p_max):
    """How much a homotopy between level tuples changes, relative to its scale: the largest
    pressure change over the rated pressure, or load change over the load."""
    C = _contact
    span = float(np.max(np.abs(goal[C.L_P] - start[C.L_P]))) / p_max if p_max > 0 else 0.0
    for k in (C.L_Q, C.L_PLATE, C.L_TARGET):
        size = float(np.max(np.abs(goal[k]), initial=0.0))
        if size > 0.0:
            span = max(span, float(np.max(np.abs(goal[k] - start[k]))) / size)
    return max(span, 1e-12)


def _snap_ahead(arm, nodes, grid, layout, start, goal, t, dt, now, weights, res_weights,
                settings, params):
    """The snap of a multiple-shooting path that ends at a fold at level t (step dt failed
    beyond it): (landed nodes, their level) or (None, None).

    The arm is sought on its new branch at SNAP_AHEAD past the fold, in turn. The offsets
    are physical (a fraction of the rated pressure, or of the loads), so that a cold ramp
    and a fine warm ramp look at the same levels past the same fold. Close to the fold the
    discrete energy's minimum may still sit by the vanishing branch (its fold lies O(h²)
    away from the shooting system's); where the ramp ends before an offset, the loads are
    carried on past its end (pressures kept within the rating) to pass the fold, and the
    arm relaxed back to the end from there.
    """
    span = _level_span(start, goal, arm.max_pressure)
    for ahead in SNAP_AHEAD:
        t_over = t + max(ahead / span, dt)
        level = _interpolate_level(start, goal, min(1.0, t_over), arm.max_pressure)
        over = _interpolate_level(start, goal, t_over, arm.max_pressure) if t_over > 1.0 \
            else None
        landed = _snap(nodes, grid, layout, now, level, over, weights, res_weights, settings,
                       params)
        if landed is not None:
            return landed, level
    return None, None


def _interpolate_level(start, goal, t, p_max):
    """The level tuple at ``t`` of the ramp from ``start`` to ``goal`` (t may exceed 1: the
    ramp carried on), pressures kept within [0, p_max]."""
    level = tuple(a + t * (b - a) for a, b in zip(start, goal))
    return (np.clip(level[0], 0.0, p_max), *level[1:])


def _snap(nodes, grid, layout, now, level, over, weights, res_weights, settings, params):
    """Where a multiple-shooting path ends at a fold: the stable equilibrium at ``level``
    that the arm, at ``nodes`` (level ``now``), snaps to; None if none is found.

    Clear of every obstacle, the arm snaps as the single-shooting path does: to the stable
    root of the level nearest its base moment (:func:`solver._planar._scan`, ``params`` its
    parameters), if that is clear of the obstacles too. Otherwise, a local minimum of the
    discrete rod's energy reached from the last state (:func:`solver._relax.relax`) — from
    the scan's root if it lands in an obstacle; with ``over`` (a level past the ramp's end)
    it relaxes there first and then back at ``level``. Either is polished by Newton on the
    shooting system and must be stable.
    """
    C = _contact
    theta0, segs = grid[C.G_THETA0], grid[C.G_SEGS]
    target = level[C.L_TARGET]
    rest = _level_rest(layout, level)
    record = np.zeros((layout.n_rows, C.N_COLUMNS))
    C._record(nodes, grid, _level_rest(layout, now), now, record)
    landed = None
    if not record[:, C.C_PEN].any() and params[_rod.N_SCAN] > 0:
        loads = _planar_loads(layout, level)
        m0, found, _ = _planar._scan(theta0, layout.secf, layout.sec_steps, rest, loads,
                                     float(target[2]), params, int(params[_rod.N_SCAN]),
                                     float(nodes[2]), _DUMMY)
        if found:
            free = np.empty((layout.n_rows, _planar.N_COLUMNS))
            _planar._integrate(m0, theta0, layout.secf, layout.sec_steps, rest, loads, True, free)
            P = _planar
            landed = _nodes_from_states(free[:, [P.X, P.Y, P.THETA, P.NX, P.NY, P.M]], segs)
            if not _planar._clear_of(free, level[C.L_DISCS], 0.0):
                record[:, [C.C_X, C.C_Y, C.C_TH, C.C_V1, C.C_V3]] = free[:, [P.X, P.Y, P.THETA,
                                                                           P.V1, P.V3]]
                landed = None
    if landed is None:
        state = _relax.strains_of_record(record, layout.sec_steps)
        for lvl in (over, level) if over is not None else (level,):
            relaxed = _relax.relax(state, theta0, layout.secf, layout.sec_steps,
                                   _level_rest(layout, lvl), lvl[C.L_Q], lvl[C.L_PLATE],
                                   lvl[C.L_TARGET][:2] - lvl[C.L_PLATE][-1], lvl[C.L_TARGET][2],
                                   lvl[C.L_DISCS])
            if relaxed is None:
                return None
            states, state = relaxed
        landed = _nodes_from_states(states, segs)
    ok, _, _, stable = C._newton(landed, grid, rest, level, weights, res_weights,
                                 settings.tol, 4 * settings.max_iter, 0.5)
    return landed if ok and stable else None


def _planar_loads(layout, level):
    """The (ns, 4) loads array of :mod:`solver._planar` (n_end, q) of a level tuple."""
    C = _contact
    q, plate = level[C.L_Q], level[C.L_PLATE]
    loads = np.empty((q.shape[0], 4))
    running = level[C.L_TARGET][:2].copy()  # n(L⁻): tip load and the last endplate
    for i in range(q.shape[0] - 1, -1, -1):
        loads[i, :2] = running
        loads[i, 2:] = q[i]
        if i > 0:
            running = running + q[i] * layout.sec_len[i] + plate[i - 1]
    return loads


def _shooting_dt_min(scene, settings):
    return settings.contact_dt_min if scene.obstacles else settings.dt_min


def _nodes_from_record(eq, layout, segs, sec_start):
    """Multiple-shooting nodes on ``layout`` from a recorded equilibrium at another
    resolution, interpolated linearly in arc length within each section (so that a node at
    a section start takes the internal force past the endplate)."""
    states = np.column_stack([eq.positions, eq.angles, eq.internal_force, eq.internal_moment])
    ends = np.asarray(eq.section_ends)
    starts = np.concatenate([[0], ends[:-1] + 1])
    rows = segs[:, _contact.SEG_ROW0] + segs[:, _contact.SEG_FIRST]
    s_rows = np.concatenate([np.linspace(0, n, n + 1) * h + s0 for n, h, s0 in zip(
        layout.sec_steps, layout.sec_len / layout.sec_steps, sec_start)])
    out = np.empty((layout.n_rows, 6))
    row = 0
    for i, n in enumerate(layout.sec_steps):
        part = slice(starts[i], ends[i] + 1)
        for c in range(6):
            out[row:row + n + 1, c] = np.interp(s_rows[row:row + n + 1], eq.s[part],
                                                states[part, c])
        row += n + 1
    return np.concatenate([out[rows[0], 3:], out[rows[1:]].ravel()])


def _loaded_nodes(arm, layout, segs, sec_start, scene, ctx, settings, load_moments):
    """Stage 1 of a cold multiple-shooting solve (cached per scene): from the straight,
    unloaded, unactuated arm the loads are ramped in with the obstacles in place. Returns a
    copy of the nodes, the iterations and whether it converged.

    An obstacle that overlaps the straight arm grows in during the ramp, from the radius at
    which it just touches the arm's axis to its own. Loading a long arm from straight is far
    from linear (its linear response to its own weight is metres): predicted moves are
    capped at one Newton step limit.
    """
    key = ("loaded-nodes", id(layout), scene, settings, load_moments)
    hit = arm._solver_cache.get(key)
    if hit is None:
        plate, target, state_w, weights, res_weights = _ms_terms(arm, layout, segs, scene, ctx,
                                                                 load_moments)
        nodes = np.zeros(weights.shape)
        rows = segs[1:, _contact.SEG_ROW0] + segs[1:, _contact.SEG_FIRST]
        s_nodes = np.concatenate([np.linspace(0, n, n + 1) * h + s0 for n, h, s0 in zip(
            layout.sec_steps, layout.sec_len / layout.sec_steps, sec_start)])[rows]
        straight = nodes[3:].reshape(-1, 6)
        axis = np.array([math.cos(scene.base_theta), math.sin(scene.base_theta)])
        straight[:, :2] = s_nodes[:, None] * axis
        straight[:, 2] = scene.base_theta
        discs = scene.discs_array()
        grown = discs.copy()
        along = np.clip(discs[:, :2] @ axis, 0.0, arm.length)
        grown[:, 2] = np.minimum(discs[:, 2], np.hypot(*(discs[:, :2] - along[:, None] * axis).T))
        p0 = np.zeros(max(arm.n_channels, 1))
        start = (p0, np.zeros_like(ctx.q), np.zeros_like(plate), np.zeros(3), grown)
        goal = (p0, ctx.q, plate, target, discs)
        grid = (scene.base_theta, segs, layout.secf, layout.sec_steps, sec_start)
        ok, its, res, stable, _, _ = _contact._follow(
            nodes, grid, layout.tubes_i, layout.tubes_f, start, goal, weights, res_weights,
            settings.tol, settings.max_iter, 0.5, settings.dt0,
            _shooting_dt_min(scene, settings), np.empty((3, len(arm.sections))),
            _contact._new_level(goal), 0.5)
        hit = arm._solver_cache[key] = (nodes, int(its), bool(ok and stable))
    nodes, its, ok = hit
    return nodes.copy(), its, ok


def _shooting_result(nodes, scene, grid, layout, level, record, **fields):
    """The Equilibrium of a multiple-shooting state ``nodes`` at ``level`` (a level tuple of
    :mod:`solver._contact`; ``grid`` its layout tuple): the backbone is integrated from the
    nodes (contact needs it for the wrap measures even when ``record`` is False; ``record``
    decides whether it is returned), with the contact fields if the scene has obstacles."""
    C = _contact
    contact = bool(scene.obstacles)
    out = np.zeros((layout.n_rows, C.N_COLUMNS))
    C._record(nodes, grid, _level_rest(layout, level), level, out)
    common = dict(tip=out[-1, [C.C_X, C.C_Y]].copy(), planar=True, scene=scene,
                  base_moment=np.array([nodes[2]]), base_force=nodes[:2].copy(),
                  shooting_nodes=nodes, in_contact=bool(contact and out[:, C.C_PEN].max() > 0.0),
                  **fields)
    if not record:
        return Equilibrium(**common)
    extra = dict(contact_force=out[:, [C.C_FX, C.C_FY]].copy(),
                 penetration=out[:, C.C_PEN].copy()) if contact else {}
    return Equilibrium(
        s=out[:, C.C_S].copy(), positions=out[:, [C.C_X, C.C_Y]].copy(),
        angles=out[:, C.C_TH].copy(), shear_stretch=out[:, [C.C_V1, C.C_V3]].copy(),
        curvature=out[:, C.C_U].copy(), internal_force=out[:, [C.C_NX, C.C_NY]].copy(),
        internal_moment=out[:, C.C_M].copy(), section_ends=layout.section_ends, **extra,
        **common)


def _level_rest(layout, level):
    """Rest strains (3, ns) at the pressures of a level tuple."""
    rest = np.empty((3, layout.secf.shape[1]))
    _rod._rest_strains(level[_contact.L_P], layout.tubes_i, layout.tubes_f, layout.secf, rest)
    return rest


def _ms_layout(arm, packed):
    """Multiple-shooting segments at the settings' resolution (cached per design)."""
    key = ("multiple", id(packed))
    hit = arm._solver_cache.get(key)
    if hit is None:
        hit = arm._solver_cache[key] = _segments(packed)
    return hit


def _nodes_from_states(states, segs):
    """Multiple-shooting unknowns from backbone samples ``states`` (N, 6) = (x, y, θ, n_x,
    n_y, m) per sample: (n0, m0), then the state at every segment start."""
    rows = segs[:, _contact.SEG_ROW0] + segs[:, _contact.SEG_FIRST]
    return np.concatenate([states[rows[0], [3, 4, 5]], states[rows[1:]].ravel()])
