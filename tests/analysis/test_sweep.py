"""Pressure grids and chunked sweeps: order, chunking and backends give identical tips."""

import itertools

import numpy as np
import pytest

import solver
from softarm_gym.analysis import PressureGrid, pressure_grid, sweep_tips

ARM = solver.designs.octarm_two_section()
SCENE = solver.Scene(base_angle_deg=45.0)


def test_grid_rows_follow_itertools_product_order():
    grid = pressure_grid(ARM, levels=3)
    expected = np.array(list(itertools.product(np.linspace(0, ARM.max_pressure, 3), repeat=4)))
    assert grid.size == 81
    np.testing.assert_array_equal(grid.rows(), expected)
    np.testing.assert_array_equal(grid.rows(10, 17), expected[10:17])


def test_grid_spans_zero_to_the_requested_maximum():
    grid = pressure_grid(ARM, levels=7, max_pressure=35 * solver.PSI)
    np.testing.assert_allclose(grid.levels / solver.PSI, np.linspace(0, 35, 7))
    assert grid.n_inputs == ARM.n_inputs(True)
    assert pressure_grid(ARM, levels=2, planar=False).n_inputs == ARM.n_channels


@pytest.mark.parametrize("kwargs, message", [
    (dict(levels=1), "levels must be an integer >= 2"),
    (dict(levels=2.5), "levels must be an integer >= 2"),
    (dict(max_pressure=200 * solver.PSI), "exceeds design"),
    (dict(max_pressure=-1.0), "max_pressure must be a finite pressure > 0"),
    (dict(max_pressure=float("nan")), "max_pressure must be a finite pressure > 0"),
])
def test_bad_grids_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        pressure_grid(ARM, **kwargs)


def test_bad_grid_objects_are_rejected():
    with pytest.raises(ValueError, match="ascending"):
        PressureGrid(np.array([0.0, 2.0, 1.0]), 2)
    with pytest.raises(ValueError, match="outside the grid"):
        PressureGrid(np.array([0.0, 1.0]), 2).rows(0, 5)


def test_sweep_is_independent_of_chunking_and_matches_solve_batch():
    grid = pressure_grid(ARM, levels=3)
    whole, ok_whole = solver.solve_batch(ARM, grid.rows(), SCENE)
    chunked, ok_chunked = sweep_tips(ARM, grid, SCENE, chunk_size=7)
    np.testing.assert_array_equal(chunked, whole)
    np.testing.assert_array_equal(ok_chunked, ok_whole)
    assert ok_whole.all()


def test_sweep_rejects_bad_options():
    grid = pressure_grid(ARM, levels=2)
    with pytest.raises(ValueError, match="unknown backend"):
        sweep_tips(ARM, grid, SCENE, backend="dask")
    with pytest.raises(ValueError, match="chunk_size"):
        sweep_tips(ARM, grid, SCENE, chunk_size=0)
    with pytest.raises(ValueError, match="backend is 'local'"):
        sweep_tips(ARM, grid, SCENE, address="auto")
    with pytest.raises(ValueError, match="unknown model"):
        sweep_tips(ARM, grid, SCENE, model="rigid")
    with pytest.raises(ValueError, match="PressureGrid"):
        sweep_tips(ARM, grid.rows(), SCENE)
    with pytest.raises(ValueError, match="ArmDesign"):
        pressure_grid("octarm_v")
