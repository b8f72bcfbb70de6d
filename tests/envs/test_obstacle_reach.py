"""Reach among obstacles: reachable targets, disc placement, contact modes, rewards, arguments."""

import copy
import math

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401  (registers the IDs)
from softarm_gym.controllers import CEMPlanner
from softarm_gym.envs import ObstacleReachEnv
from softarm_gym.envs.obstacle import total_contact_force
from softarm_gym.render import OBJECT_COLOUR
from tests.frames import has_colour

IDS = ("SoftArm/OctArmObstacleReach-v0", "SoftArm/CTObstacleReach-v0")


def _clearances(env, info):
    """Gaps (m) from base, target and current backbone to every disc's contact circle."""
    n = info["n_obstacles"]
    discs, contact = info["obstacles"][:n], info["contact_radii"][:n]
    centres = discs[:, :2]
    base = np.hypot(*centres.T) - contact
    target = np.hypot(*(centres - info["target"]).T) - contact
    backbone = np.array([np.hypot(*(env._eq.positions - c).T).min() for c in centres]) - contact
    return base, target, backbone


@pytest.mark.parametrize("action_mode", ["delta", "absolute"])
@pytest.mark.parametrize("contact", ["penalize", "forbid"])
@pytest.mark.parametrize("env_id", IDS)
def test_targets_are_reachable_with_the_discs_in_place(env_id, contact, action_mode):
    env = gym.make(env_id, contact=contact, action_mode=action_mode).unwrapped
    for seed in range(3):
        _, info = env.reset(seed=seed)
        assert env._scene.obstacles and len(env._scene.obstacles) == info["n_obstacles"]
        # Ramping the pressures straight from the start to the target pressures, in the
        # fewest steps the action mode allows, lands on the target in the scene with the
        # discs (leaning on a disc only where contact is allowed).
        start = env._eq.pressures / env.p_max
        change = env.target_pressures_pa / env.p_max - start
        if action_mode == "absolute":
            actions = [2.0 * (start + change) - 1.0]
        else:
            n = math.ceil(np.max(np.abs(change)) / env.delta_scale - 1e-9)
            actions = [change / (n * env.delta_scale)] * n
        for action in actions:
            _, _, _, _, info = env.step(action)
            assert info["converged"] and not info["contact_rejected"]
        assert info["is_success"] and info["distance"] < 1e-4
        if contact == "forbid":
            assert not info["in_contact"]


@pytest.mark.parametrize("env_id", IDS)
def test_discs_stand_clear_of_base_target_and_start(env_id):
    env = gym.make(env_id).unwrapped
    lo, hi = env.n_obstacles_range
    counts = set()
    for seed in range(6):
        obs, info = env.reset(seed=seed)
        n = info["n_obstacles"]
        counts.add(n)
        assert lo <= n <= hi
        assert info["obstacles"].shape == (hi, 3) and np.all(info["obstacles"][n:] == 0.0)
        discs = info["obstacles"][:n]
        r_lo, r_hi = env.obstacle_radius_range
        assert np.all((r_lo <= discs[:, 2]) & (discs[:, 2] <= r_hi))
        np.testing.assert_allclose(info["contact_radii"][:n], discs[:, 2] + env.half_thickness)
        assert np.all(info["contact_radii"][n:] == 0.0)
        for gaps in _clearances(env, info):
            assert np.all(gaps >= env.clearance - 1e-9)
        assert not info["in_contact"] and info["contact_force"] == 0.0
        block = obs[env.observation_slices["obstacles"]].reshape(env.max_obstacles, 3)
        np.testing.assert_allclose(block, np.column_stack([info["obstacles"][:, :2], info["contact_radii"]]),
                                   atol=1e-6)
    assert counts == {1, 2}


def test_observation_has_an_obstacle_block_before_the_goal():
    env = ObstacleReachEnv(n_obstacles=(1, 3))
    names = list(env.observation_slices)
    assert names == ["tip", "section_ends", "backbone", "pressures", "obstacles", "goal"]
    assert env.observation_slices["obstacles"].stop - env.observation_slices["obstacles"].start == 9
    assert env.observation_slices["goal"].stop == env.observation_space.shape[0]


def _touching_step(env_id=IDS[0], **kwargs):
    """An env (absolute actions: jumps that touch more often) just reset and a random action
    whose step touches a disc (tried on a copy): ``(env, obs, action, info of that step on
    the copy)``."""
    env = gym.make(env_id, action_mode="absolute", **kwargs).unwrapped
    rng = np.random.default_rng(0)
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        for action in rng.uniform(-1.0, 1.0, (20, env.n_inputs)):
            info = copy.deepcopy(env).step(action)[4]
            if info["in_contact"] or info["contact_rejected"]:
                return env, obs, action, info
    raise AssertionError("no seed in 0-19 with a random action that touches a disc")


def test_penalized_contact_costs_the_contact_force_and_terms_sum():
    env, _, action, touched = _touching_step(contact_weight=0.5)
    assert touched["contact_force"] > 0.0 and touched["penetration"] > 0.0
    names = ["reward_distance", "reward_control", "reward_success", "reward_contact", "reward_solver"]
    rng = np.random.default_rng(1)
    for a in [action, *rng.uniform(-1, 1, (4, env.n_inputs))]:
        _, r, _, _, info = env.step(a)
        assert [k for k in info if k.startswith("reward_")] == names
        assert sum(info[k] for k in names) == r
        assert info["reward_contact"] == -0.5 * info["contact_force"]
        assert info["contact_force"] == total_contact_force(env._eq)
        assert (info["contact_force"] > 0) == info["in_contact"]


def test_forbidden_contact_rejects_the_step_and_keeps_the_state():
    env, _, action, touched = _touching_step(contact="forbid", contact_penalty=2.0)
    before = env._eq
    _, reward, terminated, truncated, info = env.step(action)
    assert info["contact_rejected"] and info["converged"]
    assert info["reward_contact"] == -2.0
    assert info["contact_force"] == touched["contact_force"] > 0.0
    np.testing.assert_array_equal(info["tip_true"], before.tip)
    np.testing.assert_array_equal(info["pressures_pa"], before.pressures)
    assert not info["in_contact"] and not terminated and not truncated
    assert info["solver_failures"] == 0 and info["reward_solver"] == 0.0
    # The episode goes on: a step to the start's pressures is accepted.
    _, _, _, _, info = env.step(2.0 * before.pressures / env.p_max - 1.0)
    assert not info["contact_rejected"] and info["reward_contact"] == 0.0


@pytest.mark.parametrize("kwargs, match", [
    ({"n_obstacles": 0}, "n_obstacles must be .* got 0"),
    ({"n_obstacles": (2, 1)}, r"n_obstacles .* got \(2, 1\)"),
    ({"n_obstacles": 1.5}, "n_obstacles .* got 1.5"),
    ({"obstacle_radius": 0.0}, "obstacle_radius must be > 0 .* got 0.0"),
    ({"obstacle_radius": -0.1}, "obstacle_radius must be >= 0.0; got -0.1"),
    ({"obstacle_radius": 0.5}, "obstacle_radius 0.5 m must be smaller"),
    ({"clearance": math.nan}, "clearance must be a finite number; got nan"),
    ({"contact": "avoid"}, "unknown contact 'avoid'"),
    ({"contact_weight": -1.0}, "contact_weight must be >= 0.0; got -1.0"),
    ({"contact_stiffness": 0.0}, "contact_stiffness must be > 0 .* got 0.0"),
    ({"planar": False}, "planar only"),
    ({"observation_format": "goal"}, "no goal-conditioned format"),
])
def test_bad_arguments_name_the_value(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ObstacleReachEnv(**kwargs)


def test_reset_options_fix_target_and_discs():
    env = ObstacleReachEnv()
    _, drawn = env.reset(seed=0)
    n = drawn["n_obstacles"]
    options = {"target": tuple(drawn["target"]), "obstacles": [tuple(d) for d in drawn["obstacles"][:n]]}
    _, info = env.reset(seed=5, options=options)
    np.testing.assert_array_equal(info["target"], drawn["target"])
    np.testing.assert_array_equal(info["obstacles"], drawn["obstacles"])
    assert env.target_pressures_pa is None
    with pytest.raises(ValueError, match=r"options\['obstacles'\] must be 1 to 2 .* got \[\(0.3, 0.2\)\]"):
        env.reset(options={"obstacles": [(0.3, 0.2)]})
    with pytest.raises(ValueError, match="covers the base"):
        env.reset(options={"obstacles": [(0.01, 0.0, 0.05)]})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"disc": (0.1, 0.1, 0.1)})


def test_make_vec_gives_the_batched_env():
    from softarm_gym.vector import BatchedObstacleReachVectorEnv

    for env_id in IDS:
        assert gym.spec(env_id).vector_entry_point == "softarm_gym.vector:BatchedObstacleReachVectorEnv"
    vec = gym.make_vec(IDS[1], num_envs=2)
    assert isinstance(vec, BatchedObstacleReachVectorEnv)
    obs, _ = vec.reset(seed=[0, 1])
    assert obs.shape == (2, *gym.make(IDS[1]).observation_space.shape)
    vec.close()


def test_planner_rolls_out_in_the_scene_with_the_discs():
    env = gym.make(IDS[0])
    obs, info = env.reset(seed=0)
    planner = CEMPlanner(env, samples=8, elites=2, iterations=1, seed=0)
    action = planner.act(obs)
    assert env.action_space.contains(action)
    discs = planner._nominal.scene.obstacles
    assert len(discs) == info["n_obstacles"]
    for disc, row, contact in zip(discs, info["obstacles"], info["contact_radii"]):
        np.testing.assert_allclose(disc.center, row[:2], atol=1e-6)
        assert disc.radius == pytest.approx(contact, abs=1e-6)
        assert disc.stiffness == env.unwrapped.contact_stiffness


def test_render_draws_the_discs():
    env = ObstacleReachEnv(render_mode="rgb_array", render_size=128)
    env.reset(seed=0)
    assert has_colour(env.render(), OBJECT_COLOUR)


@pytest.mark.parametrize("contact", ["penalize", "forbid"])
def test_planner_scores_an_action_as_the_env_rewards_it(contact):
    # Nominal arm, no payload: the planner's model is the simulated arm, so its rollout of a
    # touching action earns the env's reward for it (to the float32 rounding of the discs).
    env, obs, action, _ = _touching_step(contact=contact)
    planner = CEMPlanner(env, seed=0)
    fraction = 0.5 * (obs[env.observation_slices["pressures"]] + 1.0)
    planner._track(obs, fraction)
    np.testing.assert_allclose(planner._nominal.tip, env._eq.tip, atol=1e-6)
    score = planner._score_batch(np.asarray(action, dtype=float)[None, None], fraction)[0]
    _, reward, _, _, info = env.step(action)
    assert info["in_contact"] or info["contact_rejected"]
    assert score == pytest.approx(reward, rel=1e-3, abs=1e-4)


def _place_one_at_a_time(env, n, tip, target, avoid):
    """The plain reference of ``ObstacleReachEnv._place_discs``: each disc's placements drawn
    and tested one at a time, the first that fits taken."""
    from softarm_gym.envs.obstacle import DISC_ATTEMPTS, PLACEMENT_SPAN
    rng = env.np_random
    way = target - tip
    length = float(np.hypot(*way))
    across = np.array([-way[1], way[0]]) / length
    spread = 0.5 * length if env.contact == "forbid" else 0.0
    discs = np.empty((0, 3))
    points = np.vstack([np.zeros((1, 2)), target[None], avoid])

    def gap(p, d):
        return float(np.min(np.hypot(p[:, None, 0] - d[None, :, 0], p[:, None, 1] - d[None, :, 1])
                            - d[None, :, 2] - env.half_thickness))
    for _ in range(n):
        for _ in range(DISC_ATTEMPTS):
            radius = float(rng.uniform(*env.obstacle_radius_range))
            contact = radius + env.half_thickness
            offset = rng.uniform(-1.0, 1.0) * (contact + spread)
            center = tip + rng.uniform(*PLACEMENT_SPAN) * way + offset * across
            disc = np.array([[center[0], center[1], radius]])
            if gap(points, disc) < env.clearance:
                continue
            if len(discs) and gap(center[None], discs) - contact < env.clearance:
                continue
            discs = np.vstack([discs, disc])
            break
        else:
            return None
    return discs


@pytest.mark.parametrize("contact", ["penalize", "forbid"])
def test_disc_placement_is_the_one_at_a_time_loops_draw_for_draw(contact):
    """The placements tried at once take the same discs as the plain loop and leave the
    generator where it left it (so the rest of the episode is the same), placed or not."""
    env = gym.make("SoftArm/OctArmObstacleReach-v0", contact=contact).unwrapped
    env.reset(seed=0)
    cases = np.random.default_rng(1)
    outcomes = set()
    for seed in range(40):
        tip = cases.uniform(-0.3, 0.3, 2) + (0.0, -0.6)
        target = cases.uniform(-0.5, 0.5, 2)
        avoid = tip + cases.uniform(-0.2, 0.2, (30, 2))
        n = int(cases.integers(1, 4))
        env.np_random = np.random.default_rng(seed)
        placed = env._place_discs(n, tip, target, avoid)
        after = env.np_random.random()
        env.np_random = np.random.default_rng(seed)
        expected = _place_one_at_a_time(env, n, tip, target, avoid)
        assert (placed is None) == (expected is None)
        if placed is not None:
            np.testing.assert_array_equal(placed, expected)
        assert after == env.np_random.random()
        outcomes.add(placed is None)
    assert outcomes == {True, False}  # both placed and refused draws were met
