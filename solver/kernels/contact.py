"""Planar kernels for an arm pressed against rigid discs (penalty contact), multiple shooting.

With contact the internal force is no longer known from global equilibrium, so the whole
state (x, y, θ, n_x, n_y, m) is integrated. Section i carries, from n' + f = 0 (Eq. 2.28):

    x' = v3 cos θ − v1 sin θ,   y' = v3 sin θ + v1 cos θ,   θ' = u*_i + m/EI_i
    n' = −μ_i g − Σ_discs f_c,  m' = v1 n3 − v3 n1
    f_c = k · max(0, R − |r − c|) · (r − c)/|r − c|      (force per reference length, N/m)

A stiff penalty makes this stiff: in contact, deflections decay and grow over the length
ℓ = (EI/k)^¼ (3 cm for OctArm-like sections at k = 1e5 N/m²), so single shooting across a
deep wrap amplifies errors by e^(contact length/ℓ) and fails. We use multiple shooting: the
arm is cut into segments of a few RK4 steps (chosen by the wrapper, see below),
the state at every segment start is an unknown, and Newton solves continuity between
segments plus the free-tip conditions n(L) = F_tip + W_plate, m(L) = M_tip. Endplate weights
jump n at the junctions. The segment maps' Jacobians are integrated with the segments (the
variational equations, through the same RK4 stages: the exact derivative of the discrete
map), and the banded Newton system is solved in O(N) (:func:`_band_solve`).

Resolution: the penalty's kink where the backbone meets a disc costs RK4 its order, and a
contact patch shorter than a step is seen by one or two stages only. Steps are half the
decay length away from discs and refined fivefold near them (:func:`_integrate`), which keeps
the tip within 5e-5·L of a 512-step solve with contact at the free tip or further in.
Splitting each step exactly at the crossings was tried: more accurate per step, but the
split points move with the state, the map gets kinks where one crosses a step boundary, and
Newton stalls on them along deep wraps.

Stability: the Jacobi fields of the free tip are carried back to the base through the
segment maps' Jacobians (:func:`stability_test`): the conjugate-point test of the spatial
kernels, in the plane. It is exact for conservative loads, penalty contact included.
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.grid import section_needs
from solver.kernels.homotopy import halved
from solver.kernels.obstacles import (
    accept_friction,
    contact_force,
    contact_stiffness,
    friction_impulse,
    friction_untouched,
    nearest_surface,
    tunnels,
)
from solver.kernels.self_contact import (
    build_piece,
    canonical_slot,
    clear_pieces,
    may_touch,
    moved_since,
    samples_untouched,
    self_contact_on,
    self_loads,
    trace_piece,
)
from solver.layout import (
    B_TOUCH,
    C_COLUMNS,
    C_FX,
    C_FY,
    C_M,
    C_NX,
    C_NY,
    C_PEN,
    C_S,
    C_TH,
    C_U,
    C_V1,
    C_V3,
    C_X,
    C_Y,
    CA,
    CG,
    CI,
    DT0,
    DT_MIN,
    FS_F,
    FS_WORK,
    G_SECF,
    G_SEGS,
    G_START,
    G_STEPS,
    G_THETA0,
    L_DISCS,
    L_FRICTION,
    L_MU,
    L_P,
    L_PLATE,
    L_Q,
    L_SELF_FRICTION,
    L_TARGET,
    LEN,
    MAX_ITER,
    MAX_STEP,
    N_BOUNDS,
    N_POINT,
    N_SELF,
    PREDICT_CAP,
    REST_U2,
    REST_V3,
    SEG_END,
    SEG_FIRST,
    SEG_ROW0,
    SEG_SECTION,
    SEG_STEPS,
    SELF_FX,
    SELF_FY,
    SELF_K00,
    SELF_K01,
    SELF_K11,
    SELF_M,
    SELF_PEN,
    SELF_QX,
    SELF_QY,
    TOL,
)
from solver.rod import (
    fma,
    planar_state_jacobian,
    planar_state_rates,
    planar_state_rk4,
    planar_strains_cs,
    rest_strains_into,
    turned,
)

# RK4 substeps per step near a disc (see _integrate): with steps of half the decay length
# (EI/k)^¼ away from contact, a tenth of it where the arm may touch.
NEAR_SUBSTEPS = 5
# Passes that redraw the self-contact geometry through the segments integrated with the
# last pass's loads (see _prepare_partners).
GEOMETRY_PASSES = 1
# Largest move (m) of the self-contact pieces' nodes for which the clearances of the last
# call are reused (see _prepare_partners).
REUSE_CLEARANCE = 1e-3
# Bandwidth of the shooting Jacobian (sub- and super-diagonals: a row of segment k's
# continuity couples its 6-state start to the next segment's), and its band storage: the
# rows of LAPACK's dgbtrf layout, with room for the fill-in of partial pivoting.
BAND = 2 * 8
BAND_ROWS = 3 * 8 + 1
# A sample may sink this much deeper (in m) between two accepted states than at either: the
# chord of a slide round the disc's surface (sagitta c²/8R) without counting as a tunnel.
TUNNEL_SLACK = 2e-3

# A path refuses a converged try whose state lies too far from its prediction (a branch jump:
# :func:`_path`, :func:`lean_step` and their 3D twins), so its Newton may give up as soon as
# the root lies beyond that fence. From an iterate whose steps then shrink at least twofold
# an iteration (Newton near a root: quadratically) the root lies within twice the iterate's
# Newton step, so an iterate farther out than the fence by more than that has its root
# beyond it (docs/design.md §10.1, "Newton gives up behind the fence").
FENCE_STEPS = 2.0


@njit(inline="always")
def jump_fence(move):
    """How far (weighted RMS) a path's converged try may lie from its prediction, which moved
    the accepted state by ``move``: 0.05 + half the move; farther is a branch jump, refused."""
    return 0.05 + 0.5 * move


@njit(inline="always")
def _write_row(x, y, th, nx, ny, m, c, sn, s, out, row, ca, cg, ci, ur, vr, discs):
    """Record the state (x, y, θ, n_x, n_y, m), (c, sn) = (cos θ, sin θ), at arc length ``s``
    into row ``row`` of ``out``."""
    fx, fy, pen = contact_force(x, y, discs)
    c, sn, n1, n3, v1, v3 = planar_strains_cs(c, sn, nx, ny, ca, cg, vr)
    out[row, C_S] = s
    out[row, C_X] = x
    out[row, C_Y] = y
    out[row, C_TH] = th
    out[row, C_NX] = nx
    out[row, C_NY] = ny
    out[row, C_M] = m
    out[row, C_FX] = fx
    out[row, C_FY] = fy
    out[row, C_PEN] = pen
    out[row, C_V1] = v1
    out[row, C_V3] = v3
    out[row, C_U] = ur + m * ci


@njit(inline="always")
def _stage_matrix(x, y, c, sn, nx, ny, ca, cg, vr, discs):
    """The non-zeros of A = ∂(state')/∂(state) of :func:`solver.rod.planar_state_rates` at a
    stage point, θ given by (c, sn) = (cos θ, sin θ): the 8 of
    :func:`solver.rod.planar_state_jacobian`, then the contact stiffness (k00, k01, k11)."""
    a02, a03, a04, a12, a14, a52, a53, a54 = planar_state_jacobian(c, sn, nx, ny, ca, cg, vr)
    k00, k01, k11 = contact_stiffness(x, y, discs)
    return a02, a03, a04, a12, a14, a52, a53, a54, k00, k01, k11


@njit(inline="always")
def _tangent_rates(p, a, ci):
    """A·p for a column p (6-tuple) of the tangent, A given by :func:`_stage_matrix` ``a``:
    14 of its 36 entries are non-zero (θ' = u* + m·ci)."""
    return (fma(a[0], p[2], fma(a[1], p[3], a[2] * p[4])),
            fma(a[3], p[2], fma(a[2], p[3], a[4] * p[4])),
            ci * p[5],
            -fma(a[8], p[0], a[9] * p[1]),
            -fma(a[9], p[0], a[10] * p[1]),
            fma(a[5], p[2], fma(a[6], p[3], a[7] * p[4])))


@njit(inline="always")
def _axpy(a, x, y):
    """y + a·x for 6-tuples x, y, fused."""
    return (fma(a, x[0], y[0]), fma(a, x[1], y[1]), fma(a, x[2], y[2]), fma(a, x[3], y[3]),
            fma(a, x[4], y[4]), fma(a, x[5], y[5]))


@njit(inline="always")
def _quiet(a):
    """Whether the stage matrix ``a`` (:func:`_stage_matrix`) has no contact stiffness."""
    return a[8] == 0.0 and a[9] == 0.0 and a[10] == 0.0


@njit(inline="always")
def _unit_columns(P):
    """Whether the first two columns of ``P`` (6, 6) are still those of the identity (a
    tangent that no contact stiffness has reached: nothing moves x or y but x and y)."""
    for d in range(6):
        if P[d, 0] != (1.0 if d == 0 else 0.0) or P[d, 1] != (1.0 if d == 1 else 0.0):
            return False
    return True


@njit(inline="always")
def _tangent_rk4(P, h, ci, a1, a2, a3, a4):
    """The RK4 step of the tangent ``P`` (6, 6), in place, with the stage matrices
    (:func:`_stage_matrix`) of the state's step: the exact derivative of that step (where no
    stage point sits on a disc surface). Column by column, as P' = A·P is: a column that is
    still a unit vector of x or y and meets no contact stiffness in the step's stages stays
    one (A's columns for x and y hold only that stiffness), and is skipped."""
    first = 2 if _quiet(a1) and _quiet(a2) and _quiet(a3) and _quiet(a4) and _unit_columns(P) \
        else 0
    hh = 0.5 * h
    w = h / 6.0
    for j in range(first, 6):
        p = (P[0, j], P[1, j], P[2, j], P[3, j], P[4, j], P[5, j])
        k1 = _tangent_rates(p, a1, ci)
        k2 = _tangent_rates(_axpy(hh, k1, p), a2, ci)
        k3 = _tangent_rates(_axpy(hh, k2, p), a3, ci)
        k4 = _tangent_rates(_axpy(h, k3, p), a4, ci)
        P[0, j] = fma(w, k1[0] + fma(2.0, k2[0] + k3[0], k4[0]), p[0])
        P[1, j] = fma(w, k1[1] + fma(2.0, k2[1] + k3[1], k4[1]), p[1])
        P[2, j] = fma(w, k1[2] + fma(2.0, k2[2] + k3[2], k4[2]), p[2])
        P[3, j] = fma(w, k1[3] + fma(2.0, k2[3] + k3[3], k4[3]), p[3])
        P[4, j] = fma(w, k1[4] + fma(2.0, k2[4] + k3[4], k4[4]), p[4])
        P[5, j] = fma(w, k1[5] + fma(2.0, k2[5] + k3[5], k4[5]), p[5])


@njit(inline="always")
def _step(x, y, th, c, sn, nx, ny, m, k1, h, P, ca, cg, ci, ur, vr, qx, qy, discs):
    """One RK4 step of the state (:func:`solver.rod.planar_state_rk4`, from its rates ``k1``
    at the start and (c, sn) = (cos θ, sin θ)) and, where ``P`` (6, 6) is not empty, of its
    tangent ``P`` in place with the same stages (:func:`_tangent_rk4`). Returns the state at
    the step's end, (x, y, θ, cos θ, sin θ, n_x, n_y, m)."""
    end, stages = planar_state_rk4(x, y, th, c, sn, nx, ny, m, k1, h, ca, cg, ci, ur, vr, qx, qy,
                                   discs)
    if P.shape[0] > 0:
        s2, s3, s4 = stages
        _tangent_rk4(P, h, ci, _stage_matrix(x, y, c, sn, nx, ny, ca, cg, vr, discs),
                     _stage_matrix(s2[0], s2[1], s2[2], s2[3], s2[4], s2[5], ca, cg, vr, discs),
                     _stage_matrix(s3[0], s3[1], s3[2], s3[3], s3[4], s3[5], ca, cg, vr, discs),
                     _stage_matrix(s4[0], s4[1], s4[2], s4[3], s4[4], s4[5], ca, cg, vr, discs))
    return end


@njit
def new_partners(grid):
    """Scratch for self-contact (:mod:`solver.kernels.self_contact`) on ``grid``: (points
    (M, c + 1, N_POINT), bounds (M, N_BOUNDS), loads (M, c + 1, N_SELF)), c the longest
    segment's steps; empty without self-contact."""
    segs = grid[G_SEGS]
    n_seg = segs.shape[0] if self_contact_on(grid) else 0
    cap = 0
    for seg in range(segs.shape[0]):
        cap = max(cap, segs[seg, SEG_STEPS])
    bounds = np.empty((n_seg, N_BOUNDS))
    clear_pieces(bounds)
    pts = np.full((n_seg, cap + 1, N_POINT), np.nan)  # no clearances worked out yet
    return pts, bounds, np.zeros((n_seg, cap + 1, N_SELF))


@njit
def _node_load(loads, seg, node, st, phi, tangent):
    """Apply the self-contact point load of node ``node`` of segment ``seg`` (its canonical
    slot) to the state: n⁺ = n⁻ − F, m⁺ = m⁻ − M (friction's point moment). With
    ``tangent``, the segment map's Jacobian ``phi`` takes the normal law's stiffness with the
    other part held fixed (δn⁺ = δn⁻ − K δr): Newton's coupled Jacobian replaces these
    columns by differences, so it only informs the stability test."""
    st[3] -= loads[seg, node, SELF_FX]
    st[4] -= loads[seg, node, SELF_FY]
    st[5] -= loads[seg, node, SELF_M]
    if tangent:
        k00 = loads[seg, node, SELF_K00]
        k01 = loads[seg, node, SELF_K01]
        k11 = loads[seg, node, SELF_K11]
        for e in range(6):
            phi[3, e] -= k00 * phi[0, e] + k01 * phi[1, e]
            phi[4, e] -= k01 * phi[0, e] + k11 * phi[1, e]


@njit
def _self_row(loads, segs, seg, node, out, row):
    """Add the self-contact load per length and penetration of node ``node`` of segment
    ``seg`` (its canonical slot) to the record row ``row``."""
    a, b = canonical_slot(segs, seg, node)
    out[row, C_FX] += loads[a, b, SELF_QX]
    out[row, C_FY] += loads[a, b, SELF_QY]
    out[row, C_PEN] = max(out[row, C_PEN], loads[a, b, SELF_PEN])


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def _prepare_partners(Z, grid, rest, level, partners, recording):
    """The self-contact loads of the state ``Z`` into ``partners`` (nothing without
    self-contact). Functions of Z alone (and, with self-contact friction, of the anchors of
    the level's samples ``L_SELF_FRICTION``, which the last pass writes the state of where
    ``recording``). Skipped (no loads) where no part can be near another
    (:func:`solver.kernels.self_contact.may_touch`).

    The backbone the law sees is drawn first as each segment's quintic Hermite piece from
    its start node to the next one's — the tip segment's to its end integrated without
    self-contact loads (:func:`solver.kernels.self_contact.build_piece`) — and the loads worked
    out on it (:func:`solver.kernels.self_contact.self_loads`). Then GEOMETRY_PASSES times every
    segment is integrated with them, its piece redrawn through the integrated nodes
    (:func:`solver.kernels.self_contact.trace_piece`), and the loads worked out again: a
    Hermite piece misses the kinks that the shear and stretch of point loads put into the
    backbone at loaded nodes (tens of micrometres on OctArm V at the ring stiffness, against
    a penetration of 2 mm), a traced one carries them. (Tracing only the loaded segments
    put a jump into the loads where a segment's first load appeared: its piece switched
    from one curve to the other, a micrometre apart.) The nodes' clearances, which spare
    the law the points far from any other part, are reused from the last call while the
    nodes have moved less than REUSE_CLEARANCE since (a Newton step's difference columns
    and line search), at a slack of the move (:func:`solver.kernels.self_contact.self_loads`)."""
    pts, bounds, loads = partners
    n_seg = bounds.shape[0]
    if n_seg == 0:
        return
    sfs = level[L_SELF_FRICTION]
    clear_pieces(bounds)
    theta0 = grid[G_THETA0]
    # No part near another (the nodes alone, then with the tip segment integrated, as its
    # piece needs): nothing to work out.
    near = may_touch(Z, grid, rest, math.nan, math.nan)
    tip_start = np.empty(6)
    tip_end = np.empty(6)
    if near:
        _start_state(Z, n_seg - 1, theta0, tip_start)
        none = (pts[:0], bounds[:0], loads[:0])
        _integrate(tip_start, Z, n_seg - 1, n_seg, grid, rest, level, tip_end.reshape((1, 6)),
                   False, np.empty((1, C_COLUMNS)), None, none)
        near = may_touch(Z, grid, rest, tip_end[0], tip_end[1])
    if not near:
        loads[:, :, :] = 0.0
        if recording:
            samples_untouched(sfs)
        return
    za = np.empty(6)
    zb = np.empty(6)
    segs = grid[G_SEGS]
    for seg in range(n_seg - 1):
        _start_state(Z, seg, theta0, za)
        _start_state(Z, seg + 1, theta0, zb)
        build_piece(za, zb, seg, grid, rest, level, pts, bounds)
    build_piece(tip_start, tip_end, n_seg - 1, grid, rest, level, pts, bounds)
    self_loads(grid, rest, pts, bounds, loads, _reuse(pts, segs), sfs, False)
    rows = 0
    for i in range(grid[G_STEPS].shape[0]):
        rows += grid[G_STEPS][i] + 1
    record = np.empty((rows, C_COLUMNS))
    states = np.empty((pts.shape[1], 6))
    ends = np.empty((n_seg, 6))
    # The tracing pass records, but friction's samples are the residual pass's to record (the
    # anchors a state's acceptance takes, solver.kernels.obstacles.accept_friction): it
    # integrates with a copy of them (a Newton step's difference columns trace moved states).
    fs = level[L_FRICTION]
    traced = (level[L_P], level[L_Q], level[L_PLATE], level[L_TARGET], level[L_DISCS], level[L_MU],
              fs.copy() if fs.shape[0] > 0 else fs, sfs)
    for geometry in range(GEOMETRY_PASSES):
        # The segments integrated with the loads as the residual pass integrates them.
        _start_state(Z, 0, theta0, za)
        _integrate(za, Z, 0, n_seg, grid, rest, traced, ends, True, record, None, partners)
        for seg in range(n_seg):
            first = segs[seg, SEG_ROW0] + segs[seg, SEG_FIRST]
            nst = segs[seg, SEG_STEPS]
            _record_states(record, first, nst + 1, states)
            # The end after its node's load; at a section end before the endplate's weight.
            zb[:] = states[nst] if segs[seg, SEG_END] == 1 else ends[seg]
            if seg < n_seg - 1:
                _start_state(Z, seg + 1, theta0, za)
            trace_piece(seg, states, zb, za, grid, rest, level, loads, pts, bounds)
        self_loads(grid, rest, pts, bounds, loads, _reuse(pts, segs), sfs,
                   recording and geometry == GEOMETRY_PASSES - 1)


@njit
def _record_states(record, first, n, states):
    """The states (x, y, θ, n_x, n_y, m) of the ``n`` record rows from ``first`` into
    ``states`` (≥ n, 6): the record keeps them in other columns (solver.layout, C_*)."""
    for j in range(n):
        row = first + j
        states[j, 0] = record[row, C_X]
        states[j, 1] = record[row, C_Y]
        states[j, 2] = record[row, C_TH]
        states[j, 3] = record[row, C_NX]
        states[j, 4] = record[row, C_NY]
        states[j, 5] = record[row, C_M]


@njit
def _reuse(pts, segs):
    """The ``moved`` argument of :func:`solver.kernels.self_contact.self_loads` for the pieces
    ``pts``: how far their nodes moved since their clearances were worked out, or −1 (work
    them out afresh) past REUSE_CLEARANCE."""
    moved = moved_since(pts, segs)
    return moved if moved < REUSE_CLEARANCE else -1.0


@njit
def _integrate(z0, nodes, lo, hi, grid, rest, level, ends, record, out, blocks, partners):
    """Integrate segments ``lo`` … ``hi − 1``, the first from the state ``z0`` (6,), the
    others from theirs in ``nodes`` (:func:`newton_system`'s unknowns), into ``ends``
    (hi − lo, 6), and their maps' Jacobians (∂end/∂start) into ``blocks`` (hi − lo, 6, 6)
    unless it is None (the residual pass, compiled without them).

    ``grid`` (the layout tuple, ``G_*``) and ``level`` (a level tuple, see ``L_P``…) give
    the layout and loads. Applies the endplate jump n(s⁺) = n(s⁻) − W at a section end (not
    at the tip: that is the boundary condition), and the self-contact point loads of
    ``partners`` (:func:`new_partners`, worked out by :func:`_prepare_partners`; none if
    empty) at the RK4 nodes, the tip's included. With ``record``, writes the segments' nodes
    (and their sections' last nodes) into ``out``. The self-contact loads depend on the
    shooting nodes, not on a segment's start state, and do not enter its Jacobian.

    Near a disc every RK4 step is refined into NEAR_SUBSTEPS substeps: the penalty's kink at
    the disc surface, and contact patches shorter than a step, cost RK4 its accuracy there,
    and only there. Friction (the level's samples, ``L_FRICTION``, if it has any) acts at the
    refinement's nodes as point loads, each the trapezoid rule's share of the substeps either
    side (:func:`_friction_node`); a step that is not refined reaches no disc and carries
    none. A step that cannot reach a disc (its start clears every disc by more
    than the step's reach, h·|r'|, plus h) is taken whole; in between, the two results are
    blended with a smoothstep weight of that clearance, so the map stays smooth in the
    state (a switch would put jumps of RK4's truncation size into it, which stall Newton).

    The state is stepped in scalars (:func:`_step`), the rates at a step's start, which
    decide its refinement, serving as its first stage. cos θ and sin θ are carried from node
    to node by the turns between them, and from a segment's end to the next one's start,
    which continuity puts near it (:func:`solver.rod.turned`); libm gives them at ``z0``.
    """
    segs = grid[G_SEGS]
    secf = grid[G_SECF]
    steps = grid[G_STEPS]
    sec_start = grid[G_START]
    q = level[L_Q]
    plate = level[L_PLATE]
    discs = level[L_DISCS]
    loads = partners[2]
    own = loads.shape[0] > 0
    fs = level[L_FRICTION]
    friction = fs.shape[0] > 0
    tangent = blocks is not None
    no_tangent = np.empty((0, 6))
    fine_phi = np.empty((6, 6)) if tangent else no_tangent
    grad = np.empty(6)
    st = np.empty(6)
    th_end = z0[2]
    c = math.cos(th_end)
    sn = math.sin(th_end)
    for seg in range(lo, hi):
        phi = blocks[seg - lo] if tangent else no_tangent
        if seg == lo:
            x, y, th, nx, ny, m = z0[0], z0[1], z0[2], z0[3], z0[4], z0[5]
        else:
            base = 3 + 6 * (seg - 1)
            x, y, th = nodes[base], nodes[base + 1], nodes[base + 2]
            nx, ny, m = nodes[base + 3], nodes[base + 4], nodes[base + 5]
            c, sn = turned(th_end, c, sn, th - th_end)
        if tangent:
            for d in range(6):
                for e in range(6):
                    phi[d, e] = 1.0 if d == e else 0.0
        i = segs[seg, SEG_SECTION]
        first = segs[seg, SEG_FIRST]
        nst = segs[seg, SEG_STEPS]
        h = secf[LEN, i] / steps[i]
        hf = h / NEAR_SUBSTEPS
        ca = secf[CA, i]
        cg = secf[CG, i]
        ci = secf[CI, i]
        ur = rest[REST_U2, i]
        vr = rest[REST_V3, i]
        qx = q[i, 0]
        qy = q[i, 1]
        for j in range(first, first + nst):
            if own and j > first:  # the node just reached carries its load from here on
                nx, ny, m = _loaded(loads, seg, j - first, nx, ny, m, st, phi, tangent)
            if record:
                row = segs[seg, SEG_ROW0] + j
                _write_row(x, y, th, nx, ny, m, c, sn, sec_start[i] + j * h, out, row, ca, cg, ci,
                           ur, vr, discs)
                if own:
                    _self_row(loads, segs, seg, j - first, out, row)
            if own and seg == 0 and j == first:  # the base node's load, into the clamp's reaction
                nx, ny, m = _loaded(loads, 0, 0, nx, ny, m, st, phi, tangent)
            fx, fy, pen = contact_force(x, y, discs)
            k1 = planar_state_rates(c, sn, nx, ny, m, ca, cg, ci, ur, vr, qx, qy, fx, fy)
            # The slope at the start (r' its first two entries) says how near a disc the
            # step may come; a step that starts inside one (clear <= 0) is taken in substeps
            # alone, so its whole step, which would be discarded, is not taken.
            clear = math.inf
            speed = ux = uy = 0.0
            if discs.shape[0] > 0:
                speed = math.sqrt(k1[0] * k1[0] + k1[1] * k1[1])
                gap, ux, uy = nearest_surface(x, y, discs)
                clear = gap - h * speed
            if clear < h and tangent:
                # The fine tangent starts from the start's; the blend's weight w(clear)
                # moves with the start state: d(weight)/dz = w'(x)·(−1/h)·d(clear)/dz,
                # clear = |r − c| − R − h|r'|, along the start's tangent.
                for d in range(6):
                    for e in range(6):
                        fine_phi[d, e] = phi[d, e]
                if clear > 0.0:
                    xw = 1.0 - clear / h
                    dw = -6.0 * xw * (1.0 - xw) / h
                    slope = _slope_of_speed(c, sn, nx, ny, ca, cg, vr, k1[0], k1[1], speed, h)
                    for e in range(6):
                        g = ux * phi[0, e] + uy * phi[1, e]
                        for d in range(2, 5):
                            g -= slope[d - 2] * phi[d, e]
                        grad[e] = dw * g
            end = (x, y, th, c, sn, nx, ny, m)
            at = segs[seg, SEG_ROW0] + j
            if clear > 0.0:
                end = _step(x, y, th, c, sn, nx, ny, m, k1, h, phi, ca, cg, ci, ur, vr, qx, qy,
                            discs)
                if clear >= h:
                    x, y, th, c, sn, nx, ny, m = end
                    if friction and record:
                        friction_untouched(fs, at)
                    continue
            fine = (x, y, th, c, sn, nx, ny, m)
            for sub in range(NEAR_SUBSTEPS):
                if friction:  # the node's impulse first: the substep starts past it
                    fine = _friction_node(fine, fine_phi, tangent, level, at, sub,
                                          (0.5 if sub == 0 else 1.0) * hf, record)
                if sub > 0 or friction:
                    fx, fy, pen = contact_force(fine[0], fine[1], discs)
                    k1 = planar_state_rates(fine[3], fine[4], fine[5], fine[6], fine[7], ca, cg,
                                            ci, ur, vr, qx, qy, fx, fy)
                fine = _step(fine[0], fine[1], fine[2], fine[3], fine[4], fine[5], fine[6],
                             fine[7], k1, hf, fine_phi, ca, cg, ci, ur, vr, qx, qy, discs)
            if friction:
                fine = _friction_node(fine, fine_phi, tangent, level, at, NEAR_SUBSTEPS, 0.5 * hf,
                                      record)
                if record:
                    _friction_row(fs, at, 0, hf, out, at)
            if clear <= 0.0:
                x, y, th, c, sn, nx, ny, m = fine
                if tangent:
                    for d in range(6):
                        for e in range(6):
                            phi[d, e] = fine_phi[d, e]
                continue
            xw = 1.0 - clear / h
            weight = xw * xw * (3.0 - 2.0 * xw)
            if tangent:
                coarse = (end[0], end[1], end[2], end[5], end[6], end[7])
                blend = (fine[0], fine[1], fine[2], fine[5], fine[6], fine[7])
                for d in range(6):
                    for e in range(6):
                        phi[d, e] = weight * fine_phi[d, e] + (1.0 - weight) * phi[d, e] \
                            + (blend[d] - coarse[d]) * grad[e]
            x = weight * fine[0] + (1.0 - weight) * end[0]
            y = weight * fine[1] + (1.0 - weight) * end[1]
            th_blend = weight * fine[2] + (1.0 - weight) * end[2]
            nx = weight * fine[5] + (1.0 - weight) * end[5]
            ny = weight * fine[6] + (1.0 - weight) * end[6]
            m = weight * fine[7] + (1.0 - weight) * end[7]
            c, sn = turned(th, c, sn, th_blend - th)
            th = th_blend
        if own:
            nx, ny, m = _loaded(loads, seg, nst, nx, ny, m, st, phi, tangent)
        if segs[seg, SEG_END] == 1:
            if record:
                row = segs[seg, SEG_ROW0] + steps[i]
                _write_row(x, y, th, nx, ny, m, c, sn, sec_start[i] + secf[LEN, i], out, row, ca,
                           cg, ci, ur, vr, discs)
                if own:
                    _self_row(loads, segs, seg, nst, out, row)
                if friction:
                    _friction_row(fs, row - 1, NEAR_SUBSTEPS, hf, out, row)
            if i < secf.shape[1] - 1:
                nx -= plate[i, 0]
                ny -= plate[i, 1]
        k = seg - lo
        ends[k, 0], ends[k, 1], ends[k, 2] = x, y, th
        ends[k, 3], ends[k, 4], ends[k, 5] = nx, ny, m
        th_end = th


@njit(inline="always")
def _friction_node(fine, phi, tangent, level, row, node, weight, record):
    """The state ``fine`` (x, y, θ, cos θ, sin θ, n_x, n_y, m) past the friction impulse F of
    sample (row, node) (:func:`solver.kernels.obstacles.friction_impulse`, its share
    ``weight`` of the length), a point load: n⁺ = n⁻ − F; with ``tangent``, its Jacobian
    ``phi`` too (δn⁺ = δn⁻ − ∂F/∂r·δr), in place."""
    fx, fy, k00, k01, k10, k11 = friction_impulse(fine[0], fine[1], level[L_DISCS], level[L_MU],
                                                  level[L_FRICTION], row, node, weight, record,
                                                  tangent)
    if tangent:
        for e in range(6):
            p0 = phi[0, e]
            p1 = phi[1, e]
            phi[3, e] -= k00 * p0 + k01 * p1
            phi[4, e] -= k10 * p0 + k11 * p1
    return (fine[0], fine[1], fine[2], fine[3], fine[4], fine[5] - fx, fine[6] - fy, fine[7])


@njit
def _friction_row(fs, row, node, h_sub, out, out_row):
    """Add the friction force per length of sample (row, node) (an end node of its step's
    refinement, which carries half a substep) to the contact force of record row
    ``out_row``."""
    for d in range(fs.shape[2]):
        out[out_row, C_FX] += fs[row, node, d, FS_F] / (0.5 * h_sub)
        out[out_row, C_FY] += fs[row, node, d, FS_F + 1] / (0.5 * h_sub)


@njit(inline="always")
def _loaded(loads, seg, node, nx, ny, m, st, phi, tangent):
    """The internal force (nx, ny) and moment m with the self-contact load of node ``node``
    of segment ``seg`` applied (:func:`_node_load`, through ``st`` (6,))."""
    st[3] = nx
    st[4] = ny
    st[5] = m
    _node_load(loads, seg, node, st, phi, tangent)
    return st[3], st[4], st[5]


@njit(inline="always")
def _slope_of_speed(c, sn, nx, ny, ca, cg, vr, rx, ry, speed, h):
    """h·∂|r'|/∂(θ, n_x, n_y) at orientation (c, sn) = (cos θ, sin θ) under (n_x, n_y),
    r' = (rx, ry) the slope there (the other entries of the state do not move it)."""
    a02, a03, a04, a12, a14, a52, a53, a54 = planar_state_jacobian(c, sn, nx, ny, ca, cg, vr)
    scale = h / speed if speed > 0.0 else 0.0
    return (scale * (rx * a02 + ry * a12), scale * (rx * a03 + ry * a04),
            scale * (rx * a04 + ry * a14))


@njit
def _start_state(Z, seg, theta0, z):
    """State at the start of segment ``seg``: the base (x = y = 0, θ0; n0, m0 unknown) or Z."""
    if seg == 0:
        z[0] = 0.0
        z[1] = 0.0
        z[2] = theta0
        for d in range(3):
            z[3 + d] = Z[d]
    else:
        base = 3 + 6 * (seg - 1)
        for d in range(6):
            z[d] = Z[base + d]


@njit  # the tests call it: compiled on its own anyway (solver.jit)
def newton_system(Z, grid, rest, level, F, J, want_jac, blocks, partners):
    """Residuals F (N,) of the multiple-shooting system and, if ``want_jac``, its Jacobian J.

    Unknowns Z: (n0x, n0y, m0), then the 6-state at the start of segments 1..M−1. Rows: the
    6 continuity conditions of segments 0..M−2, then n(L), m(L) against the level's tip
    target. J is banded (each row couples one segment's start to the next's) and is stored
    in the band form of :func:`_band_solve`, ``(BAND_ROWS, N)``: with self-contact, the
    Jacobian at fixed self-contact loads (their dependence on the nodes: :func:`_coupled`).
    The segment maps' Jacobians are integrated with the segments (:func:`_integrate`) into
    ``blocks`` (M, 6, 6) (their stability test: :func:`stability_test`). The self-contact
    loads of Z are worked out into ``partners`` (:func:`new_partners`) first.
    """
    recorded_system(Z, grid, rest, level, F, J, want_jac, blocks, partners,
                    np.empty((1, C_COLUMNS)))


@njit
def recorded_system(Z, grid, rest, level, F, J, want_jac, blocks, partners, out):
    """:func:`newton_system`, recording the backbone of ``Z`` into ``out`` (rows Σ(steps + 1),
    C_COLUMNS) by the same pass, as :func:`record_backbone` would; an ``out`` of one row
    records nothing."""
    segs = grid[G_SEGS]
    target = level[L_TARGET]
    n_seg = segs.shape[0]
    z = np.empty(6)
    ends = np.empty((n_seg, 6))
    record = out.shape[0] > 1
    _prepare_partners(Z, grid, rest, level, partners, record)
    _start_state(Z, 0, grid[G_THETA0], z)
    # Two calls, so that the residual pass is compiled without the tangent.
    if want_jac:
        J[:, :] = 0.0  # band storage: A[i, j] at J[BAND + i − j, j]
        _integrate(z, Z, 0, n_seg, grid, rest, level, ends, record, out, blocks, partners)
    else:
        _integrate(z, Z, 0, n_seg, grid, rest, level, ends, record, out, None, partners)
    for seg in range(n_seg):
        end = ends[seg]
        row = 6 * seg
        last = seg == n_seg - 1
        if not last:
            nxt = 3 + 6 * seg
            for d in range(6):
                F[row + d] = end[d] - Z[nxt + d]
        else:
            for d in range(3):
                F[row + d] = end[3 + d] - target[d]
        if not want_jac:
            continue
        block = blocks[seg]
        if not last:
            for d in range(6):
                J[BAND - 3, 3 + 6 * seg + d] = -1.0  # A[row + d, row + d + 3]
        # Segment 0 starts at the clamped base: only n0, m0 (its columns 3..5) are unknowns.
        first_comp = 3 if seg == 0 else 0
        col0 = 0 if seg == 0 else 3 + 6 * (seg - 1)
        for c in range(first_comp, 6):
            col = col0 + c - first_comp
            if not last:
                for d in range(6):
                    J[BAND + row + d - col, col] = block[d, c]
            else:
                for d in range(3):
                    J[BAND + row + d - col, col] = block[3 + d, c]


@njit
def stability_test(blocks):
    """The conjugate-point test of the equilibrium whose segment maps have the Jacobians
    ``blocks`` (M, 6, 6): positive if stable, ≤ 0 if not.

    As the spatial test (:func:`solver.kernels.spatial.stability_test`) does, the Jacobi fields of the
    free tip — δn(L) = δm(L) = 0, δ(x, y, θ)(L) = I — are carried from the tip to the base
    (through the inverse segment maps), and the 3×3 matrix δ(x, y, θ)(s) must not become
    singular on [0, L): the sub-rod [s, L], clamped at s and carrying its own loads, has no
    buckling mode. That sub-problem is conservative with penalty contact too (the discs push
    on the sub-rod alone); the forward test (∂(n, m)(s)/∂(n0, m0) from the base), exact for
    dead loads, is not: it takes the reaction of the part beyond s as dead, and called stable
    contact states unstable.

    Under a stiff penalty the fields grow like e^(s/ℓ) across a contact and turn parallel,
    so they are re-orthonormalised (Gram–Schmidt) at every segment: that multiplies them by
    a triangular matrix of positive determinant, which keeps the sign of det δ(x, y, θ)(s).
    Returns the smallest det of the orthonormalised fields over segment starts.
    """
    fields = np.zeros((6, 3))
    for d in range(3):
        fields[d, d] = 1.0
    lu = np.empty((6, 6))
    perm = np.empty(6, dtype=np.int64)
    smallest = 1.0
    for seg in range(blocks.shape[0] - 1, -1, -1):
        for a in range(6):
            for b in range(6):
                lu[a, b] = blocks[seg, a, b]
        if not _lu6(lu, perm):
            return -1.0
        for c in range(3):
            _lu6_solve(lu, perm, fields[:, c])
        if not _orthonormalise(fields):
            return 0.0
        det = (fields[0, 0] * (fields[1, 1] * fields[2, 2] - fields[1, 2] * fields[2, 1])
               - fields[0, 1] * (fields[1, 0] * fields[2, 2] - fields[1, 2] * fields[2, 0])
               + fields[0, 2] * (fields[1, 0] * fields[2, 1] - fields[1, 1] * fields[2, 0]))
        if not det > 0.0:
            return det
        smallest = min(smallest, det)
    return smallest


@njit
def _lu6(a, perm):
    """LU-factor the 6×6 ``a`` in place with partial pivoting (rows ``perm``); False if it
    is singular or not finite."""
    for k in range(6):
        perm[k] = k
    for k in range(6):
        p = k
        for i in range(k + 1, 6):
            if abs(a[i, k]) > abs(a[p, k]):
                p = i
        if not (abs(a[p, k]) > 0.0) or not math.isfinite(a[p, k]):
            return False
        if p != k:
            for c in range(6):
                tmp = a[k, c]
                a[k, c] = a[p, c]
                a[p, c] = tmp
            tmp_i = perm[k]
            perm[k] = perm[p]
            perm[p] = tmp_i
        for i in range(k + 1, 6):
            a[i, k] /= a[k, k]
            for c in range(k + 1, 6):
                a[i, c] -= a[i, k] * a[k, c]
    return True


@njit
def _lu6_solve(lu, perm, b):
    """Solve with the factors of :func:`_lu6`, ``b`` (6,) in place."""
    x = np.empty(6)
    for i in range(6):
        x[i] = b[perm[i]]
    for i in range(6):
        for c in range(i):
            x[i] -= lu[i, c] * x[c]
    for i in range(5, -1, -1):
        for c in range(i + 1, 6):
            x[i] -= lu[i, c] * x[c]
        x[i] /= lu[i, i]
    for i in range(6):
        b[i] = x[i]


@njit
def _orthonormalise(f):
    """Gram–Schmidt on the three columns of ``f`` (6, 3), in place; False if a column
    vanished (the fields are then degenerate)."""
    for c in range(3):
        for p in range(c):
            dot = 0.0
            for d in range(6):
                dot += f[d, c] * f[d, p]
            for d in range(6):
                f[d, c] -= dot * f[d, p]
        norm = 0.0
        for d in range(6):
            norm += f[d, c] * f[d, c]
        norm = math.sqrt(norm)
        if not norm > 0.0:
            return False
        for d in range(6):
            f[d, c] /= norm
    return True


@njit
def factor_band(ab, piv):
    """LU-factor in place the banded shooting Jacobian A stored in ``ab`` ((3·kl + 1, n):
    A[i, j] at ab[2·kl + i − j, j], kl sub- and kl super-diagonals, rows above for the
    fill-in of partial pivoting; kl = 8 in the plane, (BAND_ROWS, n), 17 in 3D), the row
    interchanges into ``piv`` (n,). Gaussian elimination with partial pivoting within the
    band, O(n): LAPACK's dgbtrf, written out so that it runs in a kernel. Returns False for
    a singular or non-finite A."""
    n = ab.shape[1]
    kl = (ab.shape[0] - 1) // 3
    kv = 2 * kl
    ju = 0
    for j in range(n):
        km = min(kl, n - 1 - j)
        p = j
        best = abs(ab[kv, j])
        for i in range(1, km + 1):
            v = abs(ab[kv + i, j])
            if v > best:
                best = v
                p = j + i
        if not (best > 0.0) or not math.isfinite(best):
            return False
        piv[j] = p
        ju = max(ju, min(p + kv - kl, n - 1))
        if p != j:
            for c in range(j, ju + 1):
                tmp = ab[kv + p - c, c]
                ab[kv + p - c, c] = ab[kv + j - c, c]
                ab[kv + j - c, c] = tmp
        pivot = ab[kv, j]
        for i in range(j + 1, j + km + 1):
            factor = ab[kv + i - j, j] / pivot
            ab[kv + i - j, j] = factor
            if factor != 0.0:
                for c in range(j + 1, ju + 1):
                    ab[kv + i - c, c] -= factor * ab[kv + j - c, c]
    return True


@njit
def band_lu_solve(ab, piv, b):
    """Solve A x = b in place (``b`` becomes x) with the factors of :func:`factor_band`."""
    n = ab.shape[1]
    kl = (ab.shape[0] - 1) // 3
    kv = 2 * kl
    for j in range(n):
        p = piv[j]
        if p != j:
            tmp = b[p]
            b[p] = b[j]
            b[j] = tmp
        for i in range(j + 1, min(n, j + kl + 1)):
            b[i] -= ab[kv + i - j, j] * b[j]
    for j in range(n - 1, -1, -1):
        acc = b[j]
        for c in range(j + 1, min(n, j + kv + 1)):
            acc -= ab[kv + j - c, c] * b[c]
        b[j] = acc / ab[kv, j]


@njit
def _band_solve(ab, b):
    """Solve A x = b in place for the banded A in ``ab`` (overwritten by its factors)."""
    piv = np.empty(ab.shape[1], dtype=np.int64)
    if not factor_band(ab, piv):
        return False
    band_lu_solve(ab, piv, b)
    return True


@njit
def weighted_norm(v, weights):
    acc = 0.0
    for k in range(v.shape[0]):
        acc += (v[k] / weights[k]) ** 2
    return math.sqrt(acc / v.shape[0])


@njit
def _distance(a, b, weights):
    """The weighted RMS distance between the states ``a`` and ``b`` (N,)."""
    acc = 0.0
    for k in range(a.shape[0]):
        acc += ((a[k] - b[k]) / weights[k]) ** 2
    return math.sqrt(acc / a.shape[0])


@njit
def _touched(partners) -> bool:
    """Whether parts of the arm press on each other (a piece is in contact)."""
    bounds = partners[1]
    for seg in range(bounds.shape[0]):
        if bounds[seg, B_TOUCH] > 0.0:
            return True
    return False


@njit
def _coupled(Z, grid, rest, level, F, J, partners, weights, A):
    """The full Jacobian (N, N) of the system into ``A`` where parts of the arm touch: the
    band ``J`` (exact at fixed self-contact loads) in the columns of nodes that shape no
    piece in contact, and forward differences of the residual ``F`` in the columns of those
    that do (the loads move with them, on their own segments and on the parts they touch).
    Returns the columns differenced (a residual pass each)."""
    n = Z.shape[0]
    A[:, :] = 0.0
    for j in range(n):
        for i in range(max(0, j - 8), min(n, j + 9)):
            A[i, j] = J[BAND + i - j, j]
    bounds = partners[1]
    n_seg = bounds.shape[0]
    columns = np.zeros(n, dtype=np.bool_)
    for seg in range(n_seg):
        if bounds[seg, B_TOUCH] > 0.0:
            for node in (seg, seg + 1):
                if node == 0:
                    columns[0:3] = True
                elif node < n_seg:
                    columns[3 + 6 * (node - 1):3 + 6 * node] = True
    # The pieces' nodes (and the clearances worked out on them) are copied: a column's
    # state is a small move from Z's (solver.kernels.self_contact.self_loads).
    scratch = (partners[0].copy(), np.empty_like(partners[1]), np.empty_like(partners[2]))
    moved = Z.copy()
    F_moved = np.empty(n)
    no_blocks = np.empty((0, 6, 6))
    differenced = 0
    for c in range(n):
        if not columns[c]:
            continue
        eps = 1e-7 * max(abs(Z[c]), weights[c])
        moved[c] = Z[c] + eps
        newton_system(moved, grid, rest, level, F_moved, J, False, no_blocks, scratch)
        differenced += 1
        moved[c] = Z[c]
        for i in range(n):
            A[i, c] = (F_moved[i] - F[i]) / eps
    return differenced


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def newton(Z, grid, rest, level, weights, res_weights, tol, max_iter, max_step):
    """Damped Newton on the multiple-shooting system at ``level``; ``Z`` is updated in place.

    Residuals and steps are measured in weighted RMS norms (weights: metres for positions,
    radians, the force and moment scales); a step is clipped to ``max_step`` and then halved
    until the residual decreases (a long wrap against a stiff penalty is far from linear
    over a full Newton step; where it never decreases, the smallest trial is taken and
    Newton goes on). The factored Jacobian is kept while the residual falls at
    least twentyfold per iteration (a Jacobian costs about two passes over the arm, a
    residual one) and recomputed otherwise, and at a converged state for its stability
    test. Where parts of the arm touch each other the system is not banded: its full
    Jacobian (:func:`_coupled`) is formed and solved densely, and kept as the band one is.
    Returns (converged, iterations, |F|, stable).
    """
    return damped_newton(Z, grid, rest, level, weights, res_weights, tol, max_iter, max_step,
                         True, np.zeros(1, dtype=np.int64), newton_work(Z.shape[0], grid), Z,
                         math.inf)


def probe(Z, grid, rest, level, weights, res_weights, tol, max_iter, max_step):
    """:func:`newton` that gives up where no trial of its line search lowers the residual
    (as :func:`solver.kernels.spatial_contact.probe`): a snap's polish from a relaxed state,
    which converges within a few iterations where it converges at all, and otherwise stalls
    on a plateau for every one of its iterations (measured on obstacle-reach snaps: every
    polish that failed after 48 iterations had stalled by its 22nd, none that converged ever
    had). Same returns."""
    return damped_newton(Z, grid, rest, level, weights, res_weights, tol, max_iter, max_step,
                         False, np.zeros(1, dtype=np.int64), newton_work(Z.shape[0], grid), Z,
                         math.inf)


@njit
def newton_work(n, grid):
    """The arrays :func:`damped_newton` works in, for ``n`` unknowns on ``grid``: (residual
    (n,), band Jacobian (BAND_ROWS, n), segment maps (M, 6, 6), self-contact scratch
    (:func:`new_partners`), and the converged state's record (one row here: nothing recorded))."""
    return (np.empty(n), np.empty((BAND_ROWS, n)), np.empty((grid[G_SEGS].shape[0], 6, 6)),
            new_partners(grid), np.empty((1, C_COLUMNS)))


@njit
def damped_newton(Z, grid, rest, level, weights, res_weights, tol, max_iter, max_step,
                  past_kinks, differenced, work, fence_center, fence):
    """:func:`newton` (``past_kinks``: where no trial of the line search lowers the residual,
    go on from the smallest) or :func:`probe` (give up there, the state restored to the
    iteration's start); ``differenced`` (1,) counts the residual passes of the full
    Jacobians formed (:func:`_coupled`). ``work`` (:func:`newton_work`): on convergence its
    residual, band Jacobian (not factored), segment maps and self-contact scratch are the
    converged state's, and its record (if it has rows) that state's backbone, from the
    pass the stability test needs anyway (a caller that would record and differentiate the
    state again saves that pass: :func:`lean_step`). ``fence_center`` (n,) and ``fence``: give
    up (unconverged, ``Z`` at the iterate) where an iterate lies farther than ``fence``
    (weighted RMS) from the centre by more than twice its Newton step, as
    :func:`solver.kernels.spatial_contact.newton_into` does (its ``FENCE_STEPS``);
    ``math.inf``: no fence. Same returns."""
    n = Z.shape[0]
    F, J, blocks, partners, out = work
    F_try = np.empty(n)
    piv = np.empty(n, dtype=np.int64)
    base = np.empty(n)
    step = np.empty(n)
    dense = np.empty((n, n)) if partners[1].shape[0] else np.empty((0, 0))
    rubs = level[L_SELF_FRICTION].shape[0] > 0
    newton_system(Z, grid, rest, level, F, J, True, blocks, partners)
    fresh = True
    coupled = _touched(partners)
    res = weighted_norm(F, res_weights)
    for it in range(max_iter + 1):
        if not math.isfinite(res):
            return False, it, math.inf, False
        if res <= tol:
            if not fresh or out.shape[0] > 1:
                # (Where the Jacobian is Z's already, a residual pass records: the same numbers.)
                recorded_system(Z, grid, rest, level, F, J, not fresh, blocks, partners, out)
            return True, it, res, stability_test(blocks) > 0.0
        if it == max_iter:
            break
        if coupled:
            if fresh:
                differenced[0] += _coupled(Z, grid, rest, level, F, J, partners, weights, dense)
                if not np.all(np.isfinite(dense)) or np.linalg.det(dense) == 0.0:
                    return False, it, res, False
            step[:] = np.linalg.solve(dense, F)
        else:
            if fresh and not factor_band(J, piv):
                return False, it, res, False
            for k in range(n):
                step[k] = F[k]
            band_lu_solve(J, piv, step)
        norm = weighted_norm(step, weights)
        if fence < math.inf and _distance(Z, fence_center, weights) - FENCE_STEPS * norm > fence:
            return False, it, res, False
        alpha = max_step / norm if norm > max_step else 1.0
        for k in range(n):
            base[k] = Z[k]
        res_try = math.inf
        for _ in range(8):
            for k in range(n):
                Z[k] = base[k] - alpha * step[k]
            newton_system(Z, grid, rest, level, F_try, J, False, blocks, partners)
            res_try = weighted_norm(F_try, res_weights)
            if res_try < res:
                break
            alpha *= 0.5
        if not (past_kinks or res_try < res):
            for k in range(n):
                Z[k] = base[k]
            return False, it + 1, res, False
        slow = not res_try <= 0.05 * res
        res = res_try
        for k in range(n):
            F[k] = F_try[k]
        fresh = False
        # The Jacobian is kept while the residual falls twentyfold an iteration — the full
        # one of touching parts too (a residual pass per column of their nodes: most of such
        # a solve's cost) while parts still touch, unless they rub with friction (a kept one
        # there lost a tip-moment curl's ramp: 237 iterations, unconverged) — and formed
        # afresh otherwise.
        if slow or _touched(partners) != coupled or (coupled and rubs):
            newton_system(Z, grid, rest, level, F, J, True, blocks, partners)
            res = weighted_norm(F, res_weights)
            fresh = True
            coupled = _touched(partners)
    if not fresh:
        newton_system(Z, grid, rest, level, F, J, True, blocks, partners)
    return False, max_iter, res, stability_test(blocks) > 0.0


@njit
def set_level(t, a, b, now):
    """Interpolate the homotopy between level tuples ``a`` and ``b`` at ``t`` into ``now``
    (planar or spatial: the widths are the arrays'); its friction (``L_MU``,
    ``L_FRICTION``) is the path's tangential state, not interpolated."""
    for k in range(a[L_P].shape[0]):
        now[L_P][k] = a[L_P][k] + t * (b[L_P][k] - a[L_P][k])
    for i in range(a[L_Q].shape[0]):
        for d in range(a[L_Q].shape[1]):
            now[L_Q][i, d] = a[L_Q][i, d] + t * (b[L_Q][i, d] - a[L_Q][i, d])
            now[L_PLATE][i, d] = a[L_PLATE][i, d] + t * (b[L_PLATE][i, d] - a[L_PLATE][i, d])
    for d in range(a[L_TARGET].shape[0]):
        now[L_TARGET][d] = a[L_TARGET][d] + t * (b[L_TARGET][d] - a[L_TARGET][d])
    for i in range(a[L_DISCS].shape[0]):
        for d in range(a[L_DISCS].shape[1]):
            now[L_DISCS][i, d] = a[L_DISCS][i, d] + t * (b[L_DISCS][i, d] - a[L_DISCS][i, d])


@njit
def start_friction(a, now):
    """A path from level ``a`` starts from its tangential state: ``a``'s friction samples
    into ``now``'s, the work dissipated so far cleared (a path counts its own)."""
    now[L_MU][:] = a[L_MU]
    _start_samples(a[L_FRICTION], now[L_FRICTION])


@njit
def _start_samples(src, fs):
    """Friction samples ``src`` into ``fs`` (the same shape), their work cleared."""
    fs[...] = src
    for row in range(fs.shape[0]):
        for node in range(fs.shape[1]):
            for d in range(fs.shape[2]):
                fs[row, node, d, FS_WORK] = 0.0


@njit
def _at_level(t, a, b, now, tubes_i, tubes_f, secf, rest):
    """:func:`set_level`, then the rest strains of its pressures into ``rest``."""
    set_level(t, a, b, now)
    rest_strains_into(now[L_P], tubes_i, tubes_f, secf, rest)


@njit
def follow(Z, grid, tubes, a, b, params, work, guard):
    """Multiple-shooting path following, in the signature the path-following kernels share.

    Args:
        Z: (N,) the nodes of the start state (see :func:`newton_system`), updated in place.
        grid: the layout tuple (``G_*``). tubes: (tubes_i, tubes_f).
        a, b: start and goal level tuples (``L_*``).
        params: (N_PARAMS,) numeric parameters (TOL, MAX_STEP, DT0, DT_MIN, MAX_ITER,
            PREDICT_CAP are used). work: (rest, now, weights, res_weights): scratch holding
            the returned state's rest strains and level, and the norms' weights (see
            :func:`_path`). guard: unused.

    Returns:
        (converged, stable, snapped, iterations, residual, t, dt), as
        :func:`solver.kernels.planar.follow`: t the level reached, dt the step that failed
        beyond it (0 if the start itself could not be corrected). Snaps are the caller's.
    """
    ok, total, res, stable, t, dt = _path(
        Z, grid, tubes[0], tubes[1], a, b, work[2], work[3], params[TOL], int(params[MAX_ITER]),
        params[MAX_STEP], params[DT0], params[DT_MIN], work[0], work[1], params[PREDICT_CAP])
    return ok, stable, False, total, res, t, dt


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def _path(Z, grid, tubes_i, tubes_f, a, b, weights, res_weights, tol, max_iter, max_step, dt0,
          dt_min, rest, now, predict_cap):
    """Quasi-static ramp from level ``a`` to level ``b`` (tuples, see ``L_P``…``L_DISCS``;
    cf. :func:`solver.kernels.planar.follow`): pressures, distributed loads, endplate weights, tip
    targets and obstacles all linear in t.

    The start ``Z`` is first corrected by Newton at t = 0 (it need not be an equilibrium of
    ``a``: a state from another resolution, or with other discs). A step is accepted if
    Newton converged on a stable state whose correction is small against the step predicted
    (tangent predictor for the first step, then secant, on all node states; a predicted
    move longer than ``predict_cap`` in the weighted RMS norm is shortened to it) and no
    backbone sample tunnelled through a disc on the way (:func:`solver.kernels.obstacles.tunnels`:
    a penalty disc stops pushing once the backbone has crossed it, so a long step could
    land beyond an obstacle that the quasi-static path runs into). A refused step is halved
    from the try it made (:func:`solver.kernels.homotopy.halved`); an accepted one doubles it,
    unless a try failed since the last acceptance. No fold scan: if the step falls below
    ``dt_min`` the last accepted state is returned, flagged unconverged.

    Returns (converged, iterations, |residual|, stable, t, dt): t the level reached (1 when
    converged) and dt the step that failed beyond it (0 if the start itself could not be
    corrected); ``Z`` holds the returned state, ``now`` (a level tuple) its level and
    ``rest`` (3, ns) its rest strains.
    """
    secf = grid[G_SECF]
    steps = grid[G_STEPS]
    n = Z.shape[0]
    t = 0.0
    dt = dt0
    slope = np.zeros(n)
    guess = np.empty(n)
    total = 0
    rows = 0
    for i in range(steps.shape[0]):
        rows += steps[i] + 1
    rec_prev = np.empty((rows, C_COLUMNS))
    rec_new = np.empty((rows, C_COLUMNS))
    has_discs = a[L_DISCS].shape[0] > 0
    friction = a[L_FRICTION].shape[0] > 0
    rubs = a[L_SELF_FRICTION].shape[0] > 0  # self-contact friction
    start_friction(a, now)
    _start_samples(a[L_SELF_FRICTION], now[L_SELF_FRICTION])
    _at_level(0.0, a, b, now, tubes_i, tubes_f, secf, rest)
    F = np.empty(n)
    differenced = np.zeros(1, dtype=np.int64)  # (counted by Newton; this path budgets no passes)
    newton_system(Z, grid, rest, now, F, rec_new, False, np.empty((0, 6, 6)), new_partners(grid))
    res = weighted_norm(F, res_weights)
    total += 1
    # With self-contact friction a warm start is no exact equilibrium of its own accepted
    # anchors (they shape the traced pieces through the first pass's friction loads: on the
    # hairpin of docs/design.md §9.1 a weighted residual of 1.3e-5, penetrations moved ~1 µm),
    # and correcting it to ``tol`` is Newton on the return mapping's kink (every slipped
    # sample sits on the cone's edge), where it crawls: 7–14 iterations, more than the
    # default 12 where the layer starts to slide. The start need only be on the path to its
    # intermediate levels' tolerance; the last level is solved to ``tol``.
    start_tol = 1e3 * tol if rubs else tol
    if not res <= start_tol:  # not an equilibrium of ``a`` (or NaN): correct it first
        ok, its, res, stable = newton(Z, grid, rest, now, weights, res_weights, start_tol,
                                      max_iter, max_step)
        total += its
        if not (ok and stable):
            return False, total, res, stable, 0.0, 0.0
    ok = True
    stable = True
    accepted = Z.copy()
    if has_discs or rubs:
        record_backbone(Z, grid, rest, now, rec_prev)
        # The start, corrected, is the path's first accepted state.
        if friction:
            accept_friction(now[L_FRICTION])
        if rubs:
            accept_friction(now[L_SELF_FRICTION])
    # Tangent predictor for the first step. Without it the first step's correction is
    # judged against a zero prediction, and a large pressure change is halved until its
    # correction is small in absolute terms — five or six converged steps thrown away.
    _initial_tangent(Z, grid, tubes_i, tubes_f, a, b, rest, now, slope)
    total += 1
    failed = False  # a try since the last acceptance failed
    while t < 1.0:
        t_new = min(1.0, t + dt)
        _at_level(t_new, a, b, now, tubes_i, tubes_f, secf, rest)
        move = 0.0
        for k in range(n):
            move += (slope[k] * (t_new - t) / weights[k]) ** 2
        move = math.sqrt(move / n)
        cap = predict_cap / move if move > predict_cap else 1.0
        for k in range(n):
            guess[k] = accepted[k] + cap * slope[k] * (t_new - t)
            Z[k] = guess[k]
        final = t_new >= 1.0
        # A try is refused beyond 0.05 + half the predicted move from its prediction (a
        # branch jump), except at the smallest step: its Newton gives up there (FENCE_STEPS).
        fence = jump_fence(_distance(guess, accepted, weights)) if dt > dt_min else math.inf
        # A try whose line search stalls is given up there (it would spend the rest of its
        # iterations on the plateau: most of a fold's approach, measured) and the step
        # halved, except with friction, whose return mapping's kinks Newton must go past.
        ok, its, res, stable = damped_newton(Z, grid, rest, now, weights, res_weights,
                                             tol if final else 1e3 * tol,
                                             max_iter if final else 8, max_step,
                                             friction or rubs, differenced,
                                             newton_work(n, grid), guess, fence)
        total += its
        if ok and stable and _distance(Z, guess, weights) <= fence:
            through = False
            if has_discs or rubs:
                record_backbone(Z, grid, rest, now, rec_new)
            if has_discs:
                through = tunnels(rec_prev[:, C_X:C_Y + 1], rec_new[:, C_X:C_Y + 1],
                                  now[L_DISCS], TUNNEL_SLACK)
            if not through:
                if friction:
                    accept_friction(now[L_FRICTION])
                if rubs:
                    accept_friction(now[L_SELF_FRICTION])
                for k in range(n):
                    slope[k] = (Z[k] - accepted[k]) / (t_new - t)
                    accepted[k] = Z[k]
                rec_prev, rec_new = rec_new, rec_prev
                t = t_new
                # Doubled after an acceptance, but kept after one that followed a failure:
                # towards a fold the distance left halves with every acceptance, and the
                # doubled try failed there every time (a try of 2h failed, then h, then h/2
                # was accepted: a third of a fold's approach spent on tries bound to fail).
                if not failed:
                    dt = min(2.0 * dt, 1.0)
                failed = False
                continue
        if dt > dt_min:
            failed = True
            dt = halved(dt, t_new - t, dt_min)
            continue
        break
    if t < 1.0:
        for k in range(n):
            Z[k] = accepted[k]
        _at_level(t, a, b, now, tubes_i, tubes_f, secf, rest)
        return False, total, res, stable, t, dt
    return ok, total, res, stable, 1.0, 0.0


@njit
def record_backbone(Z, grid, rest, level, out):
    """Write the backbone of the state ``Z`` into ``out`` (rows Σ(steps + 1), C_COLUMNS): the
    record of :func:`recorded_system`."""
    recorded_system(Z, grid, rest, level, np.empty(Z.shape[0]), np.empty((1, 1)), False,
                    np.empty((0, 6, 6)), new_partners(grid), out)


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def _initial_tangent(Z, grid, tubes_i, tubes_f, a, b, rest, now, slope):
    """dZ/dt = −J⁻¹ ∂F/∂t at the start state (an equilibrium of level ``a``), ∂F/∂t by a
    forward difference, into ``slope``; zero where J or the result is not finite."""
    secf = grid[G_SECF]
    n = Z.shape[0]
    eps_t = 1e-4
    F0 = np.empty(n)
    F1 = np.empty(n)
    J = np.empty((BAND_ROWS, n))
    blocks = np.empty((grid[G_SEGS].shape[0], 6, 6))
    partners = new_partners(grid)
    _at_level(eps_t, a, b, now, tubes_i, tubes_f, secf, rest)
    newton_system(Z, grid, rest, now, F1, J, False, blocks, partners)
    _at_level(0.0, a, b, now, tubes_i, tubes_f, secf, rest)
    newton_system(Z, grid, rest, now, F0, J, True, blocks, partners)
    for k in range(n):
        F1[k] = -(F1[k] - F0[k]) / eps_t
    slope[:] = F1
    if not (np.all(np.isfinite(F1)) and _band_solve(J, slope) and np.all(np.isfinite(slope))):
        slope[:] = 0.0


# Residual passes a lean step spends on quasi-Newton corrections before it falls back to
# full Newton; and the least fall of the residual per correction that keeps them going.
LEAN_ITER = 12
LEAN_RATE = 0.25

# What a lean contact step (planar or 3D) may spend before it hands the step to the general
# path: steps of its path tried (accepted or halved), and Jacobians formed (its Newton
# iterations and the pass of each accepted state).
LEAN_TRIES = 32
LEAN_JACOBIANS = 64

# ... and, where parts of the arm touch each other, the residual passes of the full Jacobians
# it forms (:func:`_coupled`: a pass per column of a node in contact, ~14 band Jacobians'
# worth each on a wrapped grasp). Measured on the lean moved steps of a scripted curl on
# OctArmGrasp-v1 (docs/design.md §10.1): the accepted ones formed ≤ 14 full Jacobians (204 of
# 207; at most 29), each refused one all 64 of LEAN_JACOBIANS (~70 ms, four times what the
# general path then spent on the step, a snap). Past this many such passes (~14 full
# Jacobians there) the step is handed over.
LEAN_COLUMNS = 256

# Why a lean contact step refused a try (bits of the ``refused`` it returns; a profile's
# figures, :mod:`softarm_gym.benchmarks.contact_profile`): Broyden and damped Newton did not
# converge; the state reached is unstable; it lies farther from the prediction than a step
# of the path may (a branch jump); its Jacobian is singular or its recorded pass is not
# converged; a sample tunnelled through a disc; the RK4 grid does not resolve the end state;
# the tries or Jacobians of the budget ran out.
(REFUSED_CONVERGENCE, REFUSED_UNSTABLE, REFUSED_JUMP, REFUSED_SINGULAR, REFUSED_TUNNEL,
 REFUSED_GRID, REFUSED_BUDGET) = (1, 2, 4, 8, 16, 32, 64)

# Where parts of the arm touch each other a state's full Jacobian (:func:`_coupled`) costs a
# residual pass for every column of a node that shapes a piece in contact — most of a wrapped
# arm's lean step. An accepted state whose try converged by Broyden's corrections alone keeps
# the full factors of the state before (refreshing only the band Jacobian, which the
# stability test needs), for at most this many accepted states in a row.
LEAN_REUSE_AGE = 8


@njit
def new_factors(n, coupled):
    """Scratch for the factored Jacobian of a lean state (:func:`factor_state`): (band
    factors (BAND_ROWS, n), their pivots (n,), dense factors (n, n), their pivots (n,),
    flags (1,)); the dense ones (for states where parts of the arm touch each other) are
    empty unless ``coupled`` (a scene with self-contact)."""
    m = n if coupled else 0
    return (np.empty((BAND_ROWS, n)), np.empty(n, dtype=np.int64), np.empty((m, m)),
            np.empty(m, dtype=np.int64), np.zeros(1, dtype=np.int64))


@njit
def factor_state(Z, grid, rest, level, weights, F, blocks, out, factors):
    """One pass at the state ``Z`` (``level``, ``rest`` its rest strains) that records its
    backbone into ``out``, its residual into ``F`` and its segment maps into ``blocks``,
    and factors its Jacobian into ``factors`` (:func:`new_factors`): the band one, and where
    parts of the arm touch each other the full one (:func:`_coupled`), which the next
    solves from this state use instead (flags[0] ≥ 1). Returns whether the Jacobian is
    regular."""
    return _factor_state(Z, grid, rest, level, weights, F, blocks, out, factors, factors, False,
                         np.zeros(1, dtype=np.int64))


@njit
def _factor_state(Z, grid, rest, level, weights, F, blocks, out, factors, held, reuse,
                  differenced):
    """:func:`factor_state`; with ``reuse``, where parts of the arm touch and ``held``
    (the factors of a nearby state) holds full factors younger than LEAN_REUSE_AGE, those are
    copied instead of forming the full Jacobian afresh (flags[0]: 1 fresh, one more a reuse).
    ``differenced`` (1,) counts the residual passes of a full Jacobian formed."""
    lu, piv, dense, dense_piv, flags = factors
    partners = new_partners(grid)
    recorded_system(Z, grid, rest, level, F, lu, True, blocks, partners, out)
    age = held[4][0] if reuse else 0
    flags[0] = 0
    if dense.shape[0] > 0 and _touched(partners):
        if 0 < age < LEAN_REUSE_AGE:
            dense[:, :] = held[2]
            dense_piv[:] = held[3]
            flags[0] = age + 1
        else:
            differenced[0] += _coupled(Z, grid, rest, level, F, lu, partners, weights, dense)
            if not _dense_factor(dense, dense_piv):
                return False
            flags[0] = 1
    return factor_band(lu, piv)


@njit
def _factored_solve(factors, b):
    """Solve J x = b in place with the factors of :func:`factor_state`."""
    lu, piv, dense, dense_piv, flags = factors
    if flags[0]:
        _dense_lu_solve(dense, dense_piv, b)
    else:
        band_lu_solve(lu, piv, b)


@njit
def _dense_factor(a, piv):
    """LU-factor the square ``a`` in place with partial pivoting (rows ``piv``); False if
    it is singular or not finite."""
    n = a.shape[0]
    for j in range(n):
        p = j
        best = abs(a[j, j])
        for i in range(j + 1, n):
            if abs(a[i, j]) > best:
                best = abs(a[i, j])
                p = i
        if not (best > 0.0) or not math.isfinite(best):
            return False
        piv[j] = p
        if p != j:
            for c in range(n):
                tmp = a[j, c]
                a[j, c] = a[p, c]
                a[p, c] = tmp
        for i in range(j + 1, n):
            factor = a[i, j] / a[j, j]
            a[i, j] = factor
            if factor != 0.0:
                for c in range(j + 1, n):
                    a[i, c] -= factor * a[j, c]
    return True


@njit
def _dense_lu_solve(a, piv, b):
    """Solve with the factors of :func:`_dense_factor`, ``b`` in place."""
    n = a.shape[0]
    for j in range(n):
        p = piv[j]
        if p != j:
            tmp = b[p]
            b[p] = b[j]
            b[j] = tmp
    for i in range(n):
        acc = b[i]
        for c in range(i):
            acc -= a[i, c] * b[c]
        b[i] = acc
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for c in range(i + 1, n):
            acc -= a[i, c] * b[c]
        b[i] = acc / a[i, i]


@njit
def broyden_update(steps, norms, k, z):
    """The next quasi-Newton step by Broyden's updates of an inverse Jacobian (Kelley's
    form): ``z`` (N,), the stored Jacobian's solve of −F, updated by the steps so far
    ``steps[0..k]`` (rows) with their squared norms ``norms``, scaled and written into
    ``steps[k + 1]``. Returns False where the update is singular (nothing written)."""
    n = z.shape[0]
    for j in range(k):
        c = 0.0
        for i in range(n):
            c += steps[j, i] * z[i]
        c /= norms[j]
        for i in range(n):
            z[i] += steps[j + 1, i] * c
    c = 0.0
    for i in range(n):
        c += steps[k, i] * z[i]
    denom = 1.0 - c / norms[k]
    if denom == 0.0:
        return False
    for i in range(n):
        steps[k + 1, i] = z[i] / denom
    return True


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def _broyden(Z, grid, rest, level, F, res_weights, tol, factors, res, partners):
    """Quasi-Newton corrections of the nodes ``Z`` at ``level`` from their residual ``F``
    (its weighted norm ``res``): the first step by the factored Jacobian ``factors`` (of a
    nearby state, :func:`factor_state`), later ones by Broyden's updates of its inverse
    (Kelley's form, a factored solve and a residual pass each), while the residual falls at
    least LEAN_RATE-fold a pass. ``Z`` ends at the last iterate, ``F`` holds its residual.

    Returns:
        (converged, passes, first): ``first`` (N,) the first step (a lean step's prediction).
    """
    n = Z.shape[0]
    no_record = np.empty((1, C_COLUMNS))
    no_blocks = np.empty((0, 6, 6))
    unused = np.empty((1, n))
    # Broyden steps s_k (rows) and their squared norms; S[0] is the prediction.
    steps = np.empty((LEAN_ITER + 1, n))
    norms = np.empty(LEAN_ITER + 1)
    z = np.empty(n)
    for i in range(n):
        steps[0, i] = -F[i]
    _factored_solve(factors, steps[0])
    first = steps[0].copy()
    passes = 0
    k = 0
    while True:
        norms[k] = 0.0
        for i in range(n):
            norms[k] += steps[k, i] * steps[k, i]
            Z[i] += steps[k, i]
        recorded_system(Z, grid, rest, level, F, unused, False, no_blocks, partners, no_record)
        passes += 1
        r = weighted_norm(F, res_weights)
        if r <= tol:
            return True, passes, first
        if not r <= LEAN_RATE * res or k == LEAN_ITER - 1 or norms[k] == 0.0:
            return False, passes, first
        res = r
        for i in range(n):
            z[i] = -F[i]
        _factored_solve(factors, z)
        if not broyden_update(steps, norms, k, z):
            return False, passes, first
        k += 1


@njit
def _copy_factors(src, dst):
    """Copy the factors of :func:`factor_state` ``src`` into ``dst`` (:func:`new_factors`)."""
    dst[0][:, :] = src[0]
    dst[1][:] = src[1]
    dst[2][:, :] = src[2]
    dst[3][:] = src[3]
    dst[4][0] = src[4][0]


@njit
def lean_step(Z, grid, tubes, level, p_new, discs_new, params, work, factors, records, check):
    """A warm step of the contact stepper in one kernel call: from the equilibrium ``Z`` at
    ``level`` to the pressures ``p_new`` and the discs ``discs_new`` (the same array as the
    level's where they stand still; moved, as a held object moves), the loads unchanged — a
    lean continuation.

    The quasi-static path is followed as :func:`_path` follows it — pressures and discs
    linear in t, a step accepted when converged (``tol``; a thousand times that short of the
    end), stable, within ``0.05 + 0.5·|prediction|`` of its prediction (weighted RMS: a
    branch jump is a refusal) and no sample tunnelled through a disc, halved otherwise,
    doubled after an acceptance — but each step is predicted to first order by the factored
    Jacobian of the last accepted state (kept from the step before for the first) and
    corrected by Broyden's updates of it (:func:`_broyden`), with damped Newton
    (:func:`newton`) only where those stall. The first try is the whole step: a small move
    is one prediction and a few corrections. Each accepted state gets its Jacobian,
    stability test and backbone from one more pass (:func:`factor_state`; a state Newton
    reached, from Newton's last pass, which records it), and the last
    must be resolved by the RK4 grid (:func:`solver.kernels.grid.section_needs`, the
    general path's check). Where parts of the arm touch each other, a state reached by
    Broyden's corrections alone keeps the full factors of the state before (up to
    LEAN_REUSE_AGE states; its band Jacobian, stability test and backbone are its own):
    forming them costs a residual pass per column of a node in contact. Past LEAN_TRIES
    steps, LEAN_JACOBIANS Jacobians or LEAN_COLUMNS passes of full ones (not counted in the
    passes it returns), or on anything else, every input is left untouched
    and ``ok`` is False: the caller's general path (continuation, snaps, refinement) takes
    the step.

    Args:
        Z: (N,) the nodes of the current equilibrium (:func:`newton_system`); the new ones on
            success.
        grid: the layout tuple (``G_*``). tubes: (tubes_i, tubes_f).
        level: the level tuple (``L_*``) of ``Z``; its pressures and discs become ``p_new``
            and ``discs_new`` on success, and its friction samples (if any) the path's, each
            accepted step accepting its anchors as :func:`_path`'s do
            (:func:`solver.kernels.obstacles.accept_friction`).
        p_new: (n_channels,) the target pressures (Pa). discs_new: (k, 4) the target discs
            (the same law and count as the level's).
        params: (N_PARAMS,) numeric parameters (TOL, MAX_STEP, MAX_ITER are used).
        work: (rest (3, ns), weights (N,), res_weights (N,)): scratch for the rest strains,
            and the norms' weights (:func:`_path`).
        factors: the factored Jacobian at ``Z`` (:func:`factor_state`); the new state's on
            success.
        records: (rec (rows, C_COLUMNS), new (rows, C_COLUMNS)): the backbone of ``Z``, and
            scratch that receives the new state's backbone on success.
        check: (q (ns,) |distributed load| (N/m), ends (ns,) the records' section-end rows)
            for the grid check.

    Returns:
        (ok, stable, iterations, residual, refused): iterations counts the passes of the
        step; refused, the ``REFUSED_*`` bits of the tries it refused (a profile's figure).
    """
    rest, weights, res_weights = work
    rec, new = records
    tol = params[TOL]
    n = Z.shape[0]
    secf = grid[G_SECF]
    p_old, discs_old = level[L_P], level[L_DISCS]
    p_now = np.empty_like(p_new)
    discs_now = np.empty_like(discs_new)
    # The path's tangential state: the level's samples, copied (its accepted steps accept
    # theirs, and a refused lean step leaves the level's untouched).
    fs = level[L_FRICTION]
    friction = fs.shape[0] > 0
    fs_now = fs.copy() if friction else fs
    sfs = level[L_SELF_FRICTION]
    rubs = sfs.shape[0] > 0  # self-contact friction
    sfs_now = sfs.copy() if rubs else sfs
    now = (p_now, level[L_Q], level[L_PLATE], level[L_TARGET], discs_now, level[L_MU], fs_now,
           sfs_now)
    partners = new_partners(grid)
    no_record = np.empty((1, C_COLUMNS))
    no_blocks = np.empty((0, 6, 6))
    unused = np.empty((1, n))
    blocks = np.empty((grid[G_SEGS].shape[0], 6, 6))
    need = np.empty(secf.shape[1])
    F = np.empty(n)
    start = Z.copy()
    accepted = Z.copy()
    guess = np.empty(n)
    before = rec[:, C_X:C_Y + 1].copy()  # the accepted state's backbone (the tunnel check's start)
    coupled = factors[2].shape[0] > 0
    held = new_factors(n, coupled)  # the factors of the accepted state
    _copy_factors(factors, held)
    spare = new_factors(n, coupled)
    t = 0.0
    dt = 1.0
    passes = 0
    jacobians = 0
    res = math.inf
    stable = False
    refused = 0
    differenced = np.zeros(1, dtype=np.int64)  # the passes of full Jacobians formed
    newton_partners = partners  # (each Newton call gets its own, fresh)
    for _ in range(LEAN_TRIES):
        if jacobians >= LEAN_JACOBIANS or differenced[0] >= LEAN_COLUMNS:
            break
        t_new = min(1.0, t + dt)
        final = t_new >= 1.0
        for c in range(p_new.shape[0]):
            p_now[c] = p_new[c] if final else p_old[c] + t_new * (p_new[c] - p_old[c])
        for i in range(discs_new.shape[0]):
            for d in range(discs_new.shape[1]):
                discs_now[i, d] = discs_new[i, d] if final else \
                    discs_old[i, d] + t_new * (discs_new[i, d] - discs_old[i, d])
        rest_strains_into(p_now, tubes[0], tubes[1], secf, rest)
        goal = tol if final else 1e3 * tol
        recorded_system(Z, grid, rest, now, F, unused, False, no_blocks, partners, no_record)
        passes += 1
        res = weighted_norm(F, res_weights)
        ok = res <= goal
        predicted = False
        first = F
        quasi = ok  # converged without a Jacobian formed (the held full factors may serve)
        newton_recorded = False
        if not ok and math.isfinite(res):
            ok, its, first = _broyden(Z, grid, rest, now, F, res_weights, goal, held, res,
                                      partners)
            passes += its
            predicted = True
            quasi = ok
        # A step is accepted within 0.05 + 0.5·|prediction| of its prediction: the accepted
        # state moved by the first step (none if it held). Newton gives up where its root
        # lies beyond that (FENCE_STEPS).
        for i in range(n):
            guess[i] = accepted[i] + (first[i] if predicted else 0.0)
        fence = jump_fence(_distance(guess, accepted, weights))
        if predicted and not ok:
            # Newton works in the accepted state's scratch: its converged state comes
            # back recorded into ``new``, its band Jacobian and maps into ``spare`` and
            # ``blocks`` (the pass the stability test needs), which the acceptance below
            # then need not make again.
            newton_partners = new_partners(grid)
            ok, its, res, stable = damped_newton(
                Z, grid, rest, now, weights, res_weights, goal,
                min(int(params[MAX_ITER]) if final else 8, LEAN_JACOBIANS - jacobians - 1),
                params[MAX_STEP], True, differenced,
                (F, spare[0], blocks, newton_partners, new), guess, fence)
            newton_recorded = ok
            passes += its
            jacobians += its + 1
            if not ok:
                refused |= REFUSED_JUMP if _distance(Z, guess, weights) > fence \
                    else REFUSED_CONVERGENCE
            elif not stable:
                refused |= REFUSED_UNSTABLE
            ok = ok and stable
        elif not ok:
            refused |= REFUSED_CONVERGENCE
        if ok:
            ok = _distance(Z, guess, weights) <= fence
            if not ok:
                refused |= REFUSED_JUMP
        stable = False
        if ok:
            if newton_recorded and not _touched(newton_partners):
                # Newton's last pass recorded the state with its band Jacobian (the pass
                # counted below, as the one it saves); parts that touch each other need the
                # full Jacobian, which _factor_state forms (or keeps) from its own pass.
                spare[4][0] = 0
                regular = factor_band(spare[0], spare[1])
            else:
                regular = _factor_state(Z, grid, rest, now, weights, F, blocks, new, spare,
                                        held, quasi, differenced)
            passes += 1
            jacobians += 1
            res = weighted_norm(F, res_weights)
            stable = stability_test(blocks) > 0.0
            ok = False
            if not (res <= goal and regular):
                refused |= REFUSED_SINGULAR
            elif not stable:
                refused |= REFUSED_UNSTABLE
            elif tunnels(before, new[:, C_X:C_Y + 1], discs_now, TUNNEL_SLACK):
                refused |= REFUSED_TUNNEL
            elif final and section_needs(new[:, C_U:C_U + 1], new[:, C_NX:C_NY + 1],
                                         new[:, C_V1:C_V3 + 1], check[0], secf, check[1],
                                         need) > 1.0:
                refused |= REFUSED_GRID
            else:
                ok = True
        if ok:
            t = t_new
            accepted[:] = Z
            held, spare = spare, held
            before[:, :] = new[:, C_X:C_Y + 1]
            if friction:
                accept_friction(fs_now)
            if rubs:
                accept_friction(sfs_now)
            if final:
                break
            dt = min(2.0 * dt, 1.0)
        else:
            Z[:] = accepted
            dt = halved(dt, t_new - t, 0.0)
    if t < 1.0:
        Z[:] = start
        return False, stable, passes, res, refused | REFUSED_BUDGET
    _copy_factors(held, factors)
    for c in range(p_new.shape[0]):
        p_old[c] = p_new[c]
    discs_old[:, :] = discs_new
    if friction:
        fs[...] = fs_now
    if rubs:
        sfs[...] = sfs_now
    return True, stable, passes, res, refused
