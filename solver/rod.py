"""The rod equations: one home, shared by the solver's kernels and the sensing package.

Reissner/Cosserat statics in the rest-strain form of docs/design.md §4–5, as numba kernels on
plain arrays (layouts in :mod:`solver.layout`): frames, the actuator's rest strains, the
constitutive law and right-hand sides (planar with dead loads, planar with the internal force
as state, spatial), fixed-step RK4 integrators, closed-form arcs, and the cubic Hermite
resampling of a recorded backbone. Every kernel writes into preallocated outputs and
allocates nothing it does not return. The path following, stability tests and contact live
in the solver's private kernel modules; this module is public so that estimators and sensors
integrate exactly the equations the solver does.

Planar (section i, reference arc length s, σ local to the section):

    x' = v3 cos θ − v1 sin θ,   y' = v3 sin θ + v1 cos θ,   θ' = u*_i + m/EI_i
    m' = v1 n3 − v3 n1,   v1 = n1/GA_i,   v3 = v*_i + n3/EA_i
    n1 = n·d1, n3 = n·d3,   d3 = (cos θ, sin θ), d1 = (−sin θ, cos θ)

with dead loads n(σ) = n_end_i + q_i·(L_i − σ) (n_end_i includes the endplate and everything
distal). The sensitivities a = ∂θ/∂m0, b = ∂m/∂m0 are integrated alongside:
a' = b/EI, b' = [(1/GA − 1/EA)(n1² − n3²) + v*_i n3]·a.

Spatial: r' = R v, β' = ½ β ⊗ (0, u), m' = −r' × n with v = v* + D⁻¹Rᵀn,
u = u* + C⁻¹Rᵀm, and the world-frame sensitivities to m0, δR = [δφ]×R:
δφ' = K (δm + m × δφ), K = R C⁻¹ Rᵀ; δm' = −δr' × n, δr' = δφ × r' − P(δφ × n),
P = R D⁻¹ Rᵀ.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from solver.actuator import tube_stretch
from solver.jit import njit
from solver.kernels.obstacles import contact_force, contact_force_3d
from solver.layout import (
    CA,
    CG,
    CI,
    CS_M,
    CS_N,
    CS_Q,
    CS_R,
    D_M,
    D_THETA,
    D_V1,
    D_V3,
    D_X,
    D_Y,
    EA,
    EI,
    LEN,
    N_CSTATE,
    NEX,
    NEY,
    NSTATE,
    NX,
    NY,
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
    T_CHANNEL,
    T_FIRST,
    T_LAST,
    TF_A,
    TF_AREA_RATIO,
    TF_B,
    TF_COS_ALPHA,
    TF_E,
    TF_EAT,
    THETA,
    V1,
    V3,
    M,
    S,
    U,
    X,
    Y,
)

__all__ = [
    "base_rotation", "rotation_to_quaternion", "rest_strains_into", "rest_strains_cached",
    "planar_strains", "planar_strains_cs", "integrate_planar", "shift_planar_record",
    "forget_first_variations", "planar_rest_gradient", "planar_state_rates", "planar_state_rhs",
    "planar_state_jacobian", "planar_state_rk4", "planar_state_rk4_step", "spatial_rhs",
    "spatial_rk4_step",
    "integrate_spatial", "record_spatial_row", "arc_chain_planar", "arc_chain_spatial",
    "hermite_resample", "det3", "start_spatial_state",
]


# ----------------------------------------------------------------------------- frames


@njit
def base_rotation(theta0):
    """Directors [d1 d2 d3] (columns) of a base at planar angle θ0: d3 = (cos θ0, sin θ0, 0),
    d2 = +z (docs/design.md §1). Returns (3, 3)."""
    c = math.cos(theta0)
    s = math.sin(theta0)
    rot = np.empty((3, 3))
    rot[0, 0] = -s
    rot[0, 1] = 0.0
    rot[0, 2] = c
    rot[1, 0] = c
    rot[1, 1] = 0.0
    rot[1, 2] = s
    rot[2, 0] = 0.0
    rot[2, 1] = 1.0
    rot[2, 2] = 0.0
    return rot


@njit
def rotation_to_quaternion(r, out):
    """Unit quaternion (w, x, y, z) of the rotation matrix ``r`` (3, 3) into ``out`` (4,)
    (Shepperd's method)."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        out[0] = 0.25 * s
        out[1] = (r[2, 1] - r[1, 2]) / s
        out[2] = (r[0, 2] - r[2, 0]) / s
        out[3] = (r[1, 0] - r[0, 1]) / s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        out[0] = (r[2, 1] - r[1, 2]) / s
        out[1] = 0.25 * s
        out[2] = (r[0, 1] + r[1, 0]) / s
        out[3] = (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        out[0] = (r[0, 2] - r[2, 0]) / s
        out[1] = (r[0, 1] + r[1, 0]) / s
        out[2] = 0.25 * s
        out[3] = (r[1, 2] + r[2, 1]) / s
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        out[0] = (r[1, 0] - r[0, 1]) / s
        out[1] = (r[0, 2] + r[2, 0]) / s
        out[2] = (r[1, 2] + r[2, 1]) / s
        out[3] = 0.25 * s


@njit
def unit_quaternion(y):
    """The normalised quaternion (w, x, y, z) at ``y[SP_Q:SP_Q + 4]`` (``CS_Q == SP_Q``: the
    contact state keeps it in the same place)."""
    qn = math.sqrt(y[SP_Q] ** 2 + y[SP_Q + 1] ** 2 + y[SP_Q + 2] ** 2 + y[SP_Q + 3] ** 2)
    return y[SP_Q] / qn, y[SP_Q + 1] / qn, y[SP_Q + 2] / qn, y[SP_Q + 3] / qn


@njit
def renormalise_quaternion(y):
    """Scale the quaternion at ``y[SP_Q:SP_Q + 4]`` back to unit length in place (an RK4 step
    drifts it off the unit sphere)."""
    qn = math.sqrt(y[SP_Q] ** 2 + y[SP_Q + 1] ** 2 + y[SP_Q + 2] ** 2 + y[SP_Q + 3] ** 2)
    for d in range(SP_Q, SP_Q + 4):
        y[d] /= qn


@njit
def rotation_rows(w, x, y, z):
    """The rotation matrix of the unit quaternion (w, x, y, z), row by row."""
    return (w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)


@njit(inline="always")
def det3(cols):
    """Determinant of the 3×3 matrix stored column-wise in ``cols`` (9,)."""
    return (cols[0] * (cols[4] * cols[8] - cols[5] * cols[7])
            - cols[3] * (cols[1] * cols[8] - cols[2] * cols[7])
            + cols[6] * (cols[1] * cols[5] - cols[2] * cols[4]))


# ----------------------------------------------------------------------------- actuation


@njit
def rest_strains_into(p_channel, tubes_i, tubes_f, secf, rest):
    """Rest curvature and stretch of every section from channel pressures (docs/design.md §4).

    Each tube k carries F_k = E·At·(λ_k − 1) (Eq. 2.11) at offset (a_k, b_k) along (d1, d2)
    in every section it spans, giving v3* = 1 + ΣF/EA, u1* = ΣF·b/EI, u2* = −ΣF·a/EI: the
    geometric form of Eqs. (2.47)–(2.53) and (2.62)–(2.64).

    Args:
        p_channel: (n_channels,) pressures (Pa).
        tubes_i: (n_tubes, 3) int, tubes_f: (n_tubes, 6): see :mod:`solver.layout`.
        secf: (6, ns) section array.
        rest: (3, ns) output rows u1* (rad/m), u2* (rad/m), v3*.
    """
    _clear_rest(rest)
    for k in range(tubes_i.shape[0]):
        _add_tube(k, _tube_stretch(k, p_channel, tubes_i, tubes_f), tubes_i, tubes_f, rest)
    _scale_rest(secf, rest)


@njit
def rest_strains_cached(p_channel, tubes_i, tubes_f, secf, p_seen, stretch, rest):
    """:func:`rest_strains_into`, solving λ(p) (a Newton iteration per tube) only for the
    tubes whose channel pressure differs from the one in ``p_seen`` (n_tubes,), and once for
    tubes of the same material at the same pressure (a planar arm's paired channels, the
    tubes of a channel that spans sections); ``stretch`` (n_tubes,) holds each tube's λ at
    ``p_seen`` and both are updated."""
    _clear_rest(rest)
    for k in range(tubes_i.shape[0]):
        p = p_channel[tubes_i[k, T_CHANNEL]]
        if p != p_seen[k]:
            stretch[k] = math.nan
            for j in range(k):  # p_seen[j] is already this call's pressure of tube j
                if p_seen[j] == p and _same_material(j, k, tubes_f):
                    stretch[k] = stretch[j]
                    break
            if math.isnan(stretch[k]):
                stretch[k] = _tube_stretch(k, p_channel, tubes_i, tubes_f)
            p_seen[k] = p
        _add_tube(k, stretch[k], tubes_i, tubes_f, rest)
    _scale_rest(secf, rest)


@njit(inline="always")
def _same_material(j, k, tubes_f):
    """Whether tubes j and k have the same λ(p): the same modulus, area ratio and wind angle."""
    return (tubes_f[j, TF_E] == tubes_f[k, TF_E]
            and tubes_f[j, TF_AREA_RATIO] == tubes_f[k, TF_AREA_RATIO]
            and tubes_f[j, TF_COS_ALPHA] == tubes_f[k, TF_COS_ALPHA])


@njit(inline="always")
def _tube_stretch(k, p_channel, tubes_i, tubes_f):
    return tube_stretch(p_channel[tubes_i[k, T_CHANNEL]], tubes_f[k, TF_E], tubes_f[k, TF_AREA_RATIO],
                        tubes_f[k, TF_COS_ALPHA])


@njit(inline="always")
def _clear_rest(rest):
    for i in range(rest.shape[1]):
        rest[REST_U1, i] = 0.0
        rest[REST_U2, i] = 0.0
        rest[REST_V3, i] = 0.0


@njit(inline="always")
def _add_tube(k, lam, tubes_i, tubes_f, rest):
    f = tubes_f[k, TF_EAT] * (lam - 1.0)
    for i in range(tubes_i[k, T_FIRST], tubes_i[k, T_LAST] + 1):
        rest[REST_V3, i] += f
        rest[REST_U1, i] += f * tubes_f[k, TF_B]
        rest[REST_U2, i] -= f * tubes_f[k, TF_A]


@njit(inline="always")
def _scale_rest(secf, rest):
    for i in range(rest.shape[1]):
        rest[REST_V3, i] = 1.0 + rest[REST_V3, i] / secf[EA, i]
        rest[REST_U1, i] /= secf[EI, i]
        rest[REST_U2, i] /= secf[EI, i]


# ----------------------------------------------------------------------------- planar


@intrinsic
def fma(typingctx, a, b, c):
    """a·b + c rounded once (LLVM's ``llvm.fma``; float64).

    Written out where a pass spends its time: a fused multiply-add is one instruction
    instead of two. Not by letting the compiler fuse (``fastmath`` contraction), which fuses
    differently in different inlining contexts, so that the parallel and serial forms of one
    batch kernel could disagree in the last bit.
    """
    if not all(isinstance(t, types.Float) for t in (a, b, c)):
        return None

    def codegen(context, builder, signature, args):
        values = [context.cast(builder, v, t, types.float64) for v, t in zip(args, signature.args)]
        f64 = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [f64], ir.FunctionType(f64, [f64] * 3))
        return builder.call(fn, values)

    return types.float64(a, b, c), codegen


@njit(inline="always")
def planar_strains(th, nx, ny, ca, cg, vr):
    """The planar constitutive law at orientation θ under the internal force (n_x, n_y):
    (cos θ, sin θ, n1, n3, v1, v3), n1 = n·d1, n3 = n·d3, v1 = n1/GA, v3 = v* + n3/EA."""
    return planar_strains_cs(math.cos(th), math.sin(th), nx, ny, ca, cg, vr)


@njit(inline="always")
def planar_strains_cs(c, sn, nx, ny, ca, cg, vr):
    """:func:`planar_strains` given (cos θ, sin θ)."""
    n1 = fma(ny, c, -nx * sn)
    n3 = fma(nx, c, ny * sn)
    return c, sn, n1, n3, n1 * cg, fma(n3, ca, vr)


# Below this turn (rad) cos and sin of θ + δ come from those of θ and Taylor polynomials of
# δ (terms to δ¹¹ and δ¹², truncation < 1e-16 at 0.3): RK4 stages sit a fraction of a step
# from their node, and libm's sin and cos would otherwise be two thirds of a pass.
SMALL_TURN = 0.3


@njit(inline="always")
def turned(th, c, sn, d):
    """(cos, sin) of θ + δ from θ, cos θ, sin θ: Taylor polynomials of δ below
    :data:`SMALL_TURN` (to rounding), libm above."""
    if abs(d) > SMALL_TURN:
        return math.cos(th + d), math.sin(th + d)
    # Estrin's scheme: the polynomials of Horner's rule in half as many dependent steps
    # (each stage of a pass waits for its turn).
    z = d * d
    z2 = z * z
    z4 = z2 * z2
    sd_d = fma(z4, fma(z, -1.0 / 39916800.0, 1.0 / 362880.0),
               fma(z2, fma(z, -1.0 / 5040.0, 1.0 / 120.0), fma(z, -1.0 / 6.0, 1.0)))
    cd = fma(z4, fma(z2, 1.0 / 479001600.0, fma(z, -1.0 / 3628800.0, 1.0 / 40320.0)),
             fma(z2, fma(z, -1.0 / 720.0, 1.0 / 24.0), fma(z, -0.5, 1.0)))
    # sin δ = δ·(sd_d): δ multiplies sin θ and cos θ beside the polynomial, not after it.
    return fma(-(sn * d), sd_d, c * cd), fma(c * d, sd_d, sn * cd)


@njit(inline="always")
def _planar_dead_rhs(sig, c, sn, m, a, b, length, ca, cg, ci, ur, vr, nex, ney, qx, qy):
    """Right-hand side of (θ, m, a, b, x, y) under dead loads at local coordinate ``sig``,
    θ given by (cos θ, sin θ), followed by g_θ and g_θθ, the first two derivatives of
    m' = g(θ) in θ: g_θ = (1/GA − 1/EA)(n1² − n3²) + v*·n3, g_θθ = −4(1/GA − 1/EA)·n1·n3 + v*·n1,
    then those of the first variations of x and y, a·∂x'/∂θ and a·∂y'/∂θ (inlined: a caller
    that does not use them does not compute them)."""
    nx = fma(qx, length - sig, nex)
    ny = fma(qy, length - sig, ney)
    c, sn, n1, n3, v1, v3 = planar_strains_cs(c, sn, nx, ny, ca, cg, vr)
    g_th = fma(cg - ca, fma(n1, n1, -n3 * n3), vr * n3)
    # m' = v1·n3 − v3·n1, factored: two dependent operations fewer on the pass's chain.
    m_s = n1 * fma(n3, cg - ca, -vr)
    xs = fma(v3, c, -v1 * sn)
    ys = fma(v3, sn, v1 * c)
    # x' and y' turn with θ, and n1' = −n3, n3' = n1 move v1 and v3: ∂x'/∂θ, ∂y'/∂θ.
    xs_th = fma(ca * n1, c, fma(cg * n3, sn, -ys))
    ys_th = fma(ca * n1, sn, fma(-cg * n3, c, xs))
    return (fma(m, ci, ur), m_s, b * ci, g_th * a, xs, ys, g_th,
            fma(-4.0 * (cg - ca) * n1, n3, vr * n1), xs_th * a, ys_th * a)


@njit
def integrate_planar(m0, theta0, secf, steps, rest, loads, record, out, second):
    """One RK4 pass base → tip from base moment ``m0`` under dead loads.

    Args:
        m0: base moment (N m). theta0: base orientation θ0 (rad).
        secf: (6, ns) section array. steps: (ns,) RK4 steps per section.
        rest: (3, ns) rest strains; the plane uses u2* and v3*.
        loads: (ns, 4) section-end internal force and distributed load (``NEX``…).
        record: write samples to ``out`` ((Σsteps + ns, N_COLUMNS), junctions repeated),
            with the first variations ∂(θ, m, x, y, v1, v3)/∂m0 of every sample.
        second: also integrate the second variation a2 = ∂²θ/∂m0², b2 = ∂²m/∂m0²,
            a2' = b2/EI, b2' = g_θ·a2 + g_θθ·a² (m' = g(θ)), by the midpoint rule on the RK4
            stages at the node and mid-step: second order, plenty for Halley's correction
            factor (:func:`solver.kernels.planar.newton`), at a fraction of a pass.

    Returns:
        (θ, m, ∂m/∂m0, x, y at the tip, min over nodes of ∂m/∂m0 on (0, L], ∂²m/∂m0² at the
        tip (0 unless ``second``), ∂θ/∂m0, ∂x/∂m0, ∂y/∂m0 at the tip).
    """
    th = theta0
    m = m0
    a = 0.0
    b = 1.0
    ax = 0.0
    ay = 0.0
    a2 = 0.0
    b2 = 0.0
    x = 0.0
    y = 0.0
    s0 = 0.0
    row = 0
    bmin = 1.0
    # cos θ and sin θ at the node, carried from node to node by the turn between them.
    c_node = math.cos(th)
    s_node = math.sin(th)
    for i in range(secf.shape[1]):
        length = secf[LEN, i]
        nst = steps[i]
        h = length / nst
        ca = secf[CA, i]
        cg = secf[CG, i]
        ci = secf[CI, i]
        ur = rest[REST_U2, i]
        vr = rest[REST_V3, i]
        nex = loads[i, NEX]
        ney = loads[i, NEY]
        qx = loads[i, QX]
        qy = loads[i, QY]
        for j in range(nst + 1):
            sig = j * h
            if record:
                nx = nex + qx * (length - sig)
                ny = ney + qy * (length - sig)
                c, sn, n1, n3, v1, v3 = planar_strains_cs(c_node, s_node, nx, ny, ca, cg, vr)
                out[row, S] = s0 + sig
                out[row, X] = x
                out[row, Y] = y
                out[row, THETA] = th
                out[row, M] = m
                out[row, NX] = nx
                out[row, NY] = ny
                out[row, V1] = v1
                out[row, V3] = v3
                out[row, U] = ur + m * ci
                out[row, D_THETA] = a
                out[row, D_M] = b
                out[row, D_X] = ax
                out[row, D_Y] = ay
                out[row, D_V1] = -cg * n3 * a  # n1' = −n3 and n3' = n1 as θ turns
                out[row, D_V3] = ca * n1 * a
                row += 1
            if j == nst:
                break
            k1 = _planar_dead_rhs(sig, c_node, s_node, m, a, b, length, ca, cg, ci, ur, vr, nex, ney,
                                  qx, qy)
            # θ' = u* + m/EI is linear in m, so a stage's turn is the node's plus a multiple of
            # the stages' m' before it: one multiply-add on the pass's chain of dependent
            # operations, where m_stage → θ'_stage → turn took three.
            hh = 0.5 * h
            c, sn = turned(th, c_node, s_node, hh * k1[0])
            k2 = _planar_dead_rhs(sig + hh, c, sn, m + hh * k1[1], fma(hh, k1[2], a), fma(hh, k1[3], b),
                                  length, ca, cg, ci, ur, vr, nex, ney, qx, qy)
            c, sn = turned(th, c_node, s_node, fma(hh * hh * ci, k1[1], hh * k1[0]))
            k3 = _planar_dead_rhs(sig + hh, c, sn, m + hh * k2[1], fma(hh, k2[2], a), fma(hh, k2[3], b),
                                  length, ca, cg, ci, ur, vr, nex, ney, qx, qy)
            c, sn = turned(th, c_node, s_node, fma(h * hh * ci, k2[1], h * k1[0]))
            k4 = _planar_dead_rhs(sig + h, c, sn, m + h * k3[1], fma(h, k3[2], a), fma(h, k3[3], b),
                                  length, ca, cg, ci, ur, vr, nex, ney, qx, qy)
            w = h / 6.0
            a_node = a
            turn = fma(w * h * ci, k1[1] + k2[1] + k3[1], h * k1[0])
            c_node, s_node = turned(th, c_node, s_node, turn)
            th += turn
            m = fma(w, k1[1] + fma(2.0, k2[1] + k3[1], k4[1]), m)
            a = fma(w, k1[2] + fma(2.0, k2[2] + k3[2], k4[2]), a)
            b = fma(w, k1[3] + fma(2.0, k2[3] + k3[3], k4[3]), b)
            x = fma(w, k1[4] + fma(2.0, k2[4] + k3[4], k4[4]), x)
            y = fma(w, k1[5] + fma(2.0, k2[5] + k3[5], k4[5]), y)
            ax = fma(w, k1[8] + fma(2.0, k2[8] + k3[8], k4[8]), ax)
            ay = fma(w, k1[9] + fma(2.0, k2[9] + k3[9], k4[9]), ay)
            if second:
                a_half = a_node + hh * k1[2]
                a2_half = a2 + hh * ci * b2
                b2_half = b2 + hh * (k1[6] * a2 + k1[7] * a_node * a_node)
                a2 += h * ci * b2_half
                b2 += h * (k2[6] * a2_half + k2[7] * a_half * a_half)
            if b < bmin:
                bmin = b
        s0 += length
    return th, m, b, x, y, bmin, b2, a, ax, ay


@njit
def forget_first_variations(out):
    """NaN in the first-variation columns (``D_THETA`` …) of a record ``out`` (N, N_COLUMNS)
    that is kept: they served the pass that wrote them (:func:`shift_planar_record`), and a
    kept record must not look as if they described its state (docs/design.md §8)."""
    out[:, D_THETA:] = math.nan


@njit
def shift_planar_record(out, dm0, secf, steps):
    """Move a pass's record (:func:`integrate_planar`) from base moment m0 to m0 + ``dm0`` to
    first order: every sample along its recorded first variations (θ, m, x, y, v1, v3, and
    u = u* + m/EI with m), the internal force unchanged (dead loads). The error is second
    order, ½·|∂²/∂m0²|·dm0², against the pass from m0 + dm0 itself.

    Args:
        out: (Σ(steps + 1), N_COLUMNS) the record, changed in place. dm0: the shift (N m).
        secf: (6, ns). steps: (ns,).
    """
    row = 0
    for i in range(secf.shape[1]):
        ci = secf[CI, i]
        for _ in range(steps[i] + 1):
            # Fused as the tip values the pass returns are, so the tip row is theirs bit for bit.
            out[row, THETA] = fma(dm0, out[row, D_THETA], out[row, THETA])
            out[row, M] = fma(dm0, out[row, D_M], out[row, M])
            out[row, X] = fma(dm0, out[row, D_X], out[row, X])
            out[row, Y] = fma(dm0, out[row, D_Y], out[row, Y])
            out[row, V1] = fma(dm0, out[row, D_V1], out[row, V1])
            out[row, V3] = fma(dm0, out[row, D_V3], out[row, V3])
            out[row, U] = fma(ci * dm0, out[row, D_M], out[row, U])
            row += 1


@njit
def planar_rest_gradient(record, secf, steps, rest, grad):
    """How the base moment of a planar dead-load equilibrium moves with the rest strains:
    ∂m0/∂u*_i and ∂m0/∂v*_i with the tip condition m(L) = M_tip held (the predictor of a warm
    step to new pressures).

    The linearised statics y = (δθ, δm), δθ' = δm/EI + δu*, δm' = K·δθ − n1·δv* (K = ∂m'/∂θ,
    as in :func:`integrate_planar`), discretised by Heun's rule on the recorded nodes (second
    order, plenty for a prediction that Newton then corrects), map each step's y_j to
    y_{j+1} = M_j·y_j + F_j·(δu*, δv*). Only δm(L) matters, so the sensitivities of all 2·ns + 1
    parameters come from one adjoint sweep tip → base, λ_j = M_jᵀ·λ_{j+1} from λ = (0, 1) at
    the tip: ∂m(L)/∂m0 = λ_0[1] and ∂m(L)/∂(u*_i, v*_i) = Σ_j λ_{j+1}·F_j over section i's
    steps — the discrete adjoint of the forward sensitivities, equal to them to rounding
    (``tests/solver/naive.py``) at a fraction of their cost.

    Args:
        record: (Σ(steps + 1), N_COLUMNS) the equilibrium's record (:func:`integrate_planar`).
        secf: (6, ns) section array. steps: (ns,). rest: (3, ns) its rest strains.
        grad: (2, ns) written: rows ∂m0/∂u* (N m²), ∂m0/∂v* (N m).
    """
    ns = secf.shape[1]
    lam_a = 0.0
    lam_b = 1.0
    end = record.shape[0]
    for i in range(ns - 1, -1, -1):
        ca = secf[CA, i]
        cg = secf[CG, i]
        ci = secf[CI, i]
        vr = rest[REST_V3, i]
        first = end - steps[i] - 1  # the section's first row
        gu = 0.0
        gv = 0.0
        k1, n1_1 = _stiffness_and_shear(record, end - 1, ca, cg, vr)
        for r in range(end - 2, first - 1, -1):
            h = record[r + 1, S] - record[r, S]
            k0, n1_0 = _stiffness_and_shear(record, r, ca, cg, vr)
            hh = 0.5 * h * h
            # λ_{j+1}·F_j for a unit δu* and δv*; then λ_j = M_jᵀ·λ_{j+1} with
            # M_j = [[1 + h²·K0/(2EI), h/EI], [h·(K0 + K1)/2, 1 + h²·K1/(2EI)]].
            gu += h * lam_a + hh * k1 * lam_b
            gv -= hh * ci * n1_0 * lam_a + 0.5 * h * (n1_0 + n1_1) * lam_b
            lam_a, lam_b = ((1.0 + hh * ci * k0) * lam_a + 0.5 * h * (k0 + k1) * lam_b,
                            h * ci * lam_a + (1.0 + hh * ci * k1) * lam_b)
            k1 = k0
            n1_1 = n1_0
        grad[0, i] = gu
        grad[1, i] = gv
        end = first
    for i in range(ns):
        grad[0, i] = -grad[0, i] / lam_b
        grad[1, i] = -grad[1, i] / lam_b


@njit(inline="always")
def _stiffness_and_shear(record, r, ca, cg, vr):
    """K = ∂m'/∂θ and n1 at recorded row ``r``: n1 and n3 from the recorded strains where
    the section is shearable and extensible (no trigonometry), else from θ and n."""
    if cg > 0.0 and ca > 0.0:
        n1 = record[r, V1] / cg
        n3 = (record[r, V3] - vr) / ca
    else:
        c, sn, n1, n3, v1, v3 = planar_strains(record[r, THETA], record[r, NX], record[r, NY], ca,
                                               cg, vr)
    return (cg - ca) * (n1 * n1 - n3 * n3) + vr * n3, n1


@njit(inline="always")
def planar_state_rates(c, sn, nx, ny, m, ca, cg, ci, ur, vr, qx, qy, fx, fy):
    """Right-hand side (x', y', θ', n_x', n_y', m') of the planar state (x, y, θ, n_x, n_y, m),
    the internal force as state (n' = −q − f), at orientation (cos θ, sin θ) under the
    distributed load q and the contact force f (both per length, N/m)."""
    c, sn, n1, n3, v1, v3 = planar_strains_cs(c, sn, nx, ny, ca, cg, vr)
    # m' = v1·n3 − v3·n1 = n1·((1/GA − 1/EA)·n3 − v*), as the dead-load pass has it.
    return (fma(v3, c, -v1 * sn), fma(v3, sn, v1 * c), fma(m, ci, ur), -qx - fx, -qy - fy,
            n1 * fma(n3, cg - ca, -vr))


@njit(inline="always")
def planar_state_jacobian(c, sn, nx, ny, ca, cg, vr):
    """The non-zero partial derivatives of the planar velocities and m' with respect to θ, n_x
    and n_y at orientation (cos θ, sin θ) (∂n1/∂θ = −n3, ∂n3/∂θ = n1): (∂x'/∂θ, ∂x'/∂n_x,
    ∂x'/∂n_y = ∂y'/∂n_x, ∂y'/∂θ, ∂y'/∂n_y, ∂m'/∂θ, ∂m'/∂n_x, ∂m'/∂n_y)."""
    c, sn, n1, n3, v1, v3 = planar_strains_cs(c, sn, nx, ny, ca, cg, vr)
    xs = fma(v3, c, -v1 * sn)
    ys = fma(v3, sn, v1 * c)
    dm = cg - ca
    return (fma(ca * n1, c, fma(cg * n3, sn, -ys)),
            fma(ca * c, c, cg * sn * sn),
            -dm * sn * c,
            fma(ca * n1, sn, fma(-cg * n3, c, xs)),
            fma(ca * sn, sn, cg * c * c),
            fma(dm, fma(n1, n1, -n3 * n3), vr * n3),
            fma(dm, fma(n1, c, -sn * n3), vr * sn),
            fma(dm, fma(n3, c, n1 * sn), -vr * c))


@njit(inline="always")
def planar_state_rhs(st, out, ca, cg, ci, ur, vr, qx, qy, discs):
    """:func:`planar_state_rates` of the state ``st`` (6,) (x, y, θ, n_x, n_y, m) into ``out``
    (6,), the contact force of the penalty obstacles ``discs`` (k, 4) at (x, y)."""
    fx, fy, pen = contact_force(st[0], st[1], discs)
    rates = planar_state_rates(math.cos(st[2]), math.sin(st[2]), st[3], st[4], st[5], ca, cg, ci,
                               ur, vr, qx, qy, fx, fy)
    for d in range(6):
        out[d] = rates[d]


@njit(inline="always")
def planar_state_rk4(x, y, th, c, sn, nx, ny, m, k1, h, ca, cg, ci, ur, vr, qx, qy, discs):
    """One RK4 step of length ``h`` of the planar state (x, y, θ, n_x, n_y, m) under the
    contact force of ``discs`` (k, 4), from its rates ``k1`` there
    (:func:`planar_state_rates`) and (c, sn) = (cos θ, sin θ).

    Scalars throughout. The stages' cos and sin come from the node's by :func:`turned`, and
    as θ' = u* + m/EI is linear in m, a stage's turn is the node's θ' plus a multiple of the
    stage rates of m before it (as in :func:`integrate_planar`).

    Returns:
        ((x, y, θ, cos θ, sin θ, n_x, n_y, m) at the step's end, the points (x, y, cos θ,
        sin θ, n_x, n_y) of stages 2, 3 and 4 (stage 1 is the start)).
    """
    hh = 0.5 * h
    c2, s2 = turned(th, c, sn, hh * k1[2])
    x2 = fma(hh, k1[0], x)
    y2 = fma(hh, k1[1], y)
    nx2 = fma(hh, k1[3], nx)
    ny2 = fma(hh, k1[4], ny)
    fx, fy, pen = contact_force(x2, y2, discs)
    k2 = planar_state_rates(c2, s2, nx2, ny2, fma(hh, k1[5], m), ca, cg, ci, ur, vr, qx, qy, fx, fy)
    c3, s3 = turned(th, c, sn, fma(hh * hh * ci, k1[5], hh * k1[2]))
    x3 = fma(hh, k2[0], x)
    y3 = fma(hh, k2[1], y)
    nx3 = fma(hh, k2[3], nx)
    ny3 = fma(hh, k2[4], ny)
    fx, fy, pen = contact_force(x3, y3, discs)
    k3 = planar_state_rates(c3, s3, nx3, ny3, fma(hh, k2[5], m), ca, cg, ci, ur, vr, qx, qy, fx, fy)
    c4, s4 = turned(th, c, sn, fma(h * hh * ci, k2[5], h * k1[2]))
    x4 = fma(h, k3[0], x)
    y4 = fma(h, k3[1], y)
    nx4 = fma(h, k3[3], nx)
    ny4 = fma(h, k3[4], ny)
    fx, fy, pen = contact_force(x4, y4, discs)
    k4 = planar_state_rates(c4, s4, nx4, ny4, fma(h, k3[5], m), ca, cg, ci, ur, vr, qx, qy, fx, fy)
    w = h / 6.0
    turn = fma(w * h * ci, k1[5] + k2[5] + k3[5], h * k1[2])
    c_end, s_end = turned(th, c, sn, turn)
    end = (fma(w, k1[0] + fma(2.0, k2[0] + k3[0], k4[0]), x),
           fma(w, k1[1] + fma(2.0, k2[1] + k3[1], k4[1]), y),
           th + turn, c_end, s_end,
           fma(w, k1[3] + fma(2.0, k2[3] + k3[3], k4[3]), nx),
           fma(w, k1[4] + fma(2.0, k2[4] + k3[4], k4[4]), ny),
           fma(w, k1[5] + fma(2.0, k2[5] + k3[5], k4[5]), m))
    return end, ((x2, y2, c2, s2, nx2, ny2), (x3, y3, c3, s3, nx3, ny3), (x4, y4, c4, s4, nx4, ny4))


@njit(inline="always")
def planar_state_rk4_step(st, h, ca, cg, ci, ur, vr, qx, qy, discs):
    """One RK4 step of length ``h`` of the planar state ``st`` (6,) (x, y, θ, n_x, n_y, m),
    in place (:func:`planar_state_rk4`)."""
    c = math.cos(st[2])
    sn = math.sin(st[2])
    fx, fy, pen = contact_force(st[0], st[1], discs)
    k1 = planar_state_rates(c, sn, st[3], st[4], st[5], ca, cg, ci, ur, vr, qx, qy, fx, fy)
    end, stages = planar_state_rk4(st[0], st[1], st[2], c, sn, st[3], st[4], st[5], k1, h, ca, cg,
                                   ci, ur, vr, qx, qy, discs)
    st[0] = end[0]
    st[1] = end[1]
    st[2] = end[2]
    st[3] = end[5]
    st[4] = end[6]
    st[5] = end[7]


# ----------------------------------------------------------------------------- spatial


@njit(inline="always")
def _spatial_strains(r00, r01, r02, r10, r11, r12, r20, r21, r22, n0, n1, n2, m0, m1, m2, ca,
                     cg, ci, cj, u1r, u2r, v3r):
    """The constitutive law in 3D, in scalars: from R (given row by row; its columns are the
    directors d1, d2, d3), the internal force and moment (world frame) and the section's
    compliances and rest strains, the strains in the body frame, v = (cg·n1, cg·n2,
    v3* + ca·n3) and u = (u1* + ci·m1, u2* + ci·m2, cj·m3) with n, m in the body frame;
    returns (v0, v1, v2, u0, u1, u2)."""
    # Body-frame components (Rᵀ n, Rᵀ m).
    nb0 = r00 * n0 + r10 * n1 + r20 * n2
    nb1 = r01 * n0 + r11 * n1 + r21 * n2
    nb2 = r02 * n0 + r12 * n1 + r22 * n2
    mb0 = r00 * m0 + r10 * m1 + r20 * m2
    mb1 = r01 * m0 + r11 * m1 + r21 * m2
    mb2 = r02 * m0 + r12 * m1 + r22 * m2
    return nb0 * cg, nb1 * cg, v3r + nb2 * ca, u1r + mb0 * ci, u2r + mb1 * ci, mb2 * cj


@njit(inline="always")
def _spatial_law(r00, r01, r02, r10, r11, r12, r20, r21, r22, n0, n1, n2, m0, m1, m2, ca, cg,
                 ci, cj, u1r, u2r, v3r):
    """:func:`_spatial_strains`, returning the curvature u (body frame) and the slope
    r' = R v (world frame)."""
    v0, v1, v2, u0, u1, u2 = _spatial_strains(r00, r01, r02, r10, r11, r12, r20, r21, r22, n0,
                                              n1, n2, m0, m1, m2, ca, cg, ci, cj, u1r, u2r, v3r)
    rp0 = r00 * v0 + r01 * v1 + r02 * v2
    rp1 = r10 * v0 + r11 * v1 + r12 * v2
    rp2 = r20 * v0 + r21 * v1 + r22 * v2
    return u0, u1, u2, rp0, rp1, rp2


@njit
def spatial_strains_into(rot, force, mom, rest, seg, ca, cg, ci, cj, strain_v, strain_u):
    """The body-frame strains of a spatial record by :func:`_spatial_strains`.

    Args:
        rot: (N, 3, 3) frames R (columns: the directors). force, mom: (N, 3) internal force and moment
            (N, N m; world frame). rest: (3, ns) rest strains. seg: (N,) section of each sample.
        ca, cg, ci, cj: (ns,) compliances 1/EA, 1/GA, 1/EI, 1/GJ.
        strain_v, strain_u: (N, 3) written: v and u.
    """
    for k in range(rot.shape[0]):
        i = seg[k]
        r = rot[k]
        (strain_v[k, 0], strain_v[k, 1], strain_v[k, 2], strain_u[k, 0], strain_u[k, 1],
         strain_u[k, 2]) = _spatial_strains(
            r[0, 0], r[0, 1], r[0, 2], r[1, 0], r[1, 1], r[1, 2], r[2, 0], r[2, 1], r[2, 2],
            force[k, 0], force[k, 1], force[k, 2], mom[k, 0], mom[k, 1], mom[k, 2], ca[i],
            cg[i], ci[i], cj[i], rest[REST_U1, i], rest[REST_U2, i], rest[REST_V3, i])


@njit(inline="always")
def spatial_rhs(sig, y, dy, length, ca, cg, ci, cj, u1r, u2r, v3r, loads_i):
    """Derivative of the spatial state (r, β, m, δφ, δm; ``SP_*``) at local coordinate
    ``sig`` into ``dy`` (NSTATE,). ``loads_i`` (6,): n_end and q of the section (``SL_*``).
    Written out in scalars: it runs 4× per RK4 step and must not allocate."""
    w, x, yy, z = unit_quaternion(y)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_rows(w, x, yy, z)
    rest = length - sig
    n0 = loads_i[SL_N] + loads_i[SL_Q] * rest
    n1 = loads_i[SL_N + 1] + loads_i[SL_Q + 1] * rest
    n2 = loads_i[SL_N + 2] + loads_i[SL_Q + 2] * rest
    m0 = y[SP_M]
    m1 = y[SP_M + 1]
    m2 = y[SP_M + 2]
    u0, u1, u2, rp0, rp1, rp2 = _spatial_law(r00, r01, r02, r10, r11, r12, r20, r21, r22,
                                             n0, n1, n2, m0, m1, m2, ca, cg, ci, cj, u1r, u2r, v3r)
    dy[SP_R] = rp0
    dy[SP_R + 1] = rp1
    dy[SP_R + 2] = rp2
    dy[SP_Q] = 0.5 * (-x * u0 - yy * u1 - z * u2)
    dy[SP_Q + 1] = 0.5 * (w * u0 - z * u1 + yy * u2)
    dy[SP_Q + 2] = 0.5 * (z * u0 + w * u1 - x * u2)
    dy[SP_Q + 3] = 0.5 * (-yy * u0 + x * u1 + w * u2)
    # m' = −r' × n
    dy[SP_M] = -(rp1 * n2 - rp2 * n1)
    dy[SP_M + 1] = -(rp2 * n0 - rp0 * n2)
    dy[SP_M + 2] = -(rp0 * n1 - rp1 * n0)
    for j in range(3):
        p0 = y[SP_DPHI + 3 * j]
        p1 = y[SP_DPHI + 3 * j + 1]
        p2 = y[SP_DPHI + 3 * j + 2]
        a0 = y[SP_DM + 3 * j] + (m1 * p2 - m2 * p1)
        a1 = y[SP_DM + 3 * j + 1] + (m2 * p0 - m0 * p2)
        a2 = y[SP_DM + 3 * j + 2] + (m0 * p1 - m1 * p0)
        da = (cj - ci) * (r02 * a0 + r12 * a1 + r22 * a2)
        dy[SP_DPHI + 3 * j] = ci * a0 + da * r02
        dy[SP_DPHI + 3 * j + 1] = ci * a1 + da * r12
        dy[SP_DPHI + 3 * j + 2] = ci * a2 + da * r22
        # δr' = δφ × r' − P (δφ × n)
        pn0 = p1 * n2 - p2 * n1
        pn1 = p2 * n0 - p0 * n2
        pn2 = p0 * n1 - p1 * n0
        dp = (ca - cg) * (r02 * pn0 + r12 * pn1 + r22 * pn2)
        d0 = (p1 * rp2 - p2 * rp1) - (cg * pn0 + dp * r02)
        d1 = (p2 * rp0 - p0 * rp2) - (cg * pn1 + dp * r12)
        d2 = (p0 * rp1 - p1 * rp0) - (cg * pn2 + dp * r22)
        dy[SP_DM + 3 * j] = -(d1 * n2 - d2 * n1)
        dy[SP_DM + 3 * j + 1] = -(d2 * n0 - d0 * n2)
        dy[SP_DM + 3 * j + 2] = -(d0 * n1 - d1 * n0)


@njit(inline="always")
def spatial_rk4_step(y, sig, h, work, length, ca, cg, ci, cj, u1r, u2r, v3r, loads_i):
    """One RK4 step of length ``h`` (negative: towards the base) of the spatial state ``y``
    in place, the quaternion renormalised; ``work`` (≥5, NSTATE) rows k1..k4 and a stage."""
    k1 = work[1]
    k2 = work[2]
    k3 = work[3]
    k4 = work[4]
    tmp = work[5]
    spatial_rhs(sig, y, k1, length, ca, cg, ci, cj, u1r, u2r, v3r, loads_i)
    for d in range(NSTATE):
        tmp[d] = y[d] + 0.5 * h * k1[d]
    spatial_rhs(sig + 0.5 * h, tmp, k2, length, ca, cg, ci, cj, u1r, u2r, v3r, loads_i)
    for d in range(NSTATE):
        tmp[d] = y[d] + 0.5 * h * k2[d]
    spatial_rhs(sig + 0.5 * h, tmp, k3, length, ca, cg, ci, cj, u1r, u2r, v3r, loads_i)
    for d in range(NSTATE):
        tmp[d] = y[d] + h * k3[d]
    spatial_rhs(sig + h, tmp, k4, length, ca, cg, ci, cj, u1r, u2r, v3r, loads_i)
    for d in range(NSTATE):
        y[d] += (h / 6.0) * (k1[d] + 2.0 * k2[d] + 2.0 * k3[d] + k4[d])
    renormalise_quaternion(y)


@njit(inline="always")
def spatial_state_rhs(y, dy, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles):
    """Derivative of the spatial contact state (r, β, n, m; ``CS_*``) into ``dy``
    (N_CSTATE,): the law of :func:`spatial_rhs` with the internal force as state,
    n' = −q − f_contact (``q`` (3,) the section's load per length, N/m; ``obstacles``
    (k, 8) spatial penalty obstacles, :func:`solver.kernels.obstacles.contact_force_3d`)."""
    w, x, yy, z = unit_quaternion(y)  # the quaternion sits at CS_Q == SP_Q
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_rows(w, x, yy, z)
    n0 = y[CS_N]
    n1 = y[CS_N + 1]
    n2 = y[CS_N + 2]
    m0 = y[CS_M]
    m1 = y[CS_M + 1]
    m2 = y[CS_M + 2]
    u0, u1, u2, rp0, rp1, rp2 = _spatial_law(r00, r01, r02, r10, r11, r12, r20, r21, r22,
                                             n0, n1, n2, m0, m1, m2, ca, cg, ci, cj, u1r, u2r, v3r)
    fx, fy, fz, _ = contact_force_3d(y[CS_R], y[CS_R + 1], y[CS_R + 2], obstacles)
    dy[CS_R] = rp0
    dy[CS_R + 1] = rp1
    dy[CS_R + 2] = rp2
    dy[CS_Q] = 0.5 * (-x * u0 - yy * u1 - z * u2)
    dy[CS_Q + 1] = 0.5 * (w * u0 - z * u1 + yy * u2)
    dy[CS_Q + 2] = 0.5 * (z * u0 + w * u1 - x * u2)
    dy[CS_Q + 3] = 0.5 * (-yy * u0 + x * u1 + w * u2)
    dy[CS_N] = -q[0] - fx
    dy[CS_N + 1] = -q[1] - fy
    dy[CS_N + 2] = -q[2] - fz
    dy[CS_M] = -(rp1 * n2 - rp2 * n1)
    dy[CS_M + 1] = -(rp2 * n0 - rp0 * n2)
    dy[CS_M + 2] = -(rp0 * n1 - rp1 * n0)


@njit(inline="always")
def spatial_state_rk4_step(y, h, work, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles):
    """One RK4 step of length ``h`` of the spatial contact state ``y`` (N_CSTATE,) in place
    (:func:`spatial_state_rhs`), the quaternion renormalised; ``work`` (≥5, N_CSTATE)."""
    k1 = work[0]
    k2 = work[1]
    k3 = work[2]
    k4 = work[3]
    tmp = work[4]
    spatial_state_rhs(y, k1, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    for d in range(N_CSTATE):
        tmp[d] = y[d] + 0.5 * h * k1[d]
    spatial_state_rhs(tmp, k2, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    for d in range(N_CSTATE):
        tmp[d] = y[d] + 0.5 * h * k2[d]
    spatial_state_rhs(tmp, k3, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    for d in range(N_CSTATE):
        tmp[d] = y[d] + h * k3[d]
    spatial_state_rhs(tmp, k4, ca, cg, ci, cj, u1r, u2r, v3r, q, obstacles)
    for d in range(N_CSTATE):
        y[d] += (h / 6.0) * (k1[d] + 2.0 * k2[d] + 2.0 * k3[d] + k4[d])
    renormalise_quaternion(y)


@njit(inline="always")
def start_spatial_state(y, quat0, m0):
    """The spatial state ``y`` (NSTATE,) at the base: orientation ``quat0`` (4,), moment
    ``m0`` (3,) (N m, world); position and the sensitivities zero."""
    for d in range(NSTATE):
        y[d] = 0.0
    for d in range(4):
        y[SP_Q + d] = quat0[d]
    for d in range(3):
        y[SP_M + d] = m0[d]


@njit
def integrate_spatial(m0, quat0, secf, steps, c_j, rest, loads, record, out_pos, out_rot, out_m,
                      work):
    """One RK4 pass base → tip from base moment ``m0`` (3,), with the sensitivities to m0.

    Args:
        quat0: (4,) base orientation quaternion. secf: (6, ns) section array; c_j: (ns,)
            1/GJ. rest: (3, ns) rest strains. loads: (ns, 6) dead loads (``SL_*``).
        record: write positions (N, 3), frames (N, 3, 3) and moments (N, 3) to ``out_pos``,
            ``out_rot``, ``out_m`` (junctions repeated).
        work: (6, NSTATE) scratch; ``work[0]`` holds the tip state on return.

    Returns:
        det ∂m(L)/∂m0.
    """
    y = work[0]
    start_spatial_state(y, quat0, m0)
    for d in range(3):
        y[SP_DM + 4 * d] = 1.0  # δm(0) = identity columns
    row = 0
    for i in range(secf.shape[1]):
        length = secf[LEN, i]
        nst = steps[i]
        h = length / nst
        for j in range(nst + 1):
            if record:
                record_spatial_row(y, out_pos, out_rot, out_m, row)
                row += 1
            if j == nst:
                break
            spatial_rk4_step(y, j * h, h, work, length, secf[CA, i], secf[CG, i], secf[CI, i],
                             c_j[i], rest[REST_U1, i], rest[REST_U2, i], rest[REST_V3, i], loads[i])
    return det3(y[SP_DM:SP_DM + 9])


@njit
def record_spatial_row(y, out_pos, out_rot, out_m, row):
    """Write the position, directors (columns d1 d2 d3) and moment of the spatial state
    ``y`` into row ``row`` of ``out_pos`` (N, 3), ``out_rot`` (N, 3, 3) and ``out_m``
    (N, 3)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_rows(*unit_quaternion(y))
    out_rot[row, 0, 0] = r00
    out_rot[row, 0, 1] = r01
    out_rot[row, 0, 2] = r02
    out_rot[row, 1, 0] = r10
    out_rot[row, 1, 1] = r11
    out_rot[row, 1, 2] = r12
    out_rot[row, 2, 0] = r20
    out_rot[row, 2, 1] = r21
    out_rot[row, 2, 2] = r22
    for d in range(3):
        out_pos[row, d] = y[SP_R + d]
        out_m[row, d] = y[SP_M + d]


# ----------------------------------------------------------------------------- arcs



@njit(inline="always")
def _chord_factors(phi):
    """(sin φ/φ, (1 − cos φ)/φ) of an arc turning by φ (rad): its chord along and across the
    start tangent per unit length; the Taylor forms below 1e-9 rad."""
    if abs(phi) < 1e-9:
        return 1.0 - phi * phi / 6.0, phi / 2.0
    return math.sin(phi) / phi, (1.0 - math.cos(phi)) / phi

@njit
def _arc_point(x, y, th, kappa, stretch, sig):
    """Planar pose (x, y, θ) after ``sig`` of reference arc length along an arc of curvature
    κ (per reference length) and stretch v from (x, y, θ)."""
    dth = kappa * sig
    c, d = _chord_factors(dth)
    ell = stretch * sig
    ct = math.cos(th)
    st = math.sin(th)
    # Chord in the local frame (along d3, along the bending normal), rotated to the world.
    return x + ell * (c * ct - d * st), y + ell * (c * st + d * ct), th + dth


@njit
def arc_chain_planar(theta0, sec_len, curvature, stretch, s_query, backbone, angles, ends):
    """Planar chain of circular arcs (each section: constant curvature and stretch, no
    shear): the closed-form shape of an unloaded arm, or of the constant-curvature model.

    Args:
        theta0: base orientation θ0 (rad).
        sec_len: (ns,) reference lengths (m). curvature: (ns,) dθ/ds per reference length
            (rad/m). stretch: (ns,) axial stretch v3.
        s_query: (K,) non-decreasing reference arc lengths in [0, L] (m); a repeated value
            at a junction belongs to the section that ends there.
        backbone: (K, 2) written: positions (m). angles: (K,) written: θ (rad), or empty.
        ends: (ns, 3) written: (x, y, θ) at each section end.
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
            px, py, pth = _arc_point(x, y, th, curvature[i], stretch[i], s_query[k] - s0)
            backbone[k, 0] = px
            backbone[k, 1] = py
            if angles.shape[0] > 0:
                angles[k] = pth
            k += 1
        x, y, th = _arc_point(x, y, th, curvature[i], stretch[i], sec_len[i])
        ends[i, 0] = x
        ends[i, 1] = y
        ends[i, 2] = th
        s0 += sec_len[i]


@njit
def _arc_relative(k0, k1, kappa, stretch, sig, rel_pos, rel_rot):
    """Pose after ``sig`` along an arc of body curvature κ·(k0, k1, 0), no shear or torsion.

    Rodrigues: R = I + sin φ·K + (1 − cos φ)·K², K = [k]×, φ = κσ; and
    r = v·∫₀^σ R e3 = v·σ·((1 − cos φ)/φ·(k1, −k0, 0) + (sin φ/φ)·e3). Writes rel_pos (3,),
    rel_rot (3, 3).
    """
    phi = kappa * sig
    a, b = _chord_factors(phi)
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
def arc_chain_spatial(rot0, sec_len, curvature, stretch, s_query, work, backbone, frames_at,
                      ends, frames):
    """Spatial chain of arcs (constant body curvature (u1, u2, 0) and stretch per section).

    Args:
        rot0: (3, 3) base directors. sec_len, stretch: (ns,). curvature: (ns, 2) (u1, u2)
            (rad/m).
        s_query: (K,) non-decreasing reference arc lengths in [0, L] (m) (repeated
            junction values belong to the section that ends there).
        work: (4, 3, 3) scratch.
        backbone: (K, 3) written. frames_at: (K, 3, 3) written directors at the queries, or
            empty. ends: (ns, 3) and frames: (ns, 3, 3) written at the section ends.
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
            if frames_at.shape[0] > 0:
                for r in range(3):
                    for c in range(3):
                        frames_at[k, r, c] = (rot[r, 0] * rel_rot[0, c] + rot[r, 1] * rel_rot[1, c]
                                              + rot[r, 2] * rel_rot[2, c])
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


# ----------------------------------------------------------------------------- resampling


@njit
def hermite_resample(s, pos, tangent, s_query, out):
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
