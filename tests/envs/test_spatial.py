"""planar=False: the spatial arm (one pressure per channel) with the estimators that support it."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import softarm_gym  # noqa: F401
from softarm_gym.envs import GraspEnv, ReachEnv

SPATIAL_OBSERVATIONS = ("true", "model", "constant_curvature", "cable_encoder", "load_cell")


@pytest.mark.parametrize("observation", SPATIAL_OBSERVATIONS)
def test_spatial_reach_passes_the_checkers(observation):
    env = gym.make("SoftArm/CTReach-v0", planar=False, observation=observation)
    assert env.action_space.shape == (6,)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped, warn=True)


def test_spatial_layout_and_reachable_target():
    env = ReachEnv("octarm_v", planar=False, n_backbone=4)
    obs, info = env.reset(seed=0)
    assert obs.shape == (3 + 6 * 3 + 3 * 4 + 9 + 6,)
    ends = obs[env._slices["section_ends"]].reshape(3, 6)
    eq = env._eq
    np.testing.assert_allclose(ends[:, :3], eq.positions[list(eq.section_ends)], atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(ends[:, 3:], axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(ends[:, 3:], eq.orientations[list(eq.section_ends)][:, :, 2], atol=1e-6)
    p = env.target_pressures_pa
    assert p.shape == (9,)
    for frac in np.linspace(0.1, 1.0, 10):
        _, _, _, _, info = env.step(2.0 * frac * p / env.p_max - 1.0)
    assert info["distance"] < 1e-6 and info["is_success"]
    # Three-channel pressures on one section bend it out of the x-y plane.
    assert abs(info["target"][2]) > 1e-3


def test_spatial_inclinometer_observation_reads_imus():
    env = ReachEnv("octarm_v", planar=False, observation="inclinometer", action_mode="delta")
    obs, info = env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(3):
        obs, _, _, _, info = env.step(rng.uniform(-1, 1, 9).astype(np.float32))
    assert info["sensors"]["imu"].shape == (4, 6) and env.observation_space.contains(obs)
    assert info["estimation_error"] < 0.02


def test_spatial_unsupported_combinations_are_clear_errors():
    with pytest.raises(ValueError, match="planar only"):
        GraspEnv("octarm_v", planar=False)
    with pytest.raises(ValueError, match="planar must be"):
        ReachEnv("octarm_v", planar="yes")
