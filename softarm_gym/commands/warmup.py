"""``softarm warmup``: compile every numba kernel once into the on-disk cache.

Run before a parallel test session so that worker processes load machine code instead of
each compiling the same kernels. ``--clear`` first deletes every compiled file of the
project's kernels (a damaged or stale cache; damaged entries also heal on their own, see
:mod:`solver._jit`).
"""

from __future__ import annotations

import importlib
import time

import numpy as np

import solver
from solver._jit import clear_cache

NAME = "warmup"
HELP = "compile the numba kernels into the on-disk cache"
KERNEL_MODULES = ("solver", "softarm_gym.sensing._kernels", "softarm_gym.vector")
"""Modules whose import defines every project kernel (for ``--clear``)."""


def add_arguments(p):
    p.add_argument("--clear", action="store_true",
                   help="delete the cached kernels first, then compile them afresh")


def run(args) -> int:
    if args.clear:
        for module in KERNEL_MODULES:
            importlib.import_module(module)
        removed = clear_cache()
        folders = ", ".join(sorted({str(p.parent) for p in removed}))
        print(f"removed {len(removed)} cached kernel files" + (f" from {folders}" if folders else ""))
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
