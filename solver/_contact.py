"""Planar kernels for an arm pressed against rigid discs (penalty contact).

With contact the internal force is no longer known from global equilibrium, so the base
force n0 joins the base moment as an unknown (3 in the plane). Section i carries, with
n integrated from n' + f = 0 (Eq. 2.28, static):

    x' = v3 cos θ − v1 sin θ,   y' = v3 sin θ + v1 cos θ,   θ' = u*_i + m/EI_i
    n' = −μ_i g − Σ_discs f_c,  m' = v1 n3 − v3 n1
    f_c = k · max(0, R − |r − c|) · (r − c)/|r − c|      (force per reference length, N/m)

Endplate weights jump n at the junctions; the free tip requires n(L) = F_tip + W_plate and
m(L) = M_tip. Newton uses a forward-difference Jacobian of those three residuals; the same
four trajectories, integrated in lockstep, give det ∂(n, m)(s)/∂(n0, m0) along the arm. For
the contact-free rod ∂n(s)/∂n0 = I, so this determinant is exactly the conjugate-point
quantity ∂m(s)/∂m0 of :mod:`solver._planar`; with contact we use its positivity on (0, L]
as the stability test (documented as the natural extension, not a theorem).
"""

from __future__ import annotations

import math

import numpy as np

from solver._jit import njit
from solver._planar import _rest_strains

# Columns of recorded samples: s, x, y, θ, n_x, n_y, m, f_x, f_y, penetration, v1, v3, u
C_S, C_X, C_Y, C_TH, C_NX, C_NY, C_M, C_FX, C_FY, C_PEN, C_V1, C_V3, C_U = range(13)
N_COLUMNS = 13


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
    """Derivative of one trajectory's state (x, y, θ, n_x, n_y, m) into ``out``."""
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
def _det3(a):
    return (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
            - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
            + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))


@njit
def _shoot(unknowns, eps, theta0, sec_len, sec_steps, c_a, c_g, c_i, u_rest, v_rest, q, plate,
           discs, record, out, states, k1, k2, k3, k4, tmp, jac):
    """Integrate the base state and three perturbed copies base → tip in lockstep.

    Args:
        unknowns: (3,) base force (n_x, n_y) [N] and moment m [N m].
        eps: (3,) forward-difference steps for the three unknowns.
        q: (ns, 2) weight per length (N/m, world); plate: (ns, 2) endplate weights (N).
        discs: (n, 4) obstacles. states, k1..k4, tmp: (4, 6) scratch; jac: (3, 3) scratch.
        record: write the unperturbed trajectory into ``out`` (rows, N_COLUMNS).

    Returns:
        min over nodes of det ∂(n, m)(s)/∂(n0, m0); ``states`` holds the four tip states.
    """
    for k in range(4):
        states[k, 0] = 0.0
        states[k, 1] = 0.0
        states[k, 2] = theta0
        for j in range(3):
            states[k, 3 + j] = unknowns[j] + (eps[j] if k == j + 1 else 0.0)
    dmin = 1.0
    row = 0
    s0 = 0.0
    for i in range(sec_len.shape[0]):
        h = sec_len[i] / sec_steps[i]
        for j in range(sec_steps[i] + 1):
            if record:
                fx, fy, pen = _contact_force(states[0, 0], states[0, 1], discs)
                th = states[0, 2]
                c = math.cos(th)
                sn = math.sin(th)
                n1 = -states[0, 3] * sn + states[0, 4] * c
                n3 = states[0, 3] * c + states[0, 4] * sn
                out[row, C_S] = s0 + j * h
                for d in range(6):
                    out[row, C_X + d] = states[0, d]
                out[row, C_FX] = fx
                out[row, C_FY] = fy
                out[row, C_PEN] = pen
                out[row, C_V1] = n1 * c_g[i]
                out[row, C_V3] = v_rest[i] + n3 * c_a[i]
                out[row, C_U] = u_rest[i] + states[0, 5] * c_i[i]
                row += 1
            if j == sec_steps[i]:
                break
            for k in range(4):
                _rhs(states[k], k1[k], c_a[i], c_g[i], c_i[i], u_rest[i], v_rest[i], q[i, 0],
                     q[i, 1], discs)
                for d in range(6):
                    tmp[k, d] = states[k, d] + 0.5 * h * k1[k, d]
                _rhs(tmp[k], k2[k], c_a[i], c_g[i], c_i[i], u_rest[i], v_rest[i], q[i, 0],
                     q[i, 1], discs)
                for d in range(6):
                    tmp[k, d] = states[k, d] + 0.5 * h * k2[k, d]
                _rhs(tmp[k], k3[k], c_a[i], c_g[i], c_i[i], u_rest[i], v_rest[i], q[i, 0],
                     q[i, 1], discs)
                for d in range(6):
                    tmp[k, d] = states[k, d] + h * k3[k, d]
                _rhs(tmp[k], k4[k], c_a[i], c_g[i], c_i[i], u_rest[i], v_rest[i], q[i, 0],
                     q[i, 1], discs)
                for d in range(6):
                    states[k, d] += h / 6.0 * (k1[k, d] + 2.0 * k2[k, d] + 2.0 * k3[k, d]
                                               + k4[k, d])
            for a in range(3):
                for b in range(3):
                    jac[a, b] = (states[b + 1, 3 + a] - states[0, 3 + a]) / eps[b]
            det = _det3(jac)
            if det < dmin:
                dmin = det
        # Endplate weight: n(s⁺) = n(s⁻) − W (not after the last section: that is the tip BC).
        if i < sec_len.shape[0] - 1:
            for k in range(4):
                states[k, 3] -= plate[i, 0]
                states[k, 4] -= plate[i, 1]
        s0 += sec_len[i]
    return dmin


@njit
def _newton(unknowns, eps, target, scale, theta0, sec_len, sec_steps, c_a, c_g, c_i, u_rest,
            v_rest, q, plate, discs, tol, max_iter, max_step, dummy, states, k1, k2, k3, k4, tmp,
            jac, res_out):
    """Newton on the tip residuals (n(L) − target[0:2], m(L) − target[2]).

    ``scale`` (3,) weights force against moment residuals (N vs N m → a length). Returns
    (converged, iterations, |weighted residual|, stable); ``unknowns`` is updated in place.
    """
    res = math.inf
    stable = False
    for it in range(max_iter + 1):
        dmin = _shoot(unknowns, eps, theta0, sec_len, sec_steps, c_a, c_g, c_i, u_rest, v_rest,
                      q, plate, discs, False, dummy, states, k1, k2, k3, k4, tmp, jac)
        stable = dmin > 0.0
        total = 0.0
        for a in range(3):
            res_out[a] = states[0, 3 + a] - target[a]
            total += (res_out[a] / scale[a]) ** 2
        res = math.sqrt(total)
        if not math.isfinite(res):
            return False, it, math.inf, False
        if res <= tol:
            return True, it, res, stable
        if it == max_iter:
            break
        # jac now holds ∂(n, m)(L)/∂(n0, m0).
        step = np.linalg.solve(jac, res_out)
        norm = 0.0
        for a in range(3):
            norm += (step[a] / scale[a]) ** 2
        norm = math.sqrt(norm)
        shrink = max_step / norm if norm > max_step else 1.0
        for a in range(3):
            unknowns[a] -= shrink * step[a]
    return False, max_iter, res, stable


@njit
def _follow(unknowns, theta0, secf, sec_steps, tubes_i, tubes_f, p_a, p_b, q, plate, target, discs,
            scale, tol, max_iter, max_step, dt0, dt_min, rest, p_now):
    """Quasi-static pressure ramp p_a → p_b with contact (cf. :func:`solver._planar._follow`).

    No fold scan: if the step falls below ``dt_min`` the last accepted state is returned,
    flagged unconverged. Returns (converged, iterations, |residual|, stable); ``unknowns``
    holds the returned state and ``rest`` (3, ns) its rest strains.
    """
    sec_len = secf[0]
    c_a = secf[1]
    c_g = secf[2]
    c_i = secf[3]
    u2 = rest[1]
    v3 = rest[2]
    states = np.empty((4, 6))
    k1 = np.empty((4, 6))
    k2 = np.empty((4, 6))
    k3 = np.empty((4, 6))
    k4 = np.empty((4, 6))
    tmp = np.empty((4, 6))
    jac = np.empty((3, 3))
    res_out = np.empty(3)
    dummy = np.empty((1, N_COLUMNS))
    eps = np.empty(3)
    for a in range(3):
        eps[a] = 1e-7 * scale[a] * max(1.0, max_step)
    t = 0.0
    dt = dt0
    slope = np.zeros(3)
    accepted = unknowns.copy()
    guess = np.empty(3)
    total = 0
    ok = False
    res = math.inf
    stable = False
    while t < 1.0:
        t_new = min(1.0, t + dt)
        for c in range(p_a.shape[0]):
            p_now[c] = p_a[c] + t_new * (p_b[c] - p_a[c])
        _rest_strains(p_now, tubes_i, tubes_f, secf, rest)
        for a in range(3):
            guess[a] = accepted[a] + slope[a] * (t_new - t)
            unknowns[a] = guess[a]
        ok, its, res, stable = _newton(unknowns, eps, target, scale, theta0, sec_len, sec_steps, c_a,
                                       c_g, c_i, u2, v3, q, plate, discs, tol, max_iter, max_step,
                                       dummy, states, k1, k2, k3, k4, tmp, jac, res_out)
        total += its
        jump = 0.0
        for a in range(3):
            jump += ((unknowns[a] - guess[a]) / scale[a]) ** 2
        if ok and stable and (math.sqrt(jump) <= 0.5 * max_step or dt <= dt_min):
            for a in range(3):
                slope[a] = (unknowns[a] - accepted[a]) / (t_new - t)
                accepted[a] = unknowns[a]
            t = t_new
            dt = min(2.0 * dt, 1.0)
            continue
        if dt > dt_min:
            dt *= 0.5
            continue
        break
    if t < 1.0:
        # Give back the last accepted state, with its own rest strains.
        for a in range(3):
            unknowns[a] = accepted[a]
        for c in range(p_a.shape[0]):
            p_now[c] = p_a[c] + t * (p_b[c] - p_a[c])
        _rest_strains(p_now, tubes_i, tubes_f, secf, rest)
        return False, total, res, stable
    return ok, total, res, stable


@njit
def _record(unknowns, theta0, sec_len, sec_steps, c_a, c_g, c_i, u_rest, v_rest, q, plate, discs,
            out):
    """Record the backbone of the state ``unknowns`` into ``out``; returns min det (stability)."""
    states = np.empty((4, 6))
    eps = np.full(3, 1e-7)
    return _shoot(unknowns, eps, theta0, sec_len, sec_steps, c_a, c_g, c_i, u_rest, v_rest, q,
                  plate, discs, True, out, states, np.empty((4, 6)), np.empty((4, 6)),
                  np.empty((4, 6)), np.empty((4, 6)), np.empty((4, 6)), np.empty((3, 3)))
