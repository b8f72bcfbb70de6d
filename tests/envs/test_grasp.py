"""The grasp task (``SoftArm/OctArmGrasp-v0``): a free object lifted out of its forks."""

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401  (registers the ids)
from solver.grasp import settle

ENV_ID = "SoftArm/OctArmGrasp-v0"


def _curl(env, seed, fractions):
    """Reset with ``seed`` and drive the inputs that curl towards the object (one side of every
    section) through ``fractions`` of p_max; the infos of the steps."""
    _, info = env.reset(seed=seed)
    side = 0 if info["object_center"][0] < 0 else 1  # channel I curls towards −x
    infos = [info]
    for fraction in fractions:
        f = np.zeros(env.unwrapped.n_inputs)
        f[side::2] = fraction
        infos.append(env.step(2 * f - 1)[4])
    return infos


@pytest.fixture(scope="module")
def lifted():
    env = gym.make(ENV_ID)
    infos = _curl(env, 1, [0.1 * k for k in range(1, 10)])
    return env, infos


def test_curl_lifts_the_object_out_of_its_forks_and_holds_it(lifted):
    env, infos = lifted
    base = env.unwrapped
    seat = base._seat
    before = infos[-2]
    # Pushed sideways while the wrap forms, the object stays in its forks: the walls take the
    # arm's push, the object is not held.
    assert not before["held"] and before["lift"] < base.fork_depth
    last = infos[-1]
    assert last["converged"] and last["held"] and last["is_success"]
    assert last["lift"] >= base.success_lift and last["wrap_angle_deg"] > 270
    np.testing.assert_array_equal(last["support_force"], [0.0, 0.0])
    # The arm alone carries it: its force on the object is the object's weight, upwards.
    weight = last["object_mass_kg"] * 9.81
    np.testing.assert_allclose(last["arm_force"], [0.0, weight], atol=1e-4 * (1 + weight))
    assert last["object_center"][1] - seat[1] == pytest.approx(last["lift"])
    assert last["grasp_margin_n"] > 0 and last["grasp_margins_n"].shape == (4,)
    assert last["grasp_margin_n"] == pytest.approx(last["grasp_margins_n"].min())


def test_reward_terms_sum_to_the_reward_and_lift_is_rewarded(lifted):
    env, _ = lifted
    base = env.unwrapped
    f = base._fraction  # hold the current pressures
    _, reward, _, _, info = env.step(2 * f - 1)
    terms = {k: v for k, v in info.items() if k.startswith("reward_")}
    assert set(terms) == {"reward_wrap", "reward_approach", "reward_penetration", "reward_control",
                          "reward_success", "reward_lift", "reward_margin", "reward_solver"}
    assert reward == pytest.approx(sum(terms.values()))
    assert terms["reward_lift"] == pytest.approx(base.lift_weight)
    assert terms["reward_success"] == base.success_bonus and terms["reward_margin"] == 0.0


def test_holding_the_pressures_keeps_the_state_settle_would_return(lifted):
    # A hold moves nothing, so the env keeps the state without a solve: settling arm and object
    # from it at the same pressures returns that state (here bit for bit; elsewhere to round-off).
    env, _ = lifted
    base = env.unwrapped
    before = base._grasp
    again = settle(base._sim_arm, before.arm.pressures, base._settler.scene, base._object,
                   center=before.center, warm_start=before.arm, model=base.model)
    assert again.converged and again.held == before.held and again.stable == before.stable
    np.testing.assert_array_equal(again.center, before.center)
    np.testing.assert_array_equal(again.arm.positions, before.arm.positions)
    np.testing.assert_array_equal(again.stiffness, before.stiffness)
    _, _, _, _, info = env.step(2 * base._fraction - 1)
    assert base._grasp is before and info["converged"]


def test_observation_goal_holds_the_moving_centre_and_the_seat(lifted):
    env, infos = lifted
    base = env.unwrapped
    obs = base._observation()
    goal = obs[base.observation_slices["goal"]]
    np.testing.assert_allclose(goal[:2], infos[-1]["object_center"], atol=1e-6)
    np.testing.assert_allclose(goal[2], infos[-1]["contact_radius"], atol=1e-6)
    np.testing.assert_allclose(goal[3:], base._seat, atol=1e-6)


def test_margin_reward_is_the_margin_in_object_weights():
    env = gym.make(ENV_ID, margin_weight=2.0)
    info = _curl(env, 1, [0.1 * k for k in range(1, 10)])[-1]
    weight = info["object_mass_kg"] * 9.81
    assert info["held"]
    assert info["reward_margin"] == pytest.approx(2.0 * min(info["grasp_margin_n"] / weight, 1.0))


def test_v1_leaves_the_margin_out_unless_asked():
    """v1 registers ``margin_directions=0`` (an info field that cost seconds per held state);
    the kwarg brings it back."""
    env = gym.make("SoftArm/OctArmGrasp-v1")
    assert env.unwrapped.margin_directions == 0
    _, info = env.reset(seed=0)
    assert "grasp_margin_n" not in info and info["reward_margin"] == 0.0
    _, info = gym.make("SoftArm/OctArmGrasp-v1", margin_directions=4).reset(seed=0)
    assert info["grasp_margin_n"] == 0.0 and info["grasp_margins_n"].shape == (4,)  # not held


def test_without_margin_directions_the_margin_is_not_worked_out(monkeypatch):
    """The lifted fixture's curl with ``margin_directions=0``: held, and no margin worked out
    (the solver's function is not called) or reported."""
    import softarm_gym.envs.grasp as grasp_module

    def refuse(*args, **kwargs):
        raise AssertionError("grasp_margin called with margin_directions=0")

    monkeypatch.setattr(grasp_module, "grasp_margin", refuse)
    infos = _curl(gym.make(ENV_ID, margin_directions=0), 1, [0.1 * k for k in range(1, 10)])
    assert infos[-1]["held"]
    assert not any("grasp_margin_n" in info or "grasp_margins_n" in info for info in infos)


def test_resting_object_is_not_held_and_sinks_by_its_weight():
    env = gym.make(ENV_ID)
    _, info = env.reset(seed=3)
    assert not info["held"] and not info["is_success"] and info["grasp_margin_n"] == 0.0
    weight = info["object_mass_kg"] * 9.81
    np.testing.assert_allclose(info["support_force"], [0.0, weight], atol=1e-6)
    assert info["lift"] == pytest.approx(-weight / 1e5)


@pytest.mark.parametrize("kwargs, match", [
    ({"contact_stiffness": "rigid"}, "penalty contact"),
    ({"model": "constant_curvature"}, "constant-curvature"),
    ({"success_lift": 0.01}, "success_lift"),
    ({"margin_weight": 1.0, "margin_directions": 0}, "margin_directions"),
    ({"object_mass_kg": (0.0, 0.1)}, "object_mass_kg"),
    ({"fork_depth": 0.0}, "fork_depth"),
    ({"margin_directions": 1.5}, "margin_directions"),
])
def test_bad_arguments_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make(ENV_ID, **kwargs)


def test_v1_is_sequential_self_contacting_and_frictional_and_its_planner_knows_it():
    """OctArmGrasp-v1 registers v0's task with the recommended versions' physics (self-contact,
    delta actions at 10 % of p_max) and μ = 0.7 between arm and object; the planner's model
    object carries the env's μ (a frictionless model would plan cups a frictional arm does
    not make)."""
    from softarm_gym.controllers import CEMPlanner

    env = gym.make("SoftArm/OctArmGrasp-v1")
    base = env.unwrapped
    assert base.friction == 0.7 and base.self_contact > 0
    assert base.action_mode == "delta" and base.delta_scale == 0.1
    v0 = gym.make(ENV_ID).unwrapped
    assert v0.friction == 0.0 and v0.self_contact is None and v0.action_mode == "absolute"
    assert (base.object_mass_range, base.fork_depth, base.success_lift) == \
        (v0.object_mass_range, v0.fork_depth, v0.success_lift)
    obs, info = env.reset(seed=0)
    assert info["object_mass_kg"] > 0
    planner = CEMPlanner(env, seed=0)
    planner._track(obs, 0.5 * (obs[planner._slices["pressures"]] + 1.0))
    assert planner._settler.obj.friction == 0.7
    env.close()
