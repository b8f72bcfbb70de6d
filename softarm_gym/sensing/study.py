"""The chapter-4 estimation study (§4.3, Figs. 4.4–4.6) on OctArm VI.

For each pressure level (0–90 psi, 10 levels) every one of the 64 on/off combinations of
the six planar channels is solved (code ``b1…b6`` → ``[s1_I, s1_II+III, s2_I, s2_II+III,
s3_I, s3_II+III]``, 1 = pressurised), sensors are synthesised with and without Table 4.3
noise, and every estimator's tip error is averaged over the 64 configurations in the RMS
sense, for a horizontal (90°) and a vertical (hanging, 0°) base. The payload study repeats
the sweep with an unknown 10 N tip payload (Fig. 4.6).

Two ways of accounting for sensor error are reported. ``table4.3`` simulates the sensors:
readings rounded to their Table 4.3 resolution (error uniform within ±resolution/2). The
thesis instead propagates a full resolution step through the estimator's sensitivities
(Eq. 4.12, §4.2.1; "numerically differentiating the tip position with respect to the
measured ... lengths and rotations", §4.2.2): ``bound`` is that linearised error,
E = √(Σ_i (Δ_i·∂tip/∂r_i)²) over every reading r_i with resolution Δ_i (load-cell forces
and moment perturbed in the sensor's own frame), by central differences.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import replace

import numpy as np

import solver
from softarm_gym.sensing.estimators import ESTIMATORS, make_estimator
from softarm_gym.sensing.sensors import SensorNoise, synthesize

__all__ = ["configurations", "run_study", "sensitivity_bound", "ORIENTATIONS"]

ORIENTATIONS = {"horizontal": 90.0, "vertical": 0.0}
"""Base angle (deg) of each orientation: a hanging arm is the vertical case (an upright
OctArm VI would buckle under its own weight: q·L³/EI ≈ 65 > 7.84)."""

BOUND_STEP = 1e-3
"""Central-difference step of the sensitivity bound, as a fraction of each resolution."""

STUDY_ESTIMATORS = tuple(e for e in ESTIMATORS if e != "true")

TRUTH_SETTINGS = solver.Settings(steps_per_section=64)
"""Truths on the load-cell estimator's RK4 grid (error ~1e-7 m): its initial-value
integration then reproduces them to round-off, as the thesis's "exact shape" claim needs."""


def configurations(n_inputs: int = 6) -> list[str]:
    """The 2**n on/off codes, '000000' to '111111'."""
    return ["".join(bits) for bits in itertools.product("01", repeat=n_inputs)]


SENSOR_GROUPS = ("encoders", "base_inclinometer", "inclinometers", "load_cell_shear",
                 "load_cell_axial", "load_cell_moment")


def _perturbations(readings, noise: SensorNoise):
    """One reading change of one resolution step per sensor axis, as SensorReadings deltas.

    Yields (sensor group, encoder delta (ns, 2), inclinometer delta (ns + 1,), wrench delta (3,)).
    """
    ns = readings.encoder_lengths.shape[0]
    zero_enc, zero_inc, zero_w = np.zeros((ns, 2)), np.zeros(ns + 1), np.zeros(3)
    for i in range(ns):
        for c in range(2):
            d = zero_enc.copy()
            d[i, c] = noise.encoder_resolution
            yield "encoders", d, zero_inc, zero_w
    for i in range(ns + 1):
        d = zero_inc.copy()
        d[i] = math.radians(noise.base_inclinometer_deg if i == 0 else noise.inclinometer_resolution_deg)
        yield ("base_inclinometer" if i == 0 else "inclinometers"), zero_enc, d, zero_w
    th = float(readings.inclinometers[0])
    d1 = np.array([-math.sin(th), math.cos(th), 0.0])
    d3 = np.array([math.cos(th), math.sin(th), 0.0])
    yield "load_cell_shear", zero_enc, zero_inc, noise.force_resolution * d1
    yield "load_cell_axial", zero_enc, zero_inc, noise.axial_force_resolution * d3
    yield "load_cell_moment", zero_enc, zero_inc, np.array([0.0, 0.0, noise.moment_resolution])


def sensitivity_bound(est, readings, pressures, noise: SensorNoise) -> dict:
    """Linearised tip error √(Σ (Δ_i ∂tip/∂r_i)²) of an estimator (m), thesis Eq. 4.12 style.

    Returns:
        ``{"total": E, <sensor group>: E restricted to that group, ...}`` (m).
    """
    squares = dict.fromkeys(SENSOR_GROUPS, 0.0)
    for group, d_enc, d_inc, d_w in _perturbations(readings, noise):
        tips = []
        for sign in (1.0, -1.0):
            h = sign * BOUND_STEP
            moved = replace(readings, encoder_lengths=readings.encoder_lengths + h * d_enc,
                            inclinometers=readings.inclinometers + h * d_inc,
                            base_wrench=readings.base_wrench + h * d_w)
            tips.append(est.estimate(moved, pressures).tip)
        squares[group] += float(np.sum(((tips[0] - tips[1]) / (2.0 * BOUND_STEP)) ** 2))
    out = {g: math.sqrt(v) for g, v in squares.items()}
    out["total"] = math.sqrt(sum(squares.values()))
    return out


def _sweep(arm, scene, pressures_psi, estimators, noises, payload_kg, progress, bound=True):
    """Tip errors (m) indexed [noise][estimator] -> (n_pressures, n_configs) arrays.

    A truth the solver could not converge to a stable equilibrium is left out (NaN) and
    listed in the returned ``excluded``; unconverged estimates are counted per estimator.
    """
    codes = configurations(arm.n_inputs(True))
    mask = np.array([[c == "1" for c in code] for code in codes], dtype=float)
    truth_scene = solver.Scene(base_angle_deg=scene.base_angle_deg, gravity=scene.gravity,
                               payload_kg=payload_kg)
    options = {"model": {"settings": TRUTH_SETTINGS}}  # the nominal model on the truth's grid
    ests = {name: make_estimator(name, arm, planar=True, scene=scene, **options.get(name, {}))
            for name in estimators}
    keys = list(noises) + (["bound", *(f"bound:{g}" for g in SENSOR_GROUPS)] if bound else [])
    errors = {nk: {name: np.full((len(pressures_psi), len(codes)), np.nan) for name in estimators}
              for nk in keys}
    unconverged = {name: 0 for name in estimators}
    excluded = []
    rng = np.random.default_rng(0)
    for i, p_psi in enumerate(pressures_psi):
        for k in range(len(codes)):
            p = mask[k] * p_psi * solver.PSI
            eq = solver.solve(arm, p, truth_scene, settings=TRUTH_SETTINGS)
            progress.update(1)
            if not (eq.converged and eq.stable):
                excluded.append({"pressure_psi": float(p_psi), "config": codes[k],
                                 "converged": eq.converged, "stable": eq.stable})
                continue
            for nk, noise in noises.items():
                readings = synthesize(eq, arm, noise, rng)
                for name, est in ests.items():
                    est.reset()
                    shape = est.estimate(readings, p)
                    unconverged[name] += not shape.converged
                    errors[nk][name][i, k] = float(np.linalg.norm(shape.tip - eq.tip))
                    if bound and nk == "perfect":
                        parts = (dict.fromkeys(("total", *SENSOR_GROUPS), 0.0) if name == "model"
                                 else sensitivity_bound(est, readings, p, noises["table4.3"]))
                        errors["bound"][name][i, k] = parts["total"]
                        for g in SENSOR_GROUPS:
                            errors[f"bound:{g}"][name][i, k] = parts[g]
    return codes, errors, unconverged, excluded


def _summarise(codes, errors, length):
    out = {}
    for nk, by_est in errors.items():
        out[nk] = {}
        for name, e in by_est.items():
            out[nk][name] = {
                "rms_over_L": (np.sqrt(np.nanmean(e**2, axis=1)) / length).tolist(),
                "std_over_L": (np.nanstd(e, axis=1) / length).tolist(),
                "min_config": [codes[int(j)] for j in np.nanargmin(e, axis=1)],
                "max_config": [codes[int(j)] for j in np.nanargmax(e, axis=1)],
            }
    return out


def run_study(arm: solver.designs.ArmDesign | None = None, pressures_psi=None, payload_n: float = 10.0,
              noise: SensorNoise | None = None, progress=None) -> dict:
    """Run the §4.3 study and the Fig. 4.6 payload study.

    Args:
        arm: the design (default OctArm VI).
        pressures_psi: pressure levels (default 0, 10, …, 90 psi).
        payload_n: weight of the unknown tip payload of the payload study (N).
        noise: the noisy sensors (default :meth:`SensorNoise.thesis`); also the resolutions
            of the linearised bound.
        progress: a tqdm-like object with ``update(n)`` and ``total`` (or None).

    Returns:
        A JSON-ready dict: per orientation and noise level, per estimator, the RMS and
        standard deviation of the tip error over the configurations (fraction of L) and the
        configurations of least and greatest error; the same for the payload study.
    """
    arm = solver.designs.octarm_vi() if arm is None else arm
    levels = np.arange(0.0, 100.0, 10.0) if pressures_psi is None else np.asarray(pressures_psi, float)
    if levels.ndim != 1 or levels.size == 0 or (levels < 0).any() or \
            (levels * solver.PSI > arm.max_pressure * (1 + 1e-12)).any():
        raise ValueError(f"pressure levels must be a non-empty list within [0, "
                         f"{arm.max_pressure / solver.PSI:.4g}] psi; got {levels.tolist()}")
    if not (math.isfinite(payload_n) and payload_n >= 0):
        raise ValueError(f"payload must be a finite weight >= 0 N; got {payload_n!r}")
    noise = SensorNoise.thesis() if noise is None else noise
    if not isinstance(noise, SensorNoise):
        raise ValueError(f"noise must be a SensorNoise; got {type(noise).__name__}")
    noises = {"perfect": SensorNoise.off(), "table4.3": noise}

    class _Null:
        def update(self, n):
            pass

    progress = _Null() if progress is None else progress
    t0 = time.perf_counter()
    result = {"design": arm.name, "length_m": arm.length, "pressures_psi": levels.tolist(),
              "noise": {k: v for k, v in noise.__dict__.items()},
              "orientations": {}, "payload": {}, "unconverged": {}}
    for label, angle in ORIENTATIONS.items():
        scene = solver.Scene(base_angle_deg=angle)
        codes, errors, bad, skipped = _sweep(arm, scene, levels, STUDY_ESTIMATORS, noises, 0.0, progress)
        result["orientations"][label] = {"base_angle_deg": angle, "excluded_truths": skipped,
                                         **_summarise(codes, errors, arm.length)}
        result["unconverged"][label] = bad
        payload_est = ("model", "cable_encoder", "inclinometer", "load_cell")
        codes, errors, bad, skipped = _sweep(arm, scene, levels, payload_est, noises,
                                             payload_n / scene.gravity, progress, bound=False)
        result["payload"][label] = {"payload_n": payload_n, "excluded_truths": skipped,
                                    **_summarise(codes, errors, arm.length)}
        result["unconverged"][label + "_payload"] = bad
    result["seconds"] = time.perf_counter() - t0
    return result


def total_steps(n_levels: int = 10) -> int:
    """Progress units of :func:`run_study` (one per solved configuration)."""
    return 2 * len(ORIENTATIONS) * n_levels * 64
