"""``softarm warmup``: compile every numba kernel the registered environments use into the on-disk cache.

``make demo`` and ``make test`` run it first, so a user's first episode and each test worker
load machine code instead of compiling it (``softarm bench --first-episode`` measures the
difference). It solves the named designs (planar, warm-started, spatial, batched), then
runs a short episode of every registered ID in every observation mode with Table 4.3
sensor noise and a payload range, the spatial reach task with every estimator that supports
it, and the batched vector env. ``--clear`` first deletes every compiled file of the
project's kernels (a damaged or stale cache; damaged entries also heal on their own, see
:mod:`solver.jit`).
"""

from __future__ import annotations

import importlib
import sys
import time

import numpy as np

import solver
from solver.jit import clear_cache

NAME = "warmup"
HELP = "compile the numba kernels the solver and the registered envs use into the on-disk cache"

STEPS = 3
"""Steps per warm-up episode (each kernel needs one call per argument type)."""


KERNEL_MODULES = ("solver", "softarm_gym.sensing.kernels", "softarm_gym.envs.terms")
"""Modules whose import defines every project kernel (for ``--clear``)."""


def add_arguments(p):
    p.add_argument("--quiet", action="store_true", help="no line per case on stderr")
    p.add_argument("--clear", action="store_true",
                   help="delete the cached kernels first, then compile them afresh")


def cases() -> list[tuple[str, dict]]:
    """(env_id, gym.make kwargs) of every warm-up episode: each registered ID × observation mode
    (planar), and spatial reach with every estimator that supports 3-D."""
    import gymnasium as gym

    import softarm_gym  # noqa: F401  (registers the IDs)
    from softarm_gym.sensing import ESTIMATORS

    ids = [env_id for env_id in gym.registry if env_id.startswith("SoftArm/")]
    out = [(env_id, {"observation": obs, "sensor_noise": "thesis", "payload_kg": (0.0, 0.1)})
           for env_id in ids for obs in ESTIMATORS]
    # Spatial: the reach IDs (ReachEnv; the contact tasks are planar only).
    out += [(env_id, {"observation": obs, "planar": False})
            for env_id in ids if gym.spec(env_id).entry_point == "softarm_gym.envs:ReachEnv"
            for obs in ESTIMATORS if obs != "inclinometer"]
    return out


def _solver_kernels() -> None:
    arm = solver.designs.octarm_v()
    scene = solver.Scene(base_angle_deg=45.0)
    p = np.full(6, 20 * solver.PSI)
    eq = solver.solve(arm, p, scene)
    solver.solve(arm, p * 1.1, scene, warm_start=eq)
    solver.solve(arm, np.array([20, 5, 0, 10, 0, 0, 0, 0, 0]) * solver.PSI, scene, planar=False)
    solver.solve_batch(arm, np.stack([p, p * 0.5]), scene)


def _episode(env, seed: int) -> None:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(STEPS):
        env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
    env.close()


def warm(progress=None) -> float:
    """Run every warm-up case; ``progress(message)`` after each. Returns the seconds taken."""
    import gymnasium as gym

    start = time.perf_counter()
    _solver_kernels()
    for k, (env_id, kwargs) in enumerate(cases()):
        t = time.perf_counter()
        _episode(gym.make(env_id, **kwargs), seed=k)
        if progress:
            progress(f"{env_id} {kwargs} ({time.perf_counter() - t:.1f} s)")
    # Small batches run the one-thread kernels, larger ones the parallel ones: warm both.
    for num_envs in (2, solver.BatchStepper.PARALLEL_MIN):
        _episode(gym.make_vec("SoftArm/OctArmReach-v0", num_envs=num_envs,
                              vectorization_mode="vector_entry_point"), seed=0)
    batch_kernels()
    return time.perf_counter() - start


def batch_kernels() -> solver.BatchStepper:
    """Both ways of both batch kernels (cold rows, step rows): a thread policy runs a kernel
    on the threads from its third call and measures it from its fourth
    (:class:`solver.ThreadPolicy`), and an episode resets once, so the parallel cold kernel
    would otherwise first compile inside a user's run (seconds on a 2-core machine).
    Returns the batch, its policies having measured both ways."""
    n = solver.BatchStepper.PARALLEL_MIN
    arm = solver.designs.octarm_v()
    batch = solver.BatchStepper(arm, solver.Scene(), n=n)
    p = np.full((n, arm.n_inputs(True)), 0.2 * arm.max_pressure)
    for k in range(4):
        batch.reset(p * (1 + 0.1 * k))
        batch.step(p * (1.05 + 0.1 * k))
    return batch


def run(args) -> int:
    if args.clear:
        for module in KERNEL_MODULES:
            importlib.import_module(module)
        removed = clear_cache()
        folders = ", ".join(sorted({str(p.parent) for p in removed}))
        print(f"removed {len(removed)} cached kernel files" + (f" from {folders}" if folders else ""))

    def progress(message):
        print(f"[warmup] {message}", file=sys.stderr, flush=True)

    seconds = warm(None if args.quiet else progress)
    print(f"numba kernels ready in {seconds:.1f} s")
    return 0
