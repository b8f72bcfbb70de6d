"""Shared pieces of the path-following kernels: what a ramp between two load cases is."""

from __future__ import annotations

import math

from solver.actuator import pressure_and_slope, tube_stretch
from solver.jit import njit
from solver.layout import DT_MIN, T_CHANNEL, TF_AREA_RATIO, TF_COS_ALPHA, TF_E

# A continuation step accepts a root at most ``jump`` from its prediction; Newton gives up on
# the step once an iterate would leave GIVE_UP·jump of it (the ``reach`` of the planar and
# spatial Newton): past a fold there is no root near the prediction, and Newton would spend
# its whole budget looking. Twice the acceptance radius leaves room for a first step that
# overshoots and comes back.
GIVE_UP = 2.0


@njit
def big_change(p_a, p_b, loads_a, loads_b):
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


@njit
def ramp_crowding(p_a, p_b, tubes_i, tubes_f):
    """How much faster than on average the rest strains change where a pressure ramp from
    ``p_a`` to ``p_b`` (channel pressures, Pa) changes them fastest (>= 1).

    The rest strains are linear in each tube's stretch λ, and λ(p) is far from linear: the
    braid stiffens towards lock-up, so near it most of a 0 → p_max ramp's curvature appears
    in its first 1/256. Per tube the ratio is the largest dλ/dp over the ramp (the smallest
    dp/dλ, closed form, on 17 stretches spanning it) times the pressure change, over the
    stretch change. The path-following kernels divide their smallest step by it, so that
    the smallest step is a fixed share of the strain change, not of the pressure change.
    """
    crowding = 1.0
    for k in range(tubes_i.shape[0]):
        c = tubes_i[k, T_CHANNEL]
        lo, hi = min(p_a[c], p_b[c]), max(p_a[c], p_b[c])
        if not hi > lo:
            continue
        e, ratio, cos_alpha = tubes_f[k, TF_E], tubes_f[k, TF_AREA_RATIO], tubes_f[k, TF_COS_ALPHA]
        lam_lo = tube_stretch(lo, e, ratio, cos_alpha)
        change = tube_stretch(hi, e, ratio, cos_alpha) - lam_lo
        if not change > 0.0:
            continue
        slope = math.inf
        for j in range(_SLOPE_SAMPLES):
            lam = lam_lo + change * j / (_SLOPE_SAMPLES - 1)
            slope = min(slope, pressure_and_slope(lam, e, ratio, cos_alpha)[1])
        if slope > 0.0 and math.isfinite(slope):
            crowding = max(crowding, (hi - lo) / (slope * change))
    return crowding


@njit(inline="always")
def halved(dt, tried, dt_min):
    """The next continuation step after a try of length ``tried`` (t_new − t) at the nominal
    step ``dt`` failed: ``dt`` halved — and halved again while it would still reach as far as
    the failed try, never below ``dt_min`` (0: no floor). Near the end of a ramp a try is
    clipped at t = 1 (``tried`` < ``dt``), and a halved nominal step that still reaches past
    it would repeat the same try from the same state, and its failure. The steps tried are
    those halving alone would try, less the repeats."""
    while dt > dt_min:
        dt *= 0.5
        if dt < tried:
            break
    return dt


@njit
def smallest_step(dt, dt_min, params, p_a, p_b, tubes_i, tubes_f):
    """The smallest continuation step of a ramp from ``p_a`` to ``p_b``: ``params[DT_MIN]``
    divided by :func:`ramp_crowding`, worked out only once the step ``dt`` first comes down
    to ``params[DT_MIN]`` (``dt_min`` < 0 until then; larger steps compare the same either
    way), so that a warm step accepted at once does not pay for it."""
    if dt_min < 0.0 and dt <= params[DT_MIN]:
        return params[DT_MIN] / ramp_crowding(p_a, p_b, tubes_i, tubes_f)
    return dt_min


# Stretches at which ramp_crowding samples dp/dλ over a ramp.
_SLOPE_SAMPLES = 17
