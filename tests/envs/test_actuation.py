"""Pneumatic lag: channel pressures follow the command through a first-order lag."""

import math

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401  (registers the IDs)


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmReach-v0", "SoftArm/CTWrap-v0", "SoftArm/OctArmTrack-v0"])
def test_lag_is_a_first_order_step_response(env_id):
    tau, dt = 0.3, 0.1
    env = gym.make(env_id, actuation="lag", pressure_time_constant_s=tau, step_dt_s=dt,
                   initial_pressure_fraction=0.0)
    obs, info = env.reset(seed=0)
    slices = env.unwrapped.observation_slices
    p_max = env.unwrapped.p_max
    n = env.action_space.shape[0]
    command = np.full(n, 0.6, dtype=np.float32)  # absolute: 80 % of p_max on every channel
    target = 0.5 * (float(command[0]) + 1.0)  # the float32 action's fraction
    for k in range(1, 8):
        obs, _, _, _, info = env.step(command)
        assert info["converged"]
        expected = target * p_max * (1.0 - math.exp(-k * dt / tau))
        np.testing.assert_allclose(info["pressures_pa"], expected, rtol=1e-9)
        np.testing.assert_allclose(info["commanded_pressures_pa"], target * p_max, rtol=1e-12)
        np.testing.assert_allclose(obs[slices["commanded"]], 0.6, atol=1e-6)
        np.testing.assert_allclose(obs[slices["pressures"]], 2 * expected / p_max - 1, atol=1e-6)


def test_ideal_actuation_is_unchanged_and_lag_is_validated():
    ideal, default = gym.make("SoftArm/OctArmReach-v0", actuation="ideal"), gym.make("SoftArm/OctArmReach-v0")
    assert "commanded" not in ideal.unwrapped.observation_slices
    a, b = ideal.reset(seed=1)[0], default.reset(seed=1)[0]
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="actuation"):
        gym.make("SoftArm/OctArmReach-v0", actuation="valve")
    with pytest.raises(ValueError, match="must be > 0"):
        gym.make("SoftArm/OctArmReach-v0", actuation="lag", pressure_time_constant_s=0.0)
    from softarm_gym.vector import BatchedReachVectorEnv
    with pytest.raises(ValueError, match="actuation='lag'"):
        BatchedReachVectorEnv(num_envs=2, actuation="lag")


def test_delta_actions_increment_the_command_under_lag():
    env = gym.make("SoftArm/OctArmReach-v0", actuation="lag", action_mode="delta", delta_scale=0.1,
                   initial_pressure_fraction=0.0)
    env.reset(seed=0)
    for k in range(1, 4):
        _, _, _, _, info = env.step(np.ones(6, dtype=np.float32))
        np.testing.assert_allclose(info["commanded_pressures_pa"], 0.1 * k * env.unwrapped.p_max, rtol=1e-9)
    assert np.all(info["pressures_pa"] < info["commanded_pressures_pa"])
