"""What limits the hanging OctArm V's 3D wrap: friction against the arm's own weight.

The scripted curl (:class:`softarm_gym.controllers.CurlController`: every channel pressed in
proportion to how far it bends the arm towards the cylinder, ramped to p_max in 10 steps) on
``SoftArm/OctArmWrap3D-v1`` (μ = 0.7, delta actions), seeds 0 … n−1, the wrap angle read
``STEPS`` steps in (the ramp and its settling). Two sweeps from the same pressures:

* ``friction``: μ at full gravity (does rubber stop the curl falling sideways off the cylinder?);
* ``gravity``: the arm's weight scaled (``gravity`` = fraction × 9.81 m/s²), with the registered
  μ and frictionless (how light, relative to its stiffness, must the arm be to wrap 270°?).

::

    python -m softarm_gym.benchmarks.wrap3d_limits --json > docs/bench/wrap3d_limits.json
    python -m softarm_gym.benchmarks.wrap3d_limits --from-json docs/bench/wrap3d_limits.json \\
        --picture docs/environments/wrap3d_limits.png

docs/environments.md, "3D wrap with friction (v1)", explains the result.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import softarm_gym  # noqa: F401  (registers the IDs)
from softarm_gym.controllers import CurlController

__all__ = ["ENV_ID", "STEPS", "FRICTIONS", "GRAVITY_FRACTIONS", "curl_wrap", "run", "format_table", "picture",
           "main"]

ENV_ID = "SoftArm/OctArmWrap3D-v1"
STEPS = 15
"""Steps of each curl: the ramp to full pressure takes 10, the wrap is settled by the 12th."""
FRICTIONS = (0.0, 0.7, 1.0, 2.0)
"""μ of the friction sweep (full gravity)."""
GRAVITY_FRACTIONS = (1.0, 0.75, 0.5, 0.375, 0.25, 0.0)
"""Fractions of 9.81 m/s² of the gravity sweep (μ = 0 and the registered 0.7)."""
_G = 9.81


def curl_wrap(seed: int, steps: int = STEPS, env_id: str = ENV_ID, **env_kwargs) -> float:
    """The wrap angle (deg) after ``steps`` steps of the scripted curl on ``gym.make(env_id,
    **env_kwargs)`` seeded with ``seed``.

    Raises:
        RuntimeError: a step did not converge (the wrap would then be the last converged state's).
    """
    env = gym.make(env_id, **env_kwargs)
    controller = CurlController(env)
    obs, _ = env.reset(seed=seed)
    controller.reset()
    for step in range(steps):
        obs, _, _, _, info = env.step(controller.act(obs))
        if not info["converged"]:
            raise RuntimeError(f"{env_id} {env_kwargs} seed {seed}: step {step + 1} did not converge")
    env.close()
    return float(info["wrap_angle_deg"])


def run(seeds: int = 8, progress: bool = True) -> dict:
    """Both sweeps over seeds 0 … ``seeds`` − 1.

    Returns:
        A dict with ``command``, ``date``, ``env_id``, ``steps``, ``seeds``, ``friction``
        (μ → the wraps (deg), one per seed) and ``gravity`` (μ of the registered id and 0 →
        fraction of g → the wraps); every μ and fraction a string key.
    """
    if isinstance(seeds, bool) or int(seeds) != seeds or seeds < 1:
        raise ValueError(f"seeds must be an integer >= 1; got {seeds!r}")
    seeds = int(seeds)
    registered = gym.spec(ENV_ID).kwargs["friction"]
    cases = [("friction", str(mu), None, {"friction": mu}) for mu in FRICTIONS]
    cases += [("gravity", str(mu), str(fraction), {"friction": mu, "gravity": fraction * _G})
              for mu in (registered, 0.0) for fraction in GRAVITY_FRACTIONS if fraction != 1.0]
    result = {"command": f"python -m softarm_gym.benchmarks.wrap3d_limits --seeds {seeds} --json",
              "date": datetime.date.today().isoformat(), "env_id": ENV_ID, "steps": STEPS,
              "seeds": seeds, "friction": {}, "gravity": {str(registered): {}, "0.0": {}}}
    bar = tqdm(total=len(cases) * seeds, desc="3D wrap limits", file=sys.stderr, disable=not progress)
    for sweep, mu, fraction, kwargs in cases:
        wraps = []
        for seed in range(seeds):
            wraps.append(curl_wrap(seed, **kwargs))
            bar.update()
        if sweep == "friction":
            result["friction"][mu] = wraps
        else:
            result["gravity"][mu][fraction] = wraps
    bar.close()
    for mu, wraps in result["friction"].items():  # full gravity belongs to both sweeps
        if mu in result["gravity"]:
            result["gravity"][mu]["1.0"] = wraps
    return result


def format_table(result: dict) -> str:
    """A Markdown table of both sweeps: per case the wraps of every seed, their median and how
    many reach 270°."""
    rows = [(mu, "1.0", wraps) for mu, wraps in result["friction"].items()]
    rows += [(mu, fraction, sweep[fraction]) for mu, sweep in result["gravity"].items()
             for fraction in sorted(sweep, key=float, reverse=True) if fraction != "1.0"]
    lines = [f"| μ | gravity | wrap, seeds 0–{result['seeds'] - 1} (deg) | median | ≥ 270° |",
             "|---|---|---|---|---|"]
    for mu, fraction, wraps in rows:
        lines.append(f"| {float(mu):g} | {float(fraction):g} g | {', '.join(f'{w:.0f}' for w in wraps)} "
                     f"| {np.median(wraps):.0f} | {sum(w >= 270.0 for w in wraps)} of {len(wraps)} |")
    return "\n".join(lines)


def picture(result: dict, path) -> None:
    """Two panels: the final wrap against μ at full gravity, and against the fraction of
    gravity (μ = 0.7 and 0), every seed a dot, the medians joined, 270° and 75° marked."""
    from softarm_gym.plotting import figure, save

    fig, (left, right) = figure(1, 2, figsize=(9.0, 3.6), sharey=True)
    for ax, rows, label in ((left, {"": result["friction"]}, "Coulomb μ (full gravity)"),
                            (right, result["gravity"], "gravity / 9.81 m/s²")):
        for mu, sweep in rows.items():
            x = np.array(sorted(sweep, key=float), dtype=object)
            values = [np.asarray(sweep[k]) for k in x]
            xs = np.array([float(k) for k in x])
            (line,) = ax.plot(xs, [np.median(v) for v in values], "-o",
                              label=f"median, μ = {mu}" if mu else "median")
            for xi, v in zip(xs, values):
                ax.scatter(np.full(v.size, xi), v, s=10, alpha=0.4, color=line.get_color())
        for level, name in ((270.0, "planar 270°"), (75.0, "v0/v1 success 75°")):
            ax.axhline(level, color="0.5", lw=0.8, ls="--")
            ax.text(ax.get_xlim()[0], level + 4, name, fontsize=7, color="0.3")
        ax.set_xlabel(label)
        ax.legend(fontsize=7, loc="center right")
    left.set_ylabel("wrap after the scripted curl (deg)")
    fig.suptitle(f"{result['env_id']}: scripted curl, seeds 0–{result['seeds'] - 1}", fontsize=9)
    save(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8, help="seeds 0 … N−1 (default 8)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--from-json", default=None, metavar="FILE", help="draw a result saved with --json")
    parser.add_argument("--picture", default=None, metavar="PNG", help="draw the two sweeps to this file")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1; got {args.seeds}")
    if args.from_json:
        with open(args.from_json) as f:
            result = json.load(f)
    else:
        result = run(args.seeds, progress=not args.no_progress)
    if args.picture:
        picture(result, args.picture)
    if args.json:
        print(json.dumps(result, indent=2))
    elif not args.picture or not args.from_json:
        print(format_table(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
