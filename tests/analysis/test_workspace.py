"""Workspace statistics: area methods on known shapes, and the physics of the tip cloud."""

import math

import numpy as np
import pytest

import solver
from softarm_gym.analysis import alpha_shape_area, occupancy_area, workspace

ARM = solver.designs.octarm_two_section()


def test_alpha_shape_of_a_lattice_is_its_square():
    x, y = np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 2, 21))
    pts = np.column_stack([x.ravel(), y.ravel()])
    assert alpha_shape_area(pts, alpha=0.1) == pytest.approx(2.0, rel=1e-12)
    # Duplicated points change nothing.
    assert alpha_shape_area(np.vstack([pts, pts]), alpha=0.1) == pytest.approx(2.0, rel=1e-12)


def test_alpha_shape_leaves_holes_larger_than_alpha_open():
    i, j = np.meshgrid(np.arange(21), np.arange(21))
    hole = (np.abs(i - 10) <= 3) & (np.abs(j - 10) <= 3)  # 7×7 lattice points removed
    ring = 0.05 * np.column_stack([i[~hole], j[~hole]]).astype(float)
    # The hole spans 8 cells of 0.05 m (0.4 m square) less a kept half cell at each corner,
    # whose three remaining corners still form a small right triangle.
    expected = 1.0 - (0.4**2 - 4 * 0.5 * 0.05**2)
    assert alpha_shape_area(ring, alpha=0.05) == pytest.approx(expected, rel=1e-12)
    # With alpha far above the hole size the shape is the convex hull.
    assert alpha_shape_area(ring, alpha=10.0) == pytest.approx(1.0, rel=1e-12)


def test_degenerate_point_sets_have_no_area():
    assert alpha_shape_area(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]), 1.0) == 0.0
    assert alpha_shape_area(np.zeros((2, 2)), 1.0) == 0.0


def test_occupancy_counts_cells():
    pts = np.array([[0.001, 0.001], [0.002, 0.009], [0.015, 0.0], [-0.001, 0.0]])
    assert occupancy_area(pts, 0.01) == pytest.approx(3e-4)


@pytest.mark.parametrize("call, message", [
    (lambda: alpha_shape_area(np.zeros((4, 3)), 1.0), r"shape \(n, 2\)"),
    (lambda: alpha_shape_area(np.full((4, 2), np.nan), 1.0), "finite"),
    (lambda: alpha_shape_area(np.zeros((4, 2)), 0.0), "alpha must be"),
    (lambda: occupancy_area(np.zeros((4, 2)), -1.0), "cell must be"),
    (lambda: workspace(ARM, levels=2, alpha=-0.1), "alpha must be"),
    (lambda: workspace("octarm_v", levels=2), "ArmDesign"),
])
def test_bad_input_is_rejected(call, message):
    with pytest.raises(ValueError, match=message):
        call()


@pytest.fixture(scope="module")
def hanging():
    return workspace(ARM, solver.Scene(base_angle_deg=0.0), levels=3)


def test_statistics_describe_the_tip_cloud(hanging):
    ws = hanging
    assert ws.n == 81 and ws.n_failed == 0
    np.testing.assert_allclose(ws.mean_tip, ws.tips.mean(axis=0))
    assert ws.highest_tip[1] == ws.tips[:, 1].max()
    # The unactuated arm hangs straight: its tip (row 0) is at (0, -L·stretch) below the base.
    assert ws.tips[0, 0] == pytest.approx(0.0, abs=1e-12)
    assert -ARM.length * 1.05 < ws.tips[0, 1] < -ARM.length
    # Density integrates to the number of tips; the area methods are ordered as documented.
    dens, xe, ye = ws.density(0.02)
    assert dens.sum() * 2.0**2 == pytest.approx(ws.n)
    assert 0 < ws.occupancy_area(0.01) < ws.hull_area_m2
    assert 0 < ws.area_m2 <= ws.hull_area_m2 + 1e-12
    assert ws.area_fraction == pytest.approx(ws.area_m2 / (math.pi * ARM.length**2))
    summary = ws.summary()
    assert {"n", "mean_tip", "area_m2", "highest_tip", "seconds"} <= set(summary)


def test_gravity_and_payload_lower_the_workspace(hanging):
    """Figs. 2.7-2.8 / Table 2.2: self-weight lowers the mean tip, a payload lowers it more."""
    horizontal = dict(levels=3)
    free = workspace(ARM, solver.Scene(base_angle_deg=90.0, gravity=0.0), **horizontal)
    weight = workspace(ARM, solver.Scene(base_angle_deg=90.0), **horizontal)
    loaded = workspace(ARM, solver.Scene(base_angle_deg=90.0, payload_kg=0.25), **horizontal)
    assert free.mean_tip[1] > weight.mean_tip[1] > loaded.mean_tip[1]
    assert free.highest_tip[1] > weight.highest_tip[1] > loaded.highest_tip[1]
    # Without loads the full model is the constant-curvature model exactly.
    cc = workspace(ARM, solver.Scene(base_angle_deg=90.0, gravity=0.0), model="constant_curvature",
                   **horizontal)
    np.testing.assert_allclose(free.tips, cc.tips, atol=1e-12)


def test_spatial_sweep_with_in_plane_pressures_matches_the_planar_one():
    spatial = workspace(ARM, solver.Scene(base_angle_deg=45.0), levels=2, planar=False)
    assert spatial.tips.shape == (2**6, 3)
    grid = spatial.grid.rows()
    # Rows whose II and III pressures are equal in every section bend in the plane.
    in_plane = (grid[:, 1] == grid[:, 2]) & (grid[:, 4] == grid[:, 5])
    planar_p = grid[in_plane][:, [0, 1, 3, 4]]
    tips, ok = solver.solve_batch(ARM, planar_p, solver.Scene(base_angle_deg=45.0))
    np.testing.assert_allclose(spatial.tips[in_plane, :2], tips, atol=1e-9)
    np.testing.assert_allclose(spatial.tips[in_plane, 2], 0.0, atol=1e-12)
    assert spatial.area_m2 > 0
