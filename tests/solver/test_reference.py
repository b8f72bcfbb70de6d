"""The solver against an independent scipy solve_bvp formulation and a plain RK4 reference."""

import numpy as np
import pytest

import solver
from solver import PSI, designs
from tests.solver import naive

FINE = solver.Settings(steps_per_section=128)

SCENES = [
    ("octarm_v", [30, 0, 30, 0, 30, 0], dict(base_angle_deg=0)),
    ("octarm_v", [0, 60, 20, 0, 80, 10], dict(base_angle_deg=45, payload_kg=0.1)),
    ("octarm_v", [50, 0, 0, 50, 90, 0], dict(base_angle_deg=90, payload_kg=0.25)),
    ("ct", [40, 0, 0, 20], dict(base_angle_deg=90)),
    ("octarm_vi", [0, 70, 70, 0, 20, 0], dict(base_angle_deg=90)),
]


def _channel(arm, planar_psi):
    p = np.zeros(arm.n_channels)
    for value, (_, idx) in zip(planar_psi, arm.planar_channels):
        p[list(idx)] = value * PSI
    return p


@pytest.mark.parametrize("name, psi, scene_kw", SCENES)
def test_agrees_with_solve_bvp(name, psi, scene_kw):
    arm = designs.get(name)
    scene = solver.Scene(**scene_kw)
    eq = solver.solve(arm, np.array(psi) * PSI, scene, settings=FINE)
    assert eq.converged and eq.stable
    tip, angle, _ = naive.solve_bvp_planar(arm, _channel(arm, psi), scene)
    np.testing.assert_allclose(eq.tip, tip, atol=1e-8 * arm.length)
    assert eq.tip_angle == pytest.approx(angle, abs=1e-8)


def test_unshearable_agrees_with_solve_bvp():
    arm = designs.octarm_v()
    psi = [0, 60, 20, 0, 80, 10]
    scene = solver.Scene(base_angle_deg=45)
    eq = solver.solve(arm, np.array(psi) * PSI, scene, model="unshearable", settings=FINE)
    tip, _, _ = naive.solve_bvp_planar(arm, _channel(arm, psi), scene, unshearable=True)
    np.testing.assert_allclose(eq.tip, tip, atol=1e-8)
    full = solver.solve(arm, np.array(psi) * PSI, scene, settings=FINE)
    assert np.linalg.norm(full.tip - eq.tip) > 1e-3  # shear matters for this soft arm


def test_kernel_matches_plain_rk4():
    """The numba RK4 pass equals a plain-Python RK4 of the same ODE from the same m0."""
    arm = designs.octarm_v()
    psi = [20, 0, 0, 40, 60, 0]
    scene = solver.Scene(base_angle_deg=90, payload_kg=0.1)
    steps = 40
    eq = solver.solve(arm, np.array(psi) * PSI, scene,
                      settings=solver.Settings(steps_per_section=steps))
    rest = solver.rest_strains(arm, _channel(arm, psi))
    x, y, theta, m = naive.rk4_planar(arm, rest, scene, eq.base_moment[0], steps)
    np.testing.assert_allclose(eq.tip, [x, y], atol=1e-12)
    assert eq.tip_angle == pytest.approx(theta, abs=1e-12)
    assert m == pytest.approx(0.0, abs=1e-9)


def test_fourth_order_convergence():
    """Tip error falls ~16× per doubling of RK4 steps (observed order ≈ 4)."""
    arm = designs.octarm_v()
    p = np.array([50, 0, 0, 50, 90, 0]) * PSI
    scene = solver.Scene(base_angle_deg=90, payload_kg=0.25)
    ref = solver.solve(arm, p, scene, settings=solver.Settings(steps_per_section=1024)).tip
    steps = [8, 16, 32, 64]
    errors = [np.linalg.norm(solver.solve(arm, p, scene, settings=solver.Settings(
        steps_per_section=n)).tip - ref) for n in steps]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 3.7) and np.all(orders < 4.3), orders


@pytest.mark.parametrize("name, psi, scene_kw", SCENES[:3])
def test_spatial_kernel_agrees_with_planar(name, psi, scene_kw):
    """The spatial shooting kernel reproduces planar cases (shortcut switched off)."""
    arm = designs.get(name)
    scene = solver.Scene(**scene_kw)
    planar = solver.solve(arm, np.array(psi) * PSI, scene, settings=FINE)
    spatial_p = _channel(arm, psi)
    general = solver.solve(arm, spatial_p, scene, planar=False,
                           settings=solver.Settings(steps_per_section=128, shortcuts=False))
    quick = solver.solve(arm, spatial_p, scene, planar=False, settings=FINE)
    assert general.converged and general.stable
    np.testing.assert_allclose(general.tip, np.append(planar.tip, 0.0), atol=1e-9)
    np.testing.assert_allclose(quick.tip, general.tip, atol=1e-9)
    np.testing.assert_allclose(general.positions[:, :2], planar.positions, atol=1e-9)
    np.testing.assert_allclose(general.positions[:, 2], 0.0, atol=1e-12)


def test_spatial_mirror_symmetry():
    """Swapping channels II and III mirrors the arm through the x–y plane."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90, payload_kg=0.1)
    p = np.array([10, 60, 0, 0, 40, 5, 30, 0, 20]) * PSI
    mirrored = p.copy()
    for s in range(3):
        mirrored[3 * s + 1], mirrored[3 * s + 2] = p[3 * s + 2], p[3 * s + 1]
    a = solver.solve(arm, p, scene, planar=False)
    b = solver.solve(arm, mirrored, scene, planar=False)
    assert a.converged and b.converged and abs(a.tip[2]) > 0.01
    np.testing.assert_allclose(b.tip, a.tip * [1, 1, -1], atol=1e-10)


def test_rest_strains_match_plain_loops():
    arm = designs.ct()
    p = _channel(arm, [40, 10, 70, 25])
    ours = solver.rest_strains(arm, p)
    ref = naive.rest_strains(arm, p)
    for a, b in zip(ours, ref):
        np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-9)
