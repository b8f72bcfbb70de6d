"""Planar multiple shooting along the quasi-static path (contact, and arms too long or soft
for single shooting): start states, the loading stage with obstacles, snaps at folds, and
results (docs/design.md §6–9)."""

from __future__ import annotations

import math

import numpy as np

from solver import layout as L
from solver.kernels import contact as contact_kernels
from solver.kernels import planar as planar_kernels
from solver.kernels import relax as relax_kernels
from solver.kernels.grid import section_needs
from solver.kernels.obstacles import clearance
from solver.kernels.self_contact import backbone_crosses, far_parts_clear
from solver.paths.friction import (
    friction_fields,
    landed,
    new_level,
    start_samples,
    start_self_samples,
)
from solver.paths.grid import section_rows
from solver.problem import Problem, rest_strains, shooting_layout, shooting_terms
from solver.results import Equilibrium
from solver.rod import integrate_planar, rest_strains_into
from solver.scene import self_contact_exclusion

# Snaps per multiple-shooting solve before it gives up (each costs an energy minimisation).
MAX_SNAPS = 8

# How far past a fold a snap looks, tried in turn: fractions of the rated pressure (or of
# the loads being ramped in).
SNAP_AHEAD = (0.0025, 0.01, 0.04, 0.16)

# Newton step limit of multiple shooting, in the weighted RMS norm of the unknowns.
MAX_STEP = 0.5

# Scratch of a planar scan that records nothing.
_NO_RECORD = np.empty((1, L.N_COLUMNS))
_NO_GUARD = (np.empty(0), np.empty((0, 4)))


def solve_multiple(problem: Problem) -> Equilibrium:
    """Planar dead-load solve by multiple shooting (the contact kernels, with no discs).

    For arms whose single shooting is ill-conditioned (:func:`solver.problem.shooting_index`), and
    as the fallback of a failed single-shooting solve; see :func:`solve_shooting`.
    """
    return solve_shooting(problem, shooting_layout(problem.arm, problem.packed), load_moments=True)


def solve_shooting(problem: Problem, shooting: tuple, load_moments: bool,
                   moving: bool = False) -> Equilibrium:
    """Planar multiple-shooting solve along the quasi-static path, the scene's obstacles (if
    any) present all along it.

    Start state: a multiple-shooting ``warm_start`` at this resolution continues from its
    nodes; any other warm start from its own base moment, re-integrated at this resolution
    (corrected by Newton at the start of the ramp); a cold solve from the arm loaded with
    the obstacles in place (:func:`_loaded_nodes`). Then pressures and loads are ramped from
    the start's to the target's (:func:`solver.kernels.contact.follow`, which never lets the
    backbone tunnel through a disc). ``moving``: the warm start's discs are the scene's, moved
    (same count, radii and stiffness): their centres are ramped too, as an object the arm
    holds moves quasi-statically (:mod:`solver.grasp`); otherwise obstacles that differ from
    the warm start's stand at their places from the start.

    Args:
        problem: the request. shooting: its (layout, segment table, section start arc
            lengths) (:func:`solver.problem.shooting_layout`, :func:`solver.problem.contact_layout`).
        load_moments: scale moments by the loads' (:func:`solver.problem.shooting_terms`).
        moving: the warm start's discs move to the scene's.
    """
    arm, scene, model, warm_start, settings = (problem.arm, problem.scene, problem.model,
                                               problem.warm_start, problem.settings)
    p_inputs, p_channel, p_target = problem.p_inputs, problem.p_channel, problem.p_target
    layout, segs, sec_start = shooting
    on_layout = problem.on(layout)
    free_scene = scene.without_contact
    ctx = on_layout.ctx  # (a context does not depend on obstacles)
    plate, target, _, weights, res_weights = shooting_terms(arm, layout, segs, scene, ctx,
                                                            load_moments)
    mu, samples = start_samples(scene, layout, sec_start, warm_start, moving)
    rubs = start_self_samples(scene, segs, warm_start)
    goal = (p_target, ctx.q, plate, target, scene.discs_array(), mu, samples, rubs)
    iterations = 0
    if warm_start is not None and warm_start.scene is not None:
        start_scene = warm_start.scene.without_contact
        p_start = warm_start.channel_pressures if arm.n_channels else np.zeros(1)
        start_ctx = ctx if start_scene == free_scene else on_layout.in_scene(start_scene).ctx
        if warm_start.shooting_nodes.shape == weights.shape:
            nodes = warm_start.shooting_nodes.copy()
        elif warm_start.s.size:
            nodes = _nodes_from_record(warm_start, layout, segs, sec_start)
        else:
            free = np.empty((layout.n_rows, L.N_COLUMNS))
            integrate_planar(float(warm_start.base_moment[-1]), scene.base_theta, layout.secf,
                             layout.sec_steps, np.vstack(rest_strains(arm, p_start, layout)),
                             start_ctx.loads, True, free, False)
            nodes = nodes_from_states(free[:, _FREE_STATE], segs)
        start_plate, start_target = shooting_terms(arm, layout, segs, start_scene, start_ctx,
                                                   load_moments)[:2]
        # The same obstacles at the warm start's stiffness (a stiffer penalty is ramped in),
        # or the scene's where they differ.
        start_discs = effective_discs(warm_start.scene, warm_start.penalty_stiffness)
        same = L.RADIUS if moving else L.CX  # the columns that must agree for a ramp
        if start_discs.shape != goal[L.L_DISCS].shape or np.any(
                start_discs[:, same:3] != goal[L.L_DISCS][:, same:3]):
            start_discs = goal[L.L_DISCS]
        start = (p_start, start_ctx.q, start_plate, start_target, start_discs, mu, samples, rubs)
    else:
        nodes, iterations, loaded, samples, rubs = _loaded_nodes(
            arm, layout, segs, sec_start, scene, ctx, settings, load_moments)
        start = (np.zeros_like(p_target), *goal[1:L.L_FRICTION], samples, rubs)
        if not loaded:
            grid = shooting_grid(arm, scene, layout, segs, sec_start)
            return _shooting_result(nodes, scene, grid, layout, start, None,
                                    converged=False, stable=False, iterations=iterations,
                                    residual=math.inf, model=model, pressures=p_inputs,
                                    channel_pressures=p_channel, arm=arm)
    now = new_level(goal)
    rest = np.empty((3, len(arm.sections)))
    grid = shooting_grid(arm, scene, layout, segs, sec_start)
    snapped = False
    params = shooting_params(scene, settings)
    for _ in range(MAX_SNAPS + 1):
        ok, stable, _, its, res, t, dt = contact_kernels.follow(
            nodes, grid, (layout.tubes_i, layout.tubes_f), start, goal, params,
            (rest, now, weights, res_weights), _NO_GUARD)
        iterations += its
        if ok or settings.n_scan == 0 or t >= 1.0:
            break
        # The path cannot go on past level t (a fold): the arm snaps. Find the stable
        # equilibrium it lands on a little further on and continue from there — if the grid
        # resolves the state the fold was met from: a fold met from a state it does not
        # resolve may be the grid's, and the caller refines the grid (solver.kernels.grid).
        if not _resolved(nodes, grid, layout, now):
            break
        landed, level = _snap_ahead(arm, nodes, grid, layout, start, goal, t, dt, now, weights,
                                    res_weights, settings, ctx.params)
        if landed is None:
            break
        nodes[:] = landed
        start = level
        snapped = True
    return _shooting_result(nodes, scene, grid, layout, now, warm_start,
                            converged=bool(ok), stable=bool(stable), snapped=snapped,
                            iterations=int(iterations), residual=float(res), model=model,
                            pressures=p_inputs, channel_pressures=p_channel, arm=arm)


def _resolved(nodes, grid, layout, level):
    """Whether the RK4 grid of ``layout`` resolves the multiple-shooting state ``nodes`` at
    ``level`` (:func:`solver.kernels.grid.section_needs` of its record)."""
    out = np.zeros((layout.n_rows, L.C_COLUMNS))
    contact_kernels.record_backbone(nodes, grid, _level_rest(layout, level), level, out)
    return bool(section_needs(out[:, L.C_U:L.C_U + 1], out[:, L.C_NX:L.C_NY + 1],
                              out[:, L.C_V1:L.C_V3 + 1], np.hypot(*level[L.L_Q].T),
                              layout.secf, section_rows(layout.section_ends),
                              np.empty(layout.secf.shape[1])) <= 1.0)


def _level_span(start, goal, p_max):
    """How much a homotopy between level tuples changes, relative to its scale: the largest
    pressure change over the rated pressure, or load change over the load."""
    span = float(np.max(np.abs(goal[L.L_P] - start[L.L_P]))) / p_max if p_max > 0 else 0.0
    for k in (L.L_Q, L.L_PLATE, L.L_TARGET):
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
    ramp carried on), pressures kept within [0, p_max], with no tangential state (a snap's:
    :func:`solver.paths.friction.landed`)."""
    level = tuple(a + t * (b - a) for a, b in zip(start[:L.L_MU], goal[:L.L_MU]))
    return landed((np.clip(level[0], 0.0, p_max), *level[1:], *goal[L.L_MU:]))


def _snap(nodes, grid, layout, now, level, over, weights, res_weights, settings, params):
    """Where a multiple-shooting path ends at a fold: the stable equilibrium at ``level``
    that the arm, at ``nodes`` (level ``now``), snaps to; None if none is found.

    Clear of every obstacle, the arm snaps as the single-shooting path does: to the stable
    root of the level nearest its base moment (:func:`solver.kernels.planar.fold_scan`, ``params`` its
    parameters), if that is clear of the obstacles and of itself too (with self-contact).
    Otherwise, a local minimum of the
    discrete rod's energy reached from the last state (:func:`solver.kernels.relax.relax`) — from
    the scan's root if it lands in an obstacle; with ``over`` (a level past the ramp's end)
    it relaxes there first and then back at ``level``. Either is polished by Newton on the
    shooting system and must be stable, and (with self-contact) its backbone must not cross
    itself where the fold's did not (:func:`_crosses_itself`).
    """
    theta0, segs = grid[L.G_THETA0], grid[L.G_SEGS]
    target = level[L.L_TARGET]
    rest = _level_rest(layout, level)
    record = np.zeros((layout.n_rows, L.C_COLUMNS))
    contact_kernels.record_backbone(nodes, grid, _level_rest(layout, now), now, record)
    crossed = _crosses_itself(record, grid[L.G_SELF])
    landed = None
    if not record[:, L.C_PEN].any() and params[L.N_SCAN] > 0:
        loads = _planar_loads(layout, level)
        m0, found, _ = planar_kernels.fold_scan(theta0, layout.secf, layout.sec_steps, rest, loads,
                                                float(target[2]), params, int(params[L.N_SCAN]),
                                                float(nodes[2]), _NO_RECORD)
        if found:
            free = np.empty((layout.n_rows, L.N_COLUMNS))
            integrate_planar(m0, theta0, layout.secf, layout.sec_steps, rest, loads, True, free, False)
            landed = nodes_from_states(free[:, _FREE_STATE], segs)
            if not (planar_kernels.clear_of(free, level[L.L_DISCS], 0.0)
                    and _clear_of_itself(free, layout, grid[L.G_SELF])):
                record[:, [L.C_X, L.C_Y, L.C_TH, L.C_V1, L.C_V3]] = free[:, [L.X, L.Y, L.THETA,
                                                                           L.V1, L.V3]]
                landed = None
    if landed is None:
        state = relax_kernels.strains_of_record(record, layout.sec_steps)
        for lvl in (over, level) if over is not None else (level,):
            relaxed = relax_kernels.relax(state, theta0, layout.secf, layout.sec_steps,
                                          _level_rest(layout, lvl), lvl[L.L_Q], lvl[L.L_PLATE],
                                          lvl[L.L_TARGET][:2] - lvl[L.L_PLATE][-1], lvl[L.L_TARGET][2],
                                          lvl[L.L_DISCS], grid[L.G_SELF])
            if relaxed is None:
                return None
            states, state = relaxed
        if _sunk_into_a_disc(states, level[L.L_DISCS], record):
            return None
        landed = nodes_from_states(states, segs)
    # The relaxation's self-contact is a node-to-node stand-in: where the arm lands on itself,
    # the solver's law is brought in from a thousandth, Newton following each stiffening.
    k = grid[L.G_SELF][L.SC_K]
    for stiffness in k * np.logspace(-3.0, 0.0, SELF_STAGES) if k > 0 else (k,):
        staged = (*grid[:L.G_SELF], np.concatenate([[stiffness], grid[L.G_SELF][1:]]))
        ok, _, _, stable = contact_kernels.probe(landed, staged, rest, level, weights, res_weights,
                                                 settings.tol, 4 * settings.max_iter, MAX_STEP)
        if not ok:
            return None
    if not stable:
        return None
    if k > 0 and not crossed:
        contact_kernels.record_backbone(landed, grid, rest, level, record)
        if _crosses_itself(record, grid[L.G_SELF]):
            return None
    return landed


def _sunk_into_a_disc(states, discs, record) -> bool:
    """Whether a relaxed landing (``states``: (N, ≥2) x, y) has a sample deeper in a disc than
    the deepest of the fold's ``record`` by more than TUNNEL_SLACK. The minimiser's first steps
    can jump the backbone into an object (a grasp's landing 7 cm inside a 15 cm object,
    measured), and no Newton polish brings such a state back out: it is refused before it
    costs the stiffening stages."""
    deepest = max(float(record[:, L.C_PEN].max()), 0.0) + contact_kernels.TUNNEL_SLACK
    return any(clearance(x, y, discs) < -deepest for x, y in states[:, :2])


def _crosses_itself(record, sp) -> bool:
    """Whether the backbone of a contact ``record`` crosses itself, with self-contact (False
    without: parts that do not see each other may cross). A landing whose backbone crosses
    where the fold's did not has passed the arm through itself: the stiffening stages can
    drop a layer through another while its press is a thousandth of the law's (a hairpin's
    upper layer hung through the lower one, measured), and no contact is left to push it back.
    """
    return sp[L.SC_K] > 0 and backbone_crosses(record[:, [L.C_X, L.C_Y]], record[:, L.C_S])


def _clear_of_itself(record, layout, sp):
    """Whether the planar ``record`` keeps parts of the arm farther apart than the
    self-contact exclusion out of each other's half-thicknesses (True without self-contact)."""
    if sp[L.SC_K] <= 0:
        return True
    half = np.repeat(sp[L.SC_HALF:], layout.sec_steps + 1)
    return far_parts_clear(record[:, [L.X, L.Y]], record[:, L.S], half, sp[L.SC_EXCLUSION], 0.0)


# Penalty stages (log-spaced, from a thousandth to the full stiffness) that bring a snapped
# state's self-contact in (see _snap).
SELF_STAGES = 7


def _planar_loads(layout, level):
    """The (ns, 4) loads array of :mod:`solver.kernels.planar` (n_end, q) of a level tuple."""
    q, plate = level[L.L_Q], level[L.L_PLATE]
    loads = np.empty((q.shape[0], 4))
    running = level[L.L_TARGET][:2].copy()  # n(L⁻): tip load and the last endplate
    for i in range(q.shape[0] - 1, -1, -1):
        loads[i, :2] = running
        loads[i, 2:] = q[i]
        if i > 0:
            running = running + q[i] * layout.sec_len[i] + plate[i - 1]
    return loads


def shooting_params(scene, settings, predict_cap=math.inf):
    """The numeric parameters (:mod:`solver.layout`) of a multiple-shooting path: the
    settings' tolerance (on the weighted RMS residual), iterations and steps, the smallest
    step of a contact path where the scene has obstacles, and the cap on a predicted move."""
    params = np.zeros(L.N_PARAMS)
    params[L.TOL] = settings.tol
    params[L.MAX_STEP] = MAX_STEP
    params[L.DT0] = settings.dt0
    params[L.DT_MIN] = settings.contact_dt_min if scene.has_contact else settings.dt_min
    params[L.MAX_ITER] = settings.max_iter
    params[L.N_SCAN] = settings.n_scan
    params[L.PREDICT_CAP] = predict_cap
    return params


def shooting_grid(arm, scene, layout, segs, sec_start):
    """The layout tuple (``G_*``) of a multiple-shooting solve of ``scene`` on ``layout``:
    with the scene's self-contact parameters (stiffness 0 without): its penalty, the
    exclusion length — ``SELF_CONTACT_EXCLUSION`` arm thicknesses, and at least 2.5
    segments, so that no part meets its own segment's partner piece — and the sections'
    half-thicknesses."""
    ns = len(arm.sections)
    sp = np.zeros(L.SC_HALF + ns)
    if scene.self_contact is not None:
        half = np.array(arm.half_thickness())
        seg_len = segs[:, L.SEG_STEPS] * (layout.sec_len / layout.sec_steps)[segs[:, L.SEG_SECTION]]
        sp[L.SC_K] = scene.self_contact
        sp[L.SC_MU] = scene.self_friction
        sp[L.SC_EXCLUSION] = max(self_contact_exclusion(half), 2.5 * seg_len.max())
        sp[L.SC_HALF:] = half
    return (scene.base_theta, segs, layout.secf, layout.sec_steps, sec_start, sp)


def effective_discs(scene, stiffness):
    """The scene's discs as a kernel array, rigid ones at the penalty ``stiffness``."""
    discs = scene.discs_array()
    discs[discs[:, L.STIFFNESS] == math.inf, L.STIFFNESS] = stiffness
    return discs


def _nodes_from_record(eq, layout, segs, sec_start):
    """Multiple-shooting nodes on ``layout`` from a recorded equilibrium at another
    resolution, interpolated linearly in arc length within each section (so that a node at
    a section start takes the internal force past the endplate)."""
    states = np.column_stack([eq.positions, eq.angles, eq.internal_force, eq.internal_moment])
    ends = np.asarray(eq.section_ends)
    starts = np.concatenate([[0], ends[:-1] + 1])
    rows = segs[:, L.SEG_ROW0] + segs[:, L.SEG_FIRST]
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
    copy of the nodes, the iterations, whether it converged and (copies of) the friction
    samples and self-contact friction samples it ends with.

    An obstacle that overlaps the straight arm grows in during the ramp, from the radius at
    which it just touches the arm's axis to its own. Loading a long arm from straight is far
    from linear (its linear response to its own weight is metres): predicted moves are
    capped at one Newton step limit.
    """
    def build():
        plate, target, _, weights, res_weights = shooting_terms(arm, layout, segs, scene, ctx,
                                                                load_moments)
        nodes = np.zeros(weights.shape)
        rows = segs[1:, L.SEG_ROW0] + segs[1:, L.SEG_FIRST]
        s_nodes = np.concatenate([np.linspace(0, n, n + 1) * h + s0 for n, h, s0 in zip(
            layout.sec_steps, layout.sec_len / layout.sec_steps, sec_start)])[rows]
        straight = nodes[3:].reshape(-1, 6)
        axis = np.array([math.cos(scene.base_theta), math.sin(scene.base_theta)])
        straight[:, :2] = s_nodes[:, None] * axis
        straight[:, 2] = scene.base_theta
        discs = scene.discs_array()
        grown = discs.copy()
        along = np.clip(discs[:, :2] @ axis, 0.0, arm.length)
        grown[:, L.RADIUS] = np.minimum(discs[:, L.RADIUS],
                                        np.hypot(*(discs[:, :2] - along[:, None] * axis).T))
        p0 = np.zeros(max(arm.n_channels, 1))
        mu, samples = start_samples(scene, layout, sec_start, None)
        rubs = start_self_samples(scene, segs, None)
        start = (p0, np.zeros_like(ctx.q), np.zeros_like(plate), np.zeros(3), grown, mu, samples,
                 rubs)
        goal = (p0, ctx.q, plate, target, discs, mu, samples, rubs)
        grid = shooting_grid(arm, scene, layout, segs, sec_start)
        now = new_level(goal)
        ok, stable, _, its, _, _, _ = contact_kernels.follow(
            nodes, grid, (layout.tubes_i, layout.tubes_f), start, goal,
            shooting_params(scene, settings, predict_cap=MAX_STEP),
            (np.empty((3, len(arm.sections))), now, weights, res_weights), _NO_GUARD)
        return nodes, int(its), bool(ok and stable), now[L.L_FRICTION], now[L.L_SELF_FRICTION]

    nodes, its, ok, samples, rubs = arm._solver_cache.get(
        ("loaded-nodes", layout.key, scene, load_moments), build)
    return nodes.copy(), its, ok, samples.copy(), rubs.copy()


def _shooting_result(nodes, scene, grid, layout, level, warm_start, **fields):
    """The Equilibrium of a multiple-shooting state ``nodes`` at ``level`` (a level tuple,
    ``L_*``; ``grid`` its layout tuple) on the path from ``warm_start`` (None: cold): the
    backbone integrated from the nodes, with the contact fields if the scene has obstacles or
    self-contact, and its friction (:func:`solver.paths.friction.friction_fields`)."""
    out = np.zeros((layout.n_rows, L.C_COLUMNS))
    contact_kernels.record_backbone(nodes, grid, _level_rest(layout, level), level, out)
    return shooting_equilibrium(out, nodes, scene, layout,
                                **friction_fields(level[L.L_FRICTION], warm_start,
                                                  level[L.L_SELF_FRICTION]), **fields)


def shooting_equilibrium(out, nodes, scene, layout, **fields) -> Equilibrium:
    """The Equilibrium of the multiple-shooting state ``nodes`` on ``layout`` whose backbone
    ``out`` (rows, C_COLUMNS) records (its arrays copied), with the contact fields if the
    scene has obstacles or self-contact; ``fields`` the solve's flags and inputs."""
    contact = scene.has_contact
    common = dict(tip=out[-1, [L.C_X, L.C_Y]].copy(), planar=True, scene=scene,
                  base_moment=np.array([nodes[2]]), base_force=nodes[:2].copy(),
                  shooting_nodes=nodes, in_contact=bool(contact and out[:, L.C_PEN].max() > 0.0),
                  **fields)
    extra = dict(contact_force=out[:, [L.C_FX, L.C_FY]].copy(),
                 penetration=out[:, L.C_PEN].copy()) if contact else {}
    return Equilibrium._make(
        s=out[:, L.C_S].copy(), positions=out[:, [L.C_X, L.C_Y]].copy(),
        angles=out[:, L.C_TH].copy(), shear_stretch=out[:, [L.C_V1, L.C_V3]].copy(),
        curvature=out[:, L.C_U].copy(), internal_force=out[:, [L.C_NX, L.C_NY]].copy(),
        internal_moment=out[:, L.C_M].copy(), section_ends=layout.section_ends, **extra,
        **common)


def _level_rest(layout, level):
    """Rest strains (3, ns) at the pressures of a level tuple."""
    rest = np.empty((3, layout.secf.shape[1]))
    rest_strains_into(level[L.L_P], layout.tubes_i, layout.tubes_f, layout.secf, rest)
    return rest


# Columns of a planar record that make a multiple-shooting node state (x, y, θ, n_x, n_y, m).
_FREE_STATE = [L.X, L.Y, L.THETA, L.NX, L.NY, L.M]


def nodes_from_states(states, segs):
    """Multiple-shooting unknowns from backbone samples ``states`` (N, 6) = (x, y, θ, n_x,
    n_y, m) per sample: (n0, m0), then the state at every segment start."""
    rows = segs[:, L.SEG_ROW0] + segs[:, L.SEG_FIRST]
    return np.concatenate([states[rows[0], [3, 4, 5]], states[rows[1:]].ravel()])
