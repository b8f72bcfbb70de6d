"""Kernels of :mod:`solver.rod` against the library functions they stand in for."""

import math

import numba
import numpy as np

from solver import rod


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
