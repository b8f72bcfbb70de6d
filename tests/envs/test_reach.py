"""Reach task: reachable targets, success, reward shape."""

import numpy as np
import pytest

from softarm_gym.envs import ReachEnv


@pytest.mark.parametrize("design", ["octarm_v", "ct"])
def test_targets_come_from_solved_pressures_and_can_be_reached(design):
    env = ReachEnv(design, payload_kg=(0.0, 0.2), randomization={"youngs_modulus_rel": 0.1})
    for seed in range(6):
        _, info = env.reset(seed=seed)
        p = env.target_pressures_pa
        # Ramp the target pressures in from the start state along the quasi-static path.
        for frac in np.linspace(0.1, 1.0, 10):
            _, reward, terminated, _, info = env.step(2.0 * frac * p / env.p_max - 1.0)
        np.testing.assert_allclose(info["pressures_pa"], p, rtol=1e-12)
        assert info["distance"] < 1e-6
        assert info["is_success"] and info["reward_success"] == 1.0


def test_success_terminates_only_when_asked():
    env = ReachEnv("ct", terminate_on_success=True)
    _, info = env.reset(seed=0, options={"target": (0.1, -0.3)})
    assert env.target_pressures_pa is None
    tip = info["tip_true"]
    _, info = env.reset(seed=0, options={"target": tip})
    _, _, terminated, _, info = env.step(np.full(4, -1.0))  # keep ~the start pressures low
    assert info["is_success"] == (info["distance"] <= 0.02)
    assert terminated == info["is_success"]
    free = ReachEnv("ct")
    free.reset(seed=0, options={"target": tip})
    _, _, terminated, _, _ = free.step(np.full(4, -1.0))
    assert not terminated


def test_bad_target_option():
    env = ReachEnv("ct")
    with pytest.raises(ValueError, match="target"):
        env.reset(seed=0, options={"target": (np.nan, 0.0)})
    with pytest.raises(ValueError, match="target"):
        env.reset(seed=0, options={"target": "far"})


@pytest.mark.parametrize("target", [(100.0, 100.0), (0.0, -1.1)])
def test_unreachable_target_is_an_error_not_a_clipped_goal(target):
    """OctArm V is 0.83 m long, 1.03 m with every channel at 100 psi: 100 m is also outside the
    observation bounds (2 L), 1.1 m only beyond full stretch (plus the 2 cm tolerance)."""
    env = ReachEnv("octarm_v")
    with pytest.raises(ValueError, match=r"reaches at most 1\.049 m"):
        env.reset(seed=0, options={"target": target})
    _, info = env.reset(seed=0, options={"target": (0.0, -1.0)})  # within the stretched length
    np.testing.assert_array_equal(info["target"], [0.0, -1.0])


@pytest.mark.parametrize("options", [{"targte": (0.1, -0.3)}, {"target": (0.1, -0.3), "seed": 1}])
def test_unknown_reset_options_raise(options):
    env = ReachEnv("ct")
    with pytest.raises(ValueError, match="unknown reset option.*accepts 'target'"):
        env.reset(seed=0, options=options)
    with pytest.raises(ValueError, match="must be a dict"):
        env.reset(seed=0, options=[("target", (0.1, -0.3))])


def test_reward_decreases_with_distance():
    env = ReachEnv("octarm_v", control_weight=0.0, success_bonus=0.0)
    env.reset(seed=0, options={"target": (0.5, 0.0)})
    rewards = {}
    for name, action in (("low", -np.ones(6)), ("curl", np.array([-1, 1, -1, 1, -1, 1.0]))):
        _, reward, _, _, info = env.step(action)
        rewards[name] = (reward, info["distance"])
    (r1, d1), (r2, d2) = rewards.values()
    assert (r1 - r2) == pytest.approx(d2 - d1)
