"""rl-baselines3-zoo reads the project's hyperparameter files, and their budgets are the reported runs'."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from baselines.config import HYPERPARAMS_DIR, load_hyperparams

RESULTS = Path(__file__).resolve().parents[2] / "baselines" / "results" / "training"


@pytest.mark.parametrize("summary", sorted(RESULTS.glob("*/summary.json")), ids=lambda p: p.parent.name)
def test_yaml_budget_is_the_step_count_of_the_reported_run(summary):
    run = json.loads(summary.read_text())
    # A run from another YAML folder (a remedy tried on one env) names its file.
    folder = RESULTS.parents[2] / Path(run["hyperparams_file"]).parent if "hyperparams_file" in run \
        else HYPERPARAMS_DIR
    params = load_hyperparams(run["algo"], run["env_id"], folder)
    if "imitation" in run:
        # Cloned from demonstrations (baselines.imitate): no RL budget; its steps are the
        # demonstrations' (observation, action) pairs.
        assert run["timesteps_done"] == run["imitation"]["samples"]
    elif run.get("time_limit_min") and run["timesteps_done"] < run.get("timesteps", params["n_timesteps"]):
        # Stopped by its wall-clock cap short of its budget — the YAML's, or the one its command
        # gave (`--timesteps`, recorded; RESULTS.md gives the command) — it did use the whole cap.
        assert run["wall_time_s"] >= 60 * run["time_limit_min"]
    else:
        # The budget itself (a run stopped by its cap mid-rollout, whose YAML budget is the steps
        # it got), or where SB3 stops short of a cap: the first whole rollout (PPO: n_envs ×
        # n_steps transitions; off-policy: train_freq steps of every env) at or past the budget,
        # counted from where the session that finished began (a resumed run: its checkpoint).
        per_env = params.get("n_steps", 2048) if run["algo"] == "ppo" else params.get("train_freq", 1)
        rollout = params.get("n_envs", 1) * (per_env if isinstance(per_env, int) else 1)
        start = run.get("resumed_from") or 0
        assert run["timesteps_done"] in (params["n_timesteps"],
                                         start + -(-(params["n_timesteps"] - start) // rollout) * rollout)
    # Keys a YAML leaves to the algorithm's defaults are absent from both.
    for key in ("env_kwargs", "normalize", "learning_rate", "gamma", "batch_size"):
        assert params.get(key) == run["hyperparams"].get(key), key
    assert params.get("policy_kwargs", {}).get("net_arch") == \
        run["hyperparams"].get("policy_kwargs", {}).get("net_arch")


def test_rl_zoo3_trains_with_the_project_hyperparameters(tmp_path):
    # Only look for it: importing rl_zoo3 patches gymnasium's TimeLimit for the whole process.
    if importlib.util.find_spec("rl_zoo3") is None:
        pytest.skip("rl_zoo3 not installed (pip install 'softarm-gym[baselines]')")
    env_id = "SoftArm/OctArmReach-v0"
    steps = 300
    # The YAML as it is, except that learning starts (and the buffer stays small) within the smoke run.
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "sac", "--env", env_id,
           "--gym-packages", "softarm_gym", "-conf", str(HYPERPARAMS_DIR / "sac.yml"),
           "-n", str(steps), "-f", str(tmp_path), "--eval-freq", "-1", "--seed", "0",
           "--device", "cpu", "--num-threads", "1", "-params", "learning_starts:100", "buffer_size:1000"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    run = tmp_path / "sac" / "SoftArm-OctArmReach-v0_1"
    assert (run / "SoftArm-OctArmReach-v0" / "vecnormalize.pkl").is_file()  # `normalize` was honoured
    config = yaml.unsafe_load((run / "SoftArm-OctArmReach-v0" / "config.yml").read_text())
    expected = load_hyperparams("sac", env_id)
    assert config["env_kwargs"] == expected["env_kwargs"]  # delta actions reached gym.make
    assert config["n_timesteps"] == expected["n_timesteps"]
    episodes = (run / "0.monitor.csv").read_text().splitlines()[2:]
    assert [int(line.split(",")[1]) for line in episodes] == [100] * (steps // 100)

    from stable_baselines3 import SAC

    model = SAC.load(run / "SoftArm-OctArmReach-v0.zip", device="cpu")
    assert model.num_timesteps == steps
    assert model.gamma == expected["gamma"]
    assert model.policy.net_arch == expected["policy_kwargs"]["net_arch"]
