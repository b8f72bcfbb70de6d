"""The ``friction`` kwarg of every contact id (docs/design.md §9.1): validated, carried into
the obstacles the env builds, and the batched vector env's copies equal the single envs'."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import softarm_gym  # noqa: F401  (registers the ids)
from tests.test_vector import _same_as_sync

CONTACT_IDS = [i for i in gym.registry if i.startswith("SoftArm/")
               and any(k in i for k in ("Wrap", "ObstacleReach", "Grasp"))]


def test_every_contact_id_is_covered():
    assert len(CONTACT_IDS) >= 9


@pytest.mark.parametrize("env_id", CONTACT_IDS)
@pytest.mark.parametrize("value", [-0.5, float("nan"), float("inf")])
def test_bad_friction_is_refused_naming_it(env_id, value):
    with pytest.raises(ValueError, match="friction"):
        gym.make(env_id, friction=value)


@pytest.mark.parametrize("env_id", CONTACT_IDS)
def test_friction_reaches_the_obstacles(env_id):
    env = gym.make(env_id, friction=0.6)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    inner = env.unwrapped
    assert inner.friction == 0.6
    obstacles = inner.stepper.equilibrium.scene.obstacles
    assert obstacles and all(o.friction == 0.6 for o in obstacles)
    env.close()


def test_batched_wrap_copies_with_friction_are_the_single_envs():
    """The contact BatchStepper carries each copy's friction samples as the single env's
    Stepper does: every output equal, across autoresets, with copies in contact."""
    outs = _same_as_sync("SoftArm/OctArmWrap-v1", {"friction": 0.7}, AutoresetMode.SAME_STEP)
    infos = [o[4] for o in outs] + [o[4]["final_info"] for o in outs if "final_info" in o[4]]
    assert any(np.any(info["penetration"] > 0) for info in infos)
