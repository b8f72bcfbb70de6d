"""Rod equations shared by every solver kernel: section arrays and rest strains.

The pressurised tubes impose rest strains on each section (DESIGN, "Actuation as rest
strains"); every kernel, planar, spatial or with contact, starts from them.
"""

from __future__ import annotations

from solver._jit import njit
from solver.actuator import _stretch

# Rows of the section array ``secf`` (6, ns): length, 1/EA, 1/GA (0: unshearable), 1/EI, EA, EI.
LEN, CA, CG, CI, EA, EI = range(6)
# Entries of the numeric parameter array ``params`` of the path-following kernels.
TOL, MAX_STEP, M_BOUND, DT0, DT_MIN, MAX_ITER, N_SCAN, JUMP = range(8)
N_PARAMS = 8


@njit
def _rest_strains(p_channel, tubes_i, tubes_f, secf, rest):
    """Rest curvature and stretch of every section from channel pressures (DESIGN §2).

    Each tube k carries F_k = E·At·(λ_k − 1) (Eq. 2.11) at offset (a_k, b_k) along (d1, d2)
    in every section it spans, giving v3* = 1 + ΣF/EA, u1* = ΣF·b/EI, u2* = −ΣF·a/EI: the
    geometric form of Eqs. (2.47)–(2.53) and (2.62)–(2.64).

    Args:
        p_channel: (n_channels,) pressures (Pa).
        tubes_i: (n_tubes, 3) int: channel, first section, last section.
        tubes_f: (n_tubes, 6): E·At (N), E (Pa), At/A, cos α, offset a along d1, b along d2 (m).
        secf: (6, ns) section array (rows LEN, CA, CG, CI, EA, EI).
        rest: (3, ns) output rows u1* (rad/m), u2* (rad/m), v3*.
    """
    ns = secf.shape[1]
    for i in range(ns):
        rest[0, i] = 0.0
        rest[1, i] = 0.0
        rest[2, i] = 0.0
    for k in range(tubes_i.shape[0]):
        lam = _stretch(p_channel[tubes_i[k, 0]], tubes_f[k, 1], tubes_f[k, 2], tubes_f[k, 3])
        f = tubes_f[k, 0] * (lam - 1.0)
        for i in range(tubes_i[k, 1], tubes_i[k, 2] + 1):
            rest[2, i] += f
            rest[0, i] += f * tubes_f[k, 5]
            rest[1, i] -= f * tubes_f[k, 4]
    for i in range(ns):
        rest[2, i] = 1.0 + rest[2, i] / secf[EA, i]
        rest[0, i] /= secf[EI, i]
        rest[1, i] /= secf[EI, i]


@njit
def _big_change(p_a, p_b, loads_a, loads_b):
    """A ramp worth a tangent predictor: new loads, or a pressure moving by > 5 % of the
    largest. Small warm steps (env steps) are predicted well enough by the start state."""
    scale = 0.0
    for c in range(p_a.shape[0]):
        scale = max(scale, abs(p_a[c]), abs(p_b[c]))
    for c in range(p_a.shape[0]):
        if abs(p_b[c] - p_a[c]) > 0.05 * scale:
            return True
    for i in range(loads_a.shape[0]):
        for d in range(loads_a.shape[1]):
            if loads_a[i, d] != loads_b[i, d]:
                return True
    return False
