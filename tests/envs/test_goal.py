"""observation_format="goal": a goal env whose compute_reward is the step reward, relabelled."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import softarm_gym  # noqa: F401  (registers the IDs)

REACH_IDS = ("SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0")


@pytest.mark.parametrize("env_id", REACH_IDS)
def test_goal_format_passes_gymnasium_and_sb3_checks(env_id):
    """SB3's check_env runs its goal-env checks (Dict keys, compute_reward equals the step
    reward, single and batched) whenever compute_reward exists."""
    env = gym.make(env_id, observation_format="goal")
    assert list(env.observation_space.spaces) == ["observation", "achieved_goal", "desired_goal"]
    flat = gym.make(env_id)
    end = flat.unwrapped.observation_slices["goal"].start
    assert env.observation_space["observation"].shape == (end,)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped, warn=True)
    # The other formats are not goal envs: SB3 would run the goal checks on them and fail.
    assert not hasattr(flat.unwrapped, "compute_reward")
    assert not hasattr(gym.make(env_id, observation_format="dict").unwrapped, "compute_reward")


def _episode(env, seed, actions, options=None):
    obs, _ = env.reset(seed=seed, options=options)
    steps = []
    for a in actions:
        obs, reward, _, _, info = env.step(a)
        steps.append((obs, reward, info))
    return steps


def test_observation_is_the_flat_observation_without_its_goal_block():
    goal = gym.make("SoftArm/OctArmReach-v0", observation_format="goal", action_mode="delta")
    flat = gym.make("SoftArm/OctArmReach-v0", action_mode="delta")
    actions = np.random.default_rng(0).uniform(-1, 1, (6, 6))
    end = flat.unwrapped.observation_slices["goal"].start
    for (g, rg, _), (f, rf, i_f) in zip(_episode(goal, 4, actions), _episode(flat, 4, actions)):
        np.testing.assert_array_equal(g["observation"], f[:end])
        np.testing.assert_array_equal(g["achieved_goal"], i_f["tip_true"])
        np.testing.assert_array_equal(g["desired_goal"], i_f["target"])
        assert g["achieved_goal"].dtype == np.float64 and rg == rf


def test_relabelled_rewards_are_the_rewards_of_an_episode_with_that_target():
    """compute_reward(achieved_t, g, info_t) equals, bit for bit, the reward of step t of the
    same episode replayed with the target g (the start state is drawn before the target)."""
    env = gym.make("SoftArm/OctArmReach-v0", observation_format="goal", action_mode="delta",
                   success_tolerance=0.05, control_weight=0.5)
    actions = np.random.default_rng(1).uniform(-1, 1, (12, 6))
    steps = _episode(env, 7, actions)
    achieved = np.stack([obs["achieved_goal"] for obs, _, _ in steps])
    infos = [info for _, _, info in steps]
    # The episode's own goals: the step rewards, in one batched call and from an array of infos.
    own = env.unwrapped.compute_reward(achieved, np.stack([o["desired_goal"] for o, _, _ in steps]),
                                       np.array(infos))
    np.testing.assert_array_equal(own, [r for _, r, _ in steps])
    for k in (3, 8, 11):  # hindsight goals: where the tip went at step k
        goal = achieved[k]
        replay = _episode(env, 7, actions, options={"target": goal})
        relabelled = env.unwrapped.compute_reward(achieved, np.tile(goal, (len(steps), 1)), infos)
        np.testing.assert_array_equal(relabelled, [r for _, r, _ in replay])
        assert replay[k][2]["is_success"] and relabelled[k] == pytest.approx(
            infos[k]["reward_control"] + env.unwrapped.success_bonus + infos[k]["reward_solver"])
        assert env.unwrapped.compute_reward(achieved[k], goal, infos[k]) == replay[k][1]


def test_compute_reward_takes_vector_infos_and_reports_bad_input():
    env = gym.make("SoftArm/CTReach-v0", observation_format="goal").unwrapped
    achieved = np.zeros((3, 2))
    desired = np.array([[0.0, 0.0], [0.01, 0.0], [0.3, 0.4]])
    vector_info = {"reward_control": np.array([-0.1, -0.2, -0.3]),
                   "reward_solver": np.array([0.0, -1.0, 0.0])}
    np.testing.assert_array_equal(env.compute_reward(achieved, desired, vector_info),
                                  [0.0 - 0.1 + 1.0 + 0.0, -0.01 - 0.2 + 1.0 - 1.0, -0.5 - 0.3 + 0.0 + 0.0])
    # Leading batch dimensions are kept.
    assert env.compute_reward(achieved.reshape(3, 1, 2), desired.reshape(3, 1, 2),
                              np.array([[{"reward_control": 0.0, "reward_solver": 0.0}]] * 3)).shape == (3, 1)
    with pytest.raises(ValueError, match="copy_info_dict"):
        env.compute_reward(achieved, desired, [{}, {}, {}])
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        env.compute_reward(np.zeros((3, 3)), np.zeros((3, 3)), vector_info)
    with pytest.raises(ValueError, match="one dict per transition"):
        env.compute_reward(achieved, desired, [{"reward_control": 0.0, "reward_solver": 0.0}])


def test_goal_format_refuses_estimators_and_the_wrap_task():
    with pytest.raises(ValueError, match="needs observation='true'"):
        gym.make("SoftArm/OctArmReach-v0", observation_format="goal", observation="load_cell")
    with pytest.raises(ValueError, match="WrapEnv has no goal point"):
        gym.make("SoftArm/OctArmWrap-v0", observation_format="goal")


def test_sac_with_her_learns_on_the_goal_env():
    """SB3's HerReplayBuffer relabels through compute_reward with the stored infos."""
    env = gym.make("SoftArm/OctArmReach-v0", observation_format="goal", action_mode="delta",
                   max_episode_steps=20)
    model = SAC("MultiInputPolicy", env, learning_starts=40, batch_size=16, buffer_size=1000,
                replay_buffer_class=HerReplayBuffer,
                replay_buffer_kwargs={"copy_info_dict": True, "n_sampled_goal": 4,
                                      "goal_selection_strategy": "future"},
                policy_kwargs={"net_arch": [8]}, seed=0, device="cpu")
    model.learn(120)
    assert model.num_timesteps == 120 and model.replay_buffer.size() == 120
    samples = model.replay_buffer.sample(32)
    assert np.all(np.isfinite(samples.rewards.numpy()))
