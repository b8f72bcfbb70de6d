"""Public solver API: :func:`solve`, :func:`solve_batch` and :func:`step_batch`.

Thin validated wrappers: inputs are checked here, then :func:`_dispatch` picks the path a
scene needs (the ``solver._paths_*`` modules) and those run the numba kernels. What a scene
does not need is skipped:

* no gravity acting on mass, no payload, no tip load → closed-form arcs (every model);
* planar-symmetric pressures and an in-plane scene with ``planar=False`` → the planar
  kernel, embedded in 3D, where that cannot change the answer;
* obstacles out of reach, or a path that stays clear of them → the contact-free solve;
* ``record=False`` → no backbone samples, just the tip.

Every result is checked before it is called converged: Newton's residual against the arm's
moment scale (each section's EI/L in series), and the RK4 grid against the result's own
curvature and loads (:mod:`solver._grid`); where the grid is too coarse the solve is repeated
on a finer one, up to ``Settings.max_refinement``, and sampled back on the settings' grid.

Policy for an unconverged solve: :func:`solve` returns an :class:`Equilibrium` with
``converged=False`` and the residual of the last iterate; its shape is that iterate's.
Where the kernels give no finite iterate (or fail outright) the result is the unloaded shape
at the requested pressures with ``converged=False``, ``stable=False`` and an infinite
residual: never NaN, never an exception. Pass ``strict=True`` to raise :class:`SolverError`
instead. Bad input raises ``ValueError`` naming the problem before any kernel runs
(docs/design.md §11).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from solver import _grid, _planar
from solver import layout as L
from solver._blas import single_blas_thread
from solver._model import PackedArm, context, has_load, pack, refined
from solver._paths_contact import solve_contact, solve_rigid
from solver._paths_planar import closed_form, loaded_base_moment, solve_lean, solve_planar
from solver._paths_spatial import (
    in_plane,
    in_plane_shortcut,
    in_plane_state,
    solve_spatial,
    solve_spatial_lean,
)
from solver._paths_spatial_contact import solve_contact_spatial
from solver.designs import ArmDesign
from solver.jit import njit
from solver.results import BatchState, Equilibrium, tip_only
from solver.scene import Scene, core_distance
from solver.settings import DEFAULT_SETTINGS, MODELS, Settings, SolverError

__all__ = ["solve", "solve_batch", "step_batch", "channel_pressures"]


def _channel_pressures(arm: ArmDesign, pressures, planar: bool,
                       packed: PackedArm) -> tuple[np.ndarray, np.ndarray]:
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
    # Spatial inputs are the channels: only checked (an empty index expands nothing).
    index = packed.spatial_of_planar if planar else _NO_INDEX
    p_channel = np.empty(index.shape[0]) if planar else p
    if not _channels_of(p, index, arm.max_pressure * (1 + 1e-12), p_channel):
        _explain_bad_pressures(arm, p, planar)
    return p, p_channel


_NO_INDEX = np.empty(0, dtype=np.int64)


@njit
def _channels_of(p, index, p_max, out):
    """Spatial-channel pressures ``out[c] = p[index[c]]`` of planar inputs ``p``; False if an
    input is not finite, negative or above ``p_max`` (then ``out`` is incomplete)."""
    for k in range(p.shape[0]):
        if not (0.0 <= p[k] <= p_max):
            return False
    for c in range(index.shape[0]):
        out[c] = p[index[c]]
    return True


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
    return _channel_pressures(arm, pressures, planar, pack(arm, "full", DEFAULT_SETTINGS))[1].copy()


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
        raise ValueError("scene has out-of-plane loads (tip_force z or tip_moment x/y) or "
                         "obstacles other than discs (cylinders, spheres); use planar=False")
    if scene.self_contact is not None:
        if not planar:
            raise ValueError("self-contact is supported in planar solves only")
        if model == "constant_curvature":
            raise ValueError("the constant-curvature model has no contact; self-contact needs "
                             "model 'full' or 'unshearable'")
        if not all(arm.half_thickness()):
            raise ValueError(f"self-contact needs every section's half-thickness, from its tubes; "
                             f"design {arm.name!r} has a section no tube spans")
    if planar and not arm.planar_channels and arm.tubes:
        raise ValueError(f"design {arm.name!r} defines no planar channels; use planar=False")


def solve(arm: ArmDesign, pressures, scene: Scene | None = None, model: str = "full",
          planar: bool = True, warm_start: Equilibrium | None = None, record: bool = True,
          settings: Settings = DEFAULT_SETTINGS, strict: bool = False) -> Equilibrium:
    """Static equilibrium of ``arm`` at channel ``pressures`` in ``scene``.

    Without ``warm_start`` the equilibrium reached quasi-statically is returned: the
    unactuated arm is loaded (gravity, endplates, payload, tip loads ramped from zero), then
    all pressures are ramped proportionally from zero, following the stable branch
    (docs/design.md §6). With ``warm_start`` the path from that equilibrium is
    followed the same way (the hysteresis is physical).

    Args:
        arm: the design (:mod:`solver.designs`).
        pressures: (n_inputs,) channel pressures in Pa, ordered as
            ``arm.input_names(planar)``; ``[]`` for a passive rod.
        scene: mounting and loads (default: hanging, gravity, no payload).
        model: ``"full"``, ``"unshearable"`` (GA → ∞) or ``"constant_curvature"``.
        planar: solve in the x–y plane (inputs are planar channels) or in 3D.
        warm_start: a previous equilibrium of the same arm, model and mode, solved at the
            same base angle (its loads and pressures are ramped to this scene's; obstacles it
            was not solved with must not lie across its backbone).
        record: return backbone samples (False: tip only, faster).
        settings: numerical settings.
        strict: raise :class:`SolverError` instead of returning an unconverged result.

    Returns:
        The :class:`Equilibrium`.
    """
    scene = Scene() if scene is None else scene
    _check(arm, scene, model, planar)
    packed = pack(arm, model, settings)
    p_inputs, p_channel = _channel_pressures(arm, pressures, planar, packed)
    if warm_start is not None:
        _check_warm_start(warm_start, arm, scene, model, planar)
    eq = _dispatch(arm, packed, p_inputs, p_channel, scene, model, planar, warm_start, record,
                   settings)
    if strict and not eq.converged:
        raise SolverError(f"no converged equilibrium (residual {eq.residual:.3g} N m after "
                          f"{eq.iterations} iterations)")
    return eq


def _dispatch(arm, packed, p_inputs, p_channel, scene, model, planar, warm_start, record,
              settings, moving=False) -> Equilibrium:
    """The solve of validated inputs by the path the scene needs (:func:`_path`), on an RK4
    grid fine enough for its result, returned on the settings' grid (the finer grid's nodes
    include it). ``moving``: the warm start's obstacles move to the scene's (penalty contact
    only; :func:`solver._paths_contact.solve_contact`). Never raises (module docstring)."""
    if model == "constant_curvature" or (
            not scene.has_contact and settings.shortcuts
            and not context(arm, packed, scene, 2 if planar else 3, settings).has_load):
        return closed_form(arm, packed, p_inputs, p_channel, scene, model, planar, record)
    if not moving:
        lean = solve_lean if planar else solve_spatial_lean
        try:
            eq = lean(arm, packed, p_inputs, p_channel, scene, model, warm_start, settings, record)
        except (ArithmeticError, np.linalg.LinAlgError):
            eq = None  # the general path meets it again, and reports it
        if eq is not None and all(map(math.isfinite, eq.tip)):
            return eq
    q = packed.mass_per_length * scene.gravity
    layout = packed
    while True:
        try:
            eq = _path(arm, layout, p_inputs, p_channel, scene, model, planar, warm_start,
                       settings, moving)
            need, worst = _grid.needs(eq, layout.secf, q)  # infinite at a sample not finite
        except (ArithmeticError, np.linalg.LinAlgError):
            eq = None
        if eq is None or not (math.isfinite(worst) and all(map(math.isfinite, eq.tip))):
            # No finite state: the unloaded shape at these pressures, flagged (finite, so that
            # a stepper can keep it).
            eq = closed_form(arm, packed, p_inputs, p_channel, scene, model, planar, record)
            return replace(eq, converged=False, stable=False, residual=np.inf)
        if worst <= 1.0:
            break
        steps = _grid.refined_steps(eq, packed.sec_steps, layout.sec_steps, need,
                                    settings.max_refinement)
        if steps is None:  # the finest grid allowed does not resolve this state
            eq = replace(eq, converged=False)
            break
        layout = refined(arm, packed, steps)
    if layout is not packed and not scene.has_contact:  # (contact keeps its own finer layout)
        eq = _grid.on_grid(eq, layout.sec_steps, packed.sec_steps)
    return eq if record else tip_only(eq)


def _path(arm, packed, p_inputs, p_channel, scene, model, planar, warm_start, settings,
          moving=False):
    """The recorded solve by the path the scene needs (contact, planar, the in-plane
    shortcut of a spatial solve, spatial)."""
    if scene.has_contact:
        contact = solve_contact if planar else solve_contact_spatial
        with single_blas_thread():  # dense Newton and relaxation steps (docs/design.md §8)
            if scene.has_rigid_obstacles:
                return solve_rigid(arm, packed, p_inputs, p_channel, scene, model, warm_start,
                                   settings, contact)
            if not planar:
                return contact(arm, packed, p_inputs, p_channel, scene, model, warm_start, settings)
            return contact(arm, packed, p_inputs, p_channel, scene, model, warm_start, settings,
                           moving)
    if planar:
        return solve_planar(arm, packed, p_inputs, p_channel, scene, model, warm_start, settings)
    if settings.shortcuts and scene.is_planar and (
            warm_start is None or in_plane_state(warm_start)) and in_plane(arm, packed, p_channel):
        eq = in_plane_shortcut(arm, packed, p_inputs, p_channel, scene, model, warm_start,
                               settings)
        if eq is not None:
            return eq
    return solve_spatial(arm, packed, p_inputs, p_channel, scene, model, warm_start, settings)


def _check_warm_start(warm_start, arm, scene, model, planar):
    """A warm start must be a result of this arm, model and mode, solved in a scene the path
    can ramp from: the same mounting, and no obstacle it was not solved with lying across
    its backbone (loads and pressures ramp; a base or an obstacle cannot)."""
    if not isinstance(warm_start, Equilibrium):
        raise ValueError("warm_start must be an Equilibrium returned by solve()")
    if warm_start.arm is None or warm_start.scene is None:
        raise ValueError("warm_start does not say which arm and scene it was solved for; pass "
                         "an Equilibrium returned by solve() or a Stepper")
    if warm_start.arm is not arm and warm_start.arm != arm:
        raise ValueError(f"warm_start was solved for design {warm_start.arm.name!r}, not for "
                         f"this {arm.name!r} design (or for another variant of it)")
    if warm_start.planar != planar or warm_start.model != model:
        raise ValueError(f"warm_start comes from a {'planar' if warm_start.planar else 'spatial'} "
                         f"{warm_start.model!r} solve, not a {'planar' if planar else 'spatial'} "
                         f"{model!r} one")
    if warm_start.scene.base_angle_deg != scene.base_angle_deg:
        raise ValueError(f"warm_start was solved at a different base angle "
                         f"({warm_start.scene.base_angle_deg:g} deg, not {scene.base_angle_deg:g})")
    new = [k for k, d in enumerate(scene.obstacles) if d not in warm_start.scene.obstacles]
    if not new:
        return
    points = warm_start.positions if warm_start.positions.shape[0] else warm_start.tip[None, :]
    for k in new:
        d = scene.obstacles[k]
        if np.min(core_distance(d, points)) < d.radius:
            raise ValueError(f"warm_start's backbone lies inside obstacle {k} ({d}), which it "
                             "was not solved with: an obstacle cannot be ramped in; solve cold")


def _batch_inputs(arm, pressures, scene, model, planar, settings):
    """Validated (scene, packed, input pressures (n, n_inputs), channel pressures
    (n, n_channels)) for the batch calls."""
    scene = Scene() if scene is None else scene
    _check(arm, scene, model, planar)
    packed = pack(arm, model, settings)
    p = np.asarray(pressures, dtype=float)
    if p.ndim != 2 or p.shape[1] != arm.n_inputs(planar):
        raise ValueError(f"pressures must have shape (n, {arm.n_inputs(planar)}); got {p.shape}")
    for row in p[~np.all((p >= 0) & (p <= arm.max_pressure * (1 + 1e-12)), axis=1)][:1]:
        _explain_bad_pressures(arm, row, planar)
    if not arm.n_channels:
        channel = np.zeros((p.shape[0], 1))  # the kernels' placeholder of a passive rod
    else:
        channel = p[:, packed.spatial_of_planar] if planar else p
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
    general = model != "constant_curvature" and (has_load(arm, scene) or not settings.shortcuts)
    if planar and not general and not scene.has_contact:
        tips = np.empty((p.shape[0], 2))
        _planar._arc_tips(scene.base_theta, packed.secf, packed.tubes_i, packed.tubes_f, channel,
                          tips)
        return tips, np.ones(p.shape[0], dtype=bool)
    if not (general and planar) or scene.has_contact:
        dim = 2 if planar else 3
        tips = np.empty((p.shape[0], dim))
        ok = np.empty(p.shape[0], dtype=bool)
        for k in range(p.shape[0]):
            p_channel = channel[k] if arm.n_channels else np.zeros(0)
            eq = _dispatch(arm, packed, p[k].copy(), p_channel.copy(), scene, model, planar,
                           None, False, settings)
            tips[k] = eq.tip
            ok[k] = eq.converged
        return tips, ok
    ctx = context(arm, packed, scene, 2, settings)
    loaded = loaded_base_moment(arm, packed, scene, ctx)
    n = p.shape[0]
    tips, ok = np.empty((n, 2)), np.empty(n, dtype=bool)
    stable = np.empty(n, dtype=bool)
    _planar._batch(np.full(n, loaded.m0), np.zeros_like(channel), scene.base_theta, packed.secf,
                   packed.sec_steps, packed.tubes_i, packed.tubes_f, channel, ctx.loads, ctx.m_tip,
                   ctx.params, False, tips, ok, stable, np.empty(n), np.empty((n, 1, L.N_COLUMNS)))
    for k in np.flatnonzero(~(ok & stable & loaded.resolved)):
        # What solve() does where single shooting fails or its grid is too coarse: the other
        # method, a finer grid.
        p_channel = channel[k] if arm.n_channels else np.zeros(0)
        eq = _dispatch(arm, packed, p[k].copy(), p_channel.copy(), scene, model, planar, None,
                       False, settings)
        tips[k] = eq.tip
        ok[k] = eq.converged
    return tips, ok


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
    if scene.has_contact:
        raise ValueError("step_batch does not model contact; use solve() for scenes with obstacles "
                         "or self-contact")
    ctx = context(arm, packed, scene, 2, settings)
    n = p.shape[0]
    moving = True
    if state is None:
        loaded = loaded_base_moment(arm, packed, scene, ctx)
        m_start, p_start, p_prev = np.full(n, loaded.m0), np.zeros_like(channel), np.zeros_like(p)
        # A loaded arm beyond the grid (solve() refines it): no copy moves from it.
        moving = loaded.resolved
    else:
        _check_batch_state(state, arm, scene, n)
        m_start, p_start, p_prev = state.base_moment, state.channel_pressures, state.pressures
    tips, ok, m0_out = np.empty((n, 2)), np.empty(n, dtype=bool), np.empty(n)
    shapes = np.empty((n, packed.n_rows if record else 1, L.N_COLUMNS))
    _planar._batch(m_start, p_start, scene.base_theta, packed.secf, packed.sec_steps,
                   packed.tubes_i, packed.tubes_f, channel if moving else p_start, ctx.loads,
                   ctx.m_tip, ctx.params, record, tips, ok, np.empty(n, dtype=bool), m0_out, shapes)
    ok &= moving
    keep = ~ok[:, None]
    if state is not None:
        # A copy that did not move keeps its tip as it was (the kernel's pass from the kept
        # base moment can differ from it by Newton's linearised last correction).
        tips = np.where(keep, state.tips, tips)
    return BatchState(pressures=np.where(keep, p_prev, p), tips=tips, converged=ok, shapes=shapes,
                      section_ends=packed.section_ends, base_moment=m0_out,
                      channel_pressures=np.where(keep, p_start, channel), arm=arm, scene=scene)


def _check_batch_state(state, arm, scene, n):
    """A step_batch state must come from step_batch with this arm, in this scene (the copies
    are stepped under the same loads), with n copies."""
    if not isinstance(state, BatchState) or state.arm is None:
        raise ValueError("state must be the BatchState a previous step_batch call returned")
    if state.arm is not arm and state.arm != arm:
        raise ValueError(f"state was stepped for design {state.arm.name!r}, not for this "
                         f"{arm.name!r} design (or for another variant of it)")
    if state.scene != scene:
        raise ValueError(f"state was stepped in {state.scene}, not in {scene}: step_batch keeps "
                         "the loads; solve() ramps from one scene to another")
    if state.base_moment.shape != (n,):
        raise ValueError(f"state holds {state.base_moment.shape[0]} arms; pressures has {n} rows")
