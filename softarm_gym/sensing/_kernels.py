"""numba kernels of the sensing package: quadrature, resampling and backbone integration.

Every kernel takes float arrays and writes into preallocated outputs; the validated public
wrappers live in :mod:`softarm_gym.sensing.sensors` and :mod:`softarm_gym.sensing.estimators`.
"""

from __future__ import annotations

import math

from solver._jit import njit


@njit
def _section_integrals(s, integrand, ends, out):
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
def _planar_cable_integrand(shear_stretch, curvature, radius, out):
    """Planar cable integrands √((v3 ∓ R·u)² + v1²) for the +R·d1 and −R·d1 cables, (N, 2)."""
    for k in range(curvature.shape[0]):
        v1 = shear_stretch[k, 0]
        v3 = shear_stretch[k, 1]
        ru = radius * curvature[k]
        out[k, 0] = math.sqrt((v3 - ru) ** 2 + v1 * v1)
        out[k, 1] = math.sqrt((v3 + ru) ** 2 + v1 * v1)


@njit
def _hermite_resample(s, pos, tangent, s_query, out):
    """Cubic Hermite interpolation of a backbone at reference arc lengths ``s_query``.

    Args:
        s: (N,) non-decreasing sample arc lengths (m); repeated values (section junctions)
            are zero-length intervals and are skipped.
        pos: (N, D) positions (m). tangent: (N, D) dr/ds at the samples.
        s_query: (K,) increasing query arc lengths within [s[0], s[-1]] (m).
        out: (K, D) written.
    """
    n = s.shape[0]
    dim = pos.shape[1]
    j = 0
    for k in range(s_query.shape[0]):
        q = s_query[k]
        while j < n - 2 and (s[j + 1] < q or s[j + 1] <= s[j]):
            j += 1
        h = s[j + 1] - s[j]
        if h <= 0.0:
            for d in range(dim):
                out[k, d] = pos[j + 1, d]
            continue
        t = (q - s[j]) / h
        t2 = t * t
        t3 = t2 * t
        h00 = 2.0 * t3 - 3.0 * t2 + 1.0
        h10 = t3 - 2.0 * t2 + t
        h01 = -2.0 * t3 + 3.0 * t2
        h11 = t3 - t2
        for d in range(dim):
            out[k, d] = (h00 * pos[j, d] + h10 * h * tangent[j, d] + h01 * pos[j + 1, d]
                         + h11 * h * tangent[j + 1, d])


@njit
def _arc_chain_planar(theta0, sec_len, curvature, stretch, s_query, backbone, ends):
    """Planar chain of circular arcs (constant curvature and stretch per section, no shear).

    Args:
        theta0: base orientation θ0 of d3 (rad).
        sec_len: (n_sections,) reference lengths (m).
        curvature: (n_sections,) dθ/ds per reference length (rad/m).
        stretch: (n_sections,) axial stretch v3.
        s_query: (K,) increasing reference arc lengths in [0, L] (m).
        backbone: (K, 2) written: positions at ``s_query`` (m).
        ends: (n_sections, 3) written: (x, y, θ) at each section end.
    """
    x = 0.0
    y = 0.0
    th = theta0
    s0 = 0.0
    k = 0
    ns = sec_len.shape[0]
    for i in range(ns):
        last = i == ns - 1
        while k < s_query.shape[0] and (s_query[k] <= s0 + sec_len[i] or last):
            px, py, _ = _arc_point(x, y, th, curvature[i], stretch[i], s_query[k] - s0)
            backbone[k, 0] = px
            backbone[k, 1] = py
            k += 1
        x, y, th = _arc_point(x, y, th, curvature[i], stretch[i], sec_len[i])
        ends[i, 0] = x
        ends[i, 1] = y
        ends[i, 2] = th
        s0 += sec_len[i]


@njit
def _arc_point(x, y, th, kappa, stretch, sig):
    """Pose after ``sig`` of reference arc length along an arc (x, y, θ start)."""
    dth = kappa * sig
    if abs(dth) < 1e-9:
        c = 1.0 - dth * dth / 6.0
        d = dth / 2.0
    else:
        c = math.sin(dth) / dth
        d = (1.0 - math.cos(dth)) / dth
    ell = stretch * sig
    ct = math.cos(th)
    st = math.sin(th)
    # Chord in the local frame (along d3, along the bending normal), rotated to the world.
    return x + ell * (c * ct - d * st), y + ell * (c * st + d * ct), th + dth


@njit
def _wrench_rhs(sig, th, m, ca, cg, ci, ur, vr, nx0, ny0, qx, qy):
    """Planar rod statics with the internal force n(σ) = n_start − q·σ (world frame)."""
    nx = nx0 - qx * sig
    ny = ny0 - qy * sig
    c = math.cos(th)
    sn = math.sin(th)
    n1 = -nx * sn + ny * c
    n3 = nx * c + ny * sn
    v1 = n1 * cg
    v3 = vr + n3 * ca
    return ur + m * ci, v1 * n3 - v3 * n1, v3 * c - v1 * sn, v3 * sn + v1 * c


@njit
def _load_cell_planar(theta0, n0x, n0y, m0, sec_len, sec_steps, c_a, c_g, c_i, u_rest, v_rest,
                      q, point, s_out, pos_out, tan_out, ends_out):
    """Integrate the planar equilibrium equations base → tip from a measured base wrench (§4.2.1).

    Same rod statics as the solver (DESIGN §2): θ' = u* + m/EI, m' = v1 n3 − v3 n1,
    v1 = n1/GA, v3 = v* + n3/EA, r' = v3 d3 + v1 d1, with n(s) = n0 − ∫₀ˢ q − Σ point loads
    passed (the weight of the nominal arm is known; an unknown tip payload is already in n0).
    Fixed-step RK4 on (θ, m, x, y).

    Args:
        theta0: base orientation (rad). n0x, n0y, m0: measured base wrench (N, N, N m).
        sec_len, sec_steps: (ns,) section lengths (m) and RK4 steps per section.
        c_a, c_g, c_i: (ns,) compliances 1/EA, 1/GA, 1/EI.
        u_rest, v_rest: (ns,) rest curvature (rad/m) and stretch from the pressures.
        q: (ns, 2) distributed load per reference length (N/m); point: (ns, 2) point load at
            each section end (endplate weight) (N).
        s_out: (Σ(steps + 1),) written: arc length of the samples (junctions repeated).
        pos_out, tan_out: (Σ(steps + 1), 2) written: positions and dr/ds.
        ends_out: (ns, 3) written: (x, y, θ) at each section end.

    Returns:
        The tip moment m(L) (N m): zero for a consistent measurement.
    """
    th = theta0
    m = m0
    x = 0.0
    y = 0.0
    nx = n0x
    ny = n0y
    s0 = 0.0
    row = 0
    for i in range(sec_len.shape[0]):
        h = sec_len[i] / sec_steps[i]
        ca = c_a[i]
        cg = c_g[i]
        ci = c_i[i]
        ur = u_rest[i]
        vr = v_rest[i]
        qx = q[i, 0]
        qy = q[i, 1]
        for j in range(sec_steps[i] + 1):
            sig = j * h
            d = _wrench_rhs(sig, th, m, ca, cg, ci, ur, vr, nx, ny, qx, qy)
            s_out[row] = s0 + sig
            pos_out[row, 0] = x
            pos_out[row, 1] = y
            tan_out[row, 0] = d[2]
            tan_out[row, 1] = d[3]
            row += 1
            if j == sec_steps[i]:
                break
            hh = 0.5 * h
            k2 = _wrench_rhs(sig + hh, th + hh * d[0], m + hh * d[1], ca, cg, ci, ur, vr, nx, ny,
                             qx, qy)
            k3 = _wrench_rhs(sig + hh, th + hh * k2[0], m + hh * k2[1], ca, cg, ci, ur, vr, nx, ny,
                             qx, qy)
            k4 = _wrench_rhs(sig + h, th + h * k3[0], m + h * k3[1], ca, cg, ci, ur, vr, nx, ny,
                             qx, qy)
            w = h / 6.0
            th += w * (d[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            m += w * (d[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            x += w * (d[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
            y += w * (d[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
        ends_out[i, 0] = x
        ends_out[i, 1] = y
        ends_out[i, 2] = th
        nx = nx - qx * sec_len[i] - point[i, 0]
        ny = ny - qy * sec_len[i] - point[i, 1]
        s0 += sec_len[i]
    return m


@njit
def _reduced_rhs(th, m, n1, ci, ur, v, w):
    """The chapter-4 reduced model: θ' = u* + m/EI, m' = −v·n1, n1' = w·cos θ; r' = v·d3."""
    c = math.cos(th)
    return ur + m * ci, -v * n1, w * c, v * c, v * math.sin(th)


@njit
def _reduced_planar(theta0, m0, n1_start, sec_len, sec_steps, c_i, u_rest, stretch, weight,
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
def _reduced_residual(z, theta0, sec_len, sec_steps, c_i, u_rest, stretch, weight, theta_target,
                      n_angles, tip_shear_weight, moment_scale, force_scale, ends, res):
    """Boundary residuals of the reduced model for unknowns z = (m0, n1_start[0..ns−1]).

    Rows: θ(s_i) − θ_target[i] for the first ``n_angles`` section ends; then, if
    n_angles < ns, the known tip shear n1(L) + W_tip·cos θ(L) (Eq. 4.41, W_tip the known tip
    weight, N) scaled by ``force_scale``; last, the free-tip moment m(L) (Eq. 4.33/4.40)
    scaled by ``moment_scale``. Residuals are in rad.
    """
    ns = sec_len.shape[0]
    m_tip, n1_tip = _reduced_planar(theta0, z[0], z[1:], sec_len, sec_steps, c_i, u_rest, stretch,
                                    weight, False, ends[:, 0], ends, ends, ends)
    for i in range(n_angles):
        res[i] = ends[i, 2] - theta_target[i]
    if n_angles < ns:
        res[ns - 1] = (n1_tip + tip_shear_weight * math.cos(ends[ns - 1, 2])) * force_scale
    res[ns] = m_tip * moment_scale


# Spatial load-cell state: r 0:3, R 3:12 (row-major), m 12:15.
SPATIAL_STATE = 15


@njit
def _wrench_rhs_spatial(sig, y, dy, ca, cg, ci, cj, u1r, u2r, v3r, n_start, q):
    """Spatial rod statics with n(σ) = n_start − q·σ: r' = R v, R' = R[u]×, m' = −r' × n.

    v = (n_b1/GA, n_b2/GA, v* + n_b3/EA), u = (u1* + m_b1/EI, u2* + m_b2/EI, m_b3/GJ), with
    n_b = Rᵀn, m_b = Rᵀm. Writes dy (15,); no allocation.
    """
    n0 = n_start[0] - q[0] * sig
    n1 = n_start[1] - q[1] * sig
    n2 = n_start[2] - q[2] * sig
    m0 = y[12]
    m1 = y[13]
    m2 = y[14]
    nb = (y[3] * n0 + y[6] * n1 + y[9] * n2, y[4] * n0 + y[7] * n1 + y[10] * n2,
          y[5] * n0 + y[8] * n1 + y[11] * n2)
    mb = (y[3] * m0 + y[6] * m1 + y[9] * m2, y[4] * m0 + y[7] * m1 + y[10] * m2,
          y[5] * m0 + y[8] * m1 + y[11] * m2)
    v0 = nb[0] * cg
    v1 = nb[1] * cg
    v2 = v3r + nb[2] * ca
    u0 = u1r + mb[0] * ci
    u1 = u2r + mb[1] * ci
    u2 = mb[2] * cj
    for r in range(3):
        a = y[3 + 3 * r]
        b = y[4 + 3 * r]
        c = y[5 + 3 * r]
        dy[r] = a * v0 + b * v1 + c * v2
        # Row r of R[u]×: [a b c]·[[0, −u2, u1], [u2, 0, −u0], [−u1, u0, 0]].
        dy[3 + 3 * r] = b * u2 - c * u1
        dy[4 + 3 * r] = c * u0 - a * u2
        dy[5 + 3 * r] = a * u1 - b * u0
    dy[12] = -(dy[1] * n2 - dy[2] * n1)
    dy[13] = -(dy[2] * n0 - dy[0] * n2)
    dy[14] = -(dy[0] * n1 - dy[1] * n0)


@njit
def _load_cell_spatial(rot0, n0, m0, sec_len, sec_steps, c_a, c_g, c_i, c_j, u1_rest, u2_rest,
                       v_rest, q, point, work, s_out, pos_out, tan_out, ends_out, frames_out):
    """Integrate the spatial equilibrium equations base → tip from a measured 6-axis wrench.

    Args:
        rot0: (3, 3) base directors. n0, m0: (3,) base force and moment, world frame.
        sec_len, sec_steps, c_a, c_g, c_i, c_j: (ns,) lengths, RK4 steps, 1/EA, 1/GA, 1/EI, 1/GJ.
        u1_rest, u2_rest, v_rest: (ns,) rest strains from the pressures.
        q: (ns, 3) distributed load (N/m); point: (ns, 3) point load at each section end (N).
        work: (7, 15) scratch. s_out (N,), pos_out, tan_out (N, 3): samples, written.
        ends_out: (ns, 3) and frames_out: (ns, 3, 3): section-end positions and directors.

    Returns:
        |m(L)|, the tip moment (N m): zero for a consistent measurement.
    """
    y = work[0]
    k1 = work[1]
    k2 = work[2]
    k3 = work[3]
    k4 = work[4]
    tmp = work[5]
    n_start = work[6, 0:3]
    for d in range(SPATIAL_STATE):
        y[d] = 0.0
    for r in range(3):
        for c in range(3):
            y[3 + 3 * r + c] = rot0[r, c]
        y[12 + r] = m0[r]
        n_start[r] = n0[r]
    row = 0
    s0 = 0.0
    for i in range(sec_len.shape[0]):
        h = sec_len[i] / sec_steps[i]
        args = (c_a[i], c_g[i], c_i[i], c_j[i], u1_rest[i], u2_rest[i], v_rest[i])
        for j in range(sec_steps[i] + 1):
            sig = j * h
            _wrench_rhs_spatial(sig, y, k1, *args, n_start, q[i])
            s_out[row] = s0 + sig
            for d in range(3):
                pos_out[row, d] = y[d]
                tan_out[row, d] = k1[d]
            row += 1
            if j == sec_steps[i]:
                break
            for d in range(SPATIAL_STATE):
                tmp[d] = y[d] + 0.5 * h * k1[d]
            _wrench_rhs_spatial(sig + 0.5 * h, tmp, k2, *args, n_start, q[i])
            for d in range(SPATIAL_STATE):
                tmp[d] = y[d] + 0.5 * h * k2[d]
            _wrench_rhs_spatial(sig + 0.5 * h, tmp, k3, *args, n_start, q[i])
            for d in range(SPATIAL_STATE):
                tmp[d] = y[d] + h * k3[d]
            _wrench_rhs_spatial(sig + h, tmp, k4, *args, n_start, q[i])
            for d in range(SPATIAL_STATE):
                y[d] += (h / 6.0) * (k1[d] + 2.0 * k2[d] + 2.0 * k3[d] + k4[d])
        for r in range(3):
            ends_out[i, r] = y[r]
            for c in range(3):
                frames_out[i, r, c] = y[3 + 3 * r + c]
            n_start[r] = n_start[r] - q[i, r] * sec_len[i] - point[i, r]
        s0 += sec_len[i]
    return math.sqrt(y[12] ** 2 + y[13] ** 2 + y[14] ** 2)


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
def _reduced_spatial(rot0, m0, shear_start, sec_len, sec_steps, c_i, c_j, u1_rest, u2_rest, stretch,
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


@njit
def _arc_relative(k0, k1, kappa, stretch, sig, rel_pos, rel_rot):
    """Pose after ``sig`` along an arc of body curvature κ·(k0, k1, 0), no shear or torsion.

    Rodrigues: R = I + sin φ·K + (1 − cos φ)·K², K = [k]×, φ = κσ; and
    r = v·∫₀^σ R e3 = v·σ·((1 − cos φ)/φ·(k1, −k0, 0) + (sin φ/φ)·e3). Writes rel_pos (3,),
    rel_rot (3, 3).
    """
    phi = kappa * sig
    if abs(phi) < 1e-9:
        a = 1.0 - phi * phi / 6.0
        b = phi / 2.0
    else:
        a = math.sin(phi) / phi
        b = (1.0 - math.cos(phi)) / phi
    ell = stretch * sig
    rel_pos[0] = ell * b * k1
    rel_pos[1] = -ell * b * k0
    rel_pos[2] = ell * a
    s = math.sin(phi)
    c = 1.0 - math.cos(phi)
    rel_rot[0, 0] = 1.0 - c * k1 * k1
    rel_rot[0, 1] = c * k0 * k1
    rel_rot[0, 2] = s * k1
    rel_rot[1, 0] = c * k0 * k1
    rel_rot[1, 1] = 1.0 - c * k0 * k0
    rel_rot[1, 2] = -s * k0
    rel_rot[2, 0] = -s * k1
    rel_rot[2, 1] = s * k0
    rel_rot[2, 2] = 1.0 - c * (k0 * k0 + k1 * k1)


@njit
def _arc_chain_spatial(rot0, sec_len, curvature, stretch, s_query, work, backbone, ends, frames):
    """Spatial chain of arcs (constant body curvature (u1, u2, 0) and stretch per section).

    Args:
        rot0: (3, 3) base directors. sec_len, stretch: (ns,). curvature: (ns, 2) (u1, u2) (rad/m).
        s_query: (K,) increasing reference arc lengths in [0, L] (m).
        work: (4, 3, 3) scratch (frame, relative rotation, product, relative position in row 0).
        backbone: (K, 3) written. ends: (ns, 3) and frames: (ns, 3, 3) written.
    """
    rot = work[0]
    rel_rot = work[1]
    prod = work[2]
    rel_pos = work[3, 0]
    for r in range(3):
        for c in range(3):
            rot[r, c] = rot0[r, c]
    x0 = 0.0
    x1 = 0.0
    x2 = 0.0
    s0 = 0.0
    k = 0
    ns = sec_len.shape[0]
    for i in range(ns):
        kappa = math.hypot(curvature[i, 0], curvature[i, 1])
        k0 = curvature[i, 0] / kappa if kappa > 0.0 else 0.0
        k1 = curvature[i, 1] / kappa if kappa > 0.0 else 0.0
        while k < s_query.shape[0] and (s_query[k] <= s0 + sec_len[i] or i == ns - 1):
            _arc_relative(k0, k1, kappa, stretch[i], s_query[k] - s0, rel_pos, rel_rot)
            backbone[k, 0] = x0 + rot[0, 0] * rel_pos[0] + rot[0, 1] * rel_pos[1] + rot[0, 2] * rel_pos[2]
            backbone[k, 1] = x1 + rot[1, 0] * rel_pos[0] + rot[1, 1] * rel_pos[1] + rot[1, 2] * rel_pos[2]
            backbone[k, 2] = x2 + rot[2, 0] * rel_pos[0] + rot[2, 1] * rel_pos[1] + rot[2, 2] * rel_pos[2]
            k += 1
        _arc_relative(k0, k1, kappa, stretch[i], sec_len[i], rel_pos, rel_rot)
        x0 += rot[0, 0] * rel_pos[0] + rot[0, 1] * rel_pos[1] + rot[0, 2] * rel_pos[2]
        x1 += rot[1, 0] * rel_pos[0] + rot[1, 1] * rel_pos[1] + rot[1, 2] * rel_pos[2]
        x2 += rot[2, 0] * rel_pos[0] + rot[2, 1] * rel_pos[1] + rot[2, 2] * rel_pos[2]
        for r in range(3):
            for c in range(3):
                prod[r, c] = rot[r, 0] * rel_rot[0, c] + rot[r, 1] * rel_rot[1, c] + rot[r, 2] * rel_rot[2, c]
        for r in range(3):
            for c in range(3):
                rot[r, c] = prod[r, c]
                frames[i, r, c] = prod[r, c]
        ends[i, 0] = x0
        ends[i, 1] = x1
        ends[i, 2] = x2
        s0 += sec_len[i]


@njit
def _planar_shape(s, pos, theta, strain, ends, s_query, backbone, section_ends, tangent):
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
    _hermite_resample(s, pos, tangent, s_query, backbone)
    last = s.shape[0] - 1
    backbone[backbone.shape[0] - 1, 0] = pos[last, 0]
    backbone[backbone.shape[0] - 1, 1] = pos[last, 1]
