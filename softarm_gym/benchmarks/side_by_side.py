"""Contact speed against an earlier commit, side by side: the same measurement run alternately
on this tree and on another checkout (a ``git worktree`` of the commit before), each in fresh
subprocesses, so that both see the same machine load.

Two measurements, each using only public names that both trees have (``gym.make`` and
:class:`softarm_gym.controllers.CEMPlanner`):

* ``ratios`` — single-env steps/s under seeded random actions (``true`` observations, resets
  when an episode ends) of the contact cases (default
  :data:`softarm_gym.benchmarks.envs.CONTACT_RATIO_CASES`, less the friction cases: a tree before
  friction has no `friction` kwarg), each as a multiple of its unit's
  step measured in the same process (a free ``OctArmReach-v1`` step; a 3D reach step for 3D
  wrap, :data:`~softarm_gym.benchmarks.envs.RATIO_UNITS`);
* ``planner`` — :class:`~softarm_gym.controllers.CEMPlanner` episodes (the same arguments on
  both trees, episode and planner seeded alike): the seconds of each decision that searched
  (held decisions cost almost nothing), and each episode's success.

Rounds alternate the trees (this tree first in even rounds, the other first in odd ones);
every figure is a median over rounds (ratios: of the per-process ratios; decisions: of each
round's median decision)::

    python -m softarm_gym.benchmarks.side_by_side --before PATH --rounds 3 --json OUT.json

``PATH`` is the root of the other checkout (it compiles its own numba cache the first time).
This file also runs *inside* the other tree's interpreter (``--worker``, fed a job on stdin):
its module level therefore imports nothing from ``softarm_gym``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["PLANNER_IDS", "PLANNER_KWARGS", "PLANNER_SPEEDUP_TARGET", "time_ratio_cases", "plan_episodes",
           "run_worker", "in_tree", "run", "select_cases", "format_table", "main"]

PLANNER_IDS = ("SoftArm/OctArmWrap-v1", "SoftArm/OctArmObstacleReach-v0")
"""Envs the planner measurement plans on."""

PLANNER_KWARGS = {"samples": 32, "elites": 6, "iterations": 3, "horizon": 1}
"""The planner's arguments on both trees (its defaults, spelled out: the same sample count)."""

PLANNER_SPEEDUP_TARGET = 5.0
"""Issue target: a decision on OctArmWrap-v1 this many times faster than before, same samples."""

ROOT = Path(__file__).resolve().parents[2]


def _steps_per_s(env, n_steps: int, seed: int) -> float:
    """Steps per second of ``env`` over ``n_steps`` seeded random actions, resets included."""
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, (n_steps, *env.action_space.shape)).astype(np.float32)
    env.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return n_steps / (time.perf_counter() - start)


def time_ratio_cases(cases: list, n_steps: int, seed: int, units: dict) -> dict:
    """One round of the ratio measurement in this process.

    Args:
        cases: ``[name, env_id, kwargs]`` triples; every unit named in ``units`` among them.
        n_steps: timed steps per case (a unit case runs 3× as many, being faster).
        seed: seed of the random actions and resets.
        units: case name → the name of the case whose step is its unit (absent: the first case).

    Returns:
        ``{"steps_per_s": {name: rate}, "times_unit": {name: unit rate / rate}, "module": path}``.
    """
    import gymnasium as gym

    import softarm_gym

    unit_names = {cases[0][0], *units.values()}
    envs = [(name, gym.make(env_id, **kwargs)) for name, env_id, kwargs in cases]
    rates = {}
    for _, env in envs:
        _steps_per_s(env, 20, seed + 1000)  # warm-up: kernels, first resets
    for name, env in envs:
        rates[name] = _steps_per_s(env, 3 * n_steps if name in unit_names else n_steps, seed)
        env.close()
    ratios = {name: rates[units.get(name, cases[0][0])] / rate for name, rate in rates.items()}
    return {"steps_per_s": rates, "times_unit": ratios, "module": softarm_gym.__file__}


def plan_episodes(env_id: str, seeds: list, planner_kwargs: dict) -> dict:
    """Planned episodes of ``gym.make(env_id)``, episode and planner seeded with each seed,
    after one untimed decision on an episode seeded 10,000 (kernels loaded, caches built).

    Returns:
        dict: ``episodes``, one dict an episode (``seed``, ``success``, ``decision_seconds``:
        the seconds of each decision that searched, ``decisions``: all of them), and
        ``module``, the path of the ``softarm_gym`` that ran.
    """
    import gymnasium as gym

    import softarm_gym
    from softarm_gym.controllers import CEMPlanner

    env = gym.make(env_id)  # warm-up decision, untimed: loads the kernels, builds the design caches
    obs, _ = env.reset(seed=10_000)
    CEMPlanner(env, seed=10_000, **planner_kwargs).act(obs)
    env.close()
    episodes = []
    for seed in seeds:
        env = gym.make(env_id)
        planner = CEMPlanner(env, seed=seed, **planner_kwargs)
        obs, info = env.reset(seed=seed)
        searched, decisions, done = [], 0, False
        while not done:
            start = time.perf_counter()
            action = planner.act(obs)
            spent = time.perf_counter() - start
            decisions += 1
            if planner.last_searched:
                searched.append(spent)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        env.close()
        episodes.append({"seed": seed, "success": bool(info["is_success"]), "decision_seconds": searched,
                         "decisions": decisions})
    return {"episodes": episodes, "module": softarm_gym.__file__}


def run_worker(job: dict) -> dict:
    """Run one job (``{"kind": "ratios" | "planner", ...}``, the keyword arguments of
    :func:`time_ratio_cases` or :func:`plan_episodes`) in this process."""
    kind = job.pop("kind")
    if kind == "ratios":
        return time_ratio_cases(**job)
    if kind == "planner":
        return plan_episodes(**job)
    raise ValueError(f"unknown job kind {kind!r}; choose ratios or planner")


def in_tree(tree: Path, job: dict, numba_threads: int | None, script: Path | None = None) -> dict:
    """``job`` (:func:`run_worker`'s) run by this file (or by ``script``, another module of this
    tree with a ``--worker`` mode that reads a job on stdin and prints its result's JSON last) in
    a fresh interpreter that imports ``tree``'s packages (``PYTHONPATH=tree``, working directory
    ``tree``); its result, which names the ``module`` it imported ``softarm_gym`` from.

    Raises:
        RuntimeError: the job failed, or ``softarm_gym`` came from elsewhere than ``tree``.
    """
    env = dict(os.environ, PYTHONPATH=str(tree))
    if numba_threads:
        env["NUMBA_NUM_THREADS"] = str(numba_threads)
    code = ("import runpy, sys; sys.argv = ['side_by_side', '--worker']; "
            f"runpy.run_path({str(Path(script or __file__).resolve())!r}, run_name='__main__')")
    done = subprocess.run([sys.executable, "-c", code], input=json.dumps(job), cwd=tree, env=env,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the job failed in {tree}:\n{done.stderr[-3000:]}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if not result["module"].startswith(str(tree.resolve())):
        raise RuntimeError(f"the job in {tree} imported softarm_gym from {result['module']}")
    return result


def commit_of(tree: Path) -> str:
    """The last commit of the checkout at ``tree``: short hash and subject."""
    return subprocess.run(["git", "-C", str(tree), "log", "-1", "--format=%h %s"], capture_output=True,
                          text=True, check=True).stdout.strip()


def run(before: Path, rounds: int = 3, n_steps: int = 300, episodes: int = 3, cases=None,
        planner_ids=PLANNER_IDS, planner_kwargs=None, numba_threads: int | None = None,
        measure=("ratios", "planner"), progress=None) -> dict:
    """Both measurements on this tree (``after``) and on ``before``, rounds alternating.

    Args:
        before: root of the other checkout.
        rounds: rounds (each runs every job once per tree, in fresh processes).
        n_steps: timed steps per ratio case.
        episodes: planner episodes per ID and round (seeds 0 .. episodes − 1, every round).
        cases: ratio cases (default :data:`softarm_gym.benchmarks.envs.CONTACT_RATIO_CASES`
            without the friction cases).
        planner_ids, planner_kwargs: the planner's envs and arguments (default
            :data:`PLANNER_KWARGS`).
        numba_threads: NUMBA_NUM_THREADS of the subprocesses (None: numba's default).
        measure: which measurements to run.
        progress: optional callable taking a status string.

    Returns:
        dict: ``after`` and ``before`` (their commits), ``rounds``, ``numba_threads``, the
        load averages ``load_before`` and ``load_after``; ``ratios`` (``n_steps``, ``rows``:
        per case ``name``, ``env_id``, ``kwargs``, ``unit``, the median multiple of the unit
        step per tree as ``after`` and ``before``, every round's as ``runs_after`` and
        ``runs_before``, median steps/s as ``steps_per_s_after`` and ``steps_per_s_before``);
        ``planner`` (``kwargs``, ``seeds``, ``ids``: per ID and tree the median decision
        seconds, success rate and per-seed successes, every round's episodes, then
        ``speedup`` and ``same_success``).
    """
    from softarm_gym.benchmarks.envs import CONTACT_RATIO_CASES, RATIO_UNITS

    if rounds < 1 or n_steps < 1 or episodes < 1:
        raise ValueError(f"rounds, n_steps and episodes must be >= 1; got {rounds}, {n_steps}, {episodes}")
    before = Path(before).resolve()
    if not (before / "softarm_gym" / "__init__.py").is_file():
        raise ValueError(f"--before {before} is not a softarm-gym checkout (no softarm_gym/__init__.py)")
    trees = {"after": ROOT, "before": before}
    # Friction's cases are timed against their frictionless twins (envs.contact_ratios): a
    # tree before friction has no ``friction`` kwarg.
    cases = [list(c) for c in (cases or [c for c in CONTACT_RATIO_CASES if "friction" not in c[2]])]
    planner_kwargs = dict(planner_kwargs or PLANNER_KWARGS)
    seeds = list(range(episodes))
    out = {"after": commit_of(ROOT), "before": commit_of(before), "rounds": rounds,
           "numba_threads": numba_threads or "numba default", "load_before": os.getloadavg()}
    ratio_runs = {side: [] for side in trees}
    plan_runs = {side: {env_id: [] for env_id in planner_ids} for side in trees}
    for r in range(rounds):
        order = ("after", "before") if r % 2 == 0 else ("before", "after")
        for side in order:
            if "ratios" in measure:
                ratio_runs[side].append(in_tree(trees[side], {
                    "kind": "ratios", "cases": cases, "n_steps": n_steps, "seed": r,
                    "units": dict(RATIO_UNITS)}, numba_threads))
            if "planner" in measure:
                for env_id in planner_ids:
                    plan_runs[side][env_id].append(in_tree(trees[side], {
                        "kind": "planner", "env_id": env_id, "seeds": seeds,
                        "planner_kwargs": planner_kwargs}, numba_threads))
            if progress:
                progress(f"round {r + 1} of {rounds}: {side} done")
    out["load_after"] = os.getloadavg()
    if "ratios" in measure:
        rows = []
        for name, env_id, kwargs in cases:
            row = {"name": name, "env_id": env_id, "kwargs": kwargs,
                   "unit": RATIO_UNITS.get(name, cases[0][0])}
            for side in trees:
                row[f"runs_{side}"] = [run_["times_unit"][name] for run_ in ratio_runs[side]]
                row[side] = float(np.median(row[f"runs_{side}"]))
                row[f"steps_per_s_{side}"] = float(np.median([run_["steps_per_s"][name]
                                                               for run_ in ratio_runs[side]]))
            rows.append(row)
        out["ratios"] = {"n_steps": n_steps, "rows": rows}
    if "planner" in measure:
        out["planner"] = {"kwargs": planner_kwargs, "seeds": seeds, "ids": {}}
        for env_id in planner_ids:
            entry = {}
            for side in trees:
                per_round = [float(np.median([s for e in run_["episodes"] for s in e["decision_seconds"]]
                                             or [np.nan])) for run_ in plan_runs[side][env_id]]
                success = {str(seed): [e["success"] for run_ in plan_runs[side][env_id]
                                       for e in run_["episodes"] if e["seed"] == seed] for seed in seeds}
                entry[side] = {"median_decision_s": float(np.nanmedian(per_round)),
                               "runs_median_decision_s": per_round,
                               "success_rate": float(np.mean([s for v in success.values() for s in v])),
                               "success_by_seed": success,
                               "rounds": plan_runs[side][env_id]}
            entry["speedup"] = entry["before"]["median_decision_s"] / entry["after"]["median_decision_s"]
            entry["same_success"] = entry["before"]["success_by_seed"] == entry["after"]["success_by_seed"]
            out["planner"]["ids"][env_id] = entry
    return out


def format_table(result: dict) -> str:
    """Markdown tables of :func:`run`'s result."""
    lines = []
    if "ratios" in result:
        lines += ["| single env (random actions) | × unit step, before | × unit step, after | unit |",
                  "|---|---|---|---|"]
        for r in result["ratios"]["rows"]:
            lines.append(f"| {r['name']} | {r['before']:.1f} | {r['after']:.1f} | {r['unit']} |")
    if "planner" in result:
        lines += ["", "| CEMPlanner | decision before (ms) | after (ms) | speed-up | success before | "
                      "after | same per seed |", "|---|---|---|---|---|---|---|"]
        for env_id, e in result["planner"]["ids"].items():
            lines.append(f"| {env_id} | {1e3 * e['before']['median_decision_s']:.0f} | "
                         f"{1e3 * e['after']['median_decision_s']:.0f} | {e['speedup']:.1f}× | "
                         f"{e['before']['success_rate']:.0%} | {e['after']['success_rate']:.0%} | "
                         f"{'yes' if e['same_success'] else 'no'} |")
    return "\n".join(lines)


def select_cases(names) -> list:
    """The cases of :data:`softarm_gym.benchmarks.envs.CONTACT_RATIO_CASES` named in
    ``names``, after the unit cases they are timed against (the free reach first).

    Raises:
        ValueError: a name that is not a case's (the message lists them).
    """
    from softarm_gym.benchmarks.envs import CONTACT_RATIO_CASES, RATIO_UNITS

    by_name = {c[0]: c for c in CONTACT_RATIO_CASES}
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise ValueError(f"--cases: no case named {', '.join(map(repr, unknown))}; "
                         f"the cases are {', '.join(by_name)}")
    units = [CONTACT_RATIO_CASES[0][0], *(RATIO_UNITS[n] for n in names if n in RATIO_UNITS)]
    return [by_name[n] for n in dict.fromkeys([*units, *names])]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m softarm_gym.benchmarks.side_by_side",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--before", type=Path, help="root of the other checkout (the commit before)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (default 3)")
    parser.add_argument("--steps", type=int, default=300, help="timed steps per ratio case (default 300)")
    parser.add_argument("--episodes", type=int, default=3,
                        help="planner episodes per ID and round (default 3)")
    parser.add_argument("--only", choices=("ratios", "planner"), help="run one of the two measurements")
    parser.add_argument("--cases", default=None,
                        help="comma-separated ratio case names to time (with their unit cases; "
                             "default every frictionless case)")
    parser.add_argument("--numba-threads", type=int, default=None,
                        help="NUMBA_NUM_THREADS of the subprocesses")
    parser.add_argument("--json", type=Path, default=None, help="also write the result to this file")
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(run_worker(json.loads(sys.stdin.read()))))
        return 0
    if args.before is None:
        parser.error("--before is required")
    if min(args.rounds, args.steps, args.episodes) < 1:
        parser.error("--rounds, --steps and --episodes must be >= 1")
    if args.numba_threads is not None and args.numba_threads < 1:
        parser.error("--numba-threads must be >= 1")
    try:
        cases = select_cases(args.cases.split(",")) if args.cases else None
        result = run(args.before, args.rounds, args.steps, args.episodes, cases=cases,
                     numba_threads=args.numba_threads,
                     measure=(args.only,) if args.only else ("ratios", "planner"),
                     progress=lambda m: print(f"[side_by_side] {m}", file=sys.stderr, flush=True))
    except ValueError as exc:
        parser.error(str(exc))
    command = "python -m softarm_gym.benchmarks.side_by_side --before <checkout of the commit before>"
    command += f" --rounds {args.rounds} --steps {args.steps} --episodes {args.episodes}"
    command += (f" --only {args.only}" if args.only else "") + \
        (f" --cases {args.cases}" if args.cases else "") + \
        (f" --numba-threads {args.numba_threads}" if args.numba_threads else "")
    publish(result, command + (f" --json {args.json}" if args.json else ""), format_table, args.json)
    return 0


def publish(result: dict, command: str, table, path: Path | None) -> None:
    """Stamp ``result`` with the ``command`` that produced it and today's date, print
    ``table(result)`` and, given a ``path``, write the result there (strict JSON)."""
    from softarm_gym.files import write_json

    result["command"] = command
    result["date"] = time.strftime("%Y-%m-%d")
    print(table(result))
    if path:
        write_json(path, result)


if __name__ == "__main__":
    sys.exit(main())
