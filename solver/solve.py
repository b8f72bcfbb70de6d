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

from solver import _contact, _planar, _spatial
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
        n_scan: grid points of the fold scan over the base moment (0: no scan).
        shortcuts: skip what a scene does not need (closed-form arcs when unloaded, the
            planar kernel for in-plane spatial solves). False forces the general path; the
            tests use it to check that each shortcut agrees with it.
    """

    steps_per_section: int = 16
    tol: float = 1e-10
    max_iter: int = 12
    dt0: float = 1.0
    dt_min: float = 1.0 / 256.0
    n_scan: int = 96
    shortcuts: bool = True

    def __post_init__(self):
        if int(self.steps_per_section) != self.steps_per_section or self.steps_per_section < 1:
            raise ValueError(f"steps_per_section must be an integer >= 1; got {self.steps_per_section}")
        if not (self.tol > 0 and self.max_iter >= 1 and 0 < self.dt_min <= self.dt0 <= 1
                and (self.n_scan == 0 or self.n_scan >= 4)):
            raise ValueError(f"invalid solver settings: {self}")

    @classmethod
    def without_fallback(cls, **kwargs) -> Settings:
        """Plain Newton from the start state: no continuation, no step halving, no fold scan.

        The stress test compares this against the default to show what the fallbacks buy.
        """
        return cls(dt0=1.0, dt_min=1.0, n_scan=0, **kwargs)


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
        sec_len=secf[_planar.LEN],
        sec_steps=steps,
        c_a=secf[_planar.CA],
        c_g=secf[_planar.CG],
        c_i=secf[_planar.CI],
        c_j=np.array([1.0 / s.GJ for s in secs]),
        sec_ea=secf[_planar.EA],
        sec_ei=secf[_planar.EI],
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
    _planar._rest_strains(np.ascontiguousarray(channel_pressures, dtype=float), packed.tubes_i,
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
        eq = _solve_contact(arm, packed, p_inputs, p_channel, scene, model, warm_start, record,
                            settings)
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
        params = np.empty(_planar.N_PARAMS)
        params[[_planar.TOL, _planar.MAX_STEP, _planar.M_BOUND, _planar.DT0, _planar.DT_MIN,
                _planar.MAX_ITER, _planar.N_SCAN, _planar.JUMP]] = (
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
    """A bound on |m0| for the fold scan: |M_tip| + ∫|r'||n| ds over any pressures.

    |r'| ≤ v*max + |n|/min(EA, GA), with v*max the stretch at the rated pressure.
    """
    nmax = float(np.max(np.linalg.norm(n_end, axis=1) + np.linalg.norm(q, axis=1) * packed.sec_len))
    full = np.full(max(arm.n_channels, 1), arm.max_pressure) if arm.n_channels else np.zeros(1)
    v3 = rest_strains(arm, full, packed)[2] if arm.n_channels else np.ones(1)
    stretch = float(v3.max()) + nmax * float(max(packed.c_a.max(), packed.c_g.max()))
    bound = float(np.linalg.norm(scene.tip_moment_3d())) + nmax * stretch * arm.length
    return 1.05 * bound + packed.moment_scale * 1e-6


def _follow(packed, scene, p_start, p_target, start_ctx, ctx, m0, out=None, guard_3d=False):
    """Run :func:`solver._planar._follow`; returns its tuple plus the scratch (rest, loads_now).

    With ``out`` ((n_rows, N_COLUMNS)) a converged result's backbone is recorded into it;
    with ``guard_3d`` every accepted state must be stable in 3D too (the in-plane shortcut
    of a spatial solve).
    """
    ns = packed.secf.shape[1]
    rest, p_now, loads_now = np.empty((3, ns)), np.empty(p_target.shape[0]), np.empty((ns, 4))
    result = _planar._follow(m0, scene.base_theta, packed.secf, packed.sec_steps, packed.tubes_i,
                             packed.tubes_f, p_start, p_target, start_ctx.loads, ctx.loads,
                             start_ctx.m_tip, ctx.m_tip, ctx.params, rest, p_now, loads_now,
                             _DUMMY if out is None else out, out is not None,
                             packed.c_j if guard_3d else _NO_GUARD)
    return result, rest, loads_now


_DUMMY = np.empty((1, _planar.N_COLUMNS))
_NO_GUARD = np.empty(0)


def _loaded_base_moment(arm, packed, scene, ctx, settings, guard_3d=False
                        ) -> tuple[float, int, bool, bool]:
    """Stage 1 of a cold solve: the unactuated arm under its loads ramped from zero (cached).

    Returns (m0, iterations, snapped, converged); with ``guard_3d`` converged means also
    stable in 3D all along (see :func:`_follow`).
    """
    key = ("loaded", id(ctx), settings, guard_3d)
    hit = arm._solver_cache.get(key)
    if hit is None:
        zeros = np.zeros(max(arm.n_channels, 1))
        unloaded = _SceneContext(n_end=ctx.n_end * 0, q=ctx.q * 0, loads=ctx.loads * 0,
                                 m_tip=0.0, tol=ctx.tol, max_step=ctx.max_step,
                                 params=ctx.params, has_load=False, base_force=ctx.base_force * 0,
                                 shooting_index=0.0)
        out, _, _ = _follow(packed, scene, zeros, zeros, unloaded, ctx, 0.0, guard_3d=guard_3d)
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
                  guard_3d=False):
    """Planar dead-load solve by single shooting on m0 (:func:`solver._planar._follow`).

    With ``guard_3d`` (the in-plane shortcut of a spatial solve) the result is unconverged
    as soon as the path leaves the states that are stable in 3D, loading stage included.
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
                                                              guard_3d)
        if guard_3d and not loaded:
            return Equilibrium(tip=np.full(2, np.nan), converged=False, stable=False,
                               iterations=iterations, residual=math.inf)
        start_ctx, p_start = ctx, np.zeros_like(p_target)
    out = np.empty((packed.n_rows, _planar.N_COLUMNS)) if record else None
    (m0, ok, its, snap, stab, res, x, y, th), rest, loads_now = _follow(
        packed, scene, p_start, p_target, start_ctx, ctx, m0, out, guard_3d)
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


def _contact_layout(arm, packed, scene):
    """Resolution and segments for contact solves (cached per design, settings, stiffness).

    In contact, deflections vary over ℓ_i = (EI_i/k)^¼; RK4 steps are refined to h ≤ ℓ_i/2
    (at least the setting's count, at most 1024 per section) and multiple-shooting segments
    span 4 steps, so no segment amplifies errors by more than ~e^1.4.
    """
    stiffness = max(d.stiffness for d in scene.obstacles)
    key = ("contact", id(packed), stiffness)
    hit = arm._solver_cache.get(key)
    if hit is None:
        ell = (packed.sec_ei / stiffness) ** 0.25
        steps = np.minimum(np.maximum(packed.sec_steps, np.ceil(packed.sec_len / (0.5 * ell))),
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


def _free_of_contact(arm, layout, segs, p_inputs, p_channel, scene, free_scene, model, warm_start,
                     record, settings):
    """The contact-free equilibrium as a contact result, if it clears every disc (else None).

    Samples are h apart along the backbone and distance to a disc changes by at most the arc
    length travelled, so a clearance of h/2 at every sample keeps the whole backbone (and
    the RK4 stages, which lie within h/2 of a sample) outside every disc.
    """
    eq = _solve_planar(arm, layout, p_inputs, p_channel, free_scene, model, warm_start, True,
                       settings)
    if not (eq.converged and eq.stable):
        return None
    discs = scene.discs_array()
    gap = np.hypot(eq.positions[:, None, 0] - discs[None, :, 0],
                   eq.positions[:, None, 1] - discs[None, :, 1]) - discs[None, :, 2]
    half_step = 0.5 * np.repeat(layout.sec_len / layout.sec_steps, layout.sec_steps + 1)
    if not np.all(gap.min(axis=1) > half_step):
        return None
    nodes = _nodes_from_states(np.column_stack([eq.positions, eq.angles, eq.internal_force,
                                                eq.internal_moment]), segs)
    if not record:
        return Equilibrium(tip=eq.tip, converged=True, stable=True, iterations=eq.iterations,
                           residual=eq.residual, snapped=eq.snapped, model=model, planar=True,
                           scene=scene, pressures=p_inputs, channel_pressures=p_channel,
                           base_moment=eq.base_moment, base_force=nodes[:2].copy(),
                           shooting_nodes=nodes)
    n = eq.positions.shape[0]
    return replace(eq, scene=scene, shooting_nodes=nodes, base_force=nodes[:2].copy(),
                   contact_force=np.zeros((n, 2)), penetration=np.zeros(n),
                   section_ends=layout.section_ends)


def _ms_terms(arm, layout, segs, scene, ctx, load_moments=False):
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
    fallback of a failed single-shooting solve. Cold: from the straight, unloaded rod the
    loads are ramped in at zero pressure, then the pressures; a warm start from a
    multiple-shooting result in the same scene continues from its nodes.
    """
    layout, segs, sec_start = _ms_layout(arm, packed)
    ctx = _context(arm, layout, scene, 2, settings)
    p_target = p_channel if arm.n_channels else np.zeros(1)
    plate, target, state_w, weights, res_weights = _ms_terms(arm, layout, segs, scene, ctx, True)
    rest, p_now = np.empty((3, len(arm.sections))), np.empty(p_target.shape[0])
    discs = np.empty((0, 4))
    eps = 1e-7 * state_w
    common = (scene.base_theta, segs, layout.secf, layout.sec_steps, sec_start, layout.tubes_i,
              layout.tubes_f)
    tail = (discs, eps, weights, res_weights, settings.tol, settings.max_iter, 0.5, settings.dt0,
            settings.dt_min, rest, p_now)
    iterations = 0
    ok = True
    if (warm_start is not None and warm_start.scene == scene
            and warm_start.shooting_nodes.shape == weights.shape):
        nodes = warm_start.shooting_nodes.copy()
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
    else:
        p_start = np.zeros_like(p_target)
        nodes = np.zeros(weights.shape)
        rows = segs[1:, _contact.SEG_ROW0] + segs[1:, _contact.SEG_FIRST]
        s_nodes = np.concatenate([np.linspace(0, n, n + 1) * h + s0 for n, h, s0 in zip(
            layout.sec_steps, layout.sec_len / layout.sec_steps, sec_start)])[rows]
        straight = nodes[3:].reshape(-1, 6)
        straight[:, 0] = s_nodes * math.cos(scene.base_theta)
        straight[:, 1] = s_nodes * math.sin(scene.base_theta)
        straight[:, 2] = scene.base_theta
        zero_q, zero_plate = np.zeros_like(ctx.q), np.zeros_like(plate)
        # Loading a long arm from straight is far from linear (its linear response to its
        # own weight is metres): predicted moves are capped at one Newton step limit.
        ok, iterations, res, stable = _contact._follow(
            nodes, *common, p_start, p_start, zero_q, ctx.q, zero_plate, plate, np.zeros(3),
            target, *tail, 0.5)
    if ok:
        ok, its, res, stable = _contact._follow(nodes, *common, p_start, p_target, ctx.q, ctx.q,
                                                plate, plate, target, target, *tail)
        iterations += its
    return _shooting_result(nodes, scene, segs, layout, sec_start, rest, ctx.q, plate, discs,
                            record, False, converged=bool(ok), stable=bool(stable),
                            iterations=int(iterations), residual=float(res), model=model,
                            pressures=p_inputs, channel_pressures=p_channel)


def _shooting_result(nodes, scene, segs, layout, sec_start, rest, q, plate, discs, record,
                     contact, **fields):
    """The Equilibrium of a multiple-shooting state ``nodes``: the backbone is integrated
    from the nodes (contact needs it for the wrap measures even when ``record`` is False;
    ``record`` decides whether it is returned), with the contact fields if ``contact``."""
    C = _contact
    out = np.zeros((layout.n_rows, C.N_COLUMNS))
    C._record(nodes, scene.base_theta, segs, layout.secf, layout.sec_steps, sec_start, rest, q,
              plate, discs, out)
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


def _solve_contact(arm, packed, p_inputs, p_channel, scene, model, warm_start, record, settings):
    """Planar solve with penalty contact against the scene's discs (:mod:`solver._contact`).

    Only built when a scene has obstacles. The cold path starts from the contact-free loaded
    state and ramps the pressures with contact active; a warm start continues from the
    previous state's shooting nodes.

    Shortcut (``settings.shortcuts``): when the previous state touched nothing, the
    contact-free solve comes first, at the contact layout's resolution; if its backbone
    clears every disc by half an RK4 step at every sample — so that no point in between, and
    no RK4 stage, can reach a disc — it is the contact solution (every penalty force is
    zero), obtained by single shooting in tens of microseconds instead of milliseconds.
    """
    layout, segs, sec_start = _contact_layout(arm, packed, scene)
    free_scene = replace(scene, obstacles=())
    if settings.shortcuts and (warm_start is None or not warm_start.in_contact):
        free = _free_of_contact(arm, layout, segs, p_inputs, p_channel, scene, free_scene, model,
                                warm_start, record, settings)
        if free is not None:
            return free
    ctx = _context(arm, layout, free_scene, 2, settings)
    p_target = p_channel if arm.n_channels else np.zeros(1)
    plate, target, state_w, weights, res_weights = _ms_terms(arm, layout, segs, scene, ctx)
    iterations = 0
    if warm_start is not None and warm_start.shooting_nodes.shape == weights.shape:
        nodes = warm_start.shooting_nodes.copy()
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
    else:
        if warm_start is not None and warm_start.scene is not None:
            start_eq = solve(arm, warm_start.pressures, replace(warm_start.scene, obstacles=()),
                             model, True, record=False, settings=settings, warm_start=warm_start)
            p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        else:
            start_eq = None
            p_start = np.zeros_like(p_target)
        if start_eq is None:
            m0, iterations = _loaded_base_moment(arm, layout, free_scene, ctx, settings)[:2]
        else:
            m0 = float(start_eq.base_moment[-1])
        rest = rest_strains(arm, p_start, layout)
        free = np.empty((layout.n_rows, _planar.N_COLUMNS))
        _planar._integrate(m0, scene.base_theta, layout.secf, layout.sec_steps, np.vstack(rest),
                           ctx.loads, True, free)
        P = _planar
        nodes = _nodes_from_states(free[:, [P.X, P.Y, P.THETA, P.NX, P.NY, P.M]], segs)
    rest, p_now = np.empty((3, len(arm.sections))), np.empty(p_target.shape[0])
    discs = scene.discs_array()
    eps = 1e-7 * state_w
    ok, its, res, stable = _contact._follow(
        nodes, scene.base_theta, segs, layout.secf, layout.sec_steps, sec_start, layout.tubes_i,
        layout.tubes_f, p_start, p_target, ctx.q, ctx.q, plate, plate, target, target, discs, eps,
        weights, res_weights, settings.tol, settings.max_iter, 0.5, settings.dt0, settings.dt_min,
        rest, p_now)
    return _shooting_result(nodes, scene, segs, layout, sec_start, rest, ctx.q, plate, discs,
                            record, True, converged=bool(ok), stable=bool(stable),
                            iterations=int(iterations + its), residual=float(res), model=model,
                            pressures=p_inputs, channel_pressures=p_channel)
