"""SAC + HER (``--algo sac_her``): the goal format end to end through train, evaluate and results."""

import json

import numpy as np
import pytest

from baselines import results
from baselines.config import load_normalization, load_policy, observation_sizes, sidecar_paths
from baselines.evaluate import evaluate
from baselines.train import train

ENV_ID = "SoftArm/OctArmReach-v0"
TINY_HER = {"policy": "MultiInputPolicy", "n_timesteps": 200,
            "env_kwargs": {"action_mode": "delta", "observation_format": "goal", "max_episode_steps": 20},
            "normalize": {"norm_obs": True, "norm_reward": False}, "replay_buffer_class": "HerReplayBuffer",
            "replay_buffer_kwargs": {"n_sampled_goal": 4, "goal_selection_strategy": "future",
                                     "copy_info_dict": True},
            "learning_starts": 60, "batch_size": 16, "buffer_size": 1000, "policy_kwargs": {"net_arch": [8]}}


@pytest.fixture(scope="module")
def her_run(tmp_path_factory):
    return train(ENV_ID, "sac_her", seed=1, log_dir=tmp_path_factory.mktemp("runs"), hyperparams=TINY_HER,
                 eval_freq=100, eval_episodes=1, checkpoint_freq=0, progress=False, tensorboard=False)


def test_her_run_saves_per_key_statistics_that_load_safely(her_run):
    model = her_run / "best_model.zip"
    policy, meta, vecnorm = load_policy(model)
    assert meta["algo"] == "sac_her" and meta["policy"] == "MultiInputPolicy"
    sizes = observation_sizes(vecnorm.observation_space)
    assert sizes == {"observation": 36, "achieved_goal": 2, "desired_goal": 2}
    saved = load_normalization(sidecar_paths(model)[1], sizes)["obs_rms"]
    for key, rms in vecnorm.obs_rms.items():  # the statistics reached the evaluation's VecNormalize
        np.testing.assert_array_equal(rms.mean, saved[key]["mean"])
        assert rms.count == saved[key]["count"] > 60
    with pytest.raises(ValueError, match="per observation key .* but the observation is flat"):
        load_normalization(sidecar_paths(model)[1], 40)
    with pytest.raises(ValueError, match="for the observation keys observation, goal"):
        load_normalization(sidecar_paths(model)[1], {"observation": 36, "goal": 4})
    result = evaluate(model=model, episodes=2)
    assert result["agent"] == "sac_her:best_model.zip" and result["episodes"] == 2


def test_her_agents_are_evaluated_on_true_observations_only(her_run, tmp_path):
    """The goal format shows the true tip (achieved_goal), so the estimator grid would not
    measure the estimators: a goal-format run gets the main cell alone."""
    jobs = results.evaluation_jobs(her_run.parent, tmp_path)
    mine = [path.stem for path, kwargs in jobs if path.stem.startswith(her_run.name)]
    assert mine == [f"{her_run.name}__main"]
    with pytest.raises(ValueError, match="needs observation='true'"):
        evaluate(model=her_run / "best_model.zip", episodes=1, observation="cable_encoder")


def test_replay_buffer_of_her_is_not_saved(tmp_path):
    with pytest.raises(ValueError, match="HerReplayBuffer"):
        train(ENV_ID, "sac_her", log_dir=tmp_path, hyperparams=TINY_HER, save_replay_buffer=True,
              progress=False)


def test_report_keeps_her_out_of_the_sac_mean(her_run, tmp_path):
    out = tmp_path / "results"
    results.collect(her_run.parent, out)
    result = evaluate(model=her_run / "best_model.zip", episodes=1)
    (out / "eval").mkdir()
    for name in (her_run.name, "sac_OctArmReach-v0_s7", "sac_OctArmReach-v0_s8"):
        row = {**result, "cell": "main", "agent_name": name,
               "success_rate": {"sac_OctArmReach-v0_s7": 0.5, "sac_OctArmReach-v0_s8": 0.7}.get(name, 1.0)}
        (out / "eval" / f"{name}__main.json").write_text(json.dumps(row))
    text = results.report(out, tmp_path / "RESULTS.md")
    assert "**sac mean ± std over 2 seeds** | | | | | **60 ± 14 %**" in text
    assert "sac on SoftArm/OctArmReach-v0: best 70 %" in text
    assert f"| {ENV_ID} | {her_run.name} | " in text
