"""Public solver API: :func:`solve`, :func:`solve_batch` and :func:`step_batch`.

Thin validated wrappers: inputs are checked (:mod:`solver.inputs`), then
:func:`solver.paths.dispatch.dispatch` picks the path a scene needs (:mod:`solver.paths`) and
those run the numba kernels (:mod:`solver.kernels`). What a scene
does not need is skipped:

* no gravity acting on mass, no payload, no tip load → closed-form arcs (every model);
* planar-symmetric pressures and an in-plane scene with ``planar=False`` → the planar
  kernel, embedded in 3D, where that cannot change the answer;
* obstacles out of reach, or a path that stays clear of them → the contact-free solve;
* ``record=False`` → no backbone samples, just the tip.

Every result is checked before it is called converged: Newton's residual against the arm's
moment scale (each section's EI/L in series), and the RK4 grid against the result's own
curvature and loads (:mod:`solver.kernels.grid`); where the grid is too coarse the solve is repeated
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

import numpy as np

from solver import layout as L
from solver.designs import ArmDesign
from solver.inputs import batch_inputs, check_batch_state, checked_pressures, request
from solver.kernels import planar as planar_kernels
from solver.paths.dispatch import dispatch
from solver.paths.planar import loaded_base_moment
from solver.problem import has_load, pack
from solver.results import BatchState, Equilibrium
from solver.scene import Scene
from solver.settings import DEFAULT_SETTINGS, Settings, SolverError

__all__ = ["solve", "solve_batch", "step_batch", "channel_pressures"]


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
    return checked_pressures(arm, pressures, planar, pack(arm, "full", DEFAULT_SETTINGS))[1].copy()


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
    eq = dispatch(request(arm, pressures, scene, model, planar, warm_start, settings), record)
    if strict and not eq.converged:
        raise SolverError(f"no converged equilibrium (residual {eq.residual:.3g} N m after "
                          f"{eq.iterations} iterations)")
    return eq


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
    problem, p, channel = batch_inputs(arm, pressures, scene, model, planar, settings)
    scene, packed = problem.scene, problem.packed
    general = model != "constant_curvature" and (has_load(arm, scene) or not settings.shortcuts)
    if planar and not general and not scene.has_contact:
        tips = np.empty((p.shape[0], 2))
        planar_kernels.arc_tips(scene.base_theta, packed.secf, packed.tubes_i, packed.tubes_f,
                                channel, tips)
        return tips, np.ones(p.shape[0], dtype=bool)
    if not (general and planar) or scene.has_contact:
        dim = 2 if planar else 3
        tips = np.empty((p.shape[0], dim))
        ok = np.empty(p.shape[0], dtype=bool)
        for k in range(p.shape[0]):
            p_channel = channel[k] if arm.n_channels else np.zeros(0)
            eq = dispatch(problem.with_inputs(p[k].copy(), p_channel.copy()), False)
            tips[k] = eq.tip
            ok[k] = eq.converged
        return tips, ok
    ctx = problem.ctx
    loaded = loaded_base_moment(problem)
    n = p.shape[0]
    tips, ok = np.empty((n, 2)), np.empty(n, dtype=bool)
    stable = np.empty(n, dtype=bool)
    planar_kernels.batch(np.full(n, loaded.m0), np.zeros_like(channel), scene.base_theta,
                         packed.secf, packed.sec_steps, packed.tubes_i, packed.tubes_f, channel,
                         ctx.loads, ctx.m_tip, ctx.params, False, tips, ok, stable, np.empty(n),
                         np.empty((n, 1, L.N_COLUMNS)))
    for k in np.flatnonzero(~(ok & stable & loaded.resolved)):
        # What solve() does where single shooting fails or its grid is too coarse: the other
        # method, a finer grid.
        p_channel = channel[k] if arm.n_channels else np.zeros(0)
        eq = dispatch(problem.with_inputs(p[k].copy(), p_channel.copy()), False)
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
    problem, p, channel = batch_inputs(arm, pressures, scene, model, True, settings)
    scene, packed, ctx = problem.scene, problem.packed, problem.ctx
    if scene.has_contact:
        raise ValueError("step_batch does not model contact; use solve() for scenes with obstacles "
                         "or self-contact")
    n = p.shape[0]
    moving = True
    if state is None:
        loaded = loaded_base_moment(problem)
        m_start, p_start, p_prev = np.full(n, loaded.m0), np.zeros_like(channel), np.zeros_like(p)
        # A loaded arm beyond the grid (solve() refines it): no copy moves from it.
        moving = loaded.resolved
    else:
        check_batch_state(state, arm, scene, n)
        m_start, p_start, p_prev = state.base_moment, state.channel_pressures, state.pressures
    tips, ok, m0_out = np.empty((n, 2)), np.empty(n, dtype=bool), np.empty(n)
    shapes = np.empty((n, packed.n_rows if record else 1, L.N_COLUMNS))
    planar_kernels.batch(m_start, p_start, scene.base_theta, packed.secf, packed.sec_steps,
                         packed.tubes_i, packed.tubes_f, channel if moving else p_start, ctx.loads,
                         ctx.m_tip, ctx.params, record, tips, ok, np.empty(n, dtype=bool), m0_out,
                         shapes)
    ok &= moving
    keep = ~ok[:, None]
    if state is not None:
        # A copy that did not move keeps its tip as it was (the kernel's pass from the kept
        # base moment can differ from it by Newton's linearised last correction).
        tips = np.where(keep, state.tips, tips)
    return BatchState(pressures=np.where(keep, p_prev, p), tips=tips, converged=ok, shapes=shapes,
                      section_ends=packed.section_ends, base_moment=m0_out,
                      channel_pressures=np.where(keep, p_start, channel), arm=arm, scene=scene)
