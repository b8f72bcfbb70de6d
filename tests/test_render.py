"""Rendering: rgb_array frames show the arm, the estimate and the task; human mode opens a window."""

import numpy as np
import pytest

from softarm_gym.envs import ReachEnv
from softarm_gym.render import ESTIMATE_COLOUR, TARGET_COLOUR, TRUE_COLOUR, ArmRenderer
from tests.frames import has_colour


def test_rgb_array_frame_shows_truth_estimate_and_target():
    env = ReachEnv("octarm_v", observation="constant_curvature", payload_kg=0.4,
                   render_mode="rgb_array", render_size=200)
    env.reset(seed=0)
    env.step(np.array([0.5, -1, 0.5, -1, 0.5, -1]))
    frame = env.render()
    assert frame.shape == (200, 200, 3) and frame.dtype == np.uint8
    assert has_colour(frame, TRUE_COLOUR) and has_colour(frame, ESTIMATE_COLOUR)
    assert has_colour(frame, TARGET_COLOUR)
    second = env.render()
    np.testing.assert_array_equal(frame, second)
    env.step(np.ones(6))
    assert not np.array_equal(env.render(), frame)
    env.close()


def test_render_without_mode_returns_none():
    env = ReachEnv("ct")
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_human_mode_opens_a_window():
    pytest.importorskip("pygame")
    env = ReachEnv("ct", render_mode="human", render_size=128)
    env.reset(seed=0)
    assert env.render() is None
    env.step(np.zeros(4))
    env.close()


def test_renderer_validates_its_arguments():
    with pytest.raises(ValueError, match="extent"):
        ArmRenderer(extent=0.0)
    with pytest.raises(ValueError, match="size"):
        ArmRenderer(extent=1.0, size=10)
