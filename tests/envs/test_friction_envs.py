"""The ``friction`` kwarg of every contact id (docs/design.md §9.1): validated and carried
into the obstacles the env builds (the batched vector env's copies with friction are checked
against the single envs in tests/test_vector.py)."""

import gymnasium as gym
import pytest

import softarm_gym  # noqa: F401  (registers the ids)

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

