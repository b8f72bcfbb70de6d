"""softarm_gym.sb3.BatchedVecEnv is, copy by copy and bit for bit, SB3's DummyVecEnv over the single env."""

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan, VecMonitor, VecNormalize

from softarm_gym.sb3 import BatchedVecEnv


def _assert_same(a, b, where):
    """Exact equality of SB3 outputs: arrays (dtype too), scalars (type too), dicts, lists."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for key in a:
            _assert_same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype, f"{where}: {a!r} != {b!r}"
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"


def _dummy(env_id, n, **kwargs):
    return DummyVecEnv([lambda: gym.make(env_id, **kwargs) for _ in range(n)])


@pytest.mark.parametrize("env_id, kwargs", [
    ("SoftArm/OctArmReach-v0", {"action_mode": "delta"}),
    ("SoftArm/CTReach-v0", {"terminate_on_success": True, "success_tolerance": 0.15}),
    ("SoftArm/CTTrack-v0", {"segment_steps": 3}),
    ("SoftArm/OctArmObstacleReach-v0", {}),
    ("SoftArm/OctArmWrap-v1", {}),
    ("SoftArm/OctArmWrap-v2", {"delta_scale": 1.0}),
    ("SoftArm/CTObstacleReach-v1", {}),
])
def test_copy_i_seeded_s_is_dummy_vec_env_copy_i_seeded_s_plus_i(env_id, kwargs):
    """Observations, rewards, dones, infos (terminal_observation, TimeLimit.truncated) and
    reset infos, across the auto-resets of finished copies."""
    n = 3
    batched = BatchedVecEnv(env_id, n, max_episode_steps=4, **kwargs)
    dummy = _dummy(env_id, n, max_episode_steps=4, **kwargs)
    assert batched.seed(21) == dummy.seed(21) == [21, 22, 23]
    _assert_same(batched.reset(), dummy.reset(), "reset")
    _assert_same(batched.reset_infos, dummy.reset_infos, "reset infos")
    rng = np.random.default_rng(2)
    ended = 0
    for t in range(9):
        actions = rng.uniform(-1, 1, (n, 6 if "Oct" in env_id else 4)).astype(np.float32)
        out_b, out_d = batched.step(actions), dummy.step(actions)
        _assert_same(list(out_b), list(out_d), f"step {t}")
        _assert_same(batched.reset_infos, dummy.reset_infos, f"reset infos after step {t}")
        ended += int(out_b[2].sum())
    assert ended >= n
    # Without a new seed() a reset continues each copy's stream, as DummyVecEnv's does.
    _assert_same(batched.reset(), dummy.reset(), "unseeded reset")


def test_options_reach_every_copy_alike():
    batched = BatchedVecEnv("SoftArm/OctArmWrap-v1", 2)
    dummy = _dummy("SoftArm/OctArmWrap-v1", 2)
    for venv in (batched, dummy):
        venv.seed(3)
        venv.set_options({"object": (0.2, -0.4, 0.1)})
    _assert_same(batched.reset(), dummy.reset(), "reset with options")
    _assert_same(batched.reset_infos, dummy.reset_infos, "reset infos")
    batched.set_options([{"object": (0.2, -0.4, 0.1)}, {}])
    with pytest.raises(ValueError, match="same options"):
        batched.reset()


def test_wrappers_and_sb3_nan_check():
    """VecMonitor counts whole episodes, VecNormalize normalises the terminal observation,
    and SB3's VecCheckNan sees no NaN or inf."""
    monitored = VecMonitor(BatchedVecEnv("SoftArm/OctArmReach-v0", 4, max_episode_steps=3),
                           info_keywords=("is_success", "distance"))
    venv = VecNormalize(VecCheckNan(monitored, raise_exception=True), norm_reward=False)
    venv.seed(0)
    obs = venv.reset()
    assert obs.shape == (4, venv.observation_space.shape[0]) and obs.dtype == np.float32
    for t in range(6):
        obs, rewards, dones, infos = venv.step(np.zeros((4, 6), dtype=np.float32))
        assert rewards.dtype == np.float32 and dones.dtype == bool
        assert dones.all() == (t % 3 == 2)
    for info in infos:
        assert info["episode"]["l"] == 3 and isinstance(info["is_success"], bool)
        assert info["TimeLimit.truncated"] and np.all(np.abs(info["terminal_observation"]) <= venv.clip_obs)
    venv.close()


def test_attributes_methods_and_refusals():
    venv = BatchedVecEnv("SoftArm/CTReach-v0", 3, success_tolerance=0.05)
    assert venv.get_attr("success_tolerance") == [0.05] * 3
    assert venv.get_attr("p_max", indices=[1]) == [gym.make("SoftArm/CTReach-v0").unwrapped.p_max]
    assert venv.has_attr("arm") and not venv.has_attr("no_such_attribute")
    assert venv.env_is_wrapped(gym.Wrapper) == [False] * 3
    venv.set_attr("success_tolerance", 0.5)  # every copy reads the shared configuration
    venv.seed(0)
    venv.reset()
    *_, infos = venv.step(np.zeros((3, 4)))
    assert all(info["is_success"] == (info["distance"] <= 0.5) for info in infos)
    assert venv.env_method("_solver_term", False) == [-1.0] * 3
    with pytest.raises(ValueError, match="all of them or none"):
        venv.set_attr("success_tolerance", 0.1, indices=[0])
    with pytest.raises(ValueError, match="would act on the shared template"):
        venv.env_method("reset")
    venv.set_options({"target": (0.1, -0.3)})
    with pytest.raises(ValueError, match="no reset options"):
        venv.reset()
    with pytest.raises(ValueError, match="no batched vector env"):
        BatchedVecEnv("SoftArm/OctArmWrap3D-v0", 2)
    with pytest.raises(ValueError, match="observation='load_cell'"):
        BatchedVecEnv("SoftArm/OctArmReach-v0", 2, observation="load_cell")
    with pytest.raises(RuntimeError, match="step_async"):
        venv.step_wait()


@pytest.mark.parametrize("algo, kwargs", [
    (PPO, {"n_steps": 16, "batch_size": 32, "n_epochs": 1}),
    (SAC, {"learning_starts": 32, "batch_size": 16, "buffer_size": 500, "gradient_steps": 2}),
])
def test_ppo_and_sac_learn_on_the_adapter(algo, kwargs):
    venv = VecNormalize(VecMonitor(BatchedVecEnv("SoftArm/OctArmReach-v0", 8, action_mode="delta",
                                                 max_episode_steps=20)))
    venv.seed(0)
    model = algo("MlpPolicy", venv, policy_kwargs={"net_arch": [8]}, seed=0, device="cpu", **kwargs)
    model.learn(256)
    assert model.num_timesteps == 256
    assert len(model.ep_info_buffer) == 8 * (256 // 8 // 20)  # every finished episode was seen
    assert np.all(np.isfinite(venv.obs_rms.mean)) and venv.obs_rms.count > 256


def test_adapter_benchmark_rows_and_thread_count_restored():
    import numba

    from softarm_gym.benchmarks.vector_bench import format_sb3_table, sb3_adapter

    before = numba.get_num_threads()
    rows = sb3_adapter(sizes=(2, 3), threads=(1,), steps=3)
    assert numba.get_num_threads() == before
    assert [(r["num_envs"], r["numba_threads"]) for r in rows] == [(2, 1), (3, 1)]
    assert all(r["env_steps_per_s"] > 0 and r["env_steps_per_cpu_s"] > 0 for r in rows)
    assert format_sb3_table(rows).count("\n") == 3
