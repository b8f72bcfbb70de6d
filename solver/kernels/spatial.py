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

from solver.jit import njit
from solver.kernels.homotopy import GIVE_UP, big_change, halved, smallest_step
from solver.layout import (
    CA,
    CG,
    CI,
    DT0,
    JUMP,
    LEN,
    M_BOUND,
    MAX_ITER,
    MAX_STEP,
    N_SCAN,
    NEX,
    NEY,
    NSTATE,
    QX,
    QY,
    REST_U1,
    REST_U2,
    REST_V3,
    SL_N,
    SL_Q,
    SP_DM,
    SP_DPHI,
    SP_M,
    SP_Q,
    SP_R,
    TOL,
)
from solver.rod import (
    base_rotation,
    det3,
    integrate_spatial,
    rest_strains_into,
    rotation_to_quaternion,
    spatial_rk4_step,
)


@njit
def newton(m0, quat0, secf, steps, c_j, rest, loads, m_tip, tol, max_iter, max_step, work, dummy):
    """Newton on m(L; m0) = M_tip (3 unknowns, updated in place) with the exact Jacobian.

    Returns (converged, iterations, |residual|, stable), stability by :func:`stability_test`.
    """
    return _newton_first(m0, quat0, secf, steps, c_j, rest, loads, m_tip, tol, max_iter, max_step,
                         work, dummy, False, np.empty(3), math.inf)


@njit
def _newton_first(m0, quat0, secf, steps, c_j, rest, loads, m_tip, tol, max_iter, max_step, work,
                  rec, record, first, reach):
    """:func:`newton`, also writing its first iterate to ``first`` (3,) (``m0`` itself when
    the start already meets ``tol``): the linearised response to the change of level from
    ``m0``, the prediction a continuation step without a tangent measures its jump from.
    With ``record`` every pass records into ``rec`` = (positions, frames, moments), so on
    convergence they hold the returned state's backbone (recording costs a pass a few per
    cent; a separate recording pass would cost a whole one).

    ``reach`` (N m): give up, unconverged, as soon as an iterate would leave that distance of
    the start ``m0``, as the planar Newton does (:func:`solver.kernels.planar.newton`): a
    continuation step that will reject a root that far from its prediction saves the rest
    of the passes.
    """
    c0, c1, c2 = m0[0], m0[1], m0[2]
    for d in range(3):
        first[d] = m0[d]
    res = math.inf
    r = np.empty(3)
    step = np.empty(3)
    base = np.empty(3)
    res_base = math.inf
    for it in range(max_iter + 1):
        det = integrate_spatial(m0, quat0, secf, steps, c_j, rest, loads, record, rec[0], rec[1],
                                rec[2], work)
        y = work[0]
        for d in range(3):
            r[d] = y[SP_M + d] - m_tip[d]
        res = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
        if res <= tol:
            return True, it, res, stability_test(secf, steps, c_j, rest, loads, work)
        if 0 < it < max_iter and not res < res_base and math.sqrt(
                (m0[0] - base[0]) ** 2 + (m0[1] - base[1]) ** 2 + (m0[2] - base[2]) ** 2) > tol:
            # Backtracking: the full step did not reduce the residual. Arms in tension
            # amplify base-moment errors exponentially along the length, so the residual is
            # far from linear over a full Newton step; halve it towards the last iterate.
            for d in range(3):
                m0[d] = 0.5 * (m0[d] + base[d])
            continue
        if not math.isfinite(res):
            return False, it, math.inf, False
        res_base = res
        for d in range(3):
            base[d] = m0[d]
        if it == max_iter or not math.isfinite(det) or abs(det) < 1e-300:
            break
        # Cramer's rule on the 3×3 shooting Jacobian (columns ∂m(L)/∂m0_j): a nearly
        # singular matrix ends the iteration above instead of raising.
        cramer3(y[SP_DM:SP_DM + 9], r, step)
        norm = math.sqrt(step[0] ** 2 + step[1] ** 2 + step[2] ** 2)
        shrink = max_step / norm if norm > max_step else 1.0
        if math.sqrt((m0[0] - shrink * step[0] - c0) ** 2 + (m0[1] - shrink * step[1] - c1) ** 2
                     + (m0[2] - shrink * step[2] - c2) ** 2) > reach:
            return False, it, res, False
        for d in range(3):
            m0[d] -= shrink * step[d]
        if it == 0:
            for d in range(3):
                first[d] = m0[d]
    return False, max_iter, res, False


@njit
def follow(state, grid, tubes, a, b, params, work, guard):
    """Spatial dead-load path following, in the signature the path-following kernels share.

    Args:
        state: (3,) the base moment m0 (N m), updated in place.
        grid: (quat0 (4,), secf (6, ns), steps (ns,), c_j (ns,)). tubes: (tubes_i, tubes_f).
        a, b: start and goal levels (channel pressures, loads (ns, 6), tip moment (3,)).
        params: (N_PARAMS,) numeric parameters. work: (rest, p_now, loads_now, m_tip, rec,
            record) scratch holding the returned state's level; with ``record``, ``rec`` =
            (positions (N, 3), frames (N, 3, 3), moments (N, 3)) gets its backbone (else
            1-row scratch). guard: unused (the planar kernel's).

    Returns:
        (converged, stable, snapped, iterations, residual, t, dt) (t: 1 when converged, else
        NaN; dt 0), as :func:`solver.kernels.planar.follow`; the residual is the returned state's.
    """
    quat0, secf, steps, c_j = grid
    tubes_i, tubes_f = tubes
    p_a, loads_a, mtip_a = a
    p_b, loads_b, mtip_b = b
    rest, p_now, loads_now, m_tip, rec, record = work
    ok, total, stable, res, snapped = _path(
        state, quat0, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b, mtip_a,
        mtip_b, params, rest, p_now, loads_now, m_tip, rec, record)
    return ok, stable, snapped, total, res, 1.0 if ok else math.nan, 0.0


@njit
def _path(m0, quat0, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b, mtip_a,
          mtip_b, params, rest, p_now, loads_now, m_tip, rec, record):
    """Spatial quasi-static path following (see :func:`solver.kernels.planar._path`).

    ``m0`` (3,) is updated in place. Where the step falls below ``DT_MIN`` without a stable
    converged equilibrium, stability is lost between the last two levels (a bifurcation or
    a fold): :func:`_switch_branch` looks for the stable state along the critical mode and
    the ramp resumes from there (flagged as a snap). If that fails too, the last accepted
    state is returned unconverged (and reported so). ``rest``, ``p_now``, ``loads_now``, ``m_tip``
    hold the returned state's rest strains, pressures, loads and tip moment; with ``record``
    ``rec`` its backbone (:func:`_newton_first`).

    Returns (converged, iterations, stable, |residual| of the returned state, snapped).
    """
    tol = params[TOL]
    max_iter = int(params[MAX_ITER])
    max_step = params[MAX_STEP]
    # The smallest step is a share of the rest-strain change (near braid lock-up most of it
    # is crowded into the start of a pressure ramp), worked out when the step first gets there.
    dt_min = -1.0
    work = np.empty((6, NSTATE))
    t = 0.0
    dt = params[DT0]
    slope = np.zeros(3)
    accepted = m0.copy()
    guess = np.empty(3)
    first = np.empty(3)
    total = 0
    snaps = 0
    ok = True
    stable = True
    res = 0.0
    # Whether the last pass recorded the state to be returned at its level (else one more
    # pass records it and measures its residual).
    fresh = False
    # Tangent predictor for the first step of a large change (later steps use the secant
    # through accepted points), as in the planar kernel. Heavy hanging arms are in tension,
    # where single shooting amplifies a change of the base moment by e^(L·√(T/EI)): from
    # the previous state alone, Newton overshoots.
    if big_change(p_a, p_b, loads_a, loads_b) or (mtip_a[0] != mtip_b[0]
                                                  or mtip_a[1] != mtip_b[1]
                                                  or mtip_a[2] != mtip_b[2]):
        _tangent(accepted, t, quat0, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b, loads_a,
                 loads_b, mtip_a, mtip_b, rest, p_now, loads_now, m_tip, work, rec, slope)
        total += 2
    while t < 1.0:
        dt_min = smallest_step(dt, dt_min, params, p_a, p_b, tubes_i, tubes_f)
        t_new = min(1.0, t + dt)
        set_level(t_new, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
        rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
        predicted = slope[0] != 0.0 or slope[1] != 0.0 or slope[2] != 0.0
        for d in range(3):
            guess[d] = accepted[d] + slope[d] * (t_new - t)
            m0[d] = guess[d]
        # A predicted step gives up once an iterate would leave GIVE_UP times the radius it
        # is accepted within (as in the plane; not at the smallest step, where a far root
        # is a snap). A step without prediction takes Newton's first iterate as its
        # prediction (below), so it cannot give up before it knows it.
        reach = math.inf
        if predicted and dt > dt_min:
            reach = GIVE_UP * (params[JUMP] + 0.5 * math.sqrt(
                (guess[0] - accepted[0]) ** 2 + (guess[1] - accepted[1]) ** 2
                + (guess[2] - accepted[2]) ** 2))
        ok, its, res, stable = _newton_first(m0, quat0, secf, steps, c_j, rest, loads_now, m_tip,
                                             tol, max_iter, max_step, work, rec, record, first,
                                             reach)
        fresh = ok
        total += its
        if not predicted:
            # No tangent or secant (a small warm step): Newton's first iterate, the change
            # of level linearised at the start, is the prediction. Measured from the start
            # instead, an arm whose base moment moves by a quarter of the moment scale on a
            # 1 % pressure step "jumped" and was re-solved in halves.
            for d in range(3):
                guess[d] = first[d]
        # As in the planar kernel: the corrector may move the iterate little compared with
        # the step just predicted, or Newton has left the branch.
        jump = math.sqrt((m0[0] - guess[0]) ** 2 + (m0[1] - guess[1]) ** 2 + (m0[2] - guess[2]) ** 2)
        pred = math.sqrt((guess[0] - accepted[0]) ** 2 + (guess[1] - accepted[1]) ** 2
                         + (guess[2] - accepted[2]) ** 2)
        if ok and stable and (jump <= params[JUMP] + 0.5 * pred or dt <= dt_min):
            for d in range(3):
                slope[d] = (m0[d] - accepted[d]) / (t_new - t)
                accepted[d] = m0[d]
            t = t_new
            dt = min(2.0 * dt, 1.0)
            continue
        fresh = False
        if dt > dt_min:
            # (The floor is worked out now, not when a try first comes down to it: the
            # halving may pass that try.)
            dt_min = smallest_step(0.0, dt_min, params, p_a, p_b, tubes_i, tubes_f)
            dt = halved(dt, t_new - t, dt_min)
            continue
        if snaps >= 8 or params[N_SCAN] == 0:  # no snapping without the fallbacks
            break
        # Stability is lost between t and t_new. At a bifurcation (an arm curled in a
        # vertical plane buckling sideways) the new stable branch leaves along the critical
        # mode; at a fold the arm snaps, and the state it lands on is searched the same way.
        # (Pseudo-arclength continuation round folds was tried and found nothing this
        # does not on `softarm stress`.)
        found, its = _switch_branch(m0, accepted, t, t_new, quat0, secf, steps, c_j, tubes_i,
                                    tubes_f, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, params,
                                    rest, p_now, loads_now, m_tip, work, rec)
        total += its
        if found:
            # A stable converged state (measured again below, where it is the one returned).
            ok = True
            stable = True
            snaps += 1
            for d in range(3):
                accepted[d] = m0[d]
            t = t_new
            _tangent(accepted, t, quat0, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b, loads_a,
                     loads_b, mtip_a, mtip_b, rest, p_now, loads_now, m_tip, work, rec, slope)
            total += 2
            dt = params[DT0]
            continue
        break
    if t < 1.0:
        for d in range(3):
            m0[d] = accepted[d]
        set_level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
        rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
        ok = False
        stable = False
    if not fresh:
        integrate_spatial(m0, quat0, secf, steps, c_j, rest, loads_now, record, rec[0], rec[1],
                          rec[2], work)
        res = math.sqrt((work[0, SP_M] - m_tip[0]) ** 2 + (work[0, SP_M + 1] - m_tip[1]) ** 2
                        + (work[0, SP_M + 2] - m_tip[2]) ** 2)
    return ok, total, stable, res, snaps > 0


@njit
def set_level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip):
    for c in range(p_a.shape[0]):
        p_now[c] = p_a[c] + t * (p_b[c] - p_a[c])
    for i in range(loads_now.shape[0]):
        for d in range(6):
            loads_now[i, d] = loads_a[i, d] + t * (loads_b[i, d] - loads_a[i, d])
    for d in range(3):
        m_tip[d] = mtip_a[d] + t * (mtip_b[d] - mtip_a[d])


@njit
def has_negative_eigenvalue(d, det):
    """True when the 3×3 matrix stored column-wise in ``d`` (9,), of determinant ``det``,
    has a real negative eigenvalue; in arithmetic alone (it runs at every node of the
    stability pass, where root-finding by cube roots and cosines cost a third of the pass).

    The characteristic polynomial p(λ) = λ³ + aλ² + bλ + c (a = −tr, b = Σ principal 2×2
    minors, c = −det) runs from −∞ at λ → −∞ to p(0) = −det. With det < 0 it changes sign
    an odd number of times on (−∞, 0): a negative root. With det ≥ 0 it has one there only
    if it has two, which happens iff its local maximum λ_max = (−a − √(a² − 3b))/3 lies
    below zero with p(λ_max) > 0 (from there p falls through zero to p(0) ≤ 0). A double
    root there (p(λ_max) = 0: the near-coincident pair of a round section crossing zero
    together) counts within the rounding of p's terms, as does a complex pair that close to
    the negative axis: a false alarm is conservative.
    """
    if det < 0.0:
        return True
    a = -(d[0] + d[4] + d[8])
    b = (d[0] * d[4] - d[1] * d[3]) + (d[0] * d[8] - d[2] * d[6]) + (d[4] * d[8] - d[5] * d[7])
    disc = a * a - 3.0 * b
    if disc <= 0.0:
        return False  # p is monotonic: its one real root is where p(0) = −det ≤ 0 says
    lam = (-a - math.sqrt(disc)) / 3.0
    if lam >= 0.0:
        return False
    lam2 = lam * lam
    terms = -lam * lam2 + abs(a) * lam2 - abs(b) * lam + abs(det)
    return ((lam + a) * lam + b) * lam - det >= -1e-12 * terms


@njit
def stability_test(secf, steps, c_j, rest, loads, work):
    """Conjugate-point test of the equilibrium whose tip state is ``work[0]`` (after
    :func:`_integrate`): stable iff True.

    The planar solver's forward test (∂m(s)/∂m0 > 0) asks about the sub-rod [0, s] under
    the dead internal moment m(s) at its end; a dead moment is not conservative in 3D, so
    in 3D that sub-problem has no energy and no Morse index, and the test is unreliable
    (it passed arms that had already lost stability). The sub-rod [s, L], clamped at s and
    carrying its own dead loads, is conservative: the equilibrium is stable iff no
    s ∈ [0, L) admits a Jacobi field with the free-end conditions δm(L) = 0 (δn ≡ 0 under
    dead loads) and δφ(s) = 0. So the Jacobi fields δφ(L) = I, δm(L) = 0 are integrated
    from the tip to the base along the equilibrium (RK4 with negative steps), and the 3×3
    matrix δφ(s) (δφ(L) = I) must not become singular: no real eigenvalue may cross zero.
    Its determinant alone is not enough — for arms of round section the in-plane and
    out-of-plane conjugate points come in near-coincident pairs whose signs cancel in the
    determinant — so the real eigenvalues are tracked node by node (a real eigenvalue
    that is negative at a node has crossed zero since s = L). A complex pair reaching the
    negative real axis without crossing zero (a strongly twisted rod) would be a false
    alarm; it is conservative. With a dead tip *moment* in 3D (``Scene.tip_moment``) the
    sub-rods are not conservative either, and the test is the natural extension rather
    than a theorem (as for contact in :mod:`solver.kernels.contact`).

    Args:
        secf, steps, c_j, rest, loads: as for :func:`_integrate`.
        work: (6, NSTATE) scratch whose row 0 holds the tip state; overwritten.
    """
    y = work[0]
    for d in range(SP_DPHI, NSTATE):
        y[d] = 0.0
    for d in range(3):
        y[SP_DPHI + 4 * d] = 1.0  # δφ(L) = identity columns, δm(L) = 0
    for i in range(secf.shape[1] - 1, -1, -1):
        if not fields_back(y, i, 0, steps[i], secf, steps, c_j, rest, loads, work):
            return False
    return True


@njit
def fields_back(y, i, first, count, secf, steps, c_j, rest, loads, work):
    """Integrate the state and Jacobi fields ``y`` back over ``count`` RK4 steps of section
    i, from the end of step ``first + count − 1`` to the start of step ``first``; False as
    soon as a real eigenvalue of δφ is negative (or δφ is not finite)."""
    length = secf[LEN, i]
    h = -length / steps[i]
    end = first + count
    for j in range(count):
        spatial_rk4_step(y, -(end - j) * h, h, work, length, secf[CA, i], secf[CG, i], secf[CI, i],
                         c_j[i], rest[REST_U1, i], rest[REST_U2, i], rest[REST_V3, i], loads[i])
        dphi = y[SP_DPHI:SP_DPHI + 9]
        det = det3(dphi)
        if not math.isfinite(det) or has_negative_eigenvalue(dphi, det):
            return False
    return True


@njit
def planar_state_stable(x, y, theta, m_z, secf, steps, c_j, rest, loads_planar):
    """The 3D test (:func:`stability_test`) of a planar equilibrium, from its tip state.

    A planar equilibrium can pass the planar conjugate-point test and still buckle out of
    its plane (an arm curled in a vertical plane twisting sideways). The tip state (x, y,
    θ, m_z) is embedded in 3D (z = 0, d2 = +z, m along z) and integrated back to the base
    with the out-of-plane Jacobi fields.

    Args:
        x, y, theta, m_z: tip position (m), tip orientation θ(L) (rad), tip moment (N m).
        secf, steps, c_j, rest: as for :func:`_integrate`.
        loads_planar: (ns, 4) planar loads (n_end x, y; q x, y) of :mod:`solver.kernels.planar`.
    """
    work = np.empty((6, NSTATE))
    loads = np.zeros((loads_planar.shape[0], 6))
    for i in range(loads_planar.shape[0]):
        loads[i, SL_N] = loads_planar[i, NEX]
        loads[i, SL_N + 1] = loads_planar[i, NEY]
        loads[i, SL_Q] = loads_planar[i, QX]
        loads[i, SL_Q + 1] = loads_planar[i, QY]
    tip = work[0]
    tip[SP_R] = x
    tip[SP_R + 1] = y
    tip[SP_R + 2] = 0.0
    rotation_to_quaternion(base_rotation(theta), tip[SP_Q:SP_Q + 4])
    tip[SP_M] = 0.0
    tip[SP_M + 1] = 0.0
    tip[SP_M + 2] = m_z
    return stability_test(secf, steps, c_j, rest, loads, work)


@njit
def _switch_branch(m0, accepted, t, t_new, quat0, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b,
                   loads_a, loads_b, mtip_a, mtip_b, params, rest, p_now, loads_now, m_tip, work,
                   dummy):
    """Branch switching where stability is lost between levels ``t`` and ``t_new``.

    The critical mode is the right singular vector of ∂m(L)/∂m0 for its smallest singular
    value at the last stable state ``accepted`` (at level t). Newton at level t_new starts
    from ``accepted`` displaced along ± that mode by growing amounts (0.03 … 3 × EI/L) and
    the first stable equilibrium found is taken — the buckled branch of a pitchfork, or
    the state the arm snaps to. The + direction is the one whose largest component is
    positive, so the search is deterministic. Where the x–y plane is a mirror plane of the
    problem and the last stable state lies in it (a planar arm buckling sideways), the two
    buckled branches are mirror images and the +z one is returned (documented in
    ``docs/design.md``, "Which equilibrium").

    Returns (found, iterations); ``m0`` (3,) holds the state found.
    """
    scale = 4.0 * params[JUMP]
    set_level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    integrate_spatial(accepted, quat0, secf, steps, c_j, rest, loads_now, False, dummy[0], dummy[1],
               dummy[2], work)
    a = np.empty((3, 3))
    for j in range(3):
        for d in range(3):
            a[d, j] = work[0, SP_DM + 3 * j + d]
    total = 1
    for d in range(9):
        if not math.isfinite(work[0, SP_DM + d]):
            return False, total
    vt = np.linalg.svd(a)[2]
    mode = vt[2].copy()
    big = 0
    for d in range(3):
        if abs(mode[d]) > abs(mode[big]):
            big = d
    if mode[big] < 0.0:
        for d in range(3):
            mode[d] = -mode[d]
    set_level(t_new, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    amp = 0.03
    while amp < 4.0:
        for sign in (1.0, -1.0):
            for d in range(3):
                m0[d] = accepted[d] + sign * amp * scale * mode[d]
            ok, its, res, stable = newton(m0, quat0, secf, steps, c_j, rest, loads_now, m_tip,
                                          params[TOL], int(params[MAX_ITER]), params[MAX_STEP],
                                          work, dummy)
            total += its
            if ok and stable:
                if mirror_symmetric(accepted, rest, loads_now, m_tip, scale):
                    # A pitchfork out of the x–y plane: both mirror images are equilibria
                    # (reflection z → −z maps m to (−m_x, −m_y, m_z)). Take the +z one.
                    integrate_spatial(m0, quat0, secf, steps, c_j, rest, loads_now, False, dummy[0],
                               dummy[1], dummy[2], work)
                    total += 1
                    if work[0, SP_R + 2] < 0.0:
                        m0[0] = -m0[0]
                        m0[1] = -m0[1]
                return True, total
        amp *= 3.0
    found, its = _scan_roots(m0, accepted, quat0, secf, steps, c_j, rest, loads_now, m_tip, params,
                             work, dummy)
    return found, total + its


# Shells of the root scan, as fractions of the base-moment bound M_BOUND (every equilibrium
# has |m0| <= M_BOUND, so the last shell reaches across that whole ball).
_SCAN_SHELLS = (0.05, 0.15, 0.4, 1.0, 2.0)


@njit
def _scan_roots(m0, accepted, quat0, secf, steps, c_j, rest, loads, m_tip, params, work, dummy):
    """Where the critical mode leads to no stable state (the arm snaps far): the stable
    equilibrium nearest the last base moment ``accepted``, as the planar fold scan finds it
    (:func:`solver.kernels.planar.fold_scan`) — Newton from ``accepted`` moved by shells of growing
    radius (:data:`_SCAN_SHELLS` of M_BOUND) in the 26 directions of a cube's faces, edges
    and corners; the nearest stable root of the first shell that has one.

    Returns (found, iterations); ``m0`` (3,) holds the root found.
    """
    total = 0
    best = math.inf
    root = np.empty(3)
    for shell in _SCAN_SHELLS:
        radius = shell * params[M_BOUND]
        for i in range(-1, 2):
            for j in range(-1, 2):
                for k in range(-1, 2):
                    norm = math.sqrt(i * i + j * j + k * k)
                    if norm == 0.0:
                        continue
                    m0[0] = accepted[0] + radius * i / norm
                    m0[1] = accepted[1] + radius * j / norm
                    m0[2] = accepted[2] + radius * k / norm
                    ok, its, _, stable = newton(m0, quat0, secf, steps, c_j, rest, loads, m_tip,
                                                params[TOL], int(params[MAX_ITER]),
                                                params[MAX_STEP], work, dummy)
                    total += its
                    if ok and stable:
                        gap = math.sqrt((m0[0] - accepted[0]) ** 2 + (m0[1] - accepted[1]) ** 2
                                        + (m0[2] - accepted[2]) ** 2)
                        if gap < best:
                            best = gap
                            for d in range(3):
                                root[d] = m0[d]
        if best < math.inf:
            for d in range(3):
                m0[d] = root[d]
            return True, total
    return False, total


@njit
def mirror_symmetric(m0, rest, loads, m_tip, scale):
    """True when the x–y plane is a mirror plane of the problem and of the state ``m0``:
    in-plane base moment, rest curvatures and loads (u1* = 0, no z loads, tip moment along z)."""
    tiny = 1e-9 * scale
    if abs(m0[0]) > tiny or abs(m0[1]) > tiny or abs(m_tip[0]) > tiny or abs(m_tip[1]) > tiny:
        return False
    for i in range(rest.shape[1]):
        if rest[REST_U1, i] != 0.0 or loads[i, SL_N + 2] != 0.0 or loads[i, SL_Q + 2] != 0.0:
            return False
    return True


@njit
def _tangent(m0, t, quat0, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b,
             mtip_a, mtip_b, rest, p_now, loads_now, m_tip, work, dummy, slope):
    """dm0/dt = −(∂m(L)/∂m0)⁻¹ ∂r/∂t of the path at (m0, t), ∂r/∂t by a forward difference;
    written to ``slope`` (3,), zero where ∂m(L)/∂m0 is singular."""
    eps = 1e-7
    r = np.empty(3)
    for d in range(3):
        slope[d] = 0.0
    set_level(t + eps, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    integrate_spatial(m0, quat0, secf, steps, c_j, rest, loads_now, False, dummy[0], dummy[1], dummy[2],
               work)
    for d in range(3):
        r[d] = work[0, SP_M + d] - m_tip[d]
    set_level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    integrate_spatial(m0, quat0, secf, steps, c_j, rest, loads_now, False, dummy[0], dummy[1], dummy[2],
               work)
    for d in range(3):
        r[d] = -((r[d] - (work[0, SP_M + d] - m_tip[d])) / eps)
    cramer3(work[0, SP_DM:SP_DM + 9], r, slope)
    for d in range(3):
        if not math.isfinite(slope[d]):
            for k in range(3):
                slope[k] = 0.0
            return



@njit
def cramer3(cols, rhs, x):
    """Solve the 3×3 system with columns ``cols`` (9,) for ``rhs`` into ``x`` by Cramer's
    rule, in scalars: no allocation and no LAPACK call, so a singular matrix gives
    non-finite ``x`` (checked by callers) rather than an exception. Returns the determinant."""
    a0, a1, a2 = cols[0], cols[1], cols[2]
    b0, b1, b2 = cols[3], cols[4], cols[5]
    c0, c1, c2 = cols[6], cols[7], cols[8]
    r0, r1, r2 = rhs[0], rhs[1], rhs[2]
    det = a0 * (b1 * c2 - b2 * c1) - b0 * (a1 * c2 - a2 * c1) + c0 * (a1 * b2 - a2 * b1)
    if det == 0.0:
        x[0] = x[1] = x[2] = math.inf
        return det
    x[0] = (r0 * (b1 * c2 - b2 * c1) - b0 * (r1 * c2 - r2 * c1) + c0 * (r1 * b2 - r2 * b1)) / det
    x[1] = (a0 * (r1 * c2 - r2 * c1) - r0 * (a1 * c2 - a2 * c1) + c0 * (a1 * r2 - a2 * r1)) / det
    x[2] = (a0 * (b1 * r2 - b2 * r1) - b0 * (a1 * r2 - a2 * r1) + r0 * (a1 * b2 - a2 * b1)) / det
    return det

