"""Shared stepping behaviour: actions, failed solves, reward bookkeeping, observations, info."""


import numpy as np
import pytest

import solver
from softarm_gym.envs import ReachEnv


def test_pressure_mapping_and_clipping():
    env = ReachEnv("octarm_v")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([-1.0, 1.0, 0.0, 0.5, -0.5, 1.0]))
    p_max = solver.designs.octarm_v().max_pressure
    np.testing.assert_allclose(info["pressures_pa"], np.array([0.0, 1.0, 0.5, 0.75, 0.25, 1.0]) * p_max)
    obs_clipped, *_, info_clipped = env.step(np.array([-7.0, 3.0, 0.0, 0.5, -0.5, 1e9]))
    np.testing.assert_array_equal(info_clipped["pressures_pa"], info["pressures_pa"])
    np.testing.assert_allclose(obs_clipped[env._slices["pressures"]], [-1, 1, 0, 0.5, -0.5, 1], atol=1e-7)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_names_the_channel(bad):
    env = ReachEnv("ct")
    env.reset(seed=0)
    action = np.zeros(4)
    action[2] = bad
    with pytest.raises(ValueError, match="outer_I"):
        env.step(action)


def test_huge_finite_action_is_clipped_not_called_infinite():
    """1e308 is finite; their sum overflows, which must not matter."""
    env = ReachEnv("ct")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.full(4, 1e308))
    np.testing.assert_allclose(info["pressures_pa"], env.p_max)


def test_wrong_action_shape_is_a_value_error():
    env = ReachEnv("ct")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        env.step(np.zeros(6))


def test_delta_mode_accumulates_and_zero_holds():
    env = ReachEnv("octarm_v", action_mode="delta", delta_scale=0.2, initial_pressure_fraction=0.0)
    env.reset(seed=0)
    p_max = env.p_max
    _, _, _, _, info = env.step(np.ones(6))
    np.testing.assert_allclose(info["pressures_pa"], 0.2 * p_max)
    _, _, _, _, info = env.step(np.ones(6))
    np.testing.assert_allclose(info["pressures_pa"], 0.4 * p_max)
    tip = info["tip_true"]
    _, _, _, _, info = env.step(np.zeros(6))
    np.testing.assert_allclose(info["pressures_pa"], 0.4 * p_max)
    np.testing.assert_allclose(info["tip_true"], tip, atol=1e-9)
    _, _, _, _, info = env.step(-np.ones(6) * 5)
    np.testing.assert_allclose(info["pressures_pa"], 0.2 * p_max)


def test_reward_terms_sum_exactly_to_the_reward():
    env = ReachEnv("octarm_v", control_weight=0.3)
    env.reset(seed=5)
    env.action_space.seed(0)
    for _ in range(5):
        _, reward, _, _, info = env.step(env.action_space.sample())
        terms = [info[k] for k in info if k.startswith("reward_")]
        assert len(terms) == 4
        total = 0.0
        for t in terms:
            total += t
        assert total == reward
        assert info["reward_distance"] == -info["distance"]


def test_failed_solve_keeps_last_good_state_penalises_and_truncates(monkeypatch):
    env = ReachEnv("octarm_v", solver_failure_penalty=2.5, max_solver_failures=3)
    env.reset(seed=1)
    obs_good, *_, info_good = env.step(np.zeros(6))
    stepper = env._stepper
    # A stepper whose steps fail (solver.Stepper keeps its state then: tests/solver/test_stepper.py).
    monkeypatch.setattr(stepper, "step", lambda p: solver.StepReport(False, False, False, 12, 1.0))
    for k in range(1, 4):
        obs, reward, terminated, truncated, info = env.step(np.ones(6))
        assert info["converged"] is False and info["solver"]["converged"] is False
        assert info["solver_failures"] == k
        assert info["reward_solver"] == -2.5
        np.testing.assert_array_equal(info["tip_true"], info_good["tip_true"])
        np.testing.assert_array_equal(info["pressures_pa"], info_good["pressures_pa"])
        np.testing.assert_array_equal(obs, obs_good)
        assert truncated == (k == 3)
        assert not terminated
    monkeypatch.undo()
    _, _, _, truncated, info = env.step(np.ones(6))
    assert info["converged"] and info["solver_failures"] == 0 and info["reward_solver"] == 0.0
    assert not truncated
    np.testing.assert_allclose(info["pressures_pa"], env.p_max)


def test_observation_layout_matches_the_true_shape():
    env = ReachEnv("octarm_v", n_backbone=5)
    obs, info = env.reset(seed=2)
    assert obs.shape == (2 + 4 * 3 + 2 * 5 + 6 + 4,) and obs.dtype == np.float32
    assert env.observation_space.contains(obs)
    np.testing.assert_allclose(obs[:2], info["tip_true"], atol=1e-6)
    ends = obs[env._slices["section_ends"]].reshape(3, 4)
    eq = env._eq
    np.testing.assert_allclose(ends[:, :2], eq.positions[list(eq.section_ends)], atol=1e-6)
    theta = eq.angles[list(eq.section_ends)]
    np.testing.assert_allclose(ends[:, 2:], np.column_stack([np.cos(theta), np.sin(theta)]), atol=1e-6)
    backbone = obs[env._slices["backbone"]].reshape(5, 2)
    np.testing.assert_allclose(backbone[0], [0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(backbone[-1], info["tip_true"], atol=1e-6)
    goal = obs[env._slices["goal"]]
    np.testing.assert_allclose(goal[:2], info["target"], atol=1e-6)
    np.testing.assert_allclose(goal[2:], info["target"] - info["tip_true"], atol=1e-6)
    assert info["estimation_error"] == 0.0


def test_info_carries_sensors_and_solver_status():
    env = ReachEnv("octarm_v", observation="constant_curvature", sensor_noise="thesis")
    env.reset(seed=3)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert info["sensors"]["encoder_lengths"].shape == (3, 2)
    assert info["sensors"]["inclinometers"].shape == (4,)
    assert info["sensors"]["base_wrench"].shape == (3,)
    np.testing.assert_allclose(info["sensors"]["encoder_lengths"] / 0.03,
                               np.round(info["sensors"]["encoder_lengths"] / 0.03), atol=1e-9)
    assert set(info["solver"]) >= {"converged", "iterations", "residual"}
    assert info["estimation_error"] == pytest.approx(np.hypot(*(info["tip_estimated"] - info["tip_true"])))
    assert info["estimation_error"] > 0.0


def test_model_estimator_is_exact_only_without_payload_or_randomisation():
    exact = ReachEnv("octarm_v", observation="model")
    exact.reset(seed=4)
    _, _, _, _, info = exact.step(np.full(6, -0.2))
    assert info["estimation_error"] < 1e-6
    loaded = ReachEnv("octarm_v", observation="model", payload_kg=0.3)
    loaded.reset(seed=4)
    _, _, _, _, info = loaded.step(np.full(6, -0.2))
    assert info["payload_kg"] == 0.3 and info["estimation_error"] > 0.01
    randomised = ReachEnv("octarm_v", observation="model",
                          randomization={"wind_angle_deg": 2.0, "youngs_modulus_rel": 0.1})
    randomised.reset(seed=4)
    _, _, _, _, info = randomised.step(np.full(6, -0.2))
    assert randomised.estimator.arm is randomised.arm and randomised._sim_arm is not randomised.arm
    assert info["estimation_error"] > 1e-4


def test_payload_range_is_drawn_per_episode():
    env = ReachEnv("ct", payload_kg=(0.0, 0.5))
    payloads = {env.reset(seed=s)[1]["payload_kg"] for s in range(5)}
    assert len(payloads) == 5 and all(0.0 <= p <= 0.5 for p in payloads)


@pytest.mark.parametrize("kwargs, match", [
    ({"design": "nope"}, "unknown design"),
    ({"design": 3}, "design must be"),
    ({"design": solver.designs.rod()}, "no channels"),
    ({"observation": "camera"}, "unknown observation"),
    ({"action_mode": "velocity"}, "unknown action_mode"),
    ({"observation_format": "image"}, "unknown observation_format"),
    ({"sensor_noise": "loud"}, "sensor_noise"),
    ({"sensor_noise": {"encoder_resolution": -1}}, "encoder_resolution"),
    ({"payload_kg": -0.1}, "payload_kg"),
    ({"payload_kg": (0.5, 0.1)}, "high < low"),
    ({"base_angle_deg": float("nan")}, "base_angle_deg"),
    ({"randomization": {"wind_angle_deg": 30.0}}, "outside"),
    ({"randomization": {"stiffness": 0.1}},
     r"randomization has unknown field\(s\) 'stiffness'; valid fields: wind_angle_deg, youngs_modulus_rel"),
    ({"n_backbone": 1}, "n_backbone"),
    ({"delta_scale": 0.0}, "delta_scale"),
    ({"max_solver_failures": 0}, "max_solver_failures"),
    ({"success_tolerance": 0.0}, "success_tolerance"),
    ({"render_mode": "ascii"}, "render_mode"),
    ({"render_size": 10**6}, r"render_size must be an integer in \[16, 4096\]"),
    ({"render_size": 8}, "render_size"),
    ({"render_size": 400.0}, "render_size"),
    ({"render_size": True}, "render_size"),
    ({"model": "euler"}, "unknown model"),
])
def test_bad_kwargs_raise_clear_value_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ReachEnv(**kwargs)
