"""Solver benchmark: run time against tip error, with scipy's solve_bvp timed in the same run.

Every figure is a median over a fixed, seeded set of OctArm V and CT scenes (gravity, base
angles 0/45/90°, with and without payload). Errors are against a converged reference (RK4
with 1024 steps per section; it agrees with the independent solve_bvp formulation of
``tests/solver/naive.py`` to ~1e-9 m) and are reported relative to the arm length L.
"""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path

import numpy as np

import solver

STEP_SETTINGS = (4, 6, 8, 12, 16, 24, 32, 64)
REFERENCE = solver.Settings(steps_per_section=1024)


def scenes(per_scene: int = 6, seed: int = 0):
    """The fixed scene set: (arm, planar pressures (Pa), Scene, label)."""
    rng = np.random.default_rng(seed)
    out = []
    for arm, payloads in ((solver.designs.octarm_v(), (0.0, 0.1)),
                          (solver.designs.ct(), (0.0, 0.1))):
        for angle in (0.0, 45.0, 90.0):
            for payload in payloads:
                scene = solver.Scene(base_angle_deg=angle, payload_kg=payload)
                for _ in range(per_scene):
                    p = rng.uniform(0.0, arm.max_pressure, arm.n_inputs())
                    out.append((arm, p, scene, f"{arm.name} {angle:g}deg {payload:g}kg"))
    return out


def _median_time(repeat: int, *args, **kwargs) -> float:
    """Median wall time of ``solver.solve(*args, **kwargs)`` over ``repeat`` calls (s)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        solver.solve(*args, **kwargs)
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def _warm_pairs(cases, seed=1):
    """For each case a nearby pressure vector (a small quasi-static step, as an env step)."""
    rng = np.random.default_rng(seed)
    pairs = []
    for arm, p, _, _ in cases:
        step = rng.normal(0.0, 0.01 * arm.max_pressure, p.shape)
        pairs.append(np.clip(p + step, 0.0, arm.max_pressure))
    return pairs


def load_scipy_reference():
    """The independent scipy solve_bvp formulation kept with the tests (source checkout)."""
    path = Path(__file__).resolve().parents[2] / "tests" / "solver" / "naive.py"
    if not path.exists():
        return None
    spec = importlib.util.spec_from_file_location("softarm_naive_reference", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(quick: bool = False, progress=None) -> dict:
    """Run the solver benchmark; returns a JSON-able dict (see the README table)."""
    per_scene = 2 if quick else 6
    cases = scenes(per_scene)
    tick = progress or (lambda *_: None)
    # Compile every kernel first so no timing includes JIT.
    for arm, p, scene, _ in cases[:: len(cases) // 4]:
        solver.solve(arm, p, scene, record=False)
    refs = [solver.solve(arm, p, scene, settings=REFERENCE, record=False).tip for arm, p, scene, _ in cases]
    warm_targets = _warm_pairs(cases)
    repeat = 3 if quick else 7
    rows = []
    for steps in STEP_SETTINGS:
        settings = solver.Settings(steps_per_section=steps)
        errors, cold, warm, ok = [], [], [], []
        for (arm, p, scene, _), ref, target in zip(cases, refs, warm_targets):
            eq = solver.solve(arm, p, scene, settings=settings, record=False)
            errors.append(np.linalg.norm(eq.tip - ref) / arm.length)
            ok.append(eq.converged)
            # Cold: the full quasi-static ramp (the loading stage is cached per scene, as in
            # any sweep); warm: one small step from the previous equilibrium.
            cold.append(_median_time(repeat, arm, p, scene, settings=settings, record=False))
            warm.append(_median_time(repeat, arm, target, scene, settings=settings, record=False,
                                     warm_start=eq))
        rows.append({"steps_per_section": steps,
                     "max_tip_error_over_L": float(np.max(errors)),
                     "median_tip_error_over_L": float(np.median(errors)),
                     "median_cold_us": 1e6 * float(np.median(cold)),
                     "median_warm_us": 1e6 * float(np.median(warm)),
                     "warm_solves_per_s": 1.0 / float(np.median(warm)),
                     "converged_fraction": float(np.mean(ok))})
        tick(f"steps {steps}")
    result = {"scenes": len(cases), "designs": ["octarm_v", "ct"], "base_angles_deg": [0, 45, 90],
              "settings": rows, "default_steps_per_section": solver.Settings().steps_per_section}
    result["scipy"] = _scipy_rows(cases, refs, quick, tick)
    result["spatial"] = _spatial(quick)
    result["batch"] = _batch(quick)
    default = next(r for r in rows if r["steps_per_section"] == result["default_steps_per_section"])
    if result["scipy"]:
        best = min(result["scipy"], key=lambda r: r["median_tip_error_over_L"])
        result["speedup_vs_scipy_warm"] = best["median_seconds"] / (default["median_warm_us"] * 1e-6)
        result["speedup_vs_scipy_cold"] = best["median_seconds"] / (default["median_cold_us"] * 1e-6)
    return result


def _scipy_rows(cases, refs, quick, tick):
    naive = load_scipy_reference()
    if naive is None:
        return []
    subset = list(zip(cases, refs))[:: 4 if quick else 2]
    rows = []
    for tol in (1e-4, 1e-6, 1e-8):
        times, errors = [], []
        for (arm, p, scene, _), ref in subset:
            channel = solver.channel_pressures(arm, p)
            start = time.perf_counter()
            try:
                tip, _, _ = naive.solve_bvp_planar(arm, channel, scene, tol=tol)
            except RuntimeError:
                continue
            times.append(time.perf_counter() - start)
            errors.append(np.linalg.norm(tip - ref) / arm.length)
        rows.append({"tol": tol, "solved": len(times), "of": len(subset),
                     "median_seconds": float(np.median(times)),
                     "median_tip_error_over_L": float(np.median(errors)),
                     "max_tip_error_over_L": float(np.max(errors))})
        tick(f"scipy tol {tol:g}")
    return rows


def _spatial(quick):
    arm = solver.designs.octarm_v()
    rng = np.random.default_rng(2)
    scene = solver.Scene(base_angle_deg=90.0, payload_kg=0.1)
    eq = solver.solve(arm, rng.uniform(0, 0.5, 9) * arm.max_pressure, scene, planar=False,
                      record=False)
    n = 50 if quick else 300
    times = []
    converged = 0
    for _ in range(n):
        p = np.clip(eq.pressures + rng.normal(0, 0.01 * arm.max_pressure, 9), 0, arm.max_pressure)
        start = time.perf_counter()
        eq = solver.solve(arm, p, scene, planar=False, record=False, warm_start=eq)
        times.append(time.perf_counter() - start)
        converged += eq.converged
    return {"median_warm_us": 1e6 * float(np.median(times)),
            "warm_solves_per_s": 1.0 / float(np.median(times)), "n": n,
            "converged_fraction": converged / n}


def _batch(quick):
    arm = solver.designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90.0)
    rng = np.random.default_rng(3)
    P = rng.uniform(0, arm.max_pressure, (2000 if quick else 20000, 6))
    solver.solve_batch(arm, P[:8], scene)
    start = time.perf_counter()
    _, ok = solver.solve_batch(arm, P, scene)
    seconds = time.perf_counter() - start
    import numba

    return {"points": len(P), "seconds": seconds, "cold_solves_per_s": len(P) / seconds,
            "threads": numba.get_num_threads(), "converged_fraction": float(ok.mean())}


def format_table(result: dict) -> str:
    """The README table for a :func:`run` result."""
    lines = ["| RK4 steps/section | max tip error / L | median error / L | cold solve (µs) "
             "| warm step (µs) | warm solves/s |", "|---|---|---|---|---|---|"]
    for r in result["settings"]:
        mark = " (default)" if r["steps_per_section"] == result["default_steps_per_section"] else ""
        lines.append(f"| {r['steps_per_section']}{mark} | {r['max_tip_error_over_L']:.1e} | "
                     f"{r['median_tip_error_over_L']:.1e} | {r['median_cold_us']:.0f} | "
                     f"{r['median_warm_us']:.0f} | {r['warm_solves_per_s']:,.0f} |")
    if result.get("scipy"):
        lines += ["", "| scipy solve_bvp tol | solved | median time (ms) | median error / L "
                  "| max error / L |", "|---|---|---|---|---|"]
        for r in result["scipy"]:
            lines.append(f"| {r['tol']:g} | {r['solved']}/{r['of']} | {1e3 * r['median_seconds']:.1f} | "
                         f"{r['median_tip_error_over_L']:.1e} | {r['max_tip_error_over_L']:.1e} |")
        lines.append("")
        lines.append(f"Speed-up at the default setting over the most accurate scipy run: "
                     f"{result['speedup_vs_scipy_warm']:,.0f}× warm-started, "
                     f"{result['speedup_vs_scipy_cold']:,.0f}× cold.")
    sp, b = result["spatial"], result["batch"]
    lines.append(f"Spatial warm-started step: {sp['median_warm_us']:.0f} µs "
                 f"({sp['warm_solves_per_s']:,.0f}/s, {100 * sp['converged_fraction']:.1f}% converged). "
                 f"solve_batch: {b['points']:,} cold solves in {b['seconds']:.2f} s on "
                 f"{b['threads']} threads ({b['cold_solves_per_s']:,.0f}/s).")
    return "\n".join(lines)
