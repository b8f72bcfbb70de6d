"""Fault drill: interrupt a small training run again and again, resume it each time, count what is lost.

    python -m baselines.faults --cycles 20 --json

Trains SAC with 8-unit networks on ``SoftArm/OctArmReach-v0`` through the real command line
(``python -m baselines.train``, checkpoints every 100 steps, replay buffer saved). Each
cycle lets a session run until it has written a new checkpoint and then for a random 0–3 s
more, stops it with SIGINT (even cycles) or SIGKILL (odd cycles), and the next cycle resumes with
``--resume``. After every stop it checks: the exit (status 130 and one line, no traceback,
for SIGINT), that every checkpoint with metadata loads with the safe loader, that no file
under a final name is half-written (all load), and for SIGINT that the saved checkpoint is
at the step where the run stopped. A last session runs to the target, which must be reached
exactly.
"""

from __future__ import annotations

import argparse
import json
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from baselines.config import load_policy, sidecar_paths
from baselines.train import latest_checkpoint

__all__ = ["drill", "main"]

ENV_ID = "SoftArm/OctArmReach-v0"
HYPERPARAMS = {"policy": "MlpPolicy", "n_timesteps": 1000, "env_kwargs": {"action_mode": "delta"},
               "normalize": {"norm_obs": True, "norm_reward": False}, "learning_starts": 50,
               "batch_size": 16, "buffer_size": 5000, "policy_kwargs": {"net_arch": [8]}}


def _steps(checkpoint: Path | None) -> int:
    return 0 if checkpoint is None else json.loads(sidecar_paths(checkpoint)[0].read_text())["timesteps_done"]


def check_folder(run: Path) -> int:
    """Load every complete checkpoint, the best model and the evaluations; return how many failed."""
    bad = 0
    models = [p.with_suffix(".zip") for p in (run / "checkpoints").glob("model_*_steps.json")]
    models += [run / "best_model.zip"] if (run / "best_model.json").is_file() else []
    for model in models:
        try:
            load_policy(model)
        except ValueError:
            bad += 1
    if (run / "evaluations.npz").is_file():
        try:
            np.load(run / "evaluations.npz")["timesteps"]
        except (OSError, ValueError, KeyError):
            bad += 1
    return bad


def _hear_sigint() -> None:
    """In the child before exec: SIGINT to its default. A drill started as a background job of
    a shell without job control inherits SIGINT ignored, and its sessions would not hear it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def drill(cycles: int = 20, timesteps: int = 20_000, seed: int = 0,
          workdir: Path | str | None = None) -> dict:
    """Run the drill (module docstring); returns the tallies."""
    rng = random.Random(seed)
    workdir = Path(workdir or tempfile.mkdtemp(prefix="softarm-faults-"))
    hyperparams = workdir / "hyperparams"
    hyperparams.mkdir(parents=True, exist_ok=True)
    (hyperparams / "sac.yml").write_text(yaml.safe_dump({ENV_ID: {**HYPERPARAMS, "n_timesteps": timesteps}}))
    run = workdir / "runs" / "sac_OctArmReach-v0_s0"
    train = [sys.executable, "-m", "baselines.train", "--no-progress", "--save-replay-buffer"]
    first = [*train, "--env", ENV_ID, "--algo", "sac", "--log-dir", str(workdir / "runs"),
             "--hyperparams-dir", str(hyperparams), "--checkpoint-freq", "100", "--eval-freq", "500",
             "--eval-episodes", "1"]
    tally = {"cycles": cycles, "sigint": 0, "sigkill": 0, "clean_sigint_exits": 0, "sigint_saved_at_stop": 0,
             "resumed": 0, "unloadable_files": 0, "steps_kept_by_killed_sessions": [],
             "final_timesteps": None, "target_timesteps": timesteps}
    for cycle in range(cycles):
        before = _steps(latest_checkpoint(run)) if run.exists() else 0
        proc = subprocess.Popen(first if cycle == 0 else [*train, "--resume", str(run)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=_hear_sigint)
        tally["resumed"] += cycle > 0
        while _steps(latest_checkpoint(run) if run.exists() else None) <= before and proc.poll() is None:
            time.sleep(0.1)  # until this session has trained and checkpointed something
        time.sleep(rng.uniform(0.0, 3.0))
        if proc.poll() is not None:
            raise RuntimeError(f"session {cycle} ended on its own: {proc.communicate()[1][-500:]}")
        sig = signal.SIGINT if cycle % 2 == 0 else signal.SIGKILL
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=300)
        after = latest_checkpoint(run)
        if sig == signal.SIGINT:
            tally["sigint"] += 1
            last = err.strip().splitlines()[-1] if err.strip() else ""
            tally["clean_sigint_exits"] += proc.returncode == 130 and "Traceback" not in err \
                and last.startswith("baselines.train: interrupted at step ")
            stopped = int(last.split("interrupted at step ")[1].split(";")[0]) if "at step " in last else -1
            tally["sigint_saved_at_stop"] += _steps(after) == stopped
        else:
            tally["sigkill"] += 1
            # A killed session keeps what it checkpointed; it loses at most the 100 steps since.
            tally["steps_kept_by_killed_sessions"].append(_steps(after) - before)
        tally["unloadable_files"] += check_folder(run)
    done = subprocess.run([*train, "--resume", str(run)], capture_output=True, text=True, timeout=3600)
    if done.returncode != 0:
        raise RuntimeError(f"the last session failed: {done.stderr[-500:]}")
    tally["final_timesteps"] = json.loads((run / "summary.json").read_text())["timesteps_done"]
    tally["unloadable_files"] += check_folder(run)
    tally["workdir"] = str(workdir)
    return tally


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.faults", description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=20, help="interruptions (alternately SIGINT, SIGKILL)")
    parser.add_argument("--timesteps", type=int, default=20_000, help="the run's target")
    parser.add_argument("--seed", type=int, default=0, help="seeds the waits before each interruption")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.cycles < 1:
        print("baselines.faults: error: --cycles must be >= 1", file=sys.stderr)
        return 2
    tally = drill(args.cycles, args.timesteps, args.seed)
    ok = tally["clean_sigint_exits"] == tally["sigint_saved_at_stop"] == tally["sigint"] \
        and tally["unloadable_files"] == 0 and tally["final_timesteps"] == tally["target_timesteps"]
    if args.json:
        print(json.dumps(tally, indent=2))
    else:
        print(f"{tally['cycles']} interruptions ({tally['sigint']} SIGINT, {tally['sigkill']} SIGKILL), "
              f"{tally['resumed']} resumes: {tally['clean_sigint_exits']} clean SIGINT exits, "
              f"{tally['sigint_saved_at_stop']} saved at the stopping step, {tally['unloadable_files']} "
              f"unloadable files, final step count {tally['final_timesteps']} of {tally['target_timesteps']}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
