"""The general path's steps, captured from seeded episodes and replayed side by side with an
earlier commit.

A contact env's steps mostly take a stepper's lean paths; the few its lean paths refuse (snaps,
mostly) go to the general path and cost tens to hundreds of times as much. Their share of an
episode's time is too small and too noisy to resolve a change to them at the env level on a
shared machine, so they are measured on their own:

* ``capture`` takes seeded random-action steps (``gym.make``, reset with the seed and the
  action space seeded with it; a new episode, unseeded, where one ends) and keeps, for every
  step whose ``Stepper.last_path`` was ``"general"``, the env's stepper as it stood before the
  step (pickled) and the step's pressures (``--path`` keeps another path's steps instead, e.g.
  ``"lean contact"``; ``--whole-env`` keeps every step as the whole env before it and its
  action — a grasp env's steps settle arm and object outside the stepper — and ``--expert
  curl`` acts with the scripted curl instead of random actions, to hold objects);
* ``replay`` steps each kept stepper (or env) again, in this tree and in ``--before`` (a checkout of the
  commit before), alternately in fresh processes (:func:`softarm_gym.benchmarks.side_by_side.in_tree`),
  and reports per step its milliseconds (median over rounds), ``StepReport.iterations``,
  flags and tip, and where the two trees' landings differ::

    python -m softarm_gym.benchmarks.general_steps capture --ids SoftArm/OctArmWrap3D-v0 \\
        --seeds 0-5 --steps 300 --out steps.pkl
    python -m softarm_gym.benchmarks.general_steps replay steps.pkl --before PATH --rounds 3 \\
        --json OUT.json
    python -m softarm_gym.benchmarks.general_steps capture --ids SoftArm/OctArmGrasp-v1 \\
        --seeds 0-1 --steps 100 --whole-env --expert curl --out grasp.pkl

The capture file holds pickles: replay only files you made (unpickling runs code). Both trees
must unpickle this tree's steppers or envs (the classes' state unchanged between them). This file also
runs inside the other tree's interpreter (``--worker``): its module level imports nothing from
``softarm_gym``.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXPERTS = ("random", "curl")


def capture(env_ids, seeds, n_steps: int, progress=None, path: str = "general",
            whole_env: bool = False, expert: str = "random") -> list[dict]:
    """The steps that took ``path`` (a ``Stepper.last_path``: by default the general path's; e.g.
    ``"lean contact"``) among ``n_steps`` seeded steps per seed and id (a new episode where one
    ends): per such step its ``id``, ``seed``, ``step`` (index from the seeded reset),
    ``stepper`` (pickled, as it stood before the step) and ``pressures`` (the step's inputs, Pa).

    With ``whole_env`` every step is kept as the env before it (``env``, pickled) and its
    ``action``, whatever path it took: a grasp env's steps settle the arm and its object
    (:func:`solver.grasp.settle`) outside the stepper. The actions are random (the action
    space seeded with the seed) or, with ``expert="curl"``, the scripted
    :class:`~softarm_gym.controllers.CurlController`'s (wrap and grasp envs), which holds the
    objects a random walk of the pressures rarely does."""
    import gymnasium as gym

    import softarm_gym  # noqa: F401  (registers the ids)
    from softarm_gym.controllers import CurlController

    if expert not in EXPERTS:
        raise ValueError(f"unknown expert {expert!r}; choose one of {', '.join(EXPERTS)}")
    kept = []
    for env_id in env_ids:
        env = gym.make(env_id)
        curl = CurlController(env) if expert == "curl" else None
        for seed in seeds:
            obs, _ = env.reset(seed=seed)
            env.action_space.seed(seed)
            if curl is not None:
                curl.reset()
            for step in range(n_steps):
                action = env.action_space.sample() if curl is None else curl.act(obs)
                before = pickle.dumps(env.unwrapped if whole_env else env.unwrapped.stepper)
                obs, _, terminated, truncated, _ = env.step(action)
                if whole_env:
                    kept.append({"id": env_id, "seed": seed, "step": step, "env": before,
                                 "action": action})
                elif env.unwrapped.stepper.last_path == path:
                    kept.append({"id": env_id, "seed": seed, "step": step, "stepper": before,
                                 "pressures": env.unwrapped.stepper.pressures.copy()})
                if terminated or truncated:
                    obs, _ = env.reset()
                    if curl is not None:
                        curl.reset()
            if progress:
                progress(f"{env_id} seed {seed}: {len(kept)} {'env' if whole_env else path} steps so far")
        env.close()
    return kept


def _stepper_step(kept: dict) -> tuple[float, dict]:
    """A kept stepper step taken again: its seconds and a row of :func:`replay`'s."""
    stepper = pickle.loads(kept["stepper"])
    start = time.perf_counter()
    report = stepper.step(kept["pressures"])
    seconds = time.perf_counter() - start
    eq = stepper.equilibrium
    return seconds, {"iterations": int(report.iterations), "converged": bool(report.converged),
                     "stable": bool(eq.stable), "snapped": bool(eq.snapped),
                     "path": stepper.last_path, "tip": [float(x) for x in eq.tip]}


def _env_step(kept: dict) -> tuple[float, dict]:
    """A kept env step taken again: its seconds and a row of :func:`replay`'s (the tip, and a
    grasp's object centre after it, as its ``tip``)."""
    env = pickle.loads(kept["env"])
    start = time.perf_counter()
    info = env.step(kept["action"])[4]
    seconds = time.perf_counter() - start
    report = info["solver"]
    return seconds, {"iterations": int(report["iterations"]), "converged": bool(report["converged"]),
                     "stable": bool(report["stable"]), "snapped": bool(report["snapped"]),
                     "path": "env",
                     "tip": [float(x) for x in (*info["tip_true"], *info.get("object_center", ()))]}


def replay(steps: list[dict]) -> dict:
    """Each captured step taken again from its pickled stepper (or env): per step ``ms``,
    ``iterations``, ``converged``, ``stable``, ``snapped``, ``path`` and ``tip`` (m); and
    ``module`` (where ``softarm_gym`` came from)."""
    import softarm_gym

    rows = []
    for kept in steps:
        seconds, row = (_env_step if "env" in kept else _stepper_step)(kept)
        rows.append({"case": f"{kept['id']} seed {kept['seed']} step {kept['step']}",
                     "ms": 1e3 * seconds, **row})
    return {"rows": rows, "module": softarm_gym.__file__}


def run(capture_file: Path, before: Path, rounds: int = 3, progress=None) -> dict:
    """:func:`replay` of ``capture_file`` in this tree (``after``) and ``before``, rounds
    alternating (this tree first in even rounds). Returns per step the median ms of each tree,
    both trees' iterations, flags and the largest difference between their tips (m); totals."""
    from softarm_gym.benchmarks.side_by_side import commit_of, in_tree

    if rounds < 1:
        raise ValueError(f"rounds must be >= 1; got {rounds}")
    before = Path(before).resolve()
    if not (before / "softarm_gym" / "__init__.py").is_file():
        raise ValueError(f"--before {before} is not a softarm-gym checkout (no softarm_gym/__init__.py)")
    trees = {"after": ROOT, "before": before}
    job = {"capture": str(Path(capture_file).resolve())}
    runs = {side: [] for side in trees}
    for r in range(rounds):
        for side in (("after", "before") if r % 2 == 0 else ("before", "after")):
            runs[side].append(in_tree(trees[side], dict(job), None, script=Path(__file__))["rows"])
            if progress:
                progress(f"round {r + 1} of {rounds}: {side} done")
    rows = []
    for k, first in enumerate(runs["after"][0]):
        other = runs["before"][0][k]
        rows.append({"case": first["case"],
                     **{f"ms_{side}": statistics.median(run_[k]["ms"] for run_ in runs[side])
                        for side in trees},
                     **{f"{key}_{side}": runs[side][0][k][key] for side in trees
                        for key in ("iterations", "converged", "stable", "snapped")},
                     "tip_difference_m": max(abs(a - b) for a, b in zip(first["tip"], other["tip"]))})
    totals = {f"ms_{side}": sum(row[f"ms_{side}"] for row in rows) for side in trees}
    totals.update({f"iterations_{side}": sum(row[f"iterations_{side}"] for row in rows) for side in trees})
    totals["largest_tip_difference_m"] = max((row["tip_difference_m"] for row in rows), default=0.0)
    totals["same_flags"] = sum(all(row[f"{key}_after"] == row[f"{key}_before"]
                                   for key in ("converged", "stable", "snapped")) for row in rows)
    return {"after": commit_of(ROOT), "before": commit_of(before), "rounds": rounds,
            "steps": len(rows), "rows": rows, "totals": totals, "load": os.getloadavg()}


def format_table(result: dict) -> str:
    """The replay as a text table: one line per step, then the totals."""
    lines = [f"{'step':<46} {'ms before':>9} {'ms after':>9} {'its before':>10} {'its after':>9} "
             f"{'tip diff (m)':>12}"]
    for row in result["rows"]:
        lines.append(f"{row['case']:<46} {row['ms_before']:9.0f} {row['ms_after']:9.0f} "
                     f"{row['iterations_before']:10d} {row['iterations_after']:9d} "
                     f"{row['tip_difference_m']:12.1e}")
    t = result["totals"]
    lines.append(f"{'total':<46} {t['ms_before']:9.0f} {t['ms_after']:9.0f} "
                 f"{t['iterations_before']:10d} {t['iterations_after']:9d} "
                 f"{t['largest_tip_difference_m']:12.1e}")
    lines.append(f"same converged/stable/snapped flags on {t['same_flags']} of {result['steps']} steps")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m softarm_gym.benchmarks.general_steps",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    sub = parser.add_subparsers(dest="command")
    cap = sub.add_parser("capture", help="keep the general steps of seeded episodes")
    cap.add_argument("--ids", required=True, help="comma-separated env ids")
    cap.add_argument("--seeds", default="0-2", help="seeds: 0-5, 0,3,7 or 0-4,10 (default 0-2)")
    cap.add_argument("--steps", type=int, default=300, help="steps per seed (default 300)")
    cap.add_argument("--out", type=Path, required=True, help="the capture file (a pickle)")
    cap.add_argument("--path", default="general",
                     help="keep the steps of this Stepper.last_path (default general)")
    cap.add_argument("--whole-env", action="store_true",
                     help="keep every step as the env before it and its action (grasp envs' settles)")
    cap.add_argument("--expert", default="random", choices=EXPERTS,
                     help="who acts: random actions (default) or the scripted curl (wrap, grasp)")
    rep = sub.add_parser("replay", help="replay a capture here and in --before, side by side")
    rep.add_argument("capture", type=Path, help="a file written by capture")
    rep.add_argument("--before", type=Path, required=True, help="root of the other checkout")
    rep.add_argument("--rounds", type=int, default=3, help="alternating rounds (default 3)")
    rep.add_argument("--json", type=Path, default=None, help="also write the result to this file")
    args = parser.parse_args(argv)
    if args.worker:
        job = json.loads(sys.stdin.read())
        with open(job["capture"], "rb") as f:
            print(json.dumps(replay(pickle.load(f))))
        return 0
    say = lambda m: print(f"[general_steps] {m}", file=sys.stderr, flush=True)  # noqa: E731
    if args.command == "capture":
        if args.steps < 1:
            parser.error("--steps must be >= 1")
        from softarm_gym.commands.common import parse_seeds

        try:
            seeds = parse_seeds(args.seeds)
        except ValueError as exc:
            parser.error(str(exc))
        kept = capture(args.ids.split(","), seeds, args.steps, progress=say, path=args.path,
                       whole_env=args.whole_env, expert=args.expert)
        with open(args.out, "wb") as f:
            pickle.dump(kept, f)
        say(f"{len(kept)} {'env' if args.whole_env else args.path} steps written to {args.out}")
        return 0
    if args.command != "replay":
        parser.error("choose capture or replay")
    if not args.capture.is_file():
        parser.error(f"no capture file {args.capture}")
    try:
        result = run(args.capture, args.before, args.rounds, progress=say)
    except ValueError as exc:
        parser.error(str(exc))
    from softarm_gym.benchmarks.side_by_side import publish

    publish(result, f"python -m softarm_gym.benchmarks.general_steps replay {args.capture} "
            f"--before <checkout of the commit before> --rounds {args.rounds}"
            + (f" --json {args.json}" if args.json else ""), format_table, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
