"""Collecting runs, shipping the best policy and regenerating RESULTS.md from saved files."""

import json

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
    wrap_cells = 2 * (1 + len(results.WRAP_CONDITIONS) * 6)  # the planner on both wrap envs
    assert len(jobs) == 3 * n_cells + wrap_cells  # the run and the Jacobian controller on both envs
    # Two cells, evaluated briefly, stand in for the grid.
    for cell, kwargs in (("main", {}), ("cable_encoder__noisy", {"observation": "cable_encoder",
                                                                 "sensor_noise": "thesis"})):
        result = evaluate(model=tiny_sac_run / "best_model.zip", episodes=1, **kwargs)
        result.update(cell=cell, agent_name=tiny_sac_run.name)
        (out / "eval").mkdir(exist_ok=True)
        (out / "eval" / f"{tiny_sac_run.name}__{cell}.json").write_text(json.dumps(result))
    # Done cells are skipped.
    assert len(results.evaluation_jobs(runs_dir, out)) == 3 * n_cells + wrap_cells - 2
    shipped = results.ship(runs_dir, out, tmp_path / "trained")
    assert [p.name for p in shipped] == ["sac_OctArmReach-v0.zip"]
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
