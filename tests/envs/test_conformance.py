"""Every registered ID in every observation mode is a well-formed Gymnasium / SB3 environment."""

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import softarm_gym  # noqa: F401  (registers the IDs)
from softarm_gym.envs import OBSERVATION_FORMATS
from softarm_gym.sensing import ESTIMATORS

ENV_IDS = tuple(env_id for env_id in gym.registry if env_id.startswith("SoftArm/"))


def test_all_ids_registered():
    assert set(ENV_IDS) >= {"SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0"}
    for env_id in ENV_IDS:
        assert gym.spec(env_id).max_episode_steps > 0


@pytest.mark.parametrize("observation", ESTIMATORS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env(env_id, observation):
    env = gym.make(env_id, observation=observation, sensor_noise="thesis")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=False)
        sb3_check_env(env.unwrapped, warn=True)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_dict_observations(env_id):
    env = gym.make(env_id, observation_format="dict")
    assert isinstance(env.observation_space, gym.spaces.Dict)
    # Obstacle reach adds the discs' block.
    extra = {"obstacles"} if "ObstacleReach" in env_id else set()
    base = {"tip", "section_ends", "backbone", "pressures", "goal"}
    assert set(env.observation_space.spaces) == base | extra
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_check_env_passes_on_what_gym_make_returns_in_every_format(env_id):
    """Users call ``check_env(gym.make(id, ...))``, wrappers and all: with the goal format SB3
    calls ``compute_reward`` on that env (:class:`softarm_gym.wrappers.GoalAPI` forwards it).
    The goal format is the reach and track tasks' (a target point); the others refuse it in one
    line naming the formats they have."""
    assert gym.spec(env_id).additional_wrappers[-1].entry_point == "softarm_gym.wrappers:GoalAPI"
    for observation_format in OBSERVATION_FORMATS:
        try:
            env = gym.make(env_id, observation_format=observation_format)
        except ValueError as exc:
            assert observation_format == "goal" and "'flat' or 'dict'" in str(exc), exc
            continue
        assert hasattr(env, "compute_reward") == (observation_format == "goal")
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            sb3_check_env(env, warn=True)
        env.close()


def test_vector_entry_point_and_sync_vectors_still_build_with_the_goal_wrapper_registered():
    batched = gym.make_vec("SoftArm/OctArmReach-v1", num_envs=2, vectorization_mode="vector_entry_point")
    sync = gym.make_vec("SoftArm/OctArmReach-v1", num_envs=2, vectorization_mode="sync")
    obs_b, _ = batched.reset(seed=3)
    obs_s, _ = sync.reset(seed=3)
    np.testing.assert_array_equal(obs_b, obs_s)


def _rollout(env, seed, n_steps, action_seed=7):
    obs, info = env.reset(seed=seed)
    env.action_space.seed(action_seed)
    trace = [(obs, 0.0, info["tip_true"])]
    for _ in range(n_steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        trace.append((obs, reward, info["tip_true"]))
    return trace


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_same_trajectory(env_id):
    kwargs = dict(sensor_noise={"encoder_resolution": 0.01, "gaussian_std": 1.0},
                  payload_kg=(0.0, 0.3), randomization={"wind_angle_deg": 2.0, "youngs_modulus_rel": 0.1},
                  observation="constant_curvature")
    first = _rollout(gym.make(env_id, **kwargs), seed=3, n_steps=6)
    second = _rollout(gym.make(env_id, **kwargs), seed=3, n_steps=6)
    other = _rollout(gym.make(env_id, **kwargs), seed=4, n_steps=6)
    for (o1, r1, t1), (o2, r2, t2) in zip(first, second):
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2
        np.testing.assert_array_equal(t1, t2)
    assert not np.array_equal(first[0][0], other[0][0])


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_pickled_env_continues_identically(env_id):
    env = gym.make(env_id, sensor_noise={"gaussian_std": 1.0, "encoder_resolution": 0.01},
                   observation="constant_curvature", render_mode="rgb_array").unwrapped
    env.reset(seed=11)
    env.step(env.action_space.sample())
    env.render()  # a live renderer must not stop the env from pickling
    clone = pickle.loads(pickle.dumps(env))
    action = np.linspace(-1, 1, env.action_space.shape[0])
    a = env.step(action)
    b = clone.step(action)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1] == b[1]
    assert clone.render().shape == env.render().shape


def _vector_rollout(vec, n_steps):
    obs, _ = vec.reset(seed=[1, 2])
    rewards = []
    for k in range(n_steps):
        actions = np.stack([np.full(vec.single_action_space.shape, np.sin(k + i)) for i in range(2)])
        obs, reward, terminated, truncated, info = vec.step(actions)
        rewards.append(reward)
        assert info["tip_true"].shape == (2, vec.get_attr("dim")[0])
    return obs, np.array(rewards)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sync_and_async_vector_envs_agree(env_id):
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(env_id) for _ in range(2)])
    obs_sync, rewards_sync = _vector_rollout(sync, 5)
    sync.close()
    async_ = gym.vector.AsyncVectorEnv([lambda: gym.make(env_id) for _ in range(2)])
    try:
        obs_async, rewards_async = _vector_rollout(async_, 5)
    finally:
        async_.close()
    np.testing.assert_array_equal(obs_sync, obs_async)
    np.testing.assert_array_equal(rewards_sync, rewards_async)
