"""The Dict observation format flattens to the flat format, block for block."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import FlattenObservation

import softarm_gym  # noqa: F401

IDS = [env_id for env_id in gym.registry if env_id.startswith("SoftArm/")]


@pytest.mark.parametrize("env_id", IDS)
def test_flattened_dict_observation_equals_the_flat_one(env_id):
    flat = gym.make(env_id)
    flattened = FlattenObservation(gym.make(env_id, observation_format="dict"))
    assert list(flattened.unwrapped.observation_space) == list(flat.unwrapped.observation_slices)
    assert flattened.observation_space == flat.observation_space
    obs_flat, _ = flat.reset(seed=3)
    obs_dict, _ = flattened.reset(seed=3)
    np.testing.assert_array_equal(obs_dict, obs_flat)
    rng = np.random.default_rng(0)
    for _ in range(3):
        action = rng.uniform(-1, 1, flat.action_space.shape).astype(np.float32)
        obs_flat, *_ = flat.step(action)
        obs_dict, *_ = flattened.step(action)
        np.testing.assert_array_equal(obs_dict, obs_flat)
