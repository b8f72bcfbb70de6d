"""Track task: a reachable moving target, its observation and the tracking metrics."""

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401  (registers the IDs)


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmTrack-v0", "SoftArm/CTTrack-v0"])
def test_commanding_the_path_pressures_tracks_the_target(env_id):
    """The target is the tip of the arm driven along the path: an arm commanded the same
    pressures lands on it (after the first step, which leaves the start state)."""
    env = gym.make(env_id, max_episode_steps=60)
    base = env.unwrapped
    env.reset(seed=2)
    errors = []
    for step in range(1, 60):
        action = 2.0 * base.path_fraction(step) - 1.0
        _, _, _, _, info = env.step(action.astype(np.float32))
        assert info["converged"]
        errors.append(info["distance"])
    assert np.median(errors[1:]) < 1e-4 * base.arm.length  # float32 actions round the pressures
    moved = np.linalg.norm(np.diff([base.path_fraction(k) for k in range(60)], axis=0), axis=1)
    assert moved.max() < 2.0 * np.pi / base.segment_steps  # a smooth path


def test_goal_block_and_metrics():
    env = gym.make("SoftArm/OctArmTrack-v0", segment_steps=10)
    obs, info = env.reset(seed=0)
    goal = env.unwrapped.observation_slices["goal"]
    assert goal.stop - goal.start == 6
    distances = []
    previous = info["target"]
    for _ in range(15):
        obs, reward, _, _, info = env.step(np.zeros(6, dtype=np.float32))
        np.testing.assert_allclose(obs[goal][4:], info["target"] - previous, atol=1e-6)
        np.testing.assert_allclose(info["target_velocity"], info["target"] - previous, atol=1e-12)
        previous = info["target"]
        distances.append(info["distance"])
        assert reward == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward_")), abs=1e-12)
    assert info["tracking_rms_m"] == pytest.approx(np.sqrt(np.mean(np.square(distances))))
    assert info["tracking_max_m"] == pytest.approx(max(distances))


def test_bad_input():
    with pytest.raises(ValueError, match="segment_steps"):
        gym.make("SoftArm/OctArmTrack-v0", segment_steps=0)
    env = gym.make("SoftArm/OctArmTrack-v0")
    with pytest.raises(ValueError, match="target"):
        env.reset(seed=0, options={"target": (0.5, 0.0)})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.full(6, np.nan, dtype=np.float32))
