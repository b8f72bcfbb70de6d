"""Aggregate steps per second of the batched vector envs: reach (planar and 3D), and the contact
envs (wrap, obstacle reach) beside reach in the same run."""

from __future__ import annotations

import time

import numba
import numpy as np


def _time(n: int, steps: int, action_mode: str, planar: bool = True,
          sync: bool = False) -> tuple[float, float]:
    """(seconds for ``steps`` steps of n arms, converged fraction); the first step untimed.
    ``sync``: Gymnasium's SyncVectorEnv over single envs instead of the batched env."""
    import gymnasium as gym

    from softarm_gym.vector import BatchedReachVectorEnv

    env = gym.make_vec("SoftArm/OctArmReach-v0", num_envs=n, vectorization_mode="sync",
                       action_mode=action_mode, planar=planar) if sync else \
        BatchedReachVectorEnv(num_envs=n, action_mode=action_mode, planar=planar)
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


def run(sizes=(4, 16, 256, 1024, 4096), steps: int = 100, action_mode: str = "delta",
        repeats: int = 3, progress=None) -> list[dict]:
    """Time ``steps`` steps of :class:`~softarm_gym.vector.BatchedReachVectorEnv` per size,
    with numba's full thread pool and with one thread, alternately ``repeats`` times (the
    thread policy, :class:`solver.ThreadPolicy`, measures both ways in its first steps and
    runs the faster: those steps are timed too). Each row reports the medians; a shared
    machine's load moves single runs by tens of per cent.

    Random actions in ``delta`` mode (each step changes every pressure by up to 10 % of
    p_max, as a policy exploring does); the first step after reset is not timed, an
    autoreset (after the env's 100-step episodes) is.

    Returns:
        One dict a size: ``{"num_envs", "steps", "threads", "seconds", "env_steps_per_s",
        "one_thread_env_steps_per_s", "runs_env_steps_per_s",
        "runs_one_thread_env_steps_per_s", "converged_fraction"}`` (``seconds``: the time of
        ``steps`` steps at the median rate; ``converged_fraction``: over the full-pool runs).
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1; got {repeats!r}")
    threads = numba.get_num_threads()
    rows = []
    for n in sizes:
        rates, rates_one, converged = [], [], []
        for _ in range(repeats):
            seconds, fraction = _time(n, steps, action_mode)
            rates.append(n * steps / seconds)
            converged.append(fraction)
            numba.set_num_threads(1)
            try:
                rates_one.append(n * steps / _time(n, steps, action_mode)[0])
            finally:
                numba.set_num_threads(threads)
        rate = float(np.median(rates))
        rows.append({"num_envs": n, "steps": steps, "threads": threads, "seconds": n * steps / rate,
                     "env_steps_per_s": rate, "one_thread_env_steps_per_s": float(np.median(rates_one)),
                     "runs_env_steps_per_s": rates, "runs_one_thread_env_steps_per_s": rates_one,
                     "converged_fraction": float(np.mean(converged))})
        if progress:
            progress(f"batched vector env {n}")
    return rows


CONTACT_CASES = (("reach", "SoftArm/OctArmReach-v1", {}),
                 ("wrap", "SoftArm/OctArmWrap-v1", {}),
                 ("wrap delta", "SoftArm/OctArmWrap-v1", {"action_mode": "delta"}),
                 ("obstacle reach", "SoftArm/OctArmObstacleReach-v0", {}))
"""The batched envs :func:`run_contact` times side by side (name, ID, kwargs): reach, wrap
with its registered absolute actions and with delta actions, obstacle reach (delta)."""


BATCHED_CONTACT_TARGET = 0.25
"""Issue target: batched wrap and obstacle reach at least this share of batched reach's
aggregate arm-steps/s at 1024 arms."""


def run_contact(n: int = 1024, steps: int = 40, repeats: int = 3, cases=CONTACT_CASES,
                progress=None) -> dict:
    """Aggregate arm-steps/s of the batched contact envs beside the batched reach env, in one
    process, their timed blocks interleaved (reach, wrap, ..., reach, wrap, ...) so that each
    sees the same machine load; ratios to reach.

    Each env is made once with ``n`` arms (and episodes longer than the run: resets are timed
    apart, as seconds per copy — a contact env resets each copy by its single env's solver
    calls), reset with seed 0 and stepped once untimed; then ``repeats`` rounds of ``steps``
    random actions (uniform in [−1, 1], seeded) per env. numba's full thread pool.

    Returns:
        dict: ``{"num_envs", "steps", "repeats", "threads", "rows": [{"name", "env_id", "kwargs",
        "env_steps_per_s" (median), "runs_env_steps_per_s", "ratio_to_reach",
        "converged_fraction", "reset_s_per_copy"}]}``.
    """
    import gymnasium as gym

    import softarm_gym  # noqa: F401  (registers the IDs)

    envs, rows = [], []
    for name, env_id, kwargs in cases:
        start = time.perf_counter()
        env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                           max_episode_steps=10 ** 9, **kwargs)
        made = time.perf_counter()
        env.reset(seed=0)
        reset = time.perf_counter() - made
        actions = np.random.default_rng(0).uniform(-1, 1, (repeats * steps + 1, n,
                                                           env.single_action_space.shape[0]))
        env.step(actions[0])
        envs.append((env, actions[1:]))
        rows.append({"name": name, "env_id": env_id, "kwargs": kwargs, "runs_env_steps_per_s": [],
                     "converged": 0, "reset_s_per_copy": reset / n, "make_s": made - start})
        if progress:
            progress(f"batched {name} env, {n} arms: made and reset")
    for r in range(repeats):
        for (env, actions), row in zip(envs, rows):
            block = actions[r * steps:(r + 1) * steps]
            start = time.perf_counter()
            for a in block:
                *_, info = env.step(a)
                row["converged"] += int(info["converged"].sum())
            row["runs_env_steps_per_s"].append(n * steps / (time.perf_counter() - start))
        if progress:
            progress(f"batched contact envs, round {r + 1} of {repeats}")
    for env, _ in envs:
        env.close()
    reach = float(np.median(rows[0]["runs_env_steps_per_s"]))
    for row in rows:
        row["env_steps_per_s"] = float(np.median(row["runs_env_steps_per_s"]))
        row["ratio_to_reach"] = row["env_steps_per_s"] / reach
        row["converged_fraction"] = row.pop("converged") / (n * steps * repeats)
    return {"num_envs": n, "steps": steps, "repeats": repeats, "threads": numba.get_num_threads(),
            "rows": rows}


def format_contact_table(result: dict) -> str:
    lines = [f"| batched env, {result['num_envs']} arms (random actions, {result['threads']} threads) "
             "| arm-steps/s (median) | × reach | converged | reset (ms per copy) |",
             "|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['name']} ({r['env_id']}) | {r['env_steps_per_s']:,.0f} | "
                     f"{r['ratio_to_reach']:.2f} | {100 * r['converged_fraction']:.2f} % | "
                     f"{1e3 * r['reset_s_per_copy']:.2f} |")
    return "\n".join(lines)


def run_spatial(sizes=(4, 16, 64), steps: int = 20, action_mode: str = "delta",
                progress=None) -> list[dict]:
    """The batched env with ``planar=False`` (:class:`solver.SpatialBatchStepper`) against
    SyncVectorEnv over single 3D envs, side by side per size (OctArm V reach, ``true``
    observations, random ``delta`` actions, the first step untimed)."""
    rows = []
    for n in sizes:
        seconds, converged = _time(n, steps, action_mode, planar=False)
        sync, _ = _time(n, steps, action_mode, planar=False, sync=True)
        rows.append({"num_envs": n, "steps": steps, "threads": numba.get_num_threads(),
                     "env_steps_per_s": n * steps / seconds,
                     "sync_env_steps_per_s": n * steps / sync, "converged_fraction": converged})
        if progress:
            progress(f"batched vector env 3D {n}")
    return rows


def format_spatial_table(rows: list[dict]) -> str:
    lines = ["| batched vector env, 3D (true obs., delta actions) | env-steps/s (aggregate) "
             "| SyncVectorEnv | converged |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['num_envs']} arms | {r['env_steps_per_s']:,.0f} ({r['threads']} threads) | "
                     f"{r['sync_env_steps_per_s']:,.0f} | {100 * r['converged_fraction']:.2f} % |")
    return "\n".join(lines)


def format_table(rows: list[dict]) -> str:
    lines = ["| batched vector env (true obs., delta actions) | env-steps/s (aggregate) "
             "| on one thread | converged |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['num_envs']} arms | {r['env_steps_per_s']:,.0f} ({r['threads']} threads) | "
                     f"{r['one_thread_env_steps_per_s']:,.0f} | {100 * r['converged_fraction']:.2f} % |")
    return "\n".join(lines)


def sb3_adapter(sizes=(8, 16, 64), threads=(1, 2), steps: int = 100) -> list[dict]:
    """Steps per second of :class:`softarm_gym.sb3.BatchedVecEnv` (batched step plus the
    per-copy SB3 infos), per number of arms and of numba threads, wall and CPU time.

    Random delta actions; the first step after reset is not timed. numba's thread count is
    restored afterwards.
    """
    import numba

    from softarm_gym.sb3 import BatchedVecEnv

    before = numba.get_num_threads()
    rows = []
    try:
        for k in threads:
            numba.set_num_threads(k)
            for n in sizes:
                venv = BatchedVecEnv("SoftArm/OctArmReach-v0", n, action_mode="delta")
                venv.seed(0)
                venv.reset()
                actions = np.random.default_rng(0).uniform(-1, 1, (steps + 1, n, 6)).astype(np.float32)
                venv.step(actions[0])
                wall, cpu = time.perf_counter(), time.process_time()
                for a in actions[1:]:
                    venv.step(a)
                wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
                rows.append({"num_envs": n, "numba_threads": k, "steps": steps,
                             "env_steps_per_s": n * steps / wall, "env_steps_per_cpu_s": n * steps / cpu})
                venv.close()
    finally:
        numba.set_num_threads(before)
    return rows


def format_sb3_table(rows: list[dict]) -> str:
    lines = ["| SB3 adapter (BatchedVecEnv, delta actions) | numba threads | env-steps/s | per CPU-second |",
             "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['num_envs']} arms | {r['numba_threads']} | {r['env_steps_per_s']:,.0f} | "
                     f"{r['env_steps_per_cpu_s']:,.0f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    import argparse
    import os

    from softarm_gym.files import write_json

    parser = argparse.ArgumentParser(prog="python -m softarm_gym.benchmarks.vector_bench",
                                     description="SB3 adapter steps per second by arms and numba threads")
    parser.add_argument("--json", default=None, help="also write the rows and the load average to this file")
    args = parser.parse_args()
    result = {"load_before": os.getloadavg(), "rows": sb3_adapter()}
    result["load_after"] = os.getloadavg()
    print(format_sb3_table(result["rows"]))
    if args.json:
        write_json(args.json, result)
