"""Spatial dead-load solves, and the in-plane shortcut that hands them to the planar kernel
only where that cannot change the answer (docs/design.md §6, §10)."""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache

import numpy as np

from solver import layout as L
from solver.kernels import spatial as spatial_kernels
from solver.kernels import spatial_shooting as shooting_kernels
from solver.paths.grid import needs
from solver.paths.planar import NO_DISCS, NO_GUARD, not_single, solve_either, solve_single
from solver.problem import MULTIPLE_SHOOTING_INDEX, Problem, rest_strains, shooting_layout
from solver.results import Equilibrium, tip_only
from solver.rod import base_rotation, rotation_to_quaternion, spatial_strains_into

# Scratch of a spatial path that records nothing.
_NO_RECORD = (np.empty((1, 3)), np.empty((1, 3, 3)), np.empty((1, 3)))


def in_plane_shortcut(problem: Problem) -> Equilibrium | None:
    """A spatial solve of an in-plane scene by the planar kernel, or None where that could
    differ from the spatial path: the planar path must stay stable in 3D at every accepted
    state (an arm curled in a vertical plane may buckle sideways), pass no fold, and single
    shooting must suit the arm; otherwise the spatial kernels solve it (None)."""
    planar_problem = replace(problem, planar=True)  # with the planar context
    if planar_problem.ctx.shooting_index > MULTIPLE_SHOOTING_INDEX:
        return None
    eq = solve_single(planar_problem, guard_3d=True)
    return _embed(eq) if eq.converged and eq.stable else None


def in_plane_state(eq: Equilibrium) -> bool:
    """True when a spatial equilibrium lies in the x–y plane (base moment along z only)."""
    return bool(eq.base_moment.size == 3 and eq.base_moment[0] == 0.0
                and eq.base_moment[1] == 0.0)


def in_plane(problem: Problem) -> bool:
    """True when the pressures bend every section in the x–y plane only (u1* = 0)."""
    u1, u2, _ = rest_strains(problem.arm, problem.p_channel, problem.packed)
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


def spatial_samples(arm, packed, scene, ctx):
    """(section of each sample, arc length s (m), internal force n (N, world frame)) of a
    spatial dead-load record: they depend on the layout and the scene only (cached;
    read-only, shared by every result of the scene)."""
    def build():
        ns = packed.secf.shape[1]
        seg = np.repeat(np.arange(ns), packed.sec_steps + 1)
        starts = np.concatenate([[0.0], np.cumsum(packed.sec_len)[:-1]])
        s = np.concatenate([np.linspace(0.0, length, k + 1) + off for length, k, off in
                            zip(packed.sec_len, packed.sec_steps, starts)])
        force = ctx.n_end[seg] + ctx.q[seg] * (packed.sec_len[seg] - (s - starts[seg]))[:, None]
        for a in (seg, s, force):
            a.flags.writeable = False
        return seg, s, force

    return arm._solver_cache.get(("spatial samples", packed.key, scene), build)


def solve_spatial(problem: Problem) -> Equilibrium:
    """Spatial dead-load solve: single shooting, or multiple shooting where that is
    ill-conditioned or has failed (with the fallbacks on: ``settings.n_scan > 0``), as
    :func:`solver.paths.planar.solve_planar` does in the plane."""
    return solve_either(solve_spatial_single, solve_spatial_multiple, problem)


def solve_spatial_single(problem: Problem) -> Equilibrium:
    """Spatial dead-load solve by single shooting on m0 (:func:`solver.kernels.spatial.follow`):
    the loading stage of a cold solve, then the pressure ramp, whose kernel also records
    the backbone of the state it returns."""
    arm, packed, scene, warm_start, ctx = (problem.arm, problem.packed, problem.scene,
                                           problem.warm_start, problem.ctx)
    quat0 = base_quaternion(scene.base_theta)
    p_target = problem.p_target
    ns = len(arm.sections)
    rest, p_now, loads_now, m_tip = (np.empty((3, ns)), np.empty(p_target.shape[0]),
                                     np.empty((ns, 6)), np.empty(3))
    rows = packed.n_rows
    rec = (np.zeros((rows, 3)), np.zeros((rows, 3, 3)), np.zeros((rows, 3)))
    grid = (quat0, packed.secf, packed.sec_steps, packed.c_j)
    tubes = (packed.tubes_i, packed.tubes_f)
    guard = (NO_GUARD, NO_DISCS)

    iterations = 0
    snap_load = False
    m0 = np.zeros(3)
    if warm_start is not None and warm_start.scene is not None:
        start_ctx = ctx if warm_start.scene is scene else problem.in_scene(warm_start.scene).ctx
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        m0[-warm_start.base_moment.size:] = warm_start.base_moment
        start = (p_start, start_ctx.loads, start_ctx.m_tip)
    else:
        # Stage 1: load the unactuated arm (loads ramped from zero, straight rod, m0 = 0).
        p_start = np.zeros_like(p_target)
        _, _, snap_load, its, _, _, _ = spatial_kernels.follow(
            m0, grid, tubes, (p_start, np.zeros_like(ctx.loads), np.zeros(3)),
            (p_start, ctx.loads, ctx.m_tip), ctx.params,
            (rest, p_now, loads_now, m_tip, _NO_RECORD, False), guard)
        iterations += its
        start = (p_start, ctx.loads, ctx.m_tip)
    ok, stable, snapped, its, res, _, _ = spatial_kernels.follow(
        m0, grid, tubes, start, (p_target, ctx.loads, ctx.m_tip), ctx.params,
        (rest, p_now, loads_now, m_tip, rec, True), guard)
    iterations += its
    # ``stable`` is the stability of the returned state, from the Newton pass that converged
    # on it.
    return spatial_result(problem, *rec, rest, m0,
                           converged=bool(ok and res <= 10 * ctx.tol), stable=bool(stable),
                           iterations=int(iterations), residual=float(res),
                           snapped=bool(snapped or snap_load))


def solve_spatial_lean(problem: Problem, record: bool) -> Equilibrium | None:
    """The common spatial solve, a warm one in the scene of its warm start, without the
    layers of the general path: :func:`solve_spatial_single` and the grid check.

    Returns:
        The Equilibrium :func:`solver.solve` returns where the general path would take single
        shooting and return its result as it is (converged, stable, resolved by the grid,
        no in-plane shortcut); else None (the general path takes over).
    """
    packed, scene, warm_start = problem.packed, problem.scene, problem.warm_start
    if warm_start is None or in_plane_state(warm_start) or not (
            warm_start.scene is scene or warm_start.scene == scene):
        return None
    if not_single(problem) is not None:
        return None
    eq = solve_spatial_single(problem)
    if not (eq.converged and eq.stable):
        return None
    if not needs(eq, packed.secf, packed.mass_per_length * scene.gravity)[1] <= 1.0:
        return None
    return eq if record else tip_only(eq)


@lru_cache(maxsize=64)
def base_quaternion(theta0: float) -> np.ndarray:
    """The unit quaternion of the base frame at base angle ``theta0`` (rad; shared, not to
    be written: left writeable so that the kernels see the array type they were compiled
    for)."""
    quat0 = np.empty(4)
    rotation_to_quaternion(base_rotation(theta0), quat0)
    return quat0


def solve_spatial_multiple(problem: Problem) -> Equilibrium:
    """Spatial dead-load solve by multiple shooting (:mod:`solver.kernels.spatial_shooting`): from
    the nodes of a recorded warm start on this grid, or else from the arm loaded from
    straight (cached per scene), along the pressure ramp."""
    arm, scene, warm_start = problem.arm, problem.scene, problem.warm_start
    layout, segs, _ = shooting_layout(arm, problem.packed)
    on_layout = problem.on(layout)
    ctx = on_layout.ctx
    p_target = problem.p_target
    ns = len(arm.sections)
    rest, p_now, loads_now, m_tip = (np.empty((3, ns)), np.empty(p_target.shape[0]),
                                     np.empty((ns, 6)), np.empty(3))
    kernel = (segs, layout.secf, layout.sec_steps, layout.c_j, layout.tubes_i, layout.tubes_f)
    work = (ctx.params, layout.moment_scale, rest, p_now, loads_now, m_tip)
    iterations = 0
    load_snapped = False
    if warm_start is not None and warm_start.scene is not None \
            and warm_start.orientations.shape[0] == layout.n_rows:
        quats, moms = _nodes_of(warm_start, segs, scene)
        start_ctx = on_layout.in_scene(warm_start.scene).ctx
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        start = (p_start, start_ctx.loads, start_ctx.m_tip)
    else:
        quats, moms, iterations, loaded, load_snapped = _loaded_nodes(arm, layout, segs, scene, ctx,
                                                                      kernel, work)
        start = (np.zeros_like(p_target), ctx.loads, ctx.m_tip)
        if not loaded:
            return _nodes_result(on_layout, quats, moms, segs, rest, loads_now,
                                 converged=False, stable=False, iterations=iterations,
                                 residual=math.inf, snapped=load_snapped)
    ok, its, stable, res, snapped = shooting_kernels.follow(
        quats, moms, *kernel, start[0], p_target, start[1], ctx.loads, start[2], ctx.m_tip, *work)
    return _nodes_result(on_layout, quats, moms, segs, rest, loads_now,
                         converged=bool(ok), stable=bool(stable), iterations=iterations + its,
                         residual=float(res), snapped=bool(snapped or load_snapped))


def _nodes_of(eq, segs, scene):
    """Multiple-shooting nodes (quaternions (K, 4), moments (K, 3)) at the segment starts of
    a recorded spatial equilibrium on the same grid."""
    rows = segs[:, L.SEG_ROW0] + segs[:, L.SEG_FIRST]
    quats = np.empty((rows.size, 4))
    for k, row in enumerate(rows):
        rotation_to_quaternion(np.ascontiguousarray(eq.orientations[row]), quats[k])
    quats[0] = base_quaternion(scene.base_theta)
    return quats, np.ascontiguousarray(eq.internal_moment[rows])


def _loaded_nodes(arm, layout, segs, scene, ctx, kernel, work):
    """Stage 1 of a cold multiple-shooting solve (cached per scene): the unactuated arm's
    loads ramped in from the straight, unloaded rod. Returns copies of the nodes, the
    iterations, whether it converged and whether it snapped."""
    def build():
        quats = np.empty((segs.shape[0], 4))
        quats[0] = base_quaternion(scene.base_theta)
        quats[1:] = quats[0]
        moms = np.zeros((segs.shape[0], 3))
        p0 = np.zeros(max(arm.n_channels, 1))
        ok, its, stable, _, snapped = shooting_kernels.follow(
            quats, moms, *kernel, p0, p0, np.zeros_like(ctx.loads), ctx.loads, np.zeros(3),
            ctx.m_tip, *work)
        for a in (quats, moms):
            a.flags.writeable = False
        return quats, moms, int(its), bool(ok and stable), bool(snapped)

    quats, moms, its, ok, snapped = arm._solver_cache.get(("spatial loaded nodes", layout.key, scene),
                                                          build)
    return quats.copy(), moms.copy(), its, ok, snapped


def _nodes_result(problem: Problem, quats, moms, segs, rest, loads, **fields):
    """The Equilibrium of ``problem`` (on the nodes' layout) of multiple-shooting nodes at the
    level of rest strains ``rest`` and loads ``loads`` (the backbone recorded segment by
    segment)."""
    layout = problem.packed
    rows = layout.n_rows
    pos, rot, mom = np.zeros((rows, 3)), np.zeros((rows, 3, 3)), np.zeros((rows, 3))
    shooting_kernels.record(quats, moms, segs, layout.secf, layout.sec_steps, layout.c_j, rest,
                            loads, np.empty((6, L.NSTATE)), pos, rot, mom)
    return spatial_result(problem, pos, rot, mom, rest, moms[0].copy(), **fields)


def spatial_result(problem: Problem, pos, rot, mom, rest, m0, **fields):
    """The spatial Equilibrium of ``problem`` of a recorded backbone: positions, frames and
    moments (N, ·) at the rest strains ``rest`` and base moment ``m0``; strains from the
    constitutive law."""
    packed, ctx = problem.packed, problem.ctx
    seg, s, force = spatial_samples(problem.arm, packed, problem.scene, ctx)
    strain_v, strain_u = np.empty((s.size, 3)), np.empty((s.size, 3))
    spatial_strains_into(rot, force, mom, rest, seg, packed.c_a, packed.c_g, packed.c_i,
                         packed.c_j, strain_v, strain_u)
    return problem.equilibrium(s=s, positions=pos, orientations=rot, shear_stretch=strain_v,
                               curvature=strain_u, internal_force=force, internal_moment=mom,
                               section_ends=packed.section_ends, tip=pos[-1].copy(),
                               base_moment=m0.copy(), base_force=ctx.base_force, **fields)
