"""Wall time to a success rate: agents on single envs against agents on the batched env, in one run.

    python -m baselines.time_to_success --env SoftArm/OctArmReach-v1 --budget-min 20 --speedup-goal 3 \\
        --json docs/bench/time_to_success.json --plot docs/bench/time_to_success.png

Each agent of :data:`AGENTS` — ``sac`` and ``ppo`` with the hyperparameters of the reported
runs (``--hyperparams-dir``, default ``baselines/hyperparams/``: single envs in SB3's
``DummyVecEnv``), ``sac_batched`` and ``ppo_batched`` with those of
``--batched-hyperparams-dir`` (default the ``batched/`` folder beside them: one
:class:`softarm_gym.sb3.BatchedVecEnv` of ``n_envs`` arms) — trains from scratch, one after
another in this process (so all see the same machine), until its deterministic policy
succeeds in at least ``--target`` of the evaluation episodes, or until ``--budget-min``
minutes of training.

* Clock: wall time of training from the start of ``learn()`` (model and environment
  construction excluded), with the clock stopped while an evaluation runs; the process's
  CPU time likewise (the machine may be shared: CPU time says how much compute a run got).
* Evaluation, every ``--eval-every-s`` seconds of training: :data:`EVAL_EPISODES` whole
  episodes on a batched env with the training env's settings, episode i seeded i — the
  episodes of the main column of ``baselines/RESULTS.md`` — success = the env's
  ``is_success`` at the episode's last step (reach: final true tip within the env's
  tolerance; wrap: the wrap held), the policy deterministic on observations normalised with
  the training statistics. The first evaluation at or above the target stops the agent, and its
  policy is evaluated once more on held-out episodes (seeds :data:`CONFIRM_SEED` + i).
* Result: per agent and seed the time, CPU time and steps to the target (None if the budget
  ran out), the history of evaluations with the 1-minute load average; the best agent of
  each kind (lowest median time over seeds) and the ratio best single / best batched. An
  agent that never reached the target counts as its budget, so a ratio built on it is a
  lower bound (``speedup_is_lower_bound``).

Given one folder for both kinds, the two agents of an algorithm train with the same settings
and the same ``n_envs``: the batched env's copy i equals the ``DummyVecEnv``'s env i bit for
bit, so the runs differ in how fast the environment steps, not in what is learned::

    python -m baselines.time_to_success --env SoftArm/OctArmWrap-v2 --agents sac sac_batched \
        --hyperparams-dir baselines/hyperparams/batched_gsde \
        --batched-hyperparams-dir baselines/hyperparams/batched_gsde --target 0.7

Torch runs on one thread, numba's parallel loops on ``--numba-threads`` (default 1: on a
shared two-core machine a second thread mostly waits for a core; see docs/baselines.md).
"""

from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from baselines.config import HYPERPARAMS_DIR, check_env_id, load_hyperparams, split_hyperparams
from baselines.train import build
from softarm_gym.files import write_json

__all__ = ["AGENTS", "race", "run", "episode_ends", "success_rate", "format_table", "plot", "main"]

AGENTS = {"sac": ("sac", False), "ppo": ("ppo", False),
          "sac_batched": ("sac", True), "ppo_batched": ("ppo", True)}
"""Agent name → (algorithm, on the batched env)."""
EVAL_EPISODES = 100
CONFIRM_SEED = 1000


def episode_ends(act, env, seed: int, keys=("is_success",)) -> dict[str, np.ndarray]:
    """``info[key]`` at the last step of one episode per copy of the batched ``env`` (copy i
    seeded ``seed + i``) under ``act`` (observations (n, D) → actions (n, k)), per key: arrays
    of shape (n,) (e.g. ``is_success``; ``distance``, m, on reach)."""
    obs, _ = env.reset(seed=seed)
    done = np.zeros(env.num_envs, dtype=bool)
    last = {}
    while not done.all():
        obs, _, terminated, truncated, info = env.step(act(obs))
        ending = (terminated | truncated) & ~done  # NEXT_STEP: a copy's first ending is its episode's
        for key in keys:
            last.setdefault(key, np.zeros(env.num_envs, dtype=np.asarray(info[key]).dtype))[ending] = \
                np.asarray(info[key])[ending]
        done |= ending
    return last


def success_rate(model, env, seed: int) -> float:
    """Fraction of the episodes of :func:`episode_ends` that ``model`` (deterministic, on
    observations normalised with its training statistics) ends with ``is_success``."""
    vecnorm = model.get_vec_normalize_env()

    def act(obs):
        return model.predict(obs if vecnorm is None else vecnorm.normalize_obs(obs), deterministic=True)[0]

    return float(np.mean(episode_ends(act, env, seed)["is_success"]))


class _Race(BaseCallback):
    """Evaluates every ``every_s`` seconds of training (the clock stopped meanwhile); stops at
    the target or when the budget is spent."""

    def __init__(self, evaluate, every_s: float, budget_s: float, target: float, report):
        super().__init__()
        self._evaluate, self._every, self._budget, self._target = evaluate, every_s, budget_s, target
        self._report = report
        self.history: list[dict] = []
        self.reached: dict | None = None

    def _on_training_start(self) -> None:
        self._wall0, self._cpu0 = time.perf_counter(), time.process_time()
        self._paused_wall = self._paused_cpu = 0.0
        self._next = self._every

    def _on_step(self) -> bool:
        wall = time.perf_counter() - self._wall0 - self._paused_wall
        if wall < self._next and wall < self._budget:
            return True
        cpu = time.process_time() - self._cpu0 - self._paused_cpu
        pause_wall, pause_cpu = time.perf_counter(), time.process_time()
        point = {"train_wall_s": wall, "train_cpu_s": cpu, "steps": int(self.num_timesteps),
                 "success": self._evaluate(self.model), "load_1min": os.getloadavg()[0]}
        self.history.append(point)
        self._report(point)
        self._paused_wall += time.perf_counter() - pause_wall
        self._paused_cpu += time.process_time() - pause_cpu
        self._next = wall + self._every
        if point["success"] >= self._target:
            self.reached = point
            return False
        return wall < self._budget


def race(env_id: str, agent: str, seed: int, *, target: float = 0.9, budget_min: float = 20.0,
         eval_every_s: float = 15.0, hyperparams_dir: Path | str = HYPERPARAMS_DIR,
         batched_hyperparams_dir: Path | str | None = None, progress=None) -> dict:
    """Train ``agent`` (a key of :data:`AGENTS`) from scratch until ``target`` or the budget, with
    the settings of ``hyperparams_dir`` (single envs) or ``batched_hyperparams_dir`` (batched;
    None: ``hyperparams_dir/batched``).

    Returns:
        The run's record (module docstring): ``reached``, ``time_to_target_s``,
        ``cpu_to_target_s``, ``steps_to_target``, ``confirm_success``, ``history``, ...
    """
    algo, batched = AGENTS[agent]
    if batched:
        directory = Path(hyperparams_dir) / "batched" if batched_hyperparams_dir is None \
            else Path(batched_hyperparams_dir)
    else:
        directory = Path(hyperparams_dir)
    params = load_hyperparams(algo, env_id, directory)
    special, _ = split_hyperparams(params)
    env_kwargs = dict(special.get("env_kwargs", {}))
    evaluation = gym.make_vec(env_id, num_envs=EVAL_EPISODES, vectorization_mode="vector_entry_point",
                              **env_kwargs)
    model, venv = build(env_id, algo, params, seed, batched=batched)

    def report(point):
        if progress:
            progress(f"{agent} seed {seed}: {point['train_wall_s'] / 60:.1f} min, {point['steps']:,} steps, "
                     f"{100 * point['success']:.0f} % (load {point['load_1min']:.1f})")

    clock = _Race(lambda m: success_rate(m, evaluation, 0), eval_every_s, 60.0 * budget_min, target, report)
    try:
        model.learn(total_timesteps=10**9, callback=clock)
        confirm = success_rate(model, evaluation, CONFIRM_SEED) if clock.reached else None
    finally:
        venv.close()
        evaluation.close()
    hit = clock.reached
    last = clock.history[-1] if clock.history else {"train_wall_s": 0.0, "train_cpu_s": 0.0, "steps": 0}
    return {"agent": agent, "algo": algo, "batched": batched, "n_envs": int(special.get("n_envs", 1)),
            "seed": seed, "hyperparams_file": str(directory / f"{algo}.yml"), "hyperparams": params,
            "reached": hit is not None,
            "time_to_target_s": hit and hit["train_wall_s"], "cpu_to_target_s": hit and hit["train_cpu_s"],
            "steps_to_target": hit and hit["steps"], "confirm_success": confirm,
            "trained_wall_s": last["train_wall_s"], "trained_cpu_s": last["train_cpu_s"],
            "trained_steps": last["steps"], "history": clock.history}


def _best(runs: list[dict], batched: bool, budget_s: float) -> dict | None:
    """The agent of that kind with the lowest median time over its seeds (budget if not reached)."""
    by_agent = {}
    for r in runs:
        if r["batched"] == batched:
            by_agent.setdefault(r["agent"], []).append(r)
    scored = []
    for agent, rs in by_agent.items():
        times = [r["time_to_target_s"] if r["reached"] else budget_s for r in rs]
        cpu = [r["cpu_to_target_s"] if r["reached"] else r["trained_cpu_s"] for r in rs]
        scored.append({"agent": agent, "median_time_s": statistics.median(times),
                       "median_cpu_s": statistics.median(cpu), "all_reached": all(r["reached"] for r in rs),
                       "seeds": len(rs)})
    return min(scored, key=lambda s: s["median_time_s"]) if scored else None


def run(env_id: str, agents=tuple(AGENTS), seeds=(0,), *, target: float = 0.9, budget_min: float = 20.0,
        eval_every_s: float = 15.0, numba_threads: int = 1, hyperparams_dir: Path | str = HYPERPARAMS_DIR,
        batched_hyperparams_dir: Path | str | None = None, speedup_goal: float | None = None,
        progress=None) -> dict:
    """Race every agent for every seed (seed-major order); the result of the module docstring,
    with ``speedup_goal`` (the wall-time ratio asked for, or None) for the table's verdict."""
    import numba
    import stable_baselines3
    import torch

    check_env_id(env_id)
    unknown = sorted(set(agents) - set(AGENTS))
    if unknown:
        raise ValueError(f"unknown agent(s) {', '.join(unknown)}; choose from {', '.join(AGENTS)}")
    if not 0 < target <= 1:
        raise ValueError(f"target must lie in (0, 1]; got {target}")
    if not budget_min > 0 or not eval_every_s > 0:
        raise ValueError("budget_min and eval_every_s must be > 0")
    torch_threads, numba_threads_before = torch.get_num_threads(), numba.get_num_threads()
    torch.set_num_threads(1)
    numba.set_num_threads(numba_threads)
    start = time.perf_counter()
    load_before = os.getloadavg()
    try:
        runs = [race(env_id, agent, seed, target=target, budget_min=budget_min, eval_every_s=eval_every_s,
                     hyperparams_dir=hyperparams_dir, batched_hyperparams_dir=batched_hyperparams_dir,
                     progress=progress)
                for seed in seeds for agent in agents]
    finally:  # the caller's thread counts, as found (a caller's later work is not pinned to one)
        torch.set_num_threads(torch_threads)
        numba.set_num_threads(numba_threads_before)
    budget_s = 60.0 * budget_min
    single, batched = _best(runs, False, budget_s), _best(runs, True, budget_s)
    both = single is not None and batched is not None
    speedup = single["median_time_s"] / batched["median_time_s"] if both else None
    speedup_cpu = single["median_cpu_s"] / batched["median_cpu_s"] if both else None
    return {"env_id": env_id, "target": target, "eval_episodes": EVAL_EPISODES, "eval_every_s": eval_every_s,
            "budget_min": budget_min, "seeds": list(seeds), "agents": list(agents),
            "date": datetime.date.today().isoformat(), "total_wall_s": time.perf_counter() - start,
            "machine": {"cpus": os.cpu_count(), "load_before": list(load_before),
                        "load_after": list(os.getloadavg()), "torch_threads": 1,
                        "numba_threads": numba_threads},
            "versions": {"stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__,
                         "numba": numba.__version__},
            "runs": runs, "best_single": single, "best_batched": batched, "speedup": speedup,
            "speedup_cpu": speedup_cpu, "speedup_goal": speedup_goal,
            "speedup_is_lower_bound": bool(single and not single["all_reached"]),
            "batched_reached": bool(batched and batched["all_reached"])}


def format_table(result: dict) -> str:
    lines = [f"Wall time to {100 * result['target']:.0f} % success on {result['env_id']} "
             f"({result['eval_episodes']} deterministic episodes, evaluated every "
             f"{result['eval_every_s']:g} s of training):", "",
             "| agent | env | seed | time to target (min) | CPU (min) | steps | held-out success |",
             "|---|---|---|---|---|---|---|"]
    for r in result["runs"]:
        env = f"batched, {r['n_envs']} arms" if r["batched"] else f"DummyVecEnv, {r['n_envs']} env(s)"
        if r["reached"]:
            cells = (f"{r['time_to_target_s'] / 60:.2f}", f"{r['cpu_to_target_s'] / 60:.2f}",
                     f"{r['steps_to_target']:,}", f"{100 * r['confirm_success']:.0f} %")
        else:
            cells = (f"not in {r['trained_wall_s'] / 60:.1f}", f"{r['trained_cpu_s'] / 60:.2f}",
                     f"{r['trained_steps']:,}", "–")
        lines.append(f"| {r['agent']} | {env} | {r['seed']} | " + " | ".join(cells) + " |")
    if result["speedup"] is not None:
        bound = "≥ " if result["speedup_is_lower_bound"] else ""
        goal = result.get("speedup_goal")
        verdict = ""
        if goal is not None:
            met = result["speedup"] >= goal and result["batched_reached"]
            verdict = f" (goal ≥ {goal:g}× wall time: {'met' if met else 'NOT met'})"
        lines += ["", f"Best single-env agent {result['best_single']['agent']} / best batched agent "
                      f"{result['best_batched']['agent']}: {bound}{result['speedup']:.2f}× less wall time, "
                      f"{bound}{result['speedup_cpu']:.2f}× less CPU time{verdict}."]
    return "\n".join(lines)


def plot(result: dict, path: Path | str) -> None:
    """Success rate against training wall time, one line per run, the target dashed."""
    from softarm_gym.plotting import figure, save

    fig, ax = figure(figsize=(6.5, 4))
    for r in result["runs"]:
        minutes = [0.0] + [p["train_wall_s"] / 60 for p in r["history"]]
        rates = [0.0] + [100 * p["success"] for p in r["history"]]
        kind = f"batched, {r['n_envs']} arms" if r["batched"] else "single envs"
        label = f"{r['agent']} ({kind})"
        ax.plot(minutes, rates, "-" if r["batched"] else "--", marker="o", ms=3,
                label=label + (f", seed {r['seed']}" if len(result["seeds"]) > 1 else ""))
    ax.axhline(100 * result["target"], color="k", lw=0.8, ls=":")
    ax.set_xlabel("training wall time (min, evaluations excluded)")
    ax.set_ylabel(f"success over {result['eval_episodes']} episodes (%)")
    ax.set_title(f"{result['env_id']}: time to {100 * result['target']:.0f} % success")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    save(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.time_to_success",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="SoftArm/OctArmReach-v1")
    parser.add_argument("--agents", nargs="+", default=list(AGENTS), choices=list(AGENTS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--target", type=float, default=0.9, help="success rate to reach (default 0.9)")
    parser.add_argument("--budget-min", type=float, default=20.0, help="training minutes per agent and seed")
    parser.add_argument("--eval-every-s", type=float, default=15.0,
                        help="seconds of training between evaluations")
    parser.add_argument("--numba-threads", type=int, default=1)
    parser.add_argument("--hyperparams-dir", default=str(HYPERPARAMS_DIR),
                        help="settings of the single-env agents (default baselines/hyperparams)")
    parser.add_argument("--batched-hyperparams-dir", default=None,
                        help="settings of the batched agents (default: --hyperparams-dir's batched/)")
    parser.add_argument("--speedup-goal", type=float, default=None,
                        help="wall-time ratio single/batched asked for (the table says whether it is met)")
    parser.add_argument("--json", default=None, help="write the result to this JSON file")
    parser.add_argument("--plot", default=None, help="write the success-against-time plot to this image")
    args = parser.parse_args(argv)
    for out in (args.json, args.plot):
        if out and not Path(out).resolve().parent.is_dir():
            print(f"baselines.time_to_success: error: no folder for {out}", file=sys.stderr)
            return 2

    def progress(message):
        print(f"[time_to_success] {message}", file=sys.stderr, flush=True)

    try:
        result = run(args.env, args.agents, args.seeds, target=args.target, budget_min=args.budget_min,
                     eval_every_s=args.eval_every_s, numba_threads=args.numba_threads,
                     hyperparams_dir=args.hyperparams_dir,
                     batched_hyperparams_dir=args.batched_hyperparams_dir, speedup_goal=args.speedup_goal,
                     progress=progress)
    except ValueError as exc:
        print(f"baselines.time_to_success: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        write_json(args.json, result)
    if args.plot:
        plot(result, args.plot)
    print(format_table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
