"""Self-contact of the planar backbone: parts of the arm farther apart along the arc than an
exclusion length press on each other by the discs' penalty law (docs/design.md §9).

Geometry from the shooting unknowns alone, in two passes (see
:func:`solver.kernels.contact._prepare_partners`). First each segment's backbone is drawn
as a quintic Hermite piece through its end states — positions, slopes r' from the
constitutive law and their derivatives r'' from the state's rate (:func:`build_piece`) —
the next segment's start for all but the tip segment, whose end comes from integrating it
without self-contact loads, and the loads are worked out on these pieces. Then every
segment is integrated with those loads and its piece redrawn through the integrated RK4
nodes (:func:`trace_piece`): on each RK4 step the quintic Hermite curve through the step's
end nodes, with the slopes and their derivatives on each side of a loaded node (a point
load's shear and stretch kink the backbone there), plus the quintic correction that takes
the integrated end to the next shooting node; and the loads are worked out again on the
traced pieces. At a solution the traced piece is the integrated backbone itself.

Law, point to curve. The law is sampled at SUBPOINTS points per RK4 step along the pieces
(the nodes among them), each with its share of the arc (:func:`self_loads`). A point at arc
length s with half-thickness h(s) meets another part (farther than the exclusion length
along the arc) when its distance d to that part's nearest point p is below h(s) + h(p). Per
unit length it is then pushed by f = k·(h(s) + h(p) − d)·(r − p)/d — the law of
:func:`solver.kernels.obstacles.contact_force` with the partner's surface in place of a
disc's, set in smoothly over the first ONSET of depth. The pieces' chords, widened by how
far the curves stand off them (:func:`_bulge`), find the contacts (a run of consecutive
chords within reach is one contact, so a point near a vertex is not pushed twice); p is then
the nearest point of the curve itself (:func:`_project`), whose normal turns smoothly as the
point moves. Points far from every other part are skipped by clearance bounds worked out at
the nodes.

Action and reaction. A point's force f·w (w its share of the arc) is lumped onto the two
nodes of its step in proportion to where it lies between them, and its reaction −f·w onto
the partner's two nodes either side of p in proportion to where p lies between them (their
resultant acts on the line of f, within the chord's sagitta of p: the pair carries no net
force, and a net moment only of the sagitta's component across f). Every point plays both
parts, so each pair is counted from either side, and every node carries half the sum of
the forces lumped onto it and the reactions it receives: for parts pressed side by side
this is the disc law; where the contact is one-sided (a part pressed against the arm's end)
the pair still balances exactly. The loads are point loads at RK4 nodes, applied as jumps in
the internal force between steps (as the endplates' weights are).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.obstacles import (
    friction_untouched,
    hermite_point,
    hull_circle,
    record_planar_sample,
    return_mapping,
)
from solver.layout import (
    B_R,
    B_TOUCH,
    B_X,
    B_Y,
    CA,
    CG,
    CI,
    FS_A,
    G_SECF,
    G_SEGS,
    G_SELF,
    G_START,
    G_STEPS,
    L_DISCS,
    L_PLATE,
    L_Q,
    LEN,
    P_CLEAR,
    P_DXA,
    P_DXB,
    P_EXA,
    P_EXB,
    P_H,
    P_S,
    P_X,
    P_X0,
    P_Y,
    P_Y0,
    REST_U2,
    REST_V3,
    SC_EXCLUSION,
    SC_HALF,
    SC_K,
    SC_MU,
    SEG_END,
    SEG_FIRST,
    SEG_SECTION,
    SEG_STEPS,
    SELF_FX,
    SELF_FY,
    SELF_K00,
    SELF_K01,
    SELF_K11,
    SELF_M,
    SELF_PEN,
    SELF_QX,
    SELF_QY,
)
from solver.rod import planar_state_jacobian, planar_state_rhs

# Depth (m) over which the law sets in smoothly: f = k·δ²/2ε below ε, then k·(δ − ε/2). Nodes
# are an RK4 step apart, and where a contact patch spans one or two of them, a node entering
# it with a kink in its force made Newton stall (as at the grasp's base clamp).
ONSET = 5e-4
# Points per RK4 step at which the law is sampled (docs/design.md §9, "Resolution").
SUBPOINTS = 8


END_TAU = 1e-9
"""A self-contact friction anchor this close (a fraction of its piece) to the arm's base or
tip lies at that end (:func:`_rub`): its slip is measured along the contact tangent."""


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
def moved_since(pts, segs):
    """How far (m) the farthest node of the pieces ``pts`` is from where it was when the
    nodes' clearances were last worked out (:func:`self_loads`); NaN if they never were."""
    moved = 0.0
    for seg in range(segs.shape[0]):
        for j in range(segs[seg, SEG_STEPS] + 1):
            move = math.hypot(pts[seg, j, P_X] - pts[seg, j, P_X0], pts[seg, j, P_Y] - pts[seg, j, P_Y0])
            if not move < math.inf:
                return math.nan
            moved = max(moved, move)
    return moved


@njit
def _derivatives(z, i, grid, rest, level, rate):
    """(r'_x, r'_y, r''_x, r''_y) of the backbone at the state ``z`` (6,) in section ``i``
    (per unit arc length): the slope from the constitutive law, its derivative along the arc
    from the state's rate (:func:`solver.rod.planar_state_rhs`, with the section's
    distributed load and any disc's force); ``rate`` (6,) scratch."""
    secf = grid[G_SECF]
    ca = secf[CA, i]
    cg = secf[CG, i]
    vr = rest[REST_V3, i]
    planar_state_rhs(z, rate, ca, cg, secf[CI, i], rest[REST_U2, i], vr, level[L_Q][i, 0],
                     level[L_Q][i, 1], level[L_DISCS])
    a02, a03, a04, a12, a14, _, _, _ = planar_state_jacobian(math.cos(z[2]), math.sin(z[2]), z[3],
                                                             z[4], ca, cg, vr)
    return (rate[0], rate[1], a02 * rate[2] + a03 * rate[3] + a04 * rate[4],
            a12 * rate[2] + a04 * rate[3] + a14 * rate[4])


@njit
def _quintic(t):
    """The quintic Hermite basis at t ∈ [0, 1] and its first and second derivatives, each
    for the data (a, a', a'', b, b', b'') of the ends t = 0 and t = 1."""
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    t5 = t4 * t
    c = (1.0 - 10.0 * t3 + 15.0 * t4 - 6.0 * t5, t - 6.0 * t3 + 8.0 * t4 - 3.0 * t5,
         0.5 * (t2 - 3.0 * t3 + 3.0 * t4 - t5), 10.0 * t3 - 15.0 * t4 + 6.0 * t5,
         -4.0 * t3 + 7.0 * t4 - 3.0 * t5, 0.5 * (t3 - 2.0 * t4 + t5))
    d = (-30.0 * t2 + 60.0 * t3 - 30.0 * t4, 1.0 - 18.0 * t2 + 32.0 * t3 - 15.0 * t4,
         0.5 * (2.0 * t - 9.0 * t2 + 12.0 * t3 - 5.0 * t4), 30.0 * t2 - 60.0 * t3 + 30.0 * t4,
         -12.0 * t2 + 28.0 * t3 - 15.0 * t4, 0.5 * (3.0 * t2 - 8.0 * t3 + 5.0 * t4))
    dd = (-60.0 * t + 180.0 * t2 - 120.0 * t3, -36.0 * t + 96.0 * t2 - 60.0 * t3,
          0.5 * (2.0 - 18.0 * t + 36.0 * t2 - 20.0 * t3), 60.0 * t - 180.0 * t2 + 120.0 * t3,
          -24.0 * t + 84.0 * t2 - 60.0 * t3, 0.5 * (6.0 * t - 24.0 * t2 + 20.0 * t3))
    return c, d, dd


@njit
def _node_data(pts, seg, j, side, dx, dy, ex, ey):
    """Set the slope (dx, dy) and its derivative (ex, ey) on one side of node j of piece
    ``seg``: after it (``side`` 0), before it (1) or both (2)."""
    for k in range(2):
        if side == 2 or side == k:
            col = P_DXA if k == 0 else P_DXB
            pts[seg, j, col] = dx
            pts[seg, j, col + 1] = dy
            pts[seg, j, col + 2] = ex
            pts[seg, j, col + 3] = ey


@njit
def _bound(seg, pts, bounds, n):
    """The bounding circle of the nodes of piece ``seg`` (n steps) into ``bounds[seg]``."""
    cx = 0.0
    cy = 0.0
    for j in range(n + 1):
        cx += pts[seg, j, P_X]
        cy += pts[seg, j, P_Y]
    cx /= n + 1
    cy /= n + 1
    radius = 0.0
    for j in range(n + 1):
        radius = max(radius, math.hypot(pts[seg, j, P_X] - cx, pts[seg, j, P_Y] - cy))
    bounds[seg, B_X] = cx
    bounds[seg, B_Y] = cy
    bounds[seg, B_R] = radius
    bounds[seg, B_TOUCH] = 0.0


@njit
def build_piece(za, zb, seg, grid, rest, level, pts, bounds):
    """The piece of segment ``seg`` from its start state ``za`` and end state ``zb`` (6,)
    (x, y, θ, n_x, n_y, m) at the level tuple ``level``: a quintic Hermite curve in the
    segment's arc length through their positions with their slopes r' and derivatives r''
    (:func:`_derivatives`), sampled at its RK4 nodes into ``pts[seg]`` (the same data on
    both sides of a node), its bounding circle into ``bounds[seg]``.

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
    half = sp[SC_HALF + i]
    h_start = 0.5 * (sp[SC_HALF + i - 1] + half) if segs[seg, SEG_FIRST] == 0 and i > 0 else half
    h_end = 0.5 * (half + sp[SC_HALF + i + 1]) \
        if segs[seg, SEG_END] == 1 and i < secf.shape[1] - 1 else half
    rate = np.empty(6)
    dxa, dya, exa, eya = _derivatives(za, i, grid, rest, level, rate)
    dxb, dyb, exb, eyb = _derivatives(zb, i, grid, rest, level, rate)
    coef_x = (za[0], ell * dxa, ell * ell * exa, zb[0], ell * dxb, ell * ell * exb)
    coef_y = (za[1], ell * dya, ell * ell * eya, zb[1], ell * dyb, ell * ell * eyb)
    for j in range(n + 1):
        c, d, dd = _quintic(j / n)
        px = py = vx = vy = wx = wy = 0.0
        for e in range(6):
            px += c[e] * coef_x[e]
            py += c[e] * coef_y[e]
            vx += d[e] * coef_x[e]
            vy += d[e] * coef_y[e]
            wx += dd[e] * coef_x[e]
            wy += dd[e] * coef_y[e]
        pts[seg, j, P_X] = px
        pts[seg, j, P_Y] = py
        pts[seg, j, P_S] = s0 + j * step
        pts[seg, j, P_H] = h_start if j == 0 else (h_end if j == n else half)
        _node_data(pts, seg, j, 2, vx / ell, vy / ell, wx / (ell * ell), wy / (ell * ell))
    _bound(seg, pts, bounds, n)


@njit
def trace_piece(seg, states, end, target, grid, rest, level, loads, pts, bounds):
    """The piece of segment ``seg`` from the segment integrated with the self-contact loads
    ``loads``: its RK4 nodes' states ``states`` (≥ n + 1, 6) (x, y, θ, n_x, n_y, m), each
    after its node's load (the base node: before it), the last one ``end`` (6,) — plus, where
    the segment does not end at the tip, the quintic Hermite correction that takes the
    integrated end (before its node's load) to the next segment's start ``target`` (6,)
    (after the load and any endplate): positions, slopes and their derivatives. So the piece
    meets the shooting nodes at both ends, and at a solution — where the integrated end is
    the next start — it is the integrated backbone itself, with the shear and stretch kinks
    of the point loads at its nodes. Slopes and their derivatives are kept on both sides of
    each node (:func:`_node_data`); half-thicknesses as :func:`build_piece` set them."""
    segs = grid[G_SEGS]
    i = segs[seg, SEG_SECTION]
    n = segs[seg, SEG_STEPS]
    ell = pts[seg, n, P_S] - pts[seg, 0, P_S]
    z = np.empty(6)
    rate = np.empty(6)
    mismatch = np.zeros(6)
    for j in range(n + 1):
        for d in range(6):
            z[d] = end[d] if j == n else states[j, d]
        a, b = canonical_slot(segs, seg, j)
        fx = loads[a, b, SELF_FX]
        fy = loads[a, b, SELF_FY]
        mz = loads[a, b, SELF_M]
        if seg == 0 and j == 0:  # recorded before the base node's load, which is the clamp's
            z[3] -= fx
            z[4] -= fy
            z[5] -= mz
        pts[seg, j, P_X] = z[0]
        pts[seg, j, P_Y] = z[1]
        dx, dy, ex, ey = _derivatives(z, i, grid, rest, level, rate)
        loaded = fx != 0.0 or fy != 0.0 or mz != 0.0
        _node_data(pts, seg, j, 0 if loaded else 2, dx, dy, ex, ey)
        if loaded:
            z[3] += fx  # before the node's load
            z[4] += fy
            z[5] += mz
            dx, dy, ex, ey = _derivatives(z, i, grid, rest, level, rate)
            _node_data(pts, seg, j, 1, dx, dy, ex, ey)
    if seg < segs.shape[0] - 1:
        for d in range(6):
            z[d] = target[d]
        a, b = canonical_slot(segs, seg, n)
        z[3] += loads[a, b, SELF_FX]
        z[4] += loads[a, b, SELF_FY]
        z[5] += loads[a, b, SELF_M]
        if segs[seg, SEG_END] == 1:
            z[3] += level[L_PLATE][i, 0]
            z[4] += level[L_PLATE][i, 1]
        dx, dy, ex, ey = _derivatives(z, i, grid, rest, level, rate)
        mismatch[0] = z[0] - pts[seg, n, P_X]
        mismatch[1] = z[1] - pts[seg, n, P_Y]
        mismatch[2] = ell * (dx - pts[seg, n, P_DXB])
        mismatch[3] = ell * (dy - pts[seg, n, P_DXB + 1])
        mismatch[4] = ell * ell * (ex - pts[seg, n, P_EXB])
        mismatch[5] = ell * ell * (ey - pts[seg, n, P_EXB + 1])
    for j in range(1, n + 1):
        c, d, dd = _quintic(j / n)
        for axis in range(2):
            pts[seg, j, P_X + axis] += c[3] * mismatch[axis] + c[4] * mismatch[2 + axis] \
                + c[5] * mismatch[4 + axis]
            slope = (d[3] * mismatch[axis] + d[4] * mismatch[2 + axis]
                     + d[5] * mismatch[4 + axis]) / ell
            turn = (dd[3] * mismatch[axis] + dd[4] * mismatch[2 + axis]
                    + dd[5] * mismatch[4 + axis]) / (ell * ell)
            pts[seg, j, P_DXA + axis] += slope
            pts[seg, j, P_DXB + axis] += slope
            pts[seg, j, P_EXA + axis] += turn
            pts[seg, j, P_EXB + axis] += turn
    _bound(seg, pts, bounds, n)


@njit
def may_touch(Z, grid, rest, tip_x, tip_y) -> bool:
    """A cheap, conservative test on the shooting nodes ``Z`` alone: False when no two
    points farther apart along the arc than the exclusion can come within reach of each
    other, so there is no self-contact to work out.

    With v = 1.5 × the largest rest stretch bounding |r'|, a segment of arc length ℓ lies
    within v·ℓ/2 of its end nodes' midpoint, and its first (last) δ of arc within v·δ of its
    start (end) node. Of two segments a < b only the points of a before s₁(b) − exclusion
    and those of b after s₀(a) + exclusion can touch: for a pair just beyond the exclusion,
    short pieces at its far ends, which the end nodes bound much more tightly than the
    segments' midpoints (the midpoints alone flag a straight arm: on it a pair whose far
    ends are just beyond the exclusion has midpoints closer than their radii). The tip
    segment ends at (``tip_x``, ``tip_y``) where the caller has integrated it; with NaN it is
    bounded by v·ℓ about its start."""
    segs = grid[G_SEGS]
    secf = grid[G_SECF]
    sp = grid[G_SELF]
    n_seg = segs.shape[0]
    stretch = _stretch_bound(rest)
    reach = 2.0 * _largest_half(sp)
    exclusion = sp[SC_EXCLUSION]
    ends_known = n_seg if math.isfinite(tip_x) and math.isfinite(tip_y) else n_seg - 1
    px = np.zeros(n_seg + 1)  # node k starts segment k (node 0: the base, at the origin)
    py = np.zeros(n_seg + 1)
    s0 = np.empty(n_seg)
    s1 = np.empty(n_seg)
    for seg in range(n_seg):
        i = segs[seg, SEG_SECTION]
        step = secf[LEN, i] / grid[G_STEPS][i]
        s0[seg] = grid[G_START][i] + segs[seg, SEG_FIRST] * step
        s1[seg] = s0[seg] + segs[seg, SEG_STEPS] * step
        if seg < n_seg - 1:
            px[seg + 1] = Z[3 + 6 * seg]
            py[seg + 1] = Z[4 + 6 * seg]
    px[n_seg] = tip_x
    py[n_seg] = tip_y
    for a in range(n_seg):
        ax, ay, ra = _circle(a, px, py, s0, s1, stretch, ends_known)
        for b in range(a + 1, n_seg):
            if s1[b] - s0[a] <= exclusion:
                continue
            # Points that may touch: a's within v·near_a of its start node, b's within
            # v·near_b of its end node (where known), each also within its segment's circle.
            near_a = stretch * (min(s1[a], s1[b] - exclusion) - s0[a])
            near_b = stretch * (s1[b] - max(s0[b], s0[a] + exclusion))
            bx, by, rb = _circle(b, px, py, s0, s1, stretch, ends_known)
            if _far(ax, ay, ra, bx, by, rb, reach) or _far(px[a], py[a], near_a, bx, by, rb, reach):
                continue
            if b < ends_known and (_far(ax, ay, ra, px[b + 1], py[b + 1], near_b, reach) or _far(
                    px[a], py[a], near_a, px[b + 1], py[b + 1], near_b, reach)):
                continue
            return True
    return False


@njit
def _circle(seg, px, py, s0, s1, stretch, ends_known):
    """A circle (x, y, radius) holding segment ``seg`` of :func:`may_touch`: about its end
    nodes' midpoint, or about its start where its end is not known."""
    ell = s1[seg] - s0[seg]
    if seg < ends_known:
        return 0.5 * (px[seg] + px[seg + 1]), 0.5 * (py[seg] + py[seg + 1]), 0.5 * stretch * ell
    return px[seg], py[seg], stretch * ell


@njit
def _far(x1, y1, r1, x2, y2, r2, reach) -> bool:
    """Whether no point of circle 1 is within ``reach`` of a point of circle 2."""
    return math.hypot(x1 - x2, y1 - y2) >= r1 + r2 + reach


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
def backbone_crosses(positions, s) -> bool:
    """Whether the planar backbone polyline crosses itself: two of its chords that do not
    meet along the arc (a chord ending where the other starts, or a run of zero-length
    chords between them, as at a section's repeated end sample) intersect. A thick arm that
    touches itself keeps its backbones a thickness apart; a crossing is an arm passed
    through itself (docs/design.md §9.1).

    Args:
        positions: (N, 2) samples (m) in order along the arc. s: (N,) their arc lengths (m).
    """
    n = s.shape[0]
    for i in range(n - 1):
        ax, ay = positions[i, 0], positions[i, 1]
        rx, ry = positions[i + 1, 0] - ax, positions[i + 1, 1] - ay
        for j in range(i + 1, n - 1):
            if s[j] <= s[i + 1]:
                continue  # neighbours along the arc
            bx, by = positions[j, 0], positions[j, 1]
            qx, qy = positions[j + 1, 0] - bx, positions[j + 1, 1] - by
            if max(bx, bx + qx) < min(ax, ax + rx) or min(bx, bx + qx) > max(ax, ax + rx) or \
                    max(by, by + qy) < min(ay, ay + ry) or min(by, by + qy) > max(ay, ay + ry):
                continue
            den = rx * qy - ry * qx
            if den == 0.0:
                continue  # parallel (or zero-length) chords: no single crossing point
            dx, dy = bx - ax, by - ay
            t = (dx * qy - dy * qx) / den
            u = (dx * ry - dy * rx) / den
            if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0:
                return True
    return False


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
def _stretch_bound(rest):
    """A bound on the backbone's stretch |r'|: 1.5 × the largest rest stretch."""
    stretch = 0.0
    for i in range(rest.shape[1]):
        stretch = max(stretch, rest[REST_V3, i])
    return 1.5 * stretch


@njit
def _largest_half(sp):
    largest = 0.0
    for k in range(SC_HALF, sp.shape[0]):
        largest = max(largest, sp[k])
    return largest


@njit
def _nearest_on_chord(x, y, h_own, pts, seg, j):
    """(pen, ux, uy, t, dist) of the point (x, y) against chord j of piece ``seg``:
    penetration h_own + h(p) − |r − p| at the nearest point p = (1 − t)·a + t·b, the unit
    vector from p to the point (zero where they coincide) and the distance |r − p| (m)."""
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
        return reach - dist, dx / dist, dy / dist, t, dist
    return reach, 0.0, 0.0, t, dist


@njit
def _curve(pts, segs, seg, t):
    """Point, first and second derivative (in the parameter t ∈ [0, 1] of piece ``seg``,
    spanning its arc) of the piece's backbone: on each RK4 step the quintic Hermite curve
    through the step's end nodes, their slopes and derivatives on the step's side
    (x, y, dx, dy, ddx, ddy)."""
    n = segs[seg, SEG_STEPS]
    j = min(int(t * n), n - 1)
    step = pts[seg, j + 1, P_S] - pts[seg, j, P_S]
    c, d, dd = _quintic(t * n - j)
    x, dx, ddx = _hermite(c, d, dd, pts, seg, j, 0, step)
    y, dy, ddy = _hermite(c, d, dd, pts, seg, j, 1, step)
    return x, y, n * dx, n * dy, n * n * ddx, n * n * ddy


@njit(inline="always")
def _hermite(c, d, dd, pts, seg, j, axis, step):
    """The coordinate ``axis`` of the quintic Hermite curve of step j of piece ``seg`` and
    its first and second derivatives per unit of the step's parameter, from the basis
    (:func:`_quintic`) at that parameter."""
    a = pts[seg, j, P_X + axis]
    ta = step * pts[seg, j, P_DXA + axis]
    ca = step * step * pts[seg, j, P_EXA + axis]
    b = pts[seg, j + 1, P_X + axis]
    tb = step * pts[seg, j + 1, P_DXB + axis]
    cb = step * step * pts[seg, j + 1, P_EXB + axis]
    return (c[0] * a + c[1] * ta + c[2] * ca + c[3] * b + c[4] * tb + c[5] * cb,
            d[0] * a + d[1] * ta + d[2] * ca + d[3] * b + d[4] * tb + d[5] * cb,
            dd[0] * a + dd[1] * ta + dd[2] * ca + dd[3] * b + dd[4] * tb + dd[5] * cb)


@njit
def _project(x, y, pts, bounds, segs, seg, t):
    """The point of the backbone's Hermite curves nearest (x, y), by Newton on the parameter
    from piece ``seg`` at ``t`` (a chord's nearest point), moving on to the neighbouring
    piece where it leaves this one and stopping at the arm's ends: (seg, t). The nearest
    point of the smooth curve, unlike a polyline's, has a normal that turns smoothly as the
    point moves — a polyline's jumps where the nearest chord changes on a concave side."""
    n_seg = bounds.shape[0]
    for _ in range(12):
        p = _curve(pts, segs, seg, t)
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
def _at_arc(pts, segs, arc):
    """The (piece, parameter t ∈ [0, 1]) of the backbone's pieces at reference arc length
    ``arc`` (m), clamped to the arm's ends."""
    n_seg = segs.shape[0]
    for seg in range(n_seg):
        s_hi = pts[seg, segs[seg, SEG_STEPS], P_S]
        if arc <= s_hi or seg == n_seg - 1:
            s_lo = pts[seg, 0, P_S]
            return seg, min(1.0, max(0.0, (arc - s_lo) / (s_hi - s_lo)))
    return n_seg - 1, 1.0


@njit
def _arc_of(pts, segs, piece, tau):
    """The reference arc length (m) of the point at parameter ``tau`` of ``piece``."""
    s_lo = pts[piece, 0, P_S]
    return s_lo + tau * (pts[piece, segs[piece, SEG_STEPS], P_S] - s_lo)


@njit
def _moment_at(loads, segs, pts, seg, j, cx, cy, fx, fy):
    """Add the force (fx, fy) (N), acting at the point (cx, cy), to node j of piece
    ``seg``: the force, and its moment about the node as a point moment (N m), so that the
    node carries the force's moment about any point."""
    a, b = canonical_slot(segs, seg, j)
    loads[a, b, SELF_FX] += fx
    loads[a, b, SELF_FY] += fy
    loads[a, b, SELF_M] += (cx - pts[seg, j, P_X]) * fy - (cy - pts[seg, j, P_Y]) * fx


@njit
def _rub(x, y, ux, uy, pen, h_own, dist, w, share, seg, j, piece, tau, k, mu, grid, pts, loads,
         sfs, q, record):
    """Coulomb friction between the point (x, y) of piece ``seg`` (a fraction ``share`` of
    the way from node j to node j + 1, its arc share ``w``; its friction sample
    ``sfs[seg, j, q]``) and the partner's nearest point, at parameter ``tau`` of ``piece``,
    ``dist`` away along the unit normal (ux, uy) (from the partner to the point), the
    penetration ``pen`` (docs/design.md §9.1).

    The sample's anchor is the partner's material point it sticks to, by its reference arc
    length a; its slip d = t·(r − r'(a)) is the point's tangential displacement relative to
    that material point (t the partner's unit backbone tangent at a, in the sense of the
    contact tangent (−u_y, u_x)); the obstacles' return mapping
    (:func:`solver.kernels.obstacles.return_mapping`) with the law's stiffness k and the cone
    μ·g(pen), g(pen) = the normal force per length over k (the law's onset included), gives
    the force per length f_t along t. Half of it, f_t·w/2 (each pair is counted from both
    sides, as the normal law's is), acts on the point and its reaction on the partner, both
    at the contact point c (halfway across the overlap): the point's part lumped onto its
    step's nodes by ``share``, the reaction onto the partner's nodes either side of its
    point by where that lies, each with its moment about the node (:func:`_moment_at`), so
    that the pair carries neither a net force nor a net moment. Where it slips, the anchor is
    dragged along to the cone's edge: a' = s_p + (a − s_p)·cap/|d|, s_p the partner point's
    arc length. A point without an anchor (not in contact at the last accepted state)
    sticks where it is, carrying none yet. With ``record``, the sample's new anchor,
    impulse, position and slip are written (``FS_*``)."""
    segs = grid[G_SEGS]
    s_p = _arc_of(pts, segs, piece, tau)
    anchor = sfs[seg, j, q, FS_A]
    fresh = math.isnan(anchor)
    tx = -uy
    ty = ux
    dd = 0.0
    if not fresh:
        a_piece, a_tau = _at_arc(pts, segs, anchor)
        p = _curve(pts, segs, a_piece, a_tau)
        if not ((a_piece == 0 and a_tau <= END_TAU)
                or (a_piece == segs.shape[0] - 1 and a_tau >= 1.0 - END_TAU)):
            # Anchored on the partner's side: the slip along its backbone tangent there, in
            # the contact tangent's sense — within an increment (the anchor fixed) a smooth
            # function of the nodes. The contact tangent turns with the nearest point, which
            # jumps where it crosses a kink of the traced backbone, and across the parts'
            # distance (~7 cm on OctArm V) that jumped the slip by more than the cone's
            # width: a residual without a root, where Newton stalled (docs/design.md §9.1).
            # (At an end, which the contact wraps round, the contact tangent stays.)
            size = math.hypot(p[2], p[3])
            sense = 1.0 if p[2] * tx + p[3] * ty >= 0.0 else -1.0
            tx = sense * p[2] / size
            ty = sense * p[3] / size
        dd = tx * (x - p[0]) + ty * (y - p[1])
    cap = mu * (0.5 * pen * pen / ONSET if pen < ONSET else pen - 0.5 * ONSET)
    ft, slip, sg = return_mapping(dd, cap, k)
    if fresh:
        moved = s_p
    elif sg == 0.0:
        moved = anchor
    else:
        moved = s_p + (anchor - s_p) * cap / abs(dd)
    fx = 0.5 * w * ft * tx
    fy = 0.5 * w * ft * ty
    cx = x - (h_own - 0.5 * pen) * ux
    cy = y - (h_own - 0.5 * pen) * uy
    for end in range(2):
        part = 1.0 - share if end == 0 else share
        if part != 0.0:
            _moment_at(loads, segs, pts, seg, j + end, cx, cy, part * fx, part * fy)
    n_p = segs[piece, SEG_STEPS]
    node = min(int(tau * n_p), n_p - 1)
    t = tau * n_p - node
    _moment_at(loads, segs, pts, piece, node, cx, cy, -(1.0 - t) * fx, -(1.0 - t) * fy)
    _moment_at(loads, segs, pts, piece, node + 1, cx, cy, -t * fx, -t * fy)
    if record:
        record_planar_sample(sfs[seg, j, q], moved, 0.0, fx, fy, x, y, slip)


@njit
def _contact_at(x, y, s, h_own, w, share, seg, j, grid, pts, bounds, loads, reach, exclusion, k,
                behind, ahead, wide, bulge, sfs, q, record):
    """Apply the law to the point (x, y) at arc length ``s`` with half-thickness ``h_own``
    and arc share ``w`` (m), a fraction ``share`` of the way from node j of piece ``seg`` to
    node j + 1: every contact it makes (a run of consecutive chords of another part within
    ``reach`` of the point, less the chord's half-thickness, and ``bulge`` — how far the
    curves stand off their chords (:func:`_bulge`): the curve decides, not the chord) is
    found and its load added to
    ``loads`` (see :func:`self_loads`), the point's own half lumped onto nodes j and j + 1 by
    ``share``.

    With friction (``sfs``, the self-contact friction samples, has rows) the first contact
    the point makes also carries Coulomb friction, its sample ``sfs[seg, j, q]``
    (:func:`_rub`; ``record``: write the sample's state).

    Returns (the deepest penetration, the point's clearance): a lower bound on its distance
    (m) to the chords that are not within ``exclusion`` of every arc length in
    [s − ``behind``, s + ``ahead``] — the distance to each such chord of a piece whose
    bounding circle comes within ``wide`` of the point, else to the circle; infinite where
    there is none."""
    segs = grid[G_SEGS]
    n_seg = segs.shape[0]
    deepest = 0.0
    clearance = math.inf
    rubbed = sfs.shape[0] == 0  # a point's friction: at its first contact
    in_run = False
    best_pen = 0.0
    best_t = 0.0
    best_seg = 0
    best_j = 0
    for other in range(n_seg + 1):
        near = False
        scan = False
        if other < n_seg and bounds[other, B_R] >= 0.0:
            s_lo = pts[other, 0, P_S]
            s_hi = pts[other, segs[other, SEG_STEPS], P_S]
            relevant = s_lo < s + ahead - exclusion or s_hi > s - behind + exclusion
            # A piece wholly within the exclusion (of the point itself) has no chord the
            # law may use, and needs no look unless the clearance asks for it.
            if relevant or s_lo < s - exclusion or s_hi > s + exclusion:
                dx = x - bounds[other, B_X]
                dy = y - bounds[other, B_Y]
                d2 = dx * dx + dy * dy
                far = bounds[other, B_R] + reach + bulge
                near = d2 < far * far
                if relevant and wide > 0.0:
                    gap = math.sqrt(d2) - bounds[other, B_R]
                    scan = gap < wide
                    if not scan:
                        clearance = min(clearance, gap)
        chords = segs[other, SEG_STEPS] if near or scan else 1
        for c in range(chords):
            pen = -1.0
            ux = uy = t = 0.0
            if near or scan:
                s_a = pts[other, c, P_S]
                s_b = pts[other, c + 1, P_S]
                dist = math.inf
                if near and abs(s - s_a) > exclusion and abs(s - s_b) > exclusion:
                    pen, ux, uy, t, dist = _nearest_on_chord(x, y, h_own, pts, other, c)
                if scan and not (s + ahead - exclusion <= s_a <= s - behind + exclusion
                                 or s + ahead - exclusion <= s_b <= s - behind + exclusion):
                    if dist == math.inf:
                        dist = _nearest_on_chord(x, y, h_own, pts, other, c)[4]
                    clearance = min(clearance, dist)
            if pen > -bulge and (ux != 0.0 or uy != 0.0):
                if not in_run or pen > best_pen:
                    best_pen, best_t = pen, t
                    best_seg, best_j = other, c
                in_run = True
                continue
            if not in_run:
                continue
            # A run of chords within reach ends: one contact, the nearest point of the
            # curve, from the run's nearest chord's.
            in_run = False
            n_b = segs[best_seg, SEG_STEPS]
            piece, tau = _project(x, y, pts, bounds, segs, best_seg, (best_j + best_t) / n_b)
            p = _curve(pts, segs, piece, tau)
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
            f = w * (0.5 * k * pen * pen / ONSET if pen < ONSET else k * (pen - 0.5 * ONSET))
            stiff = w * (k * pen / ONSET if pen < ONSET else k)
            for end in range(2):
                part = 1.0 - share if end == 0 else share
                if part == 0.0:
                    continue
                a, b = canonical_slot(segs, seg, j + end)
                # The piece whose map applies the load (its Jacobian carries the law's
                # stiffness, which Newton's coupled Jacobian replaces by differences).
                bounds[a, B_TOUCH] = 1.0
                loads[a, b, SELF_FX] += 0.5 * part * f * ux
                loads[a, b, SELF_FY] += 0.5 * part * f * uy
                loads[a, b, SELF_PEN] = max(loads[a, b, SELF_PEN], pen)
                # The point's own law across the normal (∂pen/∂r = −ûᵀ), the other part
                # held fixed, its share on the node: for the stability test
                # (docs/design.md §9).
                loads[a, b, SELF_K00] -= part * stiff * ux * ux
                loads[a, b, SELF_K01] -= part * stiff * ux * uy
                loads[a, b, SELF_K11] -= part * stiff * uy * uy
            _add(loads, segs, piece, node, -0.5 * f * (1.0 - t) * ux, -0.5 * f * (1.0 - t) * uy)
            _add(loads, segs, piece, node + 1, -0.5 * f * t * ux, -0.5 * f * t * uy)
            if not rubbed:
                rubbed = True
                _rub(x, y, ux, uy, pen, h_own, dist, w, share, seg, j, piece, tau, k,
                     grid[G_SELF][SC_MU], grid, pts, loads, sfs, q, record)
            deepest = max(deepest, pen)
            bounds[seg, B_TOUCH] = 1.0
            bounds[best_seg, B_TOUCH] = 1.0
            bounds[piece, B_TOUCH] = 1.0
    return deepest, clearance


@njit
def _bulge(pts, segs):
    """How far (m) the pieces' curves stand off their chords, at most: 1.5 × the largest
    distance of a curve's quarter, half and three-quarter points from its step's chord. The
    chords find the contacts, so a point the curve reaches but a chord does not would set
    in with a jump of its depth (a sagitta, 0.2 mm on a scaled arm's coarse steps) as the
    chord came within reach."""
    largest = 0.0
    for seg in range(segs.shape[0]):
        n = segs[seg, SEG_STEPS]
        for j in range(n):
            ax = pts[seg, j, P_X]
            ay = pts[seg, j, P_Y]
            ex = pts[seg, j + 1, P_X] - ax
            ey = pts[seg, j + 1, P_Y] - ay
            length = math.hypot(ex, ey)
            if not length > 0.0:
                continue
            for q in range(1, 4):
                x, y, _, _, _, _ = _curve(pts, segs, seg, (j + 0.25 * q) / n)
                largest = max(largest, abs((x - ax) * ey - (y - ay) * ex) / length)
    return 1.5 * largest


@njit
def samples_untouched(sfs):
    """Mark every self-contact friction sample ``sfs`` as not in contact at the state a
    pass records (:func:`solver.kernels.obstacles.friction_untouched`): no anchor to carry."""
    for seg in range(sfs.shape[0]):
        friction_untouched(sfs, seg)


@njit
def self_loads(grid, rest, pts, bounds, loads, moved, sfs, record):
    """The self-contact point loads of the pieces ``pts`` (see the module docstring) into
    ``loads`` (M, segment steps + 1, N_SELF), at each node's canonical slot: SELF_FX, SELF_FY
    the point load (N), SELF_QX, SELF_QY that load per length of the node's share of the arc
    (N/m), SELF_PEN its own deepest penetration (m), SELF_K00…SELF_K11 its own law's
    stiffness across the normal with the other part fixed (N/m). Pieces in contact are marked in
    ``bounds``. Returns the deepest penetration.

    The law is sampled at SUBPOINTS points per RK4 step along each piece's curve (its
    nodes among them), each with its share of the arc, and each point's load is lumped onto
    the step's two nodes in proportion to where it lies between them (docs/design.md §9,
    "Resolution"). Only points that may touch another part are worked out: a node's
    clearance (P_CLEAR) bounds from below its distance to the chords of the other parts
    over the steps either side of it, so a point of a step farther from either end node
    than that node's clearance less the point's reach and the curves' bulge off their chords
    is skipped (an exact test: the chords, widened by the bulge, find every contact).
    ``moved`` < 0 or NaN: the clearances are worked out (and where the
    nodes were, P_X0 and P_Y0); else they are those of pieces that have since moved by at
    most ``moved`` (m) at any node (:func:`moved_since`), and count 2·``moved`` less, for
    the point's and the other part's moves.

    With friction (``sfs`` (M, segment steps + 1, SUBPOINTS, N_FS), the self-contact
    friction samples, has rows; ``layout.FS_*``), each point carries Coulomb friction at
    its first contact (:func:`_rub`), into the loads and, where ``record``, their state
    into ``sfs`` (every other sample marked as not in contact, as
    :func:`solver.kernels.obstacles.friction_untouched` marks a step out of reach): the
    anchors the state's acceptance takes (:func:`solver.kernels.obstacles.accept_friction`)."""
    segs = grid[G_SEGS]
    sp = grid[G_SELF]
    k = sp[SC_K]
    exclusion = sp[SC_EXCLUSION]
    largest = _largest_half(sp)
    loads[:, :, :] = 0.0
    deepest = 0.0
    n_seg = segs.shape[0]
    stretch = _stretch_bound(rest)
    bulge = _bulge(pts, segs)
    fresh = not moved >= 0.0
    slack = (0.0 if fresh else 2.0 * moved) + bulge
    if record:
        samples_untouched(sfs)
    for seg in range(n_seg):
        n = segs[seg, SEG_STEPS]
        for j in range(0 if seg == 0 else 1, n + 1):
            reach = pts[seg, j, P_H] + largest
            if not fresh and pts[seg, j, P_CLEAR] - slack > reach:
                continue
            behind = ahead = wide = 0.0
            if fresh:
                # The steps either side of the node (the next piece's first after its last)
                # and the farthest a point on them may be from it, with that point's reach.
                if j > 0:
                    behind = pts[seg, j, P_S] - pts[seg, j - 1, P_S]
                if j < n:
                    ahead = pts[seg, j + 1, P_S] - pts[seg, j, P_S]
                elif seg + 1 < n_seg:
                    ahead = pts[seg + 1, 1, P_S] - pts[seg + 1, 0, P_S]
                wide = 2.0 * largest + stretch * max(behind, ahead) + bulge
            pen, clear = _contact_at(
                pts[seg, j, P_X], pts[seg, j, P_Y], pts[seg, j, P_S], pts[seg, j, P_H],
                _weight(segs, pts, seg, j) / SUBPOINTS, 0.0, seg, j, grid, pts, bounds, loads,
                reach, exclusion, k, behind, ahead, wide, bulge, sfs, 0, record)
            deepest = max(deepest, pen)
            if fresh:
                pts[seg, j, P_CLEAR] = clear
                if j == n and seg + 1 < n_seg:
                    pts[seg + 1, 0, P_CLEAR] = clear
    if fresh:
        for seg in range(n_seg):
            for j in range(segs[seg, SEG_STEPS] + 1):
                pts[seg, j, P_X0] = pts[seg, j, P_X]
                pts[seg, j, P_Y0] = pts[seg, j, P_Y]
    for seg in range(n_seg):
        n = segs[seg, SEG_STEPS]
        for j in range(n):
            step = pts[seg, j + 1, P_S] - pts[seg, j, P_S]
            clear_a = pts[seg, j, P_CLEAR] - slack
            clear_b = pts[seg, j + 1, P_CLEAR] - slack
            # A point a share σ of the way is within stretch·step·σ of the first node and
            # stretch·step·(1 − σ) of the second: no point of the step is nearer the other
            # parts than the mean clearance less stretch·step/2.
            if 0.5 * (clear_a + clear_b - stretch * step) \
                    > max(pts[seg, j, P_H], pts[seg, j + 1, P_H]) + largest:
                continue
            for q in range(1, SUBPOINTS):
                share = q / SUBPOINTS
                h_own = pts[seg, j, P_H] + share * (pts[seg, j + 1, P_H] - pts[seg, j, P_H])
                x, y, _, _, _, _ = _curve(pts, segs, seg, (j + share) / n)
                if max(clear_a - math.hypot(x - pts[seg, j, P_X], y - pts[seg, j, P_Y]),
                       clear_b - math.hypot(x - pts[seg, j + 1, P_X], y - pts[seg, j + 1, P_Y])) \
                        > h_own + largest:
                    continue
                pen, _ = _contact_at(
                    x, y, pts[seg, j, P_S] + share * step, h_own, step / SUBPOINTS, share, seg, j,
                    grid, pts, bounds, loads, h_own + largest, exclusion, k, 0.0, 0.0, 0.0, bulge,
                    sfs, q, record)
                deepest = max(deepest, pen)
    for seg in range(n_seg):
        for j in range(0 if seg == 0 else 1, segs[seg, SEG_STEPS] + 1):
            w = _weight(segs, pts, seg, j)
            loads[seg, j, SELF_QX] = loads[seg, j, SELF_FX] / w
            loads[seg, j, SELF_QY] = loads[seg, j, SELF_FY] / w
    return deepest


@njit
def _nearest_on_interval(x, y, positions, slopes, k, ds, t):
    """The parameter (t ∈ [0, 1]) of the point of the cubic Hermite curve between samples k
    and k + 1 nearest (x, y), by Newton on |r(t) − (x, y)|² from ``t``, kept in [0, 1]."""
    for _ in range(30):
        px, dx, ddx = hermite_point(positions, slopes, k, ds, t, 0)
        py, dy, ddy = hermite_point(positions, slopes, k, ds, t, 1)
        slope = (px - x) * dx + (py - y) * dy
        curve = dx * dx + dy * dy + (px - x) * ddx + (py - y) * ddy
        if not curve > 0.0:
            break
        t_new = min(1.0, max(0.0, t - slope / curve))
        if abs(t_new - t) < 1e-15:
            break
        t = t_new
    return t


@njit
def peak_overlap(positions, slopes, s, half, exclusion):
    """The deepest overlap (m, ≥ 0) of a planar backbone with itself anywhere along it, not
    only at its samples: the largest h(a) + h(b) − |r(a) − r(b)| over points a, b farther
    apart along the arc than ``exclusion`` (m), h the half-thickness.

    Between consecutive samples (positions (N, 2), slopes r' (N, 2) per unit arc, arc
    lengths ``s`` (N,), half-thicknesses ``half`` (N,); samples repeated at a junction are
    skipped) the backbone is the cubic Hermite curve through their positions with their
    slopes, h linear. For each pair of intervals whose control-point balls come within reach,
    from the nearest of a 5 × 5 grid of point pairs, each point is moved in turn to the
    nearest point of the other's curve (Newton) until the pair stops moving."""
    deepest = 0.0
    n = s.shape[0]
    largest = 0.0
    for k in range(n):
        largest = max(largest, half[k])
    for a in range(n - 1):
        ds_a = s[a + 1] - s[a]
        if not ds_a > 0.0:
            continue
        centre_a, radius_a = hull_circle(positions, slopes, a, ds_a)
        for b in range(a + 1, n - 1):
            ds_b = s[b + 1] - s[b]
            if not ds_b > 0.0 or s[b] - s[a + 1] <= exclusion:
                continue
            centre_b, radius_b = hull_circle(positions, slopes, b, ds_b)
            if math.hypot(centre_a[0] - centre_b[0], centre_a[1] - centre_b[1]) \
                    - radius_a - radius_b >= 2.0 * largest:
                continue
            best = math.inf  # the nearest pair of the grid, where the search starts
            t1 = t2 = 0.0
            for p in range(5):
                xa = hermite_point(positions, slopes, a, ds_a, p / 4.0, 0)[0]
                ya = hermite_point(positions, slopes, a, ds_a, p / 4.0, 1)[0]
                for q in range(5):
                    gap = math.hypot(xa - hermite_point(positions, slopes, b, ds_b, q / 4.0, 0)[0],
                                     ya - hermite_point(positions, slopes, b, ds_b, q / 4.0, 1)[0])
                    if gap < best:
                        best = gap
                        t1 = p / 4.0
                        t2 = q / 4.0
            for _ in range(50):
                xa = hermite_point(positions, slopes, a, ds_a, t1, 0)[0]
                ya = hermite_point(positions, slopes, a, ds_a, t1, 1)[0]
                t2_new = _nearest_on_interval(xa, ya, positions, slopes, b, ds_b, t2)
                xb = hermite_point(positions, slopes, b, ds_b, t2_new, 0)[0]
                yb = hermite_point(positions, slopes, b, ds_b, t2_new, 1)[0]
                t1_new = _nearest_on_interval(xb, yb, positions, slopes, a, ds_a, t1)
                done = abs(t1_new - t1) < 1e-13 and abs(t2_new - t2) < 1e-13
                t1 = t1_new
                t2 = t2_new
                if done:
                    break
            xa = hermite_point(positions, slopes, a, ds_a, t1, 0)[0]
            ya = hermite_point(positions, slopes, a, ds_a, t1, 1)[0]
            xb = hermite_point(positions, slopes, b, ds_b, t2, 0)[0]
            yb = hermite_point(positions, slopes, b, ds_b, t2, 1)[0]
            reach = half[a] + t1 * (half[a + 1] - half[a]) + half[b] + t2 * (half[b + 1] - half[b])
            deepest = max(deepest, reach - math.hypot(xa - xb, ya - yb))
    return deepest
