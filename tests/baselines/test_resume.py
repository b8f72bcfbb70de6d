"""Training survives faults: Ctrl-C and kill -9 in the middle of a tiny run, then --resume.

The subprocess tests start ``python -m baselines.train`` with a budget far larger than they
let it run, wait until checkpoints exist, then interrupt it.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from baselines import train as train_module
from baselines.config import load_policy, sidecar_paths
from baselines.evaluate import evaluate
from baselines.train import TrainingInterrupted, latest_checkpoint, resume, train
from tests.baselines.conftest import TINY, tiny_hyperparams

ENV_ID = "SoftArm/OctArmReach-v0"
ROOT = Path(__file__).resolve().parents[2]


def _start(tmp_path, *extra):
    hyperparams = tiny_hyperparams(tmp_path / "hyperparams")
    argv = [sys.executable, "-m", "baselines.train", "--env", ENV_ID, "--algo", "sac", "--seed", "5",
            "--timesteps", "1000000", "--log-dir", str(tmp_path / "runs"), "--hyperparams-dir",
            str(hyperparams), "--checkpoint-freq", "100", "--eval-freq", "100", "--eval-episodes", "1",
            "--no-progress", "--threads", "1", *extra]
    proc = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, tmp_path / "runs" / "sac_OctArmReach-v0_s5"


def _wait_for(proc, path: Path, timeout: float = 240.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"{path.name} did not appear in {timeout} s"
        time.sleep(0.2)


def _checkpoint_steps(run: Path) -> list[int]:
    return sorted(int(p.name.split("_")[1]) for p in (run / "checkpoints").glob("model_*_steps.json"))


def _assert_complete_and_loadable(run: Path) -> None:
    """Every checkpoint with metadata has its files and loads safely; no temp file has a final name."""
    steps = _checkpoint_steps(run)
    assert steps
    for n in steps:
        model = run / "checkpoints" / f"model_{n}_steps.zip"
        meta = json.loads(sidecar_paths(model)[0].read_text())
        assert meta["timesteps_done"] == n and sidecar_paths(model)[1].is_file()
        load_policy(model)
    for name in ("best_model.zip", "evaluations.npz"):
        if (run / name).exists():
            if name.endswith(".npz"):
                np.load(run / name)
            else:
                load_policy(run / name)


def test_ctrl_c_saves_everything_and_resume_continues_the_step_counter(tmp_path):
    proc, run = _start(tmp_path, "--save-replay-buffer")
    _wait_for(proc, run / "checkpoints" / "model_200_steps.json")
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    line = err.strip().splitlines()[-1]
    assert line.startswith("baselines.train: interrupted at step ") and f"--resume {run}" in line
    stopped = int(line.split("interrupted at step ")[1].split(";")[0])
    checkpoint = run / "checkpoints" / f"model_{stopped}_steps.zip"
    meta = json.loads(sidecar_paths(checkpoint)[0].read_text())
    assert meta["kind"] == "interrupted" and meta["timesteps_done"] == stopped
    assert meta["replay_buffer"] == f"model_{stopped}_steps_replay_buffer.npz"
    assert [p.name for p in (run / "checkpoints").glob("*replay_buffer.npz")] == [meta["replay_buffer"]]
    _assert_complete_and_loadable(run)
    assert evaluate(model=checkpoint, episodes=1)["episodes"] == 1

    monitor_rows = len(pd.read_csv(run / "monitor.csv", skiprows=1))
    resume(run, timesteps=stopped + 150, progress=False)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["timesteps_done"] == stopped + 150 and summary["resumed_from"] == stopped
    assert json.loads((run / "final_model.json").read_text())["timesteps_done"] == stopped + 150
    assert max(_checkpoint_steps(run)) == (stopped + 150) // 100 * 100
    assert len(pd.read_csv(run / "monitor.csv", skiprows=1)) > monitor_rows  # appended, not replaced
    assert list(run.glob("progress_*.csv"))  # the first session's log is kept
    evaluations = np.load(run / "evaluations.npz")["timesteps"]
    assert list(evaluations) == sorted(evaluations) and evaluations[-1] > stopped


def test_kill_9_leaves_complete_checkpoints_that_resume(tmp_path):
    proc, run = _start(tmp_path)
    _wait_for(proc, run / "checkpoints" / "model_300_steps.json")
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    _assert_complete_and_loadable(run)
    last = latest_checkpoint(run)
    start = json.loads(sidecar_paths(last)[0].read_text())["timesteps_done"]
    completed = subprocess.run([sys.executable, "-m", "baselines.train", "--resume", str(run), "--timesteps",
                                str(start + 120), "--no-progress"], cwd=ROOT, capture_output=True, text=True,
                               timeout=600)
    assert completed.returncode == 0, completed.stderr
    assert f"resuming {run.name} at step {start} of {start + 120}" in completed.stderr
    assert "no replay buffer saved: collecting 50 steps first" in completed.stderr
    assert json.loads((run / "summary.json").read_text())["timesteps_done"] == start + 120
    _assert_complete_and_loadable(run)


def test_python_api_raises_training_interrupted_after_saving(tmp_path, monkeypatch):
    """What a sweep (e.g. on Ray) sees when a trial is cancelled with KeyboardInterrupt."""
    original = train_module.Checkpoints._on_step

    def interrupt_at_150(self):
        if self.model.num_timesteps >= 150:
            raise KeyboardInterrupt
        return original(self)

    monkeypatch.setattr(train_module.Checkpoints, "_on_step", interrupt_at_150)
    with pytest.raises(TrainingInterrupted) as info:
        train(ENV_ID, "sac", seed=2, log_dir=tmp_path, hyperparams=TINY["sac"], eval_freq=0,
              checkpoint_freq=100, progress=False, tensorboard=False)
    assert info.value.timesteps == 150 and info.value.checkpoint == latest_checkpoint(info.value.run_dir)
    monkeypatch.undo()
    run = resume(info.value.run_dir, timesteps=250, progress=False)
    assert json.loads((run / "summary.json").read_text())["timesteps_done"] == 250


def test_resume_extends_a_finished_run_with_its_history(tiny_sac_run, tmp_path):
    run = tmp_path / tiny_sac_run.name
    shutil.copytree(tiny_sac_run, run)
    best = json.loads((run / "best_model.json").read_text())["best_mean_reward"]
    resume(run, timesteps=300, progress=False)
    assert list(np.load(run / "evaluations.npz")["timesteps"]) == [100, 200, 300]
    assert json.loads((run / "best_model.json").read_text())["best_mean_reward"] >= best
    assert json.loads((run / "config.json").read_text())["timesteps"] == 300


def test_on_policy_resume_with_reward_normalisation(tmp_path):
    run = train("SoftArm/CTReach-v0", "ppo", seed=1, log_dir=tmp_path, hyperparams=TINY["ppo"], eval_freq=0,
                checkpoint_freq=128, progress=False, tensorboard=False)
    norm = json.loads((run / "checkpoints" / "model_256_steps_vecnormalize.json").read_text())
    assert norm["norm_reward"] and norm["ret_rms"]["count"] > 1
    resume(run, timesteps=512, progress=False)
    assert json.loads((run / "summary.json").read_text())["timesteps_done"] == 512


def test_misuse_is_a_clear_error(tiny_sac_run, tmp_path):
    with pytest.raises(ValueError, match="already holds a run; continue it with --resume"):
        train(ENV_ID, "sac", seed=3, log_dir=tiny_sac_run.parent, hyperparams=TINY["sac"], progress=False)
    with pytest.raises(ValueError, match="checkpoint_freq must be an integer >= 0"):
        train(ENV_ID, "sac", log_dir=tmp_path / "new", hyperparams=TINY["sac"], checkpoint_freq=-1)
    with pytest.raises(ValueError, match="is not a training run folder"):
        resume(tmp_path)
    (tmp_path / "config.json").write_text(json.dumps({"env_id": ENV_ID}))
    with pytest.raises(ValueError, match="no complete checkpoint"):
        resume(tmp_path)


def test_sigterm_saves_like_ctrl_c(tmp_path):
    proc, run = _start(tmp_path)
    _wait_for(proc, run / "checkpoints" / "model_100_steps.json")
    os.kill(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert err.strip().splitlines()[-1].startswith("baselines.train: interrupted at step ")
    assert json.loads(sidecar_paths(latest_checkpoint(run))[0].read_text())["kind"] == "interrupted"


def test_fault_drill_counts_what_it_checks(tiny_sac_run, tmp_path):
    from baselines import faults

    run = tmp_path / "run"
    shutil.copytree(tiny_sac_run, run)
    assert faults.check_folder(run) == 0
    (run / "checkpoints" / "model_100_steps.zip").write_bytes(b"half a zip")
    assert faults.check_folder(run) == 1
    tally = faults.drill(cycles=1, timesteps=1500, workdir=tmp_path / "drill")
    assert tally["sigint"] == tally["clean_sigint_exits"] == tally["sigint_saved_at_stop"] == 1
    assert tally["unloadable_files"] == 0 and tally["final_timesteps"] == 1500
