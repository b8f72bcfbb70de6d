"""Obstacle geometry shared by the contact kernels and the contact-free guards.

Planar obstacles are discs in the x–y plane, an (n, 4) array of centre x, centre y, radius
and penalty stiffness (N/m²); spatial ones cylinders and spheres, an (n, 8) array
(``layout.O_*``): a point, an axis (zero for a sphere), radius and stiffness. The penalty
law is the same: force per reference length k·penetration along the outward normal. Two
questions are asked of a quasi-static path between accepted states: is the backbone clear
of every obstacle, and did any backbone sample *tunnel* — pass through an obstacle between
two states, which a continuation step can do when it is too long (a penalty obstacle exerts
no force on a backbone that has already crossed it)?
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.layout import (
    CX,
    CY,
    FS_A,
    FS_F,
    FS_NEW,
    FS_R,
    FS_SLIP,
    FS_WORK,
    O_AXIS,
    O_P,
    O_RADIUS,
    O_STIFFNESS,
    RADIUS,
    STIFFNESS,
    THETA,
    X,
    Y,
)

# A point whose squared distance from a disc's centre is at least this multiple of R² lies
# outside it, rounding included: the penalty sums skip such discs before the square root.
CLEAR_SQUARE = 1.0 + 1e-12


@njit(inline="always")
def contact_force(x, y, discs):
    """Penalty force per length (fx, fy) and deepest penetration at backbone point (x, y).

    f = k · max(0, R − |r − c|) · (r − c)/|r − c| summed over the discs (N/m).
    """
    fx = 0.0
    fy = 0.0
    deepest = 0.0
    for d in range(discs.shape[0]):
        dx = x - discs[d, CX]
        dy = y - discs[d, CY]
        d2 = dx * dx + dy * dy
        if not d2 < discs[d, RADIUS] * discs[d, RADIUS] * CLEAR_SQUARE:
            continue
        dist = math.sqrt(d2)
        pen = discs[d, RADIUS] - dist
        if pen > 0.0 and dist > 0.0:
            scale = discs[d, STIFFNESS] * pen / dist
            fx += scale * dx
            fy += scale * dy
            if pen > deepest:
                deepest = pen
    return fx, fy, deepest


@njit
def penalty_energy(pen, stiffness):
    """Potential (J/m) of the penalty force per length: ½ k pen² inside, 0 outside."""
    return 0.5 * stiffness * pen * pen if pen > 0.0 else 0.0


@njit(inline="always")
def contact_stiffness(x, y, discs):
    """∂f/∂r of :func:`contact_force` at (x, y), f the penalty force per length: the
    symmetric 2×2 (k00, k01, k11) summed over the discs pressed,
    −k ûûᵀ + (k·pen/|d|)(I − ûûᵀ), û = d/|d|, d = r − c."""
    k00 = 0.0
    k01 = 0.0
    k11 = 0.0
    for d in range(discs.shape[0]):
        dx = x - discs[d, CX]
        dy = y - discs[d, CY]
        d2 = dx * dx + dy * dy
        if not d2 < discs[d, RADIUS] * discs[d, RADIUS] * CLEAR_SQUARE:
            continue
        dist = math.sqrt(d2)
        pen = discs[d, RADIUS] - dist
        if pen > 0.0 and dist > 0.0:
            k = discs[d, STIFFNESS]
            ux = dx / dist
            uy = dy / dist
            hoop = k * pen / dist
            k00 += -k * ux * ux + hoop * (1.0 - ux * ux)
            k01 += -(k + hoop) * ux * uy
            k11 += -k * uy * uy + hoop * (1.0 - uy * uy)
    return k00, k01, k11


@njit
def nearest_surface(x, y, discs):
    """(gap, ux, uy): the smallest signed gap from (x, y) to a disc surface (m; negative
    inside) and the outward unit normal of that disc there (∂gap/∂(x, y))."""
    gap = math.inf
    ux = 0.0
    uy = 0.0
    for d in range(discs.shape[0]):
        dx = x - discs[d, CX]
        dy = y - discs[d, CY]
        dist = math.sqrt(dx * dx + dy * dy)
        g = dist - discs[d, RADIUS]
        if g < gap:
            gap = g
            ux = dx / dist if dist > 0.0 else 0.0
            uy = dy / dist if dist > 0.0 else 0.0
    return gap, ux, uy


@njit
def clearance(x, y, discs):
    """Smallest signed gap from (x, y) to the disc surfaces (m; negative inside a disc)."""
    gap = math.inf
    for d in range(discs.shape[0]):
        g = math.hypot(x - discs[d, CX], y - discs[d, CY]) - discs[d, RADIUS]
        if g < gap:
            gap = g
    return gap


# A backbone between two samples departs from their chord by at most its sag, ℓ·|Δθ|/8 for a
# circular arc of chord ℓ turning Δθ; the allowance doubles that (curvature varying along it)
# and adds CHORD_SLACK·ℓ for the change of stretch and shear (strains of order 1e-3).
CHORD_SLACK = 0.01


@njit(inline="always")
def _chord_allowance(rec, r) -> float:
    """ℓ·(|Δθ|/4 + CHORD_SLACK) of the chord from sample r to r + 1 of ``rec`` (m)."""
    length = math.hypot(rec[r + 1, X] - rec[r, X], rec[r + 1, Y] - rec[r, Y])
    return length * (0.25 * abs(rec[r + 1, THETA] - rec[r, THETA]) + CHORD_SLACK)


@njit
def chord_allowance(rec) -> float:
    """The largest departure (m) of the backbone of ``rec`` (rows, ≥ THETA + 1: columns x, y,
    θ of the settings' grid) from the chord between two consecutive samples:
    ℓ·(|Δθ|/4 + CHORD_SLACK) (the module's sag bound), over the chords."""
    allowance = 0.0
    for r in range(rec.shape[0] - 1):
        allowance = max(allowance, _chord_allowance(rec, r))
    return allowance


@njit
def chords_clear(rec, discs) -> bool:
    """True when the backbone of ``rec`` (rows, ≥ THETA + 1: x, y, θ) clears every disc of
    ``discs`` (n, 4) between every two consecutive samples: the straight chord between them
    stays out of the disc by more than the backbone can depart from it there,
    ℓ·(|Δθ|/4 + CHORD_SLACK) (:func:`chord_allowance`'s bound, chord by chord). Then no
    point of the backbone — not only the samples — touches a disc, so every penalty force
    along it is zero."""
    for r in range(rec.shape[0] - 1):
        allowance = _chord_allowance(rec, r)
        for d in range(discs.shape[0]):
            if _segment_depth(rec[r, X], rec[r, Y], rec[r + 1, X], rec[r + 1, Y], discs[d, CX],
                              discs[d, CY], discs[d, RADIUS]) >= -allowance:
                return False
    return True


@njit
def _segment_depth(ax, ay, bx, by, cx, cy, radius):
    """Deepest penetration of the straight segment a → b into the disc (c, radius) (m)."""
    ex = bx - ax
    ey = by - ay
    length2 = ex * ex + ey * ey
    t = 0.0
    if length2 > 0.0:
        t = min(1.0, max(0.0, ((cx - ax) * ex + (cy - ay) * ey) / length2))
    return radius - math.hypot(ax + t * ex - cx, ay + t * ey - cy)


@njit
def tunnels(prev_xy, new_xy, discs, slack):
    """True when a backbone sample crossed into a disc between two states, deeper than at
    either end.

    Each sample is taken to move along the straight segment between its two positions; a
    move is a tunnel when that segment goes deeper into a disc than the deeper of its two
    end points by more than ``slack`` (m). Sliding along or around a disc's surface in
    short steps is not a tunnel; jumping through the disc (or across part of it) is.

    Args:
        prev_xy, new_xy: (N, ≥2) sample positions (m) of the two states (columns x, y).
        discs: (n, 4) obstacles. slack: allowance (m).
    """
    for k in range(prev_xy.shape[0]):
        ax = prev_xy[k, 0]
        ay = prev_xy[k, 1]
        bx = new_xy[k, 0]
        by = new_xy[k, 1]
        for d in range(discs.shape[0]):
            cx = discs[d, CX]
            cy = discs[d, CY]
            r = discs[d, RADIUS]
            end = max(r - math.hypot(ax - cx, ay - cy), r - math.hypot(bx - cx, by - cy))
            if _segment_depth(ax, ay, bx, by, cx, cy, r) > max(end, 0.0) + slack:
                return True
    return False


@njit(inline="always")
def _offset_3d(r0, r1, r2, obstacles, d):
    """The vector (3 floats) from the core of spatial obstacle ``d`` — the nearest point of
    a cylinder's axis, or a sphere's centre — to (r0, r1, r2), and its length (m)."""
    e0 = r0 - obstacles[d, O_P]
    e1 = r1 - obstacles[d, O_P + 1]
    e2 = r2 - obstacles[d, O_P + 2]
    a0 = obstacles[d, O_AXIS]
    a1 = obstacles[d, O_AXIS + 1]
    a2 = obstacles[d, O_AXIS + 2]
    along = e0 * a0 + e1 * a1 + e2 * a2  # 0 for a sphere (zero axis)
    e0 -= along * a0
    e1 -= along * a1
    e2 -= along * a2
    return e0, e1, e2, math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)


@njit
def contact_force_3d(r0, r1, r2, obstacles):
    """Penalty force per length (fx, fy, fz; N/m) and deepest penetration (m) at backbone
    point r among spatial ``obstacles`` (n, 8): f = k · max(0, R − |e|) · e/|e|, e the offset
    from the obstacle's core (:func:`_offset_3d`)."""
    fx = 0.0
    fy = 0.0
    fz = 0.0
    deepest = 0.0
    for d in range(obstacles.shape[0]):
        e0, e1, e2, dist = _offset_3d(r0, r1, r2, obstacles, d)
        pen = obstacles[d, O_RADIUS] - dist
        if pen > 0.0 and dist > 0.0:
            scale = obstacles[d, O_STIFFNESS] * pen / dist
            fx += scale * e0
            fy += scale * e1
            fz += scale * e2
            if pen > deepest:
                deepest = pen
    return fx, fy, fz, deepest


@njit
def contact_stiffness_3d(r0, r1, r2, obstacles):
    """∂f/∂r of :func:`contact_force_3d` at r, f the penalty force per length: the
    symmetric 3×3 (k00, k01, k02, k11, k12, k22) summed over the obstacles pressed,
    k·(−ûûᵀ + (pen/|e|)(P − ûûᵀ)), û = e/|e| and P = ∂e/∂r the projection off a cylinder's
    axis (the identity about a sphere's centre)."""
    k00 = k01 = k02 = k11 = k12 = k22 = 0.0
    for d in range(obstacles.shape[0]):
        e0, e1, e2, dist = _offset_3d(r0, r1, r2, obstacles, d)
        pen = obstacles[d, O_RADIUS] - dist
        if pen > 0.0 and dist > 0.0:
            k = obstacles[d, O_STIFFNESS]
            u0 = e0 / dist
            u1 = e1 / dist
            u2 = e2 / dist
            a0 = obstacles[d, O_AXIS]
            a1 = obstacles[d, O_AXIS + 1]
            a2 = obstacles[d, O_AXIS + 2]
            hoop = pen / dist
            k00 += k * (-u0 * u0 + hoop * (1.0 - a0 * a0 - u0 * u0))
            k01 += k * (-u0 * u1 + hoop * (-a0 * a1 - u0 * u1))
            k02 += k * (-u0 * u2 + hoop * (-a0 * a2 - u0 * u2))
            k11 += k * (-u1 * u1 + hoop * (1.0 - a1 * a1 - u1 * u1))
            k12 += k * (-u1 * u2 + hoop * (-a1 * a2 - u1 * u2))
            k22 += k * (-u2 * u2 + hoop * (1.0 - a2 * a2 - u2 * u2))
    return k00, k01, k02, k11, k12, k22


@njit
def nearest_surface_3d(r0, r1, r2, obstacles):
    """(gap, u0, u1, u2): :func:`clearance_3d` at r and the outward unit normal û of the
    nearest obstacle's surface there (∂gap/∂r; zero on a core)."""
    gap = math.inf
    u0 = u1 = u2 = 0.0
    for d in range(obstacles.shape[0]):
        e0, e1, e2, dist = _offset_3d(r0, r1, r2, obstacles, d)
        g = dist - obstacles[d, O_RADIUS]
        if g < gap:
            gap = g
            scale = 1.0 / dist if dist > 0.0 else 0.0
            u0 = e0 * scale
            u1 = e1 * scale
            u2 = e2 * scale
    return gap, u0, u1, u2


@njit
def clearance_3d(r0, r1, r2, obstacles):
    """Smallest signed gap (m; negative inside) from r to the spatial obstacles' surfaces."""
    gap = math.inf
    for d in range(obstacles.shape[0]):
        g = _offset_3d(r0, r1, r2, obstacles, d)[3] - obstacles[d, O_RADIUS]
        if g < gap:
            gap = g
    return gap


@njit
def smallest_clearance_3d(points, obstacles):
    """:func:`clearance_3d` of the closest of (N, ≥3) points (m)."""
    gap = math.inf
    for k in range(points.shape[0]):
        gap = min(gap, clearance_3d(points[k, 0], points[k, 1], points[k, 2], obstacles))
    return gap


@njit(inline="always")
def _chord_allowance_3d(points, tangents, r) -> float:
    """ℓ·(|Δθ|/4 + CHORD_SLACK) of the chord from sample r to r + 1 (m): ℓ its length, Δθ
    the angle between the backbone's tangents there."""
    e0 = points[r + 1, 0] - points[r, 0]
    e1 = points[r + 1, 1] - points[r, 1]
    e2 = points[r + 1, 2] - points[r, 2]
    a0, a1, a2 = tangents[r, 0], tangents[r, 1], tangents[r, 2]
    b0, b1, b2 = tangents[r + 1, 0], tangents[r + 1, 1], tangents[r + 1, 2]
    turn = math.atan2(math.sqrt((a1 * b2 - a2 * b1) ** 2 + (a2 * b0 - a0 * b2) ** 2
                                + (a0 * b1 - a1 * b0) ** 2), a0 * b0 + a1 * b1 + a2 * b2)
    return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) * (0.25 * turn + CHORD_SLACK)


@njit
def chord_allowance_3d(points, tangents) -> float:
    """:func:`chord_allowance` of a spatial backbone: samples ``points`` (N, ≥3; m) and unit
    tangents ``tangents`` (N, 3; the d3 directors), Δθ the angle between two samples'
    tangents (the turn of the circular arc through them, of any plane)."""
    allowance = 0.0
    for r in range(points.shape[0] - 1):
        allowance = max(allowance, _chord_allowance_3d(points, tangents, r))
    return allowance


@njit(inline="always")
def _segment_depth_3d(a0, a1, a2, b0, b1, b2, obstacles, d):
    """Deepest penetration of the straight segment a → b into spatial obstacle ``d`` (m).
    The offset from the obstacle's core (:func:`_offset_3d`) is affine along the segment,
    o + t·Pe (P the projection off a cylinder's axis, the identity about a sphere's centre),
    so its smallest length is at t = −o·Pe / |Pe|², clamped to [0, 1]."""
    o0, o1, o2, _ = _offset_3d(a0, a1, a2, obstacles, d)
    e0 = b0 - a0
    e1 = b1 - a1
    e2 = b2 - a2
    along = e0 * obstacles[d, O_AXIS] + e1 * obstacles[d, O_AXIS + 1] + e2 * obstacles[d, O_AXIS + 2]
    e0 -= along * obstacles[d, O_AXIS]
    e1 -= along * obstacles[d, O_AXIS + 1]
    e2 -= along * obstacles[d, O_AXIS + 2]
    length2 = e0 * e0 + e1 * e1 + e2 * e2
    t = 0.0
    if length2 > 0.0:
        t = min(1.0, max(0.0, -(o0 * e0 + o1 * e1 + o2 * e2) / length2))
    o0 += t * e0
    o1 += t * e1
    o2 += t * e2
    return obstacles[d, O_RADIUS] - math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)


@njit
def chords_clear_3d(points, tangents, obstacles) -> bool:
    """:func:`chords_clear` against spatial obstacles: True when every straight chord
    between consecutive samples ``points`` (N, ≥3; m) stays out of every obstacle of
    ``obstacles`` (n, 8) by more than the backbone can depart from it there,
    ℓ·(|Δθ|/4 + CHORD_SLACK) (:func:`chord_allowance_3d`, ``tangents`` (N, 3) the unit d3
    directors). Then no point of the backbone touches an obstacle."""
    for r in range(points.shape[0] - 1):
        allowance = _chord_allowance_3d(points, tangents, r)
        for d in range(obstacles.shape[0]):
            if _segment_depth_3d(points[r, 0], points[r, 1], points[r, 2], points[r + 1, 0],
                                 points[r + 1, 1], points[r + 1, 2], obstacles, d) >= -allowance:
                return False
    return True


@njit
def tunnels_3d(prev, new, obstacles, slack):
    """:func:`tunnels` against spatial obstacles: True when a sample, moved along the
    straight segment between its positions in ``prev`` and ``new`` (N, ≥3; m), goes deeper
    into an obstacle (:func:`_segment_depth_3d`) than the deeper of its two ends by more
    than ``slack`` (m)."""
    for k in range(prev.shape[0]):
        for d in range(obstacles.shape[0]):
            radius = obstacles[d, O_RADIUS]
            end = max(radius - _offset_3d(prev[k, 0], prev[k, 1], prev[k, 2], obstacles, d)[3],
                      radius - _offset_3d(new[k, 0], new[k, 1], new[k, 2], obstacles, d)[3])
            if _segment_depth_3d(prev[k, 0], prev[k, 1], prev[k, 2], new[k, 0], new[k, 1],
                                 new[k, 2], obstacles, d) > max(end, 0.0) + slack:
                return True
    return False


@njit
def free_step_gap(start, end, tangents, obstacles):
    """How a contact-free step from the backbone samples ``start`` to ``end`` (N, ≥3; m;
    the same arc lengths) stands to the spatial ``obstacles`` (n, 8): (gap, clear).

    ``gap``: the smallest clearance (m) of either state's samples, −inf where a sample moving
    straight between them passes through an obstacle (:func:`tunnels_3d`, no slack).
    ``clear``: the step touches nothing — ``end`` clears every obstacle chord by chord
    (:func:`chords_clear_3d`, ``tangents`` (N, 3) its unit d3 directors) and no sample came
    within that state's chord allowance of one on the way (the contact-free path between
    accepted states is not straight; a step that leaves the obstacles' reach and comes back
    is not caught, and a warm step seldom does). One test for the stepper's kernel and the
    general path, so that they stay bit for bit."""
    # A move that passes through an obstacle (no slack) also comes within the allowance of
    # it: the no-slack test runs only where the one with the allowance has found a sample.
    near = tunnels_3d(start, end, obstacles, -chord_allowance_3d(end, tangents))
    if near and tunnels_3d(start, end, obstacles, 0.0):
        return -math.inf, False
    gap = min(smallest_clearance_3d(start, obstacles), smallest_clearance_3d(end, obstacles))
    return gap, not near and chords_clear_3d(end, tangents, obstacles)


# ----------------------------------------------------------------------------- friction


@njit(inline="always")
def return_mapping(dd, cap, k):
    """Coulomb's law on a tangential penalty spring of stiffness ``k`` (N/m², per length),
    by the exact return mapping (docs/design.md §9.1): the sample has slid ``dd`` (m,
    signed) along the surface from its anchor, and the cone admits ``cap`` = μ × the
    normal force over k (m). Stick while |dd| ≤ cap: the spring's −k·dd; else slip on the
    cone, −k·cap·sign(dd), the anchor dragged to the cone's edge.

    Returns:
        (f_t, slip, σ): the tangential force per length (N/m, along the direction in which
        ``dd`` is measured), the slip past the cone's edge (m, ≥ 0; the energy it
        dissipates is |f_t|·slip per length) and σ, 0 where it sticks, else sign(dd).
    """
    if abs(dd) <= cap:
        return -k * dd, 0.0, 0.0
    sg = 1.0 if dd > 0.0 else -1.0
    return -k * sg * cap, abs(dd) - cap, sg


@njit
def friction_impulse(x, y, discs, mu, fs, row, node, weight, record, want_k):
    """Coulomb friction at the planar contact sample (row, node) at (x, y): the impulse on the
    arm (N) it carries for its share ``weight`` (m) of the reference length, summed over the
    discs with μ > 0, by the return mapping of docs/design.md §9.

    Per disc: the sample's tangential displacement from its anchor is
    d = t·(r − c − a) (t the surface's tangent at r, a the anchor ``fs[row, node, disc,
    FS_A:]``, relative to the centre c); the tangential spring −k·d (k the disc's penalty)
    holds it while |d| ≤ μ·pen (stick) and the cone's −μ·k·pen·sign(d) where it would exceed
    it (slip): force per length along t. A sample without an anchor (NaN: it was not near
    the disc at the last accepted state) carries none.

    Args:
        x, y: the sample (m). discs: (k, 4). mu: (k,) Coulomb coefficients.
        fs: the friction samples (``FS_*``; rows, nodes, k, N_FS). row, node: the sample.
        weight: its share of the reference length (m).
        record: write the return-mapped anchor, the impulse, the position and the slip
            into ``fs[row, node]`` (``FS_NEW`` … ``FS_SLIP``).
        want_k: also return the impulse's derivative with respect to (x, y).

    Returns:
        (F_x, F_y, ∂F_x/∂x, ∂F_x/∂y, ∂F_y/∂x, ∂F_y/∂y) (N, N/m; zeros unless ``want_k``).
    """
    fx = 0.0
    fy = 0.0
    k00 = 0.0
    k01 = 0.0
    k10 = 0.0
    k11 = 0.0
    for d in range(discs.shape[0]):
        if not mu[d] > 0.0:
            continue
        ex = x - discs[d, CX]
        ey = y - discs[d, CY]
        rho = math.sqrt(ex * ex + ey * ey)
        if not rho > 0.0:
            continue
        ux = ex / rho
        uy = ey / rho
        tx = -uy
        ty = ux
        radius = discs[d, RADIUS]
        k = discs[d, STIFFNESS]
        pen = radius - rho
        cap = mu[d] * pen if pen > 0.0 else 0.0
        ax = fs[row, node, d, FS_A]
        ay = fs[row, node, d, FS_A + 1]
        fresh = math.isnan(ax)
        dd = 0.0 if fresh else tx * (ex - ax) + ty * (ey - ay)
        ft, slip, sg = return_mapping(dd, cap, k)
        if sg == 0.0:  # stick: the tangential spring
            nx = radius * ux if fresh else ax
            ny = radius * uy if fresh else ay
            # ∂(f t)/∂r = −k·g·t tᵀ − (f/ρ)·u tᵀ, g = 1 − u·(r − c − a)/ρ (t turns with r)
            a = 0.0 if fresh else -k * (1.0 - (ux * (ex - ax) + uy * (ey - ay)) / rho)
            a_t = 1.0
        else:  # slip: on the cone, the anchor dragged along
            nx = radius * ux - sg * cap * tx
            ny = radius * uy - sg * cap * ty
            # ∂(f t)/∂r = σ·μ·k·t uᵀ − (f/ρ)·u tᵀ (pen = R − ρ moves the cone)
            a = sg * mu[d] * k if pen > 0.0 else 0.0
            a_t = 0.0
        gx = weight * ft * tx
        gy = weight * ft * ty
        fx += gx
        fy += gy
        if want_k:
            b = -ft / rho
            # a·t (t or u)ᵀ + b·u tᵀ: the first factor's row vector is t in stick, u in slip.
            vx = a_t * tx + (1.0 - a_t) * ux
            vy = a_t * ty + (1.0 - a_t) * uy
            k00 += weight * (a * tx * vx + b * ux * tx)
            k01 += weight * (a * tx * vy + b * ux * ty)
            k10 += weight * (a * ty * vx + b * uy * tx)
            k11 += weight * (a * ty * vy + b * uy * ty)
        if record:
            record_planar_sample(fs[row, node, d], nx, ny, gx, gy, x, y, slip)
    return fx, fy, k00, k01, k10, k11


@njit(inline="always")
def record_planar_sample(out, a0, a1, fx, fy, x, y, slip):
    """Write a planar friction sample's state at a recording pass into ``out`` (N_FS,): its
    return-mapped anchor (a0, a1), impulse (fx, fy) (N), position (x, y) (m) and slip (m);
    the third entries 0."""
    out[FS_NEW] = a0
    out[FS_NEW + 1] = a1
    out[FS_NEW + 2] = 0.0
    out[FS_F] = fx
    out[FS_F + 1] = fy
    out[FS_F + 2] = 0.0
    out[FS_R] = x
    out[FS_R + 1] = y
    out[FS_R + 2] = 0.0
    out[FS_SLIP] = slip


@njit
def friction_impulse_3d(r0, r1, r2, obstacles, mu, fs, row, node, weight, record, stiff):
    """:func:`friction_impulse` against spatial obstacles (n, 8): the tangential
    displacement is the vector d = P·(r − p − a), P the projection on the surface's tangent
    plane at r (normal to e, the offset from the obstacle's core, :func:`_offset_3d`) and a
    the anchor relative to the obstacle's point p; stick while |d| ≤ μ·pen, else the cone's
    force −μ·k·pen·d/|d|. Returns the impulse (F_x, F_y, F_z) on the arm (N).

    ``stiff``: (3, 3) or (0, 3): if not empty, the impulse's derivative ∂F/∂r (N/m) is added
    into it — the consistent tangent of the return mapping (anchors fixed), as
    :func:`friction_impulse`'s in the plane. With Q = ∂e/∂r = I − a_c a_cᵀ (a_c the
    cylinder's axis; zero for a sphere), u = e/ρ and v = r − p − a:
    ∂d/∂r = P − (u·v/ρ)·P Q − u (dᵀQ)/ρ (the tangent plane turns with r); stick:
    −k·w·∂d/∂r (w the sample's length share); slip: −k·w·[d̂ ∂(μ pen)/∂r + (μ pen/|d|)
    (I − d̂ d̂ᵀ) ∂d/∂r], ∂pen/∂r = −uᵀ. A sample without an anchor carries no force and no
    stiffness."""
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for d in range(obstacles.shape[0]):
        if not mu[d] > 0.0:
            continue
        e0, e1, e2, rho = _offset_3d(r0, r1, r2, obstacles, d)
        if not rho > 0.0:
            continue
        u0 = e0 / rho
        u1 = e1 / rho
        u2 = e2 / rho
        radius = obstacles[d, O_RADIUS]
        k = obstacles[d, O_STIFFNESS]
        pen = radius - rho
        cap = mu[d] * pen if pen > 0.0 else 0.0
        a0 = fs[row, node, d, FS_A]
        fresh = math.isnan(a0)
        w0 = 0.0
        w1 = 0.0
        w2 = 0.0
        along = 0.0
        if not fresh:
            w0 = r0 - obstacles[d, O_P] - a0
            w1 = r1 - obstacles[d, O_P + 1] - fs[row, node, d, FS_A + 1]
            w2 = r2 - obstacles[d, O_P + 2] - fs[row, node, d, FS_A + 2]
            along = w0 * u0 + w1 * u1 + w2 * u2
            w0 -= along * u0
            w1 -= along * u1
            w2 -= along * u2
        size = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        if stiff.shape[0] and not fresh and (size <= cap or cap > 0.0):
            _friction_stiffness_3d(stiff, (u0, u1, u2), (w0, w1, w2), along, rho, size, cap,
                                   mu[d], weight * k, obstacles, d)
        # The core point nearest r, from which the surface point R·u lies.
        c0 = r0 - e0 - obstacles[d, O_P]
        c1 = r1 - e1 - obstacles[d, O_P + 1]
        c2 = r2 - e2 - obstacles[d, O_P + 2]
        if size <= cap:  # stick
            scale = 1.0
            slip = 0.0
            if fresh:
                n0 = c0 + radius * u0
                n1 = c1 + radius * u1
                n2 = c2 + radius * u2
            else:
                n0 = a0
                n1 = fs[row, node, d, FS_A + 1]
                n2 = fs[row, node, d, FS_A + 2]
        else:  # slip
            scale = cap / size
            slip = size - cap
            n0 = c0 + radius * u0 - scale * w0
            n1 = c1 + radius * u1 - scale * w1
            n2 = c2 + radius * u2 - scale * w2
        g0 = -weight * k * scale * w0
        g1 = -weight * k * scale * w1
        g2 = -weight * k * scale * w2
        fx += g0
        fy += g1
        fz += g2
        if record:
            out = fs[row, node, d]
            out[FS_NEW] = n0
            out[FS_NEW + 1] = n1
            out[FS_NEW + 2] = n2
            out[FS_F] = g0
            out[FS_F + 1] = g1
            out[FS_F + 2] = g2
            out[FS_R] = r0
            out[FS_R + 1] = r1
            out[FS_R + 2] = r2
            out[FS_SLIP] = slip
    return fx, fy, fz


@njit(inline="always")
def _friction_stiffness_3d(stiff, u, w, along, rho, size, cap, mu, wk, obstacles, d):
    """Add ∂F/∂r of one obstacle's friction impulse into ``stiff`` (3, 3)
    (:func:`friction_impulse_3d`): ``u`` the unit offset, ``w`` the tangential displacement
    d, ``along`` u·(r − p − a), ``rho`` |e|, ``size`` |d|, ``cap`` μ·pen, ``wk`` the share
    times the stiffness (N/m²·m)."""
    a = (obstacles[d, O_AXIS], obstacles[d, O_AXIS + 1], obstacles[d, O_AXIS + 2])
    w_axis = w[0] * a[0] + w[1] * a[1] + w[2] * a[2]
    slip = size > cap
    dd = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            eye = 1.0 if i == j else 0.0
            # P = I − u uᵀ; P Q = I − u uᵀ − a aᵀ (u ⟂ a); dᵀQ = dᵀ − (d·a) aᵀ.
            dd[i, j] = (eye - u[i] * u[j] - along / rho * (eye - u[i] * u[j] - a[i] * a[j])
                        - u[i] * (w[j] - w_axis * a[j]) / rho)
    if not slip:
        for i in range(3):
            for j in range(3):
                stiff[i, j] -= wk * dd[i, j]
        return
    ratio = cap / size
    for j in range(3):
        hat_dd = (w[0] * dd[0, j] + w[1] * dd[1, j] + w[2] * dd[2, j]) / size  # d̂ᵀ ∂d/∂r
        for i in range(3):
            hat = w[i] / size
            stiff[i, j] -= wk * (-hat * mu * u[j] + ratio * (dd[i, j] - hat * hat_dd))


@njit
def friction_untouched(fs, row):
    """Mark the samples of the step at ``row`` as not evaluated by a recording pass (the
    step was not refined: no obstacle within its reach): no anchor to carry, no impulse."""
    for node in range(fs.shape[1]):
        for d in range(fs.shape[2]):
            out = fs[row, node, d]
            for c in range(3):
                out[FS_NEW + c] = math.nan
                out[FS_F + c] = 0.0
                out[FS_R + c] = math.nan
            out[FS_SLIP] = 0.0


@njit
def accept_friction(fs):
    """A state is accepted on the quasi-static path: every sample's anchor becomes the
    return-mapped one its recording pass wrote (NaN where it was not evaluated), and the
    energy its slip dissipated, |F|·slip (J), is added to its work."""
    for row in range(fs.shape[0]):
        for node in range(fs.shape[1]):
            for d in range(fs.shape[2]):
                s = fs[row, node, d]
                for c in range(3):
                    s[FS_A + c] = s[FS_NEW + c]
                if s[FS_SLIP] > 0.0:
                    s[FS_WORK] += math.sqrt(s[FS_F] ** 2 + s[FS_F + 1] ** 2 + s[FS_F + 2] ** 2) \
                        * s[FS_SLIP]


# Points per interval between samples at which the deepest point of the backbone in an
# obstacle is first looked for (then polished by Newton), see peak_depth.
PEAK_SAMPLES = 8


@njit(inline="always")
def hermite_point(positions, slopes, k, ds, t, axis):
    """Coordinate ``axis`` of the cubic Hermite curve between samples k and k + 1 (positions
    (N, D), slopes r' (N, D) per unit arc, ``ds`` apart) at t ∈ [0, 1], and its first and
    second derivatives in t: (x, x', x'')."""
    t2 = t * t
    t3 = t2 * t
    a = positions[k, axis]
    ta = ds * slopes[k, axis]
    b = positions[k + 1, axis]
    tb = ds * slopes[k + 1, axis]
    return ((2.0 * t3 - 3.0 * t2 + 1.0) * a + (t3 - 2.0 * t2 + t) * ta + (3.0 * t2 - 2.0 * t3) * b
            + (t3 - t2) * tb,
            (6.0 * t2 - 6.0 * t) * a + (3.0 * t2 - 4.0 * t + 1.0) * ta + (6.0 * t - 6.0 * t2) * b
            + (3.0 * t2 - 2.0 * t) * tb,
            (12.0 * t - 6.0) * a + (6.0 * t - 4.0) * ta + (6.0 - 12.0 * t) * b + (6.0 * t - 2.0) * tb)


@njit
def hull_circle(positions, slopes, k, ds):
    """A ball (centre (3,) and radius, m) holding the cubic Hermite curve between samples k
    and k + 1 (positions (N, D), D = 2 or 3): the one about its Bézier control points' mean
    through the farthest of them (the curve lies in their convex hull)."""
    dim = positions.shape[1]
    ctrl = np.zeros((4, 3))
    for axis in range(dim):
        ctrl[0, axis] = positions[k, axis]
        ctrl[1, axis] = positions[k, axis] + ds * slopes[k, axis] / 3.0
        ctrl[2, axis] = positions[k + 1, axis] - ds * slopes[k + 1, axis] / 3.0
        ctrl[3, axis] = positions[k + 1, axis]
    centre = np.zeros(3)
    for c in range(4):
        for axis in range(3):
            centre[axis] += 0.25 * ctrl[c, axis]
    radius = 0.0
    for c in range(4):
        radius = max(radius, math.sqrt((ctrl[c, 0] - centre[0]) ** 2 + (ctrl[c, 1] - centre[1]) ** 2
                                       + (ctrl[c, 2] - centre[2]) ** 2))
    return centre, radius


@njit
def _depth_at(positions, slopes, k, ds, t, obstacles, d):
    """(depth R − |e|, ½ d|e|²/dt, ½ d²|e|²/dt²) at t of the Hermite curve between samples k
    and k + 1 against spatial obstacle ``d`` (e the offset from its core, :func:`_offset_3d`;
    planar samples lie in z = 0)."""
    dim = positions.shape[1]
    r = np.zeros(3)
    dr = np.zeros(3)
    ddr = np.zeros(3)
    for axis in range(dim):
        r[axis], dr[axis], ddr[axis] = hermite_point(positions, slopes, k, ds, t, axis)
    e0, e1, e2, dist = _offset_3d(r[0], r[1], r[2], obstacles, d)
    a0 = obstacles[d, O_AXIS]
    a1 = obstacles[d, O_AXIS + 1]
    a2 = obstacles[d, O_AXIS + 2]
    along = dr[0] * a0 + dr[1] * a1 + dr[2] * a2
    v0 = dr[0] - along * a0
    v1 = dr[1] - along * a1
    v2 = dr[2] - along * a2
    along = ddr[0] * a0 + ddr[1] * a1 + ddr[2] * a2
    w0 = ddr[0] - along * a0
    w1 = ddr[1] - along * a1
    w2 = ddr[2] - along * a2
    return (obstacles[d, O_RADIUS] - dist, e0 * v0 + e1 * v1 + e2 * v2,
            v0 * v0 + v1 * v1 + v2 * v2 + e0 * w0 + e1 * w1 + e2 * w2)


@njit
def peak_depth(positions, slopes, s, obstacles):
    """The deepest penetration (m, ≥ 0) of a backbone into spatial ``obstacles`` (n, 8)
    anywhere along it, not only at its samples.

    Between consecutive samples (positions (N, 2|3) — planar ones in z = 0 —, slopes r'
    (N, 2|3) per unit arc, arc lengths ``s`` (N,); samples repeated at a junction are
    skipped) the backbone is the cubic Hermite curve through their positions with their
    slopes: fourth-order accurate, within a micrometre of the RK4 solution on the solver's
    grids. Against each obstacle whose surface the curve's control-point ball reaches, the
    deepest of PEAK_SAMPLES + 1 points of the curve is polished by Newton on the
    parameter (on |e|², e the offset from the obstacle's core)."""
    deepest = 0.0
    for k in range(s.shape[0] - 1):
        ds = s[k + 1] - s[k]
        if not ds > 0.0:
            continue
        centre, radius = hull_circle(positions, slopes, k, ds)
        for d in range(obstacles.shape[0]):
            if _offset_3d(centre[0], centre[1], centre[2], obstacles, d)[3] - radius \
                    >= obstacles[d, O_RADIUS]:
                continue
            best = -math.inf
            t = 0.0
            for q in range(PEAK_SAMPLES + 1):
                depth = _depth_at(positions, slopes, k, ds, q / PEAK_SAMPLES, obstacles, d)[0]
                if depth > best:
                    best = depth
                    t = q / PEAK_SAMPLES
            for _ in range(30):
                depth, slope, curve = _depth_at(positions, slopes, k, ds, t, obstacles, d)
                best = max(best, depth)
                if not curve > 0.0:
                    break
                step = slope / curve
                t_new = min(1.0, max(0.0, t - step))
                if abs(t_new - t) < 1e-15:
                    break
                t = t_new
            best = max(best, _depth_at(positions, slopes, k, ds, t, obstacles, d)[0])
            deepest = max(deepest, best)
    return deepest
