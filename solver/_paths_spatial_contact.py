"""Spatial solves with obstacles: cylinders, spheres and discs pressed on by penalty contact,
by multiple shooting along the quasi-static path (docs/design.md §9)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from solver import _spatial_contact as _sc
from solver import layout as L
from solver._model import contact_layout, context, reach
from solver._obstacles import clearance_3d, tunnels_3d
from solver._paths_shooting import MAX_STEP
from solver._paths_spatial import solve_spatial
from solver.results import Equilibrium
from solver.rod import base_rotation, rest_strains_into, rotation_to_quaternion
from solver.scene import core_distance


def solve_contact_spatial(arm, packed, p_inputs, p_channel, scene, model, warm_start, settings):
    """Spatial solve with penalty contact against the scene's obstacles
    (:mod:`solver._spatial_contact`), the obstacles present all along the quasi-static path.

    Obstacles beyond the arm's reach (:func:`solver._model.reach`): the contact-free spatial
    solve (``settings.shortcuts``). Otherwise multiple shooting at the planar contact
    resolution (:func:`solver._model.contact_layout`). Start: a spatial contact
    ``warm_start`` on this grid continues from its nodes, another recorded spatial warm start
    from its samples interpolated to the nodes (Newton corrects them at the start of the
    ramp); a cold solve from the arm loaded with the obstacles in place
    (:func:`_loaded_nodes`). Pressures and loads are then ramped to the target's. A fold on
    the way (a snap) is not passed: the solve is then reported unconverged at the last
    state it reached.
    """
    free_scene = replace(scene, obstacles=())
    obstacles = scene.obstacles_array()
    if settings.shortcuts and all(core_distance(o, np.zeros(3))[0] - o.radius
                                  > reach(arm, packed, scene) for o in scene.obstacles):
        free = solve_spatial(arm, packed, p_inputs, p_channel, free_scene, model,
                             warm_start if warm_start is not None and not warm_start.in_contact
                             else None, settings)
        n = free.positions.shape[0]
        return replace(free, scene=scene, contact_force=np.zeros((n, 3)), penetration=np.zeros(n))
    if settings.shortcuts and warm_start is not None and warm_start.s.size \
            and not warm_start.in_contact:
        free = solve_spatial(arm, packed, p_inputs, p_channel, free_scene, model, warm_start,
                             settings)
        if free.converged and free.stable and _clear(free, warm_start, obstacles):
            n = free.positions.shape[0]
            return replace(free, scene=scene, contact_force=np.zeros((n, 3)),
                           penetration=np.zeros(n))
    layout, segs, sec_start = contact_layout(arm, packed, scene)
    ctx = context(arm, layout, free_scene, 3, settings)
    grid, terms = _grid_and_terms(arm, layout, segs, sec_start, scene, ctx)
    p_target = p_channel if arm.n_channels else np.zeros(1)
    goal = (p_target, ctx.q, terms[0], terms[1], obstacles)
    iterations = 0
    nodes = None
    if warm_start is not None and warm_start.scene is not None:
        start_scene = replace(warm_start.scene, obstacles=())
        start_ctx = ctx if start_scene == free_scene else context(arm, layout, start_scene, 3,
                                                                 settings)
        if warm_start.shooting_nodes.shape == (segs.shape[0] * L.N_CSTATE,):
            nodes = warm_start.shooting_nodes.reshape(-1, L.N_CSTATE).copy()
        elif warm_start.s.size:
            nodes = _nodes_from_record(warm_start, grid, layout, segs, sec_start)
        if nodes is not None:
            start_terms = _grid_and_terms(arm, layout, segs, sec_start, start_scene, start_ctx)[1]
            p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
            start = (p_start, start_ctx.q, start_terms[0], start_terms[1], obstacles)
    if nodes is None:
        nodes, iterations, loaded = _loaded_nodes(arm, layout, segs, sec_start, scene, ctx,
                                                  settings)
        start = (np.zeros_like(p_target), *goal[1:])
        if not loaded:
            return _result(nodes, scene, grid, layout, start, converged=False, stable=False,
                           iterations=iterations, residual=math.inf, model=model,
                           pressures=p_inputs, channel_pressures=p_channel, arm=arm)
    now = tuple(np.empty_like(a) for a in goal)
    rest = np.empty((3, len(arm.sections)))
    ok, its, res, stable, _ = _sc.follow(
        nodes, grid, layout.tubes_i, layout.tubes_f, start, goal, *terms[2:], settings.tol,
        settings.max_iter, MAX_STEP, settings.dt0, settings.contact_dt_min, rest, now)
    return _result(nodes, scene, grid, layout, now, converged=bool(ok), stable=bool(stable),
                   iterations=int(iterations + its), residual=float(res), model=model,
                   pressures=p_inputs, channel_pressures=p_channel, arm=arm)


def _clear(free, start, obstacles) -> bool:
    """Whether the contact-free step from the recorded ``start`` to ``free`` (same grid)
    stays clear of every obstacle: both backbones by more than an RK4 step (the samples'
    spacing), and no sample moving through one between them
    (:func:`solver._obstacles.tunnels_3d`, no slack). A contact-free path that leaves the
    obstacles' reach of either end and comes back is not caught (a warm step seldom does)."""
    if start.positions.shape != free.positions.shape:
        return False
    margin = float(np.max(np.diff(free.s)))
    for eq in (start, free):
        for k in range(obstacles.shape[0]):
            if clearance_3d_all(eq.positions, obstacles[k:k + 1]) <= margin:
                return False
    return not tunnels_3d(start.positions, free.positions, obstacles, 0.0)


def clearance_3d_all(points, obstacles) -> float:
    """Smallest signed gap (m) from (N, 3) points to the obstacles' surfaces."""
    return min(clearance_3d(p[0], p[1], p[2], obstacles) for p in points)


def _grid_and_terms(arm, layout, segs, sec_start, scene, ctx):
    """The layout tuple (``GS_*``) and (endplate weights (ns, 3), tip target (6,), weights of
    the unknowns, of the residuals, of the tangent coordinates) of ``scene``."""
    quat0 = np.empty(4)
    rotation_to_quaternion(base_rotation(scene.base_theta), quat0)
    grid = (quat0, segs, layout.secf, layout.sec_steps, layout.c_j, sec_start)
    g = np.array([0.0, -scene.gravity, 0.0])
    plate = layout.endplate[:, None] * g[None, :]
    target = np.concatenate([ctx.n_end[-1], ctx.m_tip])  # n(L⁻) includes the last endplate
    force = float(np.abs(ctx.n_end).max() + np.abs(ctx.q).max() * arm.length) + 1.0
    scales = np.repeat([arm.length, 1.0, force, layout.moment_scale], 3)
    weights = np.concatenate([scales[L.CT_N:], np.tile(scales, segs.shape[0] - 1)])
    res_weights = np.concatenate([np.tile(scales, segs.shape[0] - 1), scales[L.CT_N:]])
    return grid, (plate, target, weights, res_weights, scales)


def _node_rows(segs):
    return segs[:, L.SEG_ROW0] + segs[:, L.SEG_FIRST]


def _node_arcs(layout, segs, sec_start):
    """Arc length (m) of every node (K,)."""
    h = layout.sec_len / layout.sec_steps
    i = segs[:, L.SEG_SECTION]
    return sec_start[i] + segs[:, L.SEG_FIRST] * h[i]


def _nodes_from_record(eq, grid, layout, segs, sec_start):
    """Node states (K, N_CSTATE) from a recorded spatial equilibrium at another resolution:
    positions, forces and moments interpolated linearly in arc length within each section
    (so that a node at a section start takes the force past the endplate), orientations by
    normalised linear interpolation of sign-aligned quaternions."""
    quats = np.empty((eq.s.size, 4))
    for k in range(eq.s.size):
        rotation_to_quaternion(np.ascontiguousarray(eq.orientations[k]), quats[k])
        if k and quats[k] @ quats[k - 1] < 0.0:
            quats[k] = -quats[k]
    samples = np.column_stack([eq.positions, quats, eq.internal_force, eq.internal_moment])
    ends = np.asarray(eq.section_ends)
    starts = np.concatenate([[0], ends[:-1] + 1])
    arcs = _node_arcs(layout, segs, sec_start)
    nodes = np.empty((segs.shape[0], L.N_CSTATE))
    for k, i in enumerate(segs[:, L.SEG_SECTION]):
        part = slice(starts[i], ends[i] + 1)
        for c in range(L.N_CSTATE):
            nodes[k, c] = np.interp(arcs[k], eq.s[part], samples[part, c])
    nodes[:, L.CS_Q:L.CS_Q + 4] /= np.linalg.norm(nodes[:, L.CS_Q:L.CS_Q + 4], axis=1)[:, None]
    nodes[0, L.CS_R:L.CS_R + 3] = 0.0
    nodes[0, L.CS_Q:L.CS_Q + 4] = grid[L.GS_QUAT0]
    return nodes


def _loaded_nodes(arm, layout, segs, sec_start, scene, ctx, settings):
    """Stage 1 of a cold solve (cached per scene): from the straight, unloaded, unactuated
    arm the loads are ramped in with the obstacles in place; an obstacle that overlaps the
    straight arm grows in from the radius at which it touches the arm's axis. Returns a copy
    of the nodes, the iterations and whether it converged."""
    def build():
        grid, terms = _grid_and_terms(arm, layout, segs, sec_start, scene, ctx)
        axis = base_rotation(scene.base_theta)[:, 2]
        nodes = np.zeros((segs.shape[0], L.N_CSTATE))
        nodes[:, L.CS_R:L.CS_R + 3] = _node_arcs(layout, segs, sec_start)[:, None] * axis
        nodes[:, L.CS_Q:L.CS_Q + 4] = grid[L.GS_QUAT0]
        obstacles = scene.obstacles_array()
        straight = np.linspace(0.0, arm.length, 257)[:, None] * axis
        grown = obstacles.copy()
        for k, o in enumerate(scene.obstacles):
            grown[k, L.O_RADIUS] = min(o.radius, float(core_distance(o, straight).min()))
        p0 = np.zeros(max(arm.n_channels, 1))
        start = (p0, np.zeros_like(ctx.q), np.zeros_like(terms[0]), np.zeros(6), grown)
        goal = (p0, ctx.q, terms[0], terms[1], obstacles)
        now = tuple(np.empty_like(a) for a in goal)
        ok, its, _, stable, _ = _sc.follow(
            nodes, grid, layout.tubes_i, layout.tubes_f, start, goal, *terms[2:], settings.tol,
            settings.max_iter, MAX_STEP, settings.dt0, settings.contact_dt_min,
            np.empty((3, len(arm.sections))), now)
        nodes.flags.writeable = False
        return nodes, int(its), bool(ok and stable)

    nodes, its, ok = arm._solver_cache.get(("spatial loaded contact nodes", layout.key, scene),
                                           build)
    return nodes.copy(), its, ok


def _result(nodes, scene, grid, layout, level, **fields):
    """The spatial Equilibrium of the node states ``nodes`` at ``level``."""
    rest = np.empty((3, layout.secf.shape[1]))
    rest_strains_into(level[L.L_P], layout.tubes_i, layout.tubes_f, layout.secf, rest)
    rec = _sc.new_record(layout.n_rows)
    _sc.record(nodes, grid, rest, level, rec)
    s, pos, rot, force, mom, contact, pen, strain_v, strain_u = rec
    return Equilibrium._make(
        s=s, positions=pos, orientations=rot, shear_stretch=strain_v, curvature=strain_u,
        internal_force=force, internal_moment=mom, section_ends=layout.section_ends,
        contact_force=contact, penetration=pen, in_contact=bool(pen.max() > 0.0),
        tip=pos[-1].copy(), planar=False, scene=scene, base_moment=nodes[0, L.CS_M:].copy(),
        base_force=nodes[0, L.CS_N:L.CS_N + 3].copy(), shooting_nodes=nodes.ravel().copy(),
        **fields)
