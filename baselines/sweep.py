"""Training sweeps — environments × algorithms × seeds × observation modes — run one after another
here or as Ray tasks on a cluster, every run resumable, then evaluated and written up.

Usage::

    python -m baselines.sweep --envs SoftArm/OctArmReach-v1,SoftArm/CTReach-v1 --algos sac,ppo,td3 \\
        --seeds 0-9 --observations true,cable_encoder --backend ray --address auto
    python -m baselines.sweep ...same options... --resume   # after Ctrl-C, a lost driver or failed runs

Each run is :func:`baselines.train.train` with the hyperparameters of
``baselines/hyperparams/<algo>.yml`` for its environment (``--timesteps`` replaces their
budget) and the observation mode in ``env_kwargs``; an interrupted or failed run continues
with :func:`baselines.train.resume`. ``--backend local`` (the default) runs the plan one run
after another in this process; ``--backend ray`` makes every run one Ray task holding
``--cpus-per-run`` CPUs (torch and numba use that many threads), on the cluster at
``--address`` or, without it, Ray's default: the cluster ``ray start`` left on this machine if
there is one, else a private instance for this command. The output folder ``--out`` (default
``sweep``) receives:

* ``runs/<run>/`` — exactly what ``baselines.train`` writes (``config.json``, ``monitor.csv``,
  ``progress.csv``, TensorBoard files, ``checkpoints/``, ``evaluations.npz``,
  ``best_model.zip`` and ``final_model.zip`` with their metadata, ``summary.json``). ``<run>``
  is ``<algo>_<env>_s<seed>``, with ``_<observation>`` before ``_s<seed>`` unless the
  observation is ``true``;
* ``results/`` — :func:`baselines.results.collect` of the finished runs, the evaluation cells
  (``--evaluate main``, the default: every trained policy and the Jacobian controller with
  true observations; ``grid``: the estimator-in-the-loop cells as well; ``none``) and
  ``learning_curves.png``; ``--results-dir`` puts them elsewhere;
* ``RESULTS.md`` — :func:`baselines.results.report` of those, with a table of the runs;
  ``--results FILE`` writes it elsewhere (the shipped ``baselines/RESULTS.md`` only if asked);
* ``sweep.json`` — the plan and the state of every run: finished, failed (with the error) or
  not finished, how many attempts it took and which host finished it.

One progress bar covers the runs (another the evaluation cells). Faults:

* a run that raises, or whose Ray worker or node dies, is started again up to ``--retries``
  times; it continues from its newest complete checkpoint (``--checkpoint-freq``), so it loses
  at most the steps since then and still ends at its planned step count. A run that keeps
  failing is reported and the others go on; the results are written from what finished and
  the command ends with a one-line error (exit status 2).
* Ctrl-C (or SIGTERM) stops the sweep: running trainings save a checkpoint (Ray tasks are
  cancelled gently and given :data:`CANCEL_GRACE_S` to do so), and one line says what is kept
  (exit status 2). ``--resume`` then continues every unfinished run from its newest checkpoint
  and skips the finished runs and evaluation cells.
* An unreachable ``--address``, a Ray version mismatch, a worker that runs other code than
  this process, or one that cannot see the output folder are one-line errors (exit status 2).
  Ray workers write the run folders themselves: on a multi-node cluster ``--out`` (and
  ``--results-dir``) must be on a filesystem that every node mounts at the same path.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shlex
import shutil
import signal
import socket
import sys
import threading
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from baselines import results
from baselines.config import (
    ALGOS,
    HYPERPARAMS_DIR,
    check_env_id,
    load_hyperparams,
    make_env,
    split_hyperparams,
)
from baselines.train import CONFIG_FILE, check_counts, latest_checkpoint, resume, train
from softarm_gym.commands.common import (
    add_numba_threads_argument,
    add_quiet_argument,
    apply_numba_threads,
    parse_seeds,
)
from softarm_gym.files import write_json
from softarm_gym.jobs import (
    BACKENDS,
    DEFAULT_RETRIES,
    Interrupted,
    JobError,
    cancel_unfinished,
    code_fingerprint,
    first_line,
    ray_session,
)
from softarm_gym.sensing import ESTIMATORS

__all__ = ["RunSpec", "SweepResult", "plan_runs", "parse_seeds", "sweep", "train_run", "evaluate_cell",
           "WorkerSetupError", "EVALUATE", "main"]

PACKAGES = ("solver", "softarm_gym", "baselines")
"""Packages whose source must be the same in every Ray worker as in the driver."""
EVALUATE = ("none", "main", "grid")
PLAN_FILE = "sweep.json"
RUNS_DIR = "runs"
CANCEL_GRACE_S = 30.0
"""Seconds Ray tasks get after Ctrl-C to save a checkpoint before the driver lets go of them."""
DEFAULT_CHECKPOINT_FREQ = 10_000
"""Steps between checkpoints: what a lost worker may cost a run (the YAML budgets are 150,000)."""


class WorkerSetupError(RuntimeError):
    """A worker that cannot take part in the sweep: other code, or the output folder not visible."""


# --------------------------------------------------------------------------- the plan


@dataclass(frozen=True)
class RunSpec:
    """One training run of a sweep.

    Attributes:
        env_id: registered ``SoftArm/*`` id.
        algo: one of :data:`baselines.config.ALGOS`.
        seed: seeds the algorithm and the environments.
        observation: shape estimator of the observations, one of ``ESTIMATORS``.
        timesteps: environment steps (the budget).
        hyperparams: the YAML entry, with the observation in ``env_kwargs``.
    """

    env_id: str
    algo: str
    seed: int
    observation: str
    timesteps: int
    hyperparams: dict = field(repr=False)

    @property
    def name(self) -> str:
        """The run folder's name: ``<algo>_<env>[_<observation>]_s<seed>``."""
        observation = "" if self.observation == "true" else f"_{self.observation}"
        return f"{self.algo}_{self.env_id.split('/')[-1]}{observation}_s{self.seed}"


def _names(text: str, choices, what: str) -> list[str]:
    """Comma-separated names, each one of ``choices`` (None: any), without repeats, in order."""
    names = list(dict.fromkeys(n.strip() for n in str(text).split(",") if n.strip()))
    if not names:
        raise ValueError(f"--{what}: give at least one name")
    for name in names:
        if choices is not None and name not in choices:
            raise ValueError(f"--{what}: unknown {name!r}; choose from {', '.join(choices)}")
    return names


def _check_env_kwargs(env_id: str, env_kwargs: dict, where: str) -> None:
    """Build the env once, so that settings it refuses (``observation_format="goal"`` with an
    estimator, say) are one line before the sweep rather than a failure in every run."""
    try:
        make_env(env_id, env_kwargs).close()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {first_line(exc)}") from None


def plan_runs(env_ids, algos, seeds, observations=("true",), *, timesteps: int | None = None,
              hyperparams_dir: Path | str = HYPERPARAMS_DIR) -> list[RunSpec]:
    """Every (env, algo, observation, seed) run, with its hyperparameters and budget, checked.

    Args:
        env_ids: registered environment ids, each with an entry in every algorithm's YAML.
        algos: names in :data:`baselines.config.ALGOS`.
        seeds: integers >= 0.
        observations: names in ``softarm_gym.sensing.ESTIMATORS``.
        timesteps: budget of every run; default each YAML entry's ``n_timesteps``.
        hyperparams_dir: folder of the YAML files.

    Raises:
        ValueError: anything unknown or missing, or env settings the env refuses, named on one
            line.
    """
    if timesteps is not None and (isinstance(timesteps, bool) or int(timesteps) != timesteps
                                  or timesteps < 1):
        raise ValueError(f"timesteps must be an integer >= 1; got {timesteps!r}")
    for seed in seeds:
        if isinstance(seed, bool) or int(seed) != seed or seed < 0:
            raise ValueError(f"seeds must be integers >= 0; got {seed!r}")
    runs = []
    for env_id in env_ids:
        check_env_id(env_id)
        for algo in algos:
            if algo not in ALGOS:
                raise ValueError(f"unknown algo {algo!r}; choose one of {', '.join(ALGOS)}")
            params = load_hyperparams(algo, env_id, hyperparams_dir)
            special, _ = split_hyperparams(params)
            budget = int(special["n_timesteps"] if timesteps is None else timesteps)
            if budget < 1:
                raise ValueError(f"{algo}.yml[{env_id!r}].n_timesteps must be >= 1; got {budget}")
            for observation in observations:
                if observation not in ESTIMATORS:
                    raise ValueError(f"unknown observation {observation!r}; choose one of "
                                     f"{', '.join(ESTIMATORS)}")
                run_params = params
                if params.get("env_kwargs", {}).get("observation", "true") != observation:
                    run_params = {**params, "env_kwargs": {**params.get("env_kwargs", {}),
                                                           "observation": observation}}
                _check_env_kwargs(env_id, run_params.get("env_kwargs", {}),
                                  f"{algo}.yml[{env_id!r}] with observation {observation!r}")
                runs += [RunSpec(env_id, algo, int(seed), observation, budget, run_params) for seed in seeds]
    if not runs:
        raise ValueError("the sweep has no runs: give at least one env, algo, seed and observation")
    return runs


# --------------------------------------------------------------------------- tasks (workers)


@contextlib.contextmanager
def _worker(out: str, sweep_id: str, fingerprint: str, ray_cpus: int | None):
    """Check that this process can take part in the sweep, and prepare a Ray task for the block.

    A worker running other code, or one that does not see the output folder, raises
    :class:`WorkerSetupError`. In a Ray task (``ray_cpus``: its CPUs) numba is limited to that
    many threads, and SIGINT raises KeyboardInterrupt for the block: Ray stops a task gently
    (``ray.cancel``) with a SIGINT-style interrupt, which a worker that inherited an ignored
    SIGINT (a cluster started by ``nohup`` or a script) would drop, and the training would
    not save its checkpoint.
    """
    node = socket.gethostname()
    mine = code_fingerprint(PACKAGES)
    if mine != fingerprint:
        raise WorkerSetupError(f"the worker on {node} runs other solver/softarm_gym/baselines code "
                               f"(fingerprint {mine}, the driver {fingerprint}): install the same "
                               "softarm-gym version on every node")
    try:
        found = json.loads((Path(out) / PLAN_FILE).read_text()).get("id")
    except (OSError, ValueError, AttributeError):
        found = None
    if found != sweep_id:
        raise WorkerSetupError(f"the worker on {node} does not see the sweep's output folder {out}: put "
                               "--out (and --results-dir) on a filesystem every node mounts at the same path")
    if ray_cpus is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    import numba

    threads_before = numba.get_num_threads()
    numba.set_num_threads(max(1, min(ray_cpus, numba.config.NUMBA_NUM_THREADS)))
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        numba.set_num_threads(threads_before)


def train_run(spec: RunSpec, settings: dict, out: str, sweep_id: str, fingerprint: str,
              ray_cpus: int | None = None) -> dict:
    """One run of a sweep, in a Ray worker or in the driver; safe to call again after any fault.

    A finished run (``summary.json``) is left alone; a run with a complete checkpoint continues
    from the newest one (:func:`baselines.train.resume`); otherwise the run starts (again,
    after removing a folder that has no checkpoint yet).

    Args:
        spec: the run.
        settings: :func:`baselines.train.train` keyword arguments shared by all runs.
        out: the sweep's output folder (absolute).
        sweep_id, fingerprint: what the driver wrote to ``sweep.json`` and its code fingerprint.
        ray_cpus: the CPUs of the Ray task running this (None: not in Ray).

    Returns:
        ``{"timesteps_done", "resumed_from", "node"}``.
    """
    runs_dir = Path(out) / RUNS_DIR
    run_dir = runs_dir / spec.name
    with _worker(out, sweep_id, fingerprint, ray_cpus):
        finished = (run_dir / "summary.json").is_file()
        if not finished and (run_dir / CONFIG_FILE).is_file() and latest_checkpoint(run_dir) is not None:
            resume(run_dir, threads=settings["threads"], progress=False)
        elif not finished:  # not started, or started without reaching a checkpoint: (re)start
            shutil.rmtree(run_dir, ignore_errors=True)
            train(spec.env_id, spec.algo, timesteps=spec.timesteps, seed=spec.seed, log_dir=runs_dir,
                  run_name=spec.name, hyperparams=spec.hyperparams, progress=False, **settings)
    summary = json.loads((run_dir / "summary.json").read_text())
    return {"timesteps_done": summary["timesteps_done"], "resumed_from": summary.get("resumed_from"),
            "node": socket.gethostname()}


def evaluate_cell(job: tuple, out: str, sweep_id: str, fingerprint: str,
                  ray_cpus: int | None = None) -> str:
    """One evaluation cell (:func:`baselines.results.run_evaluation_job`), after the worker checks."""
    with _worker(out, sweep_id, fingerprint, ray_cpus):
        return results.run_evaluation_job(job)


# --------------------------------------------------------------------------- running tasks


@dataclass
class _Task:
    name: str
    args: tuple
    attempts: int = 0
    error: str | None = None
    result: object = None


def _failed(task: _Task, exc: BaseException, retries: int, what: str) -> bool:
    """Record a failure; True if the task has used up its retries, else say that it is retried."""
    task.error = f"{type(exc).__name__}: {first_line(exc)[:200]}"
    if task.attempts > retries:
        tqdm.write(f"{task.name} failed {task.attempts} time{'s' if task.attempts > 1 else ''}; giving up "
                   f"({task.error})", file=sys.stderr)
        return True
    tqdm.write(f"{task.name} failed ({task.error}); attempt {task.attempts + 1} of {retries + 1}{what}",
               file=sys.stderr)
    return False


def _execute(fn, tasks: list[_Task], *, ray, cpus: int, retries: int, bar, what: str) -> None:
    """Run ``fn(*task.args)`` for every task, here (``ray`` None) or as Ray tasks of ``cpus`` CPUs;
    a task that raises or whose worker dies is run again up to ``retries`` times. Sets each
    task's ``result`` (None if it failed for good) and updates ``bar`` as tasks end.

    Raises:
        JobError: a worker cannot take part (:class:`WorkerSetupError`).
        KeyboardInterrupt: after Ray tasks were asked to stop and given time to save.
    """
    def ended(task):
        bar.update(1)
        failed = sum(t.result is None and t.error is not None and t.attempts > retries for t in tasks)
        if failed:
            bar.set_postfix(failed=failed)

    if ray is None:
        for task in tasks:
            while True:
                task.attempts += 1
                try:
                    task.result = fn(*task.args)
                except Exception as exc:
                    if not _failed(task, exc, retries, what):
                        continue
                ended(task)
                break
        return
    remote = ray.remote(fn).options(num_cpus=cpus, max_retries=0, retry_exceptions=False)
    pending = {}

    def submit(task):
        task.attempts += 1
        pending[remote.remote(*task.args, ray_cpus=cpus)] = task

    for task in tasks:
        submit(task)
    try:
        while pending:
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            task = pending.pop(ref)
            try:
                task.result = ray.get(ref)
            except ray.exceptions.RayTaskError as exc:  # fn raised: the original exception
                cause = exc.cause if isinstance(exc.cause, BaseException) else exc
                if isinstance(cause, WorkerSetupError):
                    raise JobError(str(cause)) from None
                if not _failed(task, cause, retries, what):
                    submit(task)
                    continue
            except ray.exceptions.RayError as exc:  # the worker or its node died, the task was lost
                if not _failed(task, exc, retries, what):
                    submit(task)
                    continue
            ended(task)
    except KeyboardInterrupt:
        # A gentle cancel raises KeyboardInterrupt in the task: a training saves a checkpoint.
        cancel_unfinished(ray, pending, force=False)
        with contextlib.suppress(KeyboardInterrupt):  # a second Ctrl-C: do not wait
            ray.wait(list(pending), num_returns=len(pending), timeout=CANCEL_GRACE_S)
        raise
    finally:
        cancel_unfinished(ray, pending, force=True)


def _check_cpus(ray, cpus: int) -> None:
    """Ray waits forever for a task no node can hold: say so instead."""
    largest = max((n["Resources"].get("CPU", 0) for n in ray.nodes() if n.get("Alive")), default=0)
    if largest < cpus:
        raise JobError(f"--cpus-per-run {cpus}: no node of the Ray cluster has that many CPUs "
                       f"(the largest has {largest:g})")


# --------------------------------------------------------------------------- the sweep


@dataclass
class SweepResult:
    """What a sweep did.

    Attributes:
        runs: run name → ``{"state": "finished" | "failed" | "not finished", "attempts", "error",
            "node"}``: attempts in this command, the last error, the host that finished the run in
            this command (None: finished before, or not finished). Steps and times are in the
            run's ``summary.json``.
        failed_cells: evaluation cells (file names) that failed for good, with their errors.
        results_file: the regenerated results document.
    """

    runs: dict
    failed_cells: dict
    results_file: Path

    @property
    def failed(self) -> list[str]:
        return [name for name, state in self.runs.items() if state["state"] == "failed"]


def _existing(runs: list[RunSpec], runs_dir: Path, resume_: bool) -> None:
    """Without ``resume_``, refuse a folder that holds runs of the plan; with it, refuse runs
    that were started with other settings."""
    started = [spec for spec in runs if (runs_dir / spec.name / CONFIG_FILE).is_file()]
    if started and not resume_:
        raise ValueError(f"{runs_dir} already holds {len(started)} of the sweep's runs ({started[0].name}"
                         f"{', ...' if len(started) > 1 else ''}); continue them with --resume, or choose "
                         "another --out")
    for spec in started:
        config = json.loads((runs_dir / spec.name / CONFIG_FILE).read_text())
        for key, want in (("env_id", spec.env_id), ("algo", spec.algo), ("seed", spec.seed),
                          ("timesteps", spec.timesteps), ("hyperparams", spec.hyperparams)):
            if config.get(key) != json.loads(json.dumps(want)):
                raise ValueError(f"{spec.name} in {runs_dir} was started with another {key} than this sweep "
                                 f"plans ({json.dumps(config.get(key))[:60]} vs {json.dumps(want)[:60]}); "
                                 "choose another --out")


def _minutes(seconds) -> str:
    return "–" if seconds is None else f"{seconds / 60:.1f}"


def _intro(runs: list[RunSpec], states: dict, runs_dir: Path, results_file: Path, command: str | None,
           backend: str, evaluate: str) -> list[str]:
    """The results document's introduction: how it was made, and a table of the sweep's runs."""
    where = os.path.relpath(runs_dir, results_file.resolve().parent)
    lines = [f"Regenerated by `python -m baselines.sweep` ({backend} backend) from the runs in `{where}`"
             + (f", with:\n\n```\n{command}\n```" if command else ".") + "", "",
             "Each run is `baselines.train` with the hyperparameters of `baselines/hyperparams/<algo>.yml` "
             "for its env (budget and observation mode as in the table below); `jacobian_*` is "
             "`softarm_gym.controllers.JacobianController` on the registered env, for reference. "
             + ("Policies were not evaluated (`--evaluate none`). " if evaluate == "none" else "")
             + results.DEFINITIONS, "",
             "## Runs", "",
             "Steps done of the planned budget, wall and CPU time of the training (all sessions), the step "
             "the last session resumed from (after an interruption or a failure), attempts in the last "
             "sweep command.", "",
             "| run | env | algo | observation | seed | steps | wall (min) | CPU (min) | resumed from "
             "| attempts | state |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for spec in runs:
        state = states[spec.name]
        summary_path = runs_dir / spec.name / "summary.json"
        summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
        done = summary.get("timesteps_done")
        steps = f"{done:,} / {spec.timesteps:,}" if done is not None else f"– / {spec.timesteps:,}"
        resumed = summary.get("resumed_from")
        text = state["state"] + (f": {state['error']}" if state.get("error") and state["state"] == "failed"
                                 else "")
        lines.append(f"| {spec.name} | {spec.env_id} | {spec.algo} | {spec.observation} | {spec.seed} | "
                     f"{steps} | {_minutes(summary.get('wall_time_s'))} | "
                     f"{_minutes(summary.get('cpu_time_s'))} | "
                     f"{'–' if not resumed else f'{resumed:,}'} | {state['attempts'] or '–'} | "
                     f"{text.replace('|', '/')} |")
    return lines + [""]


@dataclass(frozen=True)
class SweepConfig:
    """How a sweep runs (every argument of :func:`sweep` but the plan), checked in
    ``__post_init__``; ``out``, ``results_dir`` and ``results_file`` resolved to absolute paths.

    Attributes:
        out: output folder (runs, results, ``RESULTS.md``, ``sweep.json``).
        backend: ``"local"`` or ``"ray"``.
        address: Ray cluster (``"auto"``, ``"HOST:PORT"``); None: the Ray session this process
            already has, else Ray's default (a cluster started on this machine, else a private
            instance).
        cpus_per_run: CPUs of each Ray task, and torch (and in Ray, numba) threads of each run.
        retries: times a failed run or evaluation cell is started again.
        resume: continue the runs already in ``out`` (else they are an error).
        evaluate: ``"main"``, ``"grid"`` or ``"none"`` (module docstring).
        evaluate_episodes: episodes of each evaluation cell (default 100 for ``main``, 20 per
            grid cell, as in ``baselines.results``).
        results_dir: default ``out/results``.
        results_file: default ``out/RESULTS.md``.
        eval_freq, eval_episodes, checkpoint_freq, save_replay_buffer: as for
            :func:`baselines.train.train`, for every run.
        progress: progress bars on stderr.
        command: the command line, quoted in the results document.
    """

    out: Path | str = "sweep"
    backend: str = "local"
    address: str | None = None
    cpus_per_run: int = 1
    retries: int = DEFAULT_RETRIES
    resume: bool = False
    evaluate: str = "main"
    evaluate_episodes: int | None = None
    results_dir: Path | str | None = None
    results_file: Path | str | None = None
    eval_freq: int = 10_000
    eval_episodes: int = 20
    checkpoint_freq: int = DEFAULT_CHECKPOINT_FREQ
    save_replay_buffer: bool = False
    progress: bool = True
    command: str | None = None

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown backend {self.backend!r}; choose one of {', '.join(BACKENDS)}")
        if self.backend == "local" and self.address is not None:
            raise ValueError("a Ray address was given but the backend is 'local'; use --backend ray")
        if self.evaluate not in EVALUATE:
            raise ValueError(f"evaluate must be one of {', '.join(EVALUATE)}; got {self.evaluate!r}")
        for name, value, low in (("cpus_per_run", self.cpus_per_run, 1), ("retries", self.retries, 0)):
            if isinstance(value, bool) or int(value) != value or value < low:
                raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
        episodes = self.evaluate_episodes
        if episodes is not None and (int(episodes) != episodes or episodes < 1):
            raise ValueError(f"evaluate_episodes must be an integer >= 1; got {episodes!r}")
        check_counts(self.eval_freq, self.checkpoint_freq, self.cpus_per_run)
        if self.eval_episodes < 1:
            raise ValueError(f"eval_episodes must be >= 1; got {self.eval_episodes}")
        out = Path(self.out).resolve()
        object.__setattr__(self, "out", out)
        object.__setattr__(self, "results_dir", out / "results" if self.results_dir is None
                           else Path(self.results_dir).resolve())
        object.__setattr__(self, "results_file", out / "RESULTS.md" if self.results_file is None
                           else Path(self.results_file).resolve())

    @property
    def runs_dir(self) -> Path:
        """Where the runs are trained."""
        return self.out / RUNS_DIR

    def run_settings(self) -> dict:
        """The training settings every run gets (:func:`train_run`)."""
        return {"eval_freq": self.eval_freq, "eval_episodes": self.eval_episodes,
                "checkpoint_freq": self.checkpoint_freq, "save_replay_buffer": self.save_replay_buffer,
                "threads": int(self.cpus_per_run)}


def sweep(runs: list[RunSpec], out: Path | str = "sweep", *, backend: str = "local",
          address: str | None = None, cpus_per_run: int = 1, retries: int = DEFAULT_RETRIES,
          resume: bool = False,
          evaluate: str = "main", evaluate_episodes: int | None = None,
          results_dir: Path | str | None = None, results_file: Path | str | None = None,
          eval_freq: int = 10_000, eval_episodes: int = 20, checkpoint_freq: int = DEFAULT_CHECKPOINT_FREQ,
          save_replay_buffer: bool = False, progress: bool = True, command: str | None = None) -> SweepResult:
    """Train every run of ``runs`` (:func:`plan_runs`), evaluate them and write the results
    document (module docstring).

    Args:
        runs: the plan.
        out: and the other keyword arguments (backend, address, cpus_per_run, retries, resume,
            evaluate, evaluate_episodes, results_dir, results_file, eval_freq, eval_episodes,
            checkpoint_freq, save_replay_buffer, progress, command): the fields of
            :class:`SweepConfig`.

    Returns:
        The state of every run, the evaluation cells that failed, the results file.

    Raises:
        ValueError: bad arguments, or an output folder that holds other runs.
        JobError: Ray could not be used (unreachable, version mismatch, a worker that runs other
            code or cannot see ``out``), one line saying what is kept.
        Interrupted: Ctrl-C (also a ``KeyboardInterrupt``); finished runs and checkpoints are kept.
    """
    config = SweepConfig(
        out=out, backend=backend, address=address, cpus_per_run=cpus_per_run, retries=retries,
        resume=resume, evaluate=evaluate, evaluate_episodes=evaluate_episodes,
        results_dir=results_dir, results_file=results_file, eval_freq=eval_freq,
        eval_episodes=eval_episodes, checkpoint_freq=checkpoint_freq,
        save_replay_buffer=save_replay_buffer, progress=progress, command=command)
    return run_sweep(runs, config)


def run_sweep(runs: list[RunSpec], config: SweepConfig) -> SweepResult:
    """:func:`sweep` of a checked :class:`SweepConfig`: train the runs, collect and evaluate
    them, write the results document."""
    names = [spec.name for spec in runs]
    if len(set(names)) != len(names):
        raise ValueError("the plan names a run twice")
    out, runs_dir, results_dir = config.out, config.runs_dir, config.results_dir
    try:
        for folder in (runs_dir, results_dir):
            folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"cannot create {folder}: {exc.strerror or exc}") from None
    _existing(runs, runs_dir, config.resume)

    settings = config.run_settings()
    sweep_id, fingerprint = uuid.uuid4().hex, code_fingerprint(PACKAGES)
    states = {}
    for spec in runs:
        finished = (runs_dir / spec.name / "summary.json").is_file()
        states[spec.name] = {"state": "finished" if finished else "not finished", "attempts": 0,
                             "error": None, "node": None}

    def record() -> None:
        write_json(out / PLAN_FILE, {
            "id": sweep_id, "command": config.command, "backend": config.backend,
            "address": config.address, "cpus_per_run": config.cpus_per_run,
            "retries": config.retries, "evaluate": config.evaluate, "settings": settings,
            "runs": [{"name": s.name, "env_id": s.env_id, "algo": s.algo, "seed": s.seed,
                      "observation": s.observation, "timesteps": s.timesteps, **states[s.name]}
                     for s in runs]})

    record()
    tasks = [_Task(spec.name, (spec, settings, str(out), sweep_id, fingerprint))
             for spec in runs if states[spec.name]["state"] != "finished"]
    cells = []
    failed_cells = {}

    def settle() -> None:
        """Each attempted run's state from its folder and its attempts; saved to ``sweep.json``."""
        for task in tasks:
            finished = (runs_dir / task.name / "summary.json").is_file()
            given_up = task.error is not None and task.attempts > config.retries
            state = "finished" if finished else "failed" if given_up else "not finished"
            states[task.name].update(attempts=task.attempts, error=None if finished else task.error,
                                     node=task.result["node"] if task.result else None,
                                     state=state)
        record()

    def kept() -> str:
        done = sum(state["state"] == "finished" for state in states.values())
        return (f"{done} of {len(runs)} runs finished and kept in {runs_dir} (unfinished runs continue from "
                "their newest checkpoint); rerun the same command with --resume to continue")

    with contextlib.ExitStack() as stack:
        ray = None

        def connect():
            nonlocal ray
            if config.backend == "ray" and ray is None:
                ray = stack.enter_context(ray_session(config.address))
                _check_cpus(ray, int(config.cpus_per_run))
            return ray

        if tasks:
            connect()  # an unreachable cluster is one line before anything happens
        try:
            if tasks:
                with tqdm(total=len(runs), initial=len(runs) - len(tasks), unit="run", desc="train",
                          file=sys.stderr, disable=not config.progress, dynamic_ncols=True) as bar:
                    _execute(train_run, tasks, ray=connect(), cpus=int(config.cpus_per_run),
                             retries=config.retries, bar=bar,
                             what=", from its newest checkpoint if it has one")
            settle()
            results.collect(runs_dir, results_dir)
            if config.evaluate != "none":
                cells = _evaluation_cells(runs, config, sweep_id, fingerprint)
                if cells:
                    with tqdm(total=len(cells), unit="cell", desc="evaluate", file=sys.stderr,
                              disable=not config.progress, dynamic_ncols=True) as bar:
                        _execute(evaluate_cell, cells, ray=connect(), cpus=1, retries=config.retries,
                                 bar=bar, what="")
                failed_cells = {c.name: c.error for c in cells if c.result is None}
        except KeyboardInterrupt:
            settle()
            done_cells = sum(c.result is not None for c in cells)
            evaluated = f"; {done_cells} of {len(cells)} evaluation cells done" if cells else ""
            raise Interrupted(f"interrupted; {kept()}{evaluated}") from None
        except JobError as exc:
            settle()
            raise JobError(f"{exc}; {kept()}") from None
    results.report(results_dir, config.results_file, title="Sweep results",
                   intro=_intro(runs, states, runs_dir, config.results_file, config.command,
                                config.backend, config.evaluate))
    return SweepResult(runs=states, failed_cells=failed_cells, results_file=config.results_file)


def _evaluation_cells(runs: list[RunSpec], config: SweepConfig, sweep_id: str,
                      fingerprint: str) -> list[_Task]:
    """The evaluation cells of the collected runs (main, or the estimator grid)."""
    envs = [e for e in dict.fromkeys(s.env_id for s in runs) if e in results.ENV_IDS]
    jobs = results.evaluation_jobs(config.runs_dir, config.results_dir, grid=config.evaluate == "grid",
                                   env_ids=envs, episodes=config.evaluate_episodes)
    return [_Task(path.name, ((path, kwargs), str(config.out), sweep_id, fingerprint))
            for path, kwargs in jobs]


# --------------------------------------------------------------------------- command line


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="python -m baselines.sweep",
                                     description=__doc__.split("\n\n")[0].replace("\n", " "))
    what = parser.add_argument_group("the plan")
    what.add_argument("--envs", default=",".join(results.ENV_IDS),
                      help="comma-separated environment ids (default %(default)s)")
    what.add_argument("--algos", default="sac",
                      help=f"comma-separated, from {', '.join(ALGOS)} (default %(default)s)")
    what.add_argument("--seeds", default="0", help="seeds: 0-9, 0,3,5 or 0-4,10 (default %(default)s)")
    what.add_argument("--observations", default="true",
                      help=f"comma-separated, from {', '.join(ESTIMATORS)} (default %(default)s)")
    what.add_argument("--timesteps", type=int, default=None,
                      help="steps of every run (default: n_timesteps of each YAML entry)")
    what.add_argument("--hyperparams-dir", default=str(HYPERPARAMS_DIR))
    where = parser.add_argument_group("where it runs")
    where.add_argument("--backend", choices=BACKENDS, default="local",
                       help="one run after another in this process (local), or one Ray task per run")
    where.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                       help="Ray cluster to use with --backend ray (default: the cluster `ray start` "
                            "left on this machine, else a private instance)")
    where.add_argument("--cpus-per-run", type=int, default=1, metavar="N",
                       help="CPUs of each run's Ray task, and its torch/numba threads (default %(default)s)")
    where.add_argument("--retries", type=int, default=DEFAULT_RETRIES, metavar="N",
                       help="times a failed run is continued from its newest checkpoint "
                            "(default %(default)s)")
    where.add_argument("--resume", action="store_true",
                       help="continue the unfinished runs and evaluations of an earlier sweep in --out")
    outputs = parser.add_argument_group("outputs")
    outputs.add_argument("--out", default="sweep", help="output folder (default %(default)s)")
    outputs.add_argument("--results", default=None, metavar="FILE.md",
                         help="the results document (default OUT/RESULTS.md)")
    outputs.add_argument("--results-dir", default=None, metavar="DIR",
                         help="collected curves and evaluation cells (default OUT/results)")
    outputs.add_argument("--evaluate", choices=EVALUATE, default="main",
                         help="after training: evaluate with true observations (main), also the estimator "
                              "grid (grid), or not (none); default %(default)s")
    outputs.add_argument("--evaluate-episodes", type=int, default=None, metavar="N",
                         help="episodes per evaluation cell (default 100 main, 20 per grid cell)")
    training = parser.add_argument_group("training (as baselines.train)")
    training.add_argument("--eval-freq", type=int, default=10_000, help="0 disables periodic evaluation")
    training.add_argument("--eval-episodes", type=int, default=20)
    training.add_argument("--checkpoint-freq", type=int, default=DEFAULT_CHECKPOINT_FREQ,
                          help="steps between checkpoints, at most what a lost worker costs (default "
                               "%(default)s)")
    training.add_argument("--save-replay-buffer", action="store_true",
                          help="save the off-policy replay buffer with checkpoints")
    add_quiet_argument(parser, help="hide the progress bars")
    add_numba_threads_argument(parser)
    args = parser.parse_args(argv)
    received = []

    def stop(signum, frame):  # schedulers stop jobs with SIGTERM: stop as on Ctrl-C
        received.append(signum)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        apply_numba_threads(args.numba_threads)
        if args.address is not None and args.backend != "ray":
            raise ValueError("--address needs --backend ray")
        if args.results is not None:
            from softarm_gym.commands.long_jobs import check_outputs

            check_outputs(args, files=("results",))
        runs = plan_runs(_names(args.envs, None, "envs"), _names(args.algos, ALGOS, "algos"),
                         parse_seeds(args.seeds), _names(args.observations, ESTIMATORS, "observations"),
                         timesteps=args.timesteps, hyperparams_dir=args.hyperparams_dir)
        result = sweep(runs, args.out, backend=args.backend, address=args.address,
                       cpus_per_run=args.cpus_per_run, retries=args.retries, resume=args.resume,
                       evaluate=args.evaluate,
                       evaluate_episodes=args.evaluate_episodes, results_dir=args.results_dir,
                       results_file=args.results, eval_freq=args.eval_freq, eval_episodes=args.eval_episodes,
                       checkpoint_freq=args.checkpoint_freq, save_replay_buffer=args.save_replay_buffer,
                       progress=not args.quiet,
                       command="python -m baselines.sweep " + shlex.join(argv))
    except (ValueError, JobError) as exc:
        print(f"baselines.sweep: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"baselines.sweep: error: interrupted; finished runs are kept in {args.out}; rerun the same "
              "command with --resume to continue", file=sys.stderr)
        return 2
    finally:
        signal.signal(signal.SIGTERM, previous)
    if result.failed or result.failed_cells:
        first = result.failed[0] if result.failed else next(iter(result.failed_cells))
        error = result.runs[first]["error"] if result.failed else result.failed_cells[first]
        print(f"baselines.sweep: error: {len(result.failed)} of {len(result.runs)} runs and "
              f"{len(result.failed_cells)} evaluation cells failed after {args.retries} retries (first: "
              f"{first}: {error}); {result.results_file} was written from the rest; rerun the same command "
              "with --resume to try them again", file=sys.stderr)
        return 2
    print(result.results_file)
    return 0


if __name__ == "__main__":
    sys.exit(main())
