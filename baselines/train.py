"""Train an SB3 agent on a soft-arm environment with the hyperparameters of ``baselines/hyperparams``.

    python -m baselines.train --env SoftArm/OctArmReach-v1 --algo sac --timesteps 150000 --seed 0
    python -m baselines.train --resume runs/sac_OctArmReach-v1_s0      # after Ctrl-C or a crash
    python -m baselines.train --env SoftArm/OctArmReach-v1 --algo ppo --batched --numba-threads 1

writes into ``<log-dir>/<algo>_<env>_s<seed>/`` (``<algo>_<env>_batched_s<seed>/`` with
``--batched``, which trains on one :class:`softarm_gym.sb3.BatchedVecEnv` of ``n_envs`` arms
with the hyperparameters of ``baselines/hyperparams/batched/``):

* ``config.json`` — everything needed to continue the run (``--resume``);
* ``monitor.csv`` — one row per training episode (return, length, wall time, final
  ``is_success`` and ``distance``, on wrap ``wrap_angle_deg``), the learning curve (with
  ``--batched``, one file for all arms, written by ``VecMonitor``);
* ``progress.csv`` and TensorBoard event files — SB3's logger (a resumed run moves the
  previous ``progress.csv`` to ``progress_<k>.csv``);
* ``checkpoints/model_<steps>_steps.zip`` every ``--checkpoint-freq`` steps, each with its
  ``.json`` metadata and ``_vecnormalize.json`` statistics (and, with
  ``--save-replay-buffer``, ``_replay_buffer.npz``; only the newest checkpoint keeps one);
* ``evaluations.npz`` — periodic deterministic evaluations (``--eval-freq``);
* ``best_model.zip`` (by evaluation return) and ``final_model.zip``, each with its ``.json``
  metadata and ``_vecnormalize.json`` statistics (see :mod:`baselines.config`);
* ``summary.json`` — timesteps, training wall time, the process's CPU time (the machine may
  be shared: CPU time says how much compute the run actually got) and the hyperparameters
  (with ``hyperparams_file``, their YAML, when it is not in ``baselines/hyperparams``).

Faults lose at most the steps since the last checkpoint:

* every model file and sidecar is written to a temporary file and renamed into place, and a
  checkpoint's metadata JSON is written last, so a checkpoint with metadata is complete and a
  ``kill -9`` leaves no half-written file under a final name;
* Ctrl-C (SIGINT) or SIGTERM saves a checkpoint at the current step (model, statistics,
  replay buffer if enabled, metadata), prints one line and exits with 130 (143 for
  SIGTERM); :func:`train` raises :class:`TrainingInterrupted` instead;
* ``--resume RUN_DIR`` (:func:`resume`) reloads the newest complete checkpoint and continues
  with the same step counter up to the run's target (or a new ``--timesteps``); the
  evaluation history and best score carry over. Without a saved replay buffer an off-policy
  run first collects ``learning_starts`` new steps before it updates again, and then trains on a
  buffer that holds only what it collected since: measured on the batched obstacle reach (SAC,
  32 updates per 128 transitions), two seeds fell from 56 % and 66 % to 20 % and 30 % over the
  70,000 steps after such a resume (baselines/RESULTS.md). Give a long off-policy run
  ``--save-replay-buffer`` from its first session. The resumed
  session seeds its environments with ``seed + steps done`` (no replay of the first episodes).

Resuming reads only weights (``torch.load(weights_only=True)``), JSON and ``.npz`` arrays
(``allow_pickle=False``): nothing in a run folder is unpickled.

``--init-policy MODEL.zip`` starts a new run from that model's policy weights and observation
statistics instead of random ones (a warm start: e.g. a policy cloned from planner
demonstrations by :mod:`baselines.imitate`); the policy class and architecture must be the
run's, and ``summary.json`` records the file.

A tqdm progress bar goes to stderr. Torch is limited to ``--threads`` (default 1) threads: the
networks are small and the machine's cores are better spent on the environment.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import numbers
import os
import re
import signal
import sys
import time
from pathlib import Path

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, EvalCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor, ResultsWriter
from stable_baselines3.common.save_util import load_from_zip_file, recursive_setattr
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor, VecNormalize
from tqdm import tqdm

from baselines.config import (
    ALGOS,
    HYPERPARAMS_DIR,
    action_noise,
    check_env_id,
    is_wrap,
    load_hyperparams,
    load_normalization,
    load_policy,
    make_env,
    observation_sizes,
    policy_metadata,
    restore_normalization,
    save_normalization,
    sidecar_paths,
    split_hyperparams,
)
from softarm_gym.commands.common import add_numba_threads_argument, add_quiet_argument, apply_numba_threads
from softarm_gym.files import atomic_write, signals_deferred, write_json
from softarm_gym.sb3 import BatchedVecEnv

__all__ = ["train", "resume", "build", "TrainingInterrupted", "latest_checkpoint", "save_checkpoint",
           "project_path", "main"]

MONITOR_KEYS = ("is_success", "distance")
"""Final-step info entries written to ``monitor.csv`` for every training episode (reach, track)."""
WRAP_MONITOR_KEYS = ("is_success", "wrap_angle_deg")
"""The same for the wrap task, which has no target distance (its measure is the wrap angle, deg)."""
CONFIG_FILE = "config.json"
_CHECKPOINT = re.compile(r"model_(\d+)_steps\.json")
_REPLAY_FIELDS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


class TrainingInterrupted(KeyboardInterrupt):
    """Training was interrupted (Ctrl-C, SIGTERM) after its state was saved.

    Attributes:
        run_dir: the run folder (continue with :func:`resume`).
        checkpoint: the checkpoint written at the interruption (None if the model did not
            exist yet).
        timesteps: environment steps done.
    """

    def __init__(self, run_dir: Path, checkpoint: Path | None, timesteps: int):
        super().__init__(f"training interrupted at step {timesteps}")
        self.run_dir, self.checkpoint, self.timesteps = run_dir, checkpoint, timesteps


# --------------------------------------------------------------------------- checkpoints

def _replay_path(model_path: Path) -> Path:
    return model_path.with_name(f"{model_path.stem}_replay_buffer.npz")


def save_checkpoint(model, model_path: Path | str, meta: dict, *, replay_buffer: bool = False) -> Path:
    """Save ``model`` with its sidecars, each file atomically, the metadata JSON last.

    Args:
        model: an SB3 algorithm (its VecNormalize, if any, is saved too).
        model_path: ``.../NAME.zip``.
        meta: metadata to store; the policy description, ``normalized``, ``timesteps_done``
            and ``n_updates`` are added.
        replay_buffer: also save an off-policy model's replay buffer (``.npz``).

    Returns:
        The metadata path (its existence marks the checkpoint complete).
    """
    # A stop inside torch's zip writer broke the save's clean-up and the run died with that
    # traceback instead of saving its interrupted checkpoint (seen in tests/baselines/test_resume.py).
    with signals_deferred(signal.SIGINT, signal.SIGTERM):
        return _save_checkpoint(model, Path(model_path), meta, replay_buffer)


def _save_checkpoint(model, model_path: Path, meta: dict, replay_buffer: bool) -> Path:
    meta_path, norm_path = sidecar_paths(model_path)
    with atomic_write(model_path, "wb") as fh:
        model.save(fh)
    vecnorm = model.get_vec_normalize_env()
    if vecnorm is not None:
        save_normalization(vecnorm, norm_path)
    saved_buffer = None
    if replay_buffer and getattr(model, "replay_buffer", None) is not None:
        buffer = model.replay_buffer
        arrays = {name: getattr(buffer, name) for name in _REPLAY_FIELDS
                  if getattr(buffer, name, None) is not None}
        with atomic_write(_replay_path(model_path), "wb") as fh:
            np.savez(fh, pos=np.int64(buffer.pos), full=np.bool_(buffer.full), **arrays)
        saved_buffer = _replay_path(model_path).name
    write_json(meta_path, {**meta, **policy_metadata(model), "normalized": vecnorm is not None,
                           "timesteps_done": int(model.num_timesteps), "n_updates": int(model._n_updates),
                           "replay_buffer": saved_buffer})
    return meta_path


def latest_checkpoint(run_dir: Path | str) -> Path | None:
    """The newest complete checkpoint (``.zip``) under ``run_dir/checkpoints``, or None."""
    found = []
    for meta_path in (Path(run_dir) / "checkpoints").glob("model_*_steps.json"):
        match = _CHECKPOINT.fullmatch(meta_path.name)
        if match and meta_path.with_suffix(".zip").is_file():
            found.append((int(match.group(1)), meta_path.with_suffix(".zip")))
    return max(found)[1] if found else None


def _restore(model, checkpoint: Path, meta: dict) -> str:
    """Load a checkpoint's weights, optimiser states, counters and replay buffer into ``model``.

    Returns a note on the replay buffer for the resume message.
    """
    _, params, variables = load_from_zip_file(checkpoint, device="cpu", load_data=False)
    model.set_parameters(params, exact_match=True, device="cpu")
    for name, tensor in (variables or {}).items():  # e.g. SAC's log_ent_coef, kept by identity
        recursive_setattr(model, f"{name}.data", tensor.data)
    model.num_timesteps = int(meta["timesteps_done"])
    model._n_updates = int(meta.get("n_updates", 0))
    buffer = getattr(model, "replay_buffer", None)
    if buffer is None:
        return ""
    path = checkpoint.parent / meta["replay_buffer"] if meta.get("replay_buffer") else None
    if path is not None and path.is_file():
        with np.load(path, allow_pickle=False) as data:
            for name in _REPLAY_FIELDS:
                if getattr(buffer, name, None) is None:
                    continue
                if name not in data or data[name].shape != getattr(buffer, name).shape:
                    raise ValueError(f"{path.name} does not fit the replay buffer of this run ({name})")
                getattr(buffer, name)[...] = data[name]
            buffer.pos, buffer.full = int(data["pos"]), bool(data["full"])
        return f", replay buffer of {buffer.size() * buffer.n_envs} transitions"
    model.learning_starts = model.num_timesteps + model.learning_starts
    return (f", no replay buffer saved: collecting {model.learning_starts - model.num_timesteps} steps "
            "first (the policy may lose ground while the buffer refills; train with "
            "--save-replay-buffer to resume with it)")


# --------------------------------------------------------------------------- callbacks

class _ProgressBar(BaseCallback):
    """A tqdm bar over environment steps, on stderr."""

    def __init__(self, total: int, initial: int):
        super().__init__()
        self._total, self._initial = total, initial
        self._bar = None

    def _on_training_start(self) -> None:
        self._bar = tqdm(total=self._total, initial=self._initial, unit="step", file=sys.stderr,
                         dynamic_ncols=True)

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


class Checkpoints(BaseCallback):
    """Calls ``save()`` whenever the step counter passes a multiple of ``freq`` (also after a resume)."""

    def __init__(self, freq: int, save):
        super().__init__()
        self._freq, self._save, self._next = freq, save, 0

    def _on_training_start(self) -> None:
        self._next = (self.model.num_timesteps // self._freq + 1) * self._freq

    def _on_step(self) -> bool:
        if self.model.num_timesteps >= self._next:
            self._save()
            self._next = (self.model.num_timesteps // self._freq + 1) * self._freq
        return True


class _Evaluation(EvalCallback):
    """``EvalCallback`` that writes ``evaluations.npz`` atomically (to a temporary name, then a
    rename) and saves each new best model through ``save_best(mean_reward)``."""

    def __init__(self, eval_env, run_dir: Path, save_best, **kwargs):
        super().__init__(eval_env, log_path=str(run_dir), best_model_save_path=None, **kwargs)
        self.log_path = str(run_dir / ".evaluations.tmp")  # np.savez appends .npz
        self._final = run_dir / "evaluations.npz"
        self._save_best = save_best

    def restore(self, upto: int, best_mean_reward: float) -> None:
        """Continue the history of a resumed run: evaluations up to step ``upto``, and its best score."""
        self.best_mean_reward = best_mean_reward
        if not self._final.is_file():
            return
        with np.load(self._final, allow_pickle=False) as data:
            keep = data["timesteps"] <= upto
            self.evaluations_timesteps = data["timesteps"][keep].tolist()
            self.evaluations_results = data["results"][keep].tolist()
            self.evaluations_length = data["ep_lengths"][keep].tolist()
            if "successes" in data:
                self.evaluations_successes = data["successes"][keep].tolist()

    def _on_step(self) -> bool:
        best = self.best_mean_reward
        keep_going = super()._on_step()
        if Path(self.log_path + ".npz").is_file():
            os.replace(self.log_path + ".npz", self._final)
        if self.best_mean_reward > best:
            self._save_best(self.best_mean_reward)
        return keep_going


# --------------------------------------------------------------------------- the run

def monitor_keys(env_id: str) -> tuple[str, ...]:
    """The final-step info entries ``monitor.csv`` records for ``env_id``'s task."""
    return WRAP_MONITOR_KEYS if is_wrap(env_id) else MONITOR_KEYS


def _batched_env(env_id: str, env_kwargs: dict, n_envs: int, seed: int, monitor_dir: Path | None,
                 append: bool = False):
    """``n_envs`` arms in one :class:`BatchedVecEnv`, in a ``VecMonitor`` (``monitor.csv``)."""
    keys = monitor_keys(env_id)
    if "action_wrapper" in env_kwargs:
        raise ValueError("--batched does not take an action_wrapper (the batched env steps Box actions)")
    venv = VecMonitor(BatchedVecEnv(env_id, n_envs, **env_kwargs), info_keywords=keys)
    if monitor_dir is not None:
        path = monitor_dir / "monitor.csv"
        t_start = _monitor_start(path) if append else None
        if t_start is not None:  # times stay relative to the run's first start
            venv.t_start = t_start
        venv.results_writer = ResultsWriter(str(path), header={"t_start": venv.t_start, "env_id": env_id},
                                            extra_keys=keys, override_existing=t_start is None)
    venv.seed(seed)
    return venv


def _vec_env(env_id: str, env_kwargs: dict, n_envs: int, seed: int, monitor_dir: Path | None,
             append: bool = False):
    keys = monitor_keys(env_id)

    def factory(rank: int):
        def thunk():
            env = make_env(env_id, env_kwargs)
            if monitor_dir is None:
                env = Monitor(env, info_keywords=keys)
            else:
                path = monitor_dir / ("monitor.csv" if rank == 0 else f"{rank}.monitor.csv")
                t_start = _monitor_start(path) if append else None
                env = Monitor(env, str(path), info_keywords=keys, override_existing=t_start is None)
                if t_start is not None:  # times stay relative to the run's first start
                    env.t_start = t_start
            env.reset(seed=seed + rank)
            env.action_space.seed(seed + rank)
            return env
        return thunk

    venv = DummyVecEnv([factory(i) for i in range(n_envs)])
    venv.seed(seed)
    return venv


def _monitor_start(path: Path) -> float | None:
    """``t_start`` of an existing monitor file's header line, or None."""
    try:
        with open(path, encoding="utf-8") as fh:
            header = json.loads(fh.readline().lstrip("#"))
        return float(header["t_start"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _rotate(path: Path) -> None:
    """Move ``path`` to ``<stem>_<k>.csv`` (first free k) so a resumed logger does not overwrite it."""
    if path.is_file():
        k = 0
        while path.with_name(f"{path.stem}_{k}{path.suffix}").exists():
            k += 1
        os.replace(path, path.with_name(f"{path.stem}_{k}{path.suffix}"))


def build(env_id: str, algo: str, params: dict, seed: int, *, batched: bool = False,
          monitor_dir: Path | None = None, append: bool = False):
    """A fresh model of ``algo`` with hyperparameters ``params`` on its training environment.

    Args:
        env_id, algo: as :func:`train`.
        params: a hyperparameter entry (:func:`baselines.config.load_hyperparams`).
        seed: seeds the model; env copy i is seeded ``seed + i``.
        batched: the ``n_envs`` copies are arms of one :class:`BatchedVecEnv` (in a
            ``VecMonitor``), not single envs in a ``DummyVecEnv`` (each in a ``Monitor``).
        monitor_dir: where the monitor files go (None: none are written).
        append: continue existing monitor files (a resumed run).

    Returns:
        (model, its VecEnv: a ``VecNormalize`` when ``normalize`` is set).
    """
    special, algo_kwargs = split_hyperparams(copy.deepcopy(params))  # SB3 edits policy_kwargs in place
    make = _batched_env if batched else _vec_env
    venv = make(env_id, dict(special.get("env_kwargs", {})), int(special.get("n_envs", 1)), seed, monitor_dir,
                append=append)
    normalize = special.get("normalize", False)
    if normalize:
        venv = VecNormalize(venv, **(normalize if isinstance(normalize, dict) else {}))
    noise = action_noise(special, venv.action_space)
    if noise is not None:
        algo_kwargs["action_noise"] = noise
    return ALGOS[algo](special["policy"], venv, seed=seed, device="cpu", verbose=0, **algo_kwargs), venv


def _learn(config: dict, run_dir: Path, checkpoint: Path | None, *, progress: bool,
           time_limit_min: float | None) -> Path:
    """Build the model (fresh, or from ``checkpoint``), train to ``config['timesteps']``, save."""
    params = config["hyperparams"]
    special, _ = split_hyperparams(params)
    env_id, algo = config["env_id"], config["algo"]
    n_envs = int(special.get("n_envs", 1))
    env_kwargs = dict(special.get("env_kwargs", {}))
    normalize = special.get("normalize", False)
    norm_kwargs = normalize if isinstance(normalize, dict) else {}
    resumed = checkpoint is not None
    prior = json.loads(sidecar_paths(checkpoint)[0].read_text()) if resumed else {}
    # A resumed session reseeds with seed + steps done, so it does not replay the first episodes.
    seed = config["seed"] + int(prior.get("timesteps_done", 0))

    torch.set_num_threads(config["threads"])
    model, venv = build(env_id, algo, params, seed, batched=config.get("batched", False), monitor_dir=run_dir,
                        append=resumed)
    # The evaluation env is wrapped as the training env is (SB3 syncs VecNormalize through the wrappers).
    make_eval = _batched_env if config.get("batched", False) else _vec_env
    eval_venv = make_eval(env_id, env_kwargs, 1, seed + 10_000, None) if config["eval_freq"] else None
    if normalize:
        if resumed:
            restore_normalization(venv, load_normalization(sidecar_paths(checkpoint)[1],
                                                           observation_sizes(venv.observation_space)))
        if eval_venv is not None:
            eval_venv = VecNormalize(eval_venv, training=False, norm_reward=False,
                                     **{k: v for k, v in norm_kwargs.items() if k != "norm_reward"})
    note = _restore(model, checkpoint, prior) if resumed else ""
    if not resumed and config.get("init_policy"):
        _initialise(model, venv, Path(config["init_policy"]), normalize)
    if resumed:
        _rotate(run_dir / "progress.csv")
    model.set_logger(configure(str(run_dir), ["csv", "tensorboard"] if config["tensorboard"] else ["csv"]))

    # The model's metadata records the budget it trained (--timesteps overrides the YAML's
    # n_timesteps); the run's config keeps the YAML entry as planned (a sweep's --resume checks it).
    meta = {"env_id": env_id, "algo": algo, "seed": config["seed"], "env_kwargs": env_kwargs,
            "hyperparams": {**params, "n_timesteps": config["timesteps"]}, "timesteps": config["timesteps"],
            "batched": config.get("batched", False)}
    if "hyperparams_file" in config:
        meta["hyperparams_file"] = config["hyperparams_file"]
    if config.get("init_policy"):
        meta["init_policy"] = config["init_policy"]
    wall0, cpu0 = float(prior.get("wall_time_s", 0.0)), float(prior.get("cpu_time_s", 0.0))
    start, cpu_start = time.perf_counter(), time.process_time()

    def spent() -> dict:
        return {"wall_time_s": wall0 + time.perf_counter() - start,
                "cpu_time_s": cpu0 + time.process_time() - cpu_start}

    def save(kind: str, path: Path | None = None, **extra) -> Path:
        path = path or run_dir / "checkpoints" / f"model_{model.num_timesteps}_steps.zip"
        path.parent.mkdir(parents=True, exist_ok=True)
        keep_buffer = config["save_replay_buffer"] and kind in ("checkpoint", "interrupted")
        save_checkpoint(model, path, {**meta, "kind": kind, **spent(), **extra}, replay_buffer=keep_buffer)
        if keep_buffer:  # replay buffers are large: only the newest complete checkpoint keeps one
            for old in path.parent.glob("model_*_steps_replay_buffer.npz"):
                if old != _replay_path(path):
                    old.unlink(missing_ok=True)
        return path

    done = int(model.num_timesteps)
    callbacks = [_ProgressBar(config["timesteps"], done)] if progress else []
    if time_limit_min is not None:
        callbacks.append(_TimeLimit(60.0 * time_limit_min))
    if config["checkpoint_freq"]:
        callbacks.append(Checkpoints(config["checkpoint_freq"], lambda: save("checkpoint")))
    if eval_venv is not None:
        evaluation = _Evaluation(
            eval_venv, run_dir, lambda best: save("best", run_dir / "best_model.zip", best_mean_reward=best),
            n_eval_episodes=config["eval_episodes"], eval_freq=max(config["eval_freq"] // n_envs, 1),
            deterministic=True, verbose=0)
        if resumed:
            best_meta = sidecar_paths(run_dir / "best_model.zip")[0]
            best = json.loads(best_meta.read_text()).get("best_mean_reward") if best_meta.is_file() else None
            evaluation.restore(done, -math.inf if best is None else float(best))
        callbacks.append(evaluation)
    if resumed:
        print(f"resuming {run_dir.name} at step {done} of {config['timesteps']}{note}", file=sys.stderr)
    try:
        try:
            if config["timesteps"] > done:
                model.learn(total_timesteps=config["timesteps"] - done, callback=CallbackList(callbacks),
                            reset_num_timesteps=not resumed)
        except KeyboardInterrupt:
            checkpoint = save("interrupted")
            raise TrainingInterrupted(run_dir, checkpoint, int(model.num_timesteps)) from None
        final_steps = int(model.num_timesteps)
        summary = {**meta, "timesteps_done": final_steps, **spent(),
                   "steps_per_s": (final_steps - done) / max(time.perf_counter() - start, 1e-9),
                   "threads": config["threads"], "time_limit_min": time_limit_min,
                   "resumed_from": done or None}
        save("final", run_dir / "final_model.zip", **{k: v for k, v in summary.items() if k not in meta})
        write_json(run_dir / "summary.json", summary)
    finally:
        model.logger.close()
        venv.close()
        if eval_venv is not None:
            eval_venv.close()
    return run_dir


def _initialise(model, venv, init_policy: Path, normalize) -> None:
    """Start ``model`` from the policy weights (and observation statistics) of ``init_policy``, a
    model file with its sidecars (e.g. a behaviour-cloned policy of :mod:`baselines.imitate`),
    loaded safely (:func:`baselines.config.load_policy`)."""
    policy, meta, vecnorm = load_policy(init_policy)
    try:
        if type(policy) is not type(model.policy):
            raise ValueError(f"--init-policy {init_policy.name} holds a {type(policy).__name__}; this run "
                             f"trains a {type(model.policy).__name__}")
        try:
            model.policy.load_state_dict(policy.state_dict(), strict=True)
        except RuntimeError as exc:
            raise ValueError(f"--init-policy {init_policy.name} does not fit this run's policy "
                             f"({str(exc).splitlines()[0]:.160})") from None
        if bool(normalize) != (vecnorm is not None):
            raise ValueError(f"--init-policy {init_policy.name} was {'' if vecnorm else 'not '}trained on "
                             f"normalised observations; this run {'does' if normalize else 'does not'} "
                             "normalise them")
        if vecnorm is not None:
            sizes = observation_sizes(venv.observation_space)
            restore_normalization(venv, load_normalization(sidecar_paths(init_policy)[1], sizes))
    finally:
        if vecnorm is not None:
            vecnorm.venv.close()


def project_path(path: Path) -> str:
    """``path`` relative to the project folder (the parent of ``baselines/``) if it lies inside
    it, so run records name their YAML file portably; else absolute."""
    path = path.resolve()
    try:
        return path.relative_to(HYPERPARAMS_DIR.parents[1]).as_posix()
    except ValueError:
        return path.as_posix()


def check_counts(eval_freq: int, checkpoint_freq: int, threads: int) -> None:
    for name, value, low in (("eval_freq", eval_freq, 0), ("checkpoint_freq", checkpoint_freq, 0),
                             ("threads", threads, 1)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")


def _check_time_limit(time_limit_min) -> None:
    if time_limit_min is not None and not time_limit_min > 0:
        raise ValueError(f"time_limit_min must be > 0 (minutes); got {time_limit_min}")


def train(env_id: str, algo: str, *, timesteps: int | None = None, seed: int = 0,
          log_dir: Path | str = "runs", hyperparams: dict | None = None,
          hyperparams_dir: Path | str | None = None, eval_freq: int = 10_000, eval_episodes: int = 20,
          checkpoint_freq: int = 50_000, threads: int = 1, progress: bool = True,
          tensorboard: bool = True, time_limit_min: float | None = None,
          save_replay_buffer: bool = False, run_name: str | None = None,
          batched: bool = False, init_policy: Path | str | None = None) -> Path:
    """Train ``algo`` on ``env_id`` and save everything under ``log_dir`` (module docstring).

    Args:
        env_id: registered environment id (e.g. ``"SoftArm/OctArmReach-v1"``).
        algo: one of :data:`baselines.config.ALGOS`.
        timesteps: environment steps; default the YAML's ``n_timesteps``.
        seed: seeds the algorithm, the environments and torch.
        log_dir: parent folder of the run folder (``run_name``), which must not hold a run
            already (continue one with :func:`resume`).
        hyperparams: replaces the YAML entry entirely (tests use tiny networks this way).
        hyperparams_dir: folder of the YAML files (default ``baselines/hyperparams``, or its
            ``batched`` subfolder with ``batched``).
        eval_freq: steps between deterministic evaluations (0 disables them).
        eval_episodes: episodes per evaluation.
        checkpoint_freq: steps between checkpoints (0 disables them).
        threads: torch CPU threads.
        progress: show a tqdm bar on stderr.
        tensorboard: also write TensorBoard event files.
        time_limit_min: stop after this many minutes of training even if ``timesteps`` are not
            done (``summary.json`` records the steps actually taken).
        save_replay_buffer: off-policy algorithms: save the replay buffer with each checkpoint
            (and at an interruption), so a resumed run continues with it (not HER's, whose
            infos and episode bookkeeping are not plain arrays).
        run_name: name of the run folder (``--run-name``); default
            ``<algo>_<env>[_batched]_s<seed>`` (``<env>`` without the ``SoftArm/`` prefix).
            :mod:`baselines.sweep` adds the observation mode.
        batched: train on one :class:`softarm_gym.sb3.BatchedVecEnv` of ``n_envs`` arms.
        init_policy: start from this model's policy weights and observation statistics
            instead of random ones (a ``.zip`` with its sidecars, of the same policy class and
            architecture; e.g. ``python -m baselines.imitate bc``'s): a warm start.

    Returns:
        The run folder.

    Raises:
        ValueError: bad arguments or hyperparameters, or a run folder that already holds a run.
        TrainingInterrupted: on KeyboardInterrupt (SIGINT) during training, after saving a
            checkpoint.
    """
    if algo not in ALGOS:
        raise ValueError(f"unknown algo {algo!r}; choose one of {', '.join(ALGOS)}")
    check_env_id(env_id)
    if hyperparams_dir is None:
        hyperparams_dir = HYPERPARAMS_DIR / "batched" if batched else HYPERPARAMS_DIR
    params = load_hyperparams(algo, env_id, hyperparams_dir) if hyperparams is None else dict(hyperparams)
    special, algo_kwargs = split_hyperparams(params)
    if save_replay_buffer and algo_kwargs.get("replay_buffer_class") is not None:
        raise ValueError("--save-replay-buffer does not support HerReplayBuffer (its infos are Python "
                         "objects); resume such a run without it")
    total = int(special["n_timesteps"] if timesteps is None else timesteps)
    if total < 1:
        raise ValueError(f"timesteps must be >= 1; got {total}")
    check_counts(eval_freq, checkpoint_freq, threads)
    _check_time_limit(time_limit_min)
    if run_name is None:
        run_name = f"{algo}_{env_id.split('/')[-1]}{'_batched' if batched else ''}_s{seed}"
    elif not isinstance(run_name, str) or run_name in ("", ".", "..") or any(c in run_name for c in "/\\\0"):
        raise ValueError(f"run_name must be a plain folder name; got {run_name!r}")
    run_dir = Path(log_dir) / run_name
    if (run_dir / CONFIG_FILE).is_file():
        raise ValueError(f"{run_dir} already holds a run; continue it with --resume {run_dir}, or choose "
                         "another --log-dir or --seed")
    run_dir.mkdir(parents=True, exist_ok=True)
    config = {"env_id": env_id, "algo": algo, "seed": seed, "hyperparams": params, "timesteps": total,
              "eval_freq": eval_freq, "eval_episodes": eval_episodes, "checkpoint_freq": checkpoint_freq,
              "threads": threads, "tensorboard": tensorboard, "save_replay_buffer": save_replay_buffer,
              "batched": bool(batched)}
    if init_policy is not None:
        if not Path(init_policy).is_file():
            raise ValueError(f"--init-policy must be an existing model file (.zip); got {str(init_policy)!r}")
        config["init_policy"] = project_path(Path(init_policy))
    if hyperparams is None and Path(hyperparams_dir).resolve() != HYPERPARAMS_DIR:
        config["hyperparams_file"] = project_path(Path(hyperparams_dir) / f"{algo}.yml")
    try:
        write_json(run_dir / CONFIG_FILE, config)
    except TypeError as exc:
        raise ValueError(f"hyperparameters must be plain data (numbers, strings, lists, mappings) to be "
                         f"saved with the run: {exc}") from None
    return _learn(config, run_dir, None, progress=progress, time_limit_min=time_limit_min)


def resume(run_dir: Path | str, *, timesteps: int | None = None, time_limit_min: float | None = None,
           threads: int | None = None, progress: bool = True) -> Path:
    """Continue the run in ``run_dir`` from its newest complete checkpoint.

    The step counter, weights, optimiser states, observation statistics, evaluation history,
    best score and (if saved) replay buffer carry over; the environments start new episodes.

    Args:
        run_dir: a folder written by :func:`train`.
        timesteps: new total number of steps (default: the run's target).
        time_limit_min: wall-time budget of this session (minutes).
        threads: torch CPU threads (default: the run's).
        progress: show a tqdm bar on stderr.

    Returns:
        The run folder.

    Raises:
        ValueError: not a run folder, no complete checkpoint yet, or a bad argument.
        TrainingInterrupted: as :func:`train`.
    """
    run_dir = Path(run_dir)
    config_path = run_dir / CONFIG_FILE
    if not config_path.is_file():
        raise ValueError(f"{run_dir} is not a training run folder (no {CONFIG_FILE})")
    config = json.loads(config_path.read_text())
    check_env_id(config.get("env_id"))
    checkpoint = latest_checkpoint(run_dir)
    if checkpoint is None:
        raise ValueError(f"{run_dir} has no complete checkpoint to resume from; start it again with "
                         "baselines.train (after removing the folder)")
    if timesteps is not None:
        if timesteps < 1:
            raise ValueError(f"timesteps must be >= 1; got {timesteps}")
        config["timesteps"] = int(timesteps)
    if threads is not None:
        config["threads"] = threads
    check_counts(config["eval_freq"], config["checkpoint_freq"], config["threads"])
    _check_time_limit(time_limit_min)
    write_json(config_path, config)
    return _learn(config, run_dir, checkpoint, progress=progress, time_limit_min=time_limit_min)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.train", description=__doc__.splitlines()[0])
    parser.add_argument("--env", help="environment id, e.g. SoftArm/OctArmReach-v1")
    parser.add_argument("--algo", choices=tuple(ALGOS))
    parser.add_argument("--resume", metavar="RUN_DIR", default=None,
                        help="continue this run from its newest checkpoint (--env/--algo not needed)")
    parser.add_argument("--timesteps", type=int, default=None,
                        help="total steps (default: n_timesteps of the YAML, or the resumed run's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log-dir", default="runs", help="parent of the run folder (default %(default)s)")
    parser.add_argument("--hyperparams-dir", default=None,
                        help=f"folder of the YAML files (default {HYPERPARAMS_DIR}, with --batched its "
                             "batched/ subfolder)")
    parser.add_argument("--run-name", default=None,
                        help="name of the run folder (default <algo>_<env>[_batched]_s<seed>)")
    parser.add_argument("--batched", action="store_true",
                        help="train on n_envs arms of one batched env (softarm_gym.sb3.BatchedVecEnv)")
    parser.add_argument("--init-policy", metavar="MODEL.zip", default=None,
                        help="start from this model's policy weights and observation statistics (a warm "
                             "start, e.g. from python -m baselines.imitate bc)")
    parser.add_argument("--eval-freq", type=int, default=10_000, help="0 disables periodic evaluation")
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--checkpoint-freq", type=int, default=50_000, help="0 disables checkpoints")
    parser.add_argument("--save-replay-buffer", action="store_true",
                        help="save the off-policy replay buffer with checkpoints (resume continues with it)")
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads (default 1)")
    add_numba_threads_argument(parser)
    parser.add_argument("--time-limit-min", type=float, default=None,
                        help="stop training after this many minutes of wall time")
    add_quiet_argument(parser, help="hide the progress bar")
    args = parser.parse_args(argv)
    if args.resume is None and (args.env is None or args.algo is None):
        parser.error("--env and --algo are required (or --resume RUN_DIR)")
    received = []

    def stop(signum, frame):  # schedulers stop jobs with SIGTERM: save first, as on Ctrl-C
        received.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)
    try:
        apply_numba_threads(args.numba_threads)
        if args.resume is not None:
            run_dir = resume(args.resume, timesteps=args.timesteps, time_limit_min=args.time_limit_min,
                             threads=args.threads, progress=not args.quiet)
        else:
            run_dir = train(args.env, args.algo, timesteps=args.timesteps, seed=args.seed,
                            log_dir=args.log_dir, hyperparams_dir=args.hyperparams_dir,
                            eval_freq=args.eval_freq, eval_episodes=args.eval_episodes,
                            checkpoint_freq=args.checkpoint_freq, threads=args.threads or 1,
                            progress=not args.quiet, time_limit_min=args.time_limit_min,
                            save_replay_buffer=args.save_replay_buffer, batched=args.batched,
                            run_name=args.run_name, init_policy=args.init_policy)
    except ValueError as exc:
        print(f"baselines.train: error: {exc}", file=sys.stderr)
        return 2
    except TrainingInterrupted as exc:
        print(f"baselines.train: interrupted at step {exc.timesteps}; saved {exc.checkpoint}; "
              f"continue with: python -m baselines.train --resume {exc.run_dir}", file=sys.stderr)
        return 128 + (received[0] if received else signal.SIGINT)
    except KeyboardInterrupt:
        print("baselines.train: interrupted outside training; nothing new saved (complete checkpoints "
              "are kept)", file=sys.stderr)
        return 128 + (received[0] if received else signal.SIGINT)
    print(run_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
