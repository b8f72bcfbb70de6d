"""Kernels of :mod:`solver.rod` against the library functions they stand in for."""

import math

import numba
import numpy as np
import pytest

from solver import layout as L
from solver import rod
from tests.solver.planar_case import planar_case, planar_grid


def test_turned_is_cos_and_sin_of_the_sum_to_rounding():
    """The Taylor polynomials (Estrin's evaluation) of a small turn, below and up to
    ``SMALL_TURN``, and libm above it, give cos and sin of θ + δ to a few units of rounding."""
    rng = np.random.default_rng(3)
    theta = rng.uniform(-4.0, 4.0, 2000)
    turn = np.concatenate([rng.uniform(-rod.SMALL_TURN, rod.SMALL_TURN, 1000),
                           rng.uniform(-1e-3, 1e-3, 500), rng.uniform(-2.0, 2.0, 496),
                           [0.0, rod.SMALL_TURN, -rod.SMALL_TURN, 1e-300]])
    worst = 0.0
    for th, d in zip(theta, turn):
        c, s = rod.turned(th, math.cos(th), math.sin(th), d)
        worst = max(worst, abs(c - math.cos(th + d)), abs(s - math.sin(th + d)))
    assert worst < 8 * np.finfo(float).eps


def test_fma_rounds_once():
    """(1 + 2⁻³⁰)(1 − 2⁻³⁰) − 1 = −2⁻⁶⁰ exactly; multiplying first rounds the product to 1."""
    fused = numba.njit(lambda a, b, c: rod.fma(a, b, c))
    a, b = 1.0 + 2.0**-30, 1.0 - 2.0**-30
    assert a * b - 1.0 == 0.0
    assert fused(a, b, -1.0) == -(2.0**-60)


@pytest.mark.parametrize("design, payload, angle, fraction", [
    ("octarm_v", 0.1, 90.0, 0.4),
    ("ct", 0.3, 180.0, 0.2),
    ("octarm_v", 0.0, 135.0, 0.8),
])
def test_a_shifted_record_is_the_pass_from_the_shifted_moment(design, payload, angle, fraction):
    """``shift_planar_record`` moves a record along its first variations. Against passes of
    their own: the change it makes is the central difference up to that difference's own
    third-order error (a tenth of the shift, a thousandth of the gap), and what it misses of
    the pass from the shifted moment is second order (a tenth of the shift, a hundredth)."""
    arm, scene, packed, ctx = planar_case(design, payload, angle)
    grid = planar_grid(arm, scene, packed, ctx, np.full(arm.n_channels, fraction * arm.max_pressure))

    def record(m0):
        out = np.empty((packed.n_rows, L.N_COLUMNS))
        rod.integrate_planar(m0, *grid, True, out, False)
        return out

    moved = [L.X, L.Y, L.THETA, L.M, L.V1, L.V3, L.U]
    m0 = 0.3 * ctx.params[L.M_BOUND]
    base = record(m0)
    gap, missed = [], []
    for fraction_of_bound in (1e-4, 1e-5):
        dm = fraction_of_bound * ctx.params[L.M_BOUND]
        shifted = base.copy()
        rod.shift_planar_record(shifted, dm, packed.secf, packed.sec_steps)
        assert np.array_equal(shifted[:, [L.S, L.NX, L.NY]], base[:, [L.S, L.NX, L.NY]])
        central = 0.5 * (record(m0 + dm) - record(m0 - dm))
        gap.append(np.abs(shifted - base - central)[:, moved].max(axis=0))
        missed.append(np.abs(shifted - record(m0 + dm))[:, moved].max(axis=0))
        scale = np.abs(central[:, moved]).max(axis=0)
    assert np.all(gap[1] <= 1e-7 * scale), gap[1] / scale
    for (large, small), order in ((gap, 3), (missed, 2)):
        ratio = large / small
        assert np.all((ratio > 10**order / 2) & (ratio < 2 * 10**order)), (order, ratio)
