"""Returns of the reference controllers on every registered ID, and the reward thresholds from them.

The reference controller of a reach, obstacle-reach or track ID is
:class:`softarm_gym.controllers.JacobianController` (damped least squares on the nominal model);
of a wrap ID the scripted :class:`softarm_gym.controllers.CurlController`. Each runs ``episodes``
full episodes of ``gym.make(env_id)`` with the registered defaults, episode i seeded with i, and
its undiscounted returns are recorded. The registered ``reward_threshold`` of each ID is
:func:`reward_threshold` of the mean return, or None where that mean is not positive (the
reference fails the task: no bar can be taken from it)::

    python -m softarm_gym.benchmarks.reference --episodes 20 --json > docs/bench/reference_returns.json

``--ids`` runs some IDs only (``--json`` then prints their rows, to merge into the record).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np
from tqdm import tqdm

import softarm_gym  # noqa: F401  (registers the IDs)
from softarm_gym.benchmarks.envs import env_ids
from softarm_gym.controllers import CurlController, JacobianController
from softarm_gym.registry import make

__all__ = ["THRESHOLD_FRACTION", "reward_threshold", "threshold_of", "reference_controller", "episode", "run",
           "main"]

THRESHOLD_FRACTION = 0.9
"""The threshold rule: this fraction of the reference's mean return (returns are positive)."""


def reward_threshold(mean_return: float) -> float:
    """The documented rule: ``floor(THRESHOLD_FRACTION · mean)`` of the reference's mean return.

    Raises:
        ValueError: a non-positive or non-finite mean (the rule is for positive returns).
    """
    if not (math.isfinite(mean_return) and mean_return > 0):
        raise ValueError(f"the threshold rule needs a positive mean return; got {mean_return!r}")
    return float(math.floor(THRESHOLD_FRACTION * mean_return))


def threshold_of(mean_return: float) -> float | None:
    """The registered ``reward_threshold`` for a reference mean return: :func:`reward_threshold`,
    or None for a mean that is not positive."""
    return reward_threshold(mean_return) if mean_return > 0 else None


def reference_controller(env):
    """The reference controller of ``env``'s task (reach, obstacle reach and track: Jacobian,
    wrap: scripted curl)."""
    if hasattr(env.unwrapped, "success_wrap_deg"):
        return CurlController(env)
    return JacobianController(env)


def episode(env_id: str, seed: int, env_kwargs: dict | None = None) -> dict:
    """One reference episode of ``gym.make(env_id, **env_kwargs)`` seeded with ``seed``.

    Returns:
        ``return`` (undiscounted), ``length``, ``success`` (``is_success`` of the last step).
    """
    env = make(env_id, quiet=True, **(env_kwargs or {}))
    controller = reference_controller(env)
    obs, _ = env.reset(seed=seed)
    controller.reset()
    total, length, done, info = 0.0, 0, False, {}
    while not done:
        obs, reward, terminated, truncated, info = env.step(controller.act(obs))
        total += float(reward)
        length += 1
        done = terminated or truncated
    env.close()
    return {"return": total, "length": length, "success": bool(info.get("is_success", False))}


def run(episodes: int = 20, ids=None, progress: bool = True) -> dict:
    """Reference returns of ``episodes`` seeded episodes (seeds 0 … episodes−1) per ID.

    Returns:
        A dict,

        ``{env_id: {"controller", "returns", "mean", "std", "success_rate", "mean_length",
        "threshold"}}``.
    """
    if isinstance(episodes, bool) or int(episodes) != episodes or episodes < 1:
        raise ValueError(f"episodes must be an integer >= 1; got {episodes!r}")
    result = {}
    for env_id in ids or env_ids():
        start = time.perf_counter()
        rows = [episode(env_id, seed) for seed in tqdm(range(int(episodes)), desc=env_id, file=sys.stderr,
                                                       disable=not progress, leave=False)]
        returns = np.array([r["return"] for r in rows])
        mean = float(returns.mean())
        result[env_id] = {
            "controller": type(reference_controller(make(env_id, quiet=True))).__name__,
            "returns": returns.tolist(), "mean": mean, "std": float(returns.std()),
            "success_rate": float(np.mean([r["success"] for r in rows])),
            "mean_length": float(np.mean([r["length"] for r in rows])),
            "threshold": threshold_of(mean), "seconds": time.perf_counter() - start}
    return result


def format_table(result: dict) -> str:
    """A Markdown table of :func:`run`'s result."""
    lines = ["| ID | reference | episodes | mean return ± std | success | registered threshold |",
             "|---|---|---|---|---|---|"]
    for env_id, row in result.items():
        lines.append(f"| `{env_id}` | `{row['controller']}` | {len(row['returns'])} | "
                     f"{row['mean']:.1f} ± {row['std']:.1f} | {100 * row['success_rate']:.0f} % | "
                     f"{'none' if row['threshold'] is None else format(row['threshold'], 'g')} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m softarm_gym.benchmarks.reference",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20, help="seeded episodes per ID (default 20)")
    parser.add_argument("--ids", default=None, help="comma-separated IDs (default: all registered)")
    parser.add_argument("--json", action="store_true", help="machine-readable output")
    args = parser.parse_args(argv)
    ids = args.ids.split(",") if args.ids else None
    unknown = [i for i in ids or () if i not in env_ids()]
    if unknown:
        print(f"reference: error: unknown ID(s) {', '.join(unknown)}; registered: {', '.join(env_ids())}",
              file=sys.stderr)
        return 2
    try:
        result = run(args.episodes, ids)
    except ValueError as exc:
        print(f"reference: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        selected = f" --ids {args.ids}" if args.ids else ""
        payload = {"command": f"python -m softarm_gym.benchmarks.reference --episodes {args.episodes}"
                              f"{selected} --json",
                   "date": time.strftime("%Y-%m-%d"),
                   "rule": f"reward_threshold = floor({THRESHOLD_FRACTION} * mean return of the reference "
                           f"controller over seeds 0-{args.episodes - 1})",
                   "ids": result}
        print(json.dumps(payload, indent=2))
    else:
        print(format_table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
