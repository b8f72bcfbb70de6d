"""Planar quasi-static Cosserat kernels: shooting on the base moment with RK4.

Planar statics of the thesis's Eqs. (2.25)–(2.27) and (2.55)–(2.57), written in the
rest-strain form of docs/design.md §1–4. In section i, with s the reference arc length,

    x' = v3 cos θ − v1 sin θ,   y' = v3 sin θ + v1 cos θ          (2.25)–(2.26)
    θ' = u*_i + m / EI_i                                          (2.27), (2.30)
    m' = −(r' × n)_z = v1 n3 − v3 n1                              (2.29)
    v1 = n1 / GA_i,  v3 = v*_i + n3 / EA_i                        (2.31)
    n1 = n · d1,  n3 = n · d3,  d3 = (cos θ, sin θ), d1 = (−sin θ, cos θ),

where u*_i, v*_i are the rest curvature and stretch the pressurised tubes impose. With dead
loads only the internal force is known in closed form from global equilibrium,
n(s) = n_end_i + q_i·(L_i − σ) in section i (σ the local coordinate; q_i the weight per
length; n_end_i includes the endplate and everything distal), so shooting has one unknown,
the base moment m0, and one residual, m(L) − M_tip. The sensitivities a = ∂θ/∂m0,
b = ∂m/∂m0 are integrated alongside:

    a' = b / EI,   b' = [(1/GA − 1/EA)(n1² − n3²) + v*_i n3] · a.

Stability (Jacobi / conjugate-point test for the clamped–free rod under dead loads): the
equilibrium is stable iff b(s) = ∂m(s)/∂m0 stays positive on (0, L]. For the upright Euler
column this gives b = cos(√(P/EI)·s), which first vanishes at P·L²/EI = π²/4.
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit, prange
from solver.kernels.grid import planar_fine
from solver.kernels.homotopy import GIVE_UP, big_change, halved
from solver.kernels.obstacles import chord_allowance, chords_clear, clearance, tunnels
from solver.kernels.self_contact import far_parts_clear
from solver.kernels.spatial import planar_state_stable
from solver.layout import (
    DT0,
    DT_MIN,
    JUMP,
    LEN,
    M_BOUND,
    MAX_ITER,
    MAX_STEP,
    N_COLUMNS,
    N_SCAN,
    REST_U2,
    REST_V3,
    TOL,
    S,
    X,
    Y,
)
from solver.rod import (
    arc_chain_planar,
    fma,
    forget_first_variations,
    integrate_planar,
    planar_rest_gradient,
    rest_strains_cached,
    rest_strains_into,
    shift_planar_record,
)

# Newton's last correction δ is applied through the pass's first variations instead of by a
# new pass when its second-order remainder ½|∂²m(L)/∂m0²|·δ² is below this fraction of the
# tolerance.
LINEAR_FINISH = 1e-3


@njit
def newton(m0, theta0, secf, steps, rest, loads, m_tip, tol, max_iter, max_step, out,
           record=False, reach=math.inf):
    """Newton on m(L; m0) = M_tip with the exact shooting derivative ∂m(L)/∂m0, each step
    corrected by Halley's factor from the second derivative ∂²m(L)/∂m0² where that factor is
    a correction (|r·m''| ≤ m'²).

    Halley's step converges cubically (docs/design.md §8); the second variation costs a few
    per cent of a pass. Steps are clipped to ``max_step`` (N m) so a poor guess cannot fling
    the iterate onto a distant branch, and halved while they do not reduce the residual.
    Returns (m0, converged, iterations, |residual|, stable, bmin, x, y, θ), the last three at
    the tip of the returned iterate. With ``record`` every pass writes its samples to
    ``out``, so that on return ``out`` holds the returned iterate's backbone (no separate
    recording pass).

    A last correction δ small enough that its second-order remainder ½|∂²m(L)/∂m0²|·δ² is
    below ``LINEAR_FINISH``·``tol`` takes no pass: the returned state is the last pass moved
    along its first variations (:func:`solver.rod.shift_planar_record`), which is the pass
    from m0 + δ to that remainder, and the residual returned is the remainder (a bound on
    what that pass would measure, rounding aside). It counts as an iteration.

    ``reach`` (N m): give up, unconverged, as soon as a step would take the iterate farther
    than this from the start ``m0`` — a caller that will reject a root that far from its
    prediction (a continuation step past a fold, where Newton wanders for its whole budget)
    saves the rest of the passes. The iterations returned are then below ``max_iter``.
    """
    result = _newton_passes(m0, theta0, secf, steps, rest, loads, m_tip, tol, max_iter, max_step,
                            out, record, reach)
    if record:
        forget_first_variations(out)
    return result


@njit
def _newton_passes(m0, theta0, secf, steps, rest, loads, m_tip, tol, max_iter, max_step, out,
                   record, reach):
    """:func:`newton` but for clearing the record's first variations."""
    res = math.inf
    bmin = 1.0
    th = x = y = math.nan
    start = m0
    base = m0
    res_base = math.inf
    for it in range(max_iter + 1):
        th, m, b, x, y, bmin, b2, a, ax, ay = integrate_planar(m0, theta0, secf, steps, rest, loads,
                                                               record, out, True)
        res = m - m_tip
        if abs(res) <= tol:
            return m0, True, it, abs(res), bmin > 0.0, bmin, x, y, th
        if 0 < it < max_iter and not abs(res) < res_base and abs(m0 - base) > tol:
            # Backtracking: the full step did not reduce the residual (soft or long arms,
            # where m(L; m0) is far from linear over a Newton step); halve it.
            m0 = 0.5 * (m0 + base)
            continue
        if not math.isfinite(res) or not math.isfinite(b):
            return m0, False, it, math.inf, False, bmin, x, y, th
        res_base = abs(res)
        base = m0
        if it == max_iter or b == 0.0:
            break
        step = -res / b
        left = 0.5 * abs(b2) * step * step
        if left <= LINEAR_FINISH * tol and abs(m0 + step - start) <= reach:
            # Newton's last correction is so small that the pass it would take is this one
            # moved along its first variations, to a second-order remainder ``left`` far
            # below the tolerance: that is the returned state, with no further pass.
            if record:
                shift_planar_record(out, step, secf, steps)
            return (m0 + step, True, it + 1, left, bmin > 0.0, bmin, fma(step, ax, x),
                    fma(step, ay, y), fma(step, a, th))
        bend = 0.5 * res * b2 / (b * b)
        if abs(bend) <= 0.5:
            step /= 1.0 - bend
        if step > max_step:
            step = max_step
        elif step < -max_step:
            step = -max_step
        if abs(m0 + step - start) > reach:
            return m0, False, it, abs(res), bmin > 0.0, bmin, x, y, th
        m0 += step
    return m0, False, max_iter, abs(res), bmin > 0.0, bmin, x, y, th


@njit
def _level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now):
    """Interpolate the homotopy at ``t``: pressures, loads; returns the tip moment."""
    for c in range(p_a.shape[0]):
        p_now[c] = p_a[c] + t * (p_b[c] - p_a[c])
    for i in range(loads_now.shape[0]):
        for d in range(4):
            loads_now[i, d] = loads_a[i, d] + t * (loads_b[i, d] - loads_a[i, d])
    return mtip_a + t * (mtip_b - mtip_a)


@njit
def fold_scan(theta0, secf, steps, rest, loads, m_tip, params, n_scan, guess, out):
    """Stable root of m(L; m0) = M_tip nearest ``guess``, by a scan of ``n_scan`` intervals
    over |m0| ≤ M_BOUND.

    Used where continuation cannot proceed (a fold passed, or a bifurcation such as Euler
    buckling): every sign change on the scan grid is polished by Newton and the stable root
    closest to ``guess`` is taken (ties broken towards positive m0). The intervals are
    visited nearest ``guess`` first, and the scan stops at the first interval farther from it
    than the nearest stable root found: a root lies inside its interval, so no farther one
    can be nearer — the root of the whole scan, for a fraction of its passes (an arm that
    snaps lands near where it left). Returns (m0, found, its).
    """
    m_bound = params[M_BOUND]
    tie = 1e-12 * m_bound
    best = math.nan
    best_d = math.inf
    if not math.isfinite(guess):
        return best, False, 0
    residual = np.full(n_scan + 1, math.nan)
    seen = np.zeros(n_scan + 1, dtype=np.bool_)
    # Interval k spans grid points k − 1 and k (1 ≤ k ≤ n_scan); start from the one holding
    # the guess (clamped to the grid) and widen to the left and right.
    first = min(max(int(math.floor((guess + m_bound) * n_scan / (2.0 * m_bound))) + 1, 1), n_scan)
    left = first
    right = first + 1
    k = first
    its = 0
    while True:
        if _grid_m(k - 1, m_bound, n_scan) <= guess <= _grid_m(k, m_bound, n_scan):
            d_k = 0.0
        else:
            d_k = min(abs(_grid_m(k - 1, m_bound, n_scan) - guess),
                      abs(_grid_m(k, m_bound, n_scan) - guess))
        if d_k > best_d + tie:
            break
        for j in (k - 1, k):
            if not seen[j]:
                th, m, b, x, y, bmin, _, _, _, _ = integrate_planar(
                    _grid_m(j, m_bound, n_scan), theta0, secf, steps, rest, loads, False, out, False)
                residual[j] = m - m_tip
                seen[j] = True
                its += 1
        root, stable, n_it = _bracket_root(_grid_m(k - 1, m_bound, n_scan), residual[k - 1],
                                           _grid_m(k, m_bound, n_scan), residual[k], theta0,
                                           secf, steps, rest, loads, m_tip, params, out)
        its += n_it
        if stable:
            d = abs(root - guess)
            if d < best_d - tie or (abs(d - best_d) <= tie and root > best):
                best = root
                best_d = d
        # The next interval: the nearer of the two neighbours not yet visited.
        if k == left:
            left -= 1
        else:
            right += 1
        if left < 1 and right > n_scan:
            break
        if left < 1:
            k = right
        elif right > n_scan:
            k = left
        else:
            to_left = guess - _grid_m(left, m_bound, n_scan)
            k = left if to_left <= _grid_m(right - 1, m_bound, n_scan) - guess else right
    return best, math.isfinite(best), its


@njit(inline="always")
def _grid_m(k, m_bound, n_scan):
    """Base moment of grid point k of the fold scan (N m)."""
    return -m_bound + 2.0 * m_bound * k / n_scan


@njit
def _bracket_root(prev_m, prev_r, mk, r, theta0, secf, steps, rest, loads, m_tip, params, out):
    """The root of m(L; m0) = M_tip in the scan interval [prev_m, mk] with residuals prev_r,
    r at its ends, if they change sign: (root, stable root found, passes)."""
    if not (math.isfinite(r) and math.isfinite(prev_r) and (r == 0.0 or prev_r * r < 0.0)):
        return math.nan, False, 0
    tol = params[TOL]
    max_iter = int(params[MAX_ITER])
    max_step = params[MAX_STEP]
    # Secant start inside the bracket, then Newton; where the residual is too steep for Newton
    # (heavily loaded arms), bisect the bracket first.
    start = prev_m - prev_r * (mk - prev_m) / (r - prev_r)
    root, ok, its, res, stable, bm, x, y, th = newton(start, theta0, secf, steps, rest, loads,
                                                      m_tip, tol, max_iter, max_step, out)
    if not (ok and prev_m <= root <= mk):
        lo, hi, r_lo = prev_m, mk, prev_r
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            th, m, b, x, y, bmin, _, _, _, _ = integrate_planar(mid, theta0, secf, steps, rest,
                                                                loads, False, out, False)
            its += 1
            r_mid = m - m_tip
            if not math.isfinite(r_mid):
                break
            if (r_mid < 0.0) == (r_lo < 0.0):
                lo, r_lo = mid, r_mid
            else:
                hi = mid
            if hi - lo <= 1e-12 * params[M_BOUND]:
                break
        root, ok, n_it, res, stable, bm, x, y, th = newton(
            0.5 * (lo + hi), theta0, secf, steps, rest, loads, m_tip, tol, max_iter, max_step, out)
        its += n_it
    return root, ok and stable, its


@njit
def _tangent(m0, eps, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b, mtip_a,
             mtip_b, rest, p_now, loads_now, out):
    """dm0/dt = −(∂r/∂t)/(∂r/∂m0) at t = 0, ∂r/∂t by a forward difference of size ``eps``.

    Both ends are integrated, so the slope is right even when ``m0`` is not an equilibrium
    at t = 0 (an unconverged start state): one pass fewer, assuming r(0) = 0, cost the plain
    Newton solves of ``softarm stress`` eight points of convergence.
    """
    mt0 = _level(0.0, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    th0, m_a, b_a, x0, y0, bm0, _, _, _, _ = integrate_planar(m0, theta0, secf, steps, rest,
                                                              loads_now, False, out, False)
    mt1 = _level(eps, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    th1, m_b, b_b, x1, y1, bm1, _, _, _, _ = integrate_planar(m0, theta0, secf, steps, rest,
                                                              loads_now, False, out, False)
    slope = -((m_b - mt1) - (m_a - mt0)) / eps / b_a if b_a != 0.0 else 0.0
    return slope if math.isfinite(slope) else 0.0


@njit
def follow(state, grid, tubes, a, b, params, work, guard):
    """Planar dead-load path following, in the signature the path-following kernels share.

    Args:
        state: (4,) in: the base moment m0 (N m) of the equilibrium at ``a``; out: m0, tip x,
            y (m) and θ (rad) of the returned state.
        grid: (θ0, secf (6, ns), steps (ns,)). tubes: (tubes_i, tubes_f).
        a, b: start and goal levels (channel pressures, loads (ns, 4), tip moment).
        params: (N_PARAMS,) numeric parameters (:mod:`solver.layout`).
        work: (rest (3, ns), p_now, loads_now (ns, 4), out (≥1, N_COLUMNS), record); see
            :func:`_path`. guard: (c_j_3d, discs); see :func:`_path`.

    Returns:
        (converged, stable, snapped, iterations, residual, t, dt): t is 1 when converged
        (NaN otherwise: the planar path does not report how far it got), dt 0.
    """
    theta0, secf, steps = grid
    tubes_i, tubes_f = tubes
    p_a, loads_a, mtip_a = a
    p_b, loads_b, mtip_b = b
    rest, p_now, loads_now, out, record = work
    c_j_3d, discs = guard
    m0, ok, total, snapped, stable, res, x, y, th = _path(
        state[0], theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b, mtip_a,
        mtip_b, params, rest, p_now, loads_now, out, record, c_j_3d, discs, math.nan, math.nan)
    state[0] = m0
    state[1] = x
    state[2] = y
    state[3] = th
    return ok, stable, snapped, total, res, 1.0 if ok else math.nan, 0.0


# Newton iterations of the stepper's direct attempt: a prediction that is any good converges
# in two or three; one that is not is left to the continuation of :func:`_path` early.
DIRECT_ITER = 6


@njit
def warm_step(state, grid, tubes, a, b, params, work, memo, guard):
    """A warm step of the stepper (:class:`solver.stepper.Stepper`): :func:`follow` from an
    equilibrium at ``a`` to the pressures of ``b`` (the same loads), first tried as one
    Newton solve from a first-order prediction.

    The prediction moves m0 by the rest-strain gradient of the start state
    (:func:`solver.rod.planar_rest_gradient`) times the change of the rest strains. It is
    accepted on the terms :func:`_path` accepts a continuation step: Newton converged on a
    stable state that moved from the prediction by at most ``JUMP`` plus half the predicted
    move. Otherwise the step is :func:`follow`'s (continuation, fold scan), with the same
    prediction as its first tangent.

    Args:
        state, grid, tubes, a, b, params, work: as :func:`follow`.
        memo: (p_seen (n_tubes,), stretch (n_tubes,), rest_a (3, ns), grad (2, ns)): the
            λ(p) cache (:func:`solver.rod.rest_strains_cached`), the start state's rest
            strains and gradient (NaN: unknown). Updated to the returned state when it
            converged; the gradient is computed only if ``work`` records.

        guard: (discs (k, 4), prev (rows, N_COLUMNS), half (rows,), exclusion): the
            contact-free step of a scene with obstacles (``discs``, else empty) or
            self-contact (``half`` the samples' half-thicknesses, else empty; ``exclusion``
            the self-contact exclusion length, m), which holds only while no contact comes
            into play (:func:`solver.paths.contact.solve_contact`): the returned backbone must
            clear every disc between every two samples
            (:func:`solver.kernels.obstacles.chords_clear`), no sample may pass within the
            chords' allowance of a disc from ``prev`` (the start's record, as the stepper
            keeps it; :func:`solver.kernels.obstacles.tunnels`) and, with self-contact, no
            two parts farther apart than the exclusion may come within their half-thicknesses
            plus an RK4 step of each other; the continuation is guarded the same way
            (:func:`_path`). Then ``work`` must record.

    Returns:
        As :func:`follow`; with ``record`` (as the steppers call it), a state the RK4 grid
        does not resolve (:func:`solver.kernels.grid.planar_fine`) is not converged: the caller's
        general path solves it on a finer grid. A guarded step that would touch is not
        converged either: the caller's general path takes it with contact.
    """
    theta0, secf, steps = grid
    rest, p_now, loads_now, out, record = work
    p_seen, stretch, rest_a, grad = memo
    discs, prev, half, exclusion = guard
    p_b, loads, m_tip = b
    m_start = state[0]
    rest_strains_cached(p_b, tubes[0], tubes[1], secf, p_seen, stretch, rest)
    slope = math.nan
    if math.isfinite(grad[0, 0]):
        slope = 0.0
        for i in range(secf.shape[1]):
            slope += (grad[0, i] * (rest[REST_U2, i] - rest_a[REST_U2, i])
                      + grad[1, i] * (rest[REST_V3, i] - rest_a[REST_V3, i]))
    guess = m_start + (slope if math.isfinite(slope) else 0.0)
    jump = params[JUMP] + 0.5 * abs(guess - m_start)
    n_direct = min(int(params[MAX_ITER]), DIRECT_ITER)
    root, ok, its, res, stable, bm, x, y, th = newton(
        guess, theta0, secf, steps, rest, loads, m_tip, params[TOL], n_direct, params[MAX_STEP],
        out, record, GIVE_UP * jump)
    snapped = False
    direct = ok and stable and abs(root - guess) <= jump
    if direct and discs.shape[0] > 0:
        direct = chords_clear(out, discs) and not tunnels(
            prev[:, X:Y + 1], out[:, X:Y + 1], discs, -max(chord_allowance(prev), chord_allowance(out)))
    if direct:
        state[0] = root
        state[1] = x
        state[2] = y
        state[3] = th
        for c in range(p_b.shape[0]):
            p_now[c] = p_b[c]
        loads_now[:, :] = loads
    else:
        # The attempt was Newton from the very prediction :func:`_path` starts with (a full
        # first step, DT0 = 1): one that converged or gave up would do so again there, so the
        # path starts at half the step. One that ran out of iterations gets the path's budget.
        dt_first = 0.5 * params[DT0] if its < n_direct and params[DT0] >= 1.0 else math.nan
        m_end, ok, more, snapped, stable, res, x, y, th = _path(
            m_start, theta0, secf, steps, tubes[0], tubes[1], a[0], p_b, a[1], loads, a[2],
            m_tip, params, rest, p_now, loads_now, out, record, np.empty(0), discs, slope,
            dt_first)
        state[0] = m_end
        state[1] = x
        state[2] = y
        state[3] = th
        its += more
    if ok and record and not planar_fine(out, secf, steps, loads):
        ok = False
    if ok and half.shape[0] > 0:
        h_max = 0.0
        for i in range(steps.shape[0]):
            h_max = max(h_max, secf[LEN, i] / steps[i])
        ok = far_parts_clear(out[:, X:Y + 1], out[:, S], half, exclusion, h_max)
    if ok:
        rest_a[:, :] = rest
        if record:
            planar_rest_gradient(out, secf, steps, rest, grad)
        else:
            grad[0, 0] = math.nan
    return ok, stable, snapped, its, res, 1.0 if ok else math.nan, 0.0


@njit
def _path(m0, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b, mtip_a,
          mtip_b, params, rest, p_now, loads_now, out, record, c_j_3d, discs, slope0,
          dt_first):
    """Quasi-static path following from the equilibrium ``m0`` at t = 0 to t = 1.

    The homotopy ramps pressures and loads linearly from state A to state B. Each step
    predicts m0 by secant, corrects by Newton, and is accepted only if Newton converged,
    landed on a stable equilibrium and did not jump far from the prediction; otherwise the
    step is halved. Below ``DT_MIN`` a fold (or bifurcation) has been passed: :func:`fold_scan`
    picks the stable equilibrium nearest the prediction and the result is flagged as a snap.

    Scratch/outputs: ``rest`` (3, ns), ``p_now`` (n_channels,), ``loads_now`` (ns, 4) hold
    the returned state's rest strains, pressures and loads; ``out`` is a (≥1, N_COLUMNS)
    scratch for :func:`_integrate`. With ``record`` (``out`` then has room for every sample)
    the Newton passes at t = 1 record into ``out``: a converged return leaves the returned
    state's backbone there, with no extra pass.

    ``c_j_3d`` (ns,) 1/GJ, or empty: when given, the path is followed for a spatial solve
    of an in-plane scene, and every accepted state must also pass the 3D stability test
    (:func:`solver.kernels.spatial.planar_state_stable`). The first that does not — and any fold
    or snap, where the 3D path may leave the plane — ends the path unconverged, so that the
    caller hands the solve to the spatial kernels: the planar shortcut never changes the
    answer. ``discs`` ((k, 4) obstacles, or empty) guards a contact-free solve of a scene
    with obstacles: the backbone must stay clear of every disc between every two samples
    (:func:`solver.kernels.obstacles.chords_clear`) at every accepted state, and no sample
    may pass within the chords' allowance of a disc between accepted states
    (:func:`solver.kernels.obstacles.tunnels`; a step that fails only that is halved); a
    snap must land clear of them as well (the contact path's snap lands there too).

    ``slope0``: dm0/dt at the start, if the caller knows it (the stepper's rest-strain
    gradient); otherwise a large change gets a finite-difference tangent (two passes).
    ``dt_first``: the first continuation step, if not ``DT0`` (a caller that has already
    tried the step to t = 1 from the same prediction and seen it rejected).

    Returns:
        (m0, converged, iterations, snapped, stable, |residual|, tip x, y, θ).
    """
    tol = params[TOL]
    max_iter = int(params[MAX_ITER])
    max_step = params[MAX_STEP]
    dt0 = params[DT0]
    dt_min = params[DT_MIN]
    t = 0.0
    dt = dt_first if math.isfinite(dt_first) else dt0
    total = 0
    snapped = False
    stable = True
    ok = True
    res = 0.0
    x = y = th = math.nan
    guard = c_j_3d.shape[0] > 0 or discs.shape[0] > 0
    rows = 1
    if discs.shape[0] > 0:
        rows = 0
        for i in range(steps.shape[0]):
            rows += steps[i] + 1
    rec_prev = np.empty((rows, N_COLUMNS))
    rec_new = np.empty((rows, N_COLUMNS))
    if discs.shape[0] > 0:
        _level(0.0, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now)
        rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
        integrate_planar(m0, theta0, secf, steps, rest, loads_now, True, rec_prev, False)
        if not chords_clear(rec_prev, discs):
            return m0, False, 1, snapped, False, math.inf, x, y, th
    # Tangent predictor for the first step (the later steps use the secant through accepted
    # points). Small warm steps (env steps) start from the previous state directly, so the
    # two extra passes are spent only on large changes (cold ramps, big jumps, new loads).
    big = mtip_a != mtip_b or big_change(p_a, p_b, loads_a, loads_b)
    slope = 0.0
    eps = 1e-6
    if math.isfinite(slope0):
        slope = slope0
    elif big:
        slope = _tangent(m0, eps, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a,
                         loads_b, mtip_a, mtip_b, rest, p_now, loads_now, out)
        total += 2
    while t < 1.0:
        t_new = min(1.0, t + dt)
        m_tip = _level(t_new, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now)
        rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
        guess = m0 + slope * (t_new - t)
        # Intermediate points only seed the next prediction: a looser tolerance and a short
        # iteration budget (a step that needs more is rejected anyway) keep ramps cheap.
        final = t_new >= 1.0
        # A continuous branch: the corrector moves the iterate little compared with the step
        # just predicted (``JUMP`` is an absolute floor, a fraction of EI/L). A larger jump
        # means Newton left the branch: retry with a smaller step. At the smallest step a
        # far root is a snap, so Newton is given its whole budget there.
        jump = params[JUMP] + 0.5 * abs(guess - m0)
        root, ok, its, res, stab, bm, x, y, th = newton(
            guess, theta0, secf, steps, rest, loads_now, m_tip, tol if final else 1e3 * tol,
            max_iter if final else min(max_iter, 6), max_step, out, record and final,
            GIVE_UP * jump if dt > dt_min else math.inf)
        total += its
        if guard and ok and stab and abs(root - guess) <= jump:
            if c_j_3d.shape[0] > 0 and not planar_state_stable(x, y, th, m_tip, secf, steps,
                                                               c_j_3d, rest, loads_now):
                return root, False, total, snapped, False, res, x, y, th
            if discs.shape[0] > 0:
                integrate_planar(root, theta0, secf, steps, rest, loads_now, True, rec_new, False)
                total += 1
                if not chords_clear(rec_new, discs):
                    return root, False, total, snapped, False, res, x, y, th
                if tunnels(rec_prev[:, X:Y + 1], rec_new[:, X:Y + 1], discs,
                           -max(chord_allowance(rec_prev), chord_allowance(rec_new))):
                    if dt > dt_min:
                        dt = halved(dt, t_new - t, dt_min)
                        continue
                    return root, False, total, snapped, False, res, x, y, th
                rec_prev, rec_new = rec_new, rec_prev
        if ok and stab and (abs(root - guess) <= jump or (dt <= dt_min and not guard)):
            if abs(root - guess) > jump:
                # Converged far from the prediction at the smallest step: the branch ended
                # (a fold) and Newton fell onto another stable one — a snap, if the grid
                # resolves the state the branch ended at (else the caller refines it).
                if not resolved(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b,
                                loads_a, loads_b, mtip_a, mtip_b):
                    return _give_back(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b,
                                      loads_a, loads_b, mtip_a, mtip_b, rest, p_now, loads_now,
                                      out, total, snapped, res)
                snapped = True
            slope = (root - m0) / (t_new - t)
            m0 = root
            t = t_new
            dt = min(2.0 * dt, 1.0)
            stable = True
            continue
        if dt > dt_min:
            dt = halved(dt, t_new - t, dt_min)
            continue
        if c_j_3d.shape[0] > 0:  # a fold or bifurcation: the 3D path may leave the plane here
            return root, False, total, snapped, False, res, x, y, th
        if params[N_SCAN] == 0:
            if ok:
                return root, final, total, snapped, bool(stab), res, x, y, th
            return _give_back(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a,
                              loads_b, mtip_a, mtip_b, rest, p_now, loads_now, out, total,
                              snapped, res)
        # A fold or bifurcation lies between t and t_new: snap to the nearest stable state —
        # if the grid resolves the last state before it; a fold met from a state it does not
        # resolve may be the grid's, not the rod's, and the caller refines the grid.
        if not resolved(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a,
                        loads_b, mtip_a, mtip_b):
            return _give_back(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a,
                              loads_b, mtip_a, mtip_b, rest, p_now, loads_now, out, total,
                              snapped, res)
        snap_to, found, its = fold_scan(theta0, secf, steps, rest, loads_now, m_tip, params,
                                        int(params[N_SCAN]), guess, out)
        total += its
        if not found:
            # Heavily loaded arms (a column far past its buckling load) have stable roots in
            # narrow windows of m0 that the default grid steps over: look once more, 8× finer.
            snap_to, found, its = fold_scan(theta0, secf, steps, rest, loads_now, m_tip, params,
                                            8 * int(params[N_SCAN]), guess, out)
            total += its
        if not found:
            # No stable equilibrium at this level. Report the Newton result as it stands, with
            # its own state: a converged but unstable root (e.g. a column past its buckling
            # load whose buckled states the scan missed) is returned as such, stable=False.
            if ok:
                # Converged but unstable: report it as such — and converged only if it is at
                # the requested pressures and loads, not an intermediate level of the ramp.
                return root, final, total, snapped, False, res, x, y, th
            return _give_back(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a,
                              loads_b, mtip_a, mtip_b, rest, p_now, loads_now, out, total,
                              snapped, res)
        snapped = True
        slope = 0.0
        m0, ok, its, res, stable, bm, x, y, th = newton(snap_to, theta0, secf, steps, rest,
                                                        loads_now, m_tip, tol, max_iter,
                                                        max_step, out, record and final)
        total += its
        if discs.shape[0] > 0:
            # Where the arm snaps clear of every disc, the contact path lands where this one
            # does (solver.paths.shooting); where it would land on one, the contact path's
            # relaxation finds where it comes to rest.
            integrate_planar(m0, theta0, secf, steps, rest, loads_now, True, rec_prev, False)
            total += 1
            if not (ok and chords_clear(rec_prev, discs)):
                return m0, False, total, snapped, False, res, x, y, th
        t = t_new
        dt = dt0
    return m0, ok, total, snapped, stable, res, x, y, th


@njit
def resolved(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b, mtip_a,
             mtip_b):
    """Whether the RK4 grid resolves the state ``m0`` at level ``t`` of the homotopy
    (:func:`solver.kernels.grid.planar_fine` of its record; one recorded pass)."""
    p_now = np.empty(p_a.shape[0])
    loads_now = np.empty(loads_a.shape)
    rest = np.empty((3, secf.shape[1]))
    _level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    rec = np.empty(((steps + 1).sum(), N_COLUMNS))
    integrate_planar(m0, theta0, secf, steps, rest, loads_now, True, rec, False)
    return planar_fine(rec, secf, steps, loads_now)


@njit
def _give_back(m0, t, theta0, secf, steps, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b, mtip_a,
               mtip_b, rest, p_now, loads_now, out, total, snapped, res):
    """The unconverged return of :func:`_path`: the last accepted state ``m0`` at its level
    ``t``, re-integrated so that the reported tip and scratch arrays belong to it (finite,
    flagged ``converged=False``) rather than to the failed attempt."""
    _level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    th, m, b, x, y, bmin, _, _, _, _ = integrate_planar(m0, theta0, secf, steps, rest, loads_now,
                                                        False, out, False)
    return m0, False, total + 1, snapped, bmin > 0.0, res, x, y, th




@njit
def clear_of(rec, discs, gap):
    """True when every recorded sample of ``rec`` clears every disc by more than ``gap`` (m)."""
    for r in range(rec.shape[0]):
        if not clearance(rec[r, X], rec[r, Y], discs) > gap:
            return False
    return True


@njit(parallel=True)
def batch(m0_start, p_start, theta0, secf, steps, tubes_i, tubes_f, p_targets, loads, mtip,
          params, record, tips, ok, stable_out, m0_out, shapes):
    """Many quasi-static solves in parallel, one per row of ``p_targets`` (n, n_channels).

    Row k follows the path from the equilibrium ``m0_start[k]`` at pressures ``p_start[k]``
    (cold solves: the loaded, unactuated state at zero pressure for every row, as
    :func:`solver.solve` does, so a sweep's result does not depend on its order). Writes the
    tips (n, 2), convergence and stability flags and the new base moments. A row that does
    not converge, or whose state the RK4 grid does not resolve (:func:`solver.kernels.grid.planar_fine`),
    keeps its start state (``m0_out[k] = m0_start[k]``, its tip and shape).
    With ``record`` each row's backbone is written to ``shapes[k]`` ((rows, N_COLUMNS));
    otherwise ``shapes`` is an (n, 1, N_COLUMNS) scratch.
    """
    n = p_targets.shape[0]
    ns = secf.shape[1]
    nc = p_targets.shape[1]
    grid = (theta0, secf, steps)
    tubes = (tubes_i, tubes_f)
    no_guard = np.empty(0)
    no_discs = np.empty((0, 4))
    rows = 0
    for i in range(ns):
        rows += steps[i] + 1
    for k in prange(n):
        rest = np.empty((3, ns))
        p_now = np.empty(nc)
        loads_now = np.empty((ns, 4))
        # A converged row's backbone is recorded by its final Newton pass (for the grid check
        # even where the caller does not keep it).
        out = shapes[k] if record else np.empty((rows, N_COLUMNS))
        state = np.empty(4)
        state[0] = m0_start[k]
        conv, stab, snapped, its, res, t, dt = follow(
            state, grid, tubes, (p_start[k], loads, mtip), (p_targets[k], loads, mtip), params,
            (rest, p_now, loads_now, out, True), (no_guard, no_discs))
        root, x, y = state[0], state[1], state[2]
        conv = conv and math.isfinite(x) and math.isfinite(y) and planar_fine(out, secf, steps,
                                                                               loads)
        if not conv:
            # Keep the last good state: its rest strains, shape and tip.
            root = m0_start[k]
            rest_strains_into(p_start[k], tubes_i, tubes_f, secf, rest)
            th, m, b, x, y, bmin, _, _, _, _ = integrate_planar(root, theta0, secf, steps, rest,
                                                                loads, record, shapes[k], False)
            if record:
                forget_first_variations(shapes[k])
        tips[k, 0] = x
        tips[k, 1] = y
        ok[k] = conv
        stable_out[k] = stab
        m0_out[k] = root


@njit(inline="always")
def _cold_row(k, grid, tubes, p_zero, p, loads, mtip, params, work, states, records, record,
              rest_a, grad, report):
    """Row k of :func:`_cold_rows`: a cold solve, as :func:`solver.solve`'s single shooting
    (not converged, too, where the grid does not resolve the state: the caller's general path
    refines it)."""
    rest, p_now, loads_now = work
    _, secf, steps = grid
    out = records[k] if record else np.empty(((steps + 1).sum(), N_COLUMNS))
    ok, stable, snapped, its, res, _, _ = follow(
        states[k], grid, tubes, (p_zero, loads, mtip), (p[k], loads, mtip), params,
        (rest[k], p_now[k], loads_now[k], out, True), (np.empty(0), np.empty((0, 4))))
    ok = ok and planar_fine(out, secf, steps, loads)
    report[k, 0] = ok
    report[k, 1] = stable
    report[k, 2] = snapped
    report[k, 3] = its
    report[k, 4] = res
    if ok and record:
        rest_strains_into(p[k], tubes[0], tubes[1], secf, rest_a[k])
        planar_rest_gradient(out, secf, steps, rest_a[k], grad[k])


@njit(parallel=True)
def cold_rows_parallel(grid, tubes, p_zero, p, loads, mtip, params, work, states, records,
                       record, rest_a, grad, report):
    """Cold solves of many copies in parallel (see :class:`solver.stepper.BatchStepper`).

    Row k follows the path from ``states[k, 0]`` (the loaded unactuated arm's m0) at zero
    pressure to ``p[k]``, exactly as :func:`solver.paths.planar.solve_single` does, so that
    a row gives the bits a single solve gives. Writes ``states`` (n, 4), ``report`` (n, 5):
    converged, stable, snapped, iterations, residual; with ``record`` the backbone into
    ``records[k]`` (otherwise an (n, 1, N_COLUMNS) scratch) and, where converged, the rest
    strains ``rest_a[k]`` (3, ns) and their gradient ``grad[k]`` (2, ns) the stepper
    predicts with. ``work`` is per-row scratch.
    """
    for k in prange(p.shape[0]):
        _cold_row(k, grid, tubes, p_zero, p, loads, mtip, params, work, states, records, record,
                  rest_a, grad, report)


@njit
def cold_rows_serial(grid, tubes, p_zero, p, loads, mtip, params, work, states, records,
                     record, rest_a, grad, report):
    """:func:`cold_rows_parallel` on one thread (small batches: no thread start-up)."""
    for k in range(p.shape[0]):
        _cold_row(k, grid, tubes, p_zero, p, loads, mtip, params, work, states, records, record,
                  rest_a, grad, report)


@njit(inline="always")
def _step_row(k, grid, tubes, p_from, p_to, loads, mtip, params, work, states, records, memo,
              guard, report):
    """Row k of :func:`_step_rows`: :func:`warm_step`, the record kept only if it converged;
    ``guard`` (discs (n, k, 4), half, exclusion) gives row k's guard of :func:`warm_step`
    (its discs, its record as ``prev``)."""
    rest, p_now, loads_now, scratch = work
    p_seen, stretch, rest_a, grad = memo
    m_start = states[k, 0]
    ok, stable, snapped, its, res, _, _ = warm_step(
        states[k], grid, tubes, (p_from[k], loads, mtip), (p_to[k], loads, mtip), params,
        (rest[k], p_now[k], loads_now[k], scratch[k], True),
        (p_seen[k], stretch[k], rest_a[k], grad[k]), (guard[0][k], records[k], guard[1], guard[2]))
    report[k, 0] = ok
    report[k, 1] = stable
    report[k, 2] = snapped
    report[k, 3] = its
    report[k, 4] = res
    if ok:
        records[k, :, :] = scratch[k]
    else:
        states[k, 0] = m_start


@njit(parallel=True)
def step_rows_parallel(grid, tubes, p_from, p_to, loads, mtip, params, work, states, records,
                       memo, guard, active, report):
    """Warm steps of many copies in parallel: :func:`warm_step` per row, from the equilibrium
    ``states[k]``/``records[k]`` at ``p_from[k]`` to ``p_to[k]`` (n, n_channels). A row
    that converged gets its new record, state and predictor memo (per-row arrays of
    :func:`warm_step`'s ``memo``); one that did not keeps its equilibrium. ``work``: per-row
    scratch (rest, p_now, loads_now, scratch records). ``guard``: (discs (n, k, 4), half,
    exclusion), as :func:`warm_step`'s (no discs and an empty half: none). Rows where
    ``active`` (n,) is False are skipped. ``report`` as :func:`cold_rows_parallel`.
    """
    for k in prange(p_to.shape[0]):
        if active[k]:
            _step_row(k, grid, tubes, p_from, p_to, loads, mtip, params, work, states, records,
                      memo, guard, report)


@njit
def step_rows_serial(grid, tubes, p_from, p_to, loads, mtip, params, work, states, records,
                     memo, guard, active, report):
    """:func:`step_rows_parallel` on one thread."""
    for k in range(p_to.shape[0]):
        if active[k]:
            _step_row(k, grid, tubes, p_from, p_to, loads, mtip, params, work, states, records,
                      memo, guard, report)


@njit(parallel=True)
def arc_tips(theta0, secf, tubes_i, tubes_f, p_channels, tips):
    """Tips of many unloaded (or constant-curvature) arms, in parallel: each section a
    circular arc of its rest curvature u2* and stretch v3* (exact without loads).

    Args:
        p_channels: (n, n_channels) pressures (Pa). tips: (n, 2) output (m).
    """
    ns = secf.shape[1]
    for k in prange(p_channels.shape[0]):
        rest = np.empty((3, ns))
        rest_strains_into(p_channels[k], tubes_i, tubes_f, secf, rest)
        tip = np.empty((1, 2))
        ends = np.empty((ns, 3))
        length = np.empty(1)
        length[0] = 0.0
        for i in range(ns):
            length[0] += secf[LEN, i]
        arc_chain_planar(theta0, secf[LEN], rest[REST_U2], rest[REST_V3], length, tip,
                         np.empty(0), ends)
        tips[k, 0] = tip[0, 0]
        tips[k, 1] = tip[0, 1]
