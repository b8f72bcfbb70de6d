"""Aggregate steps per second of the batched (solve_batch-backed) reach vector env."""

from __future__ import annotations

import time

import numpy as np


def run(sizes=(256, 1024, 4096), steps: int = 30, action_mode: str = "delta",
        progress=None) -> list[dict]:
    """Time ``steps`` steps of :class:`~softarm_gym.vector.BatchedReachVectorEnv` per size.

    Random actions in ``delta`` mode (each step changes every pressure by up to 10 % of
    p_max, as a policy exploring does); the first step after reset is not timed.
    """
    from softarm_gym.vector import BatchedReachVectorEnv

    rows = []
    for n in sizes:
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
        seconds = time.perf_counter() - start
        rows.append({"num_envs": n, "steps": steps, "seconds": seconds,
                     "env_steps_per_s": n * steps / seconds,
                     "converged_fraction": converged / (n * steps)})
        if progress:
            progress(f"batched vector env {n}")
    return rows


def format_table(rows: list[dict]) -> str:
    lines = ["| batched vector env (true obs., delta actions) | env-steps/s (aggregate) | converged |",
             "|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['num_envs']} arms | {r['env_steps_per_s']:,.0f} | "
                     f"{100 * r['converged_fraction']:.2f} % |")
    return "\n".join(lines)
