"""Measurements and the model's predictions of them."""

import numpy as np
import pytest

import solver
from solver.identify import BackbonePoints, Measurements, TipPositions, predict

ARM = solver.designs.octarm_v()
P = solver.PSI
PRESSURES = np.array([[40, 0, 0, 60, 20, 0], [0, 90, 30, 0, 0, 70], [0, 0, 0, 0, 0, 0],
                      [90, 90, 90, 90, 90, 90]]) * P
ANGLES = np.array([90.0, 90.0, 0.0, 45.0])


def _meas(observations=None, payload=0.0):
    n = len(PRESSURES)
    obs = observations or (TipPositions(np.zeros((n, 2)), 0.005),)
    return Measurements(PRESSURES, ANGLES, payload, obs)


def test_predicted_tips_and_backbones_are_cold_solves():
    meas = _meas(payload=np.array([0.0, 0.1, 0.0, 0.2]))
    tips = predict(ARM, meas).tips
    shapes = predict(ARM, meas, backbone=True)
    for k in range(meas.n):
        eq = solver.solve(ARM, PRESSURES[k], solver.Scene(base_angle_deg=ANGLES[k],
                                                            payload_kg=meas.payload_kg[k]))
        np.testing.assert_allclose(tips[k], eq.tip, rtol=0, atol=1e-12)
        np.testing.assert_allclose(shapes.equilibrium(k).positions, eq.positions, rtol=0, atol=1e-12)
        np.testing.assert_allclose(shapes.equilibrium(k).tip, eq.tip, rtol=0, atol=1e-12)
    assert shapes.converged.all()


def test_markers_between_nodes_match_a_finer_solve():
    """Cubic Hermite between the 16-step nodes against the solver's own samples on a grid 8x finer
    (whose nodes include the markers): agreement to the RK4 error, far below a camera's."""
    fine = solver.Settings(steps_per_section=128)
    s = np.array([0.0, 0.1, 0.25, 0.3046875, 0.53, 0.7, ARM.length])
    meas = _meas()
    pts = predict(ARM, meas, backbone=True).points(s)
    for k in range(meas.n):
        eq = solver.solve(ARM, PRESSURES[k], solver.Scene(base_angle_deg=ANGLES[k]), settings=fine)
        for j, sj in enumerate(s):
            i = int(np.argmin(np.abs(eq.s - sj)))
            assert abs(eq.s[i] - sj) < 1e-12 or sj in (0.1, 0.7)
            ref = eq.positions[i] if abs(eq.s[i] - sj) < 1e-12 else np.array(
                [np.interp(sj, eq.s, eq.positions[:, 0]), np.interp(sj, eq.s, eq.positions[:, 1])])
            tol = 2e-6 if abs(eq.s[i] - sj) < 1e-12 else 2e-4  # linear interpolation of the fine grid
            np.testing.assert_allclose(pts[k, j], ref, rtol=0, atol=tol)
    tips = predict(ARM, meas).tips
    np.testing.assert_allclose(pts[:, -1], tips, rtol=0, atol=1e-12)


def test_constant_readings_in_a_scene_count_once():
    """k equal readings of one quantity in a scene are weighed as one reading (σ·√k)."""
    n = len(PRESSURES)
    measured = np.column_stack([np.full(n, 17.7), np.arange(n, dtype=float), [1.0, 1.0, 2.0, np.nan]])
    from solver.identify import Observation  # an observation of three numbers

    class Three(Observation):
        name = "three"
        labels = ("a", "b", "c")
        units = ("N", "N", "N")

    meas = Measurements(PRESSURES, [90.0, 90.0, 90.0, 0.0], 0.0, (Three(measured, 0.01),))
    sigma = meas.effective_sigma()[0]
    # column a: three equal in the 90° scene, one alone at 0°; b varies; c: two equal and one other
    np.testing.assert_allclose(sigma[:, 0], [0.01 * 3**0.5] * 3 + [0.01])
    np.testing.assert_allclose(sigma[:, 1], 0.01)
    np.testing.assert_allclose(sigma[:, 2], 0.01)


@pytest.mark.parametrize("kwargs, match", [
    (dict(pressures=np.zeros((0, 6))), "n >= 1"),
    (dict(base_angle_deg=[1.0, 2.0]), "broadcast"),
    (dict(payload_kg=-1.0), "payload_kg must be >= 0"),
    (dict(observations=()), "one or more"),
    (dict(observations=(TipPositions(np.zeros((3, 2)), 0.01),)), "has 3 configurations"),
    (dict(holdout=np.ones(4)), "bool array"),
    (dict(pressures=np.full((4, 6), np.inf)), "non-finite"),
])
def test_bad_measurements_are_one_line_errors(kwargs, match):
    args = dict(pressures=PRESSURES, base_angle_deg=ANGLES, payload_kg=0.0,
                observations=(TipPositions(np.zeros((4, 2)), 0.01),))
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Measurements(**args)


@pytest.mark.parametrize("make, match", [
    (lambda: TipPositions(np.zeros((4, 3)), 0.01), r"shape \(n, 2\)"),
    (lambda: TipPositions(np.zeros((4, 2)), 0.0), "sigma must be finite numbers > 0"),
    (lambda: TipPositions(np.full((4, 2), np.inf), 0.01), "non-finite"),
    (lambda: BackbonePoints(np.zeros((4, 2)), 0.01, s=(0.3, 0.2)), "increasing"),
    (lambda: BackbonePoints(np.zeros((4, 2)), 0.01, s=(-0.1,)), "increasing reference arc lengths >= 0"),
])
def test_bad_observations_are_one_line_errors(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_measurements_the_design_cannot_take_are_named():
    meas = _meas((BackbonePoints(np.zeros((4, 2)), 0.01, s=(2.0,)),))
    with pytest.raises(ValueError, match="beyond design 'octarm_v'"):
        meas.check(ARM)
    with pytest.raises(ValueError, match="has 4 planar inputs"):
        _meas().check(solver.designs.ct())
    over = Measurements(PRESSURES * 2, ANGLES, 0.0, (TipPositions(np.zeros((4, 2)), 0.01),))
    with pytest.raises(ValueError, match="configuration 0: pressure for channel 's2_II\\+III'"):
        over.check(ARM)
