"""numba kernels of the sensing package: quadrature, resampling and backbone integration.

Every kernel takes float arrays and writes into preallocated outputs; the validated public
wrappers live in :mod:`softarm_gym.sensing.sensors` and :mod:`softarm_gym.sensing.estimators`.
"""

from __future__ import annotations

import math

from solver._jit import njit


@njit
def _section_integrals(s, integrand, starts, ends, out):
    """Cumulative integrals of sampled functions over consecutive sections.

    Composite Simpson's rule on the uniform samples of each section (Simpson 3/8 on the last
    three intervals when a section has an odd number of intervals; trapezoid for one interval).

    Args:
        s: (N,) reference arc length of the samples (m), uniform within a section.
        integrand: (N, C) sampled functions, one column per cable.
        starts, ends: (n_sections,) int sample indices of each section's first and last sample.
        out: (n_sections, C) written: integral from the base to the end of each section.
    """
    n_cols = integrand.shape[1]
    for c in range(n_cols):
        total = 0.0
        for i in range(starts.shape[0]):
            a = starts[i]
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
