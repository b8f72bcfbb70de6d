"""The sampling-based planner (:class:`softarm_gym.controllers.CEMPlanner`) on every registered ID.

Each ID runs ``episodes`` full episodes of ``gym.make(env_id)`` with the registered defaults,
episode i seeded with ``first_seed`` + i (default 0), the planner seeded with the same.
Reported per ID: the success rate (``is_success`` at the last step), the median final
distance (reach, m), RMS tracking error (track, m) or wrap angle (wrap and grasp, deg), the median step
at which an episode first succeeds (how sequential the task is), the median wall time per
episode and per decision that searched (held decisions cost almost nothing)::

    python -m softarm_gym.benchmarks.planner --episodes 20 --json
    python -m softarm_gym.benchmarks.planner --ids SoftArm/CTWrap-v1 --episodes 100 --first-seed 100
    python -m softarm_gym.benchmarks.planner --ids SoftArm/OctArmWrap-v1 --env-kwargs '{"self_contact": true}'
    python -m softarm_gym.benchmarks.planner --ids SoftArm/OctArmWrap-v2,SoftArm/CTWrap-v2 --episodes 1 \
        --picture docs/environments/wrap_v2_sequence.png

``--picture`` draws each ID's first episode (seed ``first_seed``) as a filmstrip: the start,
frames along the way and the last step, with the step, wrap or distance and success under each.

The JSON records its command; the rows of docs/bench/planner.json come from several such runs,
each with its own.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import softarm_gym  # noqa: F401  (registers the IDs)
from softarm_gym.benchmarks.envs import env_ids
from softarm_gym.controllers import CEMPlanner

__all__ = ["episode", "run", "picture", "main"]


def episode(env_id: str, seed: int, env_kwargs: dict | None = None, frames: list | None = None,
            **planner_kwargs) -> dict:
    """One planned episode of ``gym.make(env_id, **env_kwargs)`` seeded with ``seed``.

    Args:
        frames: if a list, each step's (step, rendered frame, info) is appended to it (the env
            is made with ``render_mode="rgb_array"``).

    Returns:
        ``success``, ``measure`` (reach: final distance, m; track: RMS tracking error over
        the episode, m; wrap: wrap angle, deg), ``seconds``,
        ``decision_seconds`` (median time of the decisions that searched; None if none did),
        ``first_success_step`` (the first step whose info reports success; None if none).
    """
    kwargs = dict(env_kwargs or {})
    if frames is not None:
        kwargs["render_mode"] = "rgb_array"
    env = gym.make(env_id, **kwargs)
    planner = CEMPlanner(env, seed=seed, **planner_kwargs)
    obs, info = env.reset(seed=seed)
    if frames is not None:
        frames.append((0, env.render(), info))
    start = time.perf_counter()
    searched = []
    done = False
    steps, first_success = 0, None
    while not done:
        t = time.perf_counter()
        action = planner.act(obs)
        spent = time.perf_counter() - t
        if planner.last_searched:
            searched.append(spent)
        obs, _, terminated, truncated, info = env.step(action)
        steps += 1
        if first_success is None and info["is_success"]:
            first_success = steps
        if frames is not None:
            frames.append((steps, env.render(), info))
        done = terminated or truncated
    seconds = time.perf_counter() - start
    env.close()
    key = next(k for k in ("wrap_angle_deg", "tracking_rms_m", "distance") if k in info)
    measure = info[key]
    return {"success": bool(info["is_success"]), "measure": float(measure), "seconds": seconds,
            "decision_seconds": float(np.median(searched)) if searched else None,
            "first_success_step": first_success}


def picture(ids, path, seed: int = 0, env_kwargs: dict | None = None, n_frames: int = 5) -> None:
    """A filmstrip per ID (one row each) of the planner's episode seeded with ``seed``: the
    start, frames evenly spaced up to the first success (or the end), and the last step, each
    captioned with its step, wrap angle (deg) or tip distance (mm) and success."""
    from softarm_gym.plotting import figure, save

    rows = []
    for env_id in ids:
        frames: list = []
        episode(env_id, seed, env_kwargs, frames=frames)
        end = next((k for k, (_, _, info) in enumerate(frames) if info["is_success"]), len(frames) - 1)
        picks = sorted({*np.linspace(0, end, n_frames - 1).round().astype(int).tolist(), len(frames) - 1})
        rows.append((env_id, [frames[k] for k in picks]))
    columns = max(len(picked) for _, picked in rows)
    fig, axes = figure(len(rows), columns, figsize=(2.4 * columns, 2.6 * len(rows)), squeeze=False)
    for r, (env_id, picked) in enumerate(rows):
        for c, ax in enumerate(axes[r]):
            ax.set_axis_off()
            if c >= len(picked):
                continue
            step, image, info = picked[c]
            ax.imshow(image)
            measure = f"wrap {info['wrap_angle_deg']:.0f}°" if "wrap_angle_deg" in info else \
                f"{1000 * info['distance']:.0f} mm"
            ax.set_title(f"step {step}: {measure}" + (", success" if info["is_success"] else ""), fontsize=8)
        axes[r][0].text(-0.05, 0.5, env_id.removeprefix("SoftArm/"), rotation=90, va="center", ha="right",
                        transform=axes[r][0].transAxes, fontsize=9)
    save(fig, path)


def run(ids=None, episodes: int = 20, progress: bool = True, first_seed: int = 0,
        env_kwargs: dict | None = None, **planner_kwargs) -> dict:
    """The planner's figures for ``ids`` (default: every registered ID), seeds ``first_seed``
    to ``first_seed + episodes - 1``, on ``gym.make(env_id, **env_kwargs)``."""
    command = "python -m softarm_gym.benchmarks.planner"
    if ids:
        command += f" --ids {','.join(ids)}"
    command += f" --episodes {episodes}" + (f" --first-seed {first_seed}" if first_seed else "")
    if env_kwargs:
        command += f" --env-kwargs '{json.dumps(env_kwargs)}'"
    command += " --json"
    result = {"command": command, "episodes": episodes, "first_seed": first_seed,
              "env_kwargs": env_kwargs or {}, "planner": planner_kwargs or "defaults", "ids": {}}
    seeds = range(first_seed, first_seed + episodes)
    for env_id in ids or env_ids():
        rows = [episode(env_id, seed, env_kwargs, **planner_kwargs)
                for seed in tqdm(seeds, desc=env_id, disable=not progress, file=sys.stderr)]
        firsts = [r["first_success_step"] for r in rows if r["first_success_step"] is not None]
        measure = ("median_wrap_deg" if "Wrap" in env_id or "Grasp" in env_id else
                   "median_tracking_rms_m" if "Track" in env_id else "median_final_distance_m")
        result["ids"][env_id] = {
            "success_rate": float(np.mean([r["success"] for r in rows])),
            measure: float(np.median([r["measure"] for r in rows])),
            "median_episode_s": float(np.median([r["seconds"] for r in rows])),
            "median_decision_s": float(np.median([r["decision_seconds"] for r in rows
                                                  if r["decision_seconds"] is not None] or [0.0])),
            "median_steps_to_success": float(np.median(firsts)) if firsts else None,
            "episodes": rows,
        }
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20, help="episodes per ID (default 20)")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="seed of the first episode (default 0; episode i: first seed + i)")
    parser.add_argument("--ids", default=None, help="comma-separated IDs (default: all registered)")
    parser.add_argument("--env-kwargs", default=None, metavar="JSON",
                        help='keyword arguments of gym.make, e.g. \'{"self_contact": true}\'')
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    parser.add_argument("--picture", default=None, metavar="PNG",
                        help="draw each ID's episode seeded --first-seed as a filmstrip to this file "
                             "instead of measuring")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    if args.first_seed < 0:
        parser.error("--first-seed must be >= 0")
    env_kwargs = None
    if args.env_kwargs:
        try:
            env_kwargs = json.loads(args.env_kwargs)
        except json.JSONDecodeError as exc:
            parser.error(f"--env-kwargs is not JSON: {exc}")
        if not isinstance(env_kwargs, dict):
            parser.error("--env-kwargs must be a JSON object")
    if args.picture:
        if not args.ids:
            parser.error("--picture needs --ids")
        picture(args.ids.split(","), args.picture, args.first_seed, env_kwargs)
        print(f"wrote {args.picture}")
        return 0
    result = run(args.ids.split(",") if args.ids else None, args.episodes, not args.no_progress,
                 args.first_seed, env_kwargs)
    if args.json:
        print(json.dumps(result, indent=2, allow_nan=False))
        return 0
    print(f"{'environment':24s} {'success':>8s} {'median':>12s} {'s/episode':>10s} {'ms/decision':>12s}")
    for env_id, row in result["ids"].items():
        median = next(row[key] for key in ("median_wrap_deg", "median_tracking_rms_m",
                                           "median_final_distance_m") if key in row)
        unit = "deg" if "median_wrap_deg" in row else "m"
        print(f"{env_id:24s} {row['success_rate']:8.0%} {median:9.3f} {unit:3s}"
              f"{row['median_episode_s']:10.2f} {1000 * row['median_decision_s']:12.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
