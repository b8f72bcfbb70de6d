"""The batched vector envs are, copy by copy and bit for bit, the single envs (as SyncVectorEnv runs them)."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import solver
from softarm_gym.vector import BatchedReachVectorEnv
from tests.threads import by_thread_count, needs_two_threads


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


# ------------------------------------------------------------------ track, obstacle reach, wrap


def _same_as_sync(env_id, kwargs, mode, n=3, steps=9, max_steps=4, seed=11, action_seed=5, scale=1.2):
    """Runs the batched env and SyncVectorEnv side by side, asserting every output equal;
    returns the batched env's outputs (for what the run covered)."""
    batched = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                           max_episode_steps=max_steps, autoreset_mode=mode.value, **kwargs)
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": mode}, max_episode_steps=max_steps, **kwargs)
    _assert_same(batched.reset(seed=seed), sync.reset(seed=seed), "reset")
    rng = np.random.default_rng(action_seed)
    outs = []
    for t in range(steps):
        actions = rng.uniform(-scale, scale, batched.action_space.shape).astype(np.float32)
        out_b, out_s = batched.step(actions), sync.step(actions)
        _assert_same(out_b, out_s, f"step {t}")
        outs.append(out_b)
    batched.close()
    sync.close()
    return outs


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("env_id, kwargs", [
    ("SoftArm/OctArmTrack-v0", {}),
    ("SoftArm/CTTrack-v0", {"segment_steps": 3, "terminate_on_success": True, "success_tolerance": 0.2}),
    ("SoftArm/OctArmObstacleReach-v0", {}),
    ("SoftArm/CTObstacleReach-v0", {"action_mode": "absolute", "contact_weight": 2.0}),
    ("SoftArm/OctArmWrap-v1", {}),
    ("SoftArm/CTWrap-v1", {"terminate_on_success": True, "success_wrap_deg": 5.0}),
    # The recommended versions (self-contact, delta actions) with a rate large enough that a few
    # random steps curl the arms onto their discs (and onto themselves).
    ("SoftArm/OctArmWrap-v2", {"delta_scale": 1.0}),
    ("SoftArm/CTWrap-v2", {"delta_scale": 1.0, "terminate_on_success": True, "success_wrap_deg": 5.0}),
    ("SoftArm/OctArmObstacleReach-v1", {"delta_scale": 1.0}),
    ("SoftArm/CTTrack-v1", {}),
])
def test_contact_and_track_copies_are_the_single_envs(env_id, kwargs, mode):
    """Copy i seeded s equals SyncVectorEnv's env i seeded s + i, bit for bit, across
    autoresets, for the IDs whose resets run per copy."""
    outs = _same_as_sync(env_id, kwargs, mode)
    assert sum(int(np.sum(o[2] | o[3])) for o in outs) >= 3  # the copies were reset along the way
    if "Track" not in env_id:
        # The contact kernel stepped copies in contact (seen in a step's infos, or under
        # SAME_STEP in those of a step that ended an episode).
        infos = [o[4] for o in outs] + [o[4]["final_info"] for o in outs if "final_info" in o[4]]
        assert any(np.any(info["penetration"] > 0) for info in infos)


def test_batched_wrap_copies_with_friction_are_the_single_envs():
    """The contact BatchStepper carries each copy's friction samples as the single env's
    Stepper does: every output equal, across autoresets, with copies in contact."""
    outs = _same_as_sync("SoftArm/OctArmWrap-v1", {"friction": 0.7}, AutoresetMode.SAME_STEP)
    infos = [o[4] for o in outs] + [o[4]["final_info"] for o in outs if "final_info" in o[4]]
    assert any(np.any(info["penetration"] > 0) for info in infos)


def test_forbidden_contact_is_rejected_as_in_the_single_env():
    """Absolute jumps touch the discs: the batch restores those copies as the single env does."""
    outs = _same_as_sync("SoftArm/OctArmObstacleReach-v0", {"contact": "forbid", "action_mode": "absolute"},
                         AutoresetMode.SAME_STEP, n=6, steps=16, max_steps=6, seed=0, action_seed=0,
                         scale=1.0)
    assert sum(int(o[4]["contact_rejected"].sum()) for o in outs) >= 1


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmWrap-v2", "SoftArm/CTWrap-v2",
                                    "SoftArm/OctArmObstacleReach-v1", "SoftArm/CTObstacleReach-v1",
                                    "SoftArm/OctArmTrack-v1", "SoftArm/CTTrack-v1"])
def test_recommended_versions_are_served_as_registered(env_id):
    """The registered defaults (self-contact, delta actions) through the batched env, equal to
    SyncVectorEnv across autoresets."""
    spec = gym.spec(env_id)
    assert spec.kwargs["self_contact"] is True and spec.kwargs["action_mode"] == "delta"
    outs = _same_as_sync(env_id, {}, AutoresetMode.NEXT_STEP, n=2, steps=7, max_steps=3)
    assert sum(int(np.sum(o[2] | o[3])) for o in outs) >= 2


def test_self_contact_copies_are_the_single_envs():
    outs = _same_as_sync("SoftArm/OctArmWrap-v1", {"self_contact": True, "action_mode": "delta"},
                         AutoresetMode.NEXT_STEP, n=3, steps=12, max_steps=6)
    assert len(outs) == 12
    _same_as_sync("SoftArm/OctArmTrack-v0", {"self_contact": True}, AutoresetMode.NEXT_STEP, steps=5)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_self_contact_reach_resets_by_its_single_envs(mode):
    """Reach with self-contact: the targets are solved with the arm pressing on itself, so the
    batch resets each copy by its single env (no longer a refusal) and stays bit for bit."""
    from softarm_gym.vector import BatchedSelfContactReachVectorEnv
    envs = gym.make_vec("SoftArm/OctArmReach-v1", num_envs=2, vectorization_mode="vector_entry_point",
                        self_contact=True)
    assert type(envs) is BatchedSelfContactReachVectorEnv
    envs.close()
    outs = _same_as_sync("SoftArm/OctArmReach-v1", {"self_contact": True, "delta_scale": 1.0}, mode)
    assert sum(int(np.sum(o[2] | o[3])) for o in outs) >= 3


def test_reset_options_reach_every_copy():
    env_id = "SoftArm/OctArmWrap-v1"
    batched = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    sync = gym.make_vec(env_id, num_envs=2, vectorization_mode="sync")
    options = {"object": (0.2, -0.4, 0.1)}
    _assert_same(batched.reset(seed=0, options=options), sync.reset(seed=0, options=options), "reset")
    actions = np.full((2, 6), 0.3, dtype=np.float32)
    _assert_same(batched.step(actions), sync.step(actions), "step")
    np.testing.assert_array_equal(batched.reset(seed=1, options=options)[1]["object_center"],
                                  [[0.2, -0.4], [0.2, -0.4]])


def test_a_copy_without_a_lean_record_is_read_from_its_equilibrium():
    """A state on a grid of its own (here an equilibrium solved at a finer resolution, as the
    general path's refinement leaves one) has no lean record in the batch nor in the single
    env's stepper: both read it from the equilibrium, and step on from it alike."""
    env_id = "SoftArm/OctArmWrap-v1"
    batched = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    single = gym.make(env_id).unwrapped
    batched.reset(seed=[4, 4])
    single.reset(seed=4)
    eq = single.stepper.equilibrium
    fine = solver.solve(single.arm, eq.pressures, eq.scene, settings=solver.Settings(steps_per_section=24),
                        warm_start=eq)
    assert fine.converged and fine.s.size != eq.s.size
    single.stepper.adopt(fine)
    batched._batch.adopt(fine, rows=[1])
    assert single.stepper.record is None and batched._batch.recorded().tolist() == [True, False]
    action = np.full(6, -0.9, dtype=np.float32)
    action[::2] = 0.6
    for t in range(3):
        obs, reward, _, _, info = batched.step(np.stack([action, action]))
        obs_1, reward_1, _, _, info_1 = single.step(action)
        np.testing.assert_array_equal(obs[1], obs_1, err_msg=f"step {t}")
        assert reward[1] == reward_1
        for key in ("wrap_angle_deg", "penetration", "gap", "tip_true"):
            np.testing.assert_array_equal(info[key][1], info_1[key], err_msg=key)


@pytest.mark.parametrize("env_id, kwargs, match", [
    ("SoftArm/OctArmWrap-v1", {"planar": False}, "planar=False"),
    ("SoftArm/OctArmWrap-v2", {"planar": False}, "self_contact needs planar=True"),
    ("SoftArm/OctArmWrap-v1", {"contact_stiffness": "rigid"}, "contact_stiffness=inf N/m².*rigid contact"),
    ("SoftArm/OctArmObstacleReach-v0", {"contact_stiffness": 1e6},
     "contact_stiffness=1e\\+06 N/m².*contact layout has 70 rows"),
    ("SoftArm/OctArmObstacleReach-v0", {"observation": "inclinometer"}, "observation='inclinometer'"),
    ("SoftArm/OctArmTrack-v0", {"planar": False}, "planar=False"),
    ("SoftArm/OctArmTrack-v0", {"payload_kg": (0.0, 0.1)}, "payload_kg range"),
])
def test_what_the_batched_envs_cannot_take_is_named(env_id, kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **kwargs)


@pytest.mark.parametrize("env_id, cls", [
    ("SoftArm/OctArmTrack-v0", "BatchedTrackVectorEnv"), ("SoftArm/CTTrack-v0", "BatchedTrackVectorEnv"),
    ("SoftArm/OctArmObstacleReach-v0", "BatchedObstacleReachVectorEnv"),
    ("SoftArm/CTObstacleReach-v0", "BatchedObstacleReachVectorEnv"),
    ("SoftArm/OctArmWrap-v0", "BatchedWrapVectorEnv"), ("SoftArm/CTWrap-v0", "BatchedWrapVectorEnv"),
    ("SoftArm/OctArmWrap-v1", "BatchedWrapVectorEnv"), ("SoftArm/CTWrap-v1", "BatchedWrapVectorEnv"),
    ("SoftArm/OctArmWrap-v2", "BatchedWrapVectorEnv"), ("SoftArm/CTWrap-v2", "BatchedWrapVectorEnv"),
    ("SoftArm/OctArmTrack-v1", "BatchedTrackVectorEnv"), ("SoftArm/CTTrack-v1", "BatchedTrackVectorEnv"),
    ("SoftArm/OctArmObstacleReach-v1", "BatchedObstacleReachVectorEnv"),
    ("SoftArm/CTObstacleReach-v1", "BatchedObstacleReachVectorEnv"),
])
def test_contact_and_track_ids_register_their_batched_env(env_id, cls):
    envs = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    assert type(envs).__name__ == cls
    assert envs.max_episode_steps == gym.spec(env_id).max_episode_steps
    obs, _ = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)
    assert envs.np_random_seed == (0, 1)
    envs.close()
    for env_id in ("SoftArm/OctArmWrap3D-v0", "SoftArm/OctArmGrasp-v0", "SoftArm/OctArmGrasp-v1"):
        assert gym.spec(env_id).vector_entry_point is None


def test_contact_batches_run_on_threads_as_on_one():
    runs = []
    for threaded in (False, True):
        env = gym.make_vec("SoftArm/OctArmWrap-v1", num_envs=5, vectorization_mode="vector_entry_point",
                           max_episode_steps=3)
        for policy in [*env._batch.thread_policies.values(), env._observe_policy]:
            policy.choose = lambda rows, t=threaded: t
        out = [env.reset(seed=2)]
        for k in range(4):
            out.append(env.step(np.full((5, 6), np.sin(k))))
        runs.append(tuple(out))
        env.close()
    _assert_same(runs[0], runs[1], "threaded")


@needs_two_threads
def test_copies_reset_side_by_side_as_one_after_another():
    """The copies that reset together reset on the CopyPool's threads; the batch is the one
    that resetting them one after another gives, bit for bit."""
    from softarm_gym.envs import ObstacleReachEnv

    def run(_):
        env = gym.make_vec("SoftArm/OctArmObstacleReach-v1", num_envs=4,
                           vectorization_mode="vector_entry_point", max_episode_steps=2)
        out = [env.reset(seed=7)]
        for k in range(3):  # the third step resets every copy again
            out.append(env.step(np.full((4, 6), 0.5 * np.cos(k), dtype=np.float32)))
        env.close()
        return tuple(out)

    (serial, serial_threads), (threaded, pool_threads) = by_thread_count(run, ObstacleReachEnv, "reset")
    assert serial_threads == 1 and pool_threads >= 2
    _assert_same(serial, threaded, "copies reset side by side")
