"""Spatial kernels for an arm pressed against rigid cylinders and spheres (penalty contact),
multiple shooting (docs/design.md §9).

The planar contact kernels (:mod:`solver.kernels.contact`) carried to 3D. With contact the internal
force is not known from global equilibrium, so the whole state — position r, directors
(a unit quaternion β), internal force n and moment m, world frame — is integrated
(:func:`solver.rod.spatial_state_rhs`):

    r' = R v,  β' = ½ β ⊗ u,  n' = −μ_i g − Σ f_c(r),  m' = −r' × n,
    f_c = k · max(0, R_o − |e|) · e/|e|   (e: r less the nearest point of the obstacle's core)

The arm is cut into the segments of the planar contact layout
(:func:`solver.problem.contact_layout`: the same RK4 grid, refined NEAR_SUBSTEPS-fold near an
obstacle with the same smoothstep blend). The unknowns are (n, m) at the clamped base and
the 12 tangent coordinates (δr, world rotation δφ, δn, δm) of every later segment start;
the residuals are the jumps at segment ends (the rotation jump as the rotation vector of
R_end R_nextᵀ) and n(L⁻), m(L) against the tip loads. Each segment map's Jacobian is formed
by forward differences in those tangent coordinates (13 passes over the segment), which
also carries the blend and the contact law's kink without special cases; the block-banded
Newton system is solved by :func:`solver.kernels.spatial_shooting.banded_solve`.

Stability is the planar contact test in 3D: the Jacobi fields of the free tip, δ(r, φ)(L) = I
and δ(n, m)(L) = 0, carried back to the base through the inverse segment maps; no real
eigenvalue of their δ(r, φ) block may cross zero (:func:`stability_test`).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.contact import (
    NEAR_SUBSTEPS,
    TUNNEL_SLACK,
    set_level,
    start_friction,
    weighted_norm,
)
from solver.kernels.obstacles import (
    accept_friction,
    clearance_3d,
    contact_force_3d,
    friction_impulse_3d,
    friction_untouched,
    tunnels_3d,
)
from solver.kernels.spatial_shooting import banded_solve, rotate_node, rotation_gap
from solver.layout import (
    CA,
    CG,
    CI,
    CS_M,
    CS_N,
    CS_Q,
    CS_R,
    CT_M,
    CT_N,
    CT_PHI,
    CT_R,
    FS_F,
    GS_CJ,
    GS_SECF,
    GS_SEGS,
    GS_START,
    GS_STEPS,
    L_DISCS,
    L_FRICTION,
    L_MU,
    L_P,
    L_PLATE,
    L_Q,
    L_TARGET,
    LEN,
    N_CSTATE,
    N_CTANGENT,
    REST_U1,
    REST_U2,
    REST_V3,
    SEG_END,
    SEG_FIRST,
    SEG_ROW0,
    SEG_SECTION,
    SEG_STEPS,
)
from solver.rod import rest_strains_into, rotation_rows, rotation_to_quaternion, spatial_state_rk4_step

NO_TETHER = (np.zeros(1), np.zeros((0, 3)))
"""The ``tether`` of an ordinary solve: no springs (:func:`newton_system`)."""

# Forward-difference steps of the segment Jacobians, relative to the tangent coordinates'
# weights (the square root of the machine epsilon: half the digits of the derivative).
FD_STEP = 1.5e-8


@njit
def n_unknowns(n_segments):
    """Unknowns (and residuals) of a spatial contact system of ``n_segments``."""
    return N_CTANGENT * (n_segments - 1) + 6


@njit
def _column(seg, c):
    """The unknown of tangent coordinate ``c`` of segment ``seg``'s start node (−1: fixed)."""
    if seg == 0:
        return c - CT_N if c >= CT_N else -1
    return 6 + N_CTANGENT * (seg - 1) + c


@njit
def _record_row(y, s, rec, row, ca, cg, ci, cj, u1r, u2r, v3r, obstacles):
    """Write the sample ``y`` at arc length ``s`` into row ``row`` of the record tuple
    (s, positions, frames, force, moment, contact force, penetration, strains v, u)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_rows(y[CS_Q], y[CS_Q + 1],
                                                                y[CS_Q + 2], y[CS_Q + 3])
    rec[0][row] = s
    rot = rec[2][row]
    rot[0, 0], rot[0, 1], rot[0, 2] = r00, r01, r02
    rot[1, 0], rot[1, 1], rot[1, 2] = r10, r11, r12
    rot[2, 0], rot[2, 1], rot[2, 2] = r20, r21, r22
    for d in range(3):
        rec[1][row, d] = y[CS_R + d]
        rec[3][row, d] = y[CS_N + d]
        rec[4][row, d] = y[CS_M + d]
    fx, fy, fz, pen = contact_force_3d(y[CS_R], y[CS_R + 1], y[CS_R + 2], obstacles)
    rec[5][row, 0] = fx
    rec[5][row, 1] = fy
    rec[5][row, 2] = fz
    rec[6][row] = pen
    for a in range(3):
        nb = rot[0, a] * y[CS_N] + rot[1, a] * y[CS_N + 1] + rot[2, a] * y[CS_N + 2]
        mb = rot[0, a] * y[CS_M] + rot[1, a] * y[CS_M + 1] + rot[2, a] * y[CS_M + 2]
        rec[7][row, a] = nb * (ca if a == 2 else cg) + (v3r if a == 2 else 0.0)
        rec[8][row, a] = mb * (cj if a == 2 else ci) + (u1r if a == 0 else u2r if a == 1 else 0.0)


@njit
def new_record(rows):
    """An empty record tuple of ``rows`` samples (see :func:`_record_row`)."""
    return (np.zeros(rows), np.zeros((rows, 3)), np.zeros((rows, 3, 3)), np.zeros((rows, 3)),
            np.zeros((rows, 3)), np.zeros((rows, 3)), np.zeros(rows), np.zeros((rows, 3)),
            np.zeros((rows, 3)))


@njit
def _segment(z, seg, grid, rest, level, out, work, record, rec):
    """Integrate segment ``seg`` from the node state ``z`` (N_CSTATE,) into ``out``.

    Near an obstacle each RK4 step is refined into NEAR_SUBSTEPS substeps and blended with
    the whole step by a smoothstep of the clearance, as in :func:`solver.kernels.contact._segment`,
    friction acting at the refinement's nodes as it does there
    (:func:`solver.kernels.obstacles.friction_impulse_3d`). At a section end (not the tip)
    the endplate's weight is taken off n. With ``record``, the samples go to the record tuple
    ``rec``. ``work`` (8, N_CSTATE) scratch.
    """
    segs = grid[GS_SEGS]
    secf = grid[GS_SECF]
    steps = grid[GS_STEPS]
    obstacles = level[L_DISCS]
    fs = level[L_FRICTION]
    friction = fs.shape[0] > 0
    i = segs[seg, SEG_SECTION]
    first = segs[seg, SEG_FIRST]
    h = secf[LEN, i] / steps[i]
    h_sub = h / NEAR_SUBSTEPS
    ca = secf[CA, i]
    cg = secf[CG, i]
    ci = secf[CI, i]
    cj = grid[GS_CJ][i]
    u1r = rest[REST_U1, i]
    u2r = rest[REST_U2, i]
    v3r = rest[REST_V3, i]
    q = level[L_Q][i]
    s0 = grid[GS_START][i]
    start = work[5]
    fine = work[6]
    for d in range(N_CSTATE):
        out[d] = z[d]
    for j in range(first, first + segs[seg, SEG_STEPS]):
        if record:
            _record_row(out, s0 + j * h, rec, segs[seg, SEG_ROW0] + j, ca, cg, ci, cj, u1r, u2r,
                        v3r, obstacles)
        for d in range(N_CSTATE):
            start[d] = out[d]
        spatial_state_rk4_step(out, h, work, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
        if obstacles.shape[0] == 0:
            continue
        # work[0] holds the slope at the step's start: r' its first three entries.
        speed = math.sqrt(work[0, CS_R] ** 2 + work[0, CS_R + 1] ** 2 + work[0, CS_R + 2] ** 2)
        clear = clearance_3d(start[CS_R], start[CS_R + 1], start[CS_R + 2], obstacles) - h * speed
        at = segs[seg, SEG_ROW0] + j
        if clear >= h:
            if friction and record:
                friction_untouched(fs, at)
            continue
        for d in range(N_CSTATE):
            fine[d] = start[d]
        for sub in range(NEAR_SUBSTEPS):
            if friction:
                _friction_node(fine, level, at, sub, (0.5 if sub == 0 else 1.0) * h_sub, record)
            spatial_state_rk4_step(fine, h_sub, work, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
        if friction:
            _friction_node(fine, level, at, NEAR_SUBSTEPS, 0.5 * h_sub, record)
            if record:
                _friction_row(fs, at, 0, h_sub, rec, at)
        x = 1.0 - clear / h if clear > 0.0 else 1.0
        weight = x * x * (3.0 - 2.0 * x)
        for d in range(N_CSTATE):
            out[d] = weight * fine[d] + (1.0 - weight) * out[d]
        norm = math.sqrt(out[CS_Q] ** 2 + out[CS_Q + 1] ** 2 + out[CS_Q + 2] ** 2
                         + out[CS_Q + 3] ** 2)
        for d in range(CS_Q, CS_Q + 4):
            out[d] /= norm
    if segs[seg, SEG_END] == 1:
        if record:
            _record_row(out, s0 + secf[LEN, i], rec, segs[seg, SEG_ROW0] + steps[i], ca, cg, ci, cj,
                        u1r, u2r, v3r, obstacles)
            if friction:
                _friction_row(fs, segs[seg, SEG_ROW0] + steps[i] - 1, NEAR_SUBSTEPS, h_sub, rec,
                              segs[seg, SEG_ROW0] + steps[i])
        if i < secf.shape[1] - 1:
            for d in range(3):
                out[CS_N + d] -= level[L_PLATE][i, d]


@njit
def _friction_node(y, level, row, node, weight, record):
    """Apply the friction impulse of sample (row, node), its share ``weight`` of the length,
    to the contact state ``y`` as a point load: n⁺ = n⁻ − F."""
    fx, fy, fz = friction_impulse_3d(y[CS_R], y[CS_R + 1], y[CS_R + 2], level[L_DISCS],
                                     level[L_MU], level[L_FRICTION], row, node, weight, record)
    y[CS_N] -= fx
    y[CS_N + 1] -= fy
    y[CS_N + 2] -= fz


@njit
def _friction_row(fs, row, node, h_sub, rec, out_row):
    """Add the friction force per length of sample (row, node) (an end node of its step's
    refinement: half a substep) to the contact force of record row ``out_row``."""
    for d in range(fs.shape[2]):
        for c in range(3):
            rec[5][out_row, c] += fs[row, node, d, FS_F + c] / (0.5 * h_sub)


@njit
def _nudge(z, c, amount, out):
    """``out`` = the node state ``z`` moved by ``amount`` along tangent coordinate ``c``."""
    for d in range(N_CSTATE):
        out[d] = z[d]
    if CT_PHI <= c < CT_PHI + 3:
        phi = np.zeros(3)
        phi[c - CT_PHI] = 1.0
        rotate_node(out[CS_Q:CS_Q + 4], phi, amount)
    elif c < CT_PHI:
        out[CS_R + c] += amount
    else:
        out[CS_N + c - CT_N] += amount  # n and m follow each other in both layouts


@njit
def _difference(a, b, out):
    """Tangent coordinates (N_CTANGENT,) of the state ``a`` relative to ``b``."""
    for d in range(3):
        out[CT_R + d] = a[CS_R + d] - b[CS_R + d]
        out[CT_N + d] = a[CS_N + d] - b[CS_N + d]
        out[CT_M + d] = a[CS_M + d] - b[CS_M + d]
    rotation_gap(a[CS_Q:CS_Q + 4], b[CS_Q:CS_Q + 4], 1.0, out[CT_PHI:CT_PHI + 3])


@njit
def newton_system(Z, grid, rest, level, F, J, want_jac, blocks, scales, tether):
    """Residuals F of the node states ``Z`` (K, N_CSTATE) and, with ``want_jac``, their
    Jacobian J (dense (n, n), zero off the band) and the segment maps' Jacobians ``blocks``
    (K, 12, 12) in tangent coordinates. ``scales`` (12,) the tangent coordinates' weights
    (the differences' steps are FD_STEP times them). Row order per segment: the jumps of r,
    rotation, n and m; at the tip n(L⁻) and m(L) less the level's target. ``tether``:
    (k (1,), anchors (K, 3)): with k > 0, every node after the base is held to its anchor by
    a spring of k N/m (a point load −k(r − anchor), see :func:`relax`). Returns False where
    a state is not finite."""
    segs = grid[GS_SEGS]
    n_seg = segs.shape[0]
    target = level[L_TARGET]
    end = np.empty(N_CSTATE)
    moved = np.empty(N_CSTATE)
    moved_end = np.empty(N_CSTATE)
    gap = np.empty(N_CTANGENT)
    work = np.empty((8, N_CSTATE))
    rec = new_record(1)
    if want_jac:
        J[:, :] = 0.0
    for seg in range(n_seg):
        _segment(Z[seg], seg, grid, rest, level, end, work, False, rec)
        for d in range(N_CSTATE):
            if not math.isfinite(end[d]):
                return False
        row = N_CTANGENT * seg
        last = seg == n_seg - 1
        if last:
            for d in range(3):
                F[row + d] = end[CS_N + d] - target[d]
                F[row + 3 + d] = end[CS_M + d] - target[3 + d]
        else:
            _difference(end, Z[seg + 1], F[row:row + N_CTANGENT])
            if tether[0][0] > 0.0:  # n jumps by +k(r − anchor) across the tethered node
                for d in range(3):
                    F[row + CT_N + d] += tether[0][0] * (Z[seg + 1, CS_R + d] - tether[1][seg + 1, d])
        if not want_jac:
            continue
        if not last:
            for d in range(N_CTANGENT):
                J[row + d, _column(seg + 1, d)] = -1.0
            for d in range(3):
                J[row + CT_N + d, _column(seg + 1, CT_R + d)] += tether[0][0]
        for c in range(N_CTANGENT):
            step = FD_STEP * scales[c]
            _nudge(Z[seg], c, step, moved)
            _segment(moved, seg, grid, rest, level, moved_end, work, False, rec)
            _difference(moved_end, end, gap)
            for d in range(N_CTANGENT):
                blocks[seg, d, c] = gap[d] / step
            col = _column(seg, c)
            if col < 0:
                continue
            if last:
                for d in range(6):
                    J[row + d, col] = blocks[seg, CT_N + d, c]
            else:
                for d in range(N_CTANGENT):
                    J[row + d, col] = blocks[seg, d, c]
    return True


@njit
def stability_test(blocks):
    """The conjugate-point test of the equilibrium whose segment maps have the Jacobians
    ``blocks`` (K, 12, 12): True if stable (see the module docstring).

    The Jacobi fields F (12×6) of the free tip, δ(r, φ)(L) = I and δ(n, m)(L) = 0, are
    carried back through the inverse segment maps. As in the spatial dead-load test
    (:func:`solver.kernels.spatial_shooting.stability_test`) they are restarted at every segment
    start as F·T⁻¹, T their δ(r, φ) block, so that over the next segment that block runs
    from I, and no real eigenvalue of it may turn negative: counting eigenvalues, not the
    determinant's sign, catches the near-coincident pairs of conjugate points of a round
    arm (in-plane and out-of-plane), whose signs cancel in the determinant. The restart
    also keeps the fields, which grow like e^(s/ℓ) across a stiff contact, well scaled.
    """
    fields = np.zeros((N_CTANGENT, 6))
    for d in range(6):
        fields[d, d] = 1.0
    for seg in range(blocks.shape[0] - 1, -1, -1):
        block = blocks[seg]
        if not np.all(np.isfinite(block)) or np.linalg.det(block) == 0.0:
            return False
        fields = np.linalg.solve(block, fields)
        top = np.ascontiguousarray(fields[:6, :])
        if not np.all(np.isfinite(top)):
            return False
        for value in np.linalg.eigvals(top.astype(np.complex128)):
            if value.real <= 0.0 and abs(value.imag) <= 1e-12 * (abs(value.real) + 1.0):
                return False
        fields = fields @ np.linalg.inv(top)
    return True


@njit
def retract(base, delta, amount, Z):
    """Node states ``Z`` = ``base`` moved by ``amount`` × ``delta`` (the unknowns' order)."""
    for k in range(base.shape[0]):
        for d in range(N_CSTATE):
            Z[k, d] = base[k, d]
        for c in range(N_CTANGENT):
            col = _column(k, c)
            if col < 0:
                continue
            if CT_PHI <= c < CT_PHI + 3:
                continue
            if c < CT_PHI:
                Z[k, CS_R + c] += amount * delta[col]
            else:
                Z[k, CS_N + c - CT_N] += amount * delta[col]
        if k > 0:
            col = _column(k, CT_PHI)
            rotate_node(Z[k, CS_Q:CS_Q + 4], delta[col:col + 3], amount)


@njit
def _between(a, b, out):
    """The unknowns' vector (n,) taking node states ``b`` to ``a``."""
    gap = np.empty(N_CTANGENT)
    for k in range(a.shape[0]):
        _difference(a[k], b[k], gap)
        for c in range(N_CTANGENT):
            col = _column(k, c)
            if col >= 0:
                out[col] = gap[c]


@njit
def newton(Z, grid, rest, level, weights, res_weights, scales, tol, max_iter, max_step, tether):
    """Damped Newton on the spatial contact system at ``level``; ``Z`` updated in place.

    As :func:`solver.kernels.contact.newton`: weighted RMS norms, steps clipped to ``max_step``
    and halved until the residual falls; a fresh Jacobian at every iteration. ``tether``:
    see :func:`newton_system` (:data:`NO_TETHER`: none). Returns (converged, iterations, |F|,
    stable) — stable by the test of the untethered problem.
    """
    n = weights.shape[0]
    n_seg = Z.shape[0]
    F = np.empty(n)
    F_try = np.empty(n)
    J = np.empty((n, n))
    blocks = np.empty((n_seg, N_CTANGENT, N_CTANGENT))
    step = np.empty(n)
    rhs = np.empty(n)
    base = Z.copy()
    if not newton_system(Z, grid, rest, level, F, J, True, blocks, scales, tether):
        return False, 0, math.inf, False
    res = weighted_norm(F, res_weights)
    for it in range(max_iter + 1):
        if not math.isfinite(res):
            return False, it, math.inf, False
        if res <= tol:
            return True, it, res, stability_test(blocks)
        if it == max_iter:
            break
        for k in range(n):
            rhs[k] = F[k]
        if not banded_solve(J, rhs, step):
            return False, it, res, False
        norm = weighted_norm(step, weights)
        alpha = max_step / norm if norm > max_step else 1.0
        base[:, :] = Z
        res_try = math.inf
        for _ in range(8):
            retract(base, step, -alpha, Z)
            if newton_system(Z, grid, rest, level, F_try, J, False, blocks, scales, tether):
                res_try = weighted_norm(F_try, res_weights)
                if res_try < res:
                    break
            alpha *= 0.5
        if not res_try < res:
            Z[:, :] = base
            return False, it + 1, res, False
        if not newton_system(Z, grid, rest, level, F, J, True, blocks, scales, tether):
            return False, it + 1, math.inf, False
        res = weighted_norm(F, res_weights)
    return False, max_iter, res, stability_test(blocks)


@njit
def _at_level(t, a, b, now, tubes_i, tubes_f, secf, rest):
    """Interpolate the levels at ``t`` into ``now``, and its rest strains into ``rest``."""
    set_level(t, a, b, now)
    rest_strains_into(now[L_P], tubes_i, tubes_f, secf, rest)


@njit
def record(Z, grid, rest, level, rec):
    """Write the backbone of the node states ``Z`` at ``level`` into the record tuple ``rec``
    (:func:`new_record`, Σ(steps + 1) rows)."""
    end = np.empty(N_CSTATE)
    work = np.empty((8, N_CSTATE))
    for seg in range(grid[GS_SEGS].shape[0]):
        _segment(Z[seg], seg, grid, rest, level, end, work, True, rec)


@njit
def follow(Z, grid, tubes_i, tubes_f, a, b, weights, res_weights, scales, tol, max_iter,
           max_step, dt0, dt_min, rest, now):
    """Quasi-static ramp from level ``a`` to level ``b`` (tuples ``L_*``: pressures, loads
    per length (ns, 3), endplate weights (ns, 3), tip target (6,): n(L⁻), M_tip, obstacles
    (k, 8)), all linear in t, as :func:`solver.kernels.contact._path`: the start ``Z`` corrected
    by Newton first; a step is accepted if Newton converges on a stable state with a
    correction small against the secant prediction and no sample tunnelled through an
    obstacle (:func:`solver.kernels.obstacles.tunnels_3d`); otherwise it is halved, down to
    ``dt_min``. No fold is passed: the last accepted state is then returned, unconverged.

    Returns (converged, iterations, |residual|, stable, t): ``Z`` holds the returned state,
    ``now`` its level and ``rest`` its rest strains.
    """
    secf = grid[GS_SECF]
    steps = grid[GS_STEPS]
    n = weights.shape[0]
    rows = 0
    for i in range(steps.shape[0]):
        rows += steps[i] + 1
    rec_prev = new_record(rows)
    rec_new = new_record(rows)
    has_obstacles = a[L_DISCS].shape[0] > 0
    friction = a[L_FRICTION].shape[0] > 0
    start_friction(a, now)
    _at_level(0.0, a, b, now, tubes_i, tubes_f, secf, rest)
    total = 0
    ok, its, res, stable = newton(Z, grid, rest, now, weights, res_weights, scales, tol,
                                  max_iter, max_step, NO_TETHER)
    total += its
    if not (ok and stable):
        return False, total, res, stable, 0.0
    accepted = Z.copy()
    slope = np.zeros(n)
    guess = np.empty_like(Z)
    moved = np.empty(n)
    if has_obstacles:
        record(Z, grid, rest, now, rec_prev)
        if friction:  # the start, corrected, is the path's first accepted state
            accept_friction(now[L_FRICTION])
    t = 0.0
    dt = dt0
    while t < 1.0:
        t_new = min(1.0, t + dt)
        _at_level(t_new, a, b, now, tubes_i, tubes_f, secf, rest)
        retract(accepted, slope, t_new - t, guess)
        Z[:, :] = guess
        final = t_new >= 1.0
        ok, its, res, stable = newton(Z, grid, rest, now, weights, res_weights, scales,
                                      tol if final else 1e3 * tol, max_iter if final else 8,
                                      max_step, NO_TETHER)
        total += its
        _between(Z, guess, moved)
        corr = weighted_norm(moved, weights)
        _between(guess, accepted, moved)
        pred = weighted_norm(moved, weights)
        if ok and stable and (corr <= 0.05 + 0.5 * pred or dt <= dt_min):
            through = False
            if has_obstacles:
                record(Z, grid, rest, now, rec_new)
                through = tunnels_3d(rec_prev[1], rec_new[1], now[L_DISCS], TUNNEL_SLACK)
            if not through:
                if friction:
                    accept_friction(now[L_FRICTION])
                _between(Z, accepted, slope)
                for k in range(n):
                    slope[k] /= t_new - t
                accepted[:, :] = Z
                rec_prev, rec_new = rec_new, rec_prev
                t = t_new
                dt = min(2.0 * dt, 1.0)
                continue
        if dt > dt_min:
            dt *= 0.5
            continue
        break
    if t < 1.0:
        Z[:, :] = accepted
        _at_level(t, a, b, now, tubes_i, tubes_f, secf, rest)
        return False, total, res, stable, t
    return ok, total, res, stable, 1.0


@njit
def node_states(quat0, pos, rot, force, mom, rows, out):
    """Node states (K, N_CSTATE) from recorded samples at ``rows`` (K,): positions (N, 3),
    frames (N, 3, 3), internal force and moment (N, 3); node 0 takes the base orientation
    ``quat0`` (4,)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        for d in range(3):
            out[k, CS_R + d] = pos[r, d]
            out[k, CS_N + d] = force[r, d]
            out[k, CS_M + d] = mom[r, d]
        rotation_to_quaternion(rot[r], out[k, CS_Q:CS_Q + 4])
    for d in range(4):
        out[0, CS_Q + d] = quat0[d]
    for d in range(3):
        out[0, CS_R + d] = 0.0
