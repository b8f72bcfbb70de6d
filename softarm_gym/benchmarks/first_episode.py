"""First-episode speed: how much of a fresh process's first episode goes to loading or
compiling numba kernels.

Each registered ID runs in its own fresh Python process. Imports (gymnasium, softarm_gym
and the env's module, with numba, scipy and matplotlib) are timed separately; then
``gym.make(env_id)`` and the first episode (reset and ``max_episode_steps`` steps of
seeded random absolute actions, the worst case of ``softarm bench --env``) are timed, then
``episodes`` more episodes of the same env give the steady speed. With the kernels in
numba's on-disk cache (``softarm warmup``) the first episode only loads machine code; with
an empty cache (``cold``: ``NUMBA_CACHE_DIR`` pointed at a new folder) it compiles them.
The goal is a first episode at >= 50 % of the steady speed after ``softarm warmup``.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tempfile
import time

GOAL = 0.5
"""Target ratio of first-episode to steady steps/s after ``softarm warmup``."""


def measure(env_id: str, episodes: int = 3, seed: int = 0) -> dict:
    """Time the first and ``episodes`` further episodes of ``env_id`` in this process.

    Returns:
        ``import_seconds`` (gymnasium, softarm_gym and the env's module: not timed as part of
        the episode), ``first_seconds`` and ``first_steps_per_s`` (``gym.make`` + reset + steps
        of episode 1), ``steady_steps_per_s`` (episodes 2 … episodes + 1, resets included),
        ``first_overhead_seconds`` (what episode 1 took beyond a steady episode) and ``steps``
        per episode.
    """
    start = time.perf_counter()
    import gymnasium as gym
    import numpy as np

    import softarm_gym  # noqa: F401  (registers the IDs)
    from softarm_gym.registry import make

    importlib.import_module(gym.spec(env_id).entry_point.split(":")[0])
    imports = time.perf_counter() - start
    rng = np.random.default_rng(seed)

    def episode(env, episode_seed):
        env.reset(seed=episode_seed)
        steps, done = 0, False
        while not done:
            action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
            _, _, terminated, truncated, _ = env.step(action)
            steps += 1
            done = terminated or truncated
        return steps

    start = time.perf_counter()
    env = make(env_id, quiet=True)
    steps = episode(env, seed)
    first = time.perf_counter() - start
    start = time.perf_counter()
    steady_steps = sum(episode(env, seed + 1 + k) for k in range(episodes))
    steady = time.perf_counter() - start
    env.close()
    steady_rate = steady_steps / steady
    return {"import_seconds": imports, "first_seconds": first, "first_steps_per_s": steps / first,
            "steps": steps, "steady_steps_per_s": steady_rate,
            "first_overhead_seconds": first - steps / steady_rate}


def _fresh_process(env_id: str, episodes: int, cache_dir: str | None) -> dict:
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    code = (f"import json; from softarm_gym.benchmarks.first_episode import measure; "
            f"print(json.dumps(measure({env_id!r}, episodes={episodes})))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"first-episode benchmark of {env_id} failed: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def run(ids=None, episodes: int = 3, cold: bool = False, progress=None) -> dict:
    """The first-episode table: one fresh process per ID (and per mode).

    Args:
        ids: environment IDs (default every registered ``SoftArm/*`` ID).
        episodes: steady episodes after the first.
        cold: also run each ID with an empty numba cache (compiles everything: slow).
        progress: a callable taking a message, or None.

    Returns:
        A dict,

        ``{"goal": GOAL, "rows": {env_id: {"warm": measure(...), "ratio": first/steady,
        ["cold": measure(...)]}}}``.
    """
    from softarm_gym.benchmarks.envs import env_ids

    rows = {}
    for env_id in ids or env_ids():
        if progress:
            progress(f"first episode of {env_id} in a fresh process")
        row = {"warm": _fresh_process(env_id, episodes, None)}
        row["ratio"] = row["warm"]["first_steps_per_s"] / row["warm"]["steady_steps_per_s"]
        if cold:
            with tempfile.TemporaryDirectory(prefix="softarm-cold-cache-") as cache:
                row["cold"] = _fresh_process(env_id, episodes, cache)
        rows[env_id] = row
    return {"goal": GOAL, "rows": rows}


def format_table(result: dict) -> str:
    """A text table of :func:`run`'s result."""
    cold = any("cold" in row for row in result["rows"].values())
    head = (f"{'environment':24s} {'import s':>8s} {'first ep. s':>11s} {'overhead s':>10s} {'first/s':>8s} "
            f"{'steady/s':>9s} {'ratio':>6s}")
    head += f" {'cold first ep. s':>16s} {'cold first/s':>12s}" if cold else ""
    lines = [head + f"  (fresh process per ID after softarm warmup; goal ratio >= {result['goal']:.0%})"]
    for env_id, row in result["rows"].items():
        warm = row["warm"]
        line = (f"{env_id:24s} {warm['import_seconds']:8.2f} {warm['first_seconds']:11.2f} "
                f"{warm['first_overhead_seconds']:10.2f} {warm['first_steps_per_s']:8.0f} "
                f"{warm['steady_steps_per_s']:9.0f} {row['ratio']:6.0%}")
        if cold:
            line += f" {row['cold']['first_seconds']:16.1f} {row['cold']['first_steps_per_s']:12.1f}"
        lines.append(line + ("  ok" if row["ratio"] >= result["goal"] else "  below goal"))
    return "\n".join(lines)
