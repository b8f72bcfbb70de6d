"""Env options: sensor synthesis only when the estimator reads sensors; construction-time checks."""

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401
from solver import layout as L
from tests.solver.test_self_contact import far_gap


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


def test_self_contact_keeps_the_curled_arm_out_of_itself():
    """Channels I at full pressure curl OctArm V past a full turn: with ``self_contact`` the
    env's arm stops on itself (the overlap is the penalty's give), without it passes through."""
    gaps = {}
    for self_contact in (False, True):
        env, eq = _curled(self_contact=self_contact)
        gaps[self_contact] = far_gap(eq, env.unwrapped.arm)
    assert gaps[False] < -0.02 and -0.005 < gaps[True] < 0.0


def _curled(**kwargs):
    """OctArmReach-v0 (base horizontal) curled past a full turn by three full-pressure steps of
    channel I: the env and its equilibrium; every step converged."""
    env = gym.make("SoftArm/OctArmReach-v0", base_angle_deg=0.0, **kwargs)
    env.reset(seed=0)
    action = np.tile(np.array([1.0, -1.0], dtype=np.float32), 3)
    for _ in range(3):
        _, _, _, _, info = env.step(action)
        assert info["converged"]
    return env, env.unwrapped._stepper.equilibrium


@pytest.mark.parametrize("kwargs, match", [
    ({"self_contact": -1.0}, "self_contact"),
    ({"self_contact": "yes"}, "self_contact"),
    ({"self_contact": True, "planar": False}, "planar=True"),
    ({"self_contact": True, "model": "constant_curvature"}, "planar=True and model"),
    ({"self_contact": True, "self_friction": -0.1}, "self_friction"),
    ({"self_contact": True, "self_friction": float("nan")}, "self_friction"),
    ({"self_friction": 0.5}, "self_friction = 0.5 needs self_contact"),
])
def test_self_contact_argument_is_checked(kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make("SoftArm/OctArmReach-v0", **kwargs)


def test_self_friction_reaches_the_scene_and_acts():
    """``self_friction`` is the scene's (``Scene.self_friction``); the curled arm then presses
    on itself with friction: its self-contact samples touch and carry impulses. Default 0."""
    _, eq = _curled(self_contact=True, self_friction=0.5)
    assert eq.scene.self_friction == 0.5
    fs = eq.self_friction_samples
    assert np.isfinite(fs[..., L.FS_NEW]).any() and np.abs(fs[..., L.FS_F:L.FS_F + 2]).max() > 0.0
    assert gym.make("SoftArm/OctArmWrap-v2").unwrapped.self_friction == 0.0
