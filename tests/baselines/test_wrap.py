"""The baselines on the wrap task: hyperparameters, monitor keys, evaluating the planner and a
policy by the wrap angle, the evaluation grid, shipping and the report's wrap sections."""

import json

import numpy as np
import pandas as pd
import pytest
from gymnasium import spaces

from baselines import results
from baselines.config import action_noise, is_wrap, load_hyperparams, load_policy, make_env, split_hyperparams
from baselines.evaluate import evaluate, main, summarize
from baselines.train import build, train
from softarm_gym.benchmarks.planner import episode
from tests.baselines.conftest import TINY

WRAP_KEYS = {"success_rate", "median_wrap_angle_deg", "p5_wrap_angle_deg", "mean_wrap_angle_deg",
             "reached_rate", "median_steps_to_success", "mean_estimation_error_m", "success_wrap_deg"}


@pytest.fixture(scope="module")
def tiny_wrap_run(tmp_path_factory):
    """Run folder of a 200-step SAC training (one episode) on CTWrap-v1's registered defaults."""
    tiny = {**TINY["sac"], "env_kwargs": {}}
    return train("SoftArm/CTWrap-v1", "sac", seed=1, log_dir=tmp_path_factory.mktemp("runs"),
                 hyperparams=tiny, eval_freq=100, eval_episodes=1, checkpoint_freq=0, progress=False)


@pytest.mark.parametrize("algo", ["sac", "ppo"])
@pytest.mark.parametrize("env_id", results.WRAP_ENV_IDS)
def test_wrap_entries_train_on_the_registered_defaults(algo, env_id):
    params = load_hyperparams(algo, env_id)
    special, _ = split_hyperparams(params)
    assert special["env_kwargs"] == {} and special["n_timesteps"] > 0
    assert is_wrap(env_id) and not is_wrap("SoftArm/OctArmReach-v1")
    make_env(env_id, special["env_kwargs"]).close()


def test_summarize_reports_the_wrap_angle_instead_of_an_error():
    record = {"final_error": np.full(4, np.nan), "final_wrap_deg": np.array([300.0, 95.0, 280.0, 10.0]),
              "success": np.array([True, False, True, False]), "steps_to_success": np.array([40, -1, 60, -1]),
              "estimation_error": np.zeros(4), "episode_return": np.zeros(4), "solver_failures": np.zeros(4)}
    s = summarize(record)
    assert s["median_wrap_angle_deg"] == pytest.approx(187.5) and s["mean_wrap_angle_deg"] == 171.25
    assert "median_final_error_m" not in s
    assert s["success_rate"] == 0.5 and s["median_steps_to_success"] == 50.0


def test_planner_evaluation_is_the_benchmark_episode_by_episode():
    """Each episode's planner is seeded with the episode's seed, as the planner benchmark runs it."""
    result = evaluate(controller="planner", env_id="SoftArm/CTWrap-v1", episodes=2, seed=3)
    assert WRAP_KEYS <= set(result) and result["success_wrap_deg"] == 90.0
    bench = [episode("SoftArm/CTWrap-v1", seed) for seed in (3, 4)]
    assert result["success_rate"] == np.mean([b["success"] for b in bench])
    assert result["median_wrap_angle_deg"] == pytest.approx(np.median([b["measure"] for b in bench]))


def test_a_wrap_policy_trains_and_evaluates_with_an_estimator(tiny_wrap_run, capsys):
    monitor = pd.read_csv(tiny_wrap_run / "monitor.csv", skiprows=1)
    assert list(monitor.columns) == ["r", "l", "t", "is_success", "wrap_angle_deg"]
    assert (monitor["wrap_angle_deg"] >= 0).all()
    noisy = evaluate(model=tiny_wrap_run / "best_model.zip", episodes=1, observation="cable_encoder",
                     sensor_noise="thesis")
    assert WRAP_KEYS <= set(noisy) and noisy["env_id"] == "SoftArm/CTWrap-v1"
    assert noisy["mean_estimation_error_m"] > 0.0
    assert main(["--model", str(tiny_wrap_run / "best_model.zip"), "--episodes", "1", "--no-progress"]) == 0
    assert "final wrap angle median" in capsys.readouterr().out


def test_wrap_grid_ship_and_report(tiny_wrap_run, tmp_path):
    runs_dir = tiny_wrap_run.parent
    out = tmp_path / "results"
    results.collect(runs_dir, out)
    jobs = results.evaluation_jobs(runs_dir, out, env_ids=("SoftArm/OctArmWrap-v1",))
    names = {path.stem for path, _ in jobs}
    cells = 1 + len(results.WRAP_CONDITIONS) * 6  # no payload condition on wrap
    assert len(jobs) == 2 * cells
    assert "planner_OctArmWrap-v1__inclinometer__noisy" in names
    assert not any("payload" in name for name in names)
    planner_job = next(kwargs for path, kwargs in jobs if path.stem == "planner_OctArmWrap-v1__main")
    assert planner_job["controller"] == "planner"
    # The run's main cell evaluated briefly; the planner's cells are a fixture.
    (out / "eval").mkdir()
    result = evaluate(model=tiny_wrap_run / "best_model.zip", episodes=1)
    (out / "eval" / f"{tiny_wrap_run.name}__main.json").write_text(
        json.dumps({**result, "cell": "main", "agent_name": tiny_wrap_run.name}))
    planner = {"agent": "planner", "env_id": "SoftArm/OctArmWrap-v1", "episodes": 20, "success_rate": 0.9,
               "median_wrap_angle_deg": 321.4, "p5_wrap_angle_deg": 94.0, "median_steps_to_success": 31.0,
               "mean_estimation_error_m": 0.0, "agent_name": "planner_OctArmWrap-v1"}
    for cell, extra in (("main", {}), ("cable_encoder__noisy", {"mean_estimation_error_m": 0.05,
                                                                 "success_rate": 0.85})):
        (out / "eval" / f"planner_OctArmWrap-v1__{cell}.json").write_text(
            json.dumps({**planner, **extra, "cell": cell}))
    shipped = results.ship(runs_dir, out, tmp_path / "trained", env_ids=["SoftArm/CTWrap-v1"])
    assert [p.name for p in shipped] == ["sac_CTWrap-v1.zip"]  # never the planner
    meta = json.loads(shipped[0].with_suffix(".json").read_text())
    assert meta["env_id"] == "SoftArm/CTWrap-v1" and meta["env_kwargs"] == {}
    assert results.ship(runs_dir, out, tmp_path / "none", env_ids=["SoftArm/OctArmReach-v0"]) == []
    text = results.report(out, tmp_path / "RESULTS.md")
    assert "## Reach with true observations" not in text  # no reach agent in this folder
    assert "## Wrap with true observations" in text
    assert f"| SoftArm/CTWrap-v1 | {tiny_wrap_run.name} | `{{}}` | – | 200 |" in text
    assert "| SoftArm/OctArmWrap-v1 | planner_OctArmWrap-v1 | – | – | – | – | – | 90 % | 321 | 94 | 31 |" \
        in text
    assert "## Estimator in the loop: wrap" in text
    assert "| cable_encoder | noisy | 85 % / 321 | 50.0 |" in text
    assert "best trained agent on SoftArm/OctArmWrap-v1" not in text  # no trained agent on it here


def test_corner_actions_train_load_and_evaluate_through_env_kwargs(tmp_path):
    """``env_kwargs: {action_wrapper: corners}`` puts CornerActions round the env wherever
    baselines makes it: training, the saved metadata, loading the policy and evaluating it."""
    tiny = {**TINY["ppo"], "n_envs": 1, "normalize": False, "n_steps": 32, "n_timesteps": 64,
            "env_kwargs": {"action_wrapper": "corners"}}
    run = train("SoftArm/CTWrap-v1", "ppo", seed=0, log_dir=tmp_path, hyperparams=tiny, eval_freq=0,
                checkpoint_freq=0, progress=False)
    policy, meta, _ = load_policy(run / "final_model.zip")
    assert meta["env_kwargs"] == {"action_wrapper": "corners"}
    assert policy.action_space == spaces.Discrete(2 ** 4)  # CT: four planar channels
    result = evaluate(model=run / "final_model.zip", episodes=1)
    assert WRAP_KEYS <= set(result) and result["solver_failures"] == 0


def test_unknown_action_wrapper_and_noise_on_discrete_actions_are_named():
    with pytest.raises(ValueError, match="unknown action_wrapper 'steps'; choose one of corners"):
        make_env("SoftArm/CTWrap-v1", {"action_wrapper": "steps"})
    with pytest.raises(ValueError, match="noise_type needs a continuous"):
        action_noise({"noise_type": "normal"}, spaces.Discrete(4))
    with pytest.raises(ValueError, match="noise_type must be one of 'normal', 'ornstein-uhlenbeck'; "
                                         "got 'pink'"):
        action_noise({"noise_type": "pink"}, spaces.Box(-1, 1, (2,)))
    assert make_env("SoftArm/CTWrap-v1", {"action_wrapper": "corners"}).action_space == spaces.Discrete(16)
    with pytest.raises(ValueError, match="--batched does not take an action_wrapper"):
        build("SoftArm/OctArmReach-v1", "ppo", {**TINY["ppo"], "env_kwargs": {"action_wrapper": "corners"}},
              seed=0, batched=True)


def test_ornstein_uhlenbeck_noise_is_correlated_in_time_and_reset_to_zero():
    noise = action_noise({"noise_type": "ornstein-uhlenbeck", "noise_std": 0.5}, spaces.Box(-1, 1, (3,)))
    draws = np.array([noise() for _ in range(400)])
    assert draws.shape == (400, 3)
    # Consecutive draws of an OU process share most of their value (theta·dt = 1.5e-3 per
    # step); independent Gaussian draws would correlate at 0.
    lag_one = np.corrcoef(draws[:-1].ravel(), draws[1:].ravel())[0, 1]
    assert lag_one > 0.9
    noise.reset()
    np.testing.assert_array_equal(noise.noise_prev, np.zeros(3))
