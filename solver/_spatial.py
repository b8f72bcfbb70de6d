"""Spatial quasi-static Cosserat kernels (thesis §2.3, Eqs. 2.13–2.24 and 2.28–2.31).

State along the reference arc length: position r, unit quaternion β = (β0, β1, β2, β3)
of the directors (Eqs. 2.18–2.24), and the internal moment m in the world frame. With dead
loads the internal force n(s) is known from global equilibrium, so shooting has three
unknowns, the base moment m0, and three residuals, m(L) − M_tip:

    r' = R v,   v = v* + D⁻¹ Rᵀ n,          D = diag(GA, GA, EA)          (2.31)
    β' = ½ β ⊗ (0, u),   u = u* + C⁻¹ Rᵀ m,  C = diag(EI, EI, GJ)          (2.21)–(2.24), (2.30)
    m' = −r' × n                                                          (2.29), l = 0

Sensitivities to m0, with δR = [δφ]× R (δφ a world-frame rotation):

    δφ' = K (δm + m × δφ),   K = R C⁻¹ Rᵀ
    δm' = −δr' × n,          δr' = δφ × r' − P (δφ × n),   P = R D⁻¹ Rᵀ

Stability: the conjugate-point test generalises to det ∂m(s)/∂m0 > 0 on (0, L].
"""

from __future__ import annotations

import math

import numpy as np

from solver._jit import njit
from solver._planar import _rest_strains


def base_rotation(theta0: float) -> np.ndarray:
    """Directors [d1 d2 d3] (columns) of the base: d3 = (cos θ0, sin θ0, 0), d2 = +z."""
    c, s = math.cos(theta0), math.sin(theta0)
    return np.array([[-s, 0.0, c], [c, 0.0, s], [0.0, 1.0, 0.0]])


def arc_chain(rot0, sec_len, sec_steps, u1, u2, v3, record):
    """Closed-form backbone of sections that each take their rest strains exactly.

    Each section is a circular arc (helix-free: u3 = 0, v = (0, 0, v3)): with κ = |u| and
    axis k = u/κ in the body frame, R(σ) = R0·exp(σ[u]×) and
    r(σ) = r0 + R0·[v3·e3·sin(κσ)/κ + v3·(k × e3)(1 − cos κσ)/κ].

    Returns:
        positions (N, 3), frames (N, 3, 3), s (N,) — or only the tip row when not recorded.
    """
    pos, frames, svals = [np.zeros(3)], [rot0.copy()], [0.0]
    r = np.zeros(3)
    rot = rot0.copy()
    s0 = 0.0
    for i in range(len(sec_len)):
        u = np.array([u1[i], u2[i], 0.0])
        kappa = float(np.hypot(u1[i], u2[i]))
        n = int(sec_steps[i]) if record else 1
        start_r, start_rot = r.copy(), rot.copy()
        for j in range(1, n + 1):
            sig = sec_len[i] * j / n
            rel_r, rel_rot = _arc(u, kappa, v3[i], sig)
            r = start_r + start_rot @ rel_r
            rot = start_rot @ rel_rot
            if record:
                pos.append(r.copy())
                frames.append(rot.copy())
                svals.append(s0 + sig)
        if record and i < len(sec_len) - 1:
            # Repeat the junction so that every section owns its end sample (as the
            # shooting kernels record them).
            pos.append(r.copy())
            frames.append(rot.copy())
            svals.append(s0 + sec_len[i])
        s0 += sec_len[i]
    if not record:
        return r[None, :], rot[None, :, :], np.array([s0])
    return np.array(pos), np.array(frames), np.array(svals)


def _arc(u, kappa, v3, sig):
    """Relative position and rotation after ``sig`` along an arc of body curvature ``u``."""
    e3 = np.array([0.0, 0.0, 1.0])
    if kappa * sig < 1e-8:
        return v3 * sig * e3, np.eye(3)
    k = u / kappa
    phi = kappa * sig
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    rot = np.eye(3) + math.sin(phi) * kx + (1.0 - math.cos(phi)) * (kx @ kx)
    rel = v3 * (e3 * math.sin(phi) / kappa + np.cross(k, e3) * (1.0 - math.cos(phi)) / kappa)
    return rel, rot


@njit
def _quat_to_rot(q, out):
    """Rotation matrix of the unit quaternion q (columns are d1, d2, d3; Eqs. 2.18–2.20)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    out[0, 0] = w * w + x * x - y * y - z * z
    out[0, 1] = 2.0 * (x * y - w * z)
    out[0, 2] = 2.0 * (x * z + w * y)
    out[1, 0] = 2.0 * (x * y + w * z)
    out[1, 1] = w * w - x * x + y * y - z * z
    out[1, 2] = 2.0 * (y * z - w * x)
    out[2, 0] = 2.0 * (x * z - w * y)
    out[2, 1] = 2.0 * (y * z + w * x)
    out[2, 2] = w * w - x * x - y * y + z * z


@njit
def _rot_to_quat(r, out):
    """Unit quaternion of rotation matrix ``r`` (Shepperd's method)."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        out[0] = 0.25 * s
        out[1] = (r[2, 1] - r[1, 2]) / s
        out[2] = (r[0, 2] - r[2, 0]) / s
        out[3] = (r[1, 0] - r[0, 1]) / s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        out[0] = (r[2, 1] - r[1, 2]) / s
        out[1] = 0.25 * s
        out[2] = (r[0, 1] + r[1, 0]) / s
        out[3] = (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        out[0] = (r[0, 2] - r[2, 0]) / s
        out[1] = (r[0, 1] + r[1, 0]) / s
        out[2] = 0.25 * s
        out[3] = (r[1, 2] + r[2, 1]) / s
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        out[0] = (r[1, 0] - r[0, 1]) / s
        out[1] = (r[0, 2] + r[2, 0]) / s
        out[2] = (r[1, 2] + r[2, 1]) / s
        out[3] = 0.25 * s


# State layout: r 0:3, quaternion 3:7, m 7:10, δφ 10:19 (3 columns), δm 19:28.
NSTATE = 28


@njit
def _rhs(sig, y, dy, rot, length, ca, cg, ci, cj, u1r, u2r, v3r, n_end, q):
    """Derivative of the spatial state (see module docstring) at local coordinate ``sig``."""
    qn = math.sqrt(y[3] ** 2 + y[4] ** 2 + y[5] ** 2 + y[6] ** 2)
    quat = y[3:7] / qn
    _quat_to_rot(quat, rot)
    n = np.empty(3)
    for d in range(3):
        n[d] = n_end[d] + q[d] * (length - sig)
    m = y[7:10]
    # Body-frame components.
    nb = rot.T @ n
    mb = rot.T @ m
    v = np.array([nb[0] * cg, nb[1] * cg, v3r + nb[2] * ca])
    u = np.array([u1r + mb[0] * ci, u2r + mb[1] * ci, mb[2] * cj])
    rp = rot @ v
    dy[0:3] = rp
    w, x, yy, z = quat[0], quat[1], quat[2], quat[3]
    dy[3] = 0.5 * (-x * u[0] - yy * u[1] - z * u[2])
    dy[4] = 0.5 * (w * u[0] - z * u[1] + yy * u[2])
    dy[5] = 0.5 * (z * u[0] + w * u[1] - x * u[2])
    dy[6] = 0.5 * (-yy * u[0] + x * u[1] + w * u[2])
    dy[7:10] = -np.cross(rp, n)
    d3 = rot[:, 2]
    for j in range(3):
        dphi = y[10 + 3 * j: 13 + 3 * j]
        dm = y[19 + 3 * j: 22 + 3 * j]
        a = dm + np.cross(m, dphi)
        ka = ci * a + (cj - ci) * d3 * (d3 @ a)
        pn = np.cross(dphi, n)
        ppn = cg * pn + (ca - cg) * d3 * (d3 @ pn)
        drp = np.cross(dphi, rp) - ppn
        dy[10 + 3 * j: 13 + 3 * j] = ka
        dy[19 + 3 * j: 22 + 3 * j] = -np.cross(drp, n)


@njit
def _integrate(m0, rot0, sec_len, sec_steps, c_a, c_g, c_i, c_j, u1, u2, v3, n_end, q, record,
               out_pos, out_rot, out_m):
    """One RK4 pass base → tip from base moment ``m0`` (3,).

    Returns (state at the tip (NSTATE,), min over nodes of det ∂m/∂m0). When ``record``,
    positions, frames and moments are written to ``out_pos`` (N,3), ``out_rot`` (N,3,3),
    ``out_m`` (N,3).
    """
    y = np.zeros(NSTATE)
    quat = np.empty(4)
    _rot_to_quat(rot0, quat)
    y[3:7] = quat
    y[7:10] = m0
    for j in range(3):
        y[19 + 4 * j] = 1.0  # δm(0) = identity columns
    k1 = np.empty(NSTATE)
    k2 = np.empty(NSTATE)
    k3 = np.empty(NSTATE)
    k4 = np.empty(NSTATE)
    tmp = np.empty(NSTATE)
    rot = np.empty((3, 3))
    dmin = 1.0
    row = 0
    for i in range(sec_len.shape[0]):
        length = sec_len[i]
        nst = sec_steps[i]
        h = length / nst
        for j in range(nst + 1):
            sig = j * h
            if record:
                qn = math.sqrt(y[3] ** 2 + y[4] ** 2 + y[5] ** 2 + y[6] ** 2)
                _quat_to_rot(y[3:7] / qn, rot)
                out_pos[row] = y[0:3]
                out_rot[row] = rot
                out_m[row] = y[7:10]
                row += 1
            if j == nst:
                break
            _rhs(sig, y, k1, rot, length, c_a[i], c_g[i], c_i[i], c_j[i], u1[i], u2[i], v3[i],
                 n_end[i], q[i])
            tmp[:] = y + 0.5 * h * k1
            _rhs(sig + 0.5 * h, tmp, k2, rot, length, c_a[i], c_g[i], c_i[i], c_j[i], u1[i], u2[i],
                 v3[i], n_end[i], q[i])
            tmp[:] = y + 0.5 * h * k2
            _rhs(sig + 0.5 * h, tmp, k3, rot, length, c_a[i], c_g[i], c_i[i], c_j[i], u1[i], u2[i],
                 v3[i], n_end[i], q[i])
            tmp[:] = y + h * k3
            _rhs(sig + h, tmp, k4, rot, length, c_a[i], c_g[i], c_i[i], c_j[i], u1[i], u2[i],
                 v3[i], n_end[i], q[i])
            y += (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            y[3:7] /= math.sqrt(y[3] ** 2 + y[4] ** 2 + y[5] ** 2 + y[6] ** 2)
            det = _det3(y[19:28])
            if det < dmin:
                dmin = det
    return y, dmin


@njit
def _det3(cols):
    """Determinant of the 3×3 matrix stored column-wise in ``cols`` (9,)."""
    a = cols[0:3]
    b = cols[3:6]
    c = cols[6:9]
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) - b[0] * (a[1] * c[2] - a[2] * c[1])
            + c[0] * (a[1] * b[2] - a[2] * b[1]))


@njit
def _newton(m0, rot0, sec_len, sec_steps, c_a, c_g, c_i, c_j, u1, u2, v3, n_end, q, m_tip, tol,
            max_iter, max_step, dpos, drot, dm):
    """Newton on m(L; m0) = M_tip (3 unknowns) with the exact shooting Jacobian.

    Returns (m0, converged, iterations, |residual|, stable).
    """
    m0 = m0.copy()
    res = math.inf
    dmin = 1.0
    for it in range(max_iter + 1):
        y, dmin = _integrate(m0, rot0, sec_len, sec_steps, c_a, c_g, c_i, c_j, u1, u2, v3,
                             n_end, q, False, dpos, drot, dm)
        r = y[7:10] - m_tip
        res = math.sqrt(r @ r)
        if not math.isfinite(res):
            return m0, False, it, math.inf, False
        if res <= tol:
            return m0, True, it, res, dmin > 0.0
        if it == max_iter:
            break
        jac = np.empty((3, 3))
        for j in range(3):
            jac[:, j] = y[19 + 3 * j: 22 + 3 * j]
        if abs(_det3(y[19:28])) < 1e-300:
            break
        step = -np.linalg.solve(jac, r)
        norm = math.sqrt(step @ step)
        if norm > max_step:
            step *= max_step / norm
        m0 += step
    return m0, False, max_iter, res, dmin > 0.0


@njit
def _follow(m0, rot0, sec_len, sec_steps, c_a, c_g, c_i, c_j, sec_ea, sec_ei, tubes_i, tubes_f,
            p_a, p_b, end_a, end_b, q_a, q_b, mtip_a, mtip_b, tol, max_iter, max_step, dt0,
            dt_min):
    """Spatial quasi-static path following (see :func:`solver._planar._follow`).

    In 3D no fold scan is attempted: if the step falls below ``dt_min`` without a stable
    converged equilibrium, the best iterate is returned unconverged (and reported so).
    Returns (m0 (3,), converged, iterations, stable, |residual|, u1, u2, v3, n_end, q, m_tip).
    """
    ns = sec_len.shape[0]
    u1 = np.empty(ns)
    u2 = np.empty(ns)
    v3 = np.empty(ns)
    p_now = np.empty(p_a.shape[0])
    n_end = np.empty((ns, 3))
    q = np.empty((ns, 3))
    dpos = np.empty((1, 3))
    drot = np.empty((1, 3, 3))
    dmm = np.empty((1, 3))
    t = 0.0
    dt = dt0
    slope = np.zeros(3)
    total = 0
    ok = True
    stable = True
    res = 0.0
    m_tip = mtip_a.copy()
    while True:
        t_new = min(1.0, t + dt)
        for c in range(p_a.shape[0]):
            p_now[c] = p_a[c] + t_new * (p_b[c] - p_a[c])
        n_end[:, :] = end_a + t_new * (end_b - end_a)
        q[:, :] = q_a + t_new * (q_b - q_a)
        m_tip = mtip_a + t_new * (mtip_b - mtip_a)
        _rest_strains(p_now, tubes_i[:, 0], tubes_i[:, 1], tubes_i[:, 2], tubes_f[:, 0],
                      tubes_f[:, 1], tubes_f[:, 2], tubes_f[:, 3], tubes_f[:, 4], tubes_f[:, 5],
                      sec_ea, sec_ei, u1, u2, v3)
        guess = m0 + slope * (t_new - t)
        root, ok, its, res, stable = _newton(guess, rot0, sec_len, sec_steps, c_a, c_g, c_i, c_j,
                                             u1, u2, v3, n_end, q, m_tip, tol, max_iter, max_step,
                                             dpos, drot, dmm)
        total += its
        d = root - guess
        if ok and stable and (math.sqrt(d @ d) <= 0.5 * max_step or dt <= dt_min):
            slope = (root - m0) / (t_new - t)
            m0 = root
            t = t_new
            dt = min(2.0 * dt, 1.0)
            if t >= 1.0:
                break
            continue
        if dt > dt_min:
            dt *= 0.5
            continue
        m0 = root if ok else m0
        break
    return m0, ok, total, stable, res, u1, u2, v3, n_end, q, m_tip
