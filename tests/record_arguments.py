"""Kernel arguments as named records or not: ``python -m tests.record_arguments [REPEATS]``.

The measurement behind docs/design.md §13 ("Kernel arguments"). One small path-like kernel
(a loop over sections reading ``secf`` rows and the goal level) is called four ways: loose
arrays, plain tuples unpacked by name (the solver's convention), ``namedtuple`` records and a
numba ``structref``. For each, with ``cache=True`` and a fresh ``NUMBA_CACHE_DIR``, a first
process compiles (cold) and a second loads the cache (warm); each reports the seconds from
building the arguments to the first result, and the per-call time of a warm call (µs, best
of 5 × 20,000). Prints the median of ``REPEATS`` (default 3) of each figure, and for scale the
median time of a warm :meth:`solver.Stepper.step` (2,000 small random steps of OctArm V).
"""

from __future__ import annotations

import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
from collections import namedtuple

import numba
import numpy as np
from numba.core import types
from numba.experimental import structref

KINDS = ("loose", "tuples", "namedtuple", "structref")
LEN, CA, CI = 0, 1, 3
Grid = namedtuple("Grid", "theta0 secf steps")
Level = namedtuple("Level", "p loads mtip")


@structref.register
class GridType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


class GridRecord(structref.StructRefProxy):
    def __new__(cls, theta0, secf, steps):
        return structref.StructRefProxy.__new__(cls, theta0, secf, steps)


structref.define_proxy(GridRecord, GridType, ["theta0", "secf", "steps"])


@numba.njit(cache=True)
def _body(theta0, secf, steps, p, loads, mtip):
    acc = 0.0
    for i in range(secf.shape[1]):
        h = secf[LEN, i] / steps[i]
        for k in range(steps[i]):
            acc += math.sin(theta0 + h * k * secf[CI, i]) * (p[i % p.shape[0]] + loads[i, 0]) \
                + mtip * secf[CA, i]
    return acc


@numba.njit(cache=True)
def loose(theta0, secf, steps, p_a, loads_a, mtip_a, p_b, loads_b, mtip_b):
    return _body(theta0, secf, steps, p_b, loads_b, mtip_b)


@numba.njit(cache=True)
def tuples(grid, a, b):
    theta0, secf, steps = grid
    p_b, loads_b, mtip_b = b
    return _body(theta0, secf, steps, p_b, loads_b, mtip_b)


@numba.njit(cache=True)
def records(grid, a, b):
    return _body(grid.theta0, grid.secf, grid.steps, b.p, b.loads, b.mtip)


@numba.njit(cache=True)
def structrefs(grid, a, b):
    return _body(grid.theta0, grid.secf, grid.steps, b.p, b.loads, b.mtip)


def measure(kind: str) -> tuple[float, float]:
    """(seconds from building the arguments to the first result, µs per warm call)."""
    secf = np.random.default_rng(0).uniform(0.1, 1.0, (6, 3))
    steps, p, loads = np.array([2, 2, 2]), np.ones(6), np.ones((3, 4))
    start = time.perf_counter()
    if kind == "loose":
        def call():
            return loose(0.3, secf, steps, p, loads, 0.1, p, loads, 0.1)
    elif kind == "tuples":
        grid, level = (0.3, secf, steps), (p, loads, 0.1)

        def call():
            return tuples(grid, level, level)
    elif kind == "namedtuple":
        grid, level = Grid(0.3, secf, steps), Level(p, loads, 0.1)

        def call():
            return records(grid, level, level)
    else:
        grid, level = GridRecord(0.3, secf, steps), Level(p, loads, 0.1)

        def call():
            return structrefs(grid, level, level)
    call()
    first = time.perf_counter() - start
    return first, 1e6 * min(timeit.repeat(call, number=20_000, repeat=5)) / 20_000


def stepper_step_us() -> float:
    """Median µs of a warm lean step of :class:`solver.Stepper` (OctArm V, horizontal, 0.1 kg)."""
    import solver

    arm = solver.designs.octarm_v()
    stepper = solver.Stepper(arm, solver.Scene(base_angle_deg=90, payload_kg=0.1))
    stepper.reset(np.zeros(6))
    rng, p, seconds = np.random.default_rng(0), np.zeros(6), []
    for _ in range(2000):
        p = np.clip(p + rng.uniform(-0.05, 0.05, 6) * arm.max_pressure, 0.0, arm.max_pressure)
        start = time.perf_counter()
        stepper.step(p)
        seconds.append(time.perf_counter() - start)
    return 1e6 * statistics.median(seconds[100:])


def main(repeats: int) -> None:
    figures = {kind: {"cold": [], "warm": [], "call": []} for kind in KINDS}
    for _ in range(repeats):
        for kind in KINDS:
            with tempfile.TemporaryDirectory() as cache:
                for stage in ("cold", "warm"):
                    out = subprocess.run([sys.executable, __file__, "--one", kind], check=True,
                                         capture_output=True, text=True,
                                         env={**os.environ, "NUMBA_CACHE_DIR": cache}).stdout
                    first, call = map(float, out.split())
                    figures[kind][stage].append(first)
                    if stage == "warm":
                        figures[kind]["call"].append(call)
    print("| arguments | first call, cold cache (s) | first call, warm cache (s) | warm call (µs) |")
    print("|---|---|---|---|")
    for kind, f in figures.items():
        print(f"| {kind} | {statistics.median(f['cold']):.2f} | {statistics.median(f['warm']):.2f} "
              f"| {statistics.median(f['call']):.1f} |")
    print(f"warm Stepper.step: {stepper_step_us():.1f} µs (median)")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--one"]:
        print(*measure(sys.argv[2]))
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
