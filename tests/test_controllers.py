"""The damped-least-squares Jacobian controller."""

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401
from baselines.evaluate import evaluate
from softarm_gym.controllers import (
    CEMPlanner,
    CurlController,
    JacobianController,
    distinct_scores,
    observation_slices,
)


def test_observation_slices_match_the_dict_layout():
    flat = gym.make("SoftArm/OctArmReach-v0")
    as_dict = gym.make("SoftArm/OctArmReach-v0", observation_format="dict")
    obs, _ = flat.reset(seed=2)
    blocks, _ = as_dict.reset(seed=2)
    slices = observation_slices(flat)
    assert slices == flat.unwrapped.observation_slices
    assert list(slices) == list(blocks)
    for name, block in blocks.items():
        np.testing.assert_array_equal(obs[slices[name]], block)


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0"])
def test_controller_reaches_targets_with_true_observations(env_id):
    result = evaluate(controller="jacobian", env_id=env_id, episodes=3, seed=11)
    assert result["success_rate"] == 1.0
    assert result["p95_final_error_m"] < 0.02


def test_delta_actions_move_towards_the_target():
    env = gym.make("SoftArm/OctArmReach-v0", action_mode="delta", delta_scale=0.1)
    ctrl = JacobianController(env)
    obs, info = env.reset(seed=4)
    start = info["distance"]
    for _ in range(30):
        action = ctrl.act(obs)
        assert action.dtype == np.float32 and np.all(np.abs(action) <= 1.0)
        obs, _, _, _, info = env.step(action)
    assert info["distance"] < min(start, 0.02)


def test_bad_arguments_are_named():
    env = gym.make("SoftArm/CTReach-v0")
    with pytest.raises(ValueError, match="damping"):
        JacobianController(env, damping=0.0)
    with pytest.raises(ValueError, match="max_step"):
        JacobianController(env, max_step=2.0)
    with pytest.raises(ValueError, match="observation_format='flat'"):
        JacobianController(gym.make("SoftArm/CTReach-v0", observation_format="dict"))


def _final_wrap(env, controller, seed, steps=60):
    obs, _ = env.reset(seed=seed)
    controller.reset()
    for _ in range(steps):
        obs, _, _, _, info = env.step(controller.act(obs))
    return info["wrap_angle_deg"]


@pytest.mark.parametrize("seed", [0, 3])
def test_curl_controller_curls_towards_the_disc(seed):
    env = gym.make("SoftArm/OctArmWrap-v0")
    ctrl = CurlController(env)
    chosen = _final_wrap(env, ctrl, seed)
    # The other side: flip the inputs after the controller has chosen them.
    obs, _ = env.reset(seed=seed)
    ctrl.reset()
    ctrl.act(obs)
    ctrl._inputs = 1.0 - ctrl._inputs
    for _ in range(59):
        obs, _, _, _, info = env.step(ctrl.act(obs))
    assert chosen > 180.0 > info["wrap_angle_deg"]


def test_curl_controller_curls_towards_the_cylinder_in_3d():
    """On the 3D wrap env the weights point the arm's bend at the object's heading: seed 0
    wraps past the id's 75°; the same weights turned half a turn about the arm (the channels
    facing the object pressed instead) wrap nothing."""
    env = gym.make("SoftArm/OctArmWrap3D-v0")
    ctrl = CurlController(env)
    assert _final_wrap(env, ctrl, 0, steps=30) > 75.0
    obs, _ = env.reset(seed=0)
    ctrl.reset()
    towards = ctrl._weights(obs)
    ctrl.bends = -ctrl.bends
    away = ctrl._weights(obs)
    assert np.argmax(towards) != np.argmax(away)
    for _ in range(30):
        obs, _, _, _, info = env.step(ctrl.act(obs))
    assert info["wrap_angle_deg"] == 0.0


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmWrap3D-v0", "SoftArm/OctArmWrap3D-v1"])
def test_planner_rolls_3d_wrap_candidates_through_a_3d_stepper(env_id):
    """A 3D wrap's Stepper takes the lean 3D contact path (with and without friction), but the
    contact batch is planar: the planner rolls the candidates through one 3D Stepper instead
    (it built a planar BatchStepper for the cylinder and raised)."""
    env = gym.make(env_id)
    planner = CEMPlanner(env, seed=0)
    obs, _ = env.reset(seed=0)
    for _ in range(2):
        action = planner.act(obs)
        assert env.action_space.contains(action)
        obs, _, _, _, info = env.step(action)
        assert info["converged"]
    assert planner._nominal.lean_contact and planner._batch is None
    assert planner._rollout.planar is False


def test_curl_controller_holds_after_a_rejected_command():
    env = gym.make("SoftArm/OctArmWrap-v0")
    ctrl = CurlController(env, ramp_steps=4)
    obs, _ = env.reset(seed=0)
    first = ctrl.step_fraction(obs)
    current = 0.5 * (obs[observation_slices(env)["pressures"]] + 1.0)
    assert np.all(first[ctrl._inputs > 0] >= current[ctrl._inputs > 0])
    # The env kept the old pressures (a rejected step): hold them, then halve the step.
    assert np.array_equal(ctrl.step_fraction(obs), current)
    assert ctrl._increment == pytest.approx(0.125)
    with pytest.raises(ValueError, match="ramp_steps"):
        CurlController(env, ramp_steps=0)
    with pytest.raises(ValueError, match="wrap environment"):
        CurlController(gym.make("SoftArm/CTReach-v0"))


def _planned_episode(env, planner, seed, steps):
    obs, info = env.reset(seed=seed)
    planner.reset()
    actions = []
    for _ in range(steps):
        actions.append(planner.act(obs))
        obs, _, _, _, info = env.step(actions[-1])
    return info, np.array(actions)


@pytest.mark.parametrize("env_id, action_mode", [("SoftArm/OctArmReach-v0", "absolute"),
                                                 ("SoftArm/CTReach-v0", "absolute"),
                                                 ("SoftArm/OctArmReach-v0", "delta")])
def test_planner_reaches_targets(env_id, action_mode):
    env = gym.make(env_id, action_mode=action_mode)
    planner = CEMPlanner(env)
    for seed in (0, 1, 2):
        info, _ = _planned_episode(env, planner, seed, 25)
        assert info["is_success"], (seed, info["distance"])


def test_planner_is_reproducible_and_wraps_round_the_disc():
    env = gym.make("SoftArm/OctArmWrap-v0")
    runs = [_planned_episode(env, CEMPlanner(env, seed=3), 1, 12) for _ in range(2)]
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    # The scripted full curl wraps this disc by 250 deg; the planner finds more.
    assert runs[0][0]["wrap_angle_deg"] > 270.0


def test_planner_tries_every_corner_and_escapes_the_s_curl():
    # OctArmWrap-v1 seed 2: the full curl towards the disc, one corner of the action box among
    # 64, wraps 348 deg in one step. A search drawing its corners at random missed it, settled
    # on an S-curl (section 1 curled one way, section 2 the other) that wraps ~95 deg and held.
    env = gym.make("SoftArm/OctArmWrap-v1")
    info, _ = _planned_episode(env, CEMPlanner(env, seed=2), 2, 2)
    assert info["is_success"] and info["wrap_angle_deg"] > 300.0, info["wrap_angle_deg"]
    stuck, _ = _planned_episode(env, CEMPlanner(env, seed=2, all_corners=False), 2, 2)
    assert stuck["wrap_angle_deg"] < 120.0


def test_planner_ramps_across_the_snap_of_a_rate_limited_wrap():
    # CTWrap-v2 seed 1: self-contact and delta actions (10 % of p_max per step). The default
    # planner looks ceil(1/0.1) = 10 steps ahead there, every corner held over them (a ramp
    # to a bang-bang command), and follows its best sequence without searching again until
    # the model succeeds. A search one step ahead without corners stalls near 25 deg.
    env = gym.make("SoftArm/CTWrap-v2")
    planner = CEMPlanner(env, seed=1)
    assert planner.horizon == 10 and planner.commit
    obs, info = env.reset(seed=1)
    searches, first = 0, None
    for step in range(1, 15):
        obs, _, _, _, info = env.step(planner.act(obs))
        searches += planner.last_searched
        if first is None and info["is_success"]:
            first = step
    assert info["is_success"] and first >= 9 and searches <= 2, \
        (info["wrap_angle_deg"], first, searches)
    greedy = CEMPlanner(env, seed=1, horizon=1, all_corners=False, commit=False)
    stuck, _ = _planned_episode(env, greedy, 1, 14)
    assert not stuck["is_success"], stuck["wrap_angle_deg"]


def test_planner_ramps_round_a_disc_where_one_step_stalls():
    # OctArmObstacleReach-v1 seed 14: the target lies behind a disc; every single rate-limited
    # step from the tip's way in front of it is farther from the target than holding, so the
    # one-step search holds 18 cm away. The target was drawn as the end of a straight pressure
    # ramp from the start (it is reachable); the planner's escape searches such ramps when a
    # search stalls, and reaches it.
    env = gym.make("SoftArm/OctArmObstacleReach-v1")
    assert CEMPlanner(env).escape and not CEMPlanner(gym.make("SoftArm/OctArmWrap-v2")).escape
    stuck, _ = _planned_episode(env, CEMPlanner(env, seed=14, escape=False), 14, 40)
    assert not stuck["is_success"] and stuck["distance"] > 0.1, stuck["distance"]
    info, _ = _planned_episode(env, CEMPlanner(env, seed=14), 14, 40)
    assert info["is_success"], info["distance"]


def test_planner_lifts_the_free_object_of_a_grasp_and_then_holds():
    # OctArmGrasp-v0 seed 1: one corner (channels I of section 1, II of section 2) lifts the
    # object 7 cm out of its forks, held by the arm alone; the planner's rollouts settle arm
    # and object together, with the object's mass the middle of the env's range.
    env = gym.make("SoftArm/OctArmGrasp-v0")
    planner = CEMPlanner(env, seed=1)
    info, actions = _planned_episode(env, planner, 1, 2)
    assert info["is_success"] and info["held"] and info["lift"] >= 0.03, info["lift"]
    assert not planner.last_searched  # the nominal state succeeds: it holds without searching
    np.testing.assert_array_equal(actions[0], actions[1])


def test_planner_bad_arguments_are_named():
    env = gym.make("SoftArm/OctArmReach-v0")
    with pytest.raises(ValueError, match="elites"):
        CEMPlanner(env, samples=4, elites=4)
    with pytest.raises(ValueError, match="horizon"):
        CEMPlanner(env, horizon=0)
    with pytest.raises(ValueError, match="all_corners"):
        CEMPlanner(env, all_corners="yes")
    with pytest.raises(ValueError, match="grasp_solves"):
        CEMPlanner(env, grasp_solves=0)
    with pytest.raises(ValueError, match="commit"):
        CEMPlanner(env, commit="yes")
    with pytest.raises(ValueError, match="escape"):
        CEMPlanner(env, escape="yes")
    with pytest.raises(ValueError, match="planar"):
        CEMPlanner(gym.make("SoftArm/OctArmReach-v0", planar=False))


def test_distinct_scores_rolls_each_sequence_out_once_and_scores_every_candidate():
    """Candidates equal after clipping (a corner drawn twice, a draw past the box's face) are
    scored once, in the order they first appear, and every candidate gets its sequence's score."""
    rng = np.random.default_rng(0)
    candidates = np.clip(2.0 * rng.standard_normal((12, 2, 3)), -1.0, 1.0)
    candidates[5] = candidates[1]
    candidates[9] = np.sign(candidates[9])
    candidates[11] = 3.0 * candidates[9]  # the same corner after clipping
    rolled = []

    def score(sequences, fraction):
        rolled.append(sequences.copy())
        return np.clip(sequences, -1.0, 1.0) @ np.array([1.0, 10.0, 100.0]) @ np.ones(2) + fraction

    scores = distinct_scores(score, candidates, 0.5)
    assert np.array_equal(scores, score(candidates, 0.5))
    (distinct,) = rolled[:1]
    assert len(distinct) == 10
    assert np.array_equal(distinct, candidates[[0, 1, 2, 3, 4, 6, 7, 8, 9, 10]])
