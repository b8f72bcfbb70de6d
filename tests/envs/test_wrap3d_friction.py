"""What friction does and does not do for the hanging OctArm V's 3D wrap (``SoftArm/OctArmWrap3D-v1``,
docs/environments.md "3D wrap with friction (v1)"): the scripted curl's pressures, the same in
every run, wrapped with and without friction and with the arm's weight scaled."""

import gymnasium as gym
import pytest

from softarm_gym.benchmarks.wrap3d_limits import ENV_ID, curl_wrap

STEPS = 12
"""The curl ramps to its full pressures in 10 steps; on seeds 0 and 2 the wrap is settled two
steps later."""


def _curl_wrap(seed: int, **kwargs) -> float:
    return curl_wrap(seed, STEPS, **kwargs)


def test_registered_friction_and_sequential_actions():
    spec = gym.spec(ENV_ID)
    assert spec.kwargs["friction"] == 0.7 and spec.kwargs["planar"] is False
    assert spec.kwargs["action_mode"] == "delta" and spec.kwargs["delta_scale"] == 0.1
    assert "self_contact" not in spec.kwargs  # no self-contact in 3D (docs/design.md §9)
    assert gym.spec("SoftArm/OctArmWrap3D-v0").kwargs.get("friction", 0.0) == 0.0


def test_friction_holds_what_the_curl_has_wrapped():
    """Seed 2: frictionless, the curl loses part of its wrap as the arm slips on the cylinder
    (79° at the ninth step, 53° at rest); with μ = 0.7 it keeps its grip and more."""
    frictionless = _curl_wrap(2, friction=0.0)
    rubber = _curl_wrap(2)
    assert rubber >= frictionless + 20.0, (rubber, frictionless)


@pytest.mark.parametrize("friction", [0.0, 0.7, 2.0])
def test_the_arms_weight_not_the_friction_caps_the_3d_wrap(friction):
    """Seed 0: at full gravity the curl falls sideways off the cylinder below a third of a turn
    whatever μ (0: 78°, 0.7: 92°, 2: 93°); with a quarter of the arm's weight the same pressures
    wrap it past the planar 270°, with or without friction."""
    assert _curl_wrap(0, friction=friction) < 120.0
    assert _curl_wrap(0, friction=friction, gravity=9.81 / 4) > 270.0
