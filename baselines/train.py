"""Train an SB3 agent on a soft-arm environment with the hyperparameters of ``baselines/hyperparams``.

    python -m baselines.train --env SoftArm/OctArmReach-v0 --algo sac --timesteps 300000 --seed 0

writes into ``<log-dir>/<algo>_<env>_s<seed>/``:

* ``monitor.csv`` — one row per training episode (return, length, wall time, final
  ``is_success`` and ``distance``), the learning curve;
* ``progress.csv`` and TensorBoard event files — SB3's logger;
* ``checkpoints/`` — model + VecNormalize every ``--checkpoint-freq`` steps;
* ``evaluations.npz`` — periodic deterministic evaluations (``--eval-freq``);
* ``best_model.zip`` (by evaluation return) and ``final_model.zip``, each with its ``.json``
  metadata and ``_vecnormalize.pkl`` statistics (see :mod:`baselines.config`);
* ``summary.json`` — timesteps, training wall time, the process's CPU time (the machine may
  be shared: CPU time says how much compute the run actually got) and the hyperparameters.

A tqdm progress bar goes to stderr. Torch is limited to ``--threads`` (default 1) threads: the
networks are small and the machine's cores are better spent on the environment.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback, EvalCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
from tqdm import tqdm

from baselines.config import (
    ALGOS,
    HYPERPARAMS_DIR,
    action_noise,
    load_hyperparams,
    make_env,
    sidecar_paths,
    split_hyperparams,
)

__all__ = ["train", "main"]

MONITOR_KEYS = ("is_success", "distance")
"""Final-step info entries written to ``monitor.csv`` for every training episode."""


class _ProgressBar(BaseCallback):
    """A tqdm bar over environment steps, on stderr."""

    def __init__(self, total: int):
        super().__init__()
        self._total = total
        self._bar = None

    def _on_training_start(self) -> None:
        self._bar = tqdm(total=self._total, unit="step", file=sys.stderr, dynamic_ncols=True)

    def _on_step(self) -> bool:
        self._bar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        self._bar.close()


class _TimeLimit(BaseCallback):
    """Stops training once ``seconds`` of wall time have passed (a budget, not a target)."""

    def __init__(self, seconds: float):
        super().__init__()
        self._seconds = seconds
        self._start = 0.0

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()

    def _on_step(self) -> bool:
        return time.perf_counter() - self._start < self._seconds


class _SaveNormalization(BaseCallback):
    """Called by ``EvalCallback`` on a new best model: saves the matching VecNormalize statistics."""

    def __init__(self, path: Path):
        super().__init__()
        self._path = path

    def _on_step(self) -> bool:
        vecnorm = self.model.get_vec_normalize_env()
        if vecnorm is not None:
            vecnorm.save(str(self._path))
        return True


def _vec_env(env_id: str, env_kwargs: dict, n_envs: int, seed: int, monitor_dir: Path | None):
    def factory(rank: int):
        def thunk():
            env = make_env(env_id, env_kwargs)
            if monitor_dir is not None:
                filename = str(monitor_dir / ("monitor.csv" if rank == 0 else f"{rank}.monitor.csv"))
                env = Monitor(env, filename, info_keywords=MONITOR_KEYS)
            else:
                env = Monitor(env, info_keywords=MONITOR_KEYS)
            env.reset(seed=seed + rank)
            env.action_space.seed(seed + rank)
            return env
        return thunk

    venv = DummyVecEnv([factory(i) for i in range(n_envs)])
    venv.seed(seed)
    return venv


def _write_metadata(model_path: Path, meta: dict) -> None:
    meta_path, _ = sidecar_paths(model_path)
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")


def train(env_id: str, algo: str, *, timesteps: int | None = None, seed: int = 0,
          log_dir: Path | str = "runs", hyperparams: dict | None = None,
          hyperparams_dir: Path | str = HYPERPARAMS_DIR, eval_freq: int = 10_000, eval_episodes: int = 20,
          checkpoint_freq: int = 50_000, threads: int = 1, progress: bool = True,
          tensorboard: bool = True, time_limit_min: float | None = None) -> Path:
    """Train ``algo`` on ``env_id`` and save everything under ``log_dir``.

    Args:
        env_id: registered environment id (e.g. ``"SoftArm/OctArmReach-v0"``).
        algo: one of :data:`baselines.config.ALGOS`.
        timesteps: environment steps; default the YAML's ``n_timesteps``.
        seed: seeds the algorithm, the environments and torch.
        log_dir: parent folder of the run folder.
        hyperparams: replaces the YAML entry entirely (tests use tiny networks this way).
        hyperparams_dir: folder of the YAML files.
        eval_freq: steps between deterministic evaluations (0 disables them).
        eval_episodes: episodes per evaluation.
        checkpoint_freq: steps between checkpoints (0 disables them).
        threads: torch CPU threads.
        progress: show a tqdm bar on stderr.
        tensorboard: also write TensorBoard event files.
        time_limit_min: stop after this many minutes of training even if ``timesteps`` are not
            done (``summary.json`` records the steps actually taken).

    Returns:
        The run folder.

    Raises:
        ValueError: bad arguments or hyperparameters.
    """
    if algo not in ALGOS:
        raise ValueError(f"unknown algo {algo!r}; choose one of {', '.join(ALGOS)}")
    params = load_hyperparams(algo, env_id, hyperparams_dir) if hyperparams is None else dict(hyperparams)
    special, algo_kwargs = split_hyperparams(params)
    total = int(special["n_timesteps"] if timesteps is None else timesteps)
    if total < 1:
        raise ValueError(f"timesteps must be >= 1; got {total}")
    for name, value in (("eval_freq", eval_freq), ("checkpoint_freq", checkpoint_freq)):
        if value < 0:
            raise ValueError(f"{name} must be >= 0; got {value}")
    if time_limit_min is not None and not time_limit_min > 0:
        raise ValueError(f"time_limit_min must be > 0 (minutes); got {time_limit_min}")
    n_envs = int(special.get("n_envs", 1))
    env_kwargs = dict(special.get("env_kwargs", {}))
    normalize = special.get("normalize", False)
    norm_kwargs = normalize if isinstance(normalize, dict) else {}

    torch.set_num_threads(threads)
    run_dir = Path(log_dir) / f"{algo}_{env_id.split('/')[-1]}_s{seed}"
    run_dir.mkdir(parents=True, exist_ok=True)
    venv = _vec_env(env_id, env_kwargs, n_envs, seed, run_dir)
    eval_venv = _vec_env(env_id, env_kwargs, 1, seed + 10_000, None) if eval_freq else None
    if normalize:
        venv = VecNormalize(venv, **norm_kwargs)
        if eval_venv is not None:
            eval_venv = VecNormalize(eval_venv, training=False, norm_reward=False,
                                     **{k: v for k, v in norm_kwargs.items() if k != "norm_reward"})
    noise = action_noise(special, venv.action_space.shape[0])
    if noise is not None:
        algo_kwargs["action_noise"] = noise
    model = ALGOS[algo](special["policy"], venv, seed=seed, device="cpu", verbose=0, **algo_kwargs)
    model.set_logger(configure(str(run_dir), ["csv", "tensorboard"] if tensorboard else ["csv"]))

    meta = {"env_id": env_id, "algo": algo, "seed": seed, "env_kwargs": env_kwargs,
            "hyperparams": params, "timesteps": total}
    callbacks = [_ProgressBar(total)] if progress else []
    if time_limit_min is not None:
        callbacks.append(_TimeLimit(60.0 * time_limit_min))
    if checkpoint_freq:
        callbacks.append(CheckpointCallback(max(checkpoint_freq // n_envs, 1), str(run_dir / "checkpoints"),
                                            name_prefix="model", save_vecnormalize=bool(normalize)))
    if eval_venv is not None:
        best = run_dir / "best_model.zip"
        callbacks.append(EvalCallback(
            eval_venv, n_eval_episodes=eval_episodes, eval_freq=max(eval_freq // n_envs, 1),
            log_path=str(run_dir), best_model_save_path=str(run_dir), deterministic=True, verbose=0,
            callback_on_new_best=_SaveNormalization(sidecar_paths(best)[1]) if normalize else None))
    start, cpu_start = time.perf_counter(), time.process_time()
    model.learn(total_timesteps=total, callback=CallbackList(callbacks))
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start

    final = run_dir / "final_model.zip"
    model.save(final)
    if normalize:
        venv.save(str(sidecar_paths(final)[1]))
    done = int(model.num_timesteps)
    summary = {**meta, "timesteps_done": done, "wall_time_s": wall, "cpu_time_s": cpu,
               "steps_per_s": done / wall,
               "threads": threads, "time_limit_min": time_limit_min}
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _write_metadata(final, summary)
    if eval_venv is not None and (run_dir / "best_model.zip").is_file():
        _write_metadata(run_dir / "best_model.zip", summary)
    venv.close()
    return run_dir


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.train", description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, help="environment id, e.g. SoftArm/OctArmReach-v0")
    parser.add_argument("--algo", required=True, choices=tuple(ALGOS))
    parser.add_argument("--timesteps", type=int, default=None, help="default: n_timesteps of the YAML")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log-dir", default="runs", help="parent of the run folder (default %(default)s)")
    parser.add_argument("--hyperparams-dir", default=str(HYPERPARAMS_DIR))
    parser.add_argument("--eval-freq", type=int, default=10_000, help="0 disables periodic evaluation")
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--checkpoint-freq", type=int, default=50_000, help="0 disables checkpoints")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1)")
    parser.add_argument("--time-limit-min", type=float, default=None,
                        help="stop training after this many minutes of wall time")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = parser.parse_args(argv)
    try:
        run_dir = train(args.env, args.algo, timesteps=args.timesteps, seed=args.seed, log_dir=args.log_dir,
                        hyperparams_dir=args.hyperparams_dir, eval_freq=args.eval_freq,
                        eval_episodes=args.eval_episodes, checkpoint_freq=args.checkpoint_freq,
                        threads=args.threads, progress=not args.no_progress,
                        time_limit_min=args.time_limit_min)
    except ValueError as exc:
        print(f"baselines.train: error: {exc}", file=sys.stderr)
        return 2
    print(run_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
