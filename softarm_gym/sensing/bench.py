"""Timing of sensor synthesis and of every shape estimator, as an environment uses them.

:func:`bench_estimators` walks a random quasi-static pressure path (small steps, as in an
episode), solving the truth with a warm start, and times ``synthesize`` and each
estimator's ``estimate`` at every step (the estimators keep their warm starts, as in an
episode). Compilation is excluded by a warm-up pass.
"""

from __future__ import annotations

import time

import numpy as np

import solver
from softarm_gym.sensing.estimators import ESTIMATORS, make_estimator
from softarm_gym.sensing.sensors import SensorNoise, synthesize

__all__ = ["bench_estimators"]


def bench_estimators(design: str = "octarm_vi", steps: int = 200, base_angle_deg: float = 90.0,
                     planar: bool = True, seed: int = 0) -> dict:
    """Median wall time per call of ``synthesize`` and of each estimator (seconds).

    Args:
        design: a named design (:data:`solver.designs.DESIGN_NAMES`).
        steps: timed steps of the pressure path (>= 1).
        base_angle_deg: mounting of the arm.
        planar: planar or spatial estimation (spatial: the estimators that support it).
        seed: seed of the pressure path and of the sensor noise.

    Returns:
        ``{"synthesize": s, "<estimator>": s, ..., "steps": n, "design": name, "planar": bool}``.
    """
    if isinstance(steps, bool) or int(steps) != steps or steps < 1:
        raise ValueError(f"steps must be an integer >= 1; got {steps!r}")
    arm = solver.designs.get(design)
    scene = solver.Scene(base_angle_deg=base_angle_deg)
    rng = np.random.default_rng(seed)
    n = arm.n_inputs(planar)
    path = [np.zeros(n)]
    for _ in range(int(steps) + 2):
        step = rng.normal(0.0, 0.05 * arm.max_pressure, n)
        path.append(np.clip(path[-1] + step, 0.0, arm.max_pressure))
    estimators = {}
    for name in ESTIMATORS:
        try:
            estimators[name] = make_estimator(name, arm, planar=planar, scene=scene)
        except ValueError:
            continue  # not available in this mode
    noise = SensorNoise.thesis()
    times = {name: [] for name in ["synthesize", *estimators]}
    eq = None
    for k, p in enumerate(path):
        eq = solver.solve(arm, p, scene, planar=planar, warm_start=eq)
        t0 = time.perf_counter()
        readings = synthesize(eq, arm, noise, rng)
        t1 = time.perf_counter()
        if k >= 2:  # the first two steps compile and warm up
            times["synthesize"].append(t1 - t0)
        for name, est in estimators.items():
            t0 = time.perf_counter()
            est.estimate(readings, p, truth=eq)
            t1 = time.perf_counter()
            if k >= 2:
                times[name].append(t1 - t0)
    out = {name: float(np.median(v)) for name, v in times.items()}
    out.update(steps=int(steps), design=arm.name, planar=bool(planar))
    return out
