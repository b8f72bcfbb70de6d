"""Self-contact of the planar backbone: parts of the arm farther apart along the arc than an
exclusion length press on each other by the discs' penalty law (docs/design.md §9).

Geometry from the shooting unknowns alone. Each segment's backbone is drawn as a cubic
Hermite curve through its end states (positions and slopes r' from the constitutive law),
sampled at its RK4 nodes: the next segment's start for all but the tip segment, whose end
comes from integrating it (without self-contact loads). The curve's error is Hermite's,
O((κℓ)⁴·ℓ) for a segment of length ℓ and curvature κ: below a micrometre on OctArm-sized
segments.

Law, node to curve. A node at arc length s with half-thickness h(s) meets another part
(farther than the exclusion length along the arc) when its distance d to that part's
nearest point p is below h(s) + h(p). Per unit length it is then pushed by
f = k·(h(s) + h(p) − d)·(r − p)/d — the law of :func:`solver.kernels.obstacles.contact_force`
with the partner's surface in place of a disc's, set in smoothly over the first ONSET of
depth. The pieces' chords find the contacts (a run of consecutive chords within reach is
one contact, so a node near a vertex is not pushed twice); p is then the nearest point of
the Hermite curve itself, whose normal turns smoothly as the node moves.

Action and reaction. The node's force f·w (w its share of the arc, the trapezoid weight of
the RK4 grid) acts on it as a point load, and its reaction −f·w on the partner, split
between the two nodes either side of p in proportion to where p lies between them (their
resultant acts on the line of f, within the chord's sagitta of p: the pair carries no net
force, and a net moment only of the sagitta's component across f). Every node plays both parts,
so each pair is counted from either side, and every node carries half the sum of its own
forces and the reactions it receives: for parts pressed side by side this is the disc law;
where the contact is one-sided (a part pressed against the arm's end) the pair still
balances exactly. The loads are point loads at RK4 nodes, applied as jumps in the internal
force between steps (as the endplates' weights are).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.layout import (
    B_AX,
    B_AY,
    B_BX,
    B_BY,
    B_R,
    B_TAX,
    B_TAY,
    B_TBX,
    B_TBY,
    B_TOUCH,
    B_X,
    B_Y,
    CA,
    CG,
    G_SECF,
    G_SEGS,
    G_SELF,
    G_START,
    G_STEPS,
    LEN,
    P_H,
    P_S,
    P_X,
    P_Y,
    REST_V3,
    SC_EXCLUSION,
    SC_HALF,
    SC_K,
    SEG_END,
    SEG_FIRST,
    SEG_SECTION,
    SEG_STEPS,
    SELF_FX,
    SELF_FY,
    SELF_K00,
    SELF_K01,
    SELF_K11,
    SELF_PEN,
    SELF_QX,
    SELF_QY,
)
from solver.rod import planar_strains

# Depth (m) over which the law sets in smoothly: f = k·δ²/2ε below ε, then k·(δ − ε/2). Nodes
# are an RK4 step apart, and where a contact patch spans one or two of them, a node entering
# it with a kink in its force made Newton stall (as at the grasp's base clamp).
ONSET = 5e-4


@njit
def self_contact_on(grid) -> bool:
    """Whether the layout tuple ``grid`` asks for self-contact."""
    return grid[G_SELF][SC_K] > 0.0


@njit
def clear_pieces(bounds):
    """Mark every piece as not built and not in contact."""
    for seg in range(bounds.shape[0]):
        bounds[seg, B_R] = -1.0
        bounds[seg, B_TOUCH] = 0.0


@njit
def build_piece(za, zb, seg, grid, rest, pts, bounds):
    """The piece of segment ``seg`` from its start state ``za`` and end state ``zb`` (6,)
    (x, y, θ, n_x, n_y, m): a cubic Hermite curve in the segment's arc length through their
    positions with their slopes r' (the constitutive law of the segment's section), sampled
    at its RK4 nodes into ``pts[seg]``, its bounding circle into ``bounds[seg]``.

    Half-thicknesses are the section's, except at a section junction, where the node takes
    the mean of both sections' (h varies linearly over the chords on either side, so the law
    has no jump where a node slides past the junction)."""
    segs = grid[G_SEGS]
    secf = grid[G_SECF]
    sp = grid[G_SELF]
    i = segs[seg, SEG_SECTION]
    n = segs[seg, SEG_STEPS]
    step = secf[LEN, i] / grid[G_STEPS][i]
    ell = n * step
    s0 = grid[G_START][i] + segs[seg, SEG_FIRST] * step
    c, sn, _, _, v1, v3 = planar_strains(za[2], za[3], za[4], secf[CA, i], secf[CG, i], rest[REST_V3, i])
    tax = ell * (v3 * c - v1 * sn)
    tay = ell * (v3 * sn + v1 * c)
    c, sn, _, _, v1, v3 = planar_strains(zb[2], zb[3], zb[4], secf[CA, i], secf[CG, i], rest[REST_V3, i])
    tbx = ell * (v3 * c - v1 * sn)
    tby = ell * (v3 * sn + v1 * c)
    half = sp[SC_HALF + i]
    h_start = 0.5 * (sp[SC_HALF + i - 1] + half) if segs[seg, SEG_FIRST] == 0 and i > 0 else half
    h_end = 0.5 * (half + sp[SC_HALF + i + 1]) \
        if segs[seg, SEG_END] == 1 and i < secf.shape[1] - 1 else half
    cx = 0.0
    cy = 0.0
    for j in range(n + 1):
        t = j / n
        t2 = t * t
        t3 = t2 * t
        h00 = 2.0 * t3 - 3.0 * t2 + 1.0
        h10 = t3 - 2.0 * t2 + t
        h01 = 3.0 * t2 - 2.0 * t3
        h11 = t3 - t2
        x = h00 * za[0] + h10 * tax + h01 * zb[0] + h11 * tbx
        y = h00 * za[1] + h10 * tay + h01 * zb[1] + h11 * tby
        pts[seg, j, P_X] = x
        pts[seg, j, P_Y] = y
        pts[seg, j, P_S] = s0 + j * step
        pts[seg, j, P_H] = h_start if j == 0 else (h_end if j == n else half)
        cx += x
        cy += y
    cx /= n + 1
    cy /= n + 1
    radius = 0.0
    for j in range(n + 1):
        radius = max(radius, math.hypot(pts[seg, j, P_X] - cx, pts[seg, j, P_Y] - cy))
    bounds[seg, B_X] = cx
    bounds[seg, B_Y] = cy
    bounds[seg, B_R] = radius
    bounds[seg, B_TOUCH] = 0.0
    bounds[seg, B_AX] = za[0]
    bounds[seg, B_AY] = za[1]
    bounds[seg, B_TAX] = tax
    bounds[seg, B_TAY] = tay
    bounds[seg, B_BX] = zb[0]
    bounds[seg, B_BY] = zb[1]
    bounds[seg, B_TBX] = tbx
    bounds[seg, B_TBY] = tby


@njit
def may_touch(Z, grid, rest) -> bool:
    """A cheap, conservative test on the shooting nodes ``Z`` alone: False when no two
    segments farther apart along the arc than the exclusion can come within reach of each
    other, so there is no self-contact to work out. A segment of arc length ℓ stretched at
    most v lies within v·ℓ/2 of its end nodes' midpoint (the tip segment: within v·ℓ of its
    start), v = 1.5 × the largest rest stretch."""
    segs = grid[G_SEGS]
    secf = grid[G_SECF]
    sp = grid[G_SELF]
    n_seg = segs.shape[0]
    stretch = 0.0
    for i in range(rest.shape[1]):
        stretch = max(stretch, rest[REST_V3, i])
    stretch *= 1.5
    reach = 2.0 * _largest_half(sp)
    cx = np.empty(n_seg)
    cy = np.empty(n_seg)
    radius = np.empty(n_seg)
    s0 = np.empty(n_seg)
    s1 = np.empty(n_seg)
    for seg in range(n_seg):
        i = segs[seg, SEG_SECTION]
        step = secf[LEN, i] / grid[G_STEPS][i]
        ell = segs[seg, SEG_STEPS] * step
        s0[seg] = grid[G_START][i] + segs[seg, SEG_FIRST] * step
        s1[seg] = s0[seg] + ell
        ax = 0.0 if seg == 0 else Z[3 + 6 * (seg - 1)]
        ay = 0.0 if seg == 0 else Z[4 + 6 * (seg - 1)]
        if seg < n_seg - 1:
            cx[seg] = 0.5 * (ax + Z[3 + 6 * seg])
            cy[seg] = 0.5 * (ay + Z[4 + 6 * seg])
            radius[seg] = 0.5 * stretch * ell
        else:
            cx[seg] = ax
            cy[seg] = ay
            radius[seg] = stretch * ell
    for a in range(n_seg):
        for b in range(a + 1, n_seg):
            if s1[b] - s0[a] <= sp[SC_EXCLUSION]:
                continue
            if math.hypot(cx[a] - cx[b], cy[a] - cy[b]) < radius[a] + radius[b] + reach:
                return True
    return False


# Samples per chunk of :func:`far_parts_clear`'s bounding circles.
CLEAR_CHUNK = 8


@njit
def far_parts_clear(positions, s, half, exclusion, margin) -> bool:
    """Whether every two backbone samples farther apart along the arc than ``exclusion`` (m)
    are farther apart in space than their half-thicknesses plus ``margin`` (m): the surface
    gap of every such pair exceeds ``margin``.

    Runs of :data:`CLEAR_CHUNK` samples are bounded by circles: a pair of runs whose circles
    lie apart by more than their largest half-thicknesses plus ``margin`` holds no closer pair,
    and is not looked into (an arm that is not curled onto itself costs a few dozen circle
    tests, not N² sample pairs).

    Args:
        positions: (N, 2) samples (m). s: (N,) their arc lengths (m). half: (N,) their
            half-thicknesses (m).
    """
    n = s.shape[0]
    m = (n + CLEAR_CHUNK - 1) // CLEAR_CHUNK
    circles = np.empty((m, 6))  # centre x, y, radius, largest half, first and last arc length
    for c in range(m):
        lo, hi = c * CLEAR_CHUNK, min(n, (c + 1) * CLEAR_CHUNK)
        x0 = x1 = positions[lo, 0]
        y0 = y1 = positions[lo, 1]
        biggest = half[lo]
        for r in range(lo + 1, hi):
            x0 = min(x0, positions[r, 0])
            x1 = max(x1, positions[r, 0])
            y0 = min(y0, positions[r, 1])
            y1 = max(y1, positions[r, 1])
            biggest = max(biggest, half[r])
        circles[c, 0] = 0.5 * (x0 + x1)
        circles[c, 1] = 0.5 * (y0 + y1)
        circles[c, 2] = 0.5 * math.hypot(x1 - x0, y1 - y0)
        circles[c, 3] = biggest
        circles[c, 4] = s[lo]
        circles[c, 5] = s[hi - 1]
    for a in range(m):
        for b in range(a, m):
            if abs(circles[b, 5] - circles[a, 4]) <= exclusion and \
                    abs(circles[a, 5] - circles[b, 4]) <= exclusion:
                continue  # no pair of these runs is far enough apart along the arc
            apart = math.hypot(circles[a, 0] - circles[b, 0], circles[a, 1] - circles[b, 1])
            if apart - circles[a, 2] - circles[b, 2] - circles[a, 3] - circles[b, 3] > margin:
                continue
            for i in range(a * CLEAR_CHUNK, min(n, (a + 1) * CLEAR_CHUNK)):
                first = i + 1 if a == b else b * CLEAR_CHUNK
                for j in range(first, min(n, (b + 1) * CLEAR_CHUNK)):
                    if abs(s[j] - s[i]) > exclusion:
                        d = math.hypot(positions[i, 0] - positions[j, 0],
                                       positions[i, 1] - positions[j, 1])
                        if not d - half[i] - half[j] > margin:
                            return False
    return True


@njit
def canonical_slot(segs, seg, j):
    """The canonical (segment, node) of node j of segment ``seg``: a segment's first node is
    the previous segment's last (except at the base)."""
    if j == 0 and seg > 0:
        return seg - 1, segs[seg - 1, SEG_STEPS]
    return seg, j


@njit
def _weight(segs, pts, seg, j):
    """The node's share of the arc (m): half the RK4 steps on either side of it."""
    n = segs[seg, SEG_STEPS]
    w = 0.0
    if j > 0:
        w += 0.5 * (pts[seg, j, P_S] - pts[seg, j - 1, P_S])
    elif seg > 0:
        m = segs[seg - 1, SEG_STEPS]
        w += 0.5 * (pts[seg - 1, m, P_S] - pts[seg - 1, m - 1, P_S])
    if j < n:
        w += 0.5 * (pts[seg, j + 1, P_S] - pts[seg, j, P_S])
    elif seg + 1 < segs.shape[0]:
        w += 0.5 * (pts[seg + 1, 1, P_S] - pts[seg + 1, 0, P_S])
    return w


@njit
def _largest_half(sp):
    largest = 0.0
    for k in range(SC_HALF, sp.shape[0]):
        largest = max(largest, sp[k])
    return largest


@njit
def _nearest_on_chord(x, y, h_own, pts, seg, j):
    """(pen, ux, uy, t) of the point (x, y) against chord j of piece ``seg``: penetration
    h_own + h(p) − |r − p| at the nearest point p = (1 − t)·a + t·b, and the unit vector
    from p to the point (zero where they coincide)."""
    ax = pts[seg, j, P_X]
    ay = pts[seg, j, P_Y]
    ex = pts[seg, j + 1, P_X] - ax
    ey = pts[seg, j + 1, P_Y] - ay
    length2 = ex * ex + ey * ey
    t = ((x - ax) * ex + (y - ay) * ey) / length2 if length2 > 0.0 else 0.0
    t = min(1.0, max(0.0, t))
    dx = x - (ax + t * ex)
    dy = y - (ay + t * ey)
    dist = math.sqrt(dx * dx + dy * dy)
    reach = h_own + pts[seg, j, P_H] + t * (pts[seg, j + 1, P_H] - pts[seg, j, P_H])
    if dist > 0.0:
        return reach - dist, dx / dist, dy / dist, t
    return reach, 0.0, 0.0, t


@njit
def _curve(bounds, seg, t):
    """Point, first and second derivative (in the parameter t ∈ [0, 1]) of piece ``seg``'s
    Hermite curve: (x, y, dx, dy, ddx, ddy)."""
    t2 = t * t
    t3 = t2 * t
    c = (2.0 * t3 - 3.0 * t2 + 1.0, t3 - 2.0 * t2 + t, 3.0 * t2 - 2.0 * t3, t3 - t2)
    d = (6.0 * t2 - 6.0 * t, 3.0 * t2 - 4.0 * t + 1.0, 6.0 * t - 6.0 * t2, 3.0 * t2 - 2.0 * t)
    dd = (12.0 * t - 6.0, 6.0 * t - 4.0, 6.0 - 12.0 * t, 6.0 * t - 2.0)
    out = np.empty(6)
    for axis in range(2):
        a = bounds[seg, B_AX + axis]
        ta = bounds[seg, B_TAX + axis]
        b = bounds[seg, B_BX + axis]
        tb = bounds[seg, B_TBX + axis]
        out[axis] = c[0] * a + c[1] * ta + c[2] * b + c[3] * tb
        out[2 + axis] = d[0] * a + d[1] * ta + d[2] * b + d[3] * tb
        out[4 + axis] = dd[0] * a + dd[1] * ta + dd[2] * b + dd[3] * tb
    return out


@njit
def _project(x, y, bounds, segs, seg, t):
    """The point of the backbone's Hermite curves nearest (x, y), by Newton on the parameter
    from piece ``seg`` at ``t`` (a chord's nearest point), moving on to the neighbouring
    piece where it leaves this one and stopping at the arm's ends: (seg, t). The nearest
    point of the smooth curve, unlike a polyline's, has a normal that turns smoothly as the
    point moves — a polyline's jumps where the nearest chord changes on a concave side."""
    n_seg = bounds.shape[0]
    for _ in range(12):
        p = _curve(bounds, seg, t)
        rx = p[0] - x
        ry = p[1] - y
        g = rx * p[2] + ry * p[3]
        dg = p[2] * p[2] + p[3] * p[3] + rx * p[4] + ry * p[5]
        if not dg > 0.0:
            break
        move = g / dg
        t -= move
        if t < 0.0:
            if seg == 0 or bounds[seg - 1, B_R] < 0.0:
                return seg, 0.0
            seg -= 1
            t = 1.0
            continue
        if t > 1.0:
            if seg == n_seg - 1 or bounds[seg + 1, B_R] < 0.0:
                return seg, 1.0
            seg += 1
            t = 0.0
            continue
        if abs(move) < 1e-12:
            break
    return seg, t


@njit
def _add(loads, segs, seg, j, fx, fy):
    a, b = canonical_slot(segs, seg, j)
    loads[a, b, SELF_FX] += fx
    loads[a, b, SELF_FY] += fy


@njit
def self_loads(grid, pts, bounds, loads):
    """The self-contact point loads of the pieces ``pts`` (see the module docstring) into
    ``loads`` (M, segment steps + 1, N_SELF), at each node's canonical slot: SELF_FX, SELF_FY
    the point load (N), SELF_QX, SELF_QY that load per length of the node's share of the arc
    (N/m), SELF_PEN its own deepest penetration (m), SELF_K00…SELF_K11 its own law's
    stiffness across the normal with the other part fixed (N/m). Pieces in contact are marked in
    ``bounds``. Returns the deepest penetration."""
    segs = grid[G_SEGS]
    sp = grid[G_SELF]
    k = sp[SC_K]
    exclusion = sp[SC_EXCLUSION]
    largest = _largest_half(sp)
    loads[:, :, :] = 0.0
    deepest = 0.0
    n_seg = segs.shape[0]
    for seg in range(n_seg):
        for j in range(0 if seg == 0 else 1, segs[seg, SEG_STEPS] + 1):
            x = pts[seg, j, P_X]
            y = pts[seg, j, P_Y]
            s = pts[seg, j, P_S]
            h_own = pts[seg, j, P_H]
            w = _weight(segs, pts, seg, j)
            reach = h_own + largest
            in_run = False
            best_pen = 0.0
            best_t = 0.0
            best_seg = 0
            best_j = 0
            for other in range(n_seg + 1):
                near = other < n_seg and bounds[other, B_R] >= 0.0 and math.hypot(
                    x - bounds[other, B_X], y - bounds[other, B_Y]) - bounds[other, B_R] < reach
                chords = segs[other, SEG_STEPS] if near else 1
                for c in range(chords):
                    pen = -1.0
                    ux = uy = t = 0.0
                    if near and abs(s - pts[other, c, P_S]) > exclusion \
                            and abs(s - pts[other, c + 1, P_S]) > exclusion:
                        pen, ux, uy, t = _nearest_on_chord(x, y, h_own, pts, other, c)
                    if pen > 0.0 and (ux != 0.0 or uy != 0.0):
                        if not in_run or pen > best_pen:
                            best_pen, best_t = pen, t
                            best_seg, best_j = other, c
                        in_run = True
                        continue
                    if in_run:  # a run of chords within reach ends: one contact, the
                        # nearest point of the curve, from the run's nearest chord's
                        in_run = False
                        n_b = segs[best_seg, SEG_STEPS]
                        piece, tau = _project(x, y, bounds, segs, best_seg, (best_j + best_t) / n_b)
                        p = _curve(bounds, piece, tau)
                        dx = x - p[0]
                        dy = y - p[1]
                        dist = math.sqrt(dx * dx + dy * dy)
                        n_p = segs[piece, SEG_STEPS]
                        node = min(int(tau * n_p), n_p - 1)
                        t = tau * n_p - node
                        h_p = pts[piece, node, P_H] + t * (pts[piece, node + 1, P_H] - pts[piece, node, P_H])
                        pen = h_own + h_p - dist
                        if not (pen > 0.0 and dist > 0.0):
                            continue
                        ux = dx / dist
                        uy = dy / dist
                        f = w * (0.5 * k * pen * pen / ONSET if pen < ONSET
                                 else k * (pen - 0.5 * ONSET))
                        stiff = w * (k * pen / ONSET if pen < ONSET else k)
                        _add(loads, segs, seg, j, 0.5 * f * ux, 0.5 * f * uy)
                        _add(loads, segs, piece, node, -0.5 * f * (1.0 - t) * ux,
                             -0.5 * f * (1.0 - t) * uy)
                        _add(loads, segs, piece, node + 1, -0.5 * f * t * ux, -0.5 * f * t * uy)
                        a, b = canonical_slot(segs, seg, j)
                        loads[a, b, SELF_PEN] = max(loads[a, b, SELF_PEN], pen)
                        # The node's own law across the normal (∂pen/∂r = −ûᵀ), the other
                        # part held fixed: for the stability test (docs/design.md §9).
                        loads[a, b, SELF_K00] -= stiff * ux * ux
                        loads[a, b, SELF_K01] -= stiff * ux * uy
                        loads[a, b, SELF_K11] -= stiff * uy * uy
                        deepest = max(deepest, pen)
                        bounds[seg, B_TOUCH] = 1.0
                        bounds[best_seg, B_TOUCH] = 1.0
                        bounds[piece, B_TOUCH] = 1.0
    for seg in range(n_seg):
        for j in range(0 if seg == 0 else 1, segs[seg, SEG_STEPS] + 1):
            w = _weight(segs, pts, seg, j)
            loads[seg, j, SELF_QX] = loads[seg, j, SELF_FX] / w
            loads[seg, j, SELF_QY] = loads[seg, j, SELF_FY] / w
    return deepest
