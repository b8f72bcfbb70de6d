"""The fold scan (``solver.kernels.planar.fold_scan``) visits its grid nearest the guess first and stops
early; it must pick the root a scan of every interval picks (``naive.py``). Newton gives up
on a continuation step whose iterate leaves its ``reach``, and its last correction, applied
through the pass's first variations, is the pass it saves."""

import math

import numpy as np
import pytest

import solver
from solver import layout as L
from solver.kernels import planar as planar_kernels
from solver.rod import integrate_planar
from tests.solver import naive
from tests.solver.planar_case import planar_case, planar_grid


@pytest.mark.parametrize("design, payload, angle, fraction", [
    ("octarm_v", 0.5, 180.0, 0.0),   # an upright column past buckling: two mirror roots
    ("octarm_v", 1.0, 180.0, 0.3),
    ("ct", 0.3, 180.0, 0.0),
    ("octarm_v", 0.2, 150.0, 0.5),   # leaning: two roots at different distances
    ("octarm_v", 0.0, 90.0, 0.4),    # one root
])
def test_scan_picks_the_nearest_stable_root_of_the_full_scan(design, payload, angle, fraction):
    arm, scene, packed, ctx = planar_case(design, payload, angle)
    grid = planar_grid(arm, scene, packed, ctx, np.full(arm.n_channels, fraction * arm.max_pressure))
    out = np.empty((packed.n_rows, L.N_COLUMNS))

    def residual(m0):
        return integrate_planar(m0, *grid, False, out, False)[1] - ctx.m_tip

    def stable(m0):
        return integrate_planar(m0, *grid, False, out, False)[5] > 0.0

    bound = ctx.params[L.M_BOUND]
    n_scan = solver.Settings().n_scan
    _, roots = naive.nearest_stable_root_full_scan(residual, stable, bound, n_scan, 0.0)
    # Guesses across the grid and beyond it, and a third and two thirds of the way between
    # neighbouring roots, where the nearer one is on either side.
    guesses = [*np.linspace(-1.1 * bound, 1.1 * bound, 9), 0.0, -0.0, 1e-9 * bound]
    for a, b in zip(roots[:-1], roots[1:]):
        guesses += [a + (b - a) / 3, a + 2 * (b - a) / 3]
    passes = []
    for guess in guesses:
        expected, roots = naive.nearest_stable_root_full_scan(residual, stable, bound, n_scan, guess)
        root, found, its = planar_kernels.fold_scan(*grid, ctx.m_tip, ctx.params, n_scan, guess, out)
        assert found == math.isfinite(expected), (guess, roots)
        if found:
            assert root == pytest.approx(expected, abs=1e-9 * bound), (guess, roots)
        passes.append(its)
    # Stopping early is the point: a full scan evaluates n_scan + 1 grid points alone.
    assert min(passes) < n_scan / 2, passes


def test_newton_gives_up_once_an_iterate_would_leave_its_reach():
    arm, scene, packed, ctx = planar_case("octarm_v", 0.0, 90.0)
    out = np.empty((packed.n_rows, L.N_COLUMNS))
    args = (*planar_grid(arm, scene, packed, ctx, np.full(arm.n_channels, 0.5 * arm.max_pressure)),
            ctx.m_tip, ctx.params[L.TOL], 12, ctx.params[L.MAX_STEP], out, False)
    root, ok, its, *_ = planar_kernels.newton(0.0, *args)
    assert ok and abs(root) > 0.0
    # A reach short of the root: the first step would leave it, so one pass and no more.
    gave_up, ok, its, *_ = planar_kernels.newton(0.0, *args, 0.5 * abs(root))
    assert not ok and its == 0 and gave_up == 0.0
    # A reach past the root changes nothing.
    same, ok, *_ = planar_kernels.newton(0.0, *args, 2.0 * abs(root))
    assert ok and same == root


@pytest.mark.parametrize("design, payload, angle", [
    ("octarm_v", 0.1, 90.0), ("ct", 0.3, 90.0), ("octarm_v", 0.0, 135.0)])
def test_newton_finishing_through_first_variations_is_a_pass_there(design, payload, angle):
    """Where Newton's last correction is tiny, ``newton`` returns the last pass moved along its
    first variations (no further pass): a pass from the returned moment meets the tolerance,
    gives the returned tip and record to far below the tolerance."""
    arm, scene, packed, ctx = planar_case(design, payload, angle)
    tol = ctx.params[L.TOL]
    rng = np.random.default_rng(7)
    finished = 0
    for fraction in rng.uniform(0.0, 1.0, (12, arm.n_channels)):
        grid = planar_grid(arm, scene, packed, ctx, fraction * arm.max_pressure)
        out = np.empty((packed.n_rows, L.N_COLUMNS))
        args = (*grid, ctx.m_tip, tol, 12, ctx.params[L.MAX_STEP], out, True)
        root, ok, *_ = planar_kernels.newton(0.0, *args)
        if not ok:  # plain Newton from zero does not reach every state; the others do
            continue
        # Start a small step off the root: the first correction is tiny.
        for offset in (30.0, -300.0, 3000.0):
            m0, ok, its, res, stable, _, x, y, th = planar_kernels.newton(root + offset * tol, *args)
            fresh = np.empty_like(out)
            th_p, m_p, _, x_p, y_p, *_ = integrate_planar(m0, *grid, True, fresh, False)
            assert ok and abs(m_p - ctx.m_tip) <= tol
            assert max(abs(x - x_p), abs(y - y_p), abs(th - th_p)) <= 1e-12  # m, rad
            assert np.isnan(out[:, L.D_THETA:]).all()  # the scratch the finish used is forgotten
            off = np.abs(out - fresh)[:, :L.D_THETA].max(axis=0)
            assert off[L.M] <= 1e-3 * tol and off[L.U] <= 1e-3 * tol * packed.secf[L.CI].max()
            assert off[[L.X, L.Y, L.THETA, L.V1, L.V3]].max() <= 1e-12
            # A pass's own residual would be the fresh pass's, bit for bit.
            finished += res != abs(m_p - ctx.m_tip)
    assert finished >= 10
