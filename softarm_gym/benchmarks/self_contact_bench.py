"""Self-contact solves of OctArm V: tip error against resolution and cost, side by side with
another checkout of the project (docs/design.md §9, "Self-contact").

For each scene (the curled middle pressing on the arm's base end, full curls with other
loads and stiffnesses, a curl round a disc): the tip at 16 and 32 RK4 steps per section
against a 64-step solve (error / L), the median time of a cold solve and of a warm step
(±0.5 % pressure steps about the scene's, in contact all along). Each tree is measured in
its own process through the public API alone (``solver.solve``), so an older checkout runs
the same code; the trees take turns (A, B, A, B, ...) and the medians over rounds are
reported with the ratio of each tree to the first. Timings swing twofold on a busy machine:
compare trees measured in one run, never runs with each other.

    python -m softarm_gym.benchmarks.self_contact_bench --against ../old-checkout \\
        --out docs/bench/self_contact.json

``--reach-cost`` instead times warm ``OctArmReach-v1`` steps with ``self_contact=True``
against without, side by side in one process (:func:`reach_cost`); ``--penetration`` the
sampled and peak penetration of contact scenes (:func:`penetration`); ``--self-friction``
the figures of friction in self-contact (:func:`self_friction_figures`, docs/design.md §9.1).
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

# name: (Scene keyword arguments, self-contact stiffness / ring stiffness, channel
# pressures in psi, channel I and II of sections 1–3).
SCENES = {
    "middle_on_base_end": ({"base_angle_deg": 13.44218070001563}, 1.0,
                           [90.96475894367777, 0, 90.79741275582431, 0, 89.03072383657893, 0]),
    "full_curl": ({}, 1.0, [100, 0, 100, 0, 100, 0]),
    "full_curl_payload": ({"payload_kg": 0.2}, 1.0, [100, 0, 100, 0, 100, 0]),
    "stiff_tubes": ({}, 10.0, [100, 0, 100, 0, 100, 0]),
    "tilted_mixed": ({"base_angle_deg": 30.0}, 3.0, [95, 0, 100, 0, 85, 0]),
    "round_a_disc": ({"disc": [-0.16, -0.062, 0.119 + 0.0302, 2e4]}, 1.0,
                     [100, 0, 100, 0, 100, 0]),
}


def measure(scenes: dict, accuracy: bool) -> dict:
    """Per scene: cold and warm times (ms) and, with ``accuracy``, the tip errors / L at 16 and
    32 steps per section against 64. Uses numpy and the public ``solver`` API only: it is
    run by its source in another checkout's process."""
    import time

    import numpy as np

    import solver

    arm = solver.designs.octarm_v()
    ring = min(t.material.ring_stiffness for t in arm.tubes)
    out = {}
    for name, (kw, factor, psi) in scenes.items():
        kw = dict(kw)
        disc = kw.pop("disc", None)
        if disc is not None:
            kw["obstacles"] = (solver.Disc((disc[0], disc[1]), disc[2], disc[3]),)
        scene = solver.Scene(self_contact=factor * ring, **kw)
        p = np.array(psi, dtype=float) * solver.PSI
        eq = solver.solve(arm, p, scene)
        cold = []
        for _ in range(5):
            start = time.perf_counter()
            eq = solver.solve(arm, p, scene)
            cold.append(time.perf_counter() - start)
        warm, state, touching = [], eq, 0
        for k in range(40):
            fraction = 1.0 - 0.005 * ((k % 4) + 1 if (k // 4) % 2 == 0 else 4 - k % 4)
            start = time.perf_counter()
            state = solver.solve(arm, fraction * p, scene, warm_start=state)
            warm.append(time.perf_counter() - start)
            touching += bool(state.in_contact and state.converged)
        row = {"cold_ms": 1e3 * float(np.median(cold)), "warm_ms": 1e3 * float(np.median(warm)),
               "warm_steps_in_contact": touching / 40, "converged": bool(eq.converged),
               "in_contact": bool(eq.in_contact)}
        if accuracy:
            tips = {n: solver.solve(arm, p, scene, settings=solver.Settings(steps_per_section=n)).tip
                    for n in (16, 32, 64)}
            for n in (16, 32):
                row[f"error_{n}"] = float(np.linalg.norm(tips[n] - tips[64]) / arm.length)
        out[name] = row
    return out


def reach_cost(rounds: int = 7, steps: int = 300) -> dict:
    """Warm ``OctArmReach-v1`` steps with ``self_contact=True`` against without, side by side
    in this process: both envs take the same seeded random actions in blocks of ``steps``,
    in turns, ``rounds`` times (after a warm-up block each). Returns the per-block µs per
    step of each and the ratio of their medians."""
    import gymnasium as gym

    import softarm_gym  # noqa: F401  (registers the ids)

    envs = {on: gym.make("SoftArm/OctArmReach-v1", self_contact=on) for on in (False, True)}

    def block(env, seed, n):
        env.reset(seed=seed)
        actions = np.random.default_rng(seed).uniform(-1.0, 1.0, (n, *env.action_space.shape))
        start = time.perf_counter()
        for action in actions.astype(np.float32):
            if any(env.step(action)[2:4]):
                env.reset()
        return 1e6 * (time.perf_counter() - start) / n

    for env in envs.values():
        block(env, rounds, 50)
    us = {on: [] for on in envs}
    for r in range(rounds):
        for on, env in envs.items():
            us[on].append(block(env, r, steps))
    free, touching = float(np.median(us[False])), float(np.median(us[True]))
    return {"free_us": us[False], "self_contact_us": us[True], "free_median_us": free,
            "self_contact_median_us": touching, "ratio": touching / free}


def penetration() -> dict:
    """Per scene of tests/solver/test_penetration.py, and two rigid discs at the default
    ``gap_tol``: the sampled depth and the peak between samples at the default resolution,
    and a 512-step solve's sampled depth (the rigid discs' at the penalty the default solve
    ended with), in m."""
    import solver

    arm = solver.designs.octarm_v()
    rod = solver.designs.rod(length=1.0, EI=1.0, EA=1e3, GA=1e3, GJ=0.7)
    pushed = dict(base_angle_deg=90, gravity=0.0, tip_force=(0.0, -3.0, 0.5))
    small, curl = (0.07, -0.70, 0.05), (-0.16, -0.062, 0.15)
    last = np.array([0, 0, 0, 0, 0, 100]) * solver.PSI
    all_i = np.array([100, 0, 100, 0, 100, 0]) * solver.PSI

    def disc(where, k):
        return solver.Scene(obstacles=(solver.Disc(where[:2], where[2], k),))

    cases = {  # name: (arm, pressures, scene, planar, rigid)
        "disc": (arm, last, disc(small, 2e4), True, False),
        "disc_in_3d": (arm, solver.channel_pressures(arm, last), disc(small, 2e4), False, False),
        "sphere": (rod, np.zeros(rod.n_inputs(False)), solver.Scene(**pushed, obstacles=(
            solver.Sphere((0.7, -0.3, 0.12), 0.2, 2e3),)), False, False),
        "cylinder": (rod, np.zeros(rod.n_inputs(False)), solver.Scene(**pushed, obstacles=(
            solver.Cylinder((0.6, -0.3, 0.0), (1.0, 0.3, 1.0), 0.15, 2e3),)), False, False),
        "rigid_disc_small_patch": (arm, last, disc(small, math.inf), True, True),
        "rigid_disc_full_curl": (arm, all_i, disc(curl, math.inf), True, True),
    }
    out = {}
    for name, (body, p, scene, planar, rigid) in cases.items():
        eq = solver.solve(body, p, scene, planar=planar)
        if rigid:
            scene = disc(small if "small" in name else curl, eq.penalty_stiffness)
        fine = solver.solve(body, p, scene, planar=planar,
                            settings=solver.Settings(steps_per_section=512))
        out[name] = {"samples": float(eq.penetration.max()), "peak": float(eq.peak_penetration),
                     "fine_samples": float(fine.penetration.max()),
                     "converged": bool(eq.converged and fine.converged)}
    return out


def _run(tree: Path, scenes: dict, accuracy: bool) -> dict:
    """:func:`measure` in a fresh process importing ``tree``'s ``solver``."""
    code = textwrap.dedent(inspect.getsource(measure)) + (
        f"\nimport json\nprint(json.dumps(measure({scenes!r}, {accuracy!r})))\n")
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=tree, capture_output=True,
                          text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"the measurement failed in {tree}:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def run(trees: list[Path], rounds: int = 2, scenes: dict | None = None) -> dict:
    """The trees measured in turn, ``rounds`` times; accuracy once per tree (it does not
    vary between runs). Returns the rounds, and per tree and scene the medians, with the
    time ratios to the first tree."""
    scenes = SCENES if scenes is None else scenes
    results = {str(t): [] for t in trees}
    for r in range(rounds):
        for tree in trees:
            print(f"round {r + 1}/{rounds}: {tree}", file=sys.stderr, flush=True)
            results[str(tree)].append(_run(tree, scenes, accuracy=r == 0))
    summary = {}
    for tree in trees:
        runs = results[str(tree)]
        summary[str(tree)] = {name: {
            "cold_ms": float(np.median([run[name]["cold_ms"] for run in runs])),
            "warm_ms": float(np.median([run[name]["warm_ms"] for run in runs])),
            **{k: runs[0][name][k] for k in ("error_16", "error_32")}} for name in scenes}
    first = summary[str(trees[0])]
    for tree in trees:
        for name, row in summary[str(tree)].items():
            row["cold_ratio"] = row["cold_ms"] / first[name]["cold_ms"]
            row["warm_ratio"] = row["warm_ms"] / first[name]["warm_ms"]
    return {"trees": [str(t) for t in trees], "rounds": results, "summary": summary}


def report(result: dict) -> str:
    """The summary as a table."""
    lines = ["scene                 tree  cold ms  warm ms  (ratio to the first tree)  "
             "error/L 16    32 steps"]
    for name in next(iter(result["summary"].values())):
        for k, tree in enumerate(result["trees"]):
            row = result["summary"][tree][name]
            lines.append(f"{name:20s}  {'ABCD'[k]:4s}  {row['cold_ms']:7.1f}  {row['warm_ms']:7.2f}"
                         f"  ({row['cold_ratio']:.2f}, {row['warm_ratio']:.2f})"
                         f"               {row['error_16']:.1e}  {row['error_32']:.1e}")
    lines += [f"{'ABCD'[k]}: {tree}" for k, tree in enumerate(result["trees"])]
    return "\n".join(lines)


def self_friction_figures(mu: float = 0.5, repeats: int = 3) -> dict:
    """Friction in self-contact on OctArm V curled by channel I of every section at 100 psi,
    ramped in eight warm solves from rest (the scene of ``tests/solver/test_self_friction.py``),
    with ``Scene.self_friction`` = ``mu`` and without: the base force's distance from the dead
    loads (N), the global moment balance of ``softarm stress`` (relative), the samples in
    contact and slipping, the friction impulses (N), the energy dissipated (J), the tip's and
    the backbone's distance from the frictionless state (m), the backbone's at μ = 1e-2 and
    1e-3 (/ L), and the ramp's time (s, best of ``repeats``) with and without friction."""
    import time

    import numpy as np

    import solver
    from softarm_gym.benchmarks.stress import moment_balance_error
    from solver import layout as L
    from solver.problem import context, pack

    arm = solver.designs.octarm_v()
    ring = min(t.material.ring_stiffness for t in arm.tubes)
    curl = np.where(np.arange(arm.n_inputs(True)) % 2 == 0, arm.max_pressure, 0.0)

    def ramp(value):
        scene = solver.Scene(self_contact=ring, self_friction=value)
        eq = solver.solve(arm, np.zeros(arm.n_inputs(True)), scene)
        start = time.perf_counter()
        for fraction in np.linspace(0.125, 1.0, 8):
            eq = solver.solve(arm, fraction * curl, scene, warm_start=eq)
        return eq, time.perf_counter() - start

    free, eq = ramp(0.0)[0], ramp(mu)[0]
    settings = solver.Settings()
    dead = context(arm, pack(arm, "full", settings), solver.Scene(), 2, settings).base_force
    fs = eq.self_friction_samples
    return {"mu": mu, "converged": bool(eq.converged and eq.stable),
            "base_force_error_n": float(np.abs(eq.base_force - dead).max()),
            "dead_load_n": float(np.abs(dead).max()),
            "moment_balance": moment_balance_error(arm, solver.Scene(), eq),
            "moment_balance_frictionless": moment_balance_error(arm, solver.Scene(), free),
            "samples_in_contact": int(np.isfinite(fs[..., L.FS_NEW]).sum()),
            "samples_slipping": int((fs[..., L.FS_SLIP] > 0).sum()),
            "impulses_n": float(np.hypot(fs[..., L.FS_F], fs[..., L.FS_F + 1]).sum()),
            "dissipated_j": eq.dissipated,
            "tip_shift_m": float(np.linalg.norm(eq.tip - free.tip)),
            "backbone_shift_m": float(np.abs(eq.positions - free.positions).max()),
            "small_mu_shift_over_l": {value: float(np.abs(ramp(value)[0].positions - free.positions).max()
                                                   / arm.length) for value in (1e-2, 1e-3)},
            "ramp_s": min(ramp(mu)[1] for _ in range(repeats)),
            "ramp_frictionless_s": min(ramp(0.0)[1] for _ in range(repeats))}


def self_friction_cost(n_steps: int = 200, rounds: int = 5, mu: float = 0.7) -> dict:
    """What friction adds to a self-contact step: warm ``Stepper`` steps of OctArm V pressed
    on itself (channel I of every section ramped to 100 psi, the scene of
    :func:`self_friction_figures`), then walked about that curl by random steps of ±1 % of
    p_max per input (clipped to [0, p_max]; every step in self-contact), with
    ``Scene.self_friction`` = ``mu`` and without, the two taking turns in one process
    (``rounds`` rounds, seeds 0, 1, ...). Returns the median µs a step of each, their ratio,
    each round's figures and the paths the steps took (``Stepper.last_path``)."""
    import time
    from collections import Counter

    import numpy as np

    import solver

    arm = solver.designs.octarm_v()
    ring = min(t.material.ring_stiffness for t in arm.tubes)
    curl = np.where(np.arange(arm.n_inputs(True)) % 2 == 0, arm.max_pressure, 0.0)
    times = {value: [] for value in (0.0, mu)}
    paths = {value: Counter() for value in times}
    for r in range(rounds):
        for value in times:
            stepper = solver.Stepper(arm, solver.Scene(self_contact=ring, self_friction=value))
            stepper.reset(np.zeros(arm.n_inputs(True)))
            for fraction in np.linspace(0.125, 1.0, 8):
                stepper.step(fraction * curl)
            rng = np.random.default_rng(r)
            p = curl.copy()
            start = time.perf_counter()
            for _ in range(n_steps):
                p = np.clip(p + rng.uniform(-0.01, 0.01, p.shape) * arm.max_pressure, 0.0,
                            arm.max_pressure)
                stepper.step(p)
                paths[value][stepper.last_path] += 1
            times[value].append((time.perf_counter() - start) / n_steps * 1e6)
    us = {value: float(np.median(t)) for value, t in times.items()}
    return {"n_steps": n_steps, "rounds": rounds, "mu": mu, "us_frictionless": us[0.0],
            "us_friction": us[mu], "ratio": us[mu] / us[0.0],
            "runs_us": {str(k): v for k, v in times.items()},
            "paths": {str(k): dict(v) for k, v in paths.items()}}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", action="append", default=[], metavar="TREE",
                        help="another checkout to measure side by side (repeatable)")
    parser.add_argument("--rounds", type=int, default=2, help="turns each tree takes (2)")
    parser.add_argument("--out", type=Path, help="write the result as JSON here")
    parser.add_argument("--reach-cost", action="store_true",
                        help="only time OctArmReach-v1 steps with self_contact=True against "
                             "without, in this process")
    parser.add_argument("--penetration", action="store_true",
                        help="only the sampled and peak penetration of contact scenes")
    parser.add_argument("--self-friction", action="store_true",
                        help="only the figures of friction in self-contact (docs/design.md §9.1)")
    args = parser.parse_args(argv)
    if args.self_friction:
        result = {**self_friction_figures(), "cost": self_friction_cost()}
        print(json.dumps(result, indent=1))
        if args.out:
            args.out.write_text(json.dumps(result, indent=1) + "\n")
        return 0
    if args.penetration:
        result = penetration()
        for name, row in result.items():
            print(f"{name:24s} samples {1e3 * row['samples']:.4f} mm  peak {1e3 * row['peak']:.4f}"
                  f" mm  512-step samples {1e3 * row['fine_samples']:.4f} mm")
        if args.out:
            args.out.write_text(json.dumps(result, indent=1) + "\n")
        return 0
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1; got {args.rounds}")
    if args.reach_cost:
        result = reach_cost()
        print(f"OctArmReach-v1 warm step: {result['free_median_us']:.1f} us without self-contact, "
              f"{result['self_contact_median_us']:.1f} us with it: {result['ratio']:.2f}x")
        if args.out:
            args.out.write_text(json.dumps(result, indent=1) + "\n")
        return 0
    trees = [Path(__file__).resolve().parents[2]] + [Path(t).resolve() for t in args.against]
    for tree in trees[1:]:
        if not (tree / "solver" / "__init__.py").is_file():
            parser.error(f"--against {tree}: not a checkout of this project (no solver/)")
    result = run(trees, args.rounds)
    result["command"] = "python -m softarm_gym.benchmarks.self_contact_bench " + " ".join(
        sys.argv[1:] if argv is None else argv)
    print(report(result))
    if args.out:
        args.out.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
