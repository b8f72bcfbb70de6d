"""Energy of the planar discrete rod, for snapping where path following cannot go on.

Where a quasi-static path reaches a fold the arm snaps: it moves dynamically to another
stable equilibrium. The multiple-shooting kernels of :mod:`solver.kernels.contact` find equilibria
by Newton, which needs a start inside the basin of the state the arm lands in; they have no
way to look for it. This module gives them one: the total potential energy of the rod,
discretised on the shooting grid, whose local minimisation from the last state before the
fold (damped motion, in effect) lands on a stable equilibrium near the one the arm falls
into. Newton on the shooting system then polishes it.

The discrete rod: nodes k = 0..N at the samples of the shooting layout (section junctions
not repeated), element e between nodes e and e + 1 of length h_e in section i. Unknowns:
node angles θ_1..θ_N (θ_0 is the clamped base) and per element the shear v1_e and the
stretch deviation w_e = v3_e − v*_i. Positions r_{e+1} = r_e + h_e (v3_e d3 + v1_e d1) at the
mid angle (θ_e + θ_{e+1})/2. Energy

    Σ_e h_e [½EI (Δθ/h − u*)² + ½EA w² + ½GA v1²]     (strain energy of the Cosserat rod)
    − Σ_e h_e q·(r_e + r_{e+1})/2 − Σ_i W_i·r(end of i) − F·r_N − M θ_N     (dead loads)
    + Σ_k ω_k Φ(pen_d(r_k))                                                (penalty contact)

with ω_k the trapezoid weights and Φ the penalty potential ½ k pen²
(:func:`solver.kernels.obstacles.penalty_energy`). The unshearable model (1/GA = 0) fixes v1 = 0.

The minimiser is L-BFGS in one kernel call (:func:`minimise`: Nocedal & Wright's two-loop
recursion over the last LBFGS_MEMORY steps, a strong-Wolfe line search, Algorithms 7.4, 3.5
and 3.6), run to the bottom of the basin as the path's snaps need: until the energy stops
falling in floating point. A snap used to spend two thirds of its relaxation in scipy's
L-BFGS-B's Python loop around this module's energy (docs/design.md §10.1).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.obstacles import penalty_energy
from solver.layout import (
    C_TH,
    C_V1,
    C_V3,
    CA,
    CG,
    CI,
    CX,
    CY,
    LEN,
    RADIUS,
    SC_EXCLUSION,
    SC_HALF,
    SC_K,
    STIFFNESS,
)


@njit
def _positions(theta0, x, sec_of, h, v_rest, pos, mid_c, mid_s):
    """Node positions (N + 1, 2) of the unknowns ``x`` and each element's mid-angle cos, sin."""
    n = h.shape[0]
    pos[0, 0] = 0.0
    pos[0, 1] = 0.0
    for e in range(n):
        th_a = theta0 if e == 0 else x[e - 1]
        th_b = x[e]
        phi = 0.5 * (th_a + th_b)
        c = math.cos(phi)
        s = math.sin(phi)
        mid_c[e] = c
        mid_s[e] = s
        v1 = x[n + e]
        v3 = v_rest[sec_of[e]] + x[2 * n + e]
        pos[e + 1, 0] = pos[e, 0] + h[e] * (v3 * c - v1 * s)
        pos[e + 1, 1] = pos[e, 1] + h[e] * (v3 * s + v1 * c)


@njit
def _self_contact(pos, h, node_s, node_h, self_k, exclusion, force, sign):
    """Energy (J) of self-contact between nodes farther apart along the arc than
    ``exclusion`` (m), and its forces added to ``force`` times ``sign`` (−1: dV/dr, +1: the
    external force): a pair (a, b) within h_a + h_b of each other stores
    ½ (k/R) w_a w_b (R − d)², R = h_a + h_b, w the nodes' shares of the arc. A node-to-node
    stand-in for the solver's node-to-curve law (:mod:`solver.kernels.self_contact`), which the
    Newton polish of a relaxed state then applies: it only has to keep the relaxation from
    passing the arm through itself."""
    n = h.shape[0]
    energy = 0.0
    if self_k <= 0.0:
        return energy
    for a in range(n + 1):
        wa = 0.5 * ((h[a - 1] if a > 0 else 0.0) + (h[a] if a < n else 0.0))
        for b in range(a + 1, n + 1):
            if node_s[b] - node_s[a] <= exclusion:
                continue
            reach = node_h[a] + node_h[b]
            dx = pos[a, 0] - pos[b, 0]
            dy = pos[a, 1] - pos[b, 1]
            dist = math.sqrt(dx * dx + dy * dy)
            pen = reach - dist
            if pen > 0.0 and dist > 0.0:
                wb = 0.5 * ((h[b - 1] if b > 0 else 0.0) + (h[b] if b < n else 0.0))
                stiffness = self_k * wa * wb / reach
                energy += 0.5 * stiffness * pen * pen
                push = sign * stiffness * pen / dist
                force[a, 0] += push * dx
                force[a, 1] += push * dy
                force[b, 0] -= push * dx
                force[b, 1] -= push * dy
    return energy


@njit
def energy_and_gradient(x, theta0, sec_of, h, secf, u_rest, v_rest, q, plate_at, plate,
                        tip_force, tip_moment, discs, self_params, grad):
    """Total potential energy (J) of the discrete rod at unknowns ``x`` (3N,) = (θ_1..θ_N,
    v1_0..v1_{N−1}, w_0..w_{N−1}); its gradient into ``grad`` (3N,).

    Args:
        theta0: base angle (rad). sec_of: (N,) section of each element. h: (N,) lengths (m).
        secf: (6, ns) section array. u_rest, v_rest: (ns,) rest curvature and stretch.
        q: (ns, 2) distributed load (N/m). plate_at: (ns,) node index of each section end;
        plate: (ns, 2) endplate weight there (N), the last one at the tip node.
        tip_force: (2,) tip force and payload weight (N). tip_moment: N m.
        discs: (k, 4) obstacles. self_params: (node_s (N + 1,), node_h (N + 1,), k,
            exclusion) of self-contact (k = 0: none; :func:`_self_contact`).
    """
    n = h.shape[0]
    pos = np.empty((n + 1, 2))
    mid_c = np.empty(n)
    mid_s = np.empty(n)
    _positions(theta0, x, sec_of, h, v_rest, pos, mid_c, mid_s)
    # dV/dr at every node (minus the external force there).
    force = np.zeros((n + 1, 2))
    e_total = _self_contact(pos, h, self_params[0], self_params[1], self_params[2],
                            self_params[3], force, -1.0)
    for e in range(n):
        i = sec_of[e]
        for d in range(2):
            half = 0.5 * h[e] * q[i, d]
            force[e, d] -= half
            force[e + 1, d] -= half
            e_total -= half * (pos[e, d] + pos[e + 1, d])
    for i in range(plate.shape[0]):
        k = plate_at[i]
        for d in range(2):
            force[k, d] -= plate[i, d]
            e_total -= plate[i, d] * pos[k, d]
    for d in range(2):
        force[n, d] -= tip_force[d]
        e_total -= tip_force[d] * pos[n, d]
    for k in range(n + 1):
        w = 0.5 * ((h[k - 1] if k > 0 else 0.0) + (h[k] if k < n else 0.0))
        for dd in range(discs.shape[0]):
            dx = pos[k, 0] - discs[dd, CX]
            dy = pos[k, 1] - discs[dd, CY]
            dist = math.sqrt(dx * dx + dy * dy)
            pen = discs[dd, RADIUS] - dist
            if pen > 0.0 and dist > 0.0:
                e_total += w * penalty_energy(pen, discs[dd, STIFFNESS])
                push = w * discs[dd, STIFFNESS] * pen / dist
                force[k, 0] -= push * dx
                force[k, 1] -= push * dy
    for k in range(grad.shape[0]):
        grad[k] = 0.0
    # Tail sums T_e = Σ_{m > e} dV/dr_m: the sensitivity of V to element e's chord.
    tail_x = 0.0
    tail_y = 0.0
    th_last = x[n - 1]
    e_total -= tip_moment * th_last
    grad[n - 1] -= tip_moment
    for e in range(n - 1, -1, -1):
        tail_x += force[e + 1, 0]
        tail_y += force[e + 1, 1]
        i = sec_of[e]
        c = mid_c[e]
        s = mid_s[e]
        v1 = x[n + e]
        w = x[2 * n + e]
        v3 = v_rest[i] + w
        th_a = theta0 if e == 0 else x[e - 1]
        kappa = (x[e] - th_a) / h[e] - u_rest[i]
        ei = 1.0 / secf[CI, i]
        e_total += 0.5 * h[e] * ei * kappa * kappa
        m = ei * kappa
        grad[e] += m
        if e > 0:
            grad[e - 1] -= m
        # Chord Δ_e = h (v3 d3 + v1 d1); ∂Δ/∂φ = h (v3 d1 − v1 d3), φ the mid angle.
        dphi = h[e] * (tail_x * (-v3 * s - v1 * c) + tail_y * (v3 * c - v1 * s))
        grad[e] += 0.5 * dphi
        if e > 0:
            grad[e - 1] += 0.5 * dphi
        e_total += 0.5 * h[e] * w * w / secf[CA, i]
        grad[2 * n + e] = h[e] * (w / secf[CA, i] + tail_x * c + tail_y * s)
        if secf[CG, i] > 0.0:
            e_total += 0.5 * h[e] * v1 * v1 / secf[CG, i]
            grad[n + e] = h[e] * (v1 / secf[CG, i] - tail_x * s + tail_y * c)
    return e_total


GRADIENT_TOL = 1e-12
"""The scaled gradient's largest entry at which a relaxation stops (J per unit of the scaled
unknowns: far below what any snap reaches first, the energy's floating-point floor)."""

LBFGS_MEMORY = 10
"""Step pairs the L-BFGS inverse Hessian keeps."""

WOLFE_DECREASE, WOLFE_CURVATURE = 1e-4, 0.9
"""The strong Wolfe conditions' constants (sufficient decrease, curvature)."""

LINE_SEARCH_EVALUATIONS = 20
"""Energy evaluations one line search may spend before the minimisation stops."""


@njit
def _dot(a, b):
    """aᵀb of two (n,) vectors (a loop: no BLAS call, so no BLAS threads, in the minimiser)."""
    total = 0.0
    for i in range(a.shape[0]):
        total += a[i] * b[i]
    return total


@njit
def _largest(v):
    """max |v_i| of an (n,) vector, inf if one is not finite (a loop: no temporary array at
    every iteration)."""
    top = 0.0
    for i in range(v.shape[0]):
        size = abs(v[i])
        if not math.isfinite(size):
            return math.inf
        if size > top:
            top = size
    return top


@njit
def _scaled_energy(y, scale, x, grad, args):
    """The energy (J) at the scaled unknowns ``y`` (x = y·scale) and its gradient with
    respect to y into ``grad``; ``args`` are :func:`energy_and_gradient`'s after ``x``."""
    for i in range(y.shape[0]):
        x[i] = y[i] * scale[i]
    energy = energy_and_gradient(x, args[0], args[1], args[2], args[3], args[4], args[5], args[6],
                                 args[7], args[8], args[9], args[10], args[11], args[12], grad)
    for i in range(y.shape[0]):
        grad[i] *= scale[i]
    return energy


@njit
def _cubic_minimiser(a, fa, da, b, fb, db):
    """The minimiser of the cubic through (a, fa) and (b, fb) with slopes da, db, kept inside
    the interval's middle 80 % (bisection where the cubic has none there)."""
    if a == b:
        return a
    lo, hi = min(a, b), max(a, b)
    d1 = da + db - 3.0 * (fa - fb) / (a - b)
    radicand = d1 * d1 - da * db
    guess = 0.5 * (a + b)
    if radicand >= 0.0:
        d2 = math.copysign(math.sqrt(radicand), b - a)
        denominator = db - da + 2.0 * d2
        if denominator != 0.0:
            guess = b - (b - a) * (db + d2 - d1) / denominator
    margin = 0.1 * (hi - lo)
    if not (lo + margin <= guess <= hi - margin):
        guess = 0.5 * (a + b)
    return guess


@njit
def _line_search(y, f0, g0, d, alpha, scale, x, y_new, g_new, args, budget):
    """A step length along ``d`` from ``y`` (energy f0, gradient g0) that satisfies the strong
    Wolfe conditions (Nocedal & Wright, Algorithms 3.5 and 3.6, cubic interpolation), starting
    from ``alpha``. On success ``y_new`` and ``g_new`` hold the new point.

    Returns:
        (step, energy, evaluations): step 0 where none lowered the energy within ``budget``
        evaluations.
    """
    n = y.shape[0]
    slope0 = _dot(g0, d)
    prev_a, prev_f, prev_slope = 0.0, f0, slope0
    lo_a, lo_f, lo_slope, hi_a, hi_f, hi_slope = 0.0, f0, slope0, 0.0, f0, slope0
    zooming = False
    a = alpha
    used = 0
    while used < budget:
        used += 1
        for i in range(n):
            y_new[i] = y[i] + a * d[i]
        f = _scaled_energy(y_new, scale, x, g_new, args)
        slope = _dot(g_new, d)
        if not (math.isfinite(f) and math.isfinite(slope)):
            f = math.inf
        sufficient = f <= f0 + WOLFE_DECREASE * a * slope0
        if not zooming:
            if not sufficient or (used > 1 and f >= prev_f):
                lo_a, lo_f, lo_slope, hi_a, hi_f, hi_slope = prev_a, prev_f, prev_slope, a, f, slope
                zooming = True
            elif abs(slope) <= -WOLFE_CURVATURE * slope0:
                return a, f, used
            elif slope >= 0.0:
                lo_a, lo_f, lo_slope, hi_a, hi_f, hi_slope = a, f, slope, prev_a, prev_f, prev_slope
                zooming = True
            else:  # still falling: a longer step
                prev_a, prev_f, prev_slope = a, f, slope
                lo_a, lo_f = a, f
                a *= 2.0
                continue
        else:
            if not sufficient or f >= lo_f:
                hi_a, hi_f, hi_slope = a, f, slope
            elif abs(slope) <= -WOLFE_CURVATURE * slope0:
                return a, f, used
            else:
                if slope * (hi_a - lo_a) >= 0.0:
                    hi_a, hi_f, hi_slope = lo_a, lo_f, lo_slope
                lo_a, lo_f, lo_slope = a, f, slope
        if not math.isfinite(hi_f):
            a = 0.5 * (lo_a + hi_a)
        else:
            a = _cubic_minimiser(lo_a, lo_f, lo_slope, hi_a, hi_f, hi_slope)
        if a == lo_a or a == hi_a:
            break
    # The budget is spent (or the bracket has shrunk to a point): the best point found, if
    # it lowered the energy, is the step.
    if lo_a > 0.0 and lo_f < f0:
        for i in range(n):
            y_new[i] = y[i] + lo_a * d[i]
        f = _scaled_energy(y_new, scale, x, g_new, args)
        return lo_a, f, used + 1
    return 0.0, f0, used


@njit
def minimise(y, scale, args, max_iter, gtol):
    """Minimise the discrete rod's energy over the scaled unknowns ``y`` (x = y·scale), in
    place, by L-BFGS (Nocedal & Wright, Algorithm 7.4: the two-loop recursion over the last
    LBFGS_MEMORY step pairs, the first step scaled to unit length, then H₀ = sᵀy/yᵀy) with a
    strong-Wolfe line search, until the gradient's largest entry is at most ``gtol``, the
    energy stops falling (the line search finds no lower point: the floating-point bottom of
    the basin) or ``max_iter`` iterations.

    Args:
        y: (3N,) scaled unknowns; the minimum on return.
        scale: (3N,) the unknowns' scales. args: :func:`energy_and_gradient`'s arguments after
            ``x`` and before ``grad``.

    Returns:
        (energy, iterations, evaluations).
    """
    n = y.shape[0]
    m = LBFGS_MEMORY
    s_hist = np.zeros((m, n))
    y_hist = np.zeros((m, n))
    rho = np.zeros(m)
    coef = np.zeros(m)
    x = np.empty(n)
    g = np.empty(n)
    d = np.empty(n)
    y_new = np.empty(n)
    g_new = np.empty(n)
    f = _scaled_energy(y, scale, x, g, args)
    evaluations = 1
    stored = 0
    newest = -1
    iterations = 0
    if not math.isfinite(f):
        return f, iterations, evaluations
    while iterations < max_iter:
        if _largest(g) <= gtol:
            break
        # d = −H g by the two-loop recursion.
        for i in range(n):
            d[i] = -g[i]
        for j in range(stored):
            k = (newest - j) % m
            c = rho[k] * _dot(s_hist[k], d)
            coef[k] = c
            for i in range(n):
                d[i] -= c * y_hist[k, i]
        if stored > 0:
            d *= 1.0 / (rho[newest] * _dot(y_hist[newest], y_hist[newest]))
        for j in range(stored - 1, -1, -1):
            k = (newest - j) % m
            b = rho[k] * _dot(y_hist[k], d)
            for i in range(n):
                d[i] += (coef[k] - b) * s_hist[k, i]
        slope = _dot(g, d)
        if not slope < 0.0:  # not a descent direction: forget the curvature pairs
            stored = 0
            d[:] = -g
            slope = -_dot(g, g)
        alpha = 1.0 if stored > 0 else 1.0 / math.sqrt(-slope)
        step, f_new, used = _line_search(y, f, g, d, alpha, scale, x, y_new, g_new, args,
                                         LINE_SEARCH_EVALUATIONS)
        evaluations += used
        iterations += 1
        if step == 0.0 or not f_new < f:
            break
        sy = 0.0
        for i in range(n):
            sy += (y_new[i] - y[i]) * (g_new[i] - g[i])
        # A strong-Wolfe step has sᵀy > 0; a line search's fallback step may not, and such a
        # pair is dropped (the older pairs kept).
        if sy > 0.0:
            newest = (newest + 1) % m
            for i in range(n):
                s_hist[newest, i] = y_new[i] - y[i]
                y_hist[newest, i] = g_new[i] - g[i]
            rho[newest] = 1.0 / sy
            stored = min(stored + 1, m)
        y[:] = y_new
        g[:] = g_new
        f = f_new
    return f, iterations, evaluations


@njit
def shooting_states(x, theta0, sec_of, h, secf, u_rest, v_rest, q, plate_at, plate, tip_force,
                    discs, self_params, states):
    """Shooting states (x, y, θ, n_x, n_y, m) at every node of the discrete rod (N + 1, 6).

    n at a node is the sum of the external forces distal to it (the free tip carries
    ``tip_force``); at a section end it is taken just distal of the endplate, the state
    multiple shooting starts the next section from. m = EI (θ' − u*) of the element that
    starts at the node (the last element's at the tip).
    """
    n = h.shape[0]
    pos = np.empty((n + 1, 2))
    mid_c = np.empty(n)
    mid_s = np.empty(n)
    _positions(theta0, x, sec_of, h, v_rest, pos, mid_c, mid_s)
    force = np.zeros((n + 1, 2))
    _self_contact(pos, h, self_params[0], self_params[1], self_params[2], self_params[3], force,
                  1.0)
    for e in range(n):
        for d in range(2):
            half = 0.5 * h[e] * q[sec_of[e], d]
            force[e, d] += half
            force[e + 1, d] += half
    for i in range(plate.shape[0]):
        for d in range(2):
            force[plate_at[i], d] += plate[i, d]
    for k in range(n + 1):
        w = 0.5 * ((h[k - 1] if k > 0 else 0.0) + (h[k] if k < n else 0.0))
        for dd in range(discs.shape[0]):
            dx = pos[k, 0] - discs[dd, CX]
            dy = pos[k, 1] - discs[dd, CY]
            dist = math.sqrt(dx * dx + dy * dy)
            pen = discs[dd, RADIUS] - dist
            if pen > 0.0 and dist > 0.0:
                push = w * discs[dd, STIFFNESS] * pen / dist
                force[k, 0] += push * dx
                force[k, 1] += push * dy
    nx = tip_force[0]
    ny = tip_force[1]
    for k in range(n, -1, -1):
        th = theta0 if k == 0 else x[k - 1]
        e = min(k, n - 1)
        th_a = theta0 if e == 0 else x[e - 1]
        i = sec_of[e]
        states[k, 0] = pos[k, 0]
        states[k, 1] = pos[k, 1]
        states[k, 2] = th
        states[k, 3] = nx
        states[k, 4] = ny
        states[k, 5] = ((x[e] - th_a) / h[e] - u_rest[i]) / secf[CI, i]
        nx += force[k, 0]
        ny += force[k, 1]


def element_layout(secf, steps):
    """Per-element section index (N,), lengths (N,), and the node index of each section end."""
    sec_of = np.repeat(np.arange(steps.shape[0]), steps)
    h = np.repeat(secf[LEN] / steps, steps)
    return sec_of.astype(np.int64), h, np.cumsum(steps).astype(np.int64)


def strains_of_record(record, steps):
    """The discrete rod's unknowns, in absolute terms, of a recorded state: node angles
    θ_1..θ_N, and per element the shear v1 and stretch v3 (means of its end samples).

    Args:
        record: (Σ(steps + 1), ≥13) a :mod:`solver.kernels.contact` record (columns x, y, θ, …, v1,
            v3), junction samples repeated. steps: (ns,) RK4 steps per section.
    """
    rows = np.concatenate([np.arange(k) + 1 + off for k, off in
                           zip(steps, np.concatenate([[0], np.cumsum(steps + 1)[:-1]]))])
    first = np.concatenate([[0], rows[:-1]])  # the row each element starts from
    return (record[rows, C_TH], 0.5 * (record[first, C_V1] + record[rows, C_V1]),
            0.5 * (record[first, C_V3] + record[rows, C_V3]))


def relax(start, theta0, secf, steps, level_rest, q, plate, tip_force, tip_moment, discs,
          self_contact=None, max_iter=3000):
    """Minimise the discrete rod's energy under the given loads from the state ``start``.

    Args:
        start: (θ, v1, v3), each (N,): node angles and element strains
            (:func:`strains_of_record`, or a previous result's).
        theta0: base angle (rad). secf, steps: the layout's section array and steps.
        level_rest: (3, ns) rest strains at the loads to relax under; q, plate (ns, 2),
            tip_force (2,), tip_moment, discs (k, 4): those loads (``plate`` includes the
            endplate at the tip; ``tip_force`` is the rest of the tip load).
        self_contact: the layout tuple's self-contact parameters (``G_SELF``: stiffness,
            exclusion, half-thicknesses per section), or None.

    Returns:
        ((Σ(steps + 1), 6) states (x, y, θ, n_x, n_y, m) on the record's rows, the minimum
        as a ``start``), or None if the minimisation failed.
    """
    sec_of, h, ends = element_layout(secf, steps)
    n = h.size
    u_rest, v_rest = level_rest[1], level_rest[2]
    x0 = np.concatenate([start[0], start[1], start[2] - v_rest[sec_of]])
    if not np.all(np.isfinite(x0)):
        return None
    shearable = secf[CG] > 0.0
    if not shearable.all():
        x0[n:2 * n][~shearable[sec_of]] = 0.0
    # Variables scaled by the square root of their stiffness (bending 2EI/h, stretch h·EA,
    # shear h·GA): the Hessian of the strain energy is then near the identity.
    scale = 1.0 / np.sqrt(np.concatenate([
        2.0 / (secf[CI, sec_of] * h),
        h / np.where(shearable, secf[CG], 1.0)[sec_of],
        h / secf[CA, sec_of]]))
    node_s = np.concatenate([[0.0], np.cumsum(h)])
    if self_contact is not None and self_contact[SC_K] > 0:
        half = np.asarray(self_contact[SC_HALF:])
        node_h = np.concatenate([[half[0]], half[sec_of]])
        self_params = (node_s, node_h, float(self_contact[SC_K]), float(self_contact[SC_EXCLUSION]))
    else:
        self_params = (node_s, np.zeros(n + 1), 0.0, 0.0)
    args = (theta0, sec_of, h, secf, u_rest, v_rest, q, ends, plate, tip_force,
            float(tip_moment), discs, self_params)
    y = x0 / scale
    minimise(y, scale, args, max_iter, GRADIENT_TOL)
    x = y * scale
    if not np.all(np.isfinite(x)):
        return None
    nodes = np.empty((n + 1, 6))
    shooting_states(x, theta0, sec_of, h, secf, u_rest, v_rest, q, ends, plate, tip_force, discs,
                    self_params, nodes)
    node_of_row = np.concatenate([np.arange(k + 1) + off for k, off in
                                  zip(steps, np.concatenate([[0], np.cumsum(steps)[:-1]]))])
    return nodes[node_of_row], (x[:n], x[n:2 * n], x[2 * n:] + v_rest[sec_of])
