"""Shape estimators: each recovers the truth when its assumptions hold, degrades gracefully with
noise, and shows its known failure mode."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import solver
from softarm_gym.sensing import (
    ESTIMATORS,
    SensorNoise,
    SensorReadings,
    ShapeEstimate,
    make_estimator,
    synthesize,
)
from softarm_gym.sensing.sensors import cable_radius

ARM = solver.designs.octarm_vi()
L = ARM.length
P = solver.PSI
PRESSURES = np.array([40, 0, 0, 60, 20, 0]) * P
HORIZONTAL = solver.Scene(base_angle_deg=90)


def _solve(pressures=PRESSURES, **scene):
    eq = solver.solve(ARM, pressures, solver.Scene(**{"base_angle_deg": 90, **scene}))
    assert eq.converged and eq.stable
    return eq


def _tip_error(name, eq, noise=None, rng=None, scene=HORIZONTAL, pressures=PRESSURES, **options):
    est = make_estimator(name, ARM, scene=scene, **options)
    shape = est.estimate(synthesize(eq, ARM, noise, rng), pressures, truth=eq)
    return float(np.linalg.norm(shape.tip - eq.tip))


def test_shape_estimate_layout():
    eq = _solve()
    for name in ESTIMATORS:
        shape = make_estimator(name, ARM, scene=HORIZONTAL, n_samples=17).estimate(
            synthesize(eq, ARM), PRESSURES, truth=eq)
        assert isinstance(shape, ShapeEstimate) and shape.planar and shape.converged
        assert shape.tip.shape == (2,) and shape.section_ends.shape == (3, 3)
        assert shape.backbone.shape == (17, 2)
        np.testing.assert_allclose(shape.backbone[0], 0.0, atol=1e-15)
        np.testing.assert_allclose(shape.backbone[-1], shape.tip)
        np.testing.assert_allclose(shape.section_ends[-1, :2], shape.tip)


def test_true_and_model_recover_the_equilibrium():
    eq = _solve()
    readings = synthesize(eq, ARM)
    truth = make_estimator("true", ARM, scene=HORIZONTAL, n_samples=201).estimate(readings, PRESSURES,
                                                                                  truth=eq)
    np.testing.assert_allclose(truth.tip, eq.tip)
    ends = list(eq.section_ends)
    np.testing.assert_allclose(truth.section_ends, np.column_stack([eq.positions[ends], eq.angles[ends]]))
    # The resampled backbone (cubic Hermite) agrees with a 400-step solve at the same s.
    fine = solver.solve(ARM, PRESSURES, HORIZONTAL, settings=solver.Settings(steps_per_section=400))
    s = np.linspace(0, L, 201)
    ref = np.column_stack([np.interp(s, fine.s, fine.positions[:, k]) for k in range(2)])
    np.testing.assert_allclose(truth.backbone, ref, atol=2e-6)
    model = make_estimator("model", ARM, scene=HORIZONTAL).estimate(readings, PRESSURES)
    np.testing.assert_allclose(model.tip, eq.tip, atol=1e-12)
    with pytest.raises(ValueError, match="truth"):
        make_estimator("true", ARM).estimate(readings, PRESSURES)


def test_model_warm_starts_within_an_episode():
    """Stepping follows the quasi-static path (warm start) and reset() forgets it."""
    est = make_estimator("model", ARM, scene=HORIZONTAL)
    readings = synthesize(_solve(), ARM)
    previous = None
    for k in range(1, 4):
        p = PRESSURES * k / 3
        shape = est.estimate(readings, p)
        previous = solver.solve(ARM, p, HORIZONTAL, warm_start=previous)
        np.testing.assert_allclose(shape.tip, previous.tip, atol=1e-9)
    assert est._previous is not None
    est.reset()
    assert est._previous is None


def test_model_fails_under_an_unknown_payload():
    """Known failure mode: the model cannot see a payload; the load cell measures it exactly
    and the reduced estimators (whose own error grows with the load, through the neglected
    axial force) stay well below the model."""
    assert _tip_error("model", _solve()) < 1e-12
    eq = _solve(payload_kg=1.0)
    model = _tip_error("model", eq)
    assert model > 0.1 * L
    assert _tip_error("load_cell", eq, steps_per_section=16) < 1e-9  # the solver's RK4 grid
    for name in ("cable_encoder", "inclinometer"):
        assert _tip_error(name, eq) < 0.6 * model


def test_constant_curvature_exact_without_loads_and_fails_under_gravity():
    no_gravity = solver.Scene(base_angle_deg=90, gravity=0.0)
    eq = solver.solve(ARM, PRESSURES, no_gravity)
    assert _tip_error("constant_curvature", eq, scene=no_gravity) < 1e-12
    # Under gravity the sections sag away from arcs (§4.3): a large error at zero pressure.
    eq = _solve(np.zeros(6))
    assert _tip_error("constant_curvature", eq, pressures=np.zeros(6)) > 0.05 * L


@pytest.mark.parametrize("payload", [0.0, 0.7])
@pytest.mark.parametrize("base_angle", [0.0, 60.0, 90.0])
def test_load_cell_recovers_truth_to_solver_tolerance(base_angle, payload):
    """Same RK4 grid as the solver: the solver's equilibrium to its tolerance; a finer grid
    converges to a 256-step truth (the payload is unknown to the estimator throughout)."""
    eq = _solve(base_angle_deg=base_angle, payload_kg=payload)
    scene = solver.Scene(base_angle_deg=base_angle)
    est = make_estimator("load_cell", ARM, scene=scene, n_samples=33, steps_per_section=16)
    shape = est.estimate(synthesize(eq, ARM), PRESSURES)
    np.testing.assert_allclose(shape.tip, eq.tip, atol=1e-9)
    ends = list(eq.section_ends)
    np.testing.assert_allclose(shape.section_ends, np.column_stack([eq.positions[ends], eq.angles[ends]]),
                               atol=1e-9)
    fine = solver.solve(ARM, PRESSURES, solver.Scene(base_angle_deg=base_angle, payload_kg=payload),
                        settings=solver.Settings(steps_per_section=256))
    est = make_estimator("load_cell", ARM, scene=scene, steps_per_section=128)
    np.testing.assert_allclose(est.estimate(synthesize(fine, ARM), PRESSURES).tip, fine.tip, atol=1e-6)


SPATIAL_P = np.array([40, 0, 10, 0, 50, 0, 20, 0, 60]) * P


@pytest.mark.parametrize("base_angle, payload", [(90.0, 0.0), (60.0, 1.0)])
def test_spatial_load_cell_model_and_true(base_angle, payload):
    truth_scene = solver.Scene(base_angle_deg=base_angle, payload_kg=payload)
    scene = solver.Scene(base_angle_deg=base_angle)
    eq = solver.solve(ARM, SPATIAL_P, truth_scene, planar=False,
                      settings=solver.Settings(steps_per_section=256))
    assert eq.converged and eq.stable and abs(eq.tip[2]) > 1e-3  # genuinely out of plane
    readings = synthesize(eq, ARM)
    est = make_estimator("load_cell", ARM, planar=False, scene=scene, steps_per_section=128)
    shape = est.estimate(readings, SPATIAL_P)
    assert not shape.planar and shape.backbone.shape == (32, 3)
    np.testing.assert_allclose(shape.tip, eq.tip, atol=2e-6)
    np.testing.assert_allclose(shape.section_frames, eq.orientations[list(eq.section_ends)], atol=2e-5)
    true = make_estimator("true", ARM, planar=False).estimate(readings, SPATIAL_P, truth=eq)
    np.testing.assert_allclose(true.tip, eq.tip)
    model = make_estimator("model", ARM, planar=False, scene=scene).estimate(readings, SPATIAL_P)
    error = np.linalg.norm(model.tip - eq.tip)
    assert error < 1e-6 if payload == 0 else error > 0.05 * L


def test_spatial_constant_curvature_exact_without_loads():
    scene = solver.Scene(base_angle_deg=30, gravity=0.0)
    eq = solver.solve(ARM, SPATIAL_P, scene, planar=False)
    shape = make_estimator("constant_curvature", ARM, planar=False, scene=scene, n_samples=9).estimate(
        synthesize(eq, ARM), SPATIAL_P)
    np.testing.assert_allclose(shape.tip, eq.tip, atol=1e-12)
    np.testing.assert_allclose(shape.section_frames, eq.orientations[list(eq.section_ends)], atol=1e-12)
    ref = make_estimator("true", ARM, planar=False, n_samples=9).estimate(synthesize(eq, ARM), SPATIAL_P,
                                                                          truth=eq)
    # The true backbone is cubic Hermite on the solver's 16-step nodes: ~1e-8 m off the arc.
    np.testing.assert_allclose(shape.backbone, ref.backbone, atol=5e-8)


def _reduced_world(theta0, m_guess, n1_start, stretch, weight):
    """The reduced model of §4.2.2–4.2.3 integrated independently (scipy DOP853), with the base
    moment chosen (brentq) so that the tip is moment-free. Returns section-end θ, tip, n1(L)."""
    u_rest = solver.rest_strains(ARM, _channels(PRESSURES))[1]
    lengths = [s.length for s in ARM.sections]

    def shoot(m0):
        state = np.array([theta0, m0, 0.0, 0.0, 0.0])
        ends = []
        for i, length in enumerate(lengths):
            state[2] = n1_start[i]
            ei = ARM.sections[i].EI

            def rhs(s, y, i=i, ei=ei):
                th, m, n1 = y[0], y[1], y[2]
                return [u_rest[i] + m / ei, -stretch[i] * n1, weight[i] * math.cos(th),
                        stretch[i] * math.cos(th), stretch[i] * math.sin(th)]

            state = solve_ivp(rhs, (0, length), state, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]
            ends.append(state.copy())
        return np.array(ends)

    m0 = brentq(lambda m: shoot(m)[-1, 1], m_guess - 5.0, m_guess + 5.0, xtol=1e-14)
    ends = shoot(m0)
    return ends[:, 0], ends[-1, 3:5], ends[-1, 2]


def _channels(p):
    spatial = np.zeros(ARM.n_channels)
    for value, (_, idx) in zip(p, ARM.planar_channels):
        spatial[list(idx)] = value
    return spatial


def test_reduced_estimators_exact_when_their_assumptions_hold():
    """Readings from a world that obeys the reduced model (uniform pressure stretch, no shear
    strain, no axial force, per-section shear): cable_encoder and inclinometer recover it."""
    v_rest = solver.rest_strains(ARM, _channels(PRESSURES))[2]
    weight = np.array([s.mass_per_length for s in ARM.sections]) * 9.81
    theta0 = 0.0
    n1_start = np.array([-6.0, -4.5, -2.0])
    thetas, tip, n1_tip = _reduced_world(theta0, 0.0, n1_start, v_rest, weight)
    lengths = np.array([s.length for s in ARM.sections])
    dtheta = np.diff(np.concatenate([[theta0], thetas]))
    r = cable_radius(ARM)
    enc = np.cumsum(np.column_stack([lengths * v_rest - r * dtheta, lengths * v_rest + r * dtheta]), axis=0)
    readings = SensorReadings(enc, np.concatenate([[theta0], thetas]), np.zeros(3))
    for name in ("cable_encoder", "inclinometer"):
        # 64 RK4 steps per section: discretisation error ~1e-9 m (the default 16: ~1e-6 m).
        est = make_estimator(name, ARM, scene=HORIZONTAL, steps_per_section=64)
        shape = est.estimate(readings, PRESSURES)
        assert shape.converged
        np.testing.assert_allclose(shape.tip, tip, atol=1e-8)
        np.testing.assert_allclose(shape.section_ends[:, 2], thetas, atol=1e-9)
    # Known payload (Eq. 4.41): the tip shear n1(L) = −W cos θ(L) replaces the tip inclinometer.
    w_tip = -n1_tip / math.cos(thetas[-1])
    assert w_tip > 0
    blind = SensorReadings(enc, np.concatenate([[theta0], thetas[:-1], [123.0]]), np.zeros(3))
    est = make_estimator("inclinometer", ARM, scene=HORIZONTAL, known_payload_kg=w_tip / 9.81,
                         steps_per_section=64)
    shape = est.estimate(blind, PRESSURES)
    np.testing.assert_allclose(shape.tip, tip, atol=1e-8)


def test_reduced_estimators_error_shrinks_with_gravity():
    """Their modelling error comes from the neglected axial force and shear strain: it vanishes
    with the load (zero in the unloaded, gravity-free case) and grows with gravity."""
    errors = {}
    for g in (0.0, 0.981, 9.81):
        scene = solver.Scene(base_angle_deg=90, gravity=g)
        eq = solver.solve(ARM, PRESSURES, scene)
        errors[g] = [_tip_error(n, eq, scene=scene, steps_per_section=64)
                     for n in ("cable_encoder", "inclinometer")]
    assert max(errors[0.0]) < 1e-9
    for k in range(2):
        assert errors[0.981][k] < errors[9.81][k] < 0.05 * L


@pytest.mark.parametrize("name", ["constant_curvature", "cable_encoder", "inclinometer", "load_cell"])
def test_noise_degrades_gracefully(name):
    """Gaussian noise of scale σ·resolution: the mean tip error grows about linearly in σ and
    stays bounded; Table 4.3 quantisation gives a bounded error."""
    eq = _solve()
    exact = _tip_error(name, eq)
    base = SensorNoise.thesis(quantize=False)
    means = []
    for scale in (0.01, 0.1):
        noise = SensorNoise(**{**base.__dict__, "gaussian_std": scale})
        diffs = []
        rng = np.random.default_rng(1)
        est = make_estimator(name, ARM, scene=HORIZONTAL)
        clean = est.estimate(synthesize(eq, ARM), PRESSURES).tip
        for _ in range(8):
            diffs.append(np.linalg.norm(est.estimate(synthesize(eq, ARM, noise, rng), PRESSURES).tip - clean))
        means.append(np.mean(diffs))
    assert 0 < means[0] < means[1]
    assert 4 < means[1] / means[0] < 25
    assert _tip_error(name, eq, SensorNoise.thesis()) < exact + 0.25 * L


def test_estimator_bad_input():
    eq = _solve()
    readings = synthesize(eq, ARM)
    with pytest.raises(ValueError, match="unknown estimator"):
        make_estimator("kalman", ARM)
    with pytest.raises(ValueError, match="n_samples"):
        make_estimator("model", ARM, n_samples=1)
    with pytest.raises(ValueError, match="options"):
        make_estimator("load_cell", ARM, colour="red")
    with pytest.raises(ValueError, match="known_payload_kg"):
        make_estimator("inclinometer", ARM, known_payload_kg=-1.0)
    est = make_estimator("cable_encoder", ARM, scene=HORIZONTAL)
    with pytest.raises(ValueError, match="pressures_pa"):
        est.estimate(readings, PRESSURES[:3])
    with pytest.raises(ValueError, match="negative"):
        est.estimate(readings, -PRESSURES)
    with pytest.raises(ValueError, match="maximum"):
        est.estimate(readings, PRESSURES * 10)
    with pytest.raises(ValueError, match="SensorReadings"):
        est.estimate(readings.as_vector(), PRESSURES)
    spatial = synthesize(solver.solve(ARM, np.zeros(9), planar=False), ARM)
    with pytest.raises(ValueError, match="spatial"):
        est.estimate(spatial, PRESSURES)


def test_spatial_cable_encoder():
    """Nine encoders (three per section): exact without loads (to RK4 error); under gravity
    out of the plane, converged, and better than constant curvature on the same cables."""
    no_load = solver.Scene(base_angle_deg=30, gravity=0.0)
    eq = solver.solve(ARM, SPATIAL_P, no_load, planar=False)
    est = make_estimator("cable_encoder", ARM, planar=False, scene=no_load, steps_per_section=64)
    np.testing.assert_allclose(est.estimate(synthesize(eq, ARM), SPATIAL_P).tip, eq.tip, atol=1e-9)
    for base_angle in (30.0, 90.0):
        scene = solver.Scene(base_angle_deg=base_angle)
        eq = solver.solve(ARM, SPATIAL_P, scene, planar=False)
        readings = synthesize(eq, ARM)
        shape = make_estimator("cable_encoder", ARM, planar=False, scene=scene).estimate(readings, SPATIAL_P)
        arcs = make_estimator("constant_curvature", ARM, planar=False, scene=scene).estimate(readings,
                                                                                             SPATIAL_P)
        assert shape.converged and shape.backbone.shape == (32, 3)
        error = np.linalg.norm(shape.tip - eq.tip)
        assert error < np.linalg.norm(arcs.tip - eq.tip) and error < 0.06 * L
    with pytest.raises(ValueError, match="planar inclinometer estimator only"):
        make_estimator("inclinometer", ARM, planar=False, known_payload_kg=0.1)


def test_spatial_inclinometer_estimator_reads_imus_out_of_plane():
    """In space the inclinometers are IMUs (heading too): the reduced model fitted to the
    section-end axes tracks curled, out-of-plane states within millimetres (its own model
    error: no shear, no axial force), where arcs are decimetres off."""
    arm = solver.designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90.0)
    rng = np.random.default_rng(1)
    imu = make_estimator("inclinometer", arm, planar=False, scene=scene)
    arcs = make_estimator("constant_curvature", arm, planar=False, scene=scene)
    for _ in range(6):
        eq = solver.solve(arm, rng.uniform(0, 0.6, 9) * arm.max_pressure, scene, planar=False)
        assert eq.converged and abs(eq.tip[2]) > 0.01  # out of the plane
        readings = synthesize(eq, arm)
        imu.reset()  # every estimate cold: no help from the previous one
        shape = imu.estimate(readings, eq.pressures)
        assert shape.converged
        np.testing.assert_allclose(shape.section_frames[:, :, 2],
                                   eq.orientations[list(eq.section_ends)][:, :, 2], atol=1e-5)
        error = np.linalg.norm(shape.tip - eq.tip)
        arcs_error = np.linalg.norm(arcs.estimate(readings, eq.pressures).tip - eq.tip)
        assert error < 0.012 and error < 0.1 * arcs_error
    with pytest.raises(ValueError, match="reads IMUs"):
        imu.estimate(_without_imu(readings), eq.pressures)


def _without_imu(readings):
    return SensorReadings(readings.encoder_lengths, readings.inclinometers, readings.base_wrench,
                          planar=False)


def test_spatial_imu_estimates_pick_the_root_the_twists_agree_with():
    """The reduced model can match every section-end axis with more than one root; the IMUs
    also measure the twist about each axis, which the fit leaves out. Along random spatial
    steps, every estimate whose twists agree with the IMUs (within the limit) is within
    5 cm of the truth, and most are."""
    import gymnasium as gym

    from softarm_gym.envs import ReachEnv
    from softarm_gym.sensing.estimators import InclinometerShape
    from softarm_gym.sensing.sensors import imu_frames

    env = gym.wrappers.TimeLimit(ReachEnv("octarm_v", planar=False, observation="inclinometer"), 50)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    agreed = 0
    for _ in range(120):
        *_, terminated, truncated, info = env.step(rng.uniform(-1, 1, 9).astype(np.float32))
        u = env.unwrapped
        measured = imu_frames(u._readings.imu)[1:]
        d1 = u._shape_estimate.section_frames[:, :, 0]
        twist = np.abs(np.arctan2(np.einsum("ki,ki->k", d1, measured[:, :, 1]),
                                  np.einsum("ki,ki->k", d1, measured[:, :, 0]))).max()
        if twist <= InclinometerShape.LEFT_OUT_LIMIT:
            agreed += 1
            assert info["estimation_error"] < 0.05
        if terminated or truncated:
            env.reset()
    assert agreed >= 0.85 * 120
