"""``softarm warmup``: compile every numba kernel the solver and the registered environments use
into the on-disk cache, in parallel processes.

Nothing needs it: a kernel compiles on first use, into the same cache, with one line on stderr
saying so (:func:`solver.jit.announce_compiles`), so ``make demo`` compiles only what the demo
runs. ``make test`` runs it first, so that the test workers load machine code instead of each
compiling the same kernels; a user who wants every first episode fast runs it once
(``softarm bench --first-episode`` measures the difference).

The work is split into groups of kernels (:data:`GROUPS`) run by a pool of ``--jobs``
processes (default: one per core): the solver's own kernels (planar, warm-started, spatial,
batched), the reach and track envs in every observation mode with Table 4.3 sensor noise and
a payload range (and spatial reach with every estimator that supports 3-D), the planar
contact envs (wrap, obstacle reach, grasp), the 3-D wrap envs, and the batched vector envs
(reach, and the contact rows' kernels through the batched wrap, obstacle-reach and track envs).
Every registered ID is covered, deprecated ones included, but envs are built from their
registry entries directly, not through ``gym.make``: a warm-up asked for no ID, so it prints
no "out of date" warning. ``--clear`` first deletes every compiled file of the project's
kernels (a damaged or stale cache; damaged entries also heal on their own, see
:mod:`solver.jit`).
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

import solver
from softarm_gym.cli import UsageError
from softarm_gym.commands.long_jobs import check_outputs
from softarm_gym.files import atomic_write, json_text
from solver.jit import announce_compiles, clear_cache, record_compiles

NAME = "warmup"
HELP = "compile the numba kernels the solver and the registered envs use into the on-disk cache"

STEPS = 3
"""Steps per warm-up episode (each kernel needs one call per argument type)."""

KERNEL_MODULES = ("solver", "softarm_gym.sensing.kernels", "softarm_gym.envs.terms")
"""Modules whose import defines every project kernel (for ``--clear``)."""

GROUPS = ("spatial_contact", "reach", "contact", "batch_contact", "batch", "solver")
"""Warm-up groups, each one process's work (see :func:`warm_group`), in the order the pool
starts them. Compiling is most of the warm-up, and a kernel is compiled by the first group that
runs it, so the order decides both the balance and whether two processes compile one kernel at
once. ``spatial_contact`` (the 3-D contact kernels) starts first and keeps one process for most
of the run; the other compiles ``reach``, then ``contact`` (the planar contact stepper, its
row kernel and its Newton), then the batched contact envs' terms (``batch_contact``: their rows
run ``contact``'s row kernel on Python threads), and the batched reach kernels (``batch``),
and ``solver``'s, while the first process compiles the 3-D group. On an empty cache, 2 cores
(a fresh clone's ``softarm warmup --profile``, docs/bench/warmup_profile.json, the machine
~1.35× slower than when the groups took 225 s before the batched rows lost their ``prange``
kernel): spatial_contact 240 s in one process; reach 60 s, contact 153 s, batch_contact 4 s,
batch 20 s, solver 29 s in the other; 272 s in all. As one group, the two batched groups left
the second process running 50 s after the first had finished."""

_WIDE = solver.BatchStepper.PARALLEL_MIN

BATCHED = {
    "batch_contact": (("SoftArm/OctArmWrap-v2", 2), ("SoftArm/OctArmWrap-v2", _WIDE),
                      ("SoftArm/OctArmObstacleReach-v1", 2)),
    "batch": (("SoftArm/OctArmReach-v1", 2), ("SoftArm/OctArmReach-v1", _WIDE),
              ("SoftArm/OctArmTrack-v1", 2)),
}
"""(env_id, num_envs) of each batched group's vector-env episodes. Small batches run the
one-thread kernels, larger ones the parallel ones: both are warmed, for reach and for the
contact rows (wrap, obstacle reach: the recommended versions, with self-contact), and the track
task's terms."""


def add_arguments(p):
    p.add_argument("--quiet", action="store_true", help="no line per group on stderr")
    p.add_argument("--clear", action="store_true",
                   help="delete the cached kernels first, then compile them afresh")
    p.add_argument("--jobs", type=int, default=None,
                   help="processes compiling in parallel (default: one per core)")
    p.add_argument("--only", default=None, metavar="GROUP[,GROUP]",
                   help=f"compile only these groups, of {', '.join(GROUPS)}")
    p.add_argument("--profile", default=None, metavar="FILE.json",
                   help="write each group's compiles (kernel, seconds, seconds less the kernels it "
                        "compiled in turn) to this JSON file; run it on an empty cache (--clear)")


def cases() -> list[tuple[str, dict]]:
    """(env_id, env kwargs) of every env warm-up episode: each registered ID × observation mode
    (planar), and spatial reach with every estimator that supports 3-D."""
    import gymnasium as gym

    from softarm_gym.registry import env_ids
    from softarm_gym.sensing import ESTIMATORS

    ids = env_ids()
    out = [(env_id, {"observation": obs, "sensor_noise": "thesis", "payload_kg": (0.0, 0.1)})
           for env_id in ids for obs in ESTIMATORS]
    # Spatial: the reach IDs (ReachEnv; the contact tasks are planar only).
    out += [(env_id, {"observation": obs, "planar": False})
            for env_id in ids if gym.spec(env_id).entry_point == "softarm_gym.envs:ReachEnv"
            for obs in ESTIMATORS if obs != "inclinometer"]
    return out


def group_of(env_id: str, kwargs: dict) -> str:
    """The warm-up group whose process runs the case (env_id, kwargs) of :func:`cases`."""
    import gymnasium as gym

    spec = gym.spec(env_id)
    if spec.entry_point.endswith((":WrapEnv", ":ObstacleReachEnv", ":GraspEnv")):
        planar = kwargs.get("planar", spec.kwargs.get("planar", True))
        return "contact" if planar else "spatial_contact"
    return "reach"


def _solver_kernels() -> None:
    arm = solver.designs.octarm_v()
    scene = solver.Scene(base_angle_deg=45.0)
    p = np.full(6, 20 * solver.PSI)
    eq = solver.solve(arm, p, scene)
    solver.solve(arm, p * 1.1, scene, warm_start=eq)
    solver.solve(arm, np.array([20, 5, 0, 10, 0, 0, 0, 0, 0]) * solver.PSI, scene, planar=False)
    solver.solve_batch(arm, np.stack([p, p * 0.5]), scene)
    planar_snap_kernels()
    spatial_multiple_shooting_kernels()


def planar_snap_kernels() -> solver.Equilibrium:
    """A cold planar contact solve that snaps clear of its disc and of the arm itself (OctArm V
    horizontal, a disc below it, self-contact on): the general path's landing found by the fold
    scan, whose clearance tests run from Python (:mod:`solver.paths.shooting`) and which the
    warm-up's random episodes do not reach (one compiled on a user's first such snap after a
    warm-up). Returns the solve."""
    arm = solver.designs.octarm_v()
    stiffness = 98061.91107846839
    disc = solver.Disc((0.5700159379114514, -0.5864276060318443), 0.07517650045941565, stiffness)
    scene = solver.Scene(base_angle_deg=90.0, self_contact=stiffness, obstacles=(disc,))
    p = np.array([10022.412505394157, 643435.2292238332, 59174.79990378651, 582556.5226653588,
                  253644.84076263456, 655707.2635570455])
    return solver.solve(arm, p, scene)


def spatial_multiple_shooting_kernels() -> solver.Equilibrium:
    """A cold 3D solve that single shooting cannot take (OctArm V hanging from a base pointed
    straight down, a payload, every section bent out of the plane), which the solver hands to
    spatial multiple shooting (:mod:`solver.kernels.spatial_shooting`): no env reaches it in a
    few random steps, so it was compiled inside the first such solve of a user's (~20 s).
    Returns the solve."""
    arm = solver.designs.octarm_v()
    scene = solver.Scene(base_angle_deg=180.0, payload_kg=0.109)
    p = np.array([95.2, 44.4, 44.4, 0.0, 51.6, 51.6, 52.1, 89.7, 89.7]) * solver.PSI
    return solver.solve(arm, p, scene, planar=False)


def spatial_snap_kernels() -> list:
    """A 3D contact ramp that snaps (a curl pressed on a stiff skew cylinder slides along it
    past a fold) through the stepper: the general 3D contact path — its continuation, branch
    switch and relaxation — and the stepper's adoption of its result, which random warm-up
    episodes seldom reach (a 3D wrap's first snap otherwise compiled them inside a user's
    episode: ~50 s). Returns the steps' reports."""
    arm = solver.designs.octarm_v()
    cylinder = solver.Cylinder((0.10460203587953945, -0.5475680762119925, 0.0),
                               (0.28131600500456516, 0.3821969774030357, 0.8802197315399463),
                               0.060812627916281614, 324467.14)
    scene = solver.Scene(base_angle_deg=10.699935900401458, payload_kg=0.26209498971417583,
                         obstacles=(cylinder,))
    stepper = solver.Stepper(arm, scene, model="unshearable", planar=False)
    stepper.reset(np.zeros(arm.n_inputs(False)))
    return [stepper.step(np.array([0, 1, 1, 0, 1, 1, 0, 1, 1.0]) * arm.max_pressure * k / 7)
            for k in range(1, 8)]


def _episode(env, seed: int) -> None:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(STEPS):
        env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
    env.close()


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


def warm_group(group: str) -> float:
    """Compile one group's kernels in this process; returns the seconds taken.

    ``solver``: the solver's kernels on the named designs (cold, warm, spatial, batch);
    ``reach``, ``contact``, ``spatial_contact``: a short episode of each of their
    :func:`cases` (``spatial_contact`` also a 3D ramp that snaps, :func:`spatial_snap_kernels`);
    ``batch_contact``, ``batch``: the batched vector envs of :data:`BATCHED` (one-thread and
    parallel sizes), ``batch`` also both batch kernels both ways (:func:`batch_kernels`).
    """
    from softarm_gym.registry import make_unwrapped

    if group not in GROUPS:
        raise ValueError(f"unknown warm-up group {group!r}; groups: {', '.join(GROUPS)}")
    start = time.perf_counter()
    if group == "solver":
        _solver_kernels()
    elif group in BATCHED:
        import gymnasium as gym

        for env_id, num_envs in BATCHED[group]:
            _episode(gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point"),
                     seed=0)
        if group == "batch":
            batch_kernels()
    else:
        for k, (env_id, kwargs) in enumerate(cases()):
            if group_of(env_id, kwargs) == group:
                _episode(make_unwrapped(env_id, **kwargs), seed=k)
        if group == "spatial_contact":
            spatial_snap_kernels()
    return time.perf_counter() - start


def _warm_group_recorded(group: str, quiet: bool) -> tuple[str, float, list[dict], int]:
    """:func:`warm_group` with its compiles recorded (:func:`solver.jit.record_compiles`), and
    this process's id; ``quiet``: no line of its own on the first compile (the warm-up says
    what it compiles)."""
    if quiet:
        announce_compiles(False)
    with record_compiles() as compiles:
        seconds = warm_group(group)
    return group, seconds, compiles, os.getpid()


def warm(progress=None, groups=GROUPS, jobs: int = 1, profile: dict | None = None) -> float:
    """Compile the kernels of ``groups``, ``jobs`` processes at a time (1: in this process);
    ``progress(message)`` after each group. With a dict ``profile``, each group's entry is set
    to its seconds, the process that ran it and its compiles (:func:`solver.jit.record_compiles`,
    the costliest first). Returns the seconds taken."""
    start = time.perf_counter()

    workers: dict[int, int] = {}  # process id → 0, 1, ... in the order they first report

    def done(group, seconds, compiles, pid):
        if profile is not None:
            worker = workers.setdefault(pid, len(workers))
            profile[group] = {"seconds": seconds, "process": worker, "compile_seconds": sum(
                c["exclusive_seconds"] for c in compiles), "compiles": sorted(
                compiles, key=lambda c: -c["exclusive_seconds"])}
        if progress:
            progress(f"{group} ({seconds:.1f} s)")

    if jobs <= 1:
        for group in groups:
            done(*_warm_group_recorded(group, quiet=False))
        return time.perf_counter() - start
    # spawn: a fork would copy this process's numba and thread-pool state into the workers.
    with ProcessPoolExecutor(max_workers=min(jobs, len(groups)),
                             mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(_warm_group_recorded, group, True) for group in groups]
        for future in as_completed(futures):
            done(*future.result())
    return time.perf_counter() - start


def run(args) -> int:
    groups = GROUPS
    if args.only:
        groups = tuple(g.strip() for g in args.only.split(","))
        unknown = [g for g in groups if g not in GROUPS]
        if unknown:
            raise UsageError(f"--only: unknown group(s) {', '.join(unknown)}; groups: {', '.join(GROUPS)}")
    jobs = (os.cpu_count() or 1) if args.jobs is None else args.jobs
    if jobs < 1:
        raise UsageError(f"--jobs must be at least 1; got {args.jobs}")
    check_outputs(args, files=("profile",))
    if args.clear:
        for module in KERNEL_MODULES:
            importlib.import_module(module)
        removed = clear_cache()
        folders = ", ".join(sorted({str(p.parent) for p in removed}))
        print(f"removed {len(removed)} cached kernel files" + (f" from {folders}" if folders else ""))

    def progress(message):
        print(f"[warmup] {message}", file=sys.stderr, flush=True)

    if not args.quiet:
        progress(f"compiling the kernels of {', '.join(groups)} in {min(jobs, len(groups))} process(es)")
    announce_compiles(False)
    profile = None if args.profile is None else {}
    seconds = warm(None if args.quiet else progress, groups=groups, jobs=jobs, profile=profile)
    print(f"numba kernels ready in {seconds:.1f} s")
    if profile is not None:
        with atomic_write(args.profile) as fh:
            command = ("softarm warmup" + (" --clear" if args.clear else "")
                       + (f" --only {','.join(groups)}" if args.only else "")
                       + f" --jobs {jobs} --profile {args.profile}")
            fh.write(json_text({"command": command, "jobs": jobs, "seconds": seconds,
                                "groups": profile}))
        costliest = sorted((c for g in profile.values() for c in g["compiles"]),
                           key=lambda c: -c["exclusive_seconds"])[:3]
        print(f"compile profile written to {args.profile}; costliest: " + ", ".join(
            f"{c['kernel']} {c['exclusive_seconds']:.1f} s" for c in costliest))
    return 0
