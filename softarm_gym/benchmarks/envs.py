"""Environment benchmark: steps per second per registered ID and observation mode.

Each case is timed as a user runs it: ``gym.make(env_id, observation=...)`` with random
(seeded) actions, resets included whenever an episode ends, after a warm-up that loads
the numba kernels. ``single`` is one env in this process, the median of
:data:`SINGLE_REPEATS` runs of different seeds (one short run on a shared machine can read
tens of per cent low); ``vector`` an
``AsyncVectorEnv`` with one worker per core (steps counted over all workers). The reach IDs
of :data:`SPATIAL_IDS` are also timed in 3D (``planar=False``, their registered delta
actions), with every observation, and the IDs of :data:`SELF_CONTACT_IDS` with
``self_contact=True``.
"""

from __future__ import annotations

import os
import time

import gymnasium as gym
import numpy as np

import softarm_gym  # noqa: F401  (registers the IDs)
from softarm_gym import registry
from softarm_gym.registry import make
from softarm_gym.sensing import ESTIMATORS

TARGETS = {"reach_true": 5000.0, "estimator": 1000.0, "wrap": 500.0, "reach_true_3d": 3000.0}
"""Issue targets (steps/s): OctArmReach with ``true`` observations, any estimator, wrap (and
obstacle reach and grasp, the other contact tasks), 3D reach with ``true`` observations."""

SPATIAL_IDS = ("SoftArm/OctArmReach-v1", "SoftArm/CTReach-v1")
"""Reach IDs the benchmark also times in 3D (``planar=False``)."""

SELF_CONTACT_IDS = ("SoftArm/OctArmReach-v1", "SoftArm/OctArmWrap-v1", "SoftArm/CTWrap-v1")
"""IDs the benchmark also times with ``self_contact=True`` (``true`` observations): what
self-contact costs where it is asked for."""

QUICK_OBSERVATIONS = ("true", "constant_curvature")

SINGLE_REPEATS = 3
"""Timed runs (seeds 0, 1, ...) of each single-env case; the row reports their median."""


def env_ids() -> tuple[str, ...]:
    """Registered soft-arm environment IDs (out-of-date versions included: the benchmark times them)."""
    return registry.env_ids()


def target_for(env_id: str, observation: str, planar: bool = True) -> float:
    """The issue's steps/s target for a case."""
    if "Wrap" in env_id or "ObstacleReach" in env_id or "Grasp" in env_id:
        return TARGETS["wrap"]
    if observation == "true" and "OctArm" in env_id:
        return TARGETS["reach_true"] if planar else TARGETS["reach_true_3d"]
    return TARGETS["estimator"]


def _time_steps(env, n_steps: int, seed: int) -> float:
    """Steps per second of ``env`` (single or vector) over ``n_steps`` random steps."""
    rng = np.random.default_rng(seed)
    space = env.single_action_space if hasattr(env, "single_action_space") else env.action_space
    n_envs = getattr(env, "num_envs", 1)
    shape = (n_envs, *space.shape) if n_envs > 1 else space.shape
    actions = rng.uniform(-1.0, 1.0, (n_steps, *shape)).astype(np.float32)
    env.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if n_envs == 1 and (terminated or truncated):
            env.reset()
    return n_steps * n_envs / (time.perf_counter() - start)


def run(quick: bool = False, n_steps: int | None = None, n_envs: int | None = None,
        observations=None, ids=None, progress=None) -> dict:
    """Time every (ID, observation) case, single and vectorised, the 3D cases of the IDs in
    :data:`SPATIAL_IDS` and the self-contact cases of :data:`SELF_CONTACT_IDS`.

    Args:
        quick: fewer steps and only the ``true`` and ``constant_curvature`` observations.
        n_steps: timed steps per case (default 300, quick 60).
        n_envs: workers of the vectorised case (default: the CPU count, at least 2).
        observations: observation modes to time (default all, or the quick set).
        ids: environment IDs to time (default all registered).
        progress: optional callable taking a status string.

    Returns:
        A dict,

        ``{"cases": [{"env_id", "observation", "planar", "self_contact", "single_steps_per_s",
        "single_runs_steps_per_s", "vector_steps_per_s", "n_envs", "target_steps_per_s"}],
        "n_steps": ..., "n_envs": ...}``; ``single_steps_per_s`` is the median of the
        :data:`SINGLE_REPEATS` runs in ``single_runs_steps_per_s``.
    """
    n_steps = n_steps or (60 if quick else 300)
    if n_steps < 1:
        raise ValueError(f"n_steps must be >= 1; got {n_steps}")
    n_envs = n_envs or max(2, os.cpu_count() or 2)
    observations = tuple(observations or (QUICK_OBSERVATIONS if quick else ESTIMATORS))
    ids = tuple(ids or env_ids())
    for obs in observations:
        if obs not in ESTIMATORS:
            raise ValueError(f"unknown observation {obs!r}; choose from {', '.join(ESTIMATORS)}")
    cases = []
    plan = [(env_id, obs, {}) for env_id in ids for obs in observations]
    plan += [(env_id, obs, {"planar": False}) for env_id in ids if env_id in SPATIAL_IDS
             for obs in observations]
    plan += [(env_id, "true", {"self_contact": True}) for env_id in ids
             if env_id in SELF_CONTACT_IDS and "true" in observations]
    for env_id, obs, extra in plan:
        kwargs = {"observation": obs, **extra}
        if progress:
            progress(f"{env_id} observation={obs}{''.join(f' {k}={v}' for k, v in extra.items())}")
        env = make(env_id, quiet=True, **kwargs)
        planar = env.unwrapped.planar  # a 3D id (OctArmWrap3D-v0) is spatial without the kwarg
        _time_steps(env, min(20, n_steps), seed=SINGLE_REPEATS)  # warm-up: kernels, first resets
        runs = [_time_steps(env, n_steps, seed=seed) for seed in range(SINGLE_REPEATS)]
        single = float(np.median(runs))
        env.close()
        vec = gym.vector.AsyncVectorEnv([lambda i=env_id, k=kwargs: make(i, quiet=True, **k)] * n_envs)
        try:
            _time_steps(vec, min(10, n_steps), seed=1)
            vector = _time_steps(vec, max(1, n_steps // n_envs), seed=0)
        finally:
            vec.close()
        cases.append({"env_id": env_id, "observation": obs, "planar": planar,
                      "self_contact": bool(extra.get("self_contact", False)),
                      "single_steps_per_s": single, "single_runs_steps_per_s": runs,
                      "vector_steps_per_s": vector,
                      "n_envs": n_envs, "target_steps_per_s": target_for(env_id, obs, planar)})
    resets = [reset_times(env_id) for env_id in ids if env_id in RESET_IDS]
    return {"cases": cases, "n_steps": n_steps, "n_envs": n_envs, "resets": resets}


FRICTION = 0.7
"""μ of the friction cases: rubber on common objects (docs/design.md §9.1)."""

CONTACT_RATIO_CASES = (("free reach", "SoftArm/OctArmReach-v1", {}),
                       ("wrap", "SoftArm/OctArmWrap-v1", {}),
                       ("wrap delta", "SoftArm/OctArmWrap-v1", {"action_mode": "delta"}),
                       ("obstacle reach", "SoftArm/OctArmObstacleReach-v0", {}),
                       ("grasp", "SoftArm/OctArmGrasp-v0", {}),
                       ("wrap v2", "SoftArm/OctArmWrap-v2", {}),
                       ("obstacle reach v1", "SoftArm/OctArmObstacleReach-v1", {}),
                       ("grasp v1", "SoftArm/OctArmGrasp-v1", {}),
                       ("reach self-contact", "SoftArm/OctArmReach-v1", {"self_contact": True}),
                       ("3D reach", "SoftArm/OctArmReach-v1", {"planar": False}),
                       ("3D wrap", "SoftArm/OctArmWrap3D-v0", {}),
                       ("3D wrap v1", "SoftArm/OctArmWrap3D-v1", {}),
                       ("wrap friction", "SoftArm/OctArmWrap-v1", {"friction": FRICTION}),
                       ("wrap delta friction", "SoftArm/OctArmWrap-v1",
                        {"action_mode": "delta", "friction": FRICTION}),
                       ("obstacle reach friction", "SoftArm/OctArmObstacleReach-v0",
                        {"friction": FRICTION}),
                       ("3D wrap friction", "SoftArm/OctArmWrap3D-v0", {"friction": FRICTION}))
"""The single-env cases :func:`contact_ratios` times against their unit step: name, ID,
kwargs (``true`` observations, random actions): the issue's IDs, and the recommended
versions, whose self-contact is on (``wrap v2``, ``obstacle reach v1``, ``grasp v1``), and the
recommended 3D wrap (``3D wrap v1``: friction and delta actions; 3D has no self-contact). The
unit is a free ``OctArmReach-v1`` step (the first case) unless :data:`RATIO_UNITS` names
another case. A case with ``friction`` is also timed against the same case without it
(docs/design.md §9.1)."""

RATIO_UNITS = {"3D wrap": "3D reach", "3D wrap v1": "3D reach", "3D wrap friction": "3D reach"}
"""Case name → the case whose step is its unit (the issue holds 3D wrap to a 3D reach step)."""

CONTACT_TARGETS = {"wrap": 4.0, "obstacle reach": 4.0, "grasp": 6.0, "reach self-contact": 1.5,
                   "3D wrap": 6.0, "wrap v2": 4.0, "obstacle reach v1": 4.0, "grasp v1": 6.0,
                   "3D wrap v1": 6.0}
"""Issue targets: the most a case's step may cost, as a multiple of its unit step (a
recommended version is held to its task's)."""


def contact_ratios(n_steps: int = 300, rounds: int = 7, cases=CONTACT_RATIO_CASES, progress=None) -> dict:
    """Single-env steps/s of the contact cases and of their unit steps, in one process,
    interleaved (every case once per round, ``rounds`` rounds of seeds 0, 1, ...; the unit
    cases run 3× the steps, being faster), and each case's cost as a multiple of its unit
    step (:data:`RATIO_UNITS`; default the free ``OctArmReach-v1`` step, the first case):
    median unit steps/s ÷ median case steps/s.

    Seven rounds by default: a round's 300 steps are a few episodes of one seed, whose cost
    varies with what they meet (snaps, resets), and with three rounds an obstacle-reach row's
    median moved 11 → 18 free steps between two runs of one tree (rounds 1,811 to 3,824 steps/s).

    Returns:
        dict: ``{"n_steps", "rounds", "rows": [{"name", "env_id", "kwargs", "steps_per_s",
        "runs_steps_per_s", "unit", "times_unit", "times_free_step"}]}``; a friction case's row
        also has ``"times_frictionless"``: the same case without friction's steps/s over its own.
    """
    names = [name for name, _, _ in cases]
    units = {name: RATIO_UNITS.get(name, names[0]) for name in names}
    missing = sorted({u for u in units.values() if u not in names})
    if missing:
        raise ValueError(f"unit case(s) {', '.join(missing)} missing from the cases")
    envs = [gym.make(env_id, **kwargs) for _, env_id, kwargs in cases]
    for env in envs:
        _time_steps(env, 20, seed=rounds)  # warm-up: kernels, first resets
    runs = [[] for _ in cases]
    for r in range(rounds):
        for k, env in enumerate(envs):
            runs[k].append(_time_steps(env, 3 * n_steps if names[k] in units.values() else n_steps, seed=r))
        if progress:
            progress(f"single-env contact ratios, round {r + 1} of {rounds}")
    for env in envs:
        env.close()
    median = {name: float(np.median(rates)) for name, rates in zip(names, runs)}
    rows = [{"name": name, "env_id": env_id, "kwargs": kwargs, "steps_per_s": median[name],
             "runs_steps_per_s": rates, "unit": units[name], "times_unit": median[units[name]] / median[name],
             "times_free_step": median[names[0]] / median[name]}
            for (name, env_id, kwargs), rates in zip(cases, runs)]
    for row in rows:
        if "friction" in row["kwargs"]:
            plain = {k: v for k, v in row["kwargs"].items() if k != "friction"}
            twin = [r for r in rows if r["env_id"] == row["env_id"] and r["kwargs"] == plain]
            if twin:
                row["times_frictionless"] = twin[0]["steps_per_s"] / row["steps_per_s"]
    return {"n_steps": n_steps, "rounds": rounds, "rows": rows}


def format_ratio_table(result: dict) -> str:
    lines = ["| single env (random actions, true obs.) | steps/s (median) | × a free OctArmReach-v1 step "
             "| × its unit step | × the same without friction (target <= 1.5) |",
             "|---|---|---|---|---|"]
    for r in result["rows"]:
        extra = "".join(f" {k}={v}" for k, v in r["kwargs"].items())
        frictionless = f"{r['times_frictionless']:.2f}" if "times_frictionless" in r else ""
        lines.append(f"| {r['env_id']}{extra} | {r['steps_per_s']:,.0f} | {r['times_free_step']:.2f} | "
                     f"{r['times_unit']:.2f} ({r['unit']}) | {frictionless} |")
    return "\n".join(lines)


RESET_IDS = ("SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0")
"""IDs whose resets are timed with and without domain randomisation."""
RANDOMIZATION = {"wind_angle_deg": 2.0, "youngs_modulus_rel": 0.1}
"""The randomisation of the reset benchmark (braid angle ± 2°, moduli ± 10 %)."""


def reset_times(env_id: str, n_resets: int = 200) -> dict:
    """Median reset time (s) of ``gym.make(env_id)`` without and with :data:`RANDOMIZATION`,
    the two envs reset alternately (seeds 0, 1, ...) so both see the same machine load.

    Returns:
        A dict,

        ``{"env_id", "plain_s", "randomized_s", "ratio", "n_resets"}``.
    """
    envs = [make(env_id, quiet=True), make(env_id, quiet=True, randomization=RANDOMIZATION)]
    times = [[], []]
    for seed in range(-20, n_resets):  # 20 warm-up resets (kernels, nominal caches)
        for k, env in enumerate(envs):
            start = time.perf_counter()
            env.reset(seed=seed + 20)
            if seed >= 0:
                times[k].append(time.perf_counter() - start)
    plain, randomized = (float(np.median(t)) for t in times)
    return {"env_id": env_id, "plain_s": plain, "randomized_s": randomized,
            "ratio": randomized / plain, "n_resets": n_resets}


def format_table(result: dict) -> str:
    """The benchmark as a text table."""
    lines = [f"{'environment':24s} {'observation':20s} {'single/s':>9s} "
             f"{'vector/s':>9s} {'target/s':>9s}  (vector: {result['n_envs']} async workers, "
             f"{result['n_steps']} steps per case)"]
    for c in result["cases"]:
        met = "ok" if c["single_steps_per_s"] >= c["target_steps_per_s"] else "below"
        name = c["env_id"] + ("" if c.get("planar", True) else " 3D") \
            + (" self" if c.get("self_contact") else "")
        lines.append(f"{name:24s} {c['observation']:20s} {c['single_steps_per_s']:9.0f} "
                     f"{c['vector_steps_per_s']:9.0f} {c['target_steps_per_s']:9.0f}  {met}")
    if result.get("resets"):
        lines += ["", f"reset (median of {result['resets'][0]['n_resets']}, alternating)   "
                      "plain ms  randomized ms  ratio (target <= 2)"]
        for r in result["resets"]:
            lines.append(f"{r['env_id']:34s} {r['plain_s'] * 1e3:8.3f} {r['randomized_s'] * 1e3:14.3f} "
                         f"{r['ratio']:6.2f}")
    return "\n".join(lines)
