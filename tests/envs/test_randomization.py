"""Per-episode arm randomisation: ranges, what scales, validation."""

import numpy as np
import pytest

import solver
from softarm_gym.envs import ArmRandomization


def test_inactive_randomisation_returns_the_nominal_arm():
    arm = solver.designs.octarm_v()
    assert ArmRandomization().sample(arm, np.random.default_rng(0)) is arm
    assert ArmRandomization.coerce(None) == ArmRandomization()


@pytest.mark.parametrize("design", ["octarm_v", "octarm_vi", "ct"])
def test_sampled_arms_stay_in_range_and_scale_consistently(design):
    arm = solver.designs.get(design)
    rand = ArmRandomization(wind_angle_deg=2.0, youngs_modulus_rel=0.1)
    rng = np.random.default_rng(1)
    factors, angles = [], []
    for _ in range(50):
        sim = rand.sample(arm, rng)
        factor = sim.tubes[0].material.youngs_modulus / arm.tubes[0].material.youngs_modulus
        d_alpha = sim.tubes[0].material.wind_angle_deg - arm.tubes[0].material.wind_angle_deg
        for nominal, tube in zip(arm.tubes, sim.tubes):
            assert tube.material.youngs_modulus == pytest.approx(nominal.material.youngs_modulus * factor)
            assert tube.material.shear_modulus == pytest.approx(nominal.material.shear_modulus * factor)
            assert tube.material.wind_angle_deg == pytest.approx(nominal.material.wind_angle_deg + d_alpha)
            assert (tube.channel, tube.angle_deg, tube.radius) == (nominal.channel, nominal.angle_deg,
                                                                   nominal.radius)
        for nominal, sec in zip(arm.sections, sim.sections):
            for name in ("EA", "GA", "EI", "GJ"):
                assert getattr(sec, name) == pytest.approx(getattr(nominal, name) * factor)
            assert sec.mass_per_length == nominal.mass_per_length
        factors.append(factor)
        angles.append(d_alpha)
    assert 0.9 <= min(factors) < 0.95 and 1.05 < max(factors) <= 1.1
    assert -2.0 <= min(angles) < -1.0 and 1.0 < max(angles) <= 2.0


def test_modulus_factor_changes_the_actuated_curvature_the_physical_way():
    # λ(p) grows as p/E grows, and u* = F·y/EI with F and EI both ∝ E: softer rubber curls more.
    arm = solver.designs.octarm_v()
    channels = np.zeros(9)
    channels[0] = 50.0 * solver.PSI
    u_nominal = solver.rest_strains(arm, channels)[1][0]
    for seed in range(4):
        sim = ArmRandomization(youngs_modulus_rel=0.3).sample(arm, np.random.default_rng(seed))
        factor = sim.sections[0].EA / arm.sections[0].EA
        u_sim = solver.rest_strains(sim, channels)[1][0]
        assert (abs(u_sim) > abs(u_nominal)) == (factor < 1.0)


@pytest.mark.parametrize("kwargs, match", [
    ({"wind_angle_deg": -1.0}, "wind_angle_deg"),
    ({"youngs_modulus_rel": 1.0}, "< 1"),
    ({"youngs_modulus_rel": float("nan")}, "youngs_modulus_rel"),
    ({"wind_angle_deg": True}, "wind_angle_deg"),
])
def test_invalid_widths(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ArmRandomization(**kwargs)


def test_width_that_breaks_the_braid_is_rejected():
    with pytest.raises(ValueError, match="outside"):
        ArmRandomization(wind_angle_deg=12.0).check(solver.designs.octarm_v())
    with pytest.raises(ValueError, match="randomization must be"):
        ArmRandomization.coerce(0.1)


def _posterior():
    from solver.identify import Posterior, parse_parameters

    arm = solver.designs.octarm_v()
    params = parse_parameters(arm, "wind_angle:s1,E,mass_scale")
    cov = np.array([[0.09, -1.2e4, 0.0], [-1.2e4, 4e9, 1e2], [0.0, 1e2, 1e-4]])
    return Posterior(arm, params, np.array([76.9, 2.15e6, 1.04]), cov)


def _values(arm):
    return np.array([arm.tubes[0].material.wind_angle_deg, arm.tubes[0].material.youngs_modulus,
                     arm.sections[0].mass_per_length / solver.designs.octarm_v().sections[0].mass_per_length])


def test_posterior_randomization_draws_the_fitted_distribution_from_the_env_generator():
    from softarm_gym.envs import PosteriorRandomization, ReachEnv

    post = _posterior()
    rand = PosteriorRandomization(post)
    envs = [ReachEnv(post.mean_design, randomization=rand) for _ in range(2)]
    runs = []
    for env in envs:
        env.reset(seed=11)
        arms = [env.simulated_arm]
        for _ in range(3):
            env.reset()
            arms.append(env.simulated_arm)
        runs.append(arms)
    assert runs[0] == runs[1]  # the same seed, the same arms: nothing but np_random draws them
    assert len({_values(a)[0] for a in runs[0]}) == 4
    # Many draws (from the generator an env seeds) keep the fitted means and correlations.
    env = envs[0]
    env.reset(seed=3)
    draws = np.array([_values(rand.sample(env.arm, env.np_random)) for _ in range(4000)])
    sd = np.sqrt(np.diag(post.covariance))
    np.testing.assert_allclose(draws.mean(axis=0), post.mean, atol=0.0, rtol=1e-3)
    scaled = np.outer(sd, sd)
    # Standard error of a correlation from 4000 draws ≤ 1/√4000 = 0.016: three of them.
    np.testing.assert_allclose(np.cov(draws.T) / scaled, post.covariance / scaled, atol=0.05)
    rho = post.covariance[0, 1] / scaled[0, 1]
    assert rho == pytest.approx(-0.632, abs=1e-3)
    assert np.corrcoef(draws[:, 0], draws[:, 1])[0, 1] == pytest.approx(rho, abs=0.05)


def test_posterior_randomization_checks_and_widening():
    from softarm_gym.envs import PosteriorRandomization, coerce_randomization

    post = _posterior()
    rand = PosteriorRandomization(post, widen=2.0)
    rng = np.random.default_rng(0)
    wide = np.array([_values(rand.sample(post.design, rng))[0] for _ in range(3000)])
    assert np.std(wide) == pytest.approx(2 * 0.3, rel=0.06)
    assert PosteriorRandomization(post, widen=0.0).sample(post.design, rng) == post.mean_design
    rand.check(post.design)
    rand.check(post.mean_design)
    with pytest.raises(ValueError, match="fitted to design 'octarm_v'"):
        rand.check(solver.designs.octarm_vi())
    with pytest.raises(ValueError, match="widen must be a finite number >= 0"):
        PosteriorRandomization(post, widen=-1.0)
    assert coerce_randomization(rand) is rand
    assert coerce_randomization({"youngs_modulus_rel": 0.1}) == ArmRandomization(youngs_modulus_rel=0.1)
    with pytest.raises(ValueError, match="randomization must be"):
        coerce_randomization(0.1)
