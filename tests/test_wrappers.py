"""CornerActions: the discrete corners of the pressure box."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import softarm_gym  # noqa: F401
from softarm_gym.wrappers import MAX_CORNER_INPUTS, CornerActions


def test_corners_are_the_binary_digits_of_the_action_channel_0_first():
    env = CornerActions(gym.make("SoftArm/OctArmWrap-v1"))
    n = env.unwrapped.n_inputs
    assert env.action_space == gym.spaces.Discrete(2 ** n)
    for k in (0, 1, 5, 2 ** n - 1):
        bits = [(k >> (n - 1 - c)) & 1 for c in range(n)]
        assert env.action(k).tolist() == [1.0 if b else -1.0 for b in bits]
    assert env.action(np.int64(3)).dtype == env.env.action_space.dtype


def test_wrapped_env_passes_both_checkers_without_warnings():
    env = CornerActions(gym.make("SoftArm/CTWrap-v1").unwrapped)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # Gymnasium's checker warns of any wrapper; what it checks still has to pass.
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=True)


def test_one_corner_held_wraps_a_disc_as_the_planner_does():
    """Channel II+III of every section at p_max (the corner the planner picks on seed 1) wraps the
    OctArmWrap-v1 disc past the 270° of success in one step; all channels vented leaves it."""
    env = CornerActions(gym.make("SoftArm/OctArmWrap-v1"))
    names = env.unwrapped.input_names
    n = len(names)
    channel_ii = sum(1 << (n - 1 - c) for c, name in enumerate(names) if name.endswith("II+III"))
    assert bin(channel_ii).count("1") == 3
    env.reset(seed=1)
    _, _, _, _, info = env.step(0)
    assert info["wrap_angle_deg"] == 0.0 and not info["is_success"]
    _, _, _, _, info = env.step(channel_ii)
    assert info["is_success"] and info["wrap_angle_deg"] > 270.0
    assert np.allclose(info["pressures_pa"] / env.unwrapped.p_max, (env.action(channel_ii) + 1.0) / 2.0)


@pytest.mark.parametrize("action", [-1, 64, 2.0, "3", [1, 2]])
def test_bad_actions_are_refused(action):
    env = CornerActions(gym.make("SoftArm/OctArmWrap-v1"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be an integer"):
        env.step(action)


def test_other_action_spaces_are_refused():
    with pytest.raises(ValueError, match="Box"):
        CornerActions(CornerActions(gym.make("SoftArm/CTWrap-v1")))
    wide = gym.make("SoftArm/OctArmReach-v1", planar=False)
    if wide.action_space.shape[0] > MAX_CORNER_INPUTS:
        with pytest.raises(ValueError, match="at most"):
            CornerActions(wide)
