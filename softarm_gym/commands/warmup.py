"""``softarm warmup``: compile every numba kernel once into the on-disk cache.

Run before a parallel test session so that worker processes load machine code instead of
each compiling the same kernels.
"""

from __future__ import annotations

import time

import numpy as np

import solver

NAME = "warmup"
HELP = "compile the numba kernels into the on-disk cache"


def add_arguments(p):
    pass


def run(args) -> int:
    start = time.perf_counter()
    arm = solver.designs.octarm_v()
    scene = solver.Scene(base_angle_deg=45.0)
    p = np.full(6, 20 * solver.PSI)
    eq = solver.solve(arm, p, scene)
    solver.solve(arm, p * 1.1, scene, warm_start=eq)
    solver.solve(arm, np.array([20, 5, 0, 10, 0, 0, 0, 0, 0]) * solver.PSI, scene, planar=False)
    solver.solve_batch(arm, np.stack([p, p * 0.5]), scene)
    print(f"numba kernels ready in {time.perf_counter() - start:.1f} s")
    return 0
