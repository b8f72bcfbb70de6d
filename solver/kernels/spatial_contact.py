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
R_end R_nextᵀ) and n(L⁻), m(L) against the tip loads. Each segment map's Jacobian in those
tangent coordinates is integrated along with the segment by the variational equations (one
pass: :func:`tangent_system`, which Newton uses) or formed by forward differences (13 passes:
:func:`newton_system`, kept for the critical mode of a snap); the block-banded Newton system
is solved by :func:`solver.kernels.spatial_shooting.banded_solve`.

Stability is the planar contact test in 3D: the Jacobi fields of the free tip, δ(r, φ)(L) = I
and δ(n, m)(L) = 0, carried back to the base through the inverse segment maps; no real
eigenvalue of their δ(r, φ) block may cross zero (:func:`stability_test`).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.contact import (
    FENCE_STEPS,
    LEAN_ITER,
    LEAN_JACOBIANS,
    LEAN_RATE,
    LEAN_TRIES,
    NEAR_SUBSTEPS,
    TUNNEL_SLACK,
    band_lu_solve,
    broyden_update,
    factor_band,
    jump_fence,
    set_level,
    start_friction,
    weighted_norm,
)
from solver.kernels.grid import section_needs
from solver.kernels.homotopy import halved
from solver.kernels.obstacles import (
    accept_friction,
    clearance_3d,
    contact_force_3d,
    contact_stiffness_3d,
    friction_impulse_3d,
    friction_untouched,
    nearest_surface_3d,
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
    MAX_ITER,
    MAX_STEP,
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
    TOL,
)
from solver.rod import (
    renormalise_quaternion,
    rest_strains_into,
    rotation_rows,
    rotation_to_quaternion,
    spatial_state_rhs,
    spatial_state_rk4_step,
    unit_quaternion,
)


def tether(k: float, anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ``tether`` argument of :func:`newton`: springs of ``k`` N/m tying each node after
    the base to ``anchors`` (K, 3) (m), as read-only copies: the type numba gives
    :data:`NO_TETHER` inside a kernel (a global array is a constant there), so that a call
    from Python and one from a kernel share one compiled :func:`newton`."""
    k_array, anchor_array = np.array([float(k)]), np.array(anchors, dtype=np.float64)
    k_array.flags.writeable = anchor_array.flags.writeable = False
    return k_array, anchor_array


NO_TETHER = tether(0.0, np.zeros((0, 3)))
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


@njit(inline="always")
def _tangent_rhs(y, dy, P, dP, ca, cg, ci, cj, obstacles):
    """dP = A·P for a tangent P (12, c) of the state ``y`` (N_CSTATE,), whose derivative
    ``dy`` is at hand, in the world tangent coordinates (δr, δφ, δn, δm): the variational
    equations of :func:`solver.rod.spatial_state_rhs`,

        δr' = δφ × r' + A_v (δn + n × δφ),   δφ' = A_u (δm + m × δφ),
        δn' = −K δr,                          δm' = n × δr' − r' × δn,

    A_v = R diag(cg, cg, ca) Rᵀ and A_u = R diag(ci, ci, cj) Rᵀ the world compliances and
    K = ∂f/∂r the penalty's stiffness (:func:`solver.kernels.obstacles.contact_stiffness_3d`).
    """
    w, x, yy, z = unit_quaternion(y)  # at CS_Q == SP_Q
    t0 = 2.0 * (x * z + w * yy)  # the third director d3 (R's third column)
    t1 = 2.0 * (yy * z - w * x)
    t2 = w * w - x * x - yy * yy + z * z
    p0 = dy[CS_R]
    p1 = dy[CS_R + 1]
    p2 = dy[CS_R + 2]
    n0 = y[CS_N]
    n1 = y[CS_N + 1]
    n2 = y[CS_N + 2]
    m0 = y[CS_M]
    m1 = y[CS_M + 1]
    m2 = y[CS_M + 2]
    k00, k01, k02, k11, k12, k22 = contact_stiffness_3d(y[CS_R], y[CS_R + 1], y[CS_R + 2],
                                                        obstacles)
    for j in range(P.shape[1]):
        f0 = P[CT_PHI, j]
        f1 = P[CT_PHI + 1, j]
        f2 = P[CT_PHI + 2, j]
        r0 = P[CT_R, j]
        r1 = P[CT_R + 1, j]
        r2 = P[CT_R + 2, j]
        dn0 = P[CT_N, j]
        dn1 = P[CT_N + 1, j]
        dn2 = P[CT_N + 2, j]
        a0 = dn0 + (n1 * f2 - n2 * f1)
        a1 = dn1 + (n2 * f0 - n0 * f2)
        a2 = dn2 + (n0 * f1 - n1 * f0)
        b0 = P[CT_M, j] + (m1 * f2 - m2 * f1)
        b1 = P[CT_M + 1, j] + (m2 * f0 - m0 * f2)
        b2 = P[CT_M + 2, j] + (m0 * f1 - m1 * f0)
        da = (ca - cg) * (t0 * a0 + t1 * a1 + t2 * a2)
        db = (cj - ci) * (t0 * b0 + t1 * b1 + t2 * b2)
        d0 = (f1 * p2 - f2 * p1) + cg * a0 + da * t0
        d1 = (f2 * p0 - f0 * p2) + cg * a1 + da * t1
        d2 = (f0 * p1 - f1 * p0) + cg * a2 + da * t2
        dP[CT_R, j] = d0
        dP[CT_R + 1, j] = d1
        dP[CT_R + 2, j] = d2
        dP[CT_PHI, j] = ci * b0 + db * t0
        dP[CT_PHI + 1, j] = ci * b1 + db * t1
        dP[CT_PHI + 2, j] = ci * b2 + db * t2
        dP[CT_N, j] = -(k00 * r0 + k01 * r1 + k02 * r2)
        dP[CT_N + 1, j] = -(k01 * r0 + k11 * r1 + k12 * r2)
        dP[CT_N + 2, j] = -(k02 * r0 + k12 * r1 + k22 * r2)
        dP[CT_M, j] = (n1 * d2 - n2 * d1) - (p1 * dn2 - p2 * dn1)
        dP[CT_M + 1, j] = (n2 * d0 - n0 * d2) - (p2 * dn0 - p0 * dn2)
        dP[CT_M + 2, j] = (n0 * d1 - n1 * d0) - (p0 * dn1 - p1 * dn0)


@njit(inline="always")
def _rk4_tangent(y, P, h, work, tw, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles):
    """:func:`solver.rod.spatial_state_rk4_step` on the state ``y`` (the same operations:
    the same numbers) and, through the same stages, on its tangent ``P`` (12, c)
    (:func:`_tangent_rhs`), in place. ``work`` (≥5, N_CSTATE) and ``tw`` (≥5, 12, c)
    scratch; ``tw[0]`` keeps the first stage, the tangent's slope at the start."""
    k1 = work[0]
    k2 = work[1]
    k3 = work[2]
    k4 = work[3]
    tmp = work[4]
    K1 = tw[0]
    K2 = tw[1]
    K3 = tw[2]
    K4 = tw[3]
    Q = tw[4]
    c = P.shape[1]
    spatial_state_rhs(y, k1, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    _tangent_rhs(y, k1, P, K1, ca, cg, ci, cj, obstacles)
    for d in range(N_CSTATE):
        tmp[d] = y[d] + 0.5 * h * k1[d]
    for d in range(N_CTANGENT):
        for e in range(c):
            Q[d, e] = P[d, e] + 0.5 * h * K1[d, e]
    spatial_state_rhs(tmp, k2, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    _tangent_rhs(tmp, k2, Q, K2, ca, cg, ci, cj, obstacles)
    for d in range(N_CSTATE):
        tmp[d] = y[d] + 0.5 * h * k2[d]
    for d in range(N_CTANGENT):
        for e in range(c):
            Q[d, e] = P[d, e] + 0.5 * h * K2[d, e]
    spatial_state_rhs(tmp, k3, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    _tangent_rhs(tmp, k3, Q, K3, ca, cg, ci, cj, obstacles)
    for d in range(N_CSTATE):
        tmp[d] = y[d] + h * k3[d]
    for d in range(N_CTANGENT):
        for e in range(c):
            Q[d, e] = P[d, e] + h * K3[d, e]
    spatial_state_rhs(tmp, k4, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    _tangent_rhs(tmp, k4, Q, K4, ca, cg, ci, cj, obstacles)
    for d in range(N_CSTATE):
        y[d] += (h / 6.0) * (k1[d] + 2.0 * k2[d] + 2.0 * k3[d] + k4[d])
    for d in range(N_CTANGENT):
        for e in range(c):
            P[d, e] += (h / 6.0) * (K1[d, e] + 2.0 * K2[d, e] + 2.0 * K3[d, e] + K4[d, e])
    renormalise_quaternion(y)


@njit
def _segment(z, seg, grid, rest, level, out, work, record, rec, phi, tw):
    """Integrate segment ``seg`` from the node state ``z`` (N_CSTATE,) into ``out``.

    Near an obstacle each RK4 step is refined into NEAR_SUBSTEPS substeps and blended with
    the whole step by a smoothstep of the clearance, as in :func:`solver.kernels.contact._integrate`,
    friction acting at the refinement's nodes as it does there
    (:func:`solver.kernels.obstacles.friction_impulse_3d`, its consistent tangent entering
    ``phi``). At a section end (not the tip) the endplate's weight is taken off n. With
    ``record``, the samples go to the record tuple ``rec``. ``work`` (8, N_CSTATE) scratch.
    With ``phi`` (12, 12) (not empty), the segment map's Jacobian in the tangent coordinates
    of its start and end (``CT_*``) is integrated into it alongside, by the variational
    equations through the same RK4 stages (:func:`_rk4_tangent`) and the blend's own
    derivative (``tw`` (8, 12, 12) scratch); the state is the same either way.
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
    tangent = phi.shape[0] > 0
    stiff = np.empty((3 if tangent and friction else 0, 3))
    fine_phi = tw[6] if tangent else phi  # (the refinement's tangent; unused without one)
    for d in range(N_CSTATE):
        out[d] = z[d]
    if tangent:
        for d in range(N_CTANGENT):
            for e in range(N_CTANGENT):
                phi[d, e] = 1.0 if d == e else 0.0
    for j in range(first, first + segs[seg, SEG_STEPS]):
        if record:
            _record_row(out, s0 + j * h, rec, segs[seg, SEG_ROW0] + j, ca, cg, ci, cj, u1r, u2r,
                        v3r, obstacles)
        for d in range(N_CSTATE):
            start[d] = out[d]
        if tangent:
            tw[5, :, :] = phi
            _rk4_tangent(out, phi, h, work, tw, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
        else:
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
        if tangent and clear > 0.0:
            # d(clear)/d(start) along the tangent: û·δr − h·(r'/|r'|)·δr', δr' the first
            # stage's (tw[0]); the blend's weight moves with it.
            _, u0, u1, u2 = nearest_surface_3d(start[CS_R], start[CS_R + 1], start[CS_R + 2],
                                               obstacles)
            scale = h / speed if speed > 0.0 else 0.0
            for e in range(N_CTANGENT):
                tw[7, 0, e] = (u0 * tw[5, CT_R, e] + u1 * tw[5, CT_R + 1, e]
                               + u2 * tw[5, CT_R + 2, e]
                               - scale * (work[0, CS_R] * tw[0, CT_R, e]
                                          + work[0, CS_R + 1] * tw[0, CT_R + 1, e]
                                          + work[0, CS_R + 2] * tw[0, CT_R + 2, e]))
        for d in range(N_CSTATE):
            fine[d] = start[d]
        if tangent:
            tw[6, :, :] = tw[5]
        for sub in range(NEAR_SUBSTEPS):
            if friction:
                _friction_node(fine, fine_phi, stiff, level, at, sub,
                               (0.5 if sub == 0 else 1.0) * h_sub, record)
            if tangent:
                _rk4_tangent(fine, tw[6], h_sub, work, tw, ca, cg, ci, cj, u1r, u2r, v3r, q,
                             obstacles)
            else:
                spatial_state_rk4_step(fine, h_sub, work, ca, cg, ci, cj, u1r, u2r, v3r, q,
                                       obstacles)
        if friction:
            _friction_node(fine, fine_phi, stiff, level, at, NEAR_SUBSTEPS, 0.5 * h_sub,
                           record)
            if record:
                _friction_row(fs, at, 0, h_sub, rec, at)
        x = 1.0 - clear / h if clear > 0.0 else 1.0
        weight = x * x * (3.0 - 2.0 * x)
        if tangent:
            dw = -6.0 * x * (1.0 - x) / h if clear > 0.0 else 0.0
            gap = tw[7, 1]
            _difference(fine, out, gap)
            for d in range(N_CTANGENT):
                for e in range(N_CTANGENT):
                    phi[d, e] = weight * tw[6, d, e] + (1.0 - weight) * phi[d, e]
                    if dw != 0.0:
                        phi[d, e] += gap[d] * dw * tw[7, 0, e]
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
def _friction_node(y, phi, stiff, level, row, node, weight, record):
    """Apply the friction impulse of sample (row, node), its share ``weight`` of the length,
    to the contact state ``y`` as a point load: n⁺ = n⁻ − F; with ``stiff`` (3, 3) scratch
    (not empty), to its tangent ``phi`` (12, 12) too: δn⁺ = δn⁻ − (∂F/∂r)·δr."""
    if stiff.shape[0]:
        stiff[:, :] = 0.0
    fx, fy, fz = friction_impulse_3d(y[CS_R], y[CS_R + 1], y[CS_R + 2], level[L_DISCS],
                                     level[L_MU], level[L_FRICTION], row, node, weight, record,
                                     stiff)
    y[CS_N] -= fx
    y[CS_N + 1] -= fy
    y[CS_N + 2] -= fz
    if stiff.shape[0]:
        for e in range(N_CTANGENT):
            r0 = phi[CT_R, e]
            r1 = phi[CT_R + 1, e]
            r2 = phi[CT_R + 2, e]
            for d in range(3):
                phi[CT_N + d, e] -= stiff[d, 0] * r0 + stiff[d, 1] * r1 + stiff[d, 2] * r2


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
    (K, 12, 12) in tangent coordinates, by forward differences. ``scales`` (12,) the tangent
    coordinates' weights (the differences' steps are FD_STEP times them). Row order per
    segment: the jumps of r, rotation, n and m; at the tip n(L⁻) and m(L) less the level's
    target. ``tether``: (k (1,), anchors (K, 3)): with k > 0, every node after the base is
    held to its anchor by a spring of k N/m (a point load −k(r − anchor), see
    :func:`relax`). Returns False where a state is not finite."""
    return _system(Z, grid, rest, level, F, J, JAC_DIFFERENCES if want_jac else JAC_NONE,
                   blocks, scales, tether)


@njit  # the tests call it: compiled on its own anyway (solver.jit)
def tangent_system(Z, grid, rest, level, F, J, blocks):
    """:func:`newton_system` (untethered) with the segment maps' Jacobians integrated along
    with the segments by the variational equations (:func:`_segment`) instead of forward
    differences: one pass where differences take thirteen. The residual is the same; the
    Jacobian agrees with the differences' to the RK4 truncation of the variational
    equations (docs/design.md §9)."""
    return _system(Z, grid, rest, level, F, J, JAC_VARIATIONAL, blocks, np.empty(0), NO_TETHER)


# The Jacobian :func:`_system` forms: none, by forward differences, by the variational
# equations.
JAC_NONE, JAC_DIFFERENCES, JAC_VARIATIONAL = 0, 1, 2


@njit
def _system(Z, grid, rest, level, F, J, jacobian, blocks, scales, tether):
    """:func:`newton_system` and :func:`tangent_system`: ``jacobian`` one of ``JAC_*``."""
    segs = grid[GS_SEGS]
    n_seg = segs.shape[0]
    target = level[L_TARGET]
    end = np.empty(N_CSTATE)
    moved = np.empty(N_CSTATE)
    moved_end = np.empty(N_CSTATE)
    gap = np.empty(N_CTANGENT)
    work = np.empty((8, N_CSTATE))
    rec = new_record(1)
    no_phi = np.empty((0, N_CTANGENT))
    no_tw = np.empty((0, N_CTANGENT, N_CTANGENT))
    want_jac = jacobian != JAC_NONE
    variational = jacobian == JAC_VARIATIONAL
    tw = np.empty((8, N_CTANGENT, N_CTANGENT)) if variational else no_tw
    if want_jac:
        J[:, :] = 0.0
    for seg in range(n_seg):
        _segment(Z[seg], seg, grid, rest, level, end, work, False, rec,
                 blocks[seg] if variational else no_phi, tw)
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
            if not variational:
                step = FD_STEP * scales[c]
                _nudge(Z[seg], c, step, moved)
                _segment(moved, seg, grid, rest, level, moved_end, work, False, rec, no_phi,
                         no_tw)
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

    Over a segment clear of contact the block stays near I, and Gershgorin's discs of it
    (:func:`right_of_zero`) already put every eigenvalue right of zero: the eigenvalues are
    computed (LAPACK, three quarters of the test's time) only where they do not.
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
        if not right_of_zero(top):
            for value in np.linalg.eigvals(top.astype(np.complex128)):
                if value.real <= 0.0 and abs(value.imag) <= 1e-12 * (abs(value.real) + 1.0):
                    return False
        fields = fields @ np.linalg.inv(top)
    return True


# Margin of Gershgorin's test (:func:`right_of_zero`) relative to the matrix's norm: far
# above the backward error of an eigenvalue solver (a few machine epsilons of the norm),
# so that where the test holds, computed eigenvalues are right of zero too.
GERSHGORIN_MARGIN = 1e-9


@njit
def right_of_zero(a):
    """True when Gershgorin's theorem puts every eigenvalue of the square ``a`` right of
    zero: each row's disc, centre a_ii and radius Σ_{j≠i} |a_ij|, lies right of
    GERSHGORIN_MARGIN·‖a‖∞ (or each column's does). False says nothing."""
    n = a.shape[0]
    norm = 0.0
    for i in range(n):
        row = 0.0
        for j in range(n):
            row += abs(a[i, j])
        norm = max(norm, row)
    margin = GERSHGORIN_MARGIN * norm
    rows = True
    cols = True
    for i in range(n):
        row = 0.0
        col = 0.0
        for j in range(n):
            if j != i:
                row += abs(a[i, j])
                col += abs(a[j, i])
        rows = rows and a[i, i] - row > margin
        cols = cols and a[i, i] - col > margin
    return rows or cols


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
def between(a, b, out):
    """The unknowns' vector (n,) taking node states ``b`` to ``a``."""
    gap = np.empty(N_CTANGENT)
    for k in range(a.shape[0]):
        _difference(a[k], b[k], gap)
        for c in range(N_CTANGENT):
            col = _column(k, c)
            if col >= 0:
                out[col] = gap[c]


def newton(Z, grid, rest, level, weights, res_weights, scales, tol, max_iter, max_step, tether):
    """Damped Newton on the spatial contact system at ``level``; ``Z`` updated in place.

    As :func:`solver.kernels.contact.newton`: weighted RMS norms, steps clipped to ``max_step``
    and halved until the residual falls (at most 7 times: where it never falls, the last,
    smallest trial is taken, as the planar Newton takes it); a fresh Jacobian at every
    iteration, by the variational equations (:func:`tangent_system`'s: one pass where forward
    differences take thirteen, the two agreeing to the RK4 truncation; a tether's springs
    enter the node rows, outside the segment maps). ``tether``:
    see :func:`newton_system` (:data:`NO_TETHER`: none). Returns (converged, iterations, |F|,
    stable) — stable by the test of the untethered problem.
    """
    n = weights.shape[0]
    return newton_into(Z, grid, rest, level, weights, res_weights, scales, tol, max_iter,
                       max_step, tether, np.empty(n), np.empty((n, n)),
                       np.empty((Z.shape[0], N_CTANGENT, N_CTANGENT)), JAC_VARIATIONAL, True, Z,
                       math.inf, math.inf)


def probe(Z, grid, rest, level, weights, res_weights, scales, tol, max_iter, max_step, tether):
    """:func:`newton` from a guessed start (a snap's push along the critical mode), which
    gives up where no trial of the line search lowers the residual: there the guess lies in
    no basin worth following, and going on would spend every iteration's Jacobian to find
    that out (a 3D wrap's snap took 4× as long). Same returns."""
    n = weights.shape[0]
    return newton_into(Z, grid, rest, level, weights, res_weights, scales, tol, max_iter,
                       max_step, tether, np.empty(n), np.empty((n, n)),
                       np.empty((Z.shape[0], N_CTANGENT, N_CTANGENT)), JAC_VARIATIONAL, False, Z,
                       math.inf, math.inf)


@njit
def newton_into(Z, grid, rest, level, weights, res_weights, scales, tol, max_iter, max_step,
                tether, F, J, blocks, jacobian, past_kinks, fence_center, fence, plateau):
    """:func:`newton` with its residual ``F`` (n,), Jacobian ``J`` (n, n) and segment maps
    ``blocks`` (K, 12, 12) in the caller's arrays — where it converges they hold those of
    the returned state — and its Jacobian formed as ``jacobian`` says (``JAC_DIFFERENCES``
    or ``JAC_VARIATIONAL``: :func:`_system`). ``past_kinks``: where no trial
    lowers the residual, go on from the smallest (:func:`newton`) rather than give up
    (:func:`probe`). ``fence_center`` (K, N_CSTATE) and ``fence``: give up (unconverged, ``Z``
    at the iterate) where an iterate lies farther than ``fence`` (weighted RMS) from the
    centre by more than twice its Newton step — a caller that refuses a root beyond the fence
    would refuse this one (:data:`FENCE_STEPS`); ``math.inf``: no fence. ``plateau``: give up,
    too, where a Newton step is longer than ``plateau`` fences — the iterate sits on a fold's
    plateau, where the linear model's root is no root the caller would take (the lean step's
    :data:`PLATEAU_FENCES`; ``math.inf``: never).

    With the variational Jacobian, an iteration's first trial is formed with its Jacobian in
    one pass where the iteration before accepted its first trial (and at the first
    iteration): the Jacobian pass at the accepted trial would otherwise follow its residual
    pass, at five times a residual pass's cost, and a pass computes the residual the same way
    with or without the Jacobian (the same numbers). A refused first trial then costs a
    Jacobian pass instead of a residual pass, and the line search goes on with residual passes
    as before: every iterate is the textbook one. (First trials were accepted at 91 % of the
    iterations of the 3D wraps' lean steps, 51 % of a fold's approach: docs/design.md §10.1.
    By differences a Jacobian costs thirteen residual passes: never formed ahead.)"""
    n = weights.shape[0]
    F_try = np.empty(n)
    step = np.empty(n)
    rhs = np.empty(n)
    base = Z.copy()
    if not _system(Z, grid, rest, level, F, J, jacobian, blocks, scales, tether):
        return False, 0, math.inf, False
    res = weighted_norm(F, res_weights)
    ahead = jacobian == JAC_VARIATIONAL  # first trials may be formed with their Jacobians
    first_taken = ahead  # whether the last iteration's first trial was accepted
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
        if fence < math.inf:
            between(Z, fence_center, rhs)
            if weighted_norm(rhs, weights) - FENCE_STEPS * norm > fence or norm > plateau * fence:
                return False, it, res, False
        alpha = max_step / norm if norm > max_step else 1.0
        base[:, :] = Z
        for trial in range(8):
            retract(base, step, -alpha, Z)
            res_try = math.inf
            formed = trial == 0 and first_taken  # F_try, J and blocks: this trial's
            if _system(Z, grid, rest, level, F_try, J, jacobian if formed else JAC_NONE, blocks,
                       scales, tether):
                res_try = weighted_norm(F_try, res_weights)
                if res_try < res:
                    break
            alpha *= 0.5
        first_taken = ahead and trial == 0 and res_try < res
        # No trial lowered the residual: the Jacobian holds one side of a kink of the map
        # (forward differences may straddle it) — the penalty's at a contact's edge, the
        # return mapping's at a slipping sample — and its direction is no descent direction
        # there. Newton goes on from the smallest trial with a Jacobian formed on its side of
        # the kink; stopping here stalled the 3D capstan at a residual of 1e-7 and snapped it
        # (docs/design.md §9.1).
        if not math.isfinite(res_try) or not (past_kinks or res_try < res):
            Z[:, :] = base
            return False, it + 1, res, False
        if formed:
            F[:] = F_try
        elif not _system(Z, grid, rest, level, F, J, jacobian, blocks, scales, tether):
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
        _segment(Z[seg], seg, grid, rest, level, end, work, True, rec, np.empty((0, N_CTANGENT)),
                 np.empty((0, N_CTANGENT, N_CTANGENT)))


# Newton iterations the start of a path with friction may take to be corrected. A warm start
# solved on another contact layout (the grid refines as a belt tightens on a drum) has its
# anchors resampled onto this one, so it is no exact equilibrium of them, and correcting it is
# Newton on the return mapping's kink (a slipping sample sits on the cone's edge), which crawls:
# 25 iterations on the 3D capstan at 180°, μ = 1, where the default 12 ended the path at its
# start and the solve took that for a fold and snapped, dropping the anchors (docs/design.md
# §9.1). Where 12 sufficed the iterates are the same.
FRICTION_START_ITER = 40


# The ramp parameter's step of the forward difference ∂F/∂t in :func:`initial_tangent`; and
# the first-order move (weighted RMS) from which :func:`follow` does not try a first step:
# twice the 0.05 its correction may reach. On 45 general steps of the 3D wraps the accepted
# first steps' predicted moves were at most 0.051 (within 30 % of their moves); 207 of the 259
# refused tries predicted more than 0.1.
TANGENT_DT = 1e-4
FIRST_MOVE = 0.1


@njit  # the tests call it: compiled on its own anyway (solver.jit)
def initial_tangent(Z, grid, tubes_i, tubes_f, a, b, rest, now, scales, F, J, slope):
    """The path's tangent dZ/dt = −J⁻¹ ∂F/∂t (n,) at its start ``Z``, an equilibrium of level
    ``a`` on the ramp to ``b`` (:func:`follow`), into ``slope``: ``F`` (n,) and ``J`` (n, n)
    the residual and Jacobian at ``Z`` (J is destroyed), ∂F/∂t by a forward difference of
    TANGENT_DT; zero where it is not finite. ``now`` and ``rest`` end at level ``a``."""
    secf = grid[GS_SECF]
    n = F.shape[0]
    rate = np.empty(n)
    _at_level(TANGENT_DT, a, b, now, tubes_i, tubes_f, secf, rest)
    finite = newton_system(Z, grid, rest, now, rate, np.empty((0, 0)), False,
                           np.empty((0, N_CTANGENT, N_CTANGENT)), scales, NO_TETHER)
    _at_level(0.0, a, b, now, tubes_i, tubes_f, secf, rest)
    for k in range(n):
        rate[k] = -(rate[k] - F[k]) / TANGENT_DT
    if not (finite and np.all(np.isfinite(rate)) and banded_solve(J, rate, slope)
            and np.all(np.isfinite(slope))):
        slope[:] = 0.0


@njit
def follow(Z, grid, tubes_i, tubes_f, a, b, weights, res_weights, scales, tol, max_iter,
           max_step, dt0, dt_min, rest, now):
    """Quasi-static ramp from level ``a`` to level ``b`` (tuples ``L_*``: pressures, loads
    per length (ns, 3), endplate weights (ns, 3), tip target (6,): n(L⁻), M_tip, obstacles
    (k, 8)), all linear in t, as :func:`solver.kernels.contact._path`: the start ``Z`` corrected
    by Newton first; a step is accepted if Newton converges on a stable state with a
    correction small against the secant prediction and no sample tunnelled through an
    obstacle (:func:`solver.kernels.obstacles.tunnels_3d`); otherwise it is halved, down to
    ``dt_min`` (a try short of the last level whose line search stalls is given up there,
    without friction). The first steps whose move the path's tangent predicts beyond what a
    first step may move are not tried (:data:`FIRST_MOVE`). No fold is passed: the last
    accepted state is then returned, unconverged.

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
    F = np.empty(n)
    J = np.empty((n, n))
    blocks = np.empty((Z.shape[0], N_CTANGENT, N_CTANGENT))
    ok, total, res, stable = newton_into(
        Z, grid, rest, now, weights, res_weights, scales, tol,
        max(max_iter, FRICTION_START_ITER) if friction else max_iter, max_step, NO_TETHER, F, J,
        blocks, JAC_VARIATIONAL, True, Z, math.inf, math.inf)
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
    # The first step is judged against a zero prediction, so it is accepted only where the
    # arm moves less than 0.05 (weighted RMS); the halving that finds it converged a try at
    # each larger step first, every one refused (six or seven a ramp on the general steps of
    # the 3D wraps, a quarter of the continuation's Newton iterations). The path's tangent at the start
    # (:func:`initial_tangent`, one residual pass) predicts that move to first order: the
    # halving skips the steps whose predicted move is FIRST_MOVE or more, where a try would
    # be accepted only if the path bent back by half. The steps tried are the halving's
    # (the same t-grid); the prediction stays zero, as with the tangent as predictor a large
    # first step's lenient bound (0.05 + half the predicted move) let a path jump branches.
    tangent = np.empty(n)
    initial_tangent(Z, grid, tubes_i, tubes_f, a, b, rest, now, scales, F, J, tangent)
    total += 1
    reach = weighted_norm(tangent, weights)
    dt = dt0
    while dt > dt_min and reach * min(dt, 1.0) >= FIRST_MOVE:
        dt = halved(dt, min(dt, 1.0), dt_min)
    t = 0.0
    while t < 1.0:
        t_new = min(1.0, t + dt)
        _at_level(t_new, a, b, now, tubes_i, tubes_f, secf, rest)
        retract(accepted, slope, t_new - t, guess)
        Z[:, :] = guess
        final = t_new >= 1.0
        # A try is refused beyond 0.05 + half the predicted move from its prediction (a
        # branch jump), except at the smallest step: its Newton gives up there (FENCE_STEPS).
        between(guess, accepted, moved)
        fence = jump_fence(weighted_norm(moved, weights)) if dt > dt_min else math.inf
        # A try whose line search stalls is given up there and the step halved, as the
        # planar path's are (solver.kernels.contact._path): on 45 general steps of the 3D
        # wraps no stalled try went on to be accepted (every landing the same to the last
        # bit), and a stalled iteration spends eight residual passes. Not with friction, nor
        # at the last level: there Newton must go past the kinks (the 3D capstan,
        # docs/design.md §9.1).
        ok, its, res, stable = newton_into(
            Z, grid, rest, now, weights, res_weights, scales, tol if final else 1e3 * tol,
            max_iter if final else 8, max_step, NO_TETHER, F, J, blocks, JAC_VARIATIONAL,
            friction or final, guess, fence, math.inf)
        total += its
        between(Z, guess, moved)
        if ok and stable and weighted_norm(moved, weights) <= fence:
            through = False
            if has_obstacles:
                record(Z, grid, rest, now, rec_new)
                through = tunnels_3d(rec_prev[1], rec_new[1], now[L_DISCS], TUNNEL_SLACK)
            if not through:
                if friction:
                    accept_friction(now[L_FRICTION])
                between(Z, accepted, slope)
                for k in range(n):
                    slope[k] /= t_new - t
                accepted[:, :] = Z
                rec_prev, rec_new = rec_new, rec_prev
                t = t_new
                dt = min(2.0 * dt, 1.0)
                continue
        if dt > dt_min:
            dt = halved(dt, t_new - t, dt_min)
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


@njit
def nodes_from_record(s, pos, rot, force, mom, ends, arcs, sections, quat0, out):
    """Node states ``out`` (K, N_CSTATE) from a recorded spatial backbone at another
    resolution: positions, forces and moments interpolated linearly in arc length within
    each section (so that a node at a section start takes the force past the endplate),
    orientations by normalised linear interpolation of sign-aligned quaternions; node 0 at
    the clamped base (orientation ``quat0`` (4,)).

    Args:
        s: (N,) the samples' arc lengths (m). pos, force, mom: (N, 3) positions, internal
            force and moment (world frame). rot: (N, 3, 3) frames. ends: (ns,) the samples'
            rows at the section ends. arcs: (K,) the nodes' arc lengths (m). sections: (K,)
            their sections.
    """
    n = s.shape[0]
    quats = np.empty((n, 4))
    for k in range(n):
        rotation_to_quaternion(rot[k], quats[k])
        if k and (quats[k, 0] * quats[k - 1, 0] + quats[k, 1] * quats[k - 1, 1]
                  + quats[k, 2] * quats[k - 1, 2] + quats[k, 3] * quats[k - 1, 3]) < 0.0:
            for d in range(4):
                quats[k, d] = -quats[k, d]
    for k in range(arcs.shape[0]):
        i = sections[k]
        first = 0 if i == 0 else ends[i - 1] + 1
        part = s[first:ends[i] + 1]
        for d in range(3):
            out[k, CS_R + d] = np.interp(arcs[k], part, pos[first:ends[i] + 1, d])
            out[k, CS_N + d] = np.interp(arcs[k], part, force[first:ends[i] + 1, d])
            out[k, CS_M + d] = np.interp(arcs[k], part, mom[first:ends[i] + 1, d])
        for d in range(4):
            out[k, CS_Q + d] = np.interp(arcs[k], part, quats[first:ends[i] + 1, d])
        norm = math.sqrt(out[k, CS_Q] ** 2 + out[k, CS_Q + 1] ** 2 + out[k, CS_Q + 2] ** 2
                         + out[k, CS_Q + 3] ** 2)
        for d in range(4):
            out[k, CS_Q + d] /= norm
    for d in range(3):
        out[0, CS_R + d] = 0.0
    for d in range(4):
        out[0, CS_Q + d] = quat0[d]


# The band of the shooting Jacobian: the rows of segment k's jumps couple the 12 tangent
# coordinates of its start node (6 at the base) and of the next one, 17 sub- and
# super-diagonals; stored as :func:`solver.kernels.contact.factor_band` takes it.
BAND = 17
BAND_ROWS = 3 * BAND + 1


@njit
def new_factors(n):
    """Scratch for the factored Jacobian of a lean state (:func:`factor_state`) of ``n``
    unknowns: band factors (BAND_ROWS, n) and their pivots (n,)."""
    return np.empty((BAND_ROWS, n)), np.empty(n, dtype=np.int64)


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def factor_state(Z, grid, rest, level, F, J, blocks, rec, factors):
    """One Jacobian pass at the node states ``Z`` (``level``, ``rest`` its rest strains):
    the residual into ``F``, the Jacobian into ``J`` (n, n) and the segment maps into
    ``blocks`` (:func:`tangent_system`), then :func:`factor_jacobian`. Returns (regular,
    stable): whether the Jacobian is finite and regular, and the stability test of
    ``blocks``."""
    if not tangent_system(Z, grid, rest, level, F, J, blocks):
        return False, False
    return factor_jacobian(Z, grid, rest, level, J, rec, factors), stability_test(blocks)


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def factor_jacobian(Z, grid, rest, level, J, rec, factors):
    """The backbone of the node states ``Z`` into the record tuple ``rec``
    (:func:`record`), and the band LU of their Jacobian ``J`` (n, n) into ``factors``
    (:func:`new_factors`), which the next step from this state predicts and corrects with.
    Returns whether ``J`` is regular. (A state Newton converged on has its stability test
    from Newton: :func:`newton_into`.)"""
    record(Z, grid, rest, level, rec)
    lu, piv = factors
    n = J.shape[0]
    lu[:, :] = 0.0
    for j in range(n):
        for i in range(max(0, j - BAND), min(n, j + BAND + 1)):
            lu[2 * BAND + i - j, j] = J[i, j]
    return factor_band(lu, piv)


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def broyden(Z, grid, rest, level, F, scales, res_weights, tol, factors, res):
    """Quasi-Newton corrections of the node states ``Z`` at ``level`` from the residual
    ``F`` (its weighted norm ``res``): the first step by the factored Jacobian
    (``factors``, of a nearby state), later ones by Broyden's updates of its inverse
    (Kelley's form, a factored solve and a residual pass each), while the residual falls
    at least LEAN_RATE-fold a pass. ``Z`` ends at the last iterate that lowered the
    residual, ``F`` holds its residual.

    Returns:
        (converged, residual, passes, first): ``first`` (n,) the first step (the
        prediction of a lean step).
    """
    lu, piv = factors
    n = F.shape[0]
    steps = np.empty((LEAN_ITER + 1, n))
    norms = np.empty(LEAN_ITER + 1)
    z = np.empty(n)
    base = Z.copy()
    trial = np.empty(n)
    no_jac = np.empty((0, 0))
    no_blocks = np.empty((0, N_CTANGENT, N_CTANGENT))
    for i in range(n):
        steps[0, i] = -F[i]
    band_lu_solve(lu, piv, steps[0])
    first = steps[0].copy()
    passes = 0
    k = 0
    while True:
        norms[k] = 0.0
        for i in range(n):
            norms[k] += steps[k, i] * steps[k, i]
        retract(base, steps[k], 1.0, Z)
        finite = newton_system(Z, grid, rest, level, trial, no_jac, False, no_blocks, scales,
                               NO_TETHER)
        passes += 1
        r = weighted_norm(trial, res_weights) if finite else math.inf
        if not r < res:
            Z[:, :] = base  # back to the last iterate that lowered the residual
            return False, res, passes, first
        for i in range(n):
            F[i] = trial[i]
        base[:, :] = Z
        if r <= tol:
            return True, r, passes, first
        if not r <= LEAN_RATE * res or k == LEAN_ITER - 1 or norms[k] == 0.0:
            return False, r, passes, first
        res = r
        for i in range(n):
            z[i] = -F[i]
        band_lu_solve(lu, piv, z)
        if not broyden_update(steps, norms, k, z):
            return False, res, passes, first
        k += 1


PLATEAU_FENCES = 3.0
"""A try of the lean step gives up where a Newton step is longer than this many fences (its
branch-jump bound round the prediction): the iterate sits on a fold's plateau, where Newton's
steps point far off and shrink little, and the lean step's remedy, a halved step, is cheaper
than Newton's remaining iterations there. Of 25 lean attempts before general 3D steps (the
3D wraps' random steps, docs/design.md §10.1), 6 reached t = 1 within the Jacobian budget
without it; 11, 12, 9 and 9 with 2, 3, 5 and 10 fences (the landings, checked at 2, 3 and 10,
within 4.5e-10 m of the general path's state). With 3 fences the 81 lean steps of the control
landed where they had (with 2, two moved by 3e-11 m; with 1, 61 moved and the Jacobians rose
by a third)."""


@njit
def lean_step(Z, grid, tubes, level, p_new, params, work, factors, records, check):
    """A warm step of the 3D contact stepper in one kernel call: from the equilibrium ``Z``
    at ``level`` to the pressures ``p_new``, the rest of the level (loads, obstacles)
    unchanged — :func:`solver.kernels.contact.lean_step` in 3D, where a step of an
    environment's random actions may move the arm across half its workspace.

    The quasi-static path is followed as :func:`follow` follows it — pressures linear in t,
    a step accepted when converged (``tol``; a thousand times that short of the end),
    stable, close to its prediction (within ``0.05 + 0.5·|prediction|``, weighted RMS) and
    no sample tunnelled through an obstacle, halved otherwise — but each step is predicted
    to first order by the factored Jacobian of the last accepted state (kept from the step
    before for the first) and corrected by Broyden's updates of it (:func:`broyden`: a
    residual pass and a factored solve per correction), with damped Newton (:func:`newton`)
    only where those stall (where the arm meets the obstacle, the penalty's kink). Each
    accepted state gets its Jacobian, stability test and backbone from one pass (or from
    Newton's last iterate: :func:`factor_jacobian`), and the last must be resolved by the
    RK4 grid (:func:`solver.kernels.grid.section_needs`, the general path's check). Past
    LEAN_TRIES steps or LEAN_JACOBIANS Jacobians, or on anything else, every input is left
    untouched and ``ok`` is False: the caller's general path (continuation, snaps,
    relaxation, refinement) takes the step.

    Args:
        Z: (K, N_CSTATE) the nodes of the current equilibrium; the new ones on success.
        grid: the layout tuple (``GS_*``). tubes: (tubes_i, tubes_f).
        level: the level tuple (``L_*``) of ``Z``; its pressures become ``p_new`` on success,
            and its friction samples (if any) the path's, each accepted step accepting its
            anchors as :func:`follow`'s do (:func:`solver.kernels.obstacles.accept_friction`;
            the steps work on a copy, so a refused lean step leaves them untouched).
        p_new: (n_channels,) the target pressures (Pa).
        params: (N_PARAMS,) numeric parameters (TOL, MAX_ITER, MAX_STEP are used).
        work: (rest (3, ns), weights (n,), res_weights (n,), scales (12,)): scratch for the
            rest strains, the norms' weights and the tangent coordinates' scales.
        factors: the factored Jacobian at ``Z`` (:func:`factor_state`); the new state's on
            success.
        records: (rec, new): record tuples (:func:`new_record`), the backbone of ``Z`` and
            scratch that receives the new state's on success.
        check: (q (ns,) |distributed load| (N/m), ends (ns,) the records' section-end rows)
            for the grid check.

    Returns:
        (ok, stable, passes, residual): passes counts the residual passes and Jacobians.
    """
    rest, weights, res_weights, scales = work
    rec, new = records
    tol = params[TOL]
    n = weights.shape[0]
    secf = grid[GS_SECF]
    obstacles = level[L_DISCS]
    p_old = level[L_P]
    p_now = np.empty_like(p_new)
    # The path's tangential state: the level's samples, copied (its accepted steps accept
    # theirs, and a refused lean step leaves the level's untouched).
    fs = level[L_FRICTION]
    friction = fs.shape[0] > 0
    fs_now = fs.copy() if friction else fs
    now = (p_now, level[L_Q], level[L_PLATE], level[L_TARGET], obstacles, level[L_MU], fs_now)
    F = np.empty(n)
    no_jac = np.empty((0, 0))
    no_blocks = np.empty((0, N_CTANGENT, N_CTANGENT))
    J = np.empty((n, n))
    blocks = np.empty((Z.shape[0], N_CTANGENT, N_CTANGENT))
    start = Z.copy()
    accepted = Z.copy()
    guess = np.empty_like(Z)
    moved = np.empty(n)
    need = np.empty(secf.shape[1])
    held = (factors[0].copy(), factors[1].copy())  # the factors of the accepted state
    fresh = new_factors(n)
    before = rec[1].copy()  # the accepted state's positions (the tunnel check's start)
    t = 0.0
    dt = 1.0
    passes = 0
    jacobians = 0
    res = math.inf
    stable = False
    for _ in range(LEAN_TRIES):
        if jacobians >= LEAN_JACOBIANS:
            break
        t_new = min(1.0, t + dt)
        final = t_new >= 1.0
        for c in range(p_new.shape[0]):
            p_now[c] = p_new[c] if final else p_old[c] + t_new * (p_new[c] - p_old[c])
        rest_strains_into(p_now, tubes[0], tubes[1], secf, rest)
        goal = tol if final else 1e3 * tol
        ok = newton_system(Z, grid, rest, now, F, no_jac, False, no_blocks, scales, NO_TETHER)
        passes += 1
        res = weighted_norm(F, res_weights) if ok else math.inf
        first = np.zeros(n)
        solved = False  # J and blocks hold Newton's at Z
        if math.isfinite(res) and not res <= goal:
            ok, res, its, first = broyden(Z, grid, rest, now, F, scales, res_weights, goal, held,
                                          res)
            passes += its
        else:
            ok = res <= goal
        # A step is accepted within 0.05 + 0.5·|prediction| of its prediction (the first
        # correction); Newton gives up where its root lies beyond that (FENCE_STEPS).
        retract(accepted, first, 1.0, guess)
        fence = jump_fence(weighted_norm(first, weights))
        if not ok and math.isfinite(res):
            ok, its, res, stable = newton_into(
                Z, grid, rest, now, weights, res_weights, scales, goal,
                min(int(params[MAX_ITER]) if final else 8, LEAN_JACOBIANS - jacobians - 1),
                params[MAX_STEP], NO_TETHER, F, J, blocks, JAC_VARIATIONAL, True, guess, fence,
                PLATEAU_FENCES)
            passes += its + 1
            jacobians += its + 1
            solved = ok
        if ok:
            between(Z, guess, moved)
            ok = weighted_norm(moved, weights) <= fence
        if ok:
            if solved:
                regular = factor_jacobian(Z, grid, rest, now, J, new, fresh)
            else:
                regular, stable = factor_state(Z, grid, rest, now, F, J, blocks, new, fresh)
                res = weighted_norm(F, res_weights)
                passes += 1
                jacobians += 1
            ok = (regular and stable and res <= goal
                  and not tunnels_3d(before, new[1], obstacles, TUNNEL_SLACK)
                  and (not final or section_needs(new[8], new[3], new[7], check[0], secf,
                                                  check[1], need) <= 1.0))
        if ok:
            t = t_new
            accepted[:, :] = Z
            held, fresh = fresh, held
            before[:, :] = new[1]
            if friction:  # the recording pass of the accepted state wrote its anchors
                accept_friction(fs_now)
            if final:
                break
            dt = min(2.0 * dt, 1.0)
        else:
            Z[:, :] = accepted
            dt = halved(dt, t_new - t, 0.0)
    if t < 1.0:
        Z[:, :] = start
        return False, stable, passes, res
    factors[0][:, :] = held[0]
    factors[1][:] = held[1]
    for c in range(p_new.shape[0]):
        p_old[c] = p_new[c]
    if friction:
        fs[...] = fs_now
    return True, stable, passes, res
