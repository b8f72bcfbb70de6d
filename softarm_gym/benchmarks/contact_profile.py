"""Where a contact step's time goes (``softarm bench --contact-profile``).

Each case is an env stepped as a user steps it (``gym.make``, seeded random actions, resets
when an episode ends), after a warm-up, in one process beside a free ``OctArmReach-v1``
step (the unit of the ratios), with the share of its time spent in resets (which solve the
episode's targets and placements). Two runs of the same seeded steps: a plain one for the
speed, and one under ``cProfile`` for the split of the time between

* ``lean kernels`` — the steppers' one-call paths (the guarded lean planar kernel, the lean
  contact kernel, their batch rows);
* ``continuation`` — the general path's quasi-static ramps (planar and spatial contact
  kernels, the free kernels' continuation);
* ``snap relaxation`` — energy minimisation where a path ends at a fold (L-BFGS, scipy);
* ``other kernels`` — every other numba kernel (grid checks, observations);
* ``solver Python`` and ``env Python`` — the rest, by where it runs.

The profiler inflates Python's share (it charges each Python call); the speed and the per-path
times come from the plain run. Per step: which path took it (``Stepper.last_path``), its time
by path, the median of its iterations by path (``StepReport.iterations``: a lean contact
step's passes; the general path's Newton iterations, continuation included), and for lean
contact steps the passes they made, with the cost of a residual pass and of a Jacobian pass at
a contact state and the share of RK4 rows refined near an obstacle (``Stepper.pass_costs``).
"""

from __future__ import annotations

import cProfile
import pstats
import time
from collections import Counter, defaultdict

import gymnasium as gym
import numpy as np

import softarm_gym  # noqa: F401  (registers the IDs)
import solver

CASES = (
    ("free reach", "SoftArm/OctArmReach-v1", {}),
    ("wrap, random", "SoftArm/OctArmWrap-v1", {}),
    ("wrap, delta", "SoftArm/OctArmWrap-v1", {"action_mode": "delta", "delta_scale": 0.1}),
    ("obstacle reach", "SoftArm/OctArmObstacleReach-v0", {}),
    ("grasp", "SoftArm/OctArmGrasp-v0", {}),
    ("reach, self-contact", "SoftArm/OctArmReach-v1", {"self_contact": True}),
    ("3D reach", "SoftArm/OctArmReach-v1", {"planar": False}),
    ("3D wrap", "SoftArm/OctArmWrap3D-v0", {}),
)
"""(name, id, kwargs) of the profiled cases; the first is the ratios' unit."""

CATEGORIES = ("lean kernels", "continuation", "snap relaxation", "other kernels", "solver Python",
              "env Python")

_CONTINUATION = ("follow", "newton")


def _category(filename: str, name: str) -> str:
    """The profile category of a function (module docstring)."""
    if "/solver/kernels/" in filename:
        if filename.endswith("stepping.py") or name in ("warm_step", "lean_step"):
            return "lean kernels"
        if filename.endswith("relax.py"):
            return "snap relaxation"
        if name in _CONTINUATION:
            return "continuation"
        return "other kernels"
    if "scipy/optimize" in filename:
        return "snap relaxation"
    if "/solver/" in filename:
        return "solver Python"
    return "env Python"


class _StepTimer:
    """Times every :meth:`solver.Stepper.step` of the process by the path it took."""

    def __init__(self):
        self.seconds = defaultdict(list)
        self.iterations = defaultdict(list)
        self.passes = []
        self._step = solver.Stepper.step

    def __enter__(self):
        timer, original = self, self._step

        def step(stepper, pressures):
            start = time.perf_counter()
            report = original(stepper, pressures)
            timer.seconds[stepper.last_path].append(time.perf_counter() - start)
            timer.iterations[stepper.last_path].append(report.iterations)
            if stepper.last_path == "lean contact":
                timer.passes.append(report.iterations)
            timer.last = stepper
            return report

        solver.Stepper.step = step
        return self

    def __exit__(self, *exc):
        solver.Stepper.step = self._step


def _run(env, actions) -> tuple[float, float]:
    """Seconds for ``actions`` (resets counted), and the seconds of the resets among them."""
    resets = 0.0
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            begin = time.perf_counter()
            env.reset()
            resets += time.perf_counter() - begin
    return time.perf_counter() - start, resets


def profile_case(env_id: str, kwargs: dict, steps: int, seed: int = 0) -> dict:
    """The profile of one case (module docstring): µs a step, paths, time by path and
    category, lean contact passes and pass costs."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps + steps // 5)]
    warm, timed = actions[:steps // 5], actions[steps // 5:]
    _run(env, warm)
    state = env.unwrapped
    env.reset(seed=seed + 1)
    with _StepTimer() as timer:
        seconds, reset_seconds = _run(env, timed)
    paths = {path: len(times) for path, times in timer.seconds.items()}
    by_path = {path: 1e6 * float(np.mean(times)) for path, times in timer.seconds.items()}
    env.reset(seed=seed + 1)
    profiler = cProfile.Profile()
    profiler.enable()
    _run(env, timed)
    profiler.disable()
    share = Counter()
    for (filename, _, name), (_, _, tottime, _, _) in pstats.Stats(profiler).stats.items():
        share[_category(filename, name)] += tottime
    total = sum(share.values()) or 1.0
    out = {
        "id": env_id, "kwargs": kwargs, "steps": len(timed), "us_per_step": 1e6 * seconds / len(timed),
        "reset_share": reset_seconds / seconds,
        "paths": paths, "us_per_step_by_path": by_path,
        "iterations_median_by_path": {path: float(np.median(n)) for path, n in timer.iterations.items()},
        "profile_share": {c: share[c] / total for c in CATEGORIES},
    }
    if timer.passes:
        out["lean_contact_passes_median"] = float(np.median(timer.passes))
        out["lean_contact_passes_mean"] = float(np.mean(timer.passes))
    stepper = state.stepper
    if stepper is not None and stepper.lean_contact:
        try:
            out["pass_costs"] = stepper.pass_costs()
        except ValueError:  # the last state lies off the contact layout
            pass
    env.close()
    return out


def run(steps: int = 300, quick: bool = False, progress=None) -> dict:
    """Every case of :data:`CASES` in this process; ratios to the first."""
    if quick:
        steps = min(steps, 60)
    cases = {}
    for name, env_id, kwargs in CASES:
        if progress is not None:
            progress(f"{name}: {env_id} {kwargs or ''}")
        cases[name] = profile_case(env_id, kwargs, steps)
    unit = cases[CASES[0][0]]["us_per_step"]
    for case in cases.values():
        case["ratio_to_free_step"] = case["us_per_step"] / unit
    return {"steps": steps, "cases": cases}


def format_table(result: dict) -> str:
    """Markdown tables of :func:`run`'s result: speed and paths, then where the time goes."""
    lines = ["| case | µs/step | × free step | resets | paths (steps) | µs by path | "
             "iterations by path (median) |",
             "|---|---|---|---|---|---|---|"]
    for name, case in result["cases"].items():
        paths = ", ".join(f"{p} {n}" for p, n in sorted(case["paths"].items()))
        by_path = ", ".join(f"{p} {us:.0f}" for p, us in sorted(case["us_per_step_by_path"].items()))
        iterations = ", ".join(f"{p} {n:g}" for p, n in sorted(case["iterations_median_by_path"].items()))
        lines.append(f"| {name} | {case['us_per_step']:.0f} | {case['ratio_to_free_step']:.1f} | "
                     f"{100 * case['reset_share']:.0f} % | {paths} | {by_path} | {iterations or '—'} |")
    lines += ["", "| case | " + " | ".join(CATEGORIES) + " | residual / Jacobian pass (µs), rows refined |",
              "|---|" + "---|" * (len(CATEGORIES) + 1)]
    for name, case in result["cases"].items():
        shares = " | ".join(f"{100 * case['profile_share'][c]:.0f} %" for c in CATEGORIES)
        costs = case.get("pass_costs")
        cost = f"{1e6 * costs['residual_pass_s']:.1f} / {1e6 * costs['jacobian_pass_s']:.1f}, " \
            f"{costs['refined_fraction']:.0%}" if costs else "—"
        lines.append(f"| {name} | {shares} | {cost} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------- batched contact envs

def refusal_words(bits: int) -> str:
    """The lean contact step's refusal bits (:func:`solver.refusal_names`) as words, ``"none"``
    for none."""
    if not bits:
        return "none"
    return ", ".join(solver.refusal_names(bits))


def _refusal_bits(report: np.ndarray, k: int) -> int:
    """Copy k's refusal bits in a report of the lean row kernels (0 from a tree whose
    kernels report none: a side-by-side run against an older commit)."""
    return int(report[k, 6]) if report.shape[1] > 6 else 0


class _BatchTimer:
    """Times the parts of a batched contact env's steps (:func:`profile_batched`): the lean
    row kernels and each copy's general-path step, with what the lean kernel left behind for
    it (the copy's state before, its report row, the general path's answer). ``per_copy``:
    the row kernel is called copy by copy (serially; the same numbers, rows are
    independent) to time each copy's lean step."""

    def __init__(self, batch, per_copy: bool):
        self.batch = batch
        self.lean_s = 0.0
        self.general = []  # one dict per general-path step
        self.lean = []  # per copy and step: (path code, passes, refusal bits, self-touching, seconds)
        rows = batch.contact_rows
        self._step, self._solve_copy = rows.step, batch.solve_copy
        self._report = None

        def step(p_from, p_to, active, run):
            coupled = [rows.full_factor_age(k) > 0 for k in range(rows.n)]  # parts touching
            seconds = np.zeros(rows.n)
            start = time.perf_counter()
            report = None
            if per_copy:
                for k in np.flatnonzero(active):
                    one = np.zeros(rows.n, dtype=bool)
                    one[k] = True
                    begin = time.perf_counter()
                    row = self._step(p_from, p_to, one, None)
                    report = np.zeros_like(row) if report is None else report
                    report[k] = row[k]
                    seconds[k] = time.perf_counter() - begin
            if report is None or not per_copy:
                report = self._step(p_from, p_to, active, run)
            self.lean_s += time.perf_counter() - start
            self._report = report
            for k in np.flatnonzero(active):
                self.lean.append((report[k, 5], report[k, 3], _refusal_bits(report, k),
                                  bool(coupled[k]), seconds[k]))
            return report

        def solve_copy(k, p_inputs, p_channel, warm_start, scene):
            state = {"copy": int(k), "on_contact_layout": rows.on_contact_layout(k),
                     "touching": rows.touching(k), "self_touching": rows.full_factor_age(k) > 0,
                     "lean_passes": int(self._report[k, 3]),
                     "lean_refusal": refusal_words(_refusal_bits(self._report, k))}
            start = time.perf_counter()
            eq = self._solve_copy(k, p_inputs, p_channel, warm_start, scene)
            state.update(seconds=time.perf_counter() - start, converged=bool(eq.converged),
                         snapped=bool(eq.snapped), iterations=int(eq.iterations))
            self.general.append(state)
            return eq

        # Instance attributes shadow the methods for the profile's steps (close() unshadows).
        rows.step = step
        batch.solve_copy = solve_copy

    def close(self):
        del self.batch.contact_rows.step
        del self.batch.solve_copy

    def summary(self) -> dict:
        """The lean steps by path (and the general ones), their passes and seconds, and the
        refusals met (any try refused, on steps the lean kernel finished or handed over)."""
        names = {1.0: "lean", 2.0: "lean contact", 0.0: "general"}
        out = {}
        for code, name in names.items():
            rows = [r for r in self.lean if r[0] == code]
            if not rows:
                continue
            passes = np.array([r[1] for r in rows])
            seconds = np.array([r[4] for r in rows])
            out[name] = {"steps": len(rows), "self_touching": int(sum(r[3] for r in rows)),
                         "passes_median": float(np.median(passes)),
                         "passes_mean": float(np.mean(passes)),
                         "lean_kernel_s": float(seconds.sum()),
                         "refusals": dict(Counter(refusal_words(r[2]) for r in rows if r[2]))}
        return out


def _curl_actions(controllers, obs, venv) -> np.ndarray:
    """Delta actions that follow each copy's :class:`~softarm_gym.controllers.CurlController`."""
    t = venv.template
    slices = t.observation_slices["pressures"]
    actions = np.empty((len(controllers), t.n_inputs))
    for i, c in enumerate(controllers):
        command = c.step_fraction(obs[i])
        current = 0.5 * (np.asarray(obs[i][slices], dtype=float) + 1.0)
        actions[i] = np.clip((command - current) / t.delta_scale, -1.0, 1.0)
    return actions


def profile_batched(env_id: str = "SoftArm/OctArmWrap-v2", n: int = 128, curl_steps: int = 30,
                    steps: int = 20, amplitude: float = 0.2, seed: int = 0, per_copy: bool = False,
                    progress=None) -> dict:
    """Where a batched contact env's step goes once its arms hold wraps: ``n`` copies of the
    batched env (episodes longer than the run), each curled by a
    :class:`~softarm_gym.controllers.CurlController` (``ramp_steps`` 10, delta actions) for
    ``curl_steps`` steps (a wrap env; none: any batched contact env from its reset), then
    ``steps`` timed steps of small random delta actions (uniform in
    ±``amplitude``, seeded). Per timed step: the lean row kernels' time, each general-path
    step (which copy, its state before — on the contact layout, touching a disc, touching
    itself —, the lean kernel's passes and refusal, the general path's time, snap and
    iterations) and the rest (the env's Python: observations, rewards). ``per_copy``: time
    each copy's lean step apart (:class:`_BatchTimer`; the batch's threads are not used).

    Returns:
        dict: ``{"id", "num_envs", "curl_steps", "steps", "amplitude", "arm_steps_per_s",
        "curl_arm_steps_per_s", "seconds", "lean_s", "general_s", "other_s", "paths",
        "wrap_deg_quartiles", "general"}`` (seconds over the timed steps; ``paths`` the
        timed arm-steps by the path that took them (:meth:`_BatchTimer.summary`);
        ``general`` one dict per general-path step).
    """
    import gymnasium as gym

    from softarm_gym.controllers import CurlController

    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                        max_episode_steps=10 ** 9)
    obs, _ = venv.reset(seed=seed)
    controllers = [CurlController(venv.template) for _ in range(n)] if curl_steps else []
    start = time.perf_counter()
    for k in range(curl_steps):
        obs, *_ = venv.step(_curl_actions(controllers, obs, venv))
        if progress:
            progress(f"curl step {k + 1} of {curl_steps}")
    curl_s = max(time.perf_counter() - start, 1e-300)
    wrapped = venv.unwrapped
    timer = _BatchTimer(wrapped._batch, per_copy)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-amplitude, amplitude, (steps, n, venv.single_action_space.shape[0]))
    try:
        start = time.perf_counter()
        for k, a in enumerate(actions):
            *_, info = venv.step(a)
            if progress:
                progress(f"timed step {k + 1} of {steps}")
        seconds = time.perf_counter() - start
    finally:
        timer.close()
    wrap_deg = np.asarray(info.get("wrap_angle_deg", np.zeros(n)))
    general_s = sum(g["seconds"] for g in timer.general)
    venv.close()
    return {"id": env_id, "num_envs": n, "curl_steps": curl_steps, "steps": steps,
            "amplitude": amplitude, "arm_steps_per_s": n * steps / seconds,
            "curl_arm_steps_per_s": n * curl_steps / curl_s, "seconds": seconds,
            "lean_s": timer.lean_s, "general_s": general_s,
            "other_s": seconds - timer.lean_s - general_s, "paths": timer.summary(),
            "wrap_deg_quartiles": np.percentile(wrap_deg, [25, 50, 75]).tolist(),
            "general": timer.general}
