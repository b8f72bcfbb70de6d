"""Spatial solves with obstacles: cylinders, spheres and discs pressed on by penalty contact,
by multiple shooting along the quasi-static path (docs/design.md §9)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from solver import layout as L
from solver.kernels import spatial_contact as kernel
from solver.kernels.contact import TUNNEL_SLACK
from solver.kernels.obstacles import free_step_gap, tunnels_3d
from solver.paths.contact import free_contact_result
from solver.paths.friction import friction_fields, landed, new_level, start_samples
from solver.paths.grid import section_rows
from solver.paths.shooting import MAX_STEP
from solver.paths.spatial import solve_spatial
from solver.problem import Problem, contact_layout, reach
from solver.results import Equilibrium
from solver.rod import base_rotation, rest_strains_into, rotation_to_quaternion
from solver.scene import core_distance


def solve_contact_spatial(problem: Problem) -> Equilibrium:
    """Spatial solve with penalty contact against the scene's obstacles
    (:mod:`solver.kernels.spatial_contact`), the obstacles present all along the quasi-static path.

    Obstacles beyond the arm's reach (:func:`solver.problem.reach`): the contact-free spatial
    solve (``settings.shortcuts``). From a warm start that touches nothing, the contact-free
    step answers where it did not snap and its end clears every obstacle between every two
    samples with no sample coming near one on the way
    (:func:`solver.kernels.obstacles.free_step_gap`); where its samples clear them but not
    so, Newton on the contact grid from it (not with friction). Otherwise multiple shooting
    at the planar contact resolution (:func:`solver.problem.contact_layout`). Start: a spatial contact
    ``warm_start`` on this grid continues from its nodes, another recorded spatial warm start
    from its samples interpolated to the nodes (Newton corrects them at the start of the
    ramp); a cold solve from the arm loaded with the obstacles in place
    (:func:`_loaded_nodes`). Pressures and loads are then ramped to the target's. Where the
    path ends at a fold or a bifurcation the arm snaps to the stable state found along the
    critical mode (:func:`_switch_branch`, ``eq.snapped``) and the ramp goes on from there.
    Where none is found but the contact-free step from a state that touched nothing snapped
    (the spatial kernels' branch switch) into an obstacle without passing through it, the arm
    lands there: the obstacles are grown in from the radius at which they touch it. Failing
    all of these, the solve is reported unconverged at the last state it reached.
    """
    arm, packed, scene, model, warm_start, settings = (
        problem.arm, problem.packed, problem.scene, problem.model, problem.warm_start,
        problem.settings)
    p_inputs, p_channel = problem.p_inputs, problem.p_channel
    free_scene = replace(scene, obstacles=())
    obstacles = scene.obstacles_array()
    before = warm_start.dissipated if warm_start is not None else 0.0
    if settings.shortcuts and out_of_reach(problem):
        free = solve_spatial(problem.in_scene(
            free_scene, warm_start if warm_start is not None and not warm_start.in_contact else None))
        return free_contact_result(free, scene, before)
    free, near = None, False
    if settings.shortcuts and warm_start is not None and warm_start.s.size \
            and not warm_start.in_contact:
        free = solve_spatial(problem.in_scene(free_scene, warm_start))
        # A snap's way between the two states is not known: the ramp below follows the step
        # with the obstacles present and lands it by its own branch switch.
        gap, clear = _free_step_gap(free, warm_start, obstacles) \
            if free.converged and free.stable and not free.snapped else (-math.inf, False)
        if clear:
            return free_contact_result(free, scene, before)
        # With friction the ramp takes it: Newton at the end would land without anchors (as
        # if frictionless), where the ramp forms them at its start.
        near = gap > 0.0 and not scene.has_friction
    layout, segs, sec_start = contact_layout(arm, packed, scene)
    on_layout = problem.on(layout)
    ctx = on_layout.ctx  # (a context does not depend on obstacles)
    grid, terms = grid_and_terms(arm, layout, segs, sec_start, scene, ctx)
    p_target = problem.p_target
    mu, samples = start_samples(scene, layout, sec_start, warm_start)
    goal = (p_target, ctx.q, terms[0], terms[1], obstacles, mu, samples)
    rest = np.empty((3, len(arm.sections)))
    if near:
        # The free step's samples end clear of the obstacles, but not its chords by their
        # allowance, and got there without passing through one: that state, corrected by
        # Newton on the contact grid (where a stage point may graze the obstacle), is the answer.
        nodes = _nodes_from_record(free, grid, layout, segs, sec_start)
        _level_rest(goal, layout, rest)
        ok, its, res, stable = kernel.newton(nodes, grid, rest, goal, *terms[2:], settings.tol,
                                             settings.max_iter, MAX_STEP, kernel.NO_TETHER)
        if ok and stable:
            return _result(nodes, scene, grid, layout, goal, warm_start, converged=True, stable=True,
                           snapped=free.snapped, iterations=int(free.iterations + its),
                           residual=float(res), model=model, pressures=p_inputs,
                           channel_pressures=p_channel, arm=arm)
    iterations = 0
    nodes = None
    snapped = False
    if warm_start is not None and warm_start.scene is not None:
        start_scene = replace(warm_start.scene, obstacles=())
        start_ctx = ctx if start_scene == free_scene else on_layout.in_scene(start_scene).ctx
        if warm_start.shooting_nodes.shape == (segs.shape[0] * L.N_CSTATE,):
            nodes = warm_start.shooting_nodes.reshape(-1, L.N_CSTATE).copy()
        elif warm_start.s.size:
            nodes = _nodes_from_record(warm_start, grid, layout, segs, sec_start)
        if nodes is not None:
            start_terms = grid_and_terms(arm, layout, segs, sec_start, start_scene, start_ctx)[1]
            p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
            start = (p_start, start_ctx.q, start_terms[0], start_terms[1], obstacles, mu, samples)
    if nodes is None:
        nodes, iterations, loaded, snapped, samples = _loaded_nodes(arm, layout, segs, sec_start,
                                                                    scene, ctx, settings)
        start = (np.zeros_like(p_target), *goal[1:L.L_FRICTION], samples)
        if not loaded:
            return _result(nodes, scene, grid, layout, start, None, converged=False, stable=False,
                           iterations=iterations, residual=math.inf, model=model,
                           pressures=p_inputs, channel_pressures=p_channel, arm=arm)
    now = new_level(goal)
    nodes, ok, its, res, stable, jumped = _ramp(nodes, grid, layout, start, goal, terms, settings,
                                                rest, now)
    iterations += its
    snapped = snapped or jumped
    if not ok and free is not None and free.snapped and free.converged and free.stable \
            and not tunnels_3d(warm_start.positions, free.positions, obstacles, TUNNEL_SLACK):
        # The arm snapped through free space (the free path's own branch switch) into the
        # obstacles: it lands on them, the obstacles grown in from where they touch it.
        arrived = _nodes_from_record(free, grid, layout, segs, sec_start)
        grown = obstacles.copy()
        for k, o in enumerate(scene.obstacles):
            grown[k, L.O_RADIUS] = min(o.radius, float(core_distance(o, free.positions).min()))
        ok, its, res, stable, _ = kernel.follow(
            arrived, grid, layout.tubes_i, layout.tubes_f,
            landed((*goal[:L.L_DISCS], grown, *goal[L.L_MU:])), goal,
            *terms[2:], settings.tol, settings.max_iter, MAX_STEP, settings.dt0,
            settings.contact_dt_min, rest, now)
        iterations += its
        if ok:
            nodes, snapped = arrived, True
    return _result(nodes, scene, grid, layout, now, warm_start, converged=bool(ok),
                   stable=bool(stable),
                   snapped=snapped, iterations=int(iterations), residual=float(res),
                   model=model, pressures=p_inputs, channel_pressures=p_channel, arm=arm)


def out_of_reach(problem: Problem) -> bool:
    """Whether every obstacle of the scene lies beyond the arm's reach from its base
    (:func:`solver.problem.reach`, a bound over all pressures)."""
    bound = reach(problem.arm, problem.packed, problem.scene)
    return all(core_distance(o, np.zeros(3))[0] - o.radius > bound for o in problem.scene.obstacles)


def _ramp(nodes, grid, layout, start, goal, terms, settings, rest, now):
    """The quasi-static ramp from ``nodes`` at level ``start`` to ``goal``
    (:func:`solver.kernels.spatial_contact.follow`), snapping where it ends short of the goal
    (:func:`_switch_branch`, at most MAX_SNAPS times). Returns (nodes, converged, iterations,
    |residual|, stable, snapped); ``now`` and ``rest`` hold the level reached."""
    snapped = False
    iterations = 0
    origin = (nodes.copy(), start)
    for _ in range(MAX_SNAPS + 1):
        ok, its, res, stable, t = kernel.follow(
            nodes, grid, layout.tubes_i, layout.tubes_f, start, goal, *terms[2:], settings.tol,
            settings.max_iter, MAX_STEP, settings.dt0, settings.contact_dt_min, rest, now)
        iterations += its
        if ok or t >= 1.0 or settings.n_scan == 0:
            break
        # A landing the path cannot leave (t = 0: at a fold again) asks for a real snap.
        switched = _switch_branch(nodes, origin, grid, layout, start, goal, t, terms, settings,
                                  push=not (snapped and t == 0.0))
        if switched is None:
            break
        nodes, start = switched
        snapped = True
    return nodes, ok, iterations, res, stable, snapped


# Snaps per spatial contact solve before it gives up, and how far past the fold (in the
# ramp's parameter) and how far along the critical mode (weighted RMS of the unknowns) a
# branch switch looks, tried in turn.
MAX_SNAPS = 4
SNAP_AHEAD = (1e-3, 1e-2, 5e-2)
SNAP_AMPLITUDES = (0.02, 0.05, 0.1, 0.2, 0.5)


def _switch_branch(nodes, origin, grid, layout, start, goal, t, terms, settings, push=True):
    """The stable state the arm moves to where the path from ``start`` to ``goal`` ends at
    ``t`` (a fold or a bifurcation — an arm pressed on an obstacle in its plane sliding out
    of it), and the level it stands at: (nodes, level), or None. ``origin``: (nodes, level)
    where the whole ramp began, well clear of the fold. ``push``: try the small pushes
    along the critical mode first (not where the last one landed on another fold).

    A little further on (SNAP_AHEAD), the critical mode is the right singular vector of
    the smallest singular value of the weighted shooting Jacobian at the last state; Newton
    starts from the state moved along it by growing amplitudes (the mode signed so that it
    lifts the arm towards +z first: a symmetric sideways pitchfork takes the +z mirror
    image, as the dead-load kernels do), and the first stable equilibrium whose backbone got
    there without tunnelling through an obstacle is the one the arm lands on. Failing that,
    the imperfect path (:func:`_imperfect_path`).
    """
    weights, res_weights, scales = terms[2:]
    n = weights.size
    rest = np.empty((3, layout.secf.shape[1]))
    before = kernel.new_record(layout.n_rows)
    _level_rest(_level_at(start, goal, t), layout, rest)
    kernel.record(nodes, grid, rest, _level_at(start, goal, t), before)
    for ahead in SNAP_AHEAD if push else ():
        level = _level_at(start, goal, min(1.0, t + ahead))
        _level_rest(level, layout, rest)
        mode = _critical_mode(nodes, grid, rest, level, terms)
        if mode is None:
            return None
        for amplitude in SNAP_AMPLITUDES:
            for sign in (1.0, -1.0):
                trial = np.empty_like(nodes)
                kernel.retract(nodes, mode, sign * amplitude * math.sqrt(n), trial)
                ok, _, _, stable = kernel.probe(trial, grid, rest, level, weights, res_weights,
                                                scales, settings.tol, 4 * settings.max_iter,
                                                MAX_STEP, kernel.NO_TETHER)
                if not (ok and stable):
                    continue
                after = kernel.new_record(layout.n_rows)
                kernel.record(trial, grid, rest, level, after)
                if not tunnels_3d(before[1], after[1], level[L.L_DISCS], TUNNEL_SLACK):
                    return trial, level
    level = _level_at(start, goal, min(1.0, t + SNAP_AHEAD[1]))
    relaxed = _relax(nodes, grid, layout, level, terms, settings)
    if relaxed is not None:
        return relaxed, level
    _level_rest(level, layout, rest)
    mode = _critical_mode(nodes, grid, rest, level, terms)
    if mode is None:
        return None
    return _imperfect_path(origin[0].copy(), grid, layout, origin[1], goal,
                           _tip_direction(nodes, mode), terms, settings)


def _critical_mode(nodes, grid, rest, level, terms):
    """The critical mode at ``level`` (rest strains ``rest``) of the state ``nodes``: the
    right singular vector of the smallest singular value of the weighted shooting Jacobian,
    in the unknowns' units, signed to lift the arm towards +z; None where the state is not
    finite."""
    weights, res_weights, scales = terms[2:]
    n = weights.size
    F, J = np.empty(n), np.empty((n, n))
    blocks = np.empty((nodes.shape[0], L.N_CTANGENT, L.N_CTANGENT))
    if not kernel.newton_system(nodes, grid, rest, level, F, J, True, blocks, scales, kernel.NO_TETHER):
        return None
    mode = np.linalg.svd(J * weights[None, :] / res_weights[:, None])[2][-1] * weights
    lift = np.empty_like(nodes)
    kernel.retract(nodes, mode, 1e-6, lift)
    return -mode if np.sum(lift[:, L.CS_R + 2] - nodes[:, L.CS_R + 2]) < 0.0 else mode


# Proximal relaxation (see _relax): iterations, the first spring (the force scale per
# RELAX_START of the arm's length), the move under which the springs slacken, how far they
# slacken before the arm is let go, and how far the springs' pull may change from one
# iteration to the next where they slacken as the arm slides on.
RELAX_STEPS = 400
RELAX_START = 1e-3
RELAX_MOVE = 1e-3
RELAX_END = 1e-6
RELAX_STRAIGHT = 0.1


def _relax(nodes, grid, layout, level, terms, settings):
    """The stable equilibrium at ``level`` that an arm started at ``nodes`` (past a fold,
    no longer an equilibrium) comes to rest in, by proximal point iterations: every node
    after the base is tied by a spring of k N/m to where it is, the tethered equilibrium is
    solved by Newton, and the anchors move there. The springs are conservative, so each
    iteration lowers the arm's energy: it follows its energy downhill, as a damped arm
    does. k starts stiff (the force scale per RELAX_START of the length); it slackens
    fourfold while the arm moves less than RELAX_MOVE of its length per iteration, halves
    while it slides on at an even pace (the springs' pull within RELAX_STRAIGHT of the last
    iteration's), and stiffens fourfold where Newton fails or a node would pass through an
    obstacle. Below RELAX_END of its start the arm is let go: the untethered Newton must
    land on a stable state. Returns the nodes or None."""
    weights, res_weights, scales = terms[2:]
    rest = np.empty((3, layout.secf.shape[1]))
    _level_rest(level, layout, rest)
    start = scales[L.CT_N] / (RELAX_START * scales[L.CT_R])
    stiffness = start
    state = nodes.copy()
    last_pull = None
    for _ in range(RELAX_STEPS):
        anchors = state[:, L.CS_R:L.CS_R + 3].copy()
        trial = state.copy()
        ok = kernel.newton(trial, grid, rest, level, weights, res_weights, scales, settings.tol,
                           settings.max_iter, MAX_STEP, kernel.tether(stiffness, anchors))[0]
        if not ok or tunnels_3d(anchors, trial[:, L.CS_R:L.CS_R + 3], level[L.L_DISCS],
                                TUNNEL_SLACK):
            stiffness *= 4.0
            if stiffness > start / RELAX_END:
                return None
            continue
        # The springs' pull (N per node: k times the move) is the energy's downhill force at
        # the new state, so an iteration is an implicit Euler step of the arm's gradient flow,
        # of time step 1/k. Where the pull keeps within RELAX_STRAIGHT of the last one the flow
        # runs straight at an even pace, and a step twice as long still follows it (a
        # snap's arm crept ~1 mm an iteration for 250 of them, just over RELAX_MOVE).
        moved = trial[:, L.CS_R:L.CS_R + 3] - anchors
        move = float(np.abs(moved).max())
        pull = stiffness * moved
        state = trial
        even = last_pull is not None and \
            float(np.abs(pull - last_pull).max()) <= RELAX_STRAIGHT * stiffness * move
        last_pull = pull
        if even and move >= RELAX_MOVE * scales[L.CT_R]:
            stiffness = max(0.5 * stiffness, RELAX_END * start)
        elif move < RELAX_MOVE * scales[L.CT_R]:
            stiffness *= 0.25
            if stiffness < RELAX_END * start:
                final = state.copy()
                ok, _, _, stable = kernel.newton(final, grid, rest, level, weights, res_weights,
                                                 scales, settings.tol, settings.max_iter, MAX_STEP,
                                                 kernel.NO_TETHER)
                if ok and stable:
                    return final
    return None


def _tip_direction(nodes, mode):
    """Unit tip displacement (3,) of the nodes moved along ``mode`` (zero if none)."""
    moved = np.empty_like(nodes)
    kernel.retract(nodes, mode, 1e-6, moved)
    direction = moved[-1, L.CS_R:L.CS_R + 3] - nodes[-1, L.CS_R:L.CS_R + 3]
    norm = np.linalg.norm(direction)
    return direction / norm if norm > 0.0 else direction


# Sizes of the imperfection (fractions of the force scale) an imperfect path tries in turn.
IMPERFECTIONS = (1e-3, 1e-2)


def _imperfect_path(nodes, grid, layout, level, goal, direction, terms, settings):
    """Where a small push does not land the arm on a stable state (a snap, not a gentle
    pitchfork), the way a real arm gets there: a small tip force along ``direction`` (the
    critical mode's tip displacement; an imperfection) is brought in at the path's start
    (``nodes`` at ``level``, where the ramp began), the ramp is followed to ``goal`` with
    it — the imperfect path goes round the fold the perfect one ends at — and the force is
    taken off again. Returns (nodes, goal) or None."""
    weights, res_weights, scales = terms[2:]
    if not np.linalg.norm(direction) > 0.0:
        return None
    rest = np.empty((3, layout.secf.shape[1]))
    for size in IMPERFECTIONS:
        for sign in (1.0, -1.0):
            push = sign * size * scales[L.CT_N] * direction
            trial = nodes.copy()
            stages = ((level, _pushed(level, push)), (_pushed(level, push), _pushed(goal, push)),
                      (_pushed(goal, push), goal))
            for a, b in stages:
                now = new_level(b)
                ok, _, _, stable, _ = kernel.follow(
                    trial, grid, layout.tubes_i, layout.tubes_f, a, b, weights, res_weights,
                    scales, settings.tol, settings.max_iter, MAX_STEP, settings.dt0,
                    settings.contact_dt_min, rest, now)
                if not (ok and stable):
                    break
            else:
                return trial, goal
    return None


def _pushed(level, push):
    """``level`` with the tip force ``push`` (3,) added to its tip target."""
    target = level[L.L_TARGET].copy()
    target[:3] += push
    return (*level[:L.L_TARGET], target, *level[L.L_TARGET + 1:])


def _level_at(start, goal, t):
    """The level tuple a fraction ``t`` of the way from ``start`` to ``goal``, with no
    tangential state (a snap's: :func:`solver.paths.friction.landed`)."""
    return landed((*(a + t * (b - a) for a, b in zip(start[:L.L_MU], goal[:L.L_MU])),
                   *goal[L.L_MU:]))


def _level_rest(level, layout, rest):
    """The rest strains (3, ns) at a level's pressures, into ``rest``."""
    rest_strains_into(level[L.L_P], layout.tubes_i, layout.tubes_f, layout.secf, rest)


def _free_step_gap(free, start, obstacles):
    """:func:`solver.kernels.obstacles.free_step_gap` of the contact-free step from the
    recorded ``start`` to ``free``: (gap, clear), ``start`` resampled at ``free``'s arc
    lengths if on another grid (a contact state, on the finer contact grid)."""
    before = start.positions
    if before.shape != free.positions.shape:
        before = np.column_stack([np.interp(free.s, start.s, start.positions[:, c])
                                  for c in range(3)])
    return free_step_gap(before, free.positions, free.orientations[:, :, 2], obstacles)


def grid_and_terms(arm, layout, segs, sec_start, scene, ctx):
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


def node_arcs(layout, segs, sec_start):
    """Arc length (m) of every node (K,)."""
    h = layout.sec_len / layout.sec_steps
    i = segs[:, L.SEG_SECTION]
    return sec_start[i] + segs[:, L.SEG_FIRST] * h[i]


def _nodes_from_record(eq, grid, layout, segs, sec_start):
    """Node states (K, N_CSTATE) from a recorded spatial equilibrium at another resolution
    (:func:`solver.kernels.spatial_contact.nodes_from_record`)."""
    nodes = np.empty((segs.shape[0], L.N_CSTATE))
    # Writable C arrays whatever their source (a stepper's read-only records, a column of the
    # segment table): each other layout is a signature of its own, which `softarm warmup`
    # does not compile (a 3D wrap planner's first episode compiled one, ~5 s, measured).
    arrays = (eq.s, eq.positions, eq.orientations, eq.internal_force, eq.internal_moment)
    kernel.nodes_from_record(*(np.require(a, requirements="CW") for a in arrays),
                             section_rows(eq.section_ends), node_arcs(layout, segs, sec_start),
                             np.ascontiguousarray(segs[:, L.SEG_SECTION]), grid[L.GS_QUAT0],
                             nodes)
    return nodes


def _loaded_nodes(arm, layout, segs, sec_start, scene, ctx, settings):
    """Stage 1 of a cold solve (cached per scene): from the straight, unloaded, unactuated
    arm the loads are ramped in with the obstacles in place; an obstacle that overlaps the
    straight arm grows in from the radius at which it touches the arm's axis; the arm may
    snap on the way (:func:`_ramp`). Returns a copy of the nodes, the iterations, whether it
    converged, whether it snapped and (a copy of) the friction samples it ends with."""
    def build():
        grid, terms = grid_and_terms(arm, layout, segs, sec_start, scene, ctx)
        axis = base_rotation(scene.base_theta)[:, 2]
        nodes = np.zeros((segs.shape[0], L.N_CSTATE))
        nodes[:, L.CS_R:L.CS_R + 3] = node_arcs(layout, segs, sec_start)[:, None] * axis
        nodes[:, L.CS_Q:L.CS_Q + 4] = grid[L.GS_QUAT0]
        obstacles = scene.obstacles_array()
        straight = np.linspace(0.0, arm.length, 257)[:, None] * axis
        grown = obstacles.copy()
        for k, o in enumerate(scene.obstacles):
            grown[k, L.O_RADIUS] = min(o.radius, float(core_distance(o, straight).min()))
        p0 = np.zeros(max(arm.n_channels, 1))
        mu, samples = start_samples(scene, layout, sec_start, None)
        start = (p0, np.zeros_like(ctx.q), np.zeros_like(terms[0]), np.zeros(6), grown, mu, samples)
        goal = (p0, ctx.q, terms[0], terms[1], obstacles, mu, samples)
        now = new_level(goal)
        nodes, ok, its, _, stable, snapped = _ramp(nodes, grid, layout, start, goal, terms,
                                                   settings, np.empty((3, len(arm.sections))), now)
        nodes.flags.writeable = False
        return nodes, int(its), bool(ok and stable), snapped, now[L.L_FRICTION]

    nodes, its, ok, snapped, samples = arm._solver_cache.get(
        ("spatial loaded contact nodes", layout.key, scene), build)
    return nodes.copy(), its, ok, snapped, samples.copy()


def _result(nodes, scene, grid, layout, level, warm_start, **fields):
    """The spatial Equilibrium of the node states ``nodes`` at ``level`` on the path from
    ``warm_start`` (None: cold), with its friction
    (:func:`solver.paths.friction.friction_fields`)."""
    rest = np.empty((3, layout.secf.shape[1]))
    _level_rest(level, layout, rest)
    rec = kernel.new_record(layout.n_rows)
    kernel.record(nodes, grid, rest, level, rec)
    return contact_result(rec, nodes, scene, layout,
                          **friction_fields(level[L.L_FRICTION], warm_start), **fields)


def contact_result(rec, nodes, scene, layout, **fields):
    """The spatial Equilibrium of the node states ``nodes`` (K, N_CSTATE) whose backbone is
    the record tuple ``rec`` (:func:`solver.kernels.spatial_contact.new_record`, arrays
    taken as they are) on the contact ``layout``."""
    s, pos, rot, force, mom, contact, pen, strain_v, strain_u = rec
    return Equilibrium._make(
        s=s, positions=pos, orientations=rot, shear_stretch=strain_v, curvature=strain_u,
        internal_force=force, internal_moment=mom, section_ends=layout.section_ends,
        contact_force=contact, penetration=pen, in_contact=bool(pen.max() > 0.0),
        tip=pos[-1].copy(), planar=False, scene=scene, base_moment=nodes[0, L.CS_M:].copy(),
        base_force=nodes[0, L.CS_N:L.CS_N + 3].copy(), shooting_nodes=nodes.ravel().copy(),
        **fields)
