"""Solver benchmark: run time against tip error, with scipy's solve_bvp timed in the same run.

Every figure is a median over a fixed, seeded set of OctArm V and CT scenes (gravity, base
angles 0/45/90°, with and without payload). Errors are against a converged reference (RK4
with 1024 steps per section; it agrees with the independent solve_bvp formulation of
``tests/solver/naive.py`` to ~1e-9 m) and are reported relative to the arm length L.
"""

from __future__ import annotations

import importlib.util
import math
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
        # The grid pinned: a solve would otherwise refine the coarse ones where its step-size
        # check fails (``converged_fraction`` says how often it does), and the sweep would not
        # measure the grid it names.
        settings = solver.Settings(steps_per_section=steps, max_refinement=1)
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
    result["stepper"] = _stepper(cases, warm_targets, repeat)
    result["spatial"] = _spatial(quick)
    result["batch"] = _batch(quick)
    result["contact"] = contact(quick, tick)
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


def contact_scenes(n: int, seed: int = 4):
    """Seeded OctArm V scenes with a disc the arm runs into on its way to random pressures,
    clear of the unactuated arm: (arm, planar pressures (Pa), disc centre, disc radius, base
    angle). Hanging and horizontal bases."""
    arm = solver.designs.octarm_v()
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        base = float(rng.choice([0.0, 90.0]))
        p = rng.uniform(0, 1, 6) * arm.max_pressure * (rng.uniform(size=6) < 0.6)
        free = solver.solve(arm, p, solver.Scene(base_angle_deg=base))
        j = int(rng.integers(len(free.s) // 3, len(free.s)))
        radius = float(rng.uniform(0.05, 0.15))
        normal = rng.choice([-1.0, 1.0]) * np.array([-np.sin(free.angles[j]), np.cos(free.angles[j])])
        center = free.positions[j] + normal * (radius - rng.uniform(0.0, 0.03))
        rest = solver.solve(arm, np.zeros(6), solver.Scene(base_angle_deg=base))
        if np.hypot(*(rest.positions - center).T).min() > radius + 0.01:
            out.append((arm, p, tuple(center), radius, base))
    return out


def contact(quick: bool = False, progress=None) -> dict:
    """Contact solves: time against tip error, against the hard-contact limit.

    For each scene of :func:`contact_scenes` the reference is the rigid disc solved at 64
    RK4 steps per section with ``gap_tol`` 1e-6 m (the hard-contact limit; scenes where it
    does not converge are left out). Timed: the cold
    solve and one warm step (a 1 % pressure change from the converged state), for the
    tubes' own penalty (``TubeMaterial.ring_stiffness``, the wrap envs' default) at 8, 16
    (default) and 32 steps per section, and for the rigid disc at the default resolution
    with ``gap_tol`` 1e-4 and 1e-5 m. The penalty's errors are mostly its compliance, not
    the discretisation: the 32-step row shows what is left at finer resolution.
    """
    tick = progress or (lambda *_: None)
    cases = contact_scenes(3 if quick else 8)
    arm = cases[0][0]
    ring = arm.tubes[-1].material.ring_stiffness
    configs = [("penalty (tube ring stiffness)", ring, steps, 1e-4) for steps in (8, 16, 32)]
    configs += [("rigid", math.inf, 16, tol) for tol in (1e-4, 1e-5)]
    repeat = 2 if quick else 3
    refs, kept = [], []
    for case in cases:
        arm, p, center, radius, base = case
        scene = solver.Scene(base_angle_deg=base, obstacles=(solver.Disc(center, radius, math.inf),))
        ref = solver.solve(arm, p, scene, record=False, settings=solver.Settings(
            steps_per_section=64, gap_tol=1e-6))
        if ref.converged:
            refs.append(ref.tip)
            kept.append(case)
    cases = kept
    rows = []
    rng = np.random.default_rng(5)
    for label, stiffness, steps, tol in configs:
        settings = solver.Settings(steps_per_section=steps, gap_tol=tol)
        errors, cold, warm, ok, touched = [], [], [], [], 0
        for (arm, p, center, radius, base), ref in zip(cases, refs):
            scene = solver.Scene(base_angle_deg=base, obstacles=(solver.Disc(center, radius, stiffness),))
            eq = solver.solve(arm, p, scene, settings=settings)
            ok.append(eq.converged)
            touched += eq.in_contact
            errors.append(np.linalg.norm(eq.tip - ref) / arm.length)
            cold.append(_median_time(repeat, arm, p, scene, settings=settings, record=False))
            step = np.clip(p + rng.normal(0.0, 0.01 * arm.max_pressure, p.shape), 0.0, arm.max_pressure)
            warm.append(_median_time(repeat, arm, step, scene, settings=settings, record=False,
                                     warm_start=eq))
        rows.append({"contact": label, "stiffness": stiffness, "steps_per_section": steps,
                     "gap_tol": tol if stiffness == math.inf else None,
                     "max_tip_error_over_L": float(np.max(errors)),
                     "median_tip_error_over_L": float(np.median(errors)),
                     "median_cold_ms": 1e3 * float(np.median(cold)),
                     "median_warm_ms": 1e3 * float(np.median(warm)),
                     "converged_fraction": float(np.mean(ok)), "in_contact": touched})
        tick(f"contact {label} {steps}")
    return {"scenes": len(cases), "design": arm.name, "ring_stiffness": ring,
            "reference": "rigid disc, 64 steps per section, gap_tol 1e-6 m", "rows": rows}


def _stepper(cases, warm_targets, repeat) -> dict:
    """The same small warm steps through :class:`solver.Stepper` and through ``solve()``.

    Each case steps back and forth between its pressures and the nearby target (so every
    step is a small one from a fresh equilibrium); medians over the cases of the per-case
    median step time, both paths timed in the same loop.
    """
    stepper_times, solve_times, agree = [], [], []
    for (arm, p, scene, _), target in zip(cases, warm_targets):
        stepper = solver.Stepper(arm, scene)
        stepper.reset(p)
        eq = solver.solve(arm, p, scene, record=False)
        steps, solves = [], []
        for k in range(2 * repeat):
            goal = target if k % 2 == 0 else p
            start = time.perf_counter()
            stepper.step(goal)
            steps.append(time.perf_counter() - start)
            start = time.perf_counter()
            eq = solver.solve(arm, goal, scene, record=False, warm_start=eq)
            solves.append(time.perf_counter() - start)
        agree.append(float(np.linalg.norm(stepper.tip - eq.tip)) / arm.length)
        stepper_times.append(np.median(steps))
        solve_times.append(np.median(solves))
    step_us, solve_us = 1e6 * float(np.median(stepper_times)), 1e6 * float(np.median(solve_times))
    return {"median_step_us": step_us, "steps_per_s": 1e6 / step_us, "median_solve_us": solve_us,
            "speedup_over_solve": solve_us / step_us, "max_tip_difference_over_L": float(np.max(agree))}


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
    if result.get("contact"):
        lines += ["", contact_table(result["contact"])]
    if result.get("stepper"):
        st = result["stepper"]
        lines.append(f"Warm step through solver.Stepper: {st['median_step_us']:.1f} µs "
                     f"({st['steps_per_s']:,.0f}/s), {st['speedup_over_solve']:.1f}× solve()'s "
                     f"{st['median_solve_us']:.1f} µs on the same steps (tips agree to "
                     f"{st['max_tip_difference_over_L']:.0e}·L).")
    sp, b = result["spatial"], result["batch"]
    lines.append(f"Spatial warm-started step: {sp['median_warm_us']:.0f} µs "
                 f"({sp['warm_solves_per_s']:,.0f}/s, {100 * sp['converged_fraction']:.1f}% converged). "
                 f"solve_batch: {b['points']:,} cold solves in {b['seconds']:.2f} s on "
                 f"{b['threads']} threads ({b['cold_solves_per_s']:,.0f}/s).")
    return "\n".join(lines)


def contact_table(result: dict) -> str:
    """The README table of :func:`contact`."""
    lines = [f"Contact ({result['scenes']} {result['design']} scenes; error against the hard-contact "
             f"limit: {result['reference']})", "",
             "| contact | RK4 steps/section | max tip error / L | median error / L | cold solve (ms) "
             "| warm step (ms) | converged |", "|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        label = r["contact"] if r["gap_tol"] is None else f"rigid, gap_tol {r['gap_tol']:g} m"
        if r["gap_tol"] is None:
            label += f" {r['stiffness']:.2g} N/m²"
        lines.append(f"| {label} | {r['steps_per_section']} | {r['max_tip_error_over_L']:.1e} | "
                     f"{r['median_tip_error_over_L']:.1e} | {r['median_cold_ms']:.1f} | "
                     f"{r['median_warm_ms']:.2f} | {100 * r['converged_fraction']:.0f} % |")
    return "\n".join(lines)
