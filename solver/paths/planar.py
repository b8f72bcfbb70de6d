"""Planar dead-load solves: closed-form arcs, single shooting with its fold scan, and the
choice between single and multiple shooting (docs/design.md §6–8, §10)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from solver import layout as L
from solver.kernels import planar as planar_kernels
from solver.kernels.grid import planar_fine
from solver.paths.grid import on_grid
from solver.paths.shooting import solve_multiple
from solver.problem import MULTIPLE_SHOOTING_INDEX, Problem, SceneContext, pack, refined, rest_strains
from solver.results import Equilibrium
from solver.rod import arc_chain_planar, arc_chain_spatial, base_rotation, integrate_planar

NO_GUARD = np.empty(0)
NO_DISCS = np.empty((0, 4))

# Scratch of a planar path that records nothing.
_NO_RECORD = np.empty((1, L.N_COLUMNS))


def closed_form(problem: Problem, record: bool) -> Equilibrium:
    """Unloaded arm (or the constant-curvature model): each section a circular arc.

    With no external load the internal force and moment vanish everywhere, so each section
    takes its rest strains exactly: curvature u*, stretch v*, no shear. Exact for every
    model; the ``constant_curvature`` model applies it whatever the loads. ``record``: with
    backbone samples (else the tip only).
    """
    arm, packed, scene, planar = problem.arm, problem.packed, problem.scene, problem.planar
    p_channel = problem.p_channel
    u1, u2, v3 = rest_strains(arm, p_channel, packed)
    ns = len(arm.sections)
    seg = np.repeat(np.arange(ns), packed.sec_steps + 1)
    starts = np.concatenate([[0.0], np.cumsum(packed.sec_len)[:-1]])
    s = np.concatenate([np.linspace(0.0, length, k + 1) + off for length, k, off in
                        zip(packed.sec_len, packed.sec_steps, starts)]) if record else np.empty(0)
    n = s.size
    common = dict(converged=True, stable=True, iterations=0, residual=0.0,
                  base_moment=np.zeros(1 if planar else 3), base_force=np.zeros(2 if planar else 3))
    ends = np.empty((ns, 3))
    if planar:
        positions, angles = np.empty((n, 2)), np.empty(n)
        arc_chain_planar(scene.base_theta, packed.sec_len, u2, v3, s, positions, angles, ends)
        tip = ends[-1, :2].copy()
        if not record:
            return problem.equilibrium(tip=tip, **common)
        return problem.equilibrium(
            tip=tip, s=s, positions=positions, angles=angles,
            shear_stretch=np.column_stack([np.zeros(n), v3[seg]]), curvature=u2[seg].copy(),
            internal_force=np.zeros((n, 2)), internal_moment=np.zeros(n),
            section_ends=packed.section_ends, **common)
    positions, frames = np.empty((n, 3)), np.empty((n, 3, 3))
    arc_chain_spatial(base_rotation(scene.base_theta), packed.sec_len,
                      np.ascontiguousarray(np.column_stack([u1, u2])), v3, s,
                      np.empty((4, 3, 3)), positions, frames, ends, np.empty((ns, 3, 3)))
    tip = ends[-1].copy()
    if not record:
        return problem.equilibrium(tip=tip, **common)
    return problem.equilibrium(
        tip=tip, s=s, positions=positions, orientations=frames,
        shear_stretch=np.column_stack([np.zeros(n), np.zeros(n), v3[seg]]),
        curvature=np.column_stack([u1[seg], u2[seg], np.zeros(n)]),
        internal_force=np.zeros((n, 3)), internal_moment=np.zeros((n, 3)),
        section_ends=packed.section_ends, **common)


def follow(packed, scene, p_start, p_target, start_ctx, ctx, m0, out=None, guard_3d=False,
           guard_discs=NO_DISCS):
    """Run :func:`solver.kernels.planar.follow` from base moment ``m0``.

    With ``out`` ((n_rows, N_COLUMNS)) a converged result's backbone is recorded into it;
    with ``guard_3d`` every accepted state must be stable in 3D too (the in-plane shortcut
    of a spatial solve); with ``guard_discs`` ((k, 4)) the path must stay clear of them
    (the contact-free shortcut of a scene with obstacles).

    Returns:
        (state (4,): m0, tip x, y, θ; converged, stable, snapped, iterations, residual;
        and the returned state's rest strains (3, ns) and loads (ns, 4)).
    """
    ns = packed.secf.shape[1]
    rest, p_now, loads_now = np.empty((3, ns)), np.empty(p_target.shape[0]), np.empty((ns, 4))
    state = np.array([m0, 0.0, 0.0, 0.0])
    ok, stable, snapped, its, res, _, _ = planar_kernels.follow(
        state, (scene.base_theta, packed.secf, packed.sec_steps), (packed.tubes_i, packed.tubes_f),
        (p_start, start_ctx.loads, start_ctx.m_tip), (p_target, ctx.loads, ctx.m_tip), ctx.params,
        (rest, p_now, loads_now, _NO_RECORD if out is None else out, out is not None),
        (packed.c_j if guard_3d else NO_GUARD, guard_discs))
    return state, ok, stable, snapped, its, res, rest, loads_now


class Loaded(NamedTuple):
    """Stage 1 of a cold solve (:func:`loaded_base_moment`).

    Attributes:
        m0: the base moment reached (N m). iterations, snapped: as an Equilibrium's.
        converged: the loads were ramped in (with a guard: and the guard held all along).
        resolved: the RK4 grid resolves that state (:func:`solver.kernels.grid.planar_fine`); a
            cold path that starts from a state it does not resolve is not trusted.
    """

    m0: float
    iterations: int
    snapped: bool
    converged: bool
    resolved: bool


def loaded_base_moment(problem: Problem, guard_3d=False, guard_discs=NO_DISCS) -> Loaded:
    """Stage 1 of a cold solve of a planar ``problem``: the unactuated arm under its loads
    ramped from zero (cached; the pressures of ``problem`` do not enter).

    With a guard (see :func:`follow`) converged means also that the guard held all along.
    """
    arm, packed, scene, ctx = problem.arm, problem.packed, problem.scene, problem.ctx

    def build():
        zeros = np.zeros(max(arm.n_channels, 1))
        if not guard_3d and not guard_discs.size:
            scaled = _scaled_loaded(problem)
            if scaled is not None:
                return scaled
        unloaded = SceneContext(n_end=ctx.n_end * 0, q=ctx.q * 0, loads=ctx.loads * 0,
                                m_tip=0.0, tol=ctx.tol, max_step=ctx.max_step,
                                params=ctx.params, has_load=False, base_force=ctx.base_force * 0,
                                shooting_index=0.0)
        state, ok, _, snapped, its, _, _, _ = follow(packed, scene, zeros, zeros, unloaded, ctx,
                                                     0.0, guard_3d=guard_3d,
                                                     guard_discs=guard_discs)
        record = _loaded_record(arm, packed, scene, ctx, float(state[0]))[0]
        return Loaded(float(state[0]), int(its), bool(snapped), bool(ok),
                      bool(planar_fine(record, packed.secf, packed.sec_steps, ctx.loads)))

    key = ("loaded", packed.key, scene, guard_3d, guard_discs.tobytes())
    return arm._solver_cache.get(key, build)


def _scaled_loaded(problem: Problem) -> Loaded | None:
    """Stage 1 of a design made by ``ArmDesign.scaled`` from its nominal's (None: not one,
    or the similarity does not apply).

    With every stiffness times f and zero pressure (zero rest strains whatever E and α), the
    arm under loads F has the shape of the nominal arm under F/f, with internal forces and
    moments times f (the constitutive law is linear in the stiffnesses). So the stage is the
    nominal's loaded state followed from F to F/f — the same one-parameter family of load
    levels the cold ramp of the scaled arm traces, entered at F instead of at zero, a few
    Newton steps instead of a whole ramp (docs/design.md §10). Applies when the nominal
    ramp did not snap (no fold, so the family is one branch) and the load change converges.
    """
    arm, packed, scene, ctx = problem.arm, problem.packed, problem.scene, problem.ctx
    scaled_from = arm._solver_cache.scaled_from
    if scaled_from is None or packed.key[0] != "pack":
        return None
    nominal, f = scaled_from
    _, model, settings = packed.key
    # The same request of the nominal design (its pressures do not enter stage 1).
    of_nominal = replace(problem, arm=nominal, packed=pack(nominal, model, settings),
                         settings=settings)
    npacked, nctx = of_nominal.packed, of_nominal.ctx
    base = loaded_base_moment(of_nominal)
    if not (base.converged and base.resolved) or base.snapped:
        return None
    target = replace(nctx, n_end=nctx.n_end / f, q=nctx.q / f, loads=nctx.loads / f,
                     m_tip=nctx.m_tip / f)
    zeros = np.zeros(max(arm.n_channels, 1))
    state, ok, _, snapped, its, _, _, _ = follow(npacked, scene, zeros, zeros, nctx, target, base.m0)
    if not ok or snapped:
        return None
    m0 = f * float(state[0])
    record = _loaded_record(arm, packed, scene, ctx, m0)[0]
    return Loaded(m0, int(its), False, True, bool(planar_fine(record, packed.secf, packed.sec_steps,
                                                              ctx.loads)))


def _loaded_record(arm, packed, scene, ctx, m0):
    """The backbone record of base moment ``m0`` under the scene's full loads at zero
    pressure, and its pass's ∂m/∂m0 minimum (the stage-1 state's stability)."""
    rest = np.vstack(rest_strains(arm, np.zeros(max(arm.n_channels, 1)), packed))
    out = np.empty((packed.n_rows, L.N_COLUMNS))
    bmin = integrate_planar(m0, scene.base_theta, packed.secf, packed.sec_steps, rest, ctx.loads,
                            True, out, False)[5]
    return out, bmin


def not_lean(problem: Problem) -> str | None:
    """Why the lean planar kernels (:func:`solver.kernels.planar.warm_step`,
    :func:`solve_lean`) cannot solve this request (None: they can): they are single shooting
    without contact, on a loaded arm with channels."""
    if not problem.planar:
        return "a spatial solve (planar=False)"
    return not_single(problem)


def not_single(problem: Problem) -> str | None:
    """Why a solve of this request is not plain single shooting, planar or spatial (None: it
    is): what :func:`not_lean` asks besides the plane."""
    arm, scene, model, settings, ctx = (problem.arm, problem.scene, problem.model,
                                        problem.settings, problem.ctx)
    if not arm.n_channels:
        return "a passive arm (no channels)"
    if scene.has_contact:
        return "a scene with obstacles or self-contact (contact)"
    if model == "constant_curvature":
        return "the constant_curvature model"
    if not ctx.has_load and settings.shortcuts:
        return "an unloaded arm (solved in closed form)"
    if settings.n_scan > 0 and ctx.shooting_index > MULTIPLE_SHOOTING_INDEX:
        return f"multiple shooting (L·sqrt(N/EI) = {ctx.shooting_index:.3g} > {MULTIPLE_SHOOTING_INDEX})"
    return None


def solve_lean(problem: Problem, record: bool) -> Equilibrium | None:
    """The common planar solve in one kernel call, where the scene is lean (:func:`not_lean`):
    :func:`solver.kernels.planar.follow` from the warm start (solved in the same scene) or, cold,
    from the cached loaded arm, as :func:`solve_single` calls it, with the grid check in the
    kernel.

    Returns:
        The Equilibrium :func:`solver.solve` returns when the result is converged, stable
        and resolved by the grid (the general path would return it as it is); else None
        (the general path, with its fallbacks and refinement, takes over).
    """
    if not_lean(problem) is not None:
        return None
    packed, scene, warm_start, p_channel = (problem.packed, problem.scene, problem.warm_start,
                                            problem.p_channel)
    ctx = problem.ctx
    if warm_start is not None:
        if warm_start.scene != scene:
            return None
        m0, iterations, snapped = float(warm_start.base_moment[-1]), 0, False
        p_start = warm_start.channel_pressures
    else:
        m0, iterations, snapped, loaded, resolved = loaded_base_moment(problem)
        if not resolved:
            return None
        p_start = np.zeros_like(p_channel)
    out = np.empty((packed.n_rows, L.N_COLUMNS))
    state, ok, stable, snap, its, res, _, loads_now = follow(packed, scene, p_start, p_channel,
                                                              ctx, ctx, m0, out)
    if not (ok and stable and planar_fine(out, packed.secf, packed.sec_steps, loads_now)):
        return None
    return single_result(problem, out, state[0], record, converged=True, stable=True,
                         iterations=int(iterations + its), residual=float(res),
                         snapped=bool(snapped or snap))


def solve_planar(problem: Problem) -> Equilibrium:
    """Planar dead-load solve: single shooting, or multiple shooting where that is
    ill-conditioned or has failed (with the fallbacks on: ``settings.n_scan > 0``)."""
    return solve_either(solve_single, solve_multiple, problem)


def solve_either(single, multiple, problem: Problem) -> Equilibrium:
    """Solve by ``single`` shooting, or by ``multiple`` shooting first where single shooting
    is ill-conditioned (index above MULTIPLE_SHOOTING_INDEX); with the fallbacks on
    (``settings.n_scan > 0``) the other method runs where the first did not return a stable
    converged state. Each covers the other's failures: multiple shooting the ill-conditioned
    arms, single shooting (with its fold scan and branch switching) the buckling ones. Where
    both fail, both run again with :meth:`Settings.finer` continuation, then on a grid of
    twice the steps (returned on this one; docs/design.md §8), then with both; still
    failing, the result of these settings with the smallest residual is returned,
    unconverged (on this grid: where it does not resolve that state, the caller refines)."""
    arm, packed, model, settings = problem.arm, problem.packed, problem.model, problem.settings
    fallbacks = settings.n_scan > 0 and model != "constant_curvature"
    methods = (single, multiple)
    if fallbacks and problem.ctx.shooting_index > MULTIPLE_SHOOTING_INDEX:
        methods = methods[::-1]
    eq = methods[0](problem)
    if not fallbacks or (eq.converged and eq.stable):
        return eq
    iterations = eq.iterations
    finer = settings.finer()
    doubled = refined(arm, packed, 2 * packed.sec_steps)
    stages = [(settings, doubled)]
    if finer != settings:
        stages = [(finer, _packed_for(arm, packed, model, finer)), *stages,
                  (finer, _packed_for(arm, doubled, model, finer))]
    tries = [(method, settings, packed) for method in methods[1:]]
    tries += [(method, tried, layout) for tried, layout in stages for method in methods]
    best = eq
    for method, tried, layout in tries:
        other = method(problem.on(layout, tried))
        iterations += other.iterations
        if not np.array_equal(layout.sec_steps, packed.sec_steps):
            other = on_grid(other, layout.sec_steps, packed.sec_steps)
        if other.converged and other.stable:
            return replace(other, iterations=iterations)
        if other.residual < best.residual and tried is settings:
            best = other
    # The failure nearest a solution: where its grid does not resolve it (single shooting's
    # loaded arm beyond the grid), the caller refines the grid and solves again.
    return replace(best, iterations=iterations)


def _packed_for(arm, packed, model, settings):
    """``packed``'s grid (the settings' one or a refinement of it) packed for ``settings``:
    the packed design keys the caches (scene context, loaded states) that hold the
    continuation parameters, so other settings need their own."""
    base = pack(arm, model, settings)
    if np.array_equal(base.sec_steps, packed.sec_steps):
        return base
    return refined(arm, base, packed.sec_steps)


def solve_single(problem: Problem, guard_3d=False, guard_discs=NO_DISCS) -> Equilibrium:
    """Planar dead-load solve by single shooting on m0 (:func:`solver.kernels.planar.follow`).

    With ``guard_3d`` (the in-plane shortcut of a spatial solve) the result is unconverged
    as soon as the path leaves the states that are stable in 3D, loading stage included;
    with ``guard_discs`` (the contact-free shortcut) as soon as its backbone comes within the
    chords' allowance of a disc (:func:`solver.kernels.obstacles.chords_clear`).
    """
    arm, packed, scene, warm_start, ctx = (problem.arm, problem.packed, problem.scene,
                                           problem.warm_start, problem.ctx)
    p_target = problem.p_target
    iterations = 0
    snapped = False
    if warm_start is not None and warm_start.scene is not None:
        start_ctx = ctx if warm_start.scene == scene else problem.in_scene(warm_start.scene).ctx
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        m0 = float(warm_start.base_moment[-1])  # planar m_z, or z of a spatial m0
    else:
        m0, iterations, snapped, loaded, resolved = loaded_base_moment(problem, guard_3d,
                                                                       guard_discs)
        if (guard_3d or guard_discs.size) and not loaded:
            return Equilibrium._make(tip=np.full(2, np.nan), converged=False, stable=False,
                               iterations=iterations, residual=math.inf)
        if not resolved:
            # The loaded arm is beyond this grid: the ramp from it is not trusted. Its state,
            # unconverged (the caller refines the grid).
            out, bmin = _loaded_record(arm, packed, scene, ctx, m0)
            return single_result(problem, out, m0, converged=False, stable=bool(bmin > 0.0),
                                 iterations=iterations, snapped=snapped,
                                 residual=float(abs(out[-1, L.M] - ctx.m_tip)))
        start_ctx, p_start = ctx, np.zeros_like(p_target)
    out = np.empty((packed.n_rows, L.N_COLUMNS))
    state, ok, stable, snap, its, res, rest, loads_now = follow(
        packed, scene, p_start, p_target, start_ctx, ctx, m0, out, guard_3d, guard_discs)
    if not ok:  # the returned (last good) state was not recorded by a final Newton pass
        integrate_planar(state[0], scene.base_theta, packed.secf, packed.sec_steps, rest,
                         loads_now, True, out, False)
    return single_result(problem, out, state[0], converged=bool(ok), stable=bool(stable),
                         iterations=int(iterations + its), residual=float(res),
                         snapped=bool(snapped or snap))


def single_result(problem: Problem, out, m0, record=True, **flags) -> Equilibrium:
    """The planar Equilibrium of ``problem`` of a backbone record ``out`` (its arrays views
    into it), base moment ``m0``; without ``record``, its tip only."""
    packed = problem.packed
    samples = dict(
        s=out[:, L.S], positions=out[:, L.X:L.Y + 1], angles=out[:, L.THETA],
        shear_stretch=out[:, L.V1:L.V3 + 1], curvature=out[:, L.U],
        internal_force=out[:, L.NX:L.NY + 1], internal_moment=out[:, L.M],
        section_ends=packed.section_ends) if record else {}
    return Equilibrium._make(
        tip=out[-1, L.X:L.Y + 1].copy(), model=problem.model, planar=True, scene=problem.scene,
        pressures=problem.p_inputs, channel_pressures=problem.p_channel,
        base_moment=np.array([float(m0)]), base_force=problem.ctx.base_force, arm=problem.arm,
        **samples, **flags)
