"""Planner demonstrations, behaviour cloning and the BC warm start of PPO, on a tiny scale."""

import json

import numpy as np
import pytest
import torch

from baselines.config import load_policy, make_env, sidecar_paths
from baselines.evaluate import evaluate
from baselines.imitate import behaviour_clone, collect, dagger, load_demonstrations, main, save_demonstrations
from baselines.train import train
from softarm_gym.controllers import CurlController
from tests.baselines.conftest import TINY, tiny_hyperparams

ENV_ID = "SoftArm/OctArmReach-v1"  # delta actions, like the recommended wrap; the planner is fast here


@pytest.fixture(scope="module")
def demo_file(tmp_path_factory):
    """One planner episode on reach, saved."""
    demos = collect(ENV_ID, 1, seed=3)
    return save_demonstrations(demos, tmp_path_factory.mktemp("demos") / "planner.npz"), demos


@pytest.fixture(scope="module")
def tiny_dir(tmp_path_factory):
    return tiny_hyperparams(tmp_path_factory.mktemp("hp"), env_ids=(ENV_ID,))


def test_demonstrations_are_the_planners_actions_on_the_envs_observations(demo_file):
    path, demos = demo_file
    env = make_env(ENV_ID)
    steps = env.spec.max_episode_steps
    assert demos["observations"].shape == (steps, *env.observation_space.shape)
    assert demos["actions"].shape == (steps, *env.action_space.shape)
    assert np.all(np.abs(demos["actions"]) <= 1.0) and np.any(demos["actions"] != 0.0)
    # The recorded observations are the episode the planner drove: its first is the reset's.
    first, _ = env.reset(seed=3)
    np.testing.assert_array_equal(demos["observations"][0], first)
    env.close()
    loaded = load_demonstrations([path, path])  # two files: episodes renumbered
    assert loaded["observations"].shape[0] == 2 * steps
    assert set(loaded["episodes"]) == {0, 1} and loaded["meta"]["episodes"] == 2
    assert json.loads(path.with_suffix(".json").read_text())["expert"] == "CEMPlanner"


def test_cloned_policy_fits_the_demonstrations_and_loads_for_evaluation(demo_file, tiny_dir, tmp_path):
    path, _ = demo_file
    demos = load_demonstrations([path])
    model = behaviour_clone(demos, tmp_path / "bc_s0", hyperparams_dir=tiny_dir, epochs=30, batch_size=32,
                            learning_rate=3e-3)
    assert model == tmp_path / "bc_s0" / "final_model.zip"
    summary = json.loads((tmp_path / "bc_s0" / "summary.json").read_text())  # a run, for baselines.results
    assert summary["timesteps_done"] == len(demos["actions"]) and summary["imitation"]["method"] == "bc"
    meta = json.loads(sidecar_paths(model)[0].read_text())
    losses = meta["imitation"]["loss_per_epoch"]
    assert len(losses) == 30 and losses[-1] < losses[0]  # the likelihood of the planner's actions rose
    assert sidecar_paths(model)[1].is_file()  # the demonstrations' observation statistics
    policy, _, vecnorm = load_policy(model)
    np.testing.assert_allclose(vecnorm.obs_rms.mean, demos["observations"].mean(axis=0), rtol=1e-5, atol=1e-6)
    action = policy.predict(vecnorm.normalize_obs(demos["observations"][:4]), deterministic=True)[0]
    assert action.shape == (4, *demos["actions"].shape[1:])
    vecnorm.venv.close()
    result = evaluate(model=model, episodes=1, seed=100)
    assert result["episodes"] == 1 and result["agent"] == "ppo:final_model.zip"
    with pytest.raises(ValueError, match="already holds a run"):
        behaviour_clone(demos, tmp_path / "bc_s0", hyperparams_dir=tiny_dir, epochs=1)


def test_init_policy_starts_ppo_from_the_cloned_weights(demo_file, tiny_dir, tmp_path):
    path, _ = demo_file
    model = behaviour_clone(load_demonstrations([path]), tmp_path / "bc", hyperparams_dir=tiny_dir, epochs=1)
    frozen = {**TINY["ppo"], "learning_rate": 0.0}  # no update changes the weights
    run = train(ENV_ID, "ppo", seed=0, log_dir=tmp_path, hyperparams=frozen, eval_freq=0, checkpoint_freq=0,
                progress=False, tensorboard=False, init_policy=model)
    cloned, _, _ = load_policy(model)
    trained, meta, _ = load_policy(run / "final_model.zip")
    assert meta["init_policy"].endswith("final_model.zip")
    for name, tensor in cloned.state_dict().items():
        assert torch.equal(tensor, trained.state_dict()[name]), name
    wider = {**frozen, "policy_kwargs": {"net_arch": [16]}}
    with pytest.raises(ValueError, match="does not fit"):
        train(ENV_ID, "ppo", seed=0, log_dir=tmp_path, hyperparams=wider, eval_freq=0, checkpoint_freq=0,
              progress=False, tensorboard=False, init_policy=model, run_name="wider")


def test_cli_errors_exit_2(tmp_path, capsys):
    assert main(["bc", "--demos", str(tmp_path / "none.npz"), "--out", str(tmp_path / "bc")]) == 2
    assert "not a demonstration file" in capsys.readouterr().err
    assert main(["collect", "--episodes", "0", "--out", str(tmp_path / "d.npz")]) == 2


def test_dagger_labels_the_learners_states_and_clones_again(demo_file, tiny_dir, tmp_path):
    path, demos = demo_file
    model = dagger(load_demonstrations([path]), tmp_path / "dagger", rounds=1, episodes=1, seed=50,
                   hyperparams_dir=tiny_dir, epochs=2)
    run = tmp_path / "dagger"
    assert model == run / "final_model.zip" and (run / "round0_model.zip").is_file()
    labels = load_demonstrations([run / "round1_labels.npz"])
    steps = len(demos["actions"])
    assert labels["observations"].shape == demos["observations"].shape  # one learner episode
    first, _ = make_env(ENV_ID).reset(seed=50)  # the learner's episode, on the round's seed
    np.testing.assert_array_equal(labels["observations"][0], first)
    imitation = json.loads((run / "summary.json").read_text())["imitation"]
    assert imitation["method"] == "dagger" and imitation["samples"] == 2 * steps
    assert [r["round"] for r in imitation["rounds"]] == [1]


def test_the_scripted_curl_demonstrates_where_the_planner_is_too_slow(tmp_path):
    # The curl's demonstrations are the actions it sends on the observations it sees: replayed
    # from the same reset, a fresh CurlController sends the same ones.
    env_id = "SoftArm/CTWrap-v2"
    demos = collect(env_id, 1, seed=5, expert="curl")
    assert demos["meta"]["expert"] == "CurlController"
    env = make_env(env_id)
    obs, _ = env.reset(seed=5)
    curl = CurlController(env)
    for k in range(3):
        np.testing.assert_array_equal(demos["observations"][k], obs)
        action = curl.act(obs)
        np.testing.assert_array_equal(demos["actions"][k], action)
        obs = env.step(action)[0]
    env.close()
    path = save_demonstrations(demos, tmp_path / "curl.npz")
    planner = save_demonstrations({**demos, "meta": {**demos["meta"], "expert": "CEMPlanner"}},
                                  tmp_path / "planner.npz")
    with pytest.raises(ValueError, match="different experts"):
        load_demonstrations([path, planner])
    with pytest.raises(ValueError, match="DAgger labels with the planner"):
        dagger(load_demonstrations([path]), tmp_path / "dagger")
    with pytest.raises(ValueError, match="unknown expert"):
        collect(env_id, 1, expert="oracle")
