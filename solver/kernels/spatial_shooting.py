"""Spatial multiple shooting under dead loads (docs/design.md §6).

Single shooting (:mod:`solver.kernels.spatial`) amplifies an error of the base moment by up to
e^(L·√(N/EI)) along a rod in tension: past an index of about 20 it cannot converge. Here the
rod is cut into the segments of :func:`solver.problem.shooting_layout` (a few RK4 steps
each), and the unknowns are the base moment m0 and, at every later segment start k, the
orientation R_k (a unit quaternion, corrected by world-frame rotations δφ) and the moment m_k.
With dead loads the internal force is known, and the position does not enter the equations
(r' depends on R and n only), so a node needs no position. The residuals are the jumps at
the segment ends — the rotation vector of R_end R_{k+1}ᵀ (scaled by the arm's moment scale
to N m) and m_end − m_{k+1} — and m(L) − M_tip at the tip. Each segment's sensitivities
come from the variational equations of :func:`solver.rod.spatial_rhs`, integrated twice
(δm(start) = I, then δφ(start) = I); the block-banded Newton system is solved by banded
Gaussian elimination with partial pivoting.

Stability is the conjugate-point test of :func:`solver.kernels.spatial.stability_test`, with the
Jacobi fields carried from the tip to the base segment by segment, each segment restarted
from its node (integrating the state itself back over the whole rod would be single
shooting again).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.homotopy import halved, smallest_step
from solver.kernels.spatial import fields_back, mirror_symmetric, set_level
from solver.layout import (
    CA,
    CG,
    CI,
    DT0,
    JUMP,
    LEN,
    MAX_ITER,
    MAX_STEP,
    N_SCAN,
    NSTATE,
    REST_U1,
    REST_U2,
    REST_V3,
    SEG_END,
    SEG_FIRST,
    SEG_ROW0,
    SEG_SECTION,
    SEG_STEPS,
    SP_DM,
    SP_DPHI,
    SP_M,
    SP_Q,
    SP_R,
    TOL,
)
from solver.rod import det3, record_spatial_row, rest_strains_into, spatial_rk4_step

# Columns of the variational state a segment pass starts with: δm(start) = I or δφ(start) = I.
_BY_MOMENT, _BY_ROTATION = 0, 1


@njit
def n_unknowns(n_segments):
    """Unknowns (and residuals) of a spatial multiple-shooting system of ``n_segments``."""
    return 6 * (n_segments - 1) + 3


@njit
def _run_segment(k, quat, mom, pos, by, segs, secf, steps, c_j, rest, loads, work, record,
                 out_pos, out_rot, out_m):
    """Integrate segment k from the node (quat (4,), mom (3,), pos (3,)) with the
    sensitivities to the node's moment (``by`` = _BY_MOMENT) or rotation (_BY_ROTATION);
    the end state is left in ``work[0]``. With ``record`` its samples are written."""
    y = work[0]
    for d in range(NSTATE):
        y[d] = 0.0
    for d in range(3):
        y[SP_R + d] = pos[d]
        y[SP_M + d] = mom[d]
    for d in range(4):
        y[SP_Q + d] = quat[d]
    first_column = SP_DM if by == _BY_MOMENT else SP_DPHI
    for d in range(3):
        y[first_column + 4 * d] = 1.0
    i = segs[k, SEG_SECTION]
    first = segs[k, SEG_FIRST]
    length = secf[LEN, i]
    h = length / steps[i]
    row = segs[k, SEG_ROW0] + first
    for j in range(first, first + segs[k, SEG_STEPS]):
        if record:
            record_spatial_row(y, out_pos, out_rot, out_m, row)
            row += 1
        spatial_rk4_step(y, j * h, h, work, length, secf[CA, i], secf[CG, i], secf[CI, i], c_j[i],
                         rest[REST_U1, i], rest[REST_U2, i], rest[REST_V3, i], loads[i])
    if record and segs[k, SEG_END] == 1:
        record_spatial_row(y, out_pos, out_rot, out_m, row)


@njit
def rotation_gap(qa, qb, scale, out):
    """``scale`` × the rotation vector of R(qa) R(qb)ᵀ (world frame), into ``out[0:3]``."""
    aw, ax, ay, az = qa[0], qa[1], qa[2], qa[3]
    bw, bx, by, bz = qb[0], -qb[1], -qb[2], -qb[3]
    w = aw * bw - ax * bx - ay * by - az * bz
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    v = math.sqrt(x * x + y * y + z * z)
    f = 2.0 * math.atan2(v, w) / v if v > 1e-300 else 2.0
    out[0] = scale * f * x
    out[1] = scale * f * y
    out[2] = scale * f * z


@njit
def rotate_node(quat, phi, amount):
    """quat ← exp(amount · [φ]×) ⊗ quat (a world-frame rotation), renormalised."""
    px, py, pz = amount * phi[0], amount * phi[1], amount * phi[2]
    angle = math.sqrt(px * px + py * py + pz * pz)
    half = 0.5 * angle
    s = math.sin(half) / angle if angle > 1e-300 else 0.5
    rw, rx, ry, rz = math.cos(half), s * px, s * py, s * pz
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    quat[0] = rw * w - rx * x - ry * y - rz * z
    quat[1] = rw * x + rx * w + ry * z - rz * y
    quat[2] = rw * y - rx * z + ry * w + rz * x
    quat[3] = rw * z + rx * y - ry * x + rz * w
    norm = math.sqrt(quat[0] ** 2 + quat[1] ** 2 + quat[2] ** 2 + quat[3] ** 2)
    for d in range(4):
        quat[d] /= norm


@njit
def _system(quats, moms, segs, secf, steps, c_j, rest, loads, m_tip, scale, jacobian, res,
            with_jacobian, work):
    """Residuals (N m) of the nodes ``quats`` (K, 4), ``moms`` (K, 3) into ``res``, and with
    ``with_jacobian`` their Jacobian (unknowns: δm0, then (δφ_k, δm_k) per later node) into
    ``jacobian``. Returns False where a state is not finite."""
    n_seg = segs.shape[0]
    pos = np.zeros(3)
    start = np.zeros(3)
    none = (np.empty((1, 3)), np.empty((1, 3, 3)), np.empty((1, 3)))
    if with_jacobian:
        jacobian[:, :] = 0.0
    y = work[0]
    for k in range(n_seg):
        for d in range(3):
            start[d] = pos[d]
        for by in (_BY_MOMENT, _BY_ROTATION):
            if by == _BY_ROTATION and (k == 0 or not with_jacobian):
                break  # the base orientation is given
            _run_segment(k, quats[k], moms[k], start, by, segs, secf, steps, c_j, rest, loads,
                         work, False, none[0], none[1], none[2])
            for d in range(SP_DM + 9):
                if not math.isfinite(y[d]):
                    return False
            row = 6 * k
            column = 0 if k == 0 else 3 + 6 * (k - 1) + (3 if by == _BY_MOMENT else 0)
            last = k == n_seg - 1
            if by == _BY_MOMENT:
                for d in range(3):
                    pos[d] = y[SP_R + d]
                if last:
                    for d in range(3):
                        res[row + d] = y[SP_M + d] - m_tip[d]
                else:
                    rotation_gap(y[SP_Q:SP_Q + 4], quats[k + 1], scale, res[row:row + 3])
                    for d in range(3):
                        res[row + 3 + d] = y[SP_M + d] - moms[k + 1, d]
            if not with_jacobian:
                continue
            for b in range(3):
                for a in range(3):
                    if last:
                        jacobian[row + a, column + b] = y[SP_DM + 3 * b + a]
                    else:
                        jacobian[row + a, column + b] = scale * y[SP_DPHI + 3 * b + a]
                        jacobian[row + 3 + a, column + b] = y[SP_DM + 3 * b + a]
            if by == _BY_MOMENT and not last:
                following = 3 + 6 * k
                for a in range(3):
                    jacobian[row + a, following + a] = -scale
                    jacobian[row + 3 + a, following + 3 + a] = -1.0
    return True


@njit
def banded_solve(a, b, x):
    """Solve a x = b for the block-banded multiple-shooting matrix ``a`` (n, n), destroyed,
    by Gaussian elimination with partial pivoting that visits only each row's nonzero span
    (O(n·bandwidth²)). Returns False for a singular or non-finite matrix."""
    n = a.shape[0]
    last = np.empty(n, dtype=np.int64)
    reach = 1  # rows below a pivot that may hold a nonzero in its column (the lower bandwidth + 1)
    for i in range(n):
        last[i] = -1
        first = n
        for j in range(n):
            if a[i, j] != 0.0:
                first = min(first, j)
                last[i] = j
        reach = max(reach, i - first + 1)
    for j in range(n):
        pivot = j
        big = 0.0
        end = min(n, j + reach)
        for i in range(j, end):
            if abs(a[i, j]) > big:
                big = abs(a[i, j])
                pivot = i
        if not (big > 0.0 and math.isfinite(big)):
            return False
        if pivot != j:
            for c in range(j, n):
                a[j, c], a[pivot, c] = a[pivot, c], a[j, c]
            b[j], b[pivot] = b[pivot], b[j]
            last[j], last[pivot] = last[pivot], last[j]
        for i in range(j + 1, end):
            factor = a[i, j] / a[j, j]
            if factor != 0.0:
                for c in range(j, last[j] + 1):
                    a[i, c] -= factor * a[j, c]
                b[i] -= factor * b[j]
                last[i] = max(last[i], last[j])
    for i in range(n - 1, -1, -1):
        total = b[i]
        for c in range(i + 1, last[i] + 1):
            total -= a[i, c] * x[c]
        x[i] = total / a[i, i]
        if not math.isfinite(x[i]):
            return False
    return True


@njit
def _apply(quats, moms, base_q, base_m, dx, amount):
    """Nodes = base nodes moved by ``amount`` × the Newton step ``dx``."""
    for k in range(quats.shape[0]):
        for d in range(4):
            quats[k, d] = base_q[k, d]
        for d in range(3):
            moms[k, d] = base_m[k, d]
    for d in range(3):
        moms[0, d] += amount * dx[d]
    for k in range(1, quats.shape[0]):
        col = 3 + 6 * (k - 1)
        rotate_node(quats[k], dx[col:col + 3], amount)
        for d in range(3):
            moms[k, d] += amount * dx[col + 3 + d]


@njit
def _step_size(dx, scale):
    """Largest node move of a Newton step, moments in N m and rotations × ``scale``."""
    size = math.sqrt(dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2)
    for col in range(3, dx.shape[0], 6):
        phi = scale * math.sqrt(dx[col] ** 2 + dx[col + 1] ** 2 + dx[col + 2] ** 2)
        mom = math.sqrt(dx[col + 3] ** 2 + dx[col + 4] ** 2 + dx[col + 5] ** 2)
        size = max(size, math.sqrt(phi * phi + mom * mom))
    return size


@njit
def _newton(quats, moms, segs, secf, steps, c_j, rest, loads, m_tip, scale, tol, max_iter,
            max_step, work):
    """Newton on the multiple-shooting residuals, nodes updated in place (the full step
    halved towards the last iterate while it does not reduce the residual, and limited to
    ``max_step`` N m per node). Returns (converged, iterations, |residual|)."""
    n = n_unknowns(segs.shape[0])
    jacobian = np.empty((n, n))
    res = np.empty(n)
    dx = np.empty(n)
    base_q = quats.copy()
    base_m = moms.copy()
    res_base = math.inf
    amount = 1.0
    norm = math.inf
    for it in range(max_iter + 1):
        finite = _system(quats, moms, segs, secf, steps, c_j, rest, loads, m_tip, scale,
                         jacobian, res, True, work)
        norm = math.sqrt(np.sum(res * res)) if finite else math.inf
        if norm <= tol:
            return True, it, norm
        if it > 0 and not norm < res_base and amount > 1e-3:
            amount *= 0.5  # backtrack: the full step did not reduce the residual
            _apply(quats, moms, base_q, base_m, dx, amount)
            continue
        if not finite or it == max_iter:
            break
        res_base = norm
        base_q[:, :] = quats
        base_m[:, :] = moms
        rhs = -res
        if not banded_solve(jacobian, rhs, dx):
            break
        size = _step_size(dx, scale)
        amount = max_step / size if size > max_step else 1.0
        _apply(quats, moms, base_q, base_m, dx, amount)
    quats[:, :] = base_q
    moms[:, :] = base_m
    return False, max_iter, norm


@njit
def stability_test(quats, moms, segs, secf, steps, c_j, rest, loads, work):
    """Conjugate-point test (:func:`solver.kernels.spatial.stability_test`) of converged nodes: the
    Jacobi fields δφ(L) = I, δm(L) = 0 are integrated from the tip to the base, each segment
    from its own end node (the tip's end state for the last).

    Along a rod in tension the bending fields grow like e^(L·√(N/EI)) while the torsional
    one does not: δφ(s) soon has eigenvalues 10¹⁶ apart and the small one is lost to
    round-off. So at every segment start s_k the fields F (6×3) are restarted as
    F δφ(s_k)⁻¹ = (I, W), W = δm δφ⁻¹ the Riccati variable, which stays of the size of the
    arm's stiffness away from a conjugate point. Within the segment the δφ block is then
    δφ(s) δφ(s_k)⁻¹: it starts at I, and, as in the single-shooting test, none of its real
    eigenvalues may turn negative (det δφ(s) keeps its sign through the restarts, which
    multiply it by det δφ(s_k)⁻¹ > 0).
    """
    n_seg = segs.shape[0]
    none = (np.empty((1, 3)), np.empty((1, 3, 3)), np.empty((1, 3)))
    zero = np.zeros(3)
    _run_segment(n_seg - 1, quats[n_seg - 1], moms[n_seg - 1], zero, _BY_MOMENT, segs, secf,
                 steps, c_j, rest, loads, work, False, none[0], none[1], none[2])
    y = work[0]
    for d in range(SP_DPHI, SP_DM + 9):
        y[d] = 0.0
    for d in range(3):
        y[SP_DPHI + 4 * d] = 1.0
    scratch = np.empty(18)
    for k in range(n_seg - 1, -1, -1):
        if k < n_seg - 1:
            for d in range(4):
                y[SP_Q + d] = quats[k + 1, d]
            for d in range(3):
                y[SP_M + d] = moms[k + 1, d]
            if not _restart_fields(y, scratch):
                return False
        if not fields_back(y, segs[k, SEG_SECTION], segs[k, SEG_FIRST], segs[k, SEG_STEPS],
                           secf, steps, c_j, rest, loads, work):
            return False
    return True


@njit
def _restart_fields(y, scratch):
    """Jacobi fields (δφ, δm) in ``y`` (column-wise blocks at SP_DPHI, SP_DM) replaced by
    (I, δm δφ⁻¹); ``scratch`` (18,): δφ⁻¹, then the product. False if δφ is singular or not
    finite."""
    phi = y[SP_DPHI:SP_DPHI + 9]
    det = det3(phi)
    if not (math.isfinite(det) and det != 0.0):
        return False
    inv = scratch[:9]
    riccati = scratch[9:]
    # δφ⁻¹ by the adjugate (column-wise storage: entry (row a, column b) at 3b + a).
    for a in range(3):
        for b in range(3):
            a1, a2 = (a + 1) % 3, (a + 2) % 3
            b1, b2 = (b + 1) % 3, (b + 2) % 3
            # (δφ⁻¹)[a, b] = cofactor(b, a) / det
            inv[3 * b + a] = (phi[3 * a1 + b1] * phi[3 * a2 + b2]
                              - phi[3 * a2 + b1] * phi[3 * a1 + b2]) / det
    for a in range(3):
        for b in range(3):
            total = 0.0
            for c in range(3):
                total += y[SP_DM + 3 * c + a] * inv[3 * b + c]
            riccati[3 * b + a] = total
    for d in range(9):
        y[SP_DM + d] = riccati[d]
        y[SP_DPHI + d] = 0.0
    for d in range(3):
        y[SP_DPHI + 4 * d] = 1.0
    return True


@njit
def record(quats, moms, segs, secf, steps, c_j, rest, loads, work, out_pos, out_rot, out_m):
    """Write the backbone of the nodes (positions (N, 3), frames (N, 3, 3), moments (N, 3))
    segment by segment, each from its node (positions carried from the base at the origin);
    returns the tip state's moment (3,)."""
    pos = np.zeros(3)
    for k in range(segs.shape[0]):
        _run_segment(k, quats[k], moms[k], pos, _BY_MOMENT, segs, secf, steps, c_j, rest, loads,
                     work, True, out_pos, out_rot, out_m)
        for d in range(3):
            pos[d] = work[0, SP_R + d]
    return work[0, SP_M:SP_M + 3].copy()


@njit
def _distance(quats_a, moms_a, quats_b, moms_b, scale):
    """Largest node distance between two node sets (moments N m, rotations × ``scale``)."""
    gap = np.empty(3)
    size = 0.0
    for k in range(quats_a.shape[0]):
        rotation_gap(quats_a[k], quats_b[k], scale, gap)
        dm = 0.0
        for d in range(3):
            dm += (moms_a[k, d] - moms_b[k, d]) ** 2
        size = max(size, math.sqrt(dm + gap[0] ** 2 + gap[1] ** 2 + gap[2] ** 2))
    return size


@njit
def follow(quats, moms, segs, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b, loads_a, loads_b,
           mtip_a, mtip_b, params, scale, rest, p_now, loads_now, m_tip):
    """Quasi-static path following of the nodes from level a to level b, as
    :func:`solver.kernels.spatial._path`: secant predictor, step halving down to the smallest step
    (a share of the rest-strain change, :func:`solver.kernels.homotopy.ramp_crowding`), a corrector
    that must stay near its prediction, and where stability is lost between two levels a
    switch to the stable branch (:func:`_switch_branch`). ``quats`` (K, 4) and ``moms``
    (K, 3) are updated in place; ``rest``, ``p_now``, ``loads_now``, ``m_tip`` hold the
    returned state's level. Where the path cannot go on, the last accepted state is
    returned unconverged.

    Returns (converged, iterations, stable, |residual|, snapped).
    """
    tol = params[TOL]
    max_iter = int(params[MAX_ITER])
    max_step = params[MAX_STEP]
    dt_min = -1.0  # worked out when the step first comes down to params[DT_MIN]
    work = np.empty((6, NSTATE))
    acc_q, acc_m = quats.copy(), moms.copy()
    prev_q, prev_m = quats.copy(), moms.copy()
    guess_q, guess_m = quats.copy(), moms.copy()
    t = 0.0
    t_prev = -1.0  # no earlier accepted level: the first prediction is the start state
    dt = params[DT0]
    total = 0
    snaps = 0
    ok = True
    stable = True
    res = 0.0
    while t < 1.0:
        dt_min = smallest_step(dt, dt_min, params, p_a, p_b, tubes_i, tubes_f)
        t_new = min(1.0, t + dt)
        set_level(t_new, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
        rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
        # Secant predictor through the last two accepted states.
        w = (t_new - t) / (t - t_prev) if t_prev >= 0.0 else 0.0
        for k in range(quats.shape[0]):
            for d in range(4):
                guess_q[k, d] = acc_q[k, d] + w * (acc_q[k, d] - prev_q[k, d])
            norm = math.sqrt(np.sum(guess_q[k] ** 2))
            for d in range(4):
                guess_q[k, d] /= norm
            for d in range(3):
                guess_m[k, d] = acc_m[k, d] + w * (acc_m[k, d] - prev_m[k, d])
        quats[:, :] = guess_q
        moms[:, :] = guess_m
        ok, its, res = _newton(quats, moms, segs, secf, steps, c_j, rest, loads_now, m_tip, scale,
                               tol, max_iter, max_step, work)
        total += its
        stable = ok and stability_test(quats, moms, segs, secf, steps, c_j, rest, loads_now, work)
        jump = _distance(quats, moms, guess_q, guess_m, scale)
        pred = _distance(guess_q, guess_m, acc_q, acc_m, scale)
        if ok and stable and (jump <= params[JUMP] + 0.5 * pred or dt <= dt_min):
            prev_q[:, :] = acc_q
            prev_m[:, :] = acc_m
            acc_q[:, :] = quats
            acc_m[:, :] = moms
            t_prev = t
            t = t_new
            dt = min(2.0 * dt, 1.0)
            continue
        if dt > dt_min:
            # (The floor is worked out now, not when a try first comes down to it: the
            # halving may pass that try.)
            dt_min = smallest_step(0.0, dt_min, params, p_a, p_b, tubes_i, tubes_f)
            dt = halved(dt, t_new - t, dt_min)
            continue
        if snaps >= 8 or params[N_SCAN] == 0:  # no snapping without the fallbacks
            break
        # Stability is lost between t and t_new (a bifurcation or a fold): the stable state
        # along the critical mode at t_new, and the ramp resumes from there.
        quats[:, :] = acc_q
        moms[:, :] = acc_m
        found, its = _switch_branch(quats, moms, t, t_new, segs, secf, steps, c_j, tubes_i,
                                    tubes_f, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, params,
                                    scale, rest, p_now, loads_now, m_tip, work)
        total += its
        if not found:
            break
        snaps += 1
        acc_q[:, :] = quats
        acc_m[:, :] = moms
        t_prev = -1.0  # no secant across a snap
        t = t_new
        dt = params[DT0]
    if t < 1.0:
        quats[:, :] = acc_q
        moms[:, :] = acc_m
        set_level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
        rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
        return False, total, False, res, snaps > 0
    return ok, total, stable, res, snaps > 0


@njit
def _switch_branch(quats, moms, t, t_new, segs, secf, steps, c_j, tubes_i, tubes_f, p_a, p_b,
                   loads_a, loads_b, mtip_a, mtip_b, params, scale, rest, p_now, loads_now,
                   m_tip, work):
    """Branch switching of the multiple-shooting path, as :func:`solver.kernels.spatial._switch_branch`:
    the critical mode is the right singular vector of the shooting Jacobian for its
    smallest singular value at the last stable state (``quats``, ``moms`` at level t); Newton
    at level t_new starts from that state moved along ± the mode (largest node move 0.03 …
    3 × 4·JUMP) and the first stable equilibrium is taken; where the x–y plane is a mirror
    plane of the problem and of the last state, the +z one of the two mirror images.

    Returns (found, iterations); the nodes hold the state found (else the last state).
    """
    n = n_unknowns(segs.shape[0])
    jacobian = np.empty((n, n))
    res = np.empty(n)
    set_level(t, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    base_q, base_m = quats.copy(), moms.copy()
    if not _system(quats, moms, segs, secf, steps, c_j, rest, loads_now, m_tip, scale, jacobian,
                   res, True, work):
        return False, 1
    mode = np.linalg.svd(jacobian)[2][n - 1].copy()
    big = 0
    for d in range(n):
        if abs(mode[d]) > abs(mode[big]):
            big = d
    if mode[big] < 0.0:
        mode = -mode
    symmetric = mirror_symmetric(moms[0], rest, loads_now, m_tip, 4.0 * params[JUMP])
    set_level(t_new, p_a, p_b, loads_a, loads_b, mtip_a, mtip_b, p_now, loads_now, m_tip)
    rest_strains_into(p_now, tubes_i, tubes_f, secf, rest)
    unit = 4.0 * params[JUMP] / _step_size(mode, scale)
    total = 1
    amp = 0.03
    while amp < 4.0:
        for sign in (1.0, -1.0):
            _apply(quats, moms, base_q, base_m, mode, sign * amp * unit)
            ok, its, _ = _newton(quats, moms, segs, secf, steps, c_j, rest, loads_now, m_tip,
                                 scale, params[TOL], int(params[MAX_ITER]), params[MAX_STEP], work)
            total += its
            if ok and stability_test(quats, moms, segs, secf, steps, c_j, rest, loads_now, work):
                if symmetric and _tip_z(quats, moms, segs, secf, steps, c_j, rest, loads_now,
                                        work) < 0.0:
                    # A pitchfork out of the x–y plane: reflect z → −z (m → (−m_x, −m_y, m_z),
                    # R → S R S with S = diag(1, 1, −1)).
                    for k in range(quats.shape[0]):
                        quats[k, 1] = -quats[k, 1]
                        quats[k, 2] = -quats[k, 2]
                        moms[k, 0] = -moms[k, 0]
                        moms[k, 1] = -moms[k, 1]
                return True, total
        amp *= 3.0
    quats[:, :] = base_q
    moms[:, :] = base_m
    return False, total


@njit
def _tip_z(quats, moms, segs, secf, steps, c_j, rest, loads, work):
    """The tip's height z (m) of the nodes, the base at the origin."""
    none = (np.empty((1, 3)), np.empty((1, 3, 3)), np.empty((1, 3)))
    pos = np.zeros(3)
    for k in range(segs.shape[0]):
        _run_segment(k, quats[k], moms[k], pos, _BY_MOMENT, segs, secf, steps, c_j, rest, loads,
                     work, False, none[0], none[1], none[2])
        for d in range(3):
            pos[d] = work[0, SP_R + d]
    return pos[2]
