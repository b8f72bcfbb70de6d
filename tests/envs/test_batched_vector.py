"""The solve_batch-backed vector env matches the single ReachEnv, copy by copy."""

import numpy as np
import pytest

import solver
from softarm_gym.vector import BatchedReachVectorEnv


def test_observations_match_single_env_layout_and_values():
    env = BatchedReachVectorEnv(num_envs=3)
    obs, info = env.reset(seed=0)
    assert obs.shape == (3, env.single_observation_space.shape[0])
    assert env.observation_space.contains(obs)
    actions = np.random.default_rng(0).uniform(-1, 1, (3, 6)).astype(np.float32)
    obs, reward, terminated, truncated, info = env.step(actions)
    assert info["converged"].all()
    single = env._template
    for k in range(3):
        # The single env's observation of the same equilibrium: warm path from the start state.
        fraction = 0.5 * (np.clip(actions[k], -1, 1) + 1)
        eq = solver.solve(env.arm, fraction * single.p_max, env.scene)
        np.testing.assert_allclose(info["tip_true"][k], eq.tip, atol=1e-9)
        from softarm_gym.sensing.estimators import shape_from_equilibrium
        shape = shape_from_equilibrium(eq, single.n_backbone)
        single._shape, single._fraction, single._target = shape, fraction, info["target"][k]
        np.testing.assert_allclose(obs[k], single._observation(), atol=1e-5)
        distance = np.hypot(*(eq.tip - info["target"][k]))
        expected = -distance - single.control_weight * np.mean(fraction**2) + \
            (single.success_bonus if distance <= single.success_tolerance else 0.0)
        assert reward[k] == pytest.approx(expected, abs=1e-6)
        parts = sum(info[name][k] for name in ("reward_distance", "reward_control",
                                               "reward_success", "reward_solver"))
        assert reward[k] == pytest.approx(parts, abs=1e-12)


def test_same_seed_same_trajectory_and_autoreset():
    runs = []
    for _ in range(2):
        env = BatchedReachVectorEnv(num_envs=4, max_episode_steps=3)
        obs, _ = env.reset(seed=7)
        rng = np.random.default_rng(1)
        trace = [obs]
        for _ in range(4):
            obs, reward, term, trunc, info = env.step(rng.uniform(-1, 1, (4, 6)))
            trace += [obs, reward]
        runs.append(trace)
        assert trunc.sum() == 0 and "_final_obs" not in info  # step 4: fresh episodes
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)


def test_truncation_resets_in_the_same_step():
    env = BatchedReachVectorEnv(num_envs=2, max_episode_steps=2)
    env.reset(seed=3)
    env.step(np.zeros((2, 6)))
    obs, reward, term, trunc, info = env.step(np.zeros((2, 6)))
    assert trunc.all() and info["_final_obs"].all()
    assert (env._steps == 0).all()


def test_bad_input():
    with pytest.raises(ValueError, match="observation='true' only"):
        BatchedReachVectorEnv(num_envs=2, observation="load_cell")
    with pytest.raises(ValueError, match="does not support payload_kg"):
        BatchedReachVectorEnv(num_envs=2, payload_kg=0.1)
    with pytest.raises(ValueError, match="num_envs"):
        BatchedReachVectorEnv(num_envs=0)
    env = BatchedReachVectorEnv(num_envs=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="env 1, channel 's1_II\\+III' is not finite"):
        env.step(np.array([[0, 0, 0, 0, 0, 0], [0, np.nan, 0, 0, 0, 0]]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros((3, 6)))


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0"])
def test_make_vec_vector_entry_point(env_id):
    """The reach IDs register the batched env as their ``vector_entry_point``."""
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(envs, BatchedReachVectorEnv)
    assert envs.num_envs == 3 and envs.max_episode_steps == gym.spec(env_id).max_episode_steps
    assert envs.arm.name == gym.spec(env_id).kwargs["design"]
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (3, *envs.single_observation_space.shape)
    single = gym.make(env_id)
    assert envs.observation_slices == single.unwrapped.observation_slices
    np.testing.assert_allclose(obs[:, envs.observation_slices["goal"]][:, :2],
                               envs.reset(seed=0)[1]["target"], rtol=1e-6)  # float32 obs
    envs.close()
