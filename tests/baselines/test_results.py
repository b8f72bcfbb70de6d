"""Collecting runs, shipping the best policy and regenerating RESULTS.md from saved files."""

import json
from pathlib import Path

import numpy as np
import pandas as pd

from baselines import results
from baselines.evaluate import evaluate, main


def test_collect_ship_report_round_trip(tiny_sac_run, tmp_path, capsys):
    runs_dir = tiny_sac_run.parent
    out = tmp_path / "results"
    assert results.collect(runs_dir, out) == [tiny_sac_run.name]
    training = out / "training" / tiny_sac_run.name
    monitor = pd.read_csv(training / "monitor.csv")
    assert monitor["timesteps"].iloc[-1] == monitor["l"].sum()
    assert list(pd.read_csv(training / "evaluations.csv").columns) == ["timesteps", "success_rate",
                                                                       "mean_return", "episodes"]
    jobs = results.evaluation_jobs(runs_dir, out)
    n_cells = 1 + len(results.CONDITIONS) * 6
    # The planner on each wrap env; the planner and the scripted curl on the grasp env.
    wrap_cells = ((len(results.WRAP_ENV_IDS) + 2 * len(results.GRASP_ENV_IDS))
                  * (1 + len(results.WRAP_CONDITIONS) * 6))
    # The run, and the Jacobian controller on both reach, both track and both obstacle-reach envs.
    assert len(jobs) == 7 * n_cells + wrap_cells
    # Two cells, evaluated briefly, stand in for the grid.
    for cell, kwargs in (("main", {}), ("cable_encoder__noisy", {"observation": "cable_encoder",
                                                                 "sensor_noise": "thesis"})):
        result = evaluate(model=tiny_sac_run / "best_model.zip", episodes=1, **kwargs)
        result.update(cell=cell, agent_name=tiny_sac_run.name)
        (out / "eval").mkdir(exist_ok=True)
        (out / "eval" / f"{tiny_sac_run.name}__{cell}.json").write_text(json.dumps(result))
    # Done cells are skipped.
    assert len(results.evaluation_jobs(runs_dir, out)) == 7 * n_cells + wrap_cells - 2
    # A policy of another algorithm shipped earlier for the env is displaced (one per env);
    # other envs' policies stay.
    trained = tmp_path / "trained"
    trained.mkdir()
    earlier = [trained / name for name in ("ppo_OctArmReach-v0.zip", "ppo_OctArmReach-v0.json",
                                           "ppo_OctArmReach-v0_vecnormalize.json", "ppo_CTReach-v0.zip")]
    for path in earlier:
        path.write_text("earlier")
    shipped = results.ship(runs_dir, out, trained)
    assert [p.name for p in shipped] == ["sac_OctArmReach-v0.zip"]
    assert [p.is_file() for p in earlier] == [False, False, False, True]
    meta = json.loads(shipped[0].with_suffix(".json").read_text())
    assert meta["selected_from"] == tiny_sac_run.name
    assert main(["--model", str(shipped[0]), "--episodes", "1", "--json", "--no-progress"]) == 0
    assert "success_rate" in json.loads(capsys.readouterr().out)
    text = results.report(out, tmp_path / "RESULTS.md")
    assert (out / "learning_curves.png").is_file()
    assert f"| SoftArm/OctArmReach-v0 | {tiny_sac_run.name} | " in text
    assert "| cable_encoder | noisy |" in text
    assert "1 episode each" in text and "periodic deterministic evaluations, 1 episode)" in text
    assert "![learning curves](results/learning_curves.png)" in text


def test_final_models_are_evaluated_on_unseen_seeds_and_shipped_as_evaluated(tiny_sac_run, tmp_path):
    runs_dir, out = tiny_sac_run.parent, tmp_path / "results"
    jobs = results.evaluation_jobs(runs_dir, out, grid=False, env_ids=(), seed=100_000,
                                   policy_file="final_model.zip")
    assert [(path.name, kwargs["model"], kwargs["seed"]) for path, kwargs in jobs] == \
        [(f"{tiny_sac_run.name}__main.json", tiny_sac_run / "final_model.zip", 100_000)]
    result = evaluate(**{**jobs[0][1], "episodes": 1})
    assert result["agent"] == "sac:final_model.zip" and result["seed"] == 100_000
    (out / "eval").mkdir(parents=True)
    (out / "eval" / jobs[0][0].name).write_text(json.dumps({**result, "cell": "main",
                                                            "agent_name": tiny_sac_run.name}))
    (shipped,) = results.ship(runs_dir, out, tmp_path / "trained")
    assert shipped.read_bytes() == (tiny_sac_run / "final_model.zip").read_bytes()
    assert shipped.read_bytes() != (tiny_sac_run / "best_model.zip").read_bytes()


def test_a_run_ships_under_the_registered_id_whose_defaults_it_trained_in():
    from baselines.config import registered_equivalent

    delta = {"action_mode": "delta", "delta_scale": 0.1}
    assert registered_equivalent("SoftArm/OctArmReach-v0", delta) == ("SoftArm/OctArmReach-v1", {})
    assert registered_equivalent("SoftArm/CTReach-v0", {**delta, "observation_format": "goal"}) == \
        ("SoftArm/CTReach-v1", {"observation_format": "goal"})
    # Other kwargs than a registered version's defaults keep the run's own id.
    for kwargs in ({}, {"action_mode": "delta", "delta_scale": 0.2}, {"action_mode": "delta"}):
        assert registered_equivalent("SoftArm/OctArmReach-v0", kwargs) == ("SoftArm/OctArmReach-v0", kwargs)
    assert registered_equivalent("SoftArm/OctArmWrap-v0", {}) == ("SoftArm/OctArmWrap-v0", {})
    meta = {"env_id": "SoftArm/OctArmReach-v0", "env_kwargs": delta, "algo": "sac"}
    shipped = results.shipped_metadata(meta, "sac_OctArmReach-v0_s1", "SoftArm/OctArmReach-v1", {})
    assert shipped["env_id"] == "SoftArm/OctArmReach-v1" and shipped["env_kwargs"] == {}
    assert shipped["trained_on"] == {"env_id": "SoftArm/OctArmReach-v0", "env_kwargs": delta}
    assert shipped["selected_from"] == "sac_OctArmReach-v0_s1"


def _run_summary(name: str, env_id: str, seed: int, env_kwargs: dict) -> dict:
    return {"env_id": env_id, "algo": "sac", "seed": seed, "env_kwargs": env_kwargs, "timesteps_done": 80000,
            "wall_time_s": 330.0, "cpu_time_s": 324.0, "time_limit_min": 8, "run": name}


def test_report_has_track_and_obstacle_sections(tmp_path):
    # Saved files only: two SAC seeds and the Jacobian controller per task.
    out = tmp_path / "results"
    (out / "eval").mkdir(parents=True)
    track, obstacle = "SoftArm/OctArmTrack-v0", "SoftArm/OctArmObstacleReach-v0"
    base = {"episodes": 50, "cell": "main", "observation": "true", "median_steps_to_success": 12.0,
            "mean_estimation_error_m": 0.0, "p95_final_error_m": 0.05}
    cells = {f"sac_OctArmTrack-v0_s{s}": {"env_id": track, "agent": "sac:best_model.zip",
                                          "success_rate": rate, "median_final_error_m": 0.012,
                                          "median_tracking_rms_m": rms, "median_tracking_max_m": 0.1}
             for s, rate, rms in ((0, 0.6, 0.02), (1, 0.8, 0.03))}
    cells |= {f"sac_OctArmObstacleReach-v0_s{s}": {"env_id": obstacle, "agent": "sac:best_model.zip",
                                                   "success_rate": rate, "median_final_error_m": 0.01,
                                                   "contact_rate": contact}
              for s, rate, contact in ((0, 0.5, 0.2), (1, 0.7, 0.4))}
    cells["jacobian_OctArmTrack-v0"] = {"env_id": track, "agent": "jacobian", "success_rate": 1.0,
                                        "median_final_error_m": 0.001, "median_tracking_rms_m": 0.0046,
                                        "median_tracking_max_m": 0.03}
    cells["jacobian_OctArmObstacleReach-v0"] = {"env_id": obstacle, "agent": "jacobian", "success_rate": 0.9,
                                                "median_final_error_m": 0.002, "contact_rate": 0.25}
    for name, cell in cells.items():
        (out / "eval" / f"{name}__main.json").write_text(json.dumps({**base, **cell, "agent_name": name}))
        if name.startswith("sac_"):
            env_id = cell["env_id"]
            kwargs = {"action_mode": "delta", "delta_scale": 0.1} if env_id == track else {}
            (out / "training" / name).mkdir(parents=True)
            (out / "training" / name / "summary.json").write_text(
                json.dumps(_run_summary(name, env_id, int(name[-1]), kwargs)))
    text = results.report(out, tmp_path / "RESULTS.md")
    assert "## Reach with true observations" not in text and "## Wrap with true observations" not in text
    assert "## Track with true observations" in text and "## Obstacle reach with true observations" in text
    assert text.index("## Track with") < text.index("## Obstacle reach with")
    assert ("| SoftArm/OctArmTrack-v0 | sac_OctArmTrack-v0_s0 | `{\"action_mode\": \"delta\", "
            "\"delta_scale\": 0.1}` | 8 | 80,000 | 5.5 | 5.4 | 60 % | 20.0 | 100.0 | 12.0 |") in text
    assert ("| SoftArm/OctArmTrack-v0 | jacobian_OctArmTrack-v0 | – | – | – | – | – | 100 % | 4.6 | 30.0 "
            "| 1.0 |") in text
    assert "**sac mean ± std over 2 seeds** | `{\"action_mode\": \"delta\", \"delta_scale\": 0.1}` | " \
           "| | | | **70 ± 14 %** | 25.0 | 100.0 | 12.0 |" in text
    assert ("| SoftArm/OctArmObstacleReach-v0 | sac_OctArmObstacleReach-v0_s1 | 8 | 80,000 | 5.5 | 5.4 "
            "| 70 % | 10.0 | 50.0 | 40 % | 12 |") in text
    assert ("| SoftArm/OctArmObstacleReach-v0 | jacobian_OctArmObstacleReach-v0 | – | – | – | – | 90 % "
            "| 2.0 | 50.0 | 25 % | 12 |") in text
    assert "| **sac mean ± std over 2 seeds** | | | | | **60 ± 14 %** | 10.0 | 50.0 | 30 % | |" in text
    assert results.task(track) == "track" and results.task(obstacle) == "obstacle"
    assert results.task("SoftArm/CTReach-v1") == "reach" and results.task("SoftArm/CTWrap-v1") == "wrap"


def test_shipped_metadata_records_the_budget_that_was_trained():
    """``hyperparams.n_timesteps`` is the run's budget (``timesteps``), not a YAML default it
    overrode; ``timesteps_done`` may be less (a time limit), or up to the end of the rollout
    that crosses the budget (PPO collects whole rollouts of n_envs × n_steps)."""
    shipped = sorted((Path(__file__).resolve().parents[2] / "baselines" / "trained").glob("*.json"))
    metadata = [json.loads(p.read_text()) for p in shipped if not p.name.endswith("_vecnormalize.json")]
    assert len(metadata) >= 5
    for meta in metadata:
        hyperparams = meta["hyperparams"]
        budget = hyperparams["n_timesteps"]
        ppo = meta["algo"] == "ppo"
        rollout = hyperparams.get("n_envs", 1) * hyperparams.get("n_steps", 2048) if ppo else 1
        assert budget == meta["timesteps"], meta["env_id"]
        assert meta["timesteps_done"] <= -(-budget // rollout) * rollout, meta["env_id"]


def _wrap_v2_run(out: Path, name: str, rate: float, wrap: float, summary: dict) -> None:
    """A PPO run on OctArmWrap-v2 in a results folder: its main evaluation (success ``rate``,
    median wrap ``wrap``) and its summary (:func:`_run_summary` updated with ``summary``)."""
    env_id = "SoftArm/OctArmWrap-v2"
    (out / "eval").mkdir(parents=True, exist_ok=True)
    (out / "eval" / f"{name}__main.json").write_text(json.dumps(
        {"episodes": 50, "cell": "main", "observation": "true", "env_id": env_id,
         "agent": "ppo:best_model.zip", "median_steps_to_success": 20.0, "mean_estimation_error_m": 0.0,
         "p5_wrap_angle_deg": 80.0,
         "agent_name": name, "success_rate": rate, "median_wrap_angle_deg": wrap}))
    (out / "training" / name).mkdir(parents=True)
    (out / "training" / name / "summary.json").write_text(json.dumps(
        {**_run_summary(name, env_id, int(name[-1]), {}), "algo": "ppo", **summary}))


def test_batched_runs_get_seed_bands_and_remedies_are_pooled_apart(tmp_path):
    # Saved files only: two seeds of PPO on the batched wrap and one of a remedy in its own YAML
    # folder; the remedy has the same env kwargs but must not be pooled with them.
    out = tmp_path / "results"
    runs = {"ppo_OctArmWrap-v2_batched_s0": ("batched", 0.2, 100.0),
            "ppo_OctArmWrap-v2_batched_s1": ("batched", 0.4, 200.0),
            "ppo_OctArmWrap-v2_batched_gsde_s0": ("batched_gsde", 0.9, 300.0)}
    for name, (folder, rate, wrap) in runs.items():
        _wrap_v2_run(out, name, rate, wrap, {"batched": True, "hyperparams": {"n_envs": 4},
                                             "hyperparams_file": f"baselines/hyperparams/{folder}/ppo.yml"})
        episodes = pd.DataFrame({"r": np.linspace(0, 50, 40), "l": 200, "t": np.linspace(1, 100, 40),
                                 "is_success": np.arange(40) > 20 + int(name[-1]), "wrap_angle_deg": 90.0})
        episodes["timesteps"] = episodes["l"].cumsum()
        episodes.to_csv(out / "training" / name / "monitor.csv", index=False)
    text = results.report(out, tmp_path / "RESULTS.md")
    assert (out / results.BATCHED_CURVES).is_file()
    assert f"![batched learning curves](results/{results.BATCHED_CURVES})" in text
    assert "| **ppo (batched) mean ± std over 2 seeds** | `{}` | | | | | **30 ± 14 %** | 150 | 80 | |" in text
    assert "ppo (batched_gsde) mean" not in text  # one seed: no mean row, and not in the batched mean
    assert "| SoftArm/OctArmWrap-v2 | ppo_OctArmWrap-v2_batched_gsde_s0 | `{}` | 8 | 80,000 |" in text


def test_remedies_table_keeps_cloned_and_warm_started_policies_apart_from_their_yaml_folder(tmp_path):
    # Saved files only: gSDE PPO (2 seeds), BC from planner demonstrations (2 seeds) and a PPO
    # warm-started from BC (1 seed), all from batched_gsde's YAML: three remedies, not one.
    out = tmp_path / "results"
    runs = {"ppo_OctArmWrap-v2_batched_gsde_s0": ({}, 0.9, 240.0),
            "ppo_OctArmWrap-v2_batched_gsde_s1": ({}, 0.3, 100.0),
            "bc_OctArmWrap-v2_s0": ({"imitation": {"method": "bc"}}, 0.5, 200.0),
            "bc_OctArmWrap-v2_s1": ({"imitation": {"method": "bc"}}, 0.7, 220.0),
            "ppo_OctArmWrap-v2_batched_gsde_bc_s0": ({"init_policy": "runs/bc/final_model.zip"}, 1.0, 250.0)}
    for name, (extra, rate, wrap) in runs.items():
        _wrap_v2_run(out, name, rate, wrap, {"hyperparams_file": "baselines/hyperparams/batched_gsde/ppo.yml",
                                             **extra})
    text = results.report(out, tmp_path / "RESULTS.md")
    assert "## Remedies on SoftArm/OctArmWrap-v2" in text
    assert ("| exploration: gSDE | ppo (batched_gsde) | 2 | 90 % / 30 % | **60 ± 42 %** | 170 "
            "| 80,000, 80,000 |") in text
    assert ("| behaviour cloning of planner demonstrations (no RL) | ppo (batched_gsde, bc) | 2 "
            "| 50 % / 70 % | **60 ± 14 %** | 210 |") in text
    assert ("| BC warm start, then gSDE PPO | ppo (batched_gsde, from bc) | 1 | 100 % | **100 %** "
            "| 250 |") in text
    assert "**ppo (batched_gsde) mean ± std over 2 seeds** | `{}` | | | | | **60 ± 42 %**" in text


def test_two_rounds_of_one_setting_pool_into_one_seed_mean_that_names_repeated_seeds(tmp_path):
    # Saved files only: gSDE PPO trained twice on seeds 0 and 1 (a second round renamed _r2_). The
    # rounds are one setting: the table and the target line pool all four runs, name the repeated
    # seeds, and the better round alone does not make the target.
    out = tmp_path / "results"
    runs = {"ppo_OctArmWrap-v2_batched_gsde_s0": 0.3, "ppo_OctArmWrap-v2_batched_gsde_s1": 0.2,
            "ppo_OctArmWrap-v2_batched_gsde_r2_s0": 0.9, "ppo_OctArmWrap-v2_batched_gsde_r2_s1": 0.8}
    for name, rate in runs.items():
        _wrap_v2_run(out, name, rate, 200.0,
                     {"hyperparams_file": "baselines/hyperparams/batched_gsde/ppo.yml"})
    text = results.report(out, tmp_path / "RESULTS.md")
    assert ("**ppo (batched_gsde) mean ± std over 4 runs, seeds 0, 0, 1, 1** | `{}` | | | | | "
            "**55 ± 35 %**") in text
    assert "best seed mean 55 % (ppo (batched_gsde), 4 runs, seeds 0, 0, 1, 1) — NOT met" in text
