"""Planar kernels for an arm pressed against rigid discs (penalty contact), multiple shooting.

With contact the internal force is no longer known from global equilibrium, so the whole
state (x, y, θ, n_x, n_y, m) is integrated. Section i carries, from n' + f = 0 (Eq. 2.28):

    x' = v3 cos θ − v1 sin θ,   y' = v3 sin θ + v1 cos θ,   θ' = u*_i + m/EI_i
    n' = −μ_i g − Σ_discs f_c,  m' = v1 n3 − v3 n1
    f_c = k · max(0, R − |r − c|) · (r − c)/|r − c|      (force per reference length, N/m)

A stiff penalty makes this stiff: in contact, deflections decay and grow over the length
ℓ = (EI/k)^¼ (3 cm for OctArm-like sections at k = 1e5 N/m²), so single shooting across a
deep wrap amplifies errors by e^(contact length/ℓ) and fails. We use multiple shooting: the
arm is cut into segments of a few RK4 steps (each RK4 step h ≤ ℓ/2, chosen by the wrapper),
the state at every segment start is an unknown, and Newton solves continuity between
segments plus the free-tip conditions n(L) = F_tip + W_plate, m(L) = M_tip. Endplate weights
jump n at the junctions. The segment maps' Jacobians come from forward differences.

Stability: chaining the segment Jacobians gives ∂(state)(s)/∂(n0, m0) at every segment end;
det of its (n, m) rows staying positive on (0, L] is the conjugate-point test of
:mod:`solver._planar` (for a contact-free rod it is exactly ∂m(s)/∂m0 > 0), which we use as
the stability test with contact (the natural extension, not a theorem).
"""

from __future__ import annotations

import math

import numpy as np

from solver._jit import njit
from solver._rod import _rest_strains

# Columns of recorded samples: s, x, y, θ, n_x, n_y, m, f_x, f_y, penetration, v1, v3, u
C_S, C_X, C_Y, C_TH, C_NX, C_NY, C_M, C_FX, C_FY, C_PEN, C_V1, C_V3, C_U = range(13)
N_COLUMNS = 13
# Columns of the segment table (M, 5): section, first local step, steps, ends the section,
# first recorded row of the section.
SEG_SECTION, SEG_FIRST, SEG_STEPS, SEG_END, SEG_ROW0 = range(5)


@njit
def _contact_force(x, y, discs):
    """Penalty force per length (fx, fy) and deepest penetration at backbone point (x, y).

    ``discs`` is (n, 4): centre x, centre y, radius, stiffness (N/m²).
    """
    fx = 0.0
    fy = 0.0
    deepest = 0.0
    for d in range(discs.shape[0]):
        dx = x - discs[d, 0]
        dy = y - discs[d, 1]
        dist = math.sqrt(dx * dx + dy * dy)
        pen = discs[d, 2] - dist
        if pen > 0.0 and dist > 0.0:
            scale = discs[d, 3] * pen / dist
            fx += scale * dx
            fy += scale * dy
            if pen > deepest:
                deepest = pen
    return fx, fy, deepest


@njit
def _rhs(st, out, ca, cg, ci, ur, vr, qx, qy, discs):
    """Derivative of the state (x, y, θ, n_x, n_y, m) into ``out``."""
    th = st[2]
    nx = st[3]
    ny = st[4]
    c = math.cos(th)
    sn = math.sin(th)
    n1 = -nx * sn + ny * c
    n3 = nx * c + ny * sn
    v1 = n1 * cg
    v3 = vr + n3 * ca
    fx, fy, pen = _contact_force(st[0], st[1], discs)
    out[0] = v3 * c - v1 * sn
    out[1] = v3 * sn + v1 * c
    out[2] = ur + st[5] * ci
    out[3] = -qx - fx
    out[4] = -qy - fy
    out[5] = v1 * n3 - v3 * n1


@njit
def _write_row(st, s, out, row, ca, cg, ci, ur, vr, discs):
    fx, fy, pen = _contact_force(st[0], st[1], discs)
    c = math.cos(st[2])
    sn = math.sin(st[2])
    n1 = -st[3] * sn + st[4] * c
    n3 = st[3] * c + st[4] * sn
    out[row, C_S] = s
    for d in range(6):
        out[row, C_X + d] = st[d]
    out[row, C_FX] = fx
    out[row, C_FY] = fy
    out[row, C_PEN] = pen
    out[row, C_V1] = n1 * cg
    out[row, C_V3] = vr + n3 * ca
    out[row, C_U] = ur + st[5] * ci


@njit
def _segment(z, seg, segs, secf, steps, sec_start, rest, q, plate, discs, out_state, work,
             record, out):
    """Integrate segment ``seg`` from state ``z`` (6,) into ``out_state`` (6,).

    Applies the endplate jump n(s⁺) = n(s⁻) − W at a section end (not at the tip: that is
    the boundary condition). ``work`` is (5, 6) scratch. With ``record``, writes the
    segment's nodes (and the section's last node) into ``out``.
    """
    i = segs[seg, SEG_SECTION]
    first = segs[seg, SEG_FIRST]
    nst = segs[seg, SEG_STEPS]
    h = secf[0, i] / steps[i]
    ca = secf[1, i]
    cg = secf[2, i]
    ci = secf[3, i]
    ur = rest[1, i]
    vr = rest[2, i]
    qx = q[i, 0]
    qy = q[i, 1]
    st = out_state
    for d in range(6):
        st[d] = z[d]
    k1 = work[0]
    k2 = work[1]
    k3 = work[2]
    k4 = work[3]
    tmp = work[4]
    for j in range(first, first + nst):
        if record:
            _write_row(st, sec_start[i] + j * h, out, segs[seg, SEG_ROW0] + j, ca, cg, ci, ur, vr,
                       discs)
        _rhs(st, k1, ca, cg, ci, ur, vr, qx, qy, discs)
        for d in range(6):
            tmp[d] = st[d] + 0.5 * h * k1[d]
        _rhs(tmp, k2, ca, cg, ci, ur, vr, qx, qy, discs)
        for d in range(6):
            tmp[d] = st[d] + 0.5 * h * k2[d]
        _rhs(tmp, k3, ca, cg, ci, ur, vr, qx, qy, discs)
        for d in range(6):
            tmp[d] = st[d] + h * k3[d]
        _rhs(tmp, k4, ca, cg, ci, ur, vr, qx, qy, discs)
        for d in range(6):
            st[d] += h / 6.0 * (k1[d] + 2.0 * k2[d] + 2.0 * k3[d] + k4[d])
    if segs[seg, SEG_END] == 1:
        if record:
            _write_row(st, sec_start[i] + secf[0, i], out, segs[seg, SEG_ROW0] + steps[i], ca, cg,
                       ci, ur, vr, discs)
        if i < secf.shape[1] - 1:
            st[3] -= plate[i, 0]
            st[4] -= plate[i, 1]


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


@njit
def _system(Z, theta0, segs, secf, steps, sec_start, rest, q, plate, discs, target, eps, F, J,
            want_jac, chain):
    """Residuals F (N,) of the multiple-shooting system and, if ``want_jac``, its Jacobian J.

    Unknowns Z: (n0x, n0y, m0), then the 6-state at the start of segments 1..M−1. Rows: the
    6 continuity conditions of segments 0..M−2, then n(L), m(L) against ``target`` (3,).
    ``eps`` (6,) are forward-difference steps per state component. With ``want_jac``,
    returns min over segment ends of det ∂(n, m)/∂(n0, m0) (``chain`` (6, 3) scratch).
    """
    n_seg = segs.shape[0]
    z = np.empty(6)
    zp = np.empty(6)
    end = np.empty(6)
    endp = np.empty(6)
    work = np.empty((5, 6))
    block = np.empty((6, 6))
    new = np.empty((6, 3))
    dummy = np.empty((1, N_COLUMNS))
    dmin = 1.0
    if want_jac:
        J[:, :] = 0.0
        chain[:, :] = 0.0
        for d in range(3):
            chain[3 + d, d] = 1.0
    for seg in range(n_seg):
        _start_state(Z, seg, theta0, z)
        _segment(z, seg, segs, secf, steps, sec_start, rest, q, plate, discs, end, work, False,
                 dummy)
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
        if not last:
            for d in range(6):
                J[row + d, 3 + 6 * seg + d] = -1.0
        first_comp = 3 if seg == 0 else 0
        col0 = 0 if seg == 0 else 3 + 6 * (seg - 1)
        for c in range(first_comp, 6):
            for d in range(6):
                zp[d] = z[d]
            zp[c] += eps[c]
            _segment(zp, seg, segs, secf, steps, sec_start, rest, q, plate, discs, endp, work,
                     False, dummy)
            for d in range(6):
                block[d, c] = (endp[d] - end[d]) / eps[c]
            col = col0 + c - first_comp
            if not last:
                for d in range(6):
                    J[row + d, col] = block[d, c]
            else:
                for d in range(3):
                    J[row + d, col] = block[3 + d, c]
        # Chain ∂state/∂(n0, m0) through this segment: segment 0's block columns 3..5 are it.
        for a in range(6):
            for b in range(3):
                if seg == 0:
                    new[a, b] = block[a, 3 + b]
                else:
                    acc = 0.0
                    for c in range(6):
                        acc += block[a, c] * chain[c, b]
                    new[a, b] = acc
        chain[:, :] = new
        det = (chain[3, 0] * (chain[4, 1] * chain[5, 2] - chain[4, 2] * chain[5, 1])
               - chain[3, 1] * (chain[4, 0] * chain[5, 2] - chain[4, 2] * chain[5, 0])
               + chain[3, 2] * (chain[4, 0] * chain[5, 1] - chain[4, 1] * chain[5, 0]))
        if det < dmin:
            dmin = det
    return dmin


@njit
def _weighted_norm(v, weights):
    acc = 0.0
    for k in range(v.shape[0]):
        acc += (v[k] / weights[k]) ** 2
    return math.sqrt(acc / v.shape[0])


@njit
def _newton(Z, theta0, segs, secf, steps, sec_start, rest, q, plate, discs, target, eps, weights,
            res_weights, tol, max_iter, max_step):
    """Newton on the multiple-shooting system; ``Z`` is updated in place.

    Residuals and steps are measured in weighted RMS norms (weights: metres for positions,
    radians, the force and moment scales). Returns (converged, iterations, |F|, stable).
    """
    n = Z.shape[0]
    F = np.empty(n)
    J = np.empty((n, n))
    chain = np.empty((6, 3))
    stable = False
    res = math.inf
    for it in range(max_iter + 1):
        dmin = _system(Z, theta0, segs, secf, steps, sec_start, rest, q, plate, discs, target, eps,
                       F, J, True, chain)
        stable = dmin > 0.0
        res = _weighted_norm(F, res_weights)
        if not math.isfinite(res):
            return False, it, math.inf, False
        if res <= tol:
            return True, it, res, stable
        if it == max_iter:
            break
        step = np.linalg.solve(J, F)
        norm = _weighted_norm(step, weights)
        shrink = max_step / norm if norm > max_step else 1.0
        for k in range(n):
            Z[k] -= shrink * step[k]
    return False, max_iter, res, stable


@njit
def _set_level(t, p_a, p_b, q_a, q_b, plate_a, plate_b, target_a, target_b, p_now, q_now,
               plate_now, target_now):
    """Interpolate pressures and loads of the homotopy at level ``t``."""
    for c in range(p_a.shape[0]):
        p_now[c] = p_a[c] + t * (p_b[c] - p_a[c])
    for i in range(q_a.shape[0]):
        for d in range(2):
            q_now[i, d] = q_a[i, d] + t * (q_b[i, d] - q_a[i, d])
            plate_now[i, d] = plate_a[i, d] + t * (plate_b[i, d] - plate_a[i, d])
    for d in range(3):
        target_now[d] = target_a[d] + t * (target_b[d] - target_a[d])


@njit
def _follow(Z, theta0, segs, secf, steps, sec_start, tubes_i, tubes_f, p_a, p_b, q_a, q_b,
            plate_a, plate_b, target_a, target_b, discs, eps, weights, res_weights, tol, max_iter,
            max_step, dt0, dt_min, rest, p_now, predict_cap=math.inf):
    """Quasi-static ramp from state A to state B (cf. :func:`solver._planar._follow`):
    pressures p_a → p_b, distributed loads q_a → q_b (ns, 2), endplate weights
    plate_a → plate_b (ns, 2) and tip targets target_a → target_b (3,), all linearly in t.

    A step is accepted if Newton converged on a stable state whose correction is small
    against the step predicted (tangent predictor for the first step, then secant, on all
    node states; a predicted move longer than ``predict_cap`` in the weighted RMS norm is
    shortened to it). No fold scan: if the step falls below ``dt_min`` the last accepted state
    is returned, flagged unconverged. Returns (converged, iterations, |residual|, stable);
    ``Z`` holds the returned state and ``rest`` (3, ns) its rest strains.
    """
    n = Z.shape[0]
    t = 0.0
    dt = dt0
    slope = np.zeros(n)
    accepted = Z.copy()
    guess = np.empty(n)
    total = 0
    ok = False
    res = math.inf
    stable = False
    q = np.empty_like(q_a)
    plate = np.empty_like(plate_a)
    target = np.empty(3)
    # Tangent predictor for the first step. Without it the first step's correction is
    # judged against a zero prediction, and a large pressure change is halved until its
    # correction is small in absolute terms — five or six converged steps thrown away.
    _initial_tangent(Z, theta0, segs, secf, steps, sec_start, tubes_i, tubes_f, p_a, p_b, q_a,
                     q_b, plate_a, plate_b, target_a, target_b, discs, eps, rest, p_now, q, plate,
                     target, slope)
    total += 1
    while t < 1.0:
        t_new = min(1.0, t + dt)
        _set_level(t_new, p_a, p_b, q_a, q_b, plate_a, plate_b, target_a, target_b, p_now, q,
                   plate, target)
        _rest_strains(p_now, tubes_i, tubes_f, secf, rest)
        move = 0.0
        for k in range(n):
            move += (slope[k] * (t_new - t) / weights[k]) ** 2
        move = math.sqrt(move / n)
        cap = predict_cap / move if move > predict_cap else 1.0
        for k in range(n):
            guess[k] = accepted[k] + cap * slope[k] * (t_new - t)
            Z[k] = guess[k]
        final = t_new >= 1.0
        ok, its, res, stable = _newton(Z, theta0, segs, secf, steps, sec_start, rest, q, plate,
                                       discs, target, eps, weights, res_weights,
                                       tol if final else 1e3 * tol, max_iter if final else 8,
                                       max_step)
        total += its
        corr = 0.0
        pred = 0.0
        for k in range(n):
            corr += ((Z[k] - guess[k]) / weights[k]) ** 2
            pred += ((guess[k] - accepted[k]) / weights[k]) ** 2
        corr = math.sqrt(corr / n)
        pred = math.sqrt(pred / n)
        if ok and stable and (corr <= 0.05 + 0.5 * pred or dt <= dt_min):
            for k in range(n):
                slope[k] = (Z[k] - accepted[k]) / (t_new - t)
                accepted[k] = Z[k]
            t = t_new
            dt = min(2.0 * dt, 1.0)
            continue
        if dt > dt_min:
            dt *= 0.5
            continue
        break
    if t < 1.0:
        for k in range(n):
            Z[k] = accepted[k]
        _set_level(t, p_a, p_b, q_a, q_b, plate_a, plate_b, target_a, target_b, p_now, q, plate,
                   target)
        _rest_strains(p_now, tubes_i, tubes_f, secf, rest)
        return False, total, res, stable
    return ok, total, res, stable


@njit
def _record(Z, theta0, segs, secf, steps, sec_start, rest, q, plate, discs, out):
    """Write the backbone of the state ``Z`` into ``out`` (rows Σ(steps + 1), N_COLUMNS)."""
    z = np.empty(6)
    end = np.empty(6)
    work = np.empty((5, 6))
    for seg in range(segs.shape[0]):
        _start_state(Z, seg, theta0, z)
        _segment(z, seg, segs, secf, steps, sec_start, rest, q, plate, discs, end, work, True, out)

@njit
def _initial_tangent(Z, theta0, segs, secf, steps, sec_start, tubes_i, tubes_f, p_a, p_b, q_a,
                     q_b, plate_a, plate_b, target_a, target_b, discs, eps, rest, p_now, q, plate,
                     target, slope):
    """dZ/dt = −J⁻¹ ∂F/∂t at the start state (an equilibrium), ∂F/∂t by a forward
    difference, into ``slope``; zero where J or the result is not finite."""
    n = Z.shape[0]
    eps_t = 1e-4
    F0 = np.empty(n)
    F1 = np.empty(n)
    J = np.empty((n, n))
    chain = np.empty((6, 3))
    _set_level(eps_t, p_a, p_b, q_a, q_b, plate_a, plate_b, target_a, target_b, p_now, q, plate,
               target)
    _rest_strains(p_now, tubes_i, tubes_f, secf, rest)
    _system(Z, theta0, segs, secf, steps, sec_start, rest, q, plate, discs, target, eps, F1, J,
            False, chain)
    _set_level(0.0, p_a, p_b, q_a, q_b, plate_a, plate_b, target_a, target_b, p_now, q, plate,
               target)
    _rest_strains(p_now, tubes_i, tubes_f, secf, rest)
    _system(Z, theta0, segs, secf, steps, sec_start, rest, q, plate, discs, target, eps, F0, J,
            True, chain)
    for k in range(n):
        F1[k] = -(F1[k] - F0[k]) / eps_t
    if np.all(np.isfinite(J)) and np.all(np.isfinite(F1)):
        slope[:] = np.linalg.solve(J, F1)
        if not np.all(np.isfinite(slope)):
            slope[:] = 0.0
