"""Numerical-stability stress study behind ``softarm stress``.

Three parts, all seeded (the same ``seed`` gives the same scenes and the same report):

* **random** — random scenes across the named designs: pressures uniform up to the rating,
  base angle uniform in [0°, 180°], payload up to 0.5 kg, every model, one in ten spatial.
* **classes** — adversarial scene families (:data:`CLASSES`): every channel at the maximum,
  alternating maximum/zero, heavy payloads with the base pointing up (buckling), the actuator
  driven to near braid lock-up, very soft and very stiff materials, tiny and huge arms, base
  angles all round the circle, discs pressed hard in wrap scenes (warm-started ramps).
* **env** — random actions (in range, at the corners and out of range, which the envs clip)
  on every registered ``SoftArm/*`` ID and observation mode; any exception, NaN/inf in an
  observation or reward is counted.

Every solve runs twice: with the solver's fallbacks (quasi-static continuation with step
halving, tangent/secant predictor, fold scan with snap — the default :class:`solver.Settings`)
and without them (:meth:`solver.Settings.without_fallback`, plain Newton from the start
state). The report shows both, so the fallbacks' contribution is measured, not claimed.

The study runs in chunks (:data:`DEFAULT_STRESS_CHUNK` trials, or one environment case)
through :class:`softarm_gym.jobs.Runner`, on this machine or on Ray, resumable: trials are
drawn in the driver, each chunk's outcome depends only on its trials, and the chunks' records
are merged in order, so the report (timings apart) does not depend on chunking or backend.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

import solver
from softarm_gym.jobs import Chunk, Plan, Runner, chunk_bounds
from solver import PSI, designs
from solver.designs import ArmDesign
from solver.scene import core_distance

__all__ = ["Trial", "CLASSES", "random_trials", "class_trials", "run_trials", "summarize",
           "run_env_steps", "env_plan", "run", "plan", "format_report", "TARGET_CONVERGED_FRACTION",
           "DEFAULT_STRESS_CHUNK"]

TARGET_CONVERGED_FRACTION = 0.999
"""Issue target: converged fraction of the random set (with fallbacks)."""

CLASSES = ("all_max", "alternating", "upright_payload", "near_lockup", "soft", "stiff",
           "tiny_arm", "huge_arm", "random_base", "wrap_press")
"""Adversarial scene classes, in report order."""

LOCKUP_FRACTION = 0.999
"""``near_lockup`` rates its arm at the pressure that holds λ = LOCKUP_FRACTION · λmax."""

_FAILURE_EXAMPLES = 5

DEFAULT_STRESS_CHUNK = 250
"""Trials per chunk (a trial is one solve, a ``wrap_press`` trial 8): ~1 s at ~4 ms a solve."""


@dataclass(frozen=True)
class Trial:
    """One stress case: a cold solve, then (for ramps) warm-started steps along a path.

    Attributes:
        arm: the design.
        pressures: (k, n_inputs) pressures (Pa) of the k solves; the first is cold, each later
            one warm-starts from the last converged equilibrium (as an environment steps).
        scene: mounting, loads and obstacles.
        model: solver model.
        planar: planar or spatial solve.
    """

    arm: ArmDesign
    pressures: np.ndarray
    scene: solver.Scene
    model: str = "full"
    planar: bool = True

    def __post_init__(self):
        p = np.atleast_2d(np.asarray(self.pressures, dtype=float))
        if p.ndim != 2 or p.shape[1] != self.arm.n_inputs(self.planar):
            raise ValueError(f"Trial.pressures must have shape (k, {self.arm.n_inputs(self.planar)}); "
                             f"got {np.shape(self.pressures)}")
        object.__setattr__(self, "pressures", p)


# ----------------------------------------------------------------------------- designs


def scaled(arm: ArmDesign, length: float = 1.0, stiffness: float = 1.0, name: str | None = None) -> ArmDesign:
    """``arm`` with every section length × ``length`` and every modulus/stiffness × ``stiffness``.

    Tube moduli (E, G), section stiffnesses (EA, GA, EI, GJ) and the rated pressure all scale
    by ``stiffness`` (the neo-Hookean actuator's p(λ) is proportional to E), so the rated
    pressure still reaches the same stretch; mass per length is unchanged, so gravity
    matters more for soft arms and less for stiff ones.
    """
    sections = tuple(replace(s, length=s.length * length, EA=s.EA * stiffness, GA=s.GA * stiffness,
                             EI=s.EI * stiffness, GJ=s.GJ * stiffness) for s in arm.sections)
    tubes = tuple(replace(t, material=replace(t.material,
                                              youngs_modulus=t.material.youngs_modulus * stiffness,
                                              shear_modulus=t.material.shear_modulus * stiffness))
                  for t in arm.tubes)
    return replace(arm, name=name or arm.name, sections=sections, tubes=tubes,
                   max_pressure=arm.max_pressure * stiffness)


def near_lockup(arm: ArmDesign, fraction: float = LOCKUP_FRACTION) -> ArmDesign:
    """``arm`` re-rated so that its maximum pressure holds λ = ``fraction`` · λmax (all tubes alike)."""
    m = arm.tubes[0].material
    p = float(solver.pressure_from_stretch(fraction * m.max_stretch, m.youngs_modulus, m.inner_radius,
                                           m.outer_radius, m.wind_angle_deg))
    return replace(arm, name=f"{arm.name}_lockup", max_pressure=p)


_NAMED_ARMS = tuple(designs.get(n) for n in designs.DESIGN_NAMES)


def _named(rng) -> ArmDesign:
    return _NAMED_ARMS[int(rng.integers(len(_NAMED_ARMS)))]


# ----------------------------------------------------------------------------- trials


def random_trials(n: int, rng: np.random.Generator) -> list[Trial]:
    """The random set: ``n`` cold solves on random named designs, scenes and pressures."""
    trials = []
    for _ in range(n):
        arm = _named(rng)
        planar = bool(rng.uniform() >= 0.1)
        model = solver.MODELS[int(rng.choice(3, p=(0.6, 0.3, 0.1)))]
        scene = solver.Scene(base_angle_deg=rng.uniform(0.0, 180.0), payload_kg=rng.uniform(0.0, 0.5))
        p = rng.uniform(0.0, arm.max_pressure, arm.n_inputs(planar))
        trials.append(Trial(arm, p, scene, model, planar))
    return trials


def _pattern(arm: ArmDesign, planar: bool, first: bool) -> np.ndarray:
    """Alternating maximum/zero over the inputs, starting with the maximum if ``first``."""
    k = np.arange(arm.n_inputs(planar))
    return np.where((k % 2 == 0) == first, arm.max_pressure, 0.0)


def _scene(rng, angle=(0.0, 180.0), payload=(0.0, 0.5)) -> solver.Scene:
    return solver.Scene(base_angle_deg=rng.uniform(*angle), payload_kg=rng.uniform(*payload))


def _class_all_max(n, rng):
    out = []
    for _ in range(n):
        arm, planar = _named(rng), bool(rng.uniform() >= 0.2)
        out.append(Trial(arm, np.full(arm.n_inputs(planar), arm.max_pressure), _scene(rng),
                         solver.MODELS[int(rng.integers(2))], planar))
    return out


def _class_alternating(n, rng):
    out = []
    for _ in range(n):
        arm, planar = _named(rng), bool(rng.uniform() >= 0.2)
        out.append(Trial(arm, _pattern(arm, planar, bool(rng.integers(2))), _scene(rng),
                         solver.MODELS[int(rng.integers(2))], planar))
    return out


def _class_upright_payload(n, rng):
    """Base pointing up (180° ± 2°), payload up to 5 kg: far beyond the arms' buckling loads."""
    out = []
    for _ in range(n):
        arm = _named(rng)
        scale = rng.choice([0.0, 0.1, 1.0])
        p = scale * rng.uniform(0.0, arm.max_pressure, arm.n_inputs())
        scene = solver.Scene(base_angle_deg=180.0 + rng.uniform(-2.0, 2.0) * rng.integers(2),
                             payload_kg=rng.uniform(0.0, 5.0))
        out.append(Trial(arm, p, scene, solver.MODELS[int(rng.integers(2))]))
    return out


_LOCKUP_ARMS = (near_lockup(designs.octarm_v()), near_lockup(designs.ct()),
                near_lockup(designs.pneumatic((6, 6, 3), (0.4, 0.3, 0.3), 0.004)))


def _class_near_lockup(n, rng):
    """Arms re-rated to 99.9 % of braid lock-up; pressures in the top 10 % of that rating."""
    out = []
    for _ in range(n):
        arm = _LOCKUP_ARMS[int(rng.integers(len(_LOCKUP_ARMS)))]
        planar = bool(rng.uniform() >= 0.2)
        p = rng.uniform(0.9, 1.0, arm.n_inputs(planar)) * arm.max_pressure
        p *= rng.integers(2, size=p.size)  # some channels off: strong one-sided bending
        out.append(Trial(arm, p, _scene(rng), solver.MODELS[int(rng.integers(2))], planar))
    return out


def _scaled_class(n, rng, length, stiffness, suffix, payload=(0.0, 0.5)):
    out = []
    for _ in range(n):
        base = _named(rng)
        arm = scaled(base, length=float(length(rng, base)), stiffness=float(stiffness(rng)),
                     name=f"{base.name}_{suffix}")
        planar = bool(rng.uniform() >= 0.2)
        p = rng.uniform(0.0, arm.max_pressure, arm.n_inputs(planar))
        out.append(Trial(arm, p, _scene(rng, payload=payload), solver.MODELS[int(rng.integers(2))],
                         planar))
    return out


def _class_soft(n, rng):
    """Moduli × 0.02–0.2: the arm's own weight dominates (gravity number up to ~50× OctArm V's)."""
    return _scaled_class(n, rng, lambda r, a: 1.0, lambda r: r.uniform(0.02, 0.2), "soft", (0.0, 0.1))


def _class_stiff(n, rng):
    """Moduli × 10–1000: nearly rigid under gravity, the actuation still bends it."""
    return _scaled_class(n, rng, lambda r, a: 1.0, lambda r: 10.0 ** r.uniform(1.0, 3.0), "stiff",
                         (0.0, 5.0))


def _class_tiny_arm(n, rng):
    """Total length 0.05–0.1 m, same cross-section: stiff and light relative to its length."""
    return _scaled_class(n, rng, lambda r, a: r.uniform(0.05, 0.1) / a.length, lambda r: 1.0, "tiny")


def _class_huge_arm(n, rng):
    """Total length 2.5–5 m, same cross-section and moduli × 1–100: floppy, heavy arms."""
    return _scaled_class(n, rng, lambda r, a: r.uniform(2.5, 5.0) / a.length,
                         lambda r: 10.0 ** r.uniform(0.0, 2.0), "huge", (0.0, 2.0))


def _class_random_base(n, rng):
    """Base angles anywhere in [−180°, 540°] (outside the thesis's 0–180° range), payload ≤ 1 kg."""
    out = []
    for _ in range(n):
        arm, planar = _named(rng), bool(rng.uniform() >= 0.2)
        p = rng.uniform(0.0, arm.max_pressure, arm.n_inputs(planar))
        out.append(Trial(arm, p, _scene(rng, angle=(-180.0, 540.0), payload=(0.0, 1.0)),
                         solver.MODELS[int(rng.integers(2))], planar))
    return out


def _curl_inputs(arm: ArmDesign, side: float) -> np.ndarray:
    """Planar inputs (0/1) whose pressure turns the distal section towards ``side`` (±d1)."""
    mask = np.zeros(arm.n_inputs())
    for k, (_, spatial) in enumerate(arm.planar_channels):
        channel = np.zeros(arm.n_channels)
        channel[list(spatial)] = arm.max_pressure
        u2 = solver.rest_strains(arm, channel)[1]
        mask[k] = float(np.sign(u2[-1] if u2[-1] != 0 else u2.sum()) == side)
    return mask


def _class_wrap_press(n, rng, steps: int = 8):
    """A disc tangent to the start backbone; the curling channels ramp to the maximum and press
    the arm into it (contact stiffness 1e5–1e6 N/m², the payload pushing too). One trial in
    three is spatial: the disc becomes a cylinder whose axis leans up to 30° off z, or a
    sphere, through the same centre (the arm, pressed in its plane, may slide out of it)."""
    out = []
    for _ in range(n):
        arm = _NAMED_ARMS[int(rng.integers(len(_NAMED_ARMS)))]
        scene = solver.Scene(base_angle_deg=rng.uniform(0.0, 120.0), payload_kg=rng.uniform(0.0, 0.3))
        start = solver.solve(arm, np.zeros(arm.n_inputs()), scene)
        radius = rng.uniform(0.05, 0.15)
        side = 1.0 if rng.uniform() < 0.5 else -1.0
        k = int(np.searchsorted(start.s, max(start.s[-1] - 1.5 * math.pi * radius, 0.0)))
        theta = start.angles[k]
        center = start.positions[k] + 1.05 * radius * side * np.array([-math.sin(theta), math.cos(theta)])
        stiffness = 10.0 ** rng.uniform(5.0, 6.0)
        target = _curl_inputs(arm, side) * arm.max_pressure
        planar = bool(rng.uniform() >= 1.0 / 3.0)
        if planar:
            obstacle = solver.Disc(center=tuple(center), radius=radius, stiffness=stiffness)
        else:
            target = solver.channel_pressures(arm, target)
            lean, heading = math.radians(rng.uniform(0.0, 30.0)), rng.uniform(0.0, 2.0 * math.pi)
            axis = (math.sin(lean) * math.cos(heading), math.sin(lean) * math.sin(heading), math.cos(lean))
            obstacle = solver.Cylinder((*center, 0.0), axis, radius, stiffness) \
                if rng.uniform() < 0.5 else solver.Sphere((*center, 0.0), radius, stiffness)
            if core_distance(obstacle, np.zeros(3))[0] <= radius:  # it leans over the base
                obstacle = solver.Cylinder((*center, 0.0), (0.0, 0.0, 1.0), radius, stiffness)
        ramp = np.linspace(0.0, 1.0, steps)[:, None] * target[None, :]
        out.append(Trial(arm, ramp, replace(scene, obstacles=(obstacle,)),
                         solver.MODELS[int(rng.integers(2))], planar))
    return out


_CLASS_BUILDERS = {
    "all_max": _class_all_max, "alternating": _class_alternating,
    "upright_payload": _class_upright_payload, "near_lockup": _class_near_lockup,
    "soft": _class_soft, "stiff": _class_stiff, "tiny_arm": _class_tiny_arm,
    "huge_arm": _class_huge_arm, "random_base": _class_random_base, "wrap_press": _class_wrap_press,
}


def class_trials(name: str, n: int, rng: np.random.Generator) -> list[Trial]:
    """``n`` trials of the adversarial class ``name`` (one of :data:`CLASSES`)."""
    if name not in _CLASS_BUILDERS:
        raise ValueError(f"unknown stress class {name!r}; choose from {', '.join(CLASSES)}")
    return _CLASS_BUILDERS[name](n, rng)


# ----------------------------------------------------------------------------- running


STRONGER = {
    "finer_continuation": solver.Settings(dt_min=1.0 / 4096.0, max_iter=40, n_scan=384),
    "finer_grid": solver.Settings(steps_per_section=64),
}
"""Settings a failed solve is retried with, to say why it failed (:func:`diagnose`)."""


def diagnose(trial: Trial, pressures: np.ndarray, previous, eq) -> dict:
    """Why a solve with the default settings failed: retry it with each of :data:`STRONGER`.

    Args:
        trial: the failing trial; ``pressures`` (Pa) the failing step's input.
        previous: the warm start the failing solve had (None for a cold solve).
        eq: the failed result (None if it raised).

    Returns:
        A dict,

        ``{"returned_unstable": bool, "spatial": bool, "converges_with": [names...],
        "stronger_errors": [messages...]}``; ``converges_with`` empty means no tried setting
        found a converged equilibrium.
    """
    out = {"returned_unstable": bool(eq is not None and not eq.stable), "spatial": not trial.planar,
           "converges_with": [], "stronger_errors": []}
    for name, settings in STRONGER.items():
        try:
            again = solver.solve(trial.arm, pressures, trial.scene, model=trial.model, planar=trial.planar,
                                 warm_start=previous, record=False, settings=settings)
        except Exception as exc:  # noqa: BLE001 — reported to the lead as a solver problem
            out["stronger_errors"].append(f"{name}: {type(exc).__name__}: {exc}"[:200])
            continue
        if again.converged and math.isfinite(again.residual) and np.all(np.isfinite(again.tip)):
            out["converges_with"].append(name)
    return out


@dataclass
class _Records:
    """Per-solve outcomes of a list of trials (columns of equal length)."""

    converged: list
    finite: list
    residual: list
    iterations: list
    seconds: list
    stable: list
    snapped: list
    exceptions: list
    failures: list
    diagnoses: list
    planar: list
    balance: list
    unbalanced: list


def finite_result(eq: solver.Equilibrium) -> bool:
    """No NaN or inf in what a user reads of a result: tip, backbone, moments, and the residual
    of a converged one. An unconverged result whose solve found no finite state reports
    ``residual=inf`` on purpose (with the unloaded shape, finite, as its state): that is a
    flag, not a leak."""
    return bool(np.all(np.isfinite(eq.tip)) and (math.isfinite(eq.residual) or not eq.converged)
                and np.all(np.isfinite(eq.positions)) and np.all(np.isfinite(eq.internal_moment)))


BALANCE_LIMIT = 1e-3
"""Relative global moment-balance error above which a converged result counts as unbalanced."""


def moment_balance_error(arm: ArmDesign, scene: solver.Scene, eq: solver.Equilibrium) -> float:
    """Independent check of a converged result: global moment balance about the base.

    The base moment the solver returns must equal the moment of every external load about
    the base: tip moment, r(L) × (tip force + payload weight), endplate weights at the section
    ends and ∫ r × q ds of the self-weight, the integral by Simpson's rule over each section's
    recorded samples. Only the recorded shape and the loads enter, not the shooting method,
    so a wrong result flagged as converged shows up here. The error of the check itself is the
    quadrature's (≤ 3e-7 of the load moment over 1000 random scenes at the default grid).

    Returns:
        |m(0) − Σ moments| / (Σ|loads|·L + |M_tip|); NaN where it does not apply (the
        constant-curvature model ignores loads; contact forces are too concentrated for the
        quadrature).
    """
    from scipy.integrate import simpson

    if eq.model == "constant_curvature" or scene.obstacles or eq.s.size == 0:
        return math.nan
    pos = eq.positions if eq.positions.shape[1] == 3 else np.column_stack([eq.positions, np.zeros(eq.s.size)])
    g = np.array([0.0, -scene.gravity, 0.0])
    tip_force = scene.tip_force_3d() + scene.payload_kg * g
    total = scene.tip_moment_3d() + np.cross(pos[-1], tip_force)
    scale = float(np.linalg.norm(scene.tip_moment_3d()) + np.linalg.norm(tip_force) * arm.length)
    start = 0
    for section, end in zip(arm.sections, eq.section_ends):
        samples = slice(start, end + 1)
        weight = section.mass_per_length * g
        total = total + simpson(np.cross(pos[samples], weight), x=eq.s[samples], axis=0)
        total = total + np.cross(pos[end], section.endplate_mass * g)
        mass = section.mass_per_length * section.length + section.endplate_mass
        scale += mass * scene.gravity * arm.length
        start = end + 1
    base = eq.internal_moment[0]
    base = np.array([0.0, 0.0, base]) if np.ndim(base) == 0 else base
    return float(np.linalg.norm(base - total) / scale) if scale > 0 else 0.0


def _describe(trial: Trial, step: int, eq) -> dict:
    """What a failing solve needs to be reproduced."""
    s = trial.scene
    return {"design": trial.arm.name, "model": trial.model, "planar": trial.planar, "step": step,
            "pressures_psi": [round(float(v) / PSI, 6) for v in trial.pressures[step]],
            "max_pressure_psi": trial.arm.max_pressure / PSI, "length_m": trial.arm.length,
            "EI_base": trial.arm.sections[0].EI, "base_angle_deg": s.base_angle_deg,
            "payload_kg": s.payload_kg,
            "obstacles": [{"kind": type(d).__name__, **asdict(d)} for d in s.obstacles],
            "residual": None if eq is None else float(eq.residual),
            "iterations": None if eq is None else int(eq.iterations)}


def run_trials(trials, settings: solver.Settings, progress=None, n_diagnose: int = 0) -> _Records:
    """Solve every trial with ``settings``; never raises (exceptions are recorded).

    The first ``n_diagnose`` failures are retried with :data:`STRONGER` settings (:func:`diagnose`).
    """
    rec = _Records(*([] for _ in range(13)))
    for trial in trials:
        previous = None
        for step, p in enumerate(trial.pressures):
            start = time.perf_counter()
            try:
                eq = solver.solve(trial.arm, p, trial.scene, model=trial.model, planar=trial.planar,
                                  warm_start=previous, record=True, settings=settings)
            except Exception as exc:  # noqa: BLE001 — the study counts every escape
                rec.exceptions.append(f"{type(exc).__name__}: {exc}"[:300])
                rec.failures.append(_describe(trial, step, None))
                if len(rec.diagnoses) < n_diagnose:
                    rec.diagnoses.append(diagnose(trial, p, previous, None))
                continue
            rec.seconds.append(time.perf_counter() - start)
            rec.planar.append(trial.planar)
            finite = finite_result(eq)
            rec.converged.append(bool(eq.converged and finite))
            rec.finite.append(finite)
            rec.residual.append(float(eq.residual) if math.isfinite(eq.residual) else math.inf)
            rec.iterations.append(int(eq.iterations))
            rec.stable.append(bool(eq.stable))
            rec.snapped.append(bool(eq.snapped))
            if eq.converged and finite:
                previous = eq
                rec.balance.append(moment_balance_error(trial.arm, trial.scene, eq))
                if rec.balance[-1] > BALANCE_LIMIT:
                    rec.unbalanced.append({**_describe(trial, step, eq), "stable": eq.stable,
                                           "balance_error": rec.balance[-1]})
            else:
                rec.failures.append(_describe(trial, step, eq))
                if len(rec.diagnoses) < n_diagnose:
                    rec.diagnoses.append(diagnose(trial, p, previous, eq))
        if progress:
            progress()
    return rec


def summarize(rec: _Records) -> dict:
    """Per-class figures: fractions, NaN/inf count, worst residual and iterations, times (ms)."""
    n = len(rec.converged) + len(rec.exceptions)
    conv = np.array(rec.converged, dtype=bool)
    res = np.array(rec.residual)
    planar = np.array(rec.planar, dtype=bool)
    stable = np.array(rec.stable, dtype=bool)
    balance = np.array([b for b in rec.balance if not math.isnan(b)])
    t = np.array(rec.seconds) * 1e3
    pct = (lambda q: float(np.percentile(t, q))) if t.size else (lambda q: math.nan)
    return {
        "n": n,
        "converged_fraction": float(conv.sum() / n) if n else math.nan,
        "flagged_unconverged_fraction": float((~conv).sum() / n) if n else math.nan,
        "converged_stable_fraction": float((conv & stable).sum() / n) if n else math.nan,
        "converged_fraction_planar": float(conv[planar].mean()) if planar.any() else math.nan,
        "converged_fraction_spatial": float(conv[~planar].mean()) if (~planar).any() else math.nan,
        "nan_count": int(len(rec.finite) - np.count_nonzero(rec.finite)),
        "exceptions": len(rec.exceptions),
        "worst_residual": float(res.max()) if res.size else math.nan,
        "worst_residual_converged": float(res[conv].max()) if conv.any() else math.nan,
        "worst_iterations": int(max(rec.iterations)) if rec.iterations else 0,
        "worst_balance_error": float(np.max(balance)) if balance.size else math.nan,
        "unbalanced_count": int(np.count_nonzero(balance > BALANCE_LIMIT)),
        "unbalanced_stable_count": sum(u["stable"] for u in rec.unbalanced),
        "unbalanced": rec.unbalanced[:_FAILURE_EXAMPLES],
        "unstable_count": int(np.count_nonzero(~stable)),
        "snapped_count": int(np.count_nonzero(rec.snapped)),
        "time_ms": {"p50": pct(50), "p90": pct(90), "p99": pct(99),
                    "max": float(t.max()) if t.size else math.nan},
        "failures": rec.failures[:_FAILURE_EXAMPLES],
        "diagnosis": _tally(rec.diagnoses),
        "exception_messages": sorted(set(rec.exceptions))[:_FAILURE_EXAMPLES],
    }


def _tally(diagnoses: list) -> dict:
    """Counts of the diagnoses of failed solves (how many were retried, and what fixed them)."""
    out = {"retried": len(diagnoses), "returned_unstable": 0, "spatial": 0, "fixed_by_none": 0,
           **{f"fixed_by_{name}": 0 for name in STRONGER}, "stronger_errors": []}
    for d in diagnoses:
        out["returned_unstable"] += d["returned_unstable"]
        out["spatial"] += d["spatial"]
        for name in d["converges_with"]:
            out[f"fixed_by_{name}"] += 1
        out["fixed_by_none"] += not d["converges_with"]
        out["stronger_errors"] += d["stronger_errors"]
    out["stronger_errors"] = sorted(set(out["stronger_errors"]))[:_FAILURE_EXAMPLES]
    return out


def trials_chunk(trials, settings, n_diagnose):
    """:func:`run_trials` on a chunk: ``{"records": JSON of the _Records}`` (exact floats, NaN/inf kept)."""
    rec = run_trials(trials, settings, None, n_diagnose)
    return {"records": np.array(json.dumps(asdict(rec), default=_json_scalar))}


def _json_scalar(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def merge_records(results, n_diagnose) -> _Records:
    """The chunks' records in order, as one serial run would have recorded them: each chunk
    diagnosed its first ``n_diagnose`` failures, so the first ``n_diagnose`` overall are there."""
    parts = [json.loads(str(r["records"])) for r in results]
    rec = _Records(**{f.name: [v for part in parts for v in part[f.name]] for f in fields(_Records)})
    del rec.diagnoses[n_diagnose:]
    return rec


def _study_plan(trials, n_diagnose, chunk_size) -> Plan:
    """Both columns: the solver's fallbacks on (default) and off (plain Newton)."""
    columns = []
    for settings, diag in ((solver.Settings(), n_diagnose), (solver.Settings.without_fallback(), 0)):
        chunks = [Chunk(trials_chunk, (tuple(trials[a:b]), settings, diag),
                        size=sum(t.pressures.shape[0] for t in trials[a:b]))
                  for a, b in chunk_bounds(len(trials), chunk_size)]
        columns.append(Plan(chunks, lambda results, _, diag=diag: summarize(merge_records(results, diag))))

    def finish(out):
        summary = dict(out[0])
        summary["without_fallback"] = out[1]
        return summary
    return Plan.combine(columns, finish)


# ----------------------------------------------------------------------------- environments


def _actions(rng, space, n):
    """Random actions: 80 % uniform in range, 10 % at the corners, 10 % out of range (clipped)."""
    dim = space.shape[0]
    kind = rng.uniform(size=n)
    a = rng.uniform(-1.0, 1.0, (n, dim))
    corners = kind < 0.1
    a[corners] = rng.choice([-1.0, 1.0], size=(int(corners.sum()), dim))
    wild = kind > 0.9
    a[wild] = rng.uniform(-3.0, 3.0, (int(wild.sum()), dim))
    return a.astype(np.float32)


def _finite_obs(obs) -> bool:
    if isinstance(obs, dict):
        return all(np.all(np.isfinite(v)) for v in obs.values())
    return bool(np.all(np.isfinite(obs)))


def _env_case(env_id, observation, observation_format, reset_seed, actions):
    """Random-action steps on one (ID, observation) case: ``{"case": JSON {"row", "message"}}``."""
    from softarm_gym.registry import make  # registers the SoftArm/* IDs in a fresh Ray worker

    row = dict(env_id=env_id, observation=observation, steps=0, exceptions=0, nan_observations=0,
               nan_rewards=0, solver_failures=0, failure_truncations=0, resets=0)
    message = None
    start = time.perf_counter()
    try:
        env = make(env_id, quiet=True, observation=observation, observation_format=observation_format)
        obs, _ = env.reset(seed=reset_seed)
        row["nan_observations"] += not _finite_obs(obs)
        for action in actions:
            obs, reward, terminated, truncated, info = env.step(action)
            row["steps"] += 1
            row["nan_observations"] += not _finite_obs(obs)
            row["nan_rewards"] += not math.isfinite(float(reward))
            row["solver_failures"] += not info["converged"]
            if terminated or truncated:
                row["failure_truncations"] += info["solver_failures"] >= env.unwrapped.max_solver_failures
                obs, _ = env.reset()
                row["resets"] += 1
                row["nan_observations"] += not _finite_obs(obs)
        env.close()
    except Exception as exc:  # noqa: BLE001 — the study counts every escape
        row["exceptions"] += 1
        message = f"{env_id}/{observation}: {type(exc).__name__}: {exc}"[:300]
    row["steps_per_s"] = row["steps"] / max(time.perf_counter() - start, 1e-9)
    return {"case": np.array(json.dumps({"row": row, "message": message}, default=_json_scalar))}


def env_plan(n_steps: int, seed: int = 0, ids=None, observations=None) -> Plan:
    """The chunks of :func:`run_env_steps` (one per case); the plan's result is its dict.

    The actions and reset seeds of every case are drawn here, in case order from one
    generator, so a case's steps do not depend on where it runs.
    """
    from softarm_gym.benchmarks.envs import env_ids
    from softarm_gym.registry import make
    from softarm_gym.sensing import ESTIMATORS

    if isinstance(n_steps, bool) or int(n_steps) != n_steps or n_steps < 0:
        raise ValueError(f"env steps must be an integer >= 0; got {n_steps!r}")
    ids = tuple(ids or env_ids())
    observations = tuple(observations or ESTIMATORS)
    for obs in observations:
        if obs not in ESTIMATORS:
            raise ValueError(f"unknown observation {obs!r}; choose from {', '.join(ESTIMATORS)}")
    cases = [(i, o) for i in ids for o in observations]
    per_case = -(-int(n_steps) // len(cases))  # ceil: at least n_steps in all
    spaces = {}
    rng = np.random.default_rng(seed)
    chunks = []
    for k, (env_id, obs) in enumerate(cases if per_case else ()):
        if env_id not in spaces:
            probe = make(env_id, quiet=True)
            spaces[env_id] = probe.action_space
            probe.close()
        reset_seed = int(rng.integers(2**31))
        actions = _actions(rng, spaces[env_id], per_case)
        chunks.append(Chunk(_env_case, (env_id, obs, ("flat", "dict")[k % 2], reset_seed, actions),
                            size=per_case))

    def finish(results, seconds):
        cases_out = [json.loads(str(r["case"])) for r in results]
        rows = [c["row"] for c in cases_out]
        messages = [c["message"] for c in cases_out if c["message"]]
        totals = {key: sum(r[key] for r in rows) for key in
                  ("steps", "exceptions", "nan_observations", "nan_rewards", "solver_failures",
                   "failure_truncations", "resets")}
        return {**totals, "cases": len(rows), "seconds": float(sum(seconds)), "per_case": rows,
                "exception_messages": messages[:_FAILURE_EXAMPLES]}
    return Plan(chunks, finish)


def run_env_steps(n_steps: int, seed: int = 0, ids=None, observations=None,
                  progress: bool = False) -> dict:
    """Random-action steps on every (environment ID, observation mode) case.

    ``n_steps`` is split evenly over the cases, rounded up (at least ``n_steps`` in all);
    cases alternate the flat and dict observation formats. Episodes reset when they end.

    Returns:
        A dict,

        ``{"steps", "cases", "exceptions", "nan_observations", "nan_rewards",
        "solver_failures", "failure_truncations", "resets", "seconds", "per_case": [...],
        "exception_messages": [...]}``; ``seconds`` is the summed time of the cases.
    """
    plan = env_plan(n_steps, seed, ids, observations)
    return Runner(progress=progress).run_plans([plan], desc="stress env steps", unit="step")[0]


# ----------------------------------------------------------------------------- the study


def run(seed: int = 0, n_random: int = 5000, n_per_class: int = 200, env_steps: int = 100_000,
        classes=None, n_diagnose: int = 20, progress: bool = False, backend: str = "local",
        address: str | None = None, chunk_size: int = DEFAULT_STRESS_CHUNK) -> dict:
    """The whole study.

    Args:
        seed: seeds every random draw (scenes, pressures, actions).
        n_random: solves in the random set.
        n_per_class: trials per adversarial class (a ``wrap_press`` trial is an 8-step ramp).
        env_steps: total random-action environment steps (0 skips the environment part).
        classes: adversarial classes to run (default all of :data:`CLASSES`).
        n_diagnose: failed solves per entry retried with :data:`STRONGER` settings.
        progress: one progress bar (solves and env steps) on stderr.
        backend, address: ``"local"`` or ``"ray"`` and the Ray cluster (see
            :class:`softarm_gym.jobs.Runner`).
        chunk_size: trials per chunk.

    Returns:
        A dict,

        ``{"seed", "random": {...}, "classes": {name: {...}}, "env": {...}, "targets": {...}}``;
        each solver entry holds the fields of :func:`summarize` (with fallbacks) and
        ``without_fallback`` (the same fields with plain Newton). For chunks kept on disk and
        resuming, run :func:`plan` with a :class:`~softarm_gym.jobs.Runner`.
    """
    study = plan(seed, n_random, n_per_class, env_steps, classes, n_diagnose, chunk_size)
    return Runner(backend, address, progress=progress).run_plans([study], desc="stress", unit="solve")[0]


def plan(seed: int = 0, n_random: int = 5000, n_per_class: int = 200, env_steps: int = 100_000,
         classes=None, n_diagnose: int = 20, chunk_size: int = DEFAULT_STRESS_CHUNK,
         observations=None) -> Plan:
    """The chunks of :func:`run` (same arguments; ``observations`` limits the environment part
    to those estimators, default all); the plan's result is the study's dict.

    The trials and actions are drawn here, in the order :func:`run` has always drawn them.
    """
    for name, value in (("n_random", n_random), ("n_per_class", n_per_class), ("n_diagnose", n_diagnose)):
        if isinstance(value, bool) or int(value) != value or value < 0:
            raise ValueError(f"{name} must be an integer >= 0; got {value!r}")
    classes = tuple(CLASSES if classes is None else classes)
    for name in classes:
        if name not in CLASSES:
            raise ValueError(f"unknown stress class {name!r}; choose from {', '.join(CLASSES)}")
    seeds = np.random.SeedSequence(seed).spawn(len(CLASSES) + 2)
    parts = {}
    if n_random:
        parts["random"] = _study_plan(random_trials(n_random, np.random.default_rng(seeds[0])),
                                      n_diagnose, chunk_size)
    for name in classes if n_per_class else ():
        rng = np.random.default_rng(seeds[2 + CLASSES.index(name)])
        parts[("class", name)] = _study_plan(class_trials(name, n_per_class, rng), n_diagnose, chunk_size)
    if env_steps:
        parts["env"] = env_plan(env_steps, seed=int(seeds[1].generate_state(1)[0]), observations=observations)

    def finish(out):
        done = dict(zip(parts, out))
        result = {"seed": seed}
        if "random" in done:
            result["random"] = done["random"]
        result["classes"] = {key[1]: v for key, v in done.items() if isinstance(key, tuple)}
        if "env" in done:
            result["env"] = done["env"]
        result["targets"] = _targets(result)
        return result
    return Plan.combine(list(parts.values()), finish)


def _entries(result):
    if "random" in result:
        yield "random", result["random"]
    yield from result.get("classes", {}).items()


def _targets(result: dict) -> dict:
    """The issue's targets against what was measured."""
    nan_total = sum(e["nan_count"] for _, e in _entries(result))
    exceptions = sum(e["exceptions"] for _, e in _entries(result))
    env = result.get("env")
    out = {"nan_count_total": nan_total, "solver_exceptions": exceptions,
           "zero_nan": nan_total == 0 and exceptions == 0}
    if "random" in result:
        frac = result["random"]["converged_fraction"]
        out["random_converged_fraction"] = frac
        out["random_converged_target"] = TARGET_CONVERGED_FRACTION
        out["random_converged_met"] = bool(frac >= TARGET_CONVERGED_FRACTION)
    if env:
        out["env_clean"] = env["exceptions"] == 0 and env["nan_observations"] == 0 and env["nan_rewards"] == 0
        out["zero_nan"] = out["zero_nan"] and out["env_clean"]
    return out


def format_report(result: dict) -> str:
    """The study as text tables."""
    head = (f"{'class':16s} {'n':>6s} {'conv%':>8s} {'stable%':>8s} {'plain%':>8s} {'flag%':>7s} {'nan':>4s} "
            f"{'exc':>4s} {'worst res':>10s} {'balance':>8s} {'iters':>6s} {'p50 ms':>7s} {'p99 ms':>7s} "
            f"{'max ms':>7s}")
    lines = [f"softarm stress (seed {result['seed']}): conv% with the solver's fallbacks, "
             "stable% converged and stable, plain% plain Newton (Settings.without_fallback()); balance: "
             "worst global moment-balance error of a converged result (relative)", head]
    for name, e in _entries(result):
        t = e["time_ms"]
        lines.append(
            f"{name:16s} {e['n']:6d} {100 * e['converged_fraction']:8.3f} "
            f"{100 * e['converged_stable_fraction']:8.3f} "
            f"{100 * e['without_fallback']['converged_fraction']:8.3f} "
            f"{100 * e['flagged_unconverged_fraction']:7.3f} {e['nan_count']:4d} {e['exceptions']:4d} "
            f"{e['worst_residual']:10.2e} {e['worst_balance_error']:8.1e} {e['worst_iterations']:6d} "
            f"{t['p50']:7.2f} {t['p99']:7.2f} "
            f"{t['max']:7.1f}")
    env = result.get("env")
    if env:
        lines.append(f"env: {env['steps']} steps over {env['cases']} (ID, observation) cases in "
                     f"{env['seconds']:.0f} s: exceptions {env['exceptions']}, NaN observations "
                     f"{env['nan_observations']}, NaN rewards {env['nan_rewards']}, unconverged steps "
                     f"{env['solver_failures']} (kept the last state), failure truncations "
                     f"{env['failure_truncations']}")
    tg = result["targets"]
    line = f"targets: zero NaN/inf {'met' if tg['zero_nan'] else 'MISSED'}"
    if "random_converged_fraction" in tg:
        line += (f"; random set converged {100 * tg['random_converged_fraction']:.3f}% "
                 f"(target {100 * tg['random_converged_target']:.1f}%: "
                 f"{'met' if tg['random_converged_met'] else 'MISSED'})")
    lines.append(line)
    return "\n".join(lines)
