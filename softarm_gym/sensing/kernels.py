"""numba kernels of the sensing package: cable quadrature, the load-cell integration and the
chapter-4 reduced model.

The rod equations, RK4 steps, arcs and resampling are the solver's (:mod:`solver.rod`); only
the reduced model of §4.2.2–4.2.3, whose equations differ, is integrated here. Every kernel
takes float arrays and writes into preallocated outputs; the validated public wrappers live
in :mod:`softarm_gym.sensing.sensors` and :mod:`softarm_gym.sensing.estimators`.
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.layout import SL_N, SL_Q, SP_M, SP_R
from solver.rod import (
    hermite_resample,
    planar_state_rhs,
    planar_state_rk4_step,
    record_spatial_row,
    spatial_rhs,
    spatial_rk4_step,
    start_spatial_state,
)


@njit
def section_integrals(s, integrand, ends, out):
    """Cumulative integrals of sampled functions over consecutive sections.

    Composite Simpson's rule on the uniform samples of each section (Simpson 3/8 on the last
    three intervals when a section has an odd number of intervals; trapezoid for one interval).

    Args:
        s: (N,) reference arc length of the samples (m), uniform within a section.
        integrand: (N, C) sampled functions, one column per cable.
        ends: (n_sections,) int index of each section's last sample; section i starts at
            ends[i − 1] + 1 (junction samples are repeated), section 0 at 0.
        out: (n_sections, C) written: integral from the base to the end of each section.
    """
    for c in range(integrand.shape[1]):
        total = 0.0
        for i in range(ends.shape[0]):
            a = 0 if i == 0 else ends[i - 1] + 1
            n_int = ends[i] - a
            if n_int > 0:
                h = (s[ends[i]] - s[a]) / n_int
                acc = 0.0
                simpson_end = ends[i]
                if n_int == 1:
                    acc = 0.5 * h * (integrand[a, c] + integrand[a + 1, c])
                    simpson_end = a
                elif n_int % 2 == 1:
                    simpson_end = ends[i] - 3
                    k = simpson_end
                    acc = 3.0 * h / 8.0 * (integrand[k, c] + 3.0 * integrand[k + 1, c]
                                           + 3.0 * integrand[k + 2, c] + integrand[k + 3, c])
                for k in range(a, simpson_end, 2):
                    acc += h / 3.0 * (integrand[k, c] + 4.0 * integrand[k + 1, c]
                                      + integrand[k + 2, c])
                total += acc
            out[i, c] = total


@njit
def planar_cable_integrand(shear_stretch, curvature, radius, out):
    """Planar cable integrands √((v3 ∓ R·u)² + v1²) for the +R·d1 and −R·d1 cables, (N, 2)."""
    for k in range(curvature.shape[0]):
        v1 = shear_stretch[k, 0]
        v3 = shear_stretch[k, 1]
        ru = radius * curvature[k]
        out[k, 0] = math.sqrt((v3 - ru) ** 2 + v1 * v1)
        out[k, 1] = math.sqrt((v3 + ru) ** 2 + v1 * v1)


@njit
def load_cell_planar(theta0, n0x, n0y, m0, sec_len, sec_steps, c_a, c_g, c_i, u_rest, v_rest,
                     q, point, work, s_out, pos_out, tan_out, ends_out):
    """Integrate the planar equilibrium equations base → tip from a measured base wrench (§4.2.1).

    The solver's rod statics (:func:`solver.rod.planar_state_rhs`, RK4 by
    :func:`solver.rod.planar_state_rk4_step`) on the state (x, y, θ, n_x, n_y, m) from
    (0, 0, θ0, n0, m0), with n' = −q and each endplate's weight taken off n at its section
    end (the weight of the nominal arm is known; an unknown tip payload is already in n0).

    Args:
        theta0: base orientation (rad). n0x, n0y, m0: measured base wrench (N, N, N m).
        sec_len, sec_steps: (ns,) section lengths (m) and RK4 steps per section.
        c_a, c_g, c_i: (ns,) compliances 1/EA, 1/GA, 1/EI.
        u_rest, v_rest: (ns,) rest curvature (rad/m) and stretch from the pressures.
        q: (ns, 2) distributed load per reference length (N/m); point: (ns, 2) point load at
            each section end (endplate weight) (N).
        work: (7, 6) scratch.
        s_out: (Σ(steps + 1),) written: arc length of the samples (junctions repeated).
        pos_out, tan_out: (Σ(steps + 1), 2) written: positions and dr/ds.
        ends_out: (ns, 3) written: (x, y, θ) at each section end.

    Returns:
        The tip moment m(L) (N m): zero for a consistent measurement.
    """
    st = work[5]
    rate = work[6]
    st[0] = 0.0
    st[1] = 0.0
    st[2] = theta0
    st[3] = n0x
    st[4] = n0y
    st[5] = m0
    no_discs = np.empty((0, 4))
    s0 = 0.0
    row = 0
    for i in range(sec_len.shape[0]):
        h = sec_len[i] / sec_steps[i]
        for j in range(sec_steps[i] + 1):
            planar_state_rhs(st, rate, c_a[i], c_g[i], c_i[i], u_rest[i], v_rest[i], q[i, 0],
                             q[i, 1], no_discs)
            s_out[row] = s0 + j * h
            pos_out[row, 0] = st[0]
            pos_out[row, 1] = st[1]
            tan_out[row, 0] = rate[0]
            tan_out[row, 1] = rate[1]
            row += 1
            if j == sec_steps[i]:
                break
            planar_state_rk4_step(st, h, c_a[i], c_g[i], c_i[i], u_rest[i], v_rest[i],
                                  q[i, 0], q[i, 1], no_discs)
        ends_out[i, 0] = st[0]
        ends_out[i, 1] = st[1]
        ends_out[i, 2] = st[2]
        st[3] -= point[i, 0]
        st[4] -= point[i, 1]
        s0 += sec_len[i]
    return st[5]


@njit
def _reduced_rhs(th, m, n1, ci, ur, v, w):
    """The chapter-4 reduced model: θ' = u* + m/EI, m' = −v·n1, n1' = w·cos θ; r' = v·d3."""
    c = math.cos(th)
    return ur + m * ci, -v * n1, w * c, v * c, v * math.sin(th)


@njit
def reduced_planar(theta0, m0, n1_start, sec_len, sec_steps, c_i, u_rest, stretch, weight,
                   record, s_out, pos_out, tan_out, ends_out):
    """One RK4 pass of the reduced model of §4.2.2–4.2.3 (Eq. 4.17) base → tip.

    In section i the stretch v_i is constant (from pressurisation: measured by the encoders
    or predicted by the actuator model), the backbone is unshearable, the axial force is
    neglected, and the shear force n1 starts at the unknown ``n1_start[i]`` (it may jump at
    a junction, as in the thesis, where each section carries its own shear boundary value);
    θ and m are continuous. Eliminating m and n1 gives θ''' = −(v/EI)·w·cos θ.

    Args:
        theta0: base orientation (rad). m0: base moment (N m).
        n1_start: (ns,) shear force at the start of each section (N).
        sec_len, sec_steps: (ns,) lengths (m) and RK4 steps. c_i: (ns,) 1/EI.
        u_rest: (ns,) rest curvature (rad/m). stretch: (ns,) v_i. weight: (ns,) w_i (N/m).
        record: write the samples (else only ``ends_out``).
        s_out, pos_out, tan_out: (Σ(steps + 1),), (…, 2), (…, 2) samples, written if record.
        ends_out: (ns, 3) written: (x, y, θ) at each section end.

    Returns:
        (m(L), n1(L)) at the tip.
    """
    th = theta0
    m = m0
    n1 = 0.0
    x = 0.0
    y = 0.0
    s0 = 0.0
    row = 0
    for i in range(sec_len.shape[0]):
        h = sec_len[i] / sec_steps[i]
        ci = c_i[i]
        ur = u_rest[i]
        v = stretch[i]
        w = weight[i]
        n1 = n1_start[i]
        for j in range(sec_steps[i] + 1):
            d = _reduced_rhs(th, m, n1, ci, ur, v, w)
            if record:
                s_out[row] = s0 + j * h
                pos_out[row, 0] = x
                pos_out[row, 1] = y
                tan_out[row, 0] = d[3]
                tan_out[row, 1] = d[4]
                row += 1
            if j == sec_steps[i]:
                break
            hh = 0.5 * h
            k2 = _reduced_rhs(th + hh * d[0], m + hh * d[1], n1 + hh * d[2], ci, ur, v, w)
            k3 = _reduced_rhs(th + hh * k2[0], m + hh * k2[1], n1 + hh * k2[2], ci, ur, v, w)
            k4 = _reduced_rhs(th + h * k3[0], m + h * k3[1], n1 + h * k3[2], ci, ur, v, w)
            hw = h / 6.0
            th += hw * (d[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            m += hw * (d[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            n1 += hw * (d[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
            x += hw * (d[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
            y += hw * (d[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
        ends_out[i, 0] = x
        ends_out[i, 1] = y
        ends_out[i, 2] = th
        s0 += sec_len[i]
    return m, n1


@njit
def reduced_residual(z, theta0, sec_len, sec_steps, c_i, u_rest, stretch, weight, theta_target,
                     n_angles, tip_shear_weight, moment_scale, force_scale, ends, res):
    """Boundary residuals of the reduced model for unknowns z = (m0, n1_start[0..ns−1]).

    Rows: θ(s_i) − θ_target[i] for the first ``n_angles`` section ends; then, if
    n_angles < ns, the known tip shear n1(L) + W_tip·cos θ(L) (Eq. 4.41, W_tip the known tip
    weight, N) scaled by ``force_scale``; last, the free-tip moment m(L) (Eq. 4.33/4.40)
    scaled by ``moment_scale``. Residuals are in rad.
    """
    ns = sec_len.shape[0]
    m_tip, n1_tip = reduced_planar(theta0, z[0], z[1:], sec_len, sec_steps, c_i, u_rest, stretch,
                                   weight, False, ends[:, 0], ends, ends, ends)
    for i in range(n_angles):
        res[i] = ends[i, 2] - theta_target[i]
    if n_angles < ns:
        res[ns - 1] = (n1_tip + tip_shear_weight * math.cos(ends[ns - 1, 2])) * force_scale
    res[ns] = m_tip * moment_scale


@njit
def load_cell_spatial(quat0, n0, m0, sec_len, sec_steps, c_a, c_g, c_i, c_j, u1_rest, u2_rest,
                      v_rest, q, point, work, s_out, pos_out, tan_out, ends_out, frames_out):
    """Integrate the spatial equilibrium equations base → tip from a measured 6-axis wrench.

    The solver's rod statics and RK4 step (:func:`solver.rod.spatial_rhs`,
    :func:`solver.rod.spatial_rk4_step`; their m0-sensitivities start and stay at zero),
    with the internal force known from the measured n0: n' = −q, and each endplate's weight
    taken off at its section end.

    Args:
        quat0: (4,) base orientation quaternion. n0, m0: (3,) base force and moment, world.
        sec_len, sec_steps, c_a, c_g, c_i, c_j: (ns,) lengths, RK4 steps, 1/EA, 1/GA, 1/EI, 1/GJ.
        u1_rest, u2_rest, v_rest: (ns,) rest strains from the pressures.
        q: (ns, 3) distributed load (N/m); point: (ns, 3) point load at each section end (N).
        work: (8, NSTATE) scratch. s_out (N,), pos_out, tan_out (N, 3): samples, written.
        ends_out: (ns, 3) and frames_out: (ns, 3, 3): section-end positions and directors.

    Returns:
        |m(L)|, the tip moment (N m): zero for a consistent measurement.
    """
    y = work[0]
    rate = work[6]
    loads_i = work[7, :6]
    n_start = work[7, 6:9]
    moments = np.empty((sec_len.shape[0], 3))
    start_spatial_state(y, quat0, m0)
    for d in range(3):
        n_start[d] = n0[d]
    row = 0
    s0 = 0.0
    for i in range(sec_len.shape[0]):
        length = sec_len[i]
        h = length / sec_steps[i]
        for d in range(3):  # n(σ) = n_end + q·(L − σ)
            loads_i[SL_N + d] = n_start[d] - q[i, d] * length
            loads_i[SL_Q + d] = q[i, d]
        for j in range(sec_steps[i] + 1):
            spatial_rhs(j * h, y, rate, length, c_a[i], c_g[i], c_i[i], c_j[i], u1_rest[i],
                        u2_rest[i], v_rest[i], loads_i)
            s_out[row] = s0 + j * h
            for d in range(3):
                pos_out[row, d] = y[SP_R + d]
                tan_out[row, d] = rate[SP_R + d]
            row += 1
            if j == sec_steps[i]:
                break
            spatial_rk4_step(y, j * h, h, work, length, c_a[i], c_g[i], c_i[i], c_j[i],
                             u1_rest[i], u2_rest[i], v_rest[i], loads_i)
        record_spatial_row(y, ends_out, frames_out, moments, i)
        for d in range(3):
            n_start[d] = loads_i[SL_N + d] - point[i, d]
        s0 += length
    return math.sqrt(y[SP_M] ** 2 + y[SP_M + 1] ** 2 + y[SP_M + 2] ** 2)


# Spatial reduced-model state: r 0:3, R 3:12 (row-major), m 12:15, body shear (n1, n2) 15:17,
# ∫u1, ∫u2 over the current section 17:19.
REDUCED_STATE = 19


@njit
def _reduced_rhs_spatial(y, dy, ci, cj, u1r, u2r, v, q):
    """Spatial reduced model: r' = v·d3, R' = R[u]×, u = u* + C⁻¹Rᵀm, m' = −r' × R(n1, n2, 0),
    (n1, n2)' = −(Rᵀq)₁,₂ ± u3·(n2, n1) (axial force neglected), and ∫u1, ∫u2. Writes dy."""
    nb1 = y[15]
    nb2 = y[16]
    # World shear force n = n1·d1 + n2·d2 (columns 0 and 1 of R).
    nx = y[3] * nb1 + y[4] * nb2
    ny = y[6] * nb1 + y[7] * nb2
    nz = y[9] * nb1 + y[10] * nb2
    mb0 = y[3] * y[12] + y[6] * y[13] + y[9] * y[14]
    mb1 = y[4] * y[12] + y[7] * y[13] + y[10] * y[14]
    mb2 = y[5] * y[12] + y[8] * y[13] + y[11] * y[14]
    u0 = u1r + mb0 * ci
    u1 = u2r + mb1 * ci
    u2 = mb2 * cj
    for r in range(3):
        a = y[3 + 3 * r]
        b = y[4 + 3 * r]
        c = y[5 + 3 * r]
        dy[r] = v * c
        dy[3 + 3 * r] = b * u2 - c * u1
        dy[4 + 3 * r] = c * u0 - a * u2
        dy[5 + 3 * r] = a * u1 - b * u0
    dy[12] = -(dy[1] * nz - dy[2] * ny)
    dy[13] = -(dy[2] * nx - dy[0] * nz)
    dy[14] = -(dy[0] * ny - dy[1] * nx)
    qb0 = y[3] * q[0] + y[6] * q[1] + y[9] * q[2]
    qb1 = y[4] * q[0] + y[7] * q[1] + y[10] * q[2]
    dy[15] = -qb0 + u2 * nb2
    dy[16] = -qb1 - u2 * nb1
    dy[17] = u0
    dy[18] = u1


@njit
def reduced_spatial(rot0, m0, shear_start, sec_len, sec_steps, c_i, c_j, u1_rest, u2_rest, stretch,
                    q, record, work, s_out, pos_out, tan_out, ends_out, frames_out, curv_out):
    """One RK4 pass of the spatial reduced model base → tip (see :func:`_reduced_rhs_spatial`).

    Args:
        rot0: (3, 3) base directors. m0: (3,) base moment (N m, world).
        shear_start: (ns, 2) body shear (n1, n2) at the start of every section (N).
        sec_len, sec_steps, c_i, c_j: (ns,) lengths, steps, 1/EI, 1/GJ.
        u1_rest, u2_rest, stretch: (ns,) rest curvatures and the section stretch.
        q: (ns, 3) distributed load (N/m). record: write the samples.
        work: (6, 19) scratch; ``work[0, 12:15]`` holds m(L) on return.
        s_out, pos_out, tan_out: samples (written if record). ends_out (ns, 3), frames_out
        (ns, 3, 3): section-end poses. curv_out: (ns, 2) ∫u1, ∫u2 over each section (rad).
    """
    y = work[0]
    k1 = work[1]
    k2 = work[2]
    k3 = work[3]
    k4 = work[4]
    tmp = work[5]
    for d in range(REDUCED_STATE):
        y[d] = 0.0
    for r in range(3):
        for c in range(3):
            y[3 + 3 * r + c] = rot0[r, c]
        y[12 + r] = m0[r]
    row = 0
    s0 = 0.0
    for i in range(sec_len.shape[0]):
        h = sec_len[i] / sec_steps[i]
        y[15] = shear_start[i, 0]
        y[16] = shear_start[i, 1]
        y[17] = 0.0
        y[18] = 0.0
        args = (c_i[i], c_j[i], u1_rest[i], u2_rest[i], stretch[i])
        for j in range(sec_steps[i] + 1):
            _reduced_rhs_spatial(y, k1, *args, q[i])
            if record:
                s_out[row] = s0 + j * h
                for d in range(3):
                    pos_out[row, d] = y[d]
                    tan_out[row, d] = k1[d]
                row += 1
            if j == sec_steps[i]:
                break
            for d in range(REDUCED_STATE):
                tmp[d] = y[d] + 0.5 * h * k1[d]
            _reduced_rhs_spatial(tmp, k2, *args, q[i])
            for d in range(REDUCED_STATE):
                tmp[d] = y[d] + 0.5 * h * k2[d]
            _reduced_rhs_spatial(tmp, k3, *args, q[i])
            for d in range(REDUCED_STATE):
                tmp[d] = y[d] + h * k3[d]
            _reduced_rhs_spatial(tmp, k4, *args, q[i])
            for d in range(REDUCED_STATE):
                y[d] += (h / 6.0) * (k1[d] + 2.0 * k2[d] + 2.0 * k3[d] + k4[d])
        for r in range(3):
            ends_out[i, r] = y[r]
            for c in range(3):
                frames_out[i, r, c] = y[3 + 3 * r + c]
        curv_out[i, 0] = y[17]
        curv_out[i, 1] = y[18]
        s0 += sec_len[i]


CABLE_DATA, IMU_DATA = 0, 1
"""What the spatial reduced model is fitted to: the sections' ∫u1, ∫u2 (cable encoders) or
their end axes d3 in measured frames (IMUs)."""


@njit
def reduced_spatial_residual(z, model, data, out):
    """Boundary residual (2·ns + 3,) of the spatial reduced model at unknowns ``z`` (3 + 2·ns:
    m0, then (n1, n2) per section start), in rad: the misfit to the data per section, then
    m(L) over the moment scale.

    Args:
        model: (rot0, sec_len, sec_steps, c_i, c_j, u1_rest, u2_rest, stretch, q, work, s, pos,
            tan, ends, frames, curv, moment_scale) as :func:`reduced_spatial` takes them.
        data: (kind, target_curv (ns, 2), target_frames (ns, 3, 3)): ``CABLE_DATA`` matches
            ∫u1, ∫u2; ``IMU_DATA`` the two angles of each estimated end axis d3 off the
            measured frame's (atan2, so a reversed axis is no root).
    """
    (rot0, sec_len, sec_steps, c_i, c_j, u1_rest, u2_rest, stretch, q, work, s, pos, tan, ends,
     frames, curv, moment_scale) = model
    kind, target_curv, target_frames = data
    ns = sec_len.shape[0]
    reduced_spatial(rot0, z[:3], z[3:].reshape((ns, 2)), sec_len, sec_steps, c_i, c_j, u1_rest,
                    u2_rest, stretch, q, False, work, s, pos, tan, ends, frames, curv)
    for i in range(ns):
        if kind == CABLE_DATA:
            out[2 * i] = curv[i, 0] - target_curv[i, 0]
            out[2 * i + 1] = curv[i, 1] - target_curv[i, 1]
        else:
            x = y = w = 0.0
            for r in range(3):
                x += frames[i, r, 2] * target_frames[i, r, 0]
                y += frames[i, r, 2] * target_frames[i, r, 1]
                w += frames[i, r, 2] * target_frames[i, r, 2]
            out[2 * i] = math.atan2(x, w)
            out[2 * i + 1] = math.atan2(y, w)
    for d in range(3):
        out[2 * ns + d] = work[0, 12 + d] * moment_scale


@njit
def reduced_spatial_newton(z, unknown_scale, tol, max_iter, max_step, model, data, jac, jac_ok):
    """:func:`softarm_gym.sensing.estimators.damped_newton` on
    :func:`reduced_spatial_residual`, compiled (the spatial reduced model's Python Newton
    spent most of an estimate in calls): forward-difference Jacobian, steps clipped to
    ``max_step`` units of ``unknown_scale`` then halved until the residual's 2-norm falls.

    The Jacobian is kept between calls (``jac`` (n, n), valid while ``jac_ok[0]``): an
    estimator warm-starts from its previous estimate, where the last Jacobian nearly holds.
    Each step taken with it updates it by Broyden's rank-one rule (so a step costs one
    residual, not n + 1); it is rebuilt by differences only when a step with it does not cut
    the residual's 2-norm by 10 % (the step is then not taken): a quasi-Newton with refresh,
    converging to the same root. A fresh Jacobian whose step no halving improves, or three in a
    row that gain under 2 % of the merit, end the search unconverged: the start is in a valley
    of the merit, not near a root, and the caller tries another (a stalled start cost 60
    iterations' worth of residuals before). In place on ``z``; returns (converged,
    max |residual|)."""
    n = z.shape[0]
    res = np.empty(n)
    trial = np.empty(n)
    probe = np.empty(n)
    start = np.empty(n)
    reduced_spatial_residual(z, model, data, res)
    merit = 0.0
    for k in range(n):
        merit += res[k] * res[k]
    crawl = 0
    for it in range(max_iter + 1):
        err = 0.0
        for k in range(n):
            err = max(err, abs(res[k]))
        if not math.isfinite(err) or not (res == res).all():
            return False, math.inf
        if err <= tol:
            return True, err
        if it == max_iter:
            break
        if not jac_ok[0]:
            for j in range(n):
                h = 1e-6 * unknown_scale[j]
                keep = z[j]
                z[j] = keep + h
                reduced_spatial_residual(z, model, data, probe)
                for k in range(n):
                    jac[k, j] = (probe[k] - res[k]) / h
                z[j] = keep
            jac_ok[0] = True
            fresh = True
        else:
            fresh = False
        try:
            step = np.linalg.solve(jac, -res)
        except Exception:  # a singular Jacobian
            jac_ok[0] = False
            if fresh:
                return False, err
            continue
        worst = 0.0
        for k in range(n):
            worst = max(worst, abs(step[k]) / unknown_scale[k])
        shrink = min(1.0, max_step / worst) if worst > 0 else 1.0
        for k in range(n):
            step[k] *= shrink
            start[k] = z[k]
        scale = 1.0
        trial_merit = merit
        for _ in range(21):
            for k in range(n):
                z[k] = start[k] + scale * step[k]
            reduced_spatial_residual(z, model, data, trial)
            trial_merit = 0.0
            for k in range(n):
                trial_merit += trial[k] * trial[k]
            if trial_merit < merit and (fresh or scale == 1.0):
                break
            if not fresh:
                break  # a kept Jacobian that needs halving is stale: rebuild it instead
            scale *= 0.5
        if fresh and not trial_merit < merit:
            # A fresh Jacobian's direction that no step length improves: Newton has stalled
            # here (a local minimum of the merit); the caller tries another start.
            for k in range(n):
                z[k] = start[k]
            break
        # Fresh Jacobians that gain under 2 % of the merit three times running: a crawl
        # along a valley of the merit, not a descent to a root.
        if fresh:
            crawl = 0 if trial_merit < 0.98 * merit else crawl + 1
            if crawl >= 3:
                break
        if not fresh and not trial_merit < 0.81 * merit:
            jac_ok[0] = False  # too slow a contraction: the kept Jacobian is stale
            for k in range(n):
                z[k] = start[k]  # and the step is not taken
            continue
        # Broyden's update along the step taken: J += (Δr − J Δz) Δzᵀ / |Δz|².
        dz2 = 0.0
        for k in range(n):
            dz2 += (z[k] - start[k]) ** 2
        if dz2 > 0.0:
            for r in range(n):
                mismatch = trial[r] - res[r]
                for k in range(n):
                    mismatch -= jac[r, k] * (z[k] - start[k])
                mismatch /= dz2
                for k in range(n):
                    jac[r, k] += mismatch * (z[k] - start[k])
        for k in range(n):
            res[k] = trial[k]
        merit = trial_merit
    err = 0.0
    for k in range(n):
        err = max(err, abs(res[k]))
    return False, err


@njit
def planar_shape(s, pos, theta, strain, ends, s_query, backbone, section_ends, tangent):
    """The ``true`` shape of a recorded planar equilibrium in one pass.

    Tangent dr/ds = v3 d3 + v1 d1 at every sample (``strain`` columns v1, v3), section-end
    poses (x, y, θ) into ``section_ends``, the backbone resampled at ``s_query`` by cubic
    Hermite into ``backbone``; ``tangent`` is (N, 2) scratch.
    """
    for r in range(s.shape[0]):
        c = math.cos(theta[r])
        sn = math.sin(theta[r])
        tangent[r, 0] = strain[r, 1] * c - strain[r, 0] * sn
        tangent[r, 1] = strain[r, 1] * sn + strain[r, 0] * c
    for i in range(ends.shape[0]):
        section_ends[i, 0] = pos[ends[i], 0]
        section_ends[i, 1] = pos[ends[i], 1]
        section_ends[i, 2] = theta[ends[i]]
    hermite_resample(s, pos, tangent, s_query, backbone)
    last = s.shape[0] - 1
    backbone[backbone.shape[0] - 1, 0] = pos[last, 0]
    backbone[backbone.shape[0] - 1, 1] = pos[last, 1]
