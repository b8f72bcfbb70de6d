"""Aggregate steps per second of the batched (BatchStepper-backed) reach vector env."""

from __future__ import annotations

import time

import numba
import numpy as np


def _time(n: int, steps: int, action_mode: str) -> tuple[float, float]:
    """(seconds for ``steps`` steps of n arms, converged fraction); the first step untimed."""
    from softarm_gym.vector import BatchedReachVectorEnv

    env = BatchedReachVectorEnv(num_envs=n, action_mode=action_mode)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (steps + 1, n, env.single_action_space.shape[0]))
    env.step(actions[0])
    converged = 0
    start = time.perf_counter()
    for a in actions[1:]:
        *_, info = env.step(a)
        converged += int(info["converged"].sum())
    return time.perf_counter() - start, converged / (n * steps)


def run(sizes=(4, 16, 256, 1024, 4096), steps: int = 30, action_mode: str = "delta",
        progress=None) -> list[dict]:
    """Time ``steps`` steps of :class:`~softarm_gym.vector.BatchedReachVectorEnv` per size,
    with numba's full thread pool and with one thread, side by side (the thread policy:
    :attr:`solver.BatchStepper.PARALLEL_MIN`).

    Random actions in ``delta`` mode (each step changes every pressure by up to 10 % of
    p_max, as a policy exploring does); the first step after reset is not timed.
    """
    threads = numba.get_num_threads()
    rows = []
    for n in sizes:
        seconds, converged = _time(n, steps, action_mode)
        numba.set_num_threads(1)
        try:
            one, _ = _time(n, steps, action_mode)
        finally:
            numba.set_num_threads(threads)
        rows.append({"num_envs": n, "steps": steps, "threads": threads, "seconds": seconds,
                     "env_steps_per_s": n * steps / seconds,
                     "one_thread_env_steps_per_s": n * steps / one,
                     "converged_fraction": converged})
        if progress:
            progress(f"batched vector env {n}")
    return rows


def format_table(rows: list[dict]) -> str:
    lines = ["| batched vector env (true obs., delta actions) | env-steps/s (aggregate) "
             "| on one thread | converged |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['num_envs']} arms | {r['env_steps_per_s']:,.0f} ({r['threads']} threads) | "
                     f"{r['one_thread_env_steps_per_s']:,.0f} | {100 * r['converged_fraction']:.2f} % |")
    return "\n".join(lines)
