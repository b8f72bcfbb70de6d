"""The evaluation script on a tiny saved model, and its bad-input handling."""

import json
from pathlib import Path

import numpy as np
import pytest

from baselines.evaluate import evaluate, main, summarize

KEYS = {"success_rate", "median_final_error_m", "p95_final_error_m", "reached_rate",
        "median_steps_to_success", "mean_estimation_error_m", "episodes", "solver_failures"}


def test_evaluate_saved_model_with_estimator_in_the_loop(tiny_sac_run):
    model = tiny_sac_run / "final_model.zip"
    truth = evaluate(model=model, episodes=2, seed=5)
    assert KEYS <= set(truth)
    assert truth["env_id"] == "SoftArm/OctArmReach-v0" and truth["episodes"] == 2
    assert 0.0 <= truth["success_rate"] <= 1.0
    assert truth["mean_estimation_error_m"] == 0.0  # "true" observations are the equilibrium
    noisy = evaluate(model=model, episodes=2, seed=5, observation="constant_curvature",
                     sensor_noise="thesis", payload_kg=(0.1, 0.3))
    assert noisy["mean_estimation_error_m"] > 0.0
    assert noisy["payload_kg"] == [0.1, 0.3]
    assert evaluate(model=model, episodes=2, seed=5) == {**truth, "wall_time_s": pytest.approx(0, abs=1e9)}


def test_cli_json_and_out_file(tiny_sac_run, tmp_path, capsys):
    out = tmp_path / "eval.json"
    code = main(["--model", str(tiny_sac_run / "best_model.zip"), "--env", "SoftArm/OctArmReach-v0",
                 "--episodes", "1", "--json", "--no-progress", "--out", str(out)])
    assert code == 0
    printed = json.loads(capsys.readouterr().out)
    assert KEYS <= set(printed) and json.loads(out.read_text()) == printed


@pytest.mark.parametrize(("argv", "message"), [
    (["--model", "missing.zip"], "existing .zip"),
    (["--controller", "jacobian"], "--env is required"),
    (["--controller", "jacobian", "--env", "SoftArm/CTReach-v0", "--payload-kg", "a"], "--payload-kg"),
    (["--controller", "jacobian", "--env", "SoftArm/CTReach-v0", "--env-kwargs", "[1]"], "JSON object"),
    (["--controller", "jacobian", "--env", "SoftArm/CTReach-v0", "--episodes", "0"], "episodes must be"),
])
def test_cli_bad_input(argv, message, capsys):
    assert main([*argv, "--no-progress"]) == 2
    assert message in capsys.readouterr().err


def test_summarize_counts_steps_only_over_reached_episodes():
    record = {"final_error": np.array([0.01, 0.05, 0.03, 0.0]),
              "success": np.array([True, False, False, True]),
              "steps_to_success": np.array([4, -1, 10, 2]), "estimation_error": np.zeros(4),
              "episode_return": np.zeros(4), "solver_failures": np.array([0, 1, 0, 0])}
    s = summarize(record)
    assert s["success_rate"] == 0.5 and s["reached_rate"] == 0.75
    assert s["median_steps_to_success"] == 4.0
    assert s["median_final_error_m"] == pytest.approx(0.02)
    assert s["solver_failures"] == 1


def test_summarize_adds_tracking_errors_on_track_and_contact_on_obstacle_reach():
    common = {"final_error": np.array([0.01, 0.05, 0.03]), "success": np.array([True, False, False]),
              "steps_to_success": np.array([4, -1, -1]), "estimation_error": np.zeros(3),
              "episode_return": np.zeros(3), "solver_failures": np.zeros(3, dtype=int),
              "final_wrap_deg": np.full(3, np.nan)}
    nan = {key: np.full(3, np.nan) for key in ("tracking_rms", "tracking_max", "contact")}
    track = summarize({**common, **nan, "tracking_rms": np.array([0.02, 0.04, 0.01]),
                       "tracking_max": np.array([0.05, 0.2, 0.03])})
    assert track["median_tracking_rms_m"] == pytest.approx(0.02)
    assert track["median_tracking_max_m"] == pytest.approx(0.05)
    assert track["median_final_error_m"] == pytest.approx(0.03) and "contact_rate" not in track
    obstacle = summarize({**common, **nan, "contact": np.array([1.0, 0.0, 1.0])})
    assert obstacle["contact_rate"] == pytest.approx(2 / 3) and "median_tracking_rms_m" not in obstacle
    reach = summarize({**common, **nan})
    assert not {"contact_rate", "median_tracking_rms_m", "median_tracking_max_m"} & set(reach)


@pytest.mark.parametrize(("env_id", "keys"), [
    ("SoftArm/OctArmTrack-v0", {"median_tracking_rms_m", "median_tracking_max_m"}),
    ("SoftArm/OctArmObstacleReach-v0", {"contact_rate"}),
])
def test_evaluate_records_the_track_and_obstacle_measures(env_id, keys):
    result = evaluate(controller="jacobian", env_id=env_id, episodes=1)
    assert keys <= set(result) and "median_final_error_m" in result
    for key in keys:
        assert 0.0 <= result[key] <= 1.0  # metres or a fraction


SHIPPED = Path(__file__).resolve().parents[2] / "baselines" / "trained"


@pytest.mark.parametrize(("model", "env", "message"), [
    ("sac_OctArmReach-v1.zip", "SoftArm/OctArmReach-v0",
     "action semantics: delta actions (delta_scale 0.1) vs absolute actions"),
    ("sac_OctArmWrap3D-v0.zip", "SoftArm/OctArmWrap-v1",
     "action space: Box(9,) vs Box(6,); observation space: Box(61,) vs Box(39,)"),
    ("ppo_OctArmWrap-v1.zip", "SoftArm/CTWrap-v1", "action space: Discrete(64) vs Discrete(16)"),
])
def test_a_model_on_an_env_it_was_not_trained_for_is_refused_in_one_line(model, env, message, capsys):
    argv = ["--model", str(SHIPPED / model), "--env", env, "--episodes", "1", "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and env in err[0] and "--force" in err[0], err


def test_force_evaluates_anyway_and_lists_the_differences():
    result = evaluate(model=SHIPPED / "sac_OctArmReach-v1.zip", env_id="SoftArm/OctArmReach-v0", episodes=1,
                      force=True)
    assert result["model_env_differences"] == [
        "action semantics: delta actions (delta_scale 0.1) vs absolute actions"]
    same = evaluate(model=SHIPPED / "sac_OctArmReach-v1.zip", env_id="SoftArm/OctArmReach-v0", episodes=1,
                    env_kwargs={"action_mode": "delta", "delta_scale": 0.1})
    assert "model_env_differences" not in same  # the same env under its old id
