"""Where a contact step's time goes (``softarm bench --contact-profile``).

Each case is an env stepped as a user steps it (``gym.make``, seeded random actions, resets
when an episode ends), after a warm-up, in one process beside a free ``OctArmReach-v1``
step (the unit of the ratios), with the share of its time spent in resets (which solve the
episode's targets and placements). Two runs of the same seeded steps: a plain one for the
speed, and one under ``cProfile`` for the split of the time between

* ``lean kernels`` — the steppers' one-call paths (the guarded lean planar kernel, the lean
  contact kernel, their batch rows);
* ``continuation`` — the general path's quasi-static ramps (planar and spatial contact
  kernels, the free kernels' continuation);
* ``snap relaxation`` — energy minimisation where a path ends at a fold (L-BFGS, scipy);
* ``other kernels`` — every other numba kernel (grid checks, observations);
* ``solver Python`` and ``env Python`` — the rest, by where it runs.

The profiler inflates Python's share (it charges each Python call); the speed and the per-path
times come from the plain run. Per step: which path took it (``Stepper.last_path``), its time
by path, the median of its iterations by path (``StepReport.iterations``: a lean contact
step's passes; the general path's Newton iterations, continuation included), and for lean
contact steps the passes they made, with the cost of a residual pass and of a Jacobian pass at
a contact state and the share of RK4 rows refined near an obstacle (``Stepper.pass_costs``).
"""

from __future__ import annotations

import cProfile
import pstats
import time
from collections import Counter, defaultdict

import gymnasium as gym
import numpy as np

import softarm_gym  # noqa: F401  (registers the IDs)
import solver

CASES = (
    ("free reach", "SoftArm/OctArmReach-v1", {}),
    ("wrap, random", "SoftArm/OctArmWrap-v1", {}),
    ("wrap, delta", "SoftArm/OctArmWrap-v1", {"action_mode": "delta", "delta_scale": 0.1}),
    ("obstacle reach", "SoftArm/OctArmObstacleReach-v0", {}),
    ("grasp", "SoftArm/OctArmGrasp-v0", {}),
    ("reach, self-contact", "SoftArm/OctArmReach-v1", {"self_contact": True}),
    ("3D reach", "SoftArm/OctArmReach-v1", {"planar": False}),
    ("3D wrap", "SoftArm/OctArmWrap3D-v0", {}),
)
"""(name, id, kwargs) of the profiled cases; the first is the ratios' unit."""

CATEGORIES = ("lean kernels", "continuation", "snap relaxation", "other kernels", "solver Python",
              "env Python")

_CONTINUATION = ("follow", "newton")


def _category(filename: str, name: str) -> str:
    """The profile category of a function (module docstring)."""
    if "/solver/kernels/" in filename:
        if filename.endswith("stepping.py") or name in ("warm_step", "lean_step"):
            return "lean kernels"
        if filename.endswith("relax.py"):
            return "snap relaxation"
        if name in _CONTINUATION:
            return "continuation"
        return "other kernels"
    if "scipy/optimize" in filename:
        return "snap relaxation"
    if "/solver/" in filename:
        return "solver Python"
    return "env Python"


class _StepTimer:
    """Times every :meth:`solver.Stepper.step` of the process by the path it took."""

    def __init__(self):
        self.seconds = defaultdict(list)
        self.iterations = defaultdict(list)
        self.passes = []
        self._step = solver.Stepper.step

    def __enter__(self):
        timer, original = self, self._step

        def step(stepper, pressures):
            start = time.perf_counter()
            report = original(stepper, pressures)
            timer.seconds[stepper.last_path].append(time.perf_counter() - start)
            timer.iterations[stepper.last_path].append(report.iterations)
            if stepper.last_path == "lean contact":
                timer.passes.append(report.iterations)
            timer.last = stepper
            return report

        solver.Stepper.step = step
        return self

    def __exit__(self, *exc):
        solver.Stepper.step = self._step


def _run(env, actions) -> tuple[float, float]:
    """Seconds for ``actions`` (resets counted), and the seconds of the resets among them."""
    resets = 0.0
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            begin = time.perf_counter()
            env.reset()
            resets += time.perf_counter() - begin
    return time.perf_counter() - start, resets


def profile_case(env_id: str, kwargs: dict, steps: int, seed: int = 0) -> dict:
    """The profile of one case (module docstring): µs a step, paths, time by path and
    category, lean contact passes and pass costs."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps + steps // 5)]
    warm, timed = actions[:steps // 5], actions[steps // 5:]
    _run(env, warm)
    state = env.unwrapped
    env.reset(seed=seed + 1)
    with _StepTimer() as timer:
        seconds, reset_seconds = _run(env, timed)
    paths = {path: len(times) for path, times in timer.seconds.items()}
    by_path = {path: 1e6 * float(np.mean(times)) for path, times in timer.seconds.items()}
    env.reset(seed=seed + 1)
    profiler = cProfile.Profile()
    profiler.enable()
    _run(env, timed)
    profiler.disable()
    share = Counter()
    for (filename, _, name), (_, _, tottime, _, _) in pstats.Stats(profiler).stats.items():
        share[_category(filename, name)] += tottime
    total = sum(share.values()) or 1.0
    out = {
        "id": env_id, "kwargs": kwargs, "steps": len(timed), "us_per_step": 1e6 * seconds / len(timed),
        "reset_share": reset_seconds / seconds,
        "paths": paths, "us_per_step_by_path": by_path,
        "iterations_median_by_path": {path: float(np.median(n)) for path, n in timer.iterations.items()},
        "profile_share": {c: share[c] / total for c in CATEGORIES},
    }
    if timer.passes:
        out["lean_contact_passes_median"] = float(np.median(timer.passes))
        out["lean_contact_passes_mean"] = float(np.mean(timer.passes))
    stepper = state.stepper
    if stepper is not None and stepper.lean_contact:
        try:
            out["pass_costs"] = stepper.pass_costs()
        except ValueError:  # the last state lies off the contact layout
            pass
    env.close()
    return out


def run(steps: int = 300, quick: bool = False, progress=None) -> dict:
    """Every case of :data:`CASES` in this process; ratios to the first."""
    if quick:
        steps = min(steps, 60)
    cases = {}
    for name, env_id, kwargs in CASES:
        if progress is not None:
            progress(f"{name}: {env_id} {kwargs or ''}")
        cases[name] = profile_case(env_id, kwargs, steps)
    unit = cases[CASES[0][0]]["us_per_step"]
    for case in cases.values():
        case["ratio_to_free_step"] = case["us_per_step"] / unit
    return {"steps": steps, "cases": cases}


def format_table(result: dict) -> str:
    """Markdown tables of :func:`run`'s result: speed and paths, then where the time goes."""
    lines = ["| case | µs/step | × free step | resets | paths (steps) | µs by path | "
             "iterations by path (median) |",
             "|---|---|---|---|---|---|---|"]
    for name, case in result["cases"].items():
        paths = ", ".join(f"{p} {n}" for p, n in sorted(case["paths"].items()))
        by_path = ", ".join(f"{p} {us:.0f}" for p, us in sorted(case["us_per_step_by_path"].items()))
        iterations = ", ".join(f"{p} {n:g}" for p, n in sorted(case["iterations_median_by_path"].items()))
        lines.append(f"| {name} | {case['us_per_step']:.0f} | {case['ratio_to_free_step']:.1f} | "
                     f"{100 * case['reset_share']:.0f} % | {paths} | {by_path} | {iterations or '—'} |")
    lines += ["", "| case | " + " | ".join(CATEGORIES) + " | residual / Jacobian pass (µs), rows refined |",
              "|---|" + "---|" * (len(CATEGORIES) + 1)]
    for name, case in result["cases"].items():
        shares = " | ".join(f"{100 * case['profile_share'][c]:.0f} %" for c in CATEGORIES)
        costs = case.get("pass_costs")
        cost = f"{1e6 * costs['residual_pass_s']:.1f} / {1e6 * costs['jacobian_pass_s']:.1f}, " \
            f"{costs['refined_fraction']:.0%}" if costs else "—"
        lines.append(f"| {name} | {shares} | {cost} |")
    return "\n".join(lines)
