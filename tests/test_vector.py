"""The BatchedReachVectorEnv is, copy by copy and bit for bit, the single ReachEnv."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from softarm_gym.vector import BatchedReachVectorEnv


def _assert_same(a, b, where):
    """Recursive exact equality of vector-env outputs (arrays, dicts of arrays, object arrays
    of arrays or None)."""
    if isinstance(a, np.ndarray) and a.dtype == object:
        assert isinstance(b, np.ndarray) and b.dtype == object and a.shape == b.shape, where
        for i, (x, y) in enumerate(zip(a, b)):
            assert (x is None) == (y is None), f"{where}[{i}]"
            if x is not None:
                _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for key in a:
            _assert_same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, tuple):
        assert len(a) == len(b)
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{i}]")
    else:
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype, f"{where}: dtype {a.dtype} != {b.dtype}"
        np.testing.assert_array_equal(a, b, err_msg=where)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("env_id, kwargs", [
    ("SoftArm/OctArmReach-v0", {}),
    ("SoftArm/OctArmReach-v0", {"action_mode": "delta", "terminate_on_success": True,
                                "success_tolerance": 0.15}),
    ("SoftArm/CTReach-v0", {"payload_kg": 0.05, "base_angle_deg": 45.0}),
    ("SoftArm/OctArmReach-v0", {"planar": False}),
    ("SoftArm/CTReach-v0", {"planar": False, "action_mode": "delta", "base_angle_deg": 90.0}),
])
def test_copy_i_seeded_s_is_the_single_env_seeded_s_plus_i(env_id, kwargs, mode):
    """Observations, rewards, flags and infos (with SAME_STEP's final_obs and final_info)
    equal SyncVectorEnv's over the single env, bit for bit, across autoresets."""
    n, steps = 3, 9
    batched = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                           max_episode_steps=4, autoreset_mode=mode.value, **kwargs)
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": mode}, max_episode_steps=4, **kwargs)
    assert batched.metadata["autoreset_mode"] == mode
    _assert_same(batched.reset(seed=11), sync.reset(seed=11), "reset")
    rng = np.random.default_rng(5)
    ended = 0
    for t in range(steps):
        actions = rng.uniform(-1.2, 1.2, batched.action_space.shape).astype(np.float32)
        out_b, out_s = batched.step(actions), sync.step(actions)
        _assert_same(out_b, out_s, f"step {t}")
        ended += int(np.sum(out_b[2] | out_b[3]))
    assert ended >= n  # the episodes ended (and the copies were reset) along the way
    batched.close()
    sync.close()


def test_unseeded_reset_continues_each_copy_stream():
    a, b = BatchedReachVectorEnv(num_envs=2), BatchedReachVectorEnv(num_envs=2)
    a.reset(seed=3)
    b.reset(seed=[3, 4])
    assert a.np_random_seed == b.np_random_seed == (3, 4)
    _assert_same(a.reset(), b.reset(), "second reset")
    first = a.reset(seed=3)[1]["target"]
    assert not np.array_equal(first, a.reset()[1]["target"])


def test_gymnasium_vector_wrappers_accept_it():
    envs = gym.wrappers.vector.RecordEpisodeStatistics(
        gym.wrappers.vector.NormalizeObservation(
            BatchedReachVectorEnv(num_envs=2, max_episode_steps=2)))
    obs, _ = envs.reset(seed=0)
    finished = []
    for _ in range(5):
        obs, reward, term, trunc, info = envs.step(np.zeros((2, 6)))
        assert np.all(np.isfinite(obs))
        if "episode" in info:
            finished.append(info["_episode"].copy())
    assert finished and all(mask.all() for mask in finished)


def test_step_before_reset_and_bad_input():
    with pytest.raises(ValueError, match="does not support observation='load_cell'") as raised:
        BatchedReachVectorEnv(num_envs=2, observation="load_cell")
    assert "synthesize_sensors" not in str(raised.value)  # implied by the estimator, not asked for
    with pytest.raises(ValueError, match=r"observation='cable_encoder' \(estimators need per-copy sensing; "
                                         r"the batched env observes 'true'\): use gym.make_vec"):
        gym.make_vec("SoftArm/OctArmReach-v1", num_envs=2, vectorization_mode="vector_entry_point",
                     observation="cable_encoder")
    with pytest.raises(ValueError, match="does not support synthesize_sensors=True: use"):
        BatchedReachVectorEnv(num_envs=2, synthesize_sensors=True)
    with pytest.raises(ValueError, match="payload_kg range"):
        BatchedReachVectorEnv(num_envs=2, payload_kg=(0.0, 0.1))
    with pytest.raises(ValueError, match="randomization"):
        BatchedReachVectorEnv(num_envs=2, randomization={"youngs_modulus_rel": 0.1})
    with pytest.raises(ValueError, match="constant_curvature"):
        BatchedReachVectorEnv(num_envs=2, model="constant_curvature")
    with pytest.raises(ValueError, match="num_envs"):
        BatchedReachVectorEnv(num_envs=0)
    with pytest.raises(ValueError, match="autoreset_mode must be one of NextStep, SameStep"):
        BatchedReachVectorEnv(num_envs=2, autoreset_mode=AutoresetMode.DISABLED)
    env = BatchedReachVectorEnv(num_envs=2)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros((2, 6)))
    with pytest.raises(ValueError, match="reset options"):
        env.reset(seed=0, options={"target": (0.1, 0.2)})
    with pytest.raises(ValueError, match="seed"):
        env.reset(seed=[1, 2, 3])
    env.reset(seed=0)
    with pytest.raises(ValueError, match="env 1, channel 's1_II\\+III' is not finite"):
        env.step(np.array([[0, 0, 0, 0, 0, 0], [0, np.nan, 0, 0, 0, 0]]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros((3, 6)))


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0"])
def test_make_vec_vector_entry_point(env_id):
    """The reach IDs register the batched env as their ``vector_entry_point``."""
    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(envs, BatchedReachVectorEnv)
    assert envs.num_envs == 3 and envs.max_episode_steps == gym.spec(env_id).max_episode_steps
    assert envs.arm.name == gym.spec(env_id).kwargs["design"]
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, *envs.single_observation_space.shape)
    assert envs.observation_space.contains(obs)
    single = gym.make(env_id)
    assert envs.observation_slices == single.unwrapped.observation_slices
    envs.close()


@pytest.mark.parametrize("planar", [True, False])
def test_batches_run_on_threads_as_on_one(planar):
    """The batch gives the same bits whichever way its thread policies run it (forced each
    way here): planar, the step and cold kernels and the observation kernel; spatial, the
    copies' steppers on the pool."""
    runs = []
    for threaded in (False, True):
        env = BatchedReachVectorEnv(num_envs=6, planar=planar, max_episode_steps=3)
        policies = list(env._batch.thread_policies.values())
        if planar:
            policies.append(env._observe_policy)
        for policy in policies:
            policy.choose = lambda rows, t=threaded: t
        out = [env.reset(seed=2)]
        for k in range(4):
            out.append(env.step(np.full((6, env.single_action_space.shape[0]), np.sin(k))))
        runs.append(tuple(out))
        env.close()
    _assert_same(runs[0], runs[1], "threaded")
