"""Sensor synthesis against geometry and global equilibrium (oracles independent of our code)."""

import math

import numpy as np
import pytest
from scipy.integrate import simpson

import solver
from softarm_gym.sensing import SensorNoise, SensorReadings, synthesize
from softarm_gym.sensing.sensors import cable_angles, cable_radius, imu_frames

ARM = solver.designs.octarm_vi()
P = solver.PSI
PRESSURES = np.array([40, 0, 0, 60, 20, 0]) * P
FINE = solver.Settings(steps_per_section=400)


def _arcs(arm, channel_pressures):
    """Per-section (u1, u2, v) of an unloaded arm: the closed-form rest strains."""
    return solver.rest_strains(arm, channel_pressures)


def _planar_channels(arm, p):
    spatial = np.zeros(arm.n_channels)
    for value, (_, idx) in zip(p, arm.planar_channels):
        spatial[list(idx)] = value
    return spatial


def test_planar_encoders_unloaded_match_arc_formula():
    """Without loads every section is an arc: l± = Σ L_i (v_i ∓ R u_i) (Eq. 4.28)."""
    eq = solver.solve(ARM, PRESSURES, solver.Scene(base_angle_deg=90, gravity=0.0))
    readings = synthesize(eq, ARM)
    _, u2, v = _arcs(ARM, _planar_channels(ARM, PRESSURES))
    lengths = np.array([s.length for s in ARM.sections])
    r = cable_radius(ARM)
    expect = np.column_stack([np.cumsum(lengths * (v - r * u2)), np.cumsum(lengths * (v + r * u2))])
    np.testing.assert_allclose(readings.encoder_lengths, expect, rtol=0, atol=1e-12)
    # Inclinometers: θ0 and θ0 + cumulative arc angles.
    theta = math.radians(0.0) + np.concatenate([[0.0], np.cumsum(lengths * u2)])
    np.testing.assert_allclose(readings.inclinometers, theta, atol=1e-12)
    np.testing.assert_allclose(readings.base_wrench, 0.0, atol=1e-12)


@pytest.mark.parametrize("base_angle, payload", [(90.0, 0.0), (0.0, 0.5), (45.0, 1.0)])
def test_planar_encoders_equal_cable_polyline_length(base_angle, payload):
    """Under load (shear, extension): the strain integral equals the length of the cable curve
    r + c·R·d1 traced on the same equilibrium (pure geometry: chord lengths, Richardson-
    extrapolated from 200 and 400 steps per section, error O(h⁴))."""
    scene = solver.Scene(base_angle_deg=base_angle, payload_kg=payload)
    r = cable_radius(ARM)
    polylines = []
    for steps in (200, 400):
        fine = solver.solve(ARM, PRESSURES, scene, settings=solver.Settings(steps_per_section=steps))
        assert fine.converged
        d1 = np.column_stack([-np.sin(fine.angles), np.cos(fine.angles)])
        per_cable = []
        for sign in (1.0, -1.0):
            seg = np.linalg.norm(np.diff(fine.positions + sign * r * d1, axis=0), axis=1)
            per_cable.append(np.concatenate([[0.0], np.cumsum(seg)])[list(fine.section_ends)])
        polylines.append(np.column_stack(per_cable))
    np.testing.assert_allclose(synthesize(fine, ARM).encoder_lengths, (4 * polylines[1] - polylines[0]) / 3,
                               rtol=1e-9)
    # The default 16-step solve reads the same to its own discretisation error.
    coarse = synthesize(solver.solve(ARM, PRESSURES, scene), ARM).encoder_lengths
    np.testing.assert_allclose(coarse, synthesize(fine, ARM).encoder_lengths, rtol=1e-5)


def test_base_wrench_is_global_equilibrium():
    """n(0) carries all the weight; m(0) = r_tip × F_tip + ∫ r × q ds (moment of the loads)."""
    payload = 0.3
    scene = solver.Scene(base_angle_deg=70, payload_kg=payload)
    eq = solver.solve(ARM, PRESSURES, scene, settings=FINE)
    wrench = synthesize(eq, ARM).base_wrench
    g = scene.gravity
    np.testing.assert_allclose(wrench[:2], [0.0, -(ARM.mass + payload) * g], atol=1e-9)
    moment = eq.tip[0] * (-payload * g)
    for i, sec in enumerate(ARM.sections):
        start = 0 if i == 0 else eq.section_ends[i - 1] + 1
        idx = slice(start, eq.section_ends[i] + 1)
        moment += simpson(-sec.mass_per_length * g * eq.positions[idx, 0], eq.s[idx])
    assert wrench[2] == pytest.approx(moment, abs=1e-6)


def test_spatial_readings_match_arc_formula_and_planar():
    """Spatial cables at φ = 0/120/240°: l = Σ L (v + R(u1 sin φ − u2 cos φ)) when unloaded."""
    p = np.array([40, 0, 10, 0, 50, 0, 20, 0, 60]) * P
    eq = solver.solve(ARM, p, solver.Scene(base_angle_deg=30, gravity=0.0), planar=False)
    readings = synthesize(eq, ARM)
    u1, u2, v = _arcs(ARM, p)
    phi = cable_angles(False)
    lengths = np.array([s.length for s in ARM.sections])
    per = lengths[:, None] * (v[:, None] + cable_radius(ARM) * (
        u1[:, None] * np.sin(phi) - u2[:, None] * np.cos(phi)))
    np.testing.assert_allclose(readings.encoder_lengths, np.cumsum(per, axis=0), atol=1e-12)
    assert readings.inclinometers.shape == (4, 2) and readings.base_wrench.shape == (6,)
    # A planar equilibrium embedded in 3D reads the same on the +R·d1 cable, base and wrench.
    scene = solver.Scene(base_angle_deg=90)
    planar = synthesize(solver.solve(ARM, PRESSURES, scene), ARM)
    spatial = synthesize(solver.solve(ARM, _planar_channels(ARM, PRESSURES), scene, planar=False), ARM)
    np.testing.assert_allclose(spatial.encoder_lengths[:, 0], planar.encoder_lengths[:, 0], atol=1e-8)
    np.testing.assert_allclose(spatial.base_wrench[[0, 1, 5]], planar.base_wrench, atol=1e-8)
    np.testing.assert_allclose(spatial.inclinometers[:, 0], np.arcsin(np.sin(planar.inclinometers)),
                               atol=1e-8)


def test_quantisation_and_seeded_gaussian_noise():
    eq = solver.solve(ARM, PRESSURES, solver.Scene(base_angle_deg=90))
    exact = synthesize(eq, ARM)
    noisy = synthesize(eq, ARM, SensorNoise.thesis())
    counts = noisy.encoder_lengths / 0.03
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert np.all(np.abs(noisy.encoder_lengths - exact.encoder_lengths) <= 0.015 + 1e-12)
    res = np.radians([0.05] + [2.5] * 3)
    assert np.all(np.abs(noisy.inclinometers - exact.inclinometers) <= res / 2 + 1e-12)
    gauss = SensorNoise(encoder_resolution=1e-3, inclinometer_resolution_deg=0.1, force_resolution=0.01,
                        axial_force_resolution=0.01, moment_resolution=0.001, gaussian_std=1.0,
                        quantize=False)
    a = synthesize(eq, ARM, gauss, np.random.default_rng(7)).as_vector()
    b = synthesize(eq, ARM, gauss, np.random.default_rng(7)).as_vector()
    c = synthesize(eq, ARM, gauss, np.random.default_rng(8)).as_vector()
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.shape == (6 + 4 + 3,) and np.all(np.abs(a - exact.as_vector()) < 6 * 0.01)
    with pytest.raises(ValueError, match="rng"):
        synthesize(eq, ARM, gauss)


@pytest.mark.parametrize("kwargs", [dict(encoder_resolution=-1.0), dict(moment_resolution=math.nan),
                                    dict(gaussian_std="x"), dict(quantize=1)])
def test_noise_validation(kwargs):
    with pytest.raises(ValueError, match="SensorNoise"):
        SensorNoise(**kwargs)


def test_noise_presets():
    assert SensorNoise.off().is_off
    t = SensorNoise.thesis()
    assert (t.encoder_resolution, t.inclinometer_resolution_deg, t.force_resolution,
            t.axial_force_resolution, t.moment_resolution) == (0.03, 2.5, 1 / 200, 1 / 100, 1 / 800)
    assert math.radians(t.base_inclinometer_deg) == pytest.approx(8.7e-4)
    assert SensorNoise(inclinometer_resolution_deg=1.0).base_inclinometer_deg == 1.0


def test_bad_input():
    eq = solver.solve(ARM, PRESSURES, solver.Scene(), record=False)
    with pytest.raises(ValueError, match="record=True"):
        synthesize(eq, ARM)
    with pytest.raises(ValueError, match="sections"):
        synthesize(solver.solve(ARM, PRESSURES), solver.designs.octarm_two_section())
    with pytest.raises(ValueError, match="Generator"):
        synthesize(solver.solve(ARM, PRESSURES), ARM, SensorNoise.off(), rng=3)
    with pytest.raises(ValueError, match="shape"):
        SensorReadings(np.zeros((3, 2)), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="non-finite"):
        SensorReadings(np.full((3, 2), np.nan), np.zeros(4), np.zeros(3))


def test_imus_give_the_whole_orientation_heading_included():
    arm = solver.designs.octarm_v()
    p = np.zeros(9)
    p[[1, 5]] = 0.6 * arm.max_pressure  # channels II: curls out of the x-y plane
    for base_angle in (0.0, 90.0, 180.0):  # hanging (d3 along gravity), horizontal, upright
        eq = solver.solve(arm, p, solver.Scene(base_angle_deg=base_angle), planar=False)
        truth = eq.orientations[[0, *eq.section_ends]]
        readings = synthesize(eq, arm)
        assert readings.imu.shape == (4, 6)
        np.testing.assert_allclose(imu_frames(readings.imu), truth, atol=1e-12)
        noise = SensorNoise(imu_tilt_resolution_deg=0.5, imu_heading_resolution_deg=2.0, gaussian_std=1.0,
                            quantize=False)
        frames = imu_frames(synthesize(eq, arm, noise, np.random.default_rng(0)).imu)
        np.testing.assert_allclose(np.einsum("kji,kjl->kil", frames, frames), np.tile(np.eye(3), (4, 1, 1)),
                                   atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(frames), 1.0)
        # The up direction is matched exactly: the tilt error is the accelerometer's alone.
        angle = np.degrees(np.arccos(np.clip((np.einsum("kij,kij->k", frames, truth) - 1) / 2, -1, 1)))
        assert 0 < angle.max() < 15
    assert synthesize(solver.solve(ARM, PRESSURES), ARM).imu.shape == (0, 6)  # planar: no IMUs
    with pytest.raises(ValueError, match="imu must have shape"):
        SensorReadings(np.zeros((3, 3)), np.zeros((4, 2)), np.zeros(6), planar=False, imu=np.zeros((3, 6)))
    with pytest.raises(ValueError, match="parallel"):
        imu_frames(np.array([[0, 1, 0, 0, 1, 0]]))
    assert SensorNoise.thesis().imu_heading_resolution_deg == 2.5 and not SensorNoise.thesis().is_off
