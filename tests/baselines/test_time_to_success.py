"""The wall-time-to-success benchmark: its evaluation, its clock and its verdict."""

import json

import gymnasium as gym
import numpy as np
import pytest
import yaml

from baselines import time_to_success as tts
from baselines.config import load_policy
from baselines.evaluate import rollouts
from tests.baselines.conftest import TINY

ENV_ID = "SoftArm/OctArmReach-v0"


def test_batched_evaluation_is_the_single_env_evaluation(tiny_sac_run):
    """episode_ends on a batched env (copy i seeded i) repeats baselines.evaluate's episodes."""
    policy, _, vecnorm = load_policy(tiny_sac_run / "best_model.zip")

    def act(obs):
        return policy.predict(vecnorm.normalize_obs(obs), deterministic=True)[0]

    env_kwargs = {"action_mode": "delta", "max_episode_steps": 30}
    batched = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", **env_kwargs)
    single = rollouts(gym.make(ENV_ID, **env_kwargs), act, lambda: None, episodes=4, seed=3)
    # One policy call on 4 observations against 4 calls on one: the same up to float rounding.
    ends = tts.episode_ends(act, batched, 3, keys=("distance", "is_success"))
    np.testing.assert_allclose(ends["distance"], single["final_error"], rtol=1e-4, atol=1e-7)
    within = single["final_error"] <= batched.template.success_tolerance
    np.testing.assert_array_equal(ends["is_success"], within)


def test_a_wrap_is_judged_by_its_own_success_rule():
    """On a task without a distance to a target (wrap), the batched episodes' ends are the
    single env's ``info["is_success"]``: one constant delta ramp curls seeds 7 and 9 round
    their discs (≥ 90°) and not seeds 8 and 10."""
    env_id, env_kwargs = "SoftArm/CTWrap-v2", {"max_episode_steps": 15}
    ramp = np.array([1.0, -1.0, -1.0, 1.0], dtype=np.float32)
    batched = gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point", **env_kwargs)
    ends = tts.episode_ends(lambda obs: np.tile(ramp, (len(obs), 1)), batched, 7,
                            keys=("is_success", "wrap_angle_deg"))
    single = []
    for seed in range(7, 11):
        env = gym.make(env_id, **env_kwargs)
        env.reset(seed=seed)
        done = False
        while not done:
            _, _, terminated, truncated, info = env.step(ramp)
            done = terminated or truncated
        single.append((info["is_success"], info["wrap_angle_deg"]))
    np.testing.assert_array_equal(ends["is_success"], [s for s, _ in single])
    np.testing.assert_array_equal(ends["wrap_angle_deg"], [w for _, w in single])
    assert ends["is_success"].tolist() == [True, False, True, False]


@pytest.fixture
def tiny_hyperparams(tmp_path):
    """Tiny entries for all four agents, with 10-step episodes."""
    fast = {"action_mode": "delta", "max_episode_steps": 10}
    batched_dir = tmp_path / "batched"
    batched_dir.mkdir()
    for algo in ("sac", "ppo"):
        entry = {**TINY[algo], "env_kwargs": fast}
        (tmp_path / f"{algo}.yml").write_text(yaml.safe_dump({ENV_ID: entry}))
        (batched_dir / f"{algo}.yml").write_text(yaml.safe_dump({ENV_ID: {**entry, "n_envs": 4}}))
    return tmp_path


def test_clock_verdict_and_outputs(tiny_hyperparams, tmp_path, monkeypatch, capsys):
    """Scripted success rates (0, then 1 from the second evaluation on) stand in for learning:
    every agent stops at its second evaluation, whose clock readings are recorded."""
    calls = {}

    def scripted(model, env, seed):
        key = id(model)
        calls[key] = calls.get(key, 0) + 1
        return 0.0 if calls[key] == 1 else 1.0

    monkeypatch.setattr(tts, "success_rate", scripted)
    out, figure = tmp_path / "tts.json", tmp_path / "tts.png"
    assert tts.main(["--env", ENV_ID, "--budget-min", "1", "--eval-every-s", "0.5", "--hyperparams-dir",
                     str(tiny_hyperparams), "--speedup-goal", "3", "--json", str(out),
                     "--plot", str(figure)]) == 0
    result = json.loads(out.read_text())
    table = capsys.readouterr().out
    assert figure.is_file() and "Best single-env agent" in table and "goal ≥ 3× wall time" in table
    assert [r["agent"] for r in result["runs"]] == list(tts.AGENTS)
    for r in result["runs"]:
        first, second = r["history"]
        assert r["reached"] and r["confirm_success"] == 1.0 and first["success"] == 0.0
        assert r["time_to_target_s"] == second["train_wall_s"] >= first["train_wall_s"] + 0.5
        assert r["steps_to_target"] == second["steps"] > first["steps"] > 0
        assert r["cpu_to_target_s"] > 0
        assert r["n_envs"] == (4 if r["batched"] else TINY[r["algo"]].get("n_envs", 1))
    fastest = {kind: min((r for r in result["runs"] if r["batched"] == kind),
                         key=lambda r: r["time_to_target_s"]) for kind in (False, True)}
    assert result["best_single"]["agent"] == fastest[False]["agent"]
    assert result["speedup"] == pytest.approx(fastest[False]["time_to_target_s"]
                                              / fastest[True]["time_to_target_s"])
    assert not result["speedup_is_lower_bound"] and result["batched_reached"]


def test_a_budget_that_runs_out_gives_a_lower_bound(tiny_hyperparams, monkeypatch):
    monkeypatch.setattr(tts, "success_rate", lambda model, env, seed: 0.5)
    result = tts.run(ENV_ID, ("sac", "ppo_batched"), target=0.9, budget_min=0.02, eval_every_s=0.4,
                     hyperparams_dir=tiny_hyperparams)
    for r in result["runs"]:
        assert not r["reached"] and r["time_to_target_s"] is None and r["confirm_success"] is None
        assert r["trained_wall_s"] >= 0.02 * 60 and all(p["success"] == 0.5 for p in r["history"])
    assert result["speedup"] == 1.0 and result["speedup_is_lower_bound"] and not result["batched_reached"]
    with pytest.raises(ValueError, match="unknown agent"):
        tts.run(ENV_ID, ("dqn",))
    with pytest.raises(ValueError, match="target"):
        tts.run(ENV_ID, ("sac",), target=1.5)


def test_one_folder_gives_both_kinds_the_same_settings(tiny_hyperparams, monkeypatch):
    """With one hyperparameter folder for both kinds, the single-env agent trains the batched
    entry's n_envs envs in a DummyVecEnv, and no verdict is given without a goal."""
    monkeypatch.setattr(tts, "success_rate", lambda model, env, seed: 1.0)
    folder = tiny_hyperparams / "batched"
    result = tts.run(ENV_ID, ("sac", "sac_batched"), budget_min=0.02, eval_every_s=0.1,
                     hyperparams_dir=folder, batched_hyperparams_dir=folder)
    single, batched = result["runs"]
    assert single["hyperparams_file"] == batched["hyperparams_file"] == str(folder / "sac.yml")
    assert single["hyperparams"] == batched["hyperparams"] and single["n_envs"] == batched["n_envs"] == 4
    assert not single["batched"] and batched["batched"] and result["speedup_goal"] is None
    assert "goal" not in tts.format_table(result)
