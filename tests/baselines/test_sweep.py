"""baselines.sweep on the local backend: the plan, bad input, a tiny sweep with its results and
--resume, and a run that keeps failing. The Ray backend is tested on the suite's local Ray
cluster in tests/test_jobs.py (one cluster for the whole suite)."""

import json
import socket

import pandas as pd
import pytest

from baselines.sweep import PACKAGES, PLAN_FILE, WorkerSetupError, main, parse_seeds, plan_runs, train_run
from softarm_gym.jobs import code_fingerprint
from tests.baselines.conftest import TINY, tiny_hyperparams

ENV_ID = "SoftArm/OctArmReach-v0"
TRAINING = ["--eval-freq", "100", "--eval-episodes", "1", "--checkpoint-freq", "100", "--no-progress"]
"""Periodic evaluation and checkpoints every 100 steps of the 200-step tiny runs."""


def _stderr_error(capsys) -> str:
    """The one error line the sweep printed (retry notes may precede it, no traceback)."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("baselines.sweep: error: ")]
    assert len(errors) == 1 and err.strip().splitlines()[-1] == errors[0], err
    return errors[0]


def test_seeds_and_the_plan():
    assert parse_seeds("0-3") == [0, 1, 2, 3] and parse_seeds("5, 0-1,1") == [0, 1, 5]
    for bad in ("", "a", "3-1", "-1", "1-"):
        with pytest.raises(ValueError, match="--seeds"):
            parse_seeds(bad)
    runs = plan_runs([ENV_ID], ["sac", "ppo"], [0, 1], ["true", "cable_encoder"], timesteps=500)
    assert len(runs) == 8 and {r.timesteps for r in runs} == {500}
    names = {r.name for r in runs}
    assert {"sac_OctArmReach-v0_s0", "ppo_OctArmReach-v0_cable_encoder_s1"} <= names and len(names) == 8
    cable = next(r for r in runs if r.observation == "cable_encoder")
    assert cable.hyperparams["env_kwargs"]["observation"] == "cable_encoder"
    plain = next(r for r in runs if r.observation == "true")
    assert "observation" not in plain.hyperparams["env_kwargs"]  # the YAML entry as it is
    assert plan_runs([ENV_ID], ["sac"], [0])[0].timesteps == 150_000  # the YAML budget
    for args, kwargs, message in (
            (([ENV_ID], ["dqn"], [0]), {}, "unknown algo 'dqn'"),
            (([ENV_ID], ["sac"], [0], ["truth"]), {}, "unknown observation 'truth'"),
            (([ENV_ID], ["sac_her"], [0], ["cable_encoder"]), {},
             "sac_her.yml\\['SoftArm/OctArmReach-v0'\\] with observation 'cable_encoder': "
             "observation_format='goal' needs observation='true'"),
            ((["SoftArm/OctArmWrap-v0"], ["sac"], [0]), {}, "no entry for 'SoftArm/OctArmWrap-v0'"),
            (([ENV_ID], ["sac"], [0]), {"timesteps": 0}, "timesteps must be an integer >= 1"),
            (([ENV_ID], ["sac"], []), {}, "the sweep has no runs")):
        with pytest.raises(ValueError, match=message):
            plan_runs(*args, **kwargs)


@pytest.mark.parametrize("argv, message", [
    (["--seeds", "0-x"], "--seeds '0-x'"),
    (["--algos", "sac,dqn"], "--algos: unknown 'dqn'"),
    (["--observations", "truth"], "--observations: unknown 'truth'"),
    (["--envs", "SoftArm/Nope-v0"], "registered SoftArm/* id"),
    (["--address", "127.0.0.1:1"], "--address needs --backend ray"),
    (["--results", "/nonexistent/R.md"], "directory '/nonexistent' does not exist"),
    (["--cpus-per-run", "0"], "cpus_per_run must be an integer >= 1"),
    (["--algos", "sac_her", "--observations", "true,load_cell"], "with observation 'load_cell': "
     "observation_format='goal' needs observation='true'"),
    (["--backend", "ray", "--address", "nowhere"], "is not 'auto', HOST:PORT"),
])
def test_bad_input_is_one_line_before_any_training(tmp_path, capsys, argv, message):
    assert main(["--out", str(tmp_path / "out"), "--timesteps", "100", *argv]) == 2
    assert message in _stderr_error(capsys)
    assert not list(tmp_path.glob("out/runs/*"))


def test_local_sweep_writes_runs_results_and_resumes(tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["--envs", ENV_ID, "--algos", "sac", "--seeds", "0", "--observations", "true,cable_encoder",
            "--timesteps", "200", "--hyperparams-dir", str(tiny_hyperparams(tmp_path / "hp")),
            "--out", str(out), "--evaluate-episodes", "1", *TRAINING]
    assert main(argv) == 0
    assert capsys.readouterr().out.strip() == str(out / "RESULTS.md")
    names = ["sac_OctArmReach-v0_s0", "sac_OctArmReach-v0_cable_encoder_s0"]
    for name, observation in zip(names, ("true", "cable_encoder")):
        run = out / "runs" / name
        summary = json.loads((run / "summary.json").read_text())
        assert summary["timesteps_done"] == 200 and summary["resumed_from"] is None
        meta = json.loads((run / "final_model.json").read_text())
        assert meta["env_kwargs"].get("observation", "true") == observation and meta["seed"] == 0
        assert meta["hyperparams"]["policy_kwargs"] == TINY["sac"]["policy_kwargs"]
        assert (run / "best_model.zip").is_file() and (run / "checkpoints" / "model_200_steps.json").is_file()
        assert (out / "results" / "training" / name / "monitor.csv").is_file()
        cell = json.loads((out / "results" / "eval" / f"{name}__main.json").read_text())
        assert cell["episodes"] == 1 and cell["observation"] == "true"
    assert (out / "results" / "eval" / "jacobian_OctArmReach-v0__main.json").is_file()
    assert not list((out / "results" / "eval").glob("*__cable_encoder__*"))  # --evaluate main: no grid
    plan = json.loads((out / "sweep.json").read_text())
    assert [(r["name"], r["state"], r["attempts"], r["node"]) for r in plan["runs"]] == \
        [(n, "finished", 1, socket.gethostname()) for n in names]
    text = (out / "RESULTS.md").read_text()
    assert "# Sweep results" in text and "--observations true,cable_encoder" in text
    for name, observation in zip(names, ("true", "cable_encoder")):
        assert f"| {name} | {ENV_ID} | sac | {observation} | 0 | 200 / 200 |" in text
        assert f"| {ENV_ID} | {name} | – | 200 |" in text  # its evaluation
    assert "1 episode each" in text and "![learning curves](results/learning_curves.png)" in text
    assert (out / "results" / "learning_curves.png").stat().st_size > 10_000
    assert "Estimator in the loop" not in text

    assert main(argv) == 2  # the runs are there: continuing them must be asked for
    assert "already holds 2 of the sweep's runs" in _stderr_error(capsys)
    monitor = (out / "runs" / names[0] / "monitor.csv").read_text()
    assert main(argv + ["--resume", "--evaluate", "none"]) == 0
    assert (out / "runs" / names[0] / "monitor.csv").read_text() == monitor  # nothing trained again
    assert main(argv[:-len(TRAINING)] + ["--timesteps", "300", "--resume", *TRAINING]) == 2
    assert "started with another timesteps than this sweep plans (200 vs 300)" in _stderr_error(capsys)


def test_a_run_that_keeps_failing_is_reported_and_the_others_finish(tmp_path, capsys):
    """A TD3 entry whose network cannot be built fails in the task itself (the plan's checks
    cannot see it): it is retried, given up, and named; the SAC run and the results are kept."""
    broken = {**TINY["td3"], "policy_kwargs": {"net_arch": [-8]}}
    out = tmp_path / "out"
    argv = ["--envs", ENV_ID, "--algos", "sac,td3", "--seeds", "1", "--timesteps", "200",
            "--hyperparams-dir", str(tiny_hyperparams(tmp_path / "hp", td3=broken)), "--out", str(out),
            "--retries", "1", "--evaluate", "none", *TRAINING]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "td3_OctArmReach-v0_s1 failed (RuntimeError: " in err and "attempt 2 of 2" in err
    line = err.strip().splitlines()[-1]
    assert line.startswith("baselines.sweep: error: 1 of 2 runs and 0 evaluation cells failed after 1 "
                           "retries (first: td3_OctArmReach-v0_s1: RuntimeError: ") and "--resume" in line
    assert "Traceback" not in err
    states = {r["name"]: r for r in json.loads((out / "sweep.json").read_text())["runs"]}
    failed = states["td3_OctArmReach-v0_s1"]
    assert failed["state"] == "failed" and failed["attempts"] == 2 and "negative dimension" in failed["error"]
    assert states["sac_OctArmReach-v0_s1"] == {**states["sac_OctArmReach-v0_s1"], "state": "finished",
                                               "attempts": 1, "error": None}
    assert failed["node"] is None
    text = (out / "RESULTS.md").read_text()
    assert "| td3_OctArmReach-v0_s1 | SoftArm/OctArmReach-v0 | td3 | true | 1 | – / 200 |" in text
    assert "failed: RuntimeError" in text
    assert "| sac_OctArmReach-v0_s1 | SoftArm/OctArmReach-v0 | sac | true | 1 | 200 / 200 |" in text
    assert len(pd.read_csv(out / "results" / "training" / "sac_OctArmReach-v0_s1" / "monitor.csv")) > 0


def test_a_worker_refuses_other_code_or_an_output_folder_it_cannot_see(tmp_path):
    """What a Ray worker on a node without the shared folder or with another install runs into;
    the driver turns it into a one-line error (exit status 2)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / PLAN_FILE).write_text(json.dumps({"id": "this-sweep"}))
    spec = plan_runs([ENV_ID], ["sac"], [0], timesteps=100)[0]
    with pytest.raises(WorkerSetupError, match="runs other solver/softarm_gym/baselines code"):
        train_run(spec, {}, str(out), "this-sweep", "0123456789abcdef")
    with pytest.raises(WorkerSetupError, match="does not see the sweep's output folder"):
        train_run(spec, {}, str(tmp_path / "elsewhere"), "this-sweep", code_fingerprint(PACKAGES))
    with pytest.raises(WorkerSetupError, match="does not see the sweep's output folder"):
        train_run(spec, {}, str(out), "an-older-sweep", code_fingerprint(PACKAGES))
    assert not (out / "runs").exists()
