"""Smoke training runs of every algorithm and the hyperparameter files."""

import json

import pandas as pd
import pytest
from stable_baselines3 import HerReplayBuffer

from baselines.config import (
    ALGOS,
    HYPERPARAMS_DIR,
    load_hyperparams,
    make_env,
    sidecar_paths,
    split_hyperparams,
)
from baselines.train import build, main, resume, train
from softarm_gym.sb3 import BatchedVecEnv
from tests.baselines.conftest import TINY, tiny_hyperparams

ENV_IDS = ("SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0")


def test_tiny_sac_run_writes_logs_checkpoints_and_sidecars(tiny_sac_run):
    run = tiny_sac_run
    summary = json.loads((run / "summary.json").read_text())
    assert summary["timesteps_done"] >= 200
    assert summary["wall_time_s"] > 0
    assert summary["env_kwargs"] == {"action_mode": "delta"}
    monitor = pd.read_csv(run / "monitor.csv", skiprows=1)
    assert {"r", "l", "t", "is_success", "distance"} <= set(monitor.columns)
    assert (monitor["l"] == 100).all()  # registered max_episode_steps
    assert "time/total_timesteps" in pd.read_csv(run / "progress.csv").columns
    assert list(run.glob("events.out.tfevents.*")), "no TensorBoard event file"
    assert sorted(p.name for p in (run / "checkpoints").glob("*.zip")) == \
        ["model_100_steps.zip", "model_200_steps.zip"]
    assert len(list((run / "checkpoints").glob("*_vecnormalize.json"))) == 2
    assert len(list((run / "checkpoints").glob("model_*_steps.json"))) == 2  # metadata with every checkpoint
    assert not list(run.rglob("*.pkl")) and not list(run.rglob("*.tmp"))
    for name in ("final_model.zip", "best_model.zip"):
        meta_path, norm_path = sidecar_paths(run / name)
        assert (run / name).is_file() and norm_path.is_file()
        assert json.loads(meta_path.read_text())["algo"] == "sac"
    assert (run / "evaluations.npz").is_file()


@pytest.mark.parametrize("algo", ["td3", "ppo"])
def test_smoke_training(algo, tmp_path):
    run = train("SoftArm/CTReach-v0", algo, seed=1, log_dir=tmp_path, hyperparams=TINY[algo],
                eval_freq=0, checkpoint_freq=0, progress=False, tensorboard=False)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["timesteps_done"] >= TINY[algo]["n_timesteps"]
    assert (run / "final_model.zip").is_file()
    assert sidecar_paths(run / "final_model.zip")[1].is_file() == ("normalize" in TINY[algo])
    if algo == "ppo":  # two envs: one monitor file each
        assert (run / "monitor.csv").is_file() and (run / "1.monitor.csv").is_file()


@pytest.mark.parametrize("algo", sorted(ALGOS))
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_algorithm_has_hyperparameters_for_both_reach_envs(algo, env_id):
    params = load_hyperparams(algo, env_id)
    special, algo_kwargs = split_hyperparams(params)
    assert special["n_timesteps"] > 0
    assert "n_timesteps" not in algo_kwargs and "env_kwargs" not in algo_kwargs
    if algo == "sac_her":  # the goal format, relabelled through the env's compute_reward
        assert special["policy"] == "MultiInputPolicy"
        assert algo_kwargs["replay_buffer_class"] is HerReplayBuffer
        env = make_env(env_id, special["env_kwargs"])
    else:
        assert special["policy"] == "MlpPolicy"
        env = "Pendulum-v1"
    ALGOS[algo](special["policy"], env, device="cpu", **algo_kwargs)  # keys the constructor accepts


@pytest.mark.parametrize("algo", ["ppo", "sac"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_batched_hyperparameters_build_on_the_batched_env(algo, env_id):
    params = load_hyperparams(algo, env_id, HYPERPARAMS_DIR / "batched")
    model, venv = build(env_id, algo, params, seed=0, batched=True)
    assert isinstance(venv.unwrapped, BatchedVecEnv) and venv.num_envs == params["n_envs"] > 1
    venv.close()


CONTACT_ENTRIES = [("batched", "SoftArm/OctArmWrap-v2"), ("batched", "SoftArm/CTWrap-v2"),
                   ("batched", "SoftArm/OctArmObstacleReach-v1"), ("batched", "SoftArm/OctArmTrack-v1"),
                   ("batched_gsde", "SoftArm/OctArmWrap-v2"), ("batched_gsde", "SoftArm/CTWrap-v2")]
"""(YAML folder, id) of the batched PPO entries of the recommended contact and track ids (issue #37)."""


@pytest.mark.parametrize("folder,env_id", CONTACT_ENTRIES)
def test_contact_ppo_entries_train_the_registered_defaults(folder, env_id, tmp_path):
    params = load_hyperparams("ppo", env_id, HYPERPARAMS_DIR / folder)
    assert params["env_kwargs"] == {}  # the recommended id itself: sequential, self-contact on
    assert params["n_envs"] * params["n_steps"] >= 8192 and params["n_envs"] * params["n_steps"] % \
        params["batch_size"] == 0
    # One update on the batched env with the entry's settings, but 4 arms and 4 steps each.
    small = {**params, "n_envs": 4, "n_steps": 4, "batch_size": 8, "n_epochs": 1, "n_timesteps": 16}
    run = train(env_id, "ppo", seed=0, log_dir=tmp_path, hyperparams=small, eval_freq=0, checkpoint_freq=0,
                progress=False, tensorboard=False, batched=True)
    assert json.loads((run / "summary.json").read_text())["timesteps_done"] == 16
    model, venv = build(env_id, "ppo", small, seed=0, batched=True)
    assert isinstance(venv.unwrapped, BatchedVecEnv) and model.use_sde == params.get("use_sde", False)
    venv.close()


def test_batched_run_and_its_resume_write_one_monitor_file(tmp_path):
    tiny = {**TINY["ppo"], "n_envs": 4, "n_steps": 16, "n_timesteps": 128,
            "env_kwargs": {"action_mode": "delta", "max_episode_steps": 8}}
    run = train(ENV_IDS[0], "ppo", seed=2, log_dir=tmp_path, hyperparams=tiny, eval_freq=64, eval_episodes=1,
                checkpoint_freq=64, progress=False, tensorboard=False, batched=True)
    assert run.name == "ppo_OctArmReach-v0_batched_s2"
    assert json.loads((run / "config.json").read_text())["batched"] is True
    assert json.loads((run / "summary.json").read_text())["batched"] is True
    monitor = pd.read_csv(run / "monitor.csv", skiprows=1)
    assert {"r", "l", "t", "is_success", "distance"} <= set(monitor.columns)
    assert list(monitor["l"]) == [8] * (128 // 8) and not list(run.glob("[0-9]*.monitor.csv"))
    header = (run / "monitor.csv").read_text().splitlines()[0]
    resume(run, timesteps=256, progress=False)
    assert (run / "monitor.csv").read_text().splitlines()[0] == header  # appended, not restarted
    assert len(pd.read_csv(run / "monitor.csv", skiprows=1)) == 256 // 8


def test_bad_hyperparameters_are_named(tmp_path):
    with pytest.raises(ValueError, match="unknown algo 'dqn'"):
        load_hyperparams("dqn", ENV_IDS[0])
    with pytest.raises(ValueError, match="no entry for 'SoftArm/Nope-v0'"):
        load_hyperparams("sac", "SoftArm/Nope-v0")
    (tmp_path / "sac.yml").write_text("SoftArm/OctArmReach-v0: {policy: MlpPolicy}\n")
    with pytest.raises(ValueError, match="'policy' and 'n_timesteps'"):
        load_hyperparams("sac", ENV_IDS[0], tmp_path)
    with pytest.raises(ValueError, match="no hyperparameter file"):
        load_hyperparams("td3", ENV_IDS[0], tmp_path)
    with pytest.raises(ValueError, match="time_limit_min"):
        train(ENV_IDS[0], "sac", log_dir=tmp_path, hyperparams=TINY["sac"], time_limit_min=0)
    for name in ("", "..", "a/b"):
        with pytest.raises(ValueError, match="run_name must be a plain folder name"):
            train(ENV_IDS[0], "sac", log_dir=tmp_path, hyperparams=TINY["sac"], run_name=name)
    assert HYPERPARAMS_DIR.is_dir() and not list(tmp_path.glob("*/config.json"))


@pytest.mark.parametrize(("env_id", "message"), [
    ("SoftArm/OctArmWrap-v0", "no entry for 'SoftArm/OctArmWrap-v0'"),
    ("SoftArm/Nope-v0", "registered SoftArm/* id"),
    ("evil_module:Env", "registered SoftArm/* id"),
])
def test_cli_reports_bad_input_with_exit_status_2(tmp_path, capsys, env_id, message):
    assert main(["--env", env_id, "--algo", "sac", "--log-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_a_run_from_another_yaml_folder_names_its_file(tmp_path, tiny_sac_run):
    folder = tiny_hyperparams(tmp_path / "remedy")
    assert main(["--env", ENV_IDS[0], "--algo", "sac", "--hyperparams-dir", str(folder),
                 "--run-name", "remedy_s0", "--log-dir", str(tmp_path / "runs"), "--timesteps", "60",
                 "--eval-freq", "0", "--checkpoint-freq", "0", "--no-progress"]) == 0
    run = tmp_path / "runs" / "remedy_s0"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["hyperparams_file"] == (folder / "sac.yml").resolve().as_posix()
    meta = json.loads((run / "final_model.json").read_text())
    assert meta["hyperparams_file"] == summary["hyperparams_file"]
    assert "hyperparams_file" not in json.loads((tiny_sac_run / "summary.json").read_text())
