"""Env options: sensor synthesis only when the estimator reads sensors; construction-time checks."""

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401


@pytest.mark.parametrize("observation, expected", [("true", False), ("model", False),
                                                    ("load_cell", True), ("cable_encoder", True)])
def test_default_synthesis_follows_the_estimator(observation, expected):
    env = gym.make("SoftArm/OctArmReach-v0", observation=observation)
    _, info = env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(6, dtype=np.float32))
    assert bool(info["sensors"]) == expected
    if expected:
        assert info["sensors"]["encoder_lengths"].shape == (3, 2)


def test_forced_synthesis_and_invalid_request():
    env = gym.make("SoftArm/OctArmReach-v0", observation="true", synthesize_sensors=True)
    _, info = env.reset(seed=0)
    assert info["sensors"]["base_wrench"].shape == (3,)
    with pytest.raises(ValueError, match="synthesize_sensors cannot be False"):
        gym.make("SoftArm/OctArmReach-v0", observation="inclinometer", synthesize_sensors=False)


def test_wrap_object_too_large_is_a_constructor_error():
    with pytest.raises(ValueError, match="object_radius 5.0 m must be smaller"):
        gym.make("SoftArm/OctArmWrap-v0", object_radius=5.0)
