"""Validation studies of the fit (``softarm fit --reproduce``) and its benchmark (``softarm bench --fit``).

Every study fits synthetic "measured" data made by the solver from a perturbed OctArm V
(:data:`~softarm_gym.identify.data.PERTURBED_ARM`) at the thesis's experiment (§2.4: the 64
on/off combinations of the six planar inputs at 30–90 psi, vertical and horizontal base),
so the truth is known and the fit is judged against it, not against itself.

* :func:`fig_2_6` — the thesis's Fig. 2.6 as a table: mean tip error against pressure of the
  constant-curvature, unshearable and full models with the nominal parameters, and of the full
  model after the fit (on the fit set and on held-out configurations), with the noise floor.
* :func:`noise_study` — parameter error against the camera noise level.
* :func:`sensitivity` — why the wind angle dominates: the actuator's stretch and the tip's
  displacement per degree of α, against a 10 % change of E, EI or mass.
* :func:`benchmark` — the fit's time for the thesis's experiment size (64 × 7 configurations,
  nine parameters), side by side with one batch of its solves.
"""

from __future__ import annotations

import math
import statistics
import time

import numpy as np

import solver
from softarm_gym.identify.data import PERTURBED_ARM, make_synthetic, on_off_configurations
from softarm_gym.sensing import SensorNoise
from solver.identify import Measurements, TipPositions, apply_parameters, fit, parse_parameters, predict

__all__ = ["fig_2_6", "format_fig_2_6", "plot_fig_2_6", "noise_study", "format_noise", "sensitivity",
           "format_sensitivity", "benchmark", "format_benchmark", "LEVELS_PSI", "ORIENTATIONS"]

LEVELS_PSI = (30, 40, 50, 60, 70, 80, 90)
"""The pressure levels of §2.4 (psi)."""
ORIENTATIONS = {"vertical": 0.0, "horizontal": 90.0}
"""Base angle of each orientation of Fig. 2.6 (deg): vertical hangs."""
MODEL_LABELS = {"constant_curvature": "constant curvature", "unshearable": "infinite shear", "full": "full"}


class _Cumulative:
    """A progress callback that counts evaluations across several fits."""

    def __init__(self, progress):
        self.progress, self.done = progress, 0

    def __call__(self, info):
        if self.progress is not None:
            self.progress({**info, "evaluations": self.done + info["evaluations"]})

    def finish(self, result):
        self.done += result.optimizer["evaluations"]


def _levels(n_angles: int, levels, n_codes: int) -> np.ndarray:
    """Pressure level (psi) of each row of :func:`on_off_configurations`."""
    return np.tile(np.repeat(np.asarray(levels, dtype=float), n_codes), n_angles)


def _tip_errors(design, meas: Measurements, tips: np.ndarray, model: str) -> np.ndarray:
    shapes = predict(design, meas, model=model)
    return np.hypot(*(shapes.tips - tips).T)


def fig_2_6(seed: int = 0, levels=LEVELS_PSI, sigma: float = 0.005, progress=None) -> dict:
    """The Fig. 2.6-style table (module docstring) on synthetic measured tips and markers.

    Args:
        seed: seeds the camera noise and the hold-out choice.
        levels: pressure levels (psi).
        sigma: camera noise of tips and markers (m).
        progress: as :func:`solver.identify.fit`'s.

    Returns:
        ``{"rows": [...], "parameters": [...], "noise_floor_mm", "fit": summary, ...}``; each
        row is one orientation and level with the mean tip error (mm) of every model.
    """
    design = solver.designs.octarm_v()
    meas, labels, true_arm = make_synthetic(design, PERTURBED_ARM, pressures_psi=levels,
                                            base_angles_deg=tuple(ORIENTATIONS.values()), tip_sigma=sigma,
                                            point_sigma=sigma, sensor_noise=SensorNoise.off(), seed=seed)
    result = fit(design, meas, list(PERTURBED_ARM), progress=progress)
    tips = next(o for o in meas.observations if isinstance(o, TipPositions)).measured
    errors = {f"{MODEL_LABELS[m]} (nominal)": _tip_errors(design, meas, tips, m) for m in MODEL_LABELS}
    errors["full (fitted)"] = _tip_errors(result.fitted_design, meas, tips, "full")
    errors["full (true parameters)"] = _tip_errors(true_arm, meas, tips, "full")
    level = _levels(len(ORIENTATIONS), levels, 2 ** design.n_inputs(True))
    rows = []
    for name, angle in ORIENTATIONS.items():
        for lv in levels:
            sel = (meas.base_angle_deg == angle) & (level == lv)
            row = {"orientation": name, "base_angle_deg": angle, "pressure_psi": float(lv),
                   "configurations": int(sel.sum())}
            row.update({k: 1e3 * float(np.mean(v[sel])) for k, v in errors.items()})
            row["full (fitted), held out"] = 1e3 * float(np.mean(errors["full (fitted)"][sel & meas.holdout]))
            rows.append(row)
    params = parse_parameters(design, list(PERTURBED_ARM))
    table = [{"parameter": p.name, "unit": p.unit, "nominal": p.nominal, "truth": PERTURBED_ARM[p.name],
              "fitted": float(result.values[k]), "std": float(result.std[k]),
              "z": float((result.values[k] - PERTURBED_ARM[p.name]) / result.std[k])}
             for k, p in enumerate(params)]
    return {"design": design.name, "levels_psi": list(levels), "sigma_m": sigma, "seed": seed,
            "noise_floor_mm": 1e3 * sigma * math.sqrt(math.pi / 2.0), "rows": rows, "parameters": table,
            "chi_square": result.chi_square, "holdout": result.holdout,
            "fit_seconds": result.optimizer["seconds"], "configurations": meas.n}


def format_fig_2_6(result: dict) -> str:
    """Markdown tables of :func:`fig_2_6`."""
    cols = [k for k in result["rows"][0] if k not in ("orientation", "base_angle_deg", "pressure_psi",
                                                       "configurations")]
    lines = [f"Mean tip error (mm) over the 64 on/off configurations of {result['design']}, synthetic data "
             f"of a perturbed arm (camera sigma {1e3 * result['sigma_m']:g} mm: noise floor "
             f"{result['noise_floor_mm']:.1f} mm)", "",
             "| base | psi | " + " | ".join(cols) + " |", "|---|---|" + "---|" * len(cols)]
    for r in result["rows"]:
        lines.append(f"| {r['orientation']} | {r['pressure_psi']:g} | "
                     + " | ".join(f"{r[c]:.1f}" for c in cols) + " |")
    lines += ["", "| parameter | nominal | truth | fitted ± std | (fitted − truth)/std |",
              "|---|---|---|---|---|"]
    for p in result["parameters"]:
        lines.append(f"| {p['parameter']} | {p['nominal']:.6g} | {p['truth']:.6g} | {p['fitted']:.6g} ± "
                     f"{p['std']:.2g} | {p['z']:+.2f} |")
    c = result["chi_square"]
    lines.append(f"\nchi-square {c['statistic']:.0f} on {c['dof']} dof (p = {c['p_value']:.2g}); fit "
                 f"{result['fit_seconds']:.1f} s")
    return "\n".join(lines)


def plot_fig_2_6(result: dict, path):
    """Fig. 2.6 style: mean tip error against pressure, one panel per orientation (log scale)."""
    from softarm_gym.plotting import figure, save

    styles = {"constant curvature (nominal)": dict(marker="^", linestyle="-.", color="C2"),
              "infinite shear (nominal)": dict(marker="o", linestyle=":", color="C1"),
              "full (nominal)": dict(marker="s", linestyle="--", color="0.4", mfc="white"),
              "full (fitted)": dict(marker="s", linestyle="-", color="C0"),
              "full (true parameters)": dict(marker="", linestyle=":", color="C0", linewidth=1),
              "full (fitted), held out": dict(marker="D", linestyle="", color="C3", ms=4)}
    fig, axes = figure(1, len(ORIENTATIONS), figsize=(5.2 * len(ORIENTATIONS), 4.6), squeeze=False,
                       sharey=True)
    for ax, name in zip(axes[0], ORIENTATIONS):
        rows = [r for r in result["rows"] if r["orientation"] == name]
        x = [r["pressure_psi"] for r in rows]
        for key, style in styles.items():
            ax.plot(x, [r[key] for r in rows], label=key, **style)
        ax.axhline(result["noise_floor_mm"], color="k", linewidth=0.8, linestyle="--",
                   label="noise floor (camera σ)")
        ax.set_yscale("log")
        ax.set_xlabel("pressure (psi)")
        ax.set_title(f"({'ab'[list(ORIENTATIONS).index(name)]}) {name} base", fontsize=10)
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].set_ylabel("mean tip error over 64 configurations (mm)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    return save(fig, path)


def noise_study(sigmas_mm=(1.0, 2.0, 5.0, 10.0, 20.0), seeds=(0, 1, 2), levels=LEVELS_PSI,
                progress=None) -> dict:
    """Parameter error against camera noise: nine parameters of the perturbed arm fitted to
    tips and markers of both orientations, ``len(seeds)`` noise draws per level.

    Returns:
        ``{"rows": [{"sigma_mm", "parameter", "rms_error", "mean_std", "covered"}...], ...}``;
        ``covered`` counts the draws whose 95 % interval holds the truth.
    """
    design = solver.designs.octarm_v()
    truth = np.array(list(PERTURBED_ARM.values()))
    counter = _Cumulative(progress)
    rows, seconds = [], []
    for sigma in sigmas_mm:
        err, std, covered = [], [], []
        for seed in seeds:
            meas = make_synthetic(design, PERTURBED_ARM, pressures_psi=levels,
                                  base_angles_deg=tuple(ORIENTATIONS.values()), tip_sigma=sigma / 1e3,
                                  point_sigma=sigma / 1e3, sensor_noise=SensorNoise.off(), seed=seed)[0]
            result = fit(design, meas, list(PERTURBED_ARM), progress=counter)
            counter.finish(result)
            seconds.append(result.optimizer["seconds"])
            err.append(result.values - truth)
            std.append(result.std)
            lo, hi = result.interval().T
            covered.append((lo <= truth) & (truth <= hi))
        err, std, covered = np.array(err), np.array(std), np.array(covered)
        for k, name in enumerate(PERTURBED_ARM):
            rows.append({"sigma_mm": float(sigma), "parameter": name,
                         "rms_error": float(np.sqrt(np.mean(err[:, k] ** 2))),
                         "mean_std": float(np.mean(std[:, k])), "covered": int(covered[:, k].sum()),
                         "draws": len(seeds)})
    return {"design": design.name, "levels_psi": list(levels), "seeds": list(seeds), "rows": rows,
            "truth": PERTURBED_ARM, "fit_seconds_median": statistics.median(seconds)}


def format_noise(result: dict) -> str:
    """A Markdown table of :func:`noise_study`: RMS error (mean reported std) per parameter."""
    names = list(result["truth"])
    sigmas = sorted({r["sigma_mm"] for r in result["rows"]})
    cell = {(r["sigma_mm"], r["parameter"]): r for r in result["rows"]}
    lines = [f"Parameter error against camera noise ({len(result['seeds'])} draws per level): RMS error "
             "(mean reported std) [draws whose 95 % interval holds the truth]", "",
             "| sigma (mm) | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for s in sigmas:
        lines.append(f"| {s:g} | " + " | ".join(
            f"{cell[s, n]['rms_error']:.3g} ({cell[s, n]['mean_std']:.2g}) [{cell[s, n]['covered']}]"
            for n in names) + " |")
    covered = sum(r["covered"] for r in result["rows"])
    total = sum(r["draws"] for r in result["rows"])
    lines.append(f"\n{covered} of {total} intervals hold the truth ({100 * covered / total:.0f} %); "
                 f"median fit {result['fit_seconds_median']:.1f} s")
    return "\n".join(lines)


SENSITIVITY_PARAMETERS = {"wind_angle": 1.0, "wind_angle:s1_I": 1.0, "E": 0.1, "EI_scale": 0.1,
                          "mass_scale": 0.1}
"""The changes of :func:`sensitivity`: 1° of α (all tubes; channel I of section 1 alone) against
10 % of E, of every section's EI, of the mass."""
SENSITIVITY_ALPHAS = (60.0, 65.0, 70.0, 75.0, 78.0, 85.0)
"""Braid angles of the actuator table (deg): from near the locking angle 54.74° to OctArm's 78°."""


def sensitivity(levels=LEVELS_PSI, base_angle_deg: float = 90.0) -> dict:
    """Why the wind angle dominates (docs/identification.md, the thesis note).

    Returns:
        A dict,
        ``{"actuator": per braid angle α its λmax, dλmax/dα and, per pressure, λ and the
        relative change of the extension λ − 1 for +1° of α (and for +10 % of E), "arm": per
        parameter change the tip displacement (mm) of the on/off configurations along their
        branch — median, 90th percentile, largest, over all of them and over those where both
        sides of section 1 are pressurised — and how many configurations the cold solve moves
        to another branch}``.
    """
    design = solver.designs.octarm_v()
    m = solver.designs.OCTARM_V_TUBE

    def extension(p, e, alpha):
        return solver.stretch_from_pressure(p, e, m.inner_radius, m.outer_radius, alpha) - 1.0

    actuator = []
    for alpha in SENSITIVITY_ALPHAS:
        lam_max = solver.actuator.max_stretch(alpha)
        row = {"alpha_deg": alpha, "max_stretch": lam_max,  # dλmax/dα = λmax·tan α
               "d_max_stretch_per_degree": lam_max * math.tan(math.radians(alpha)) * math.pi / 180.0,
               "pressures": []}
        for lv in (levels[0], levels[len(levels) // 2], levels[-1]):
            p = lv * solver.PSI
            e = m.youngs_modulus
            base = extension(p, e, alpha)
            row["pressures"].append({"pressure_psi": float(lv), "stretch": 1.0 + base,
                                     "per_degree_alpha": extension(p, e, alpha + 1.0) / base - 1,
                                     "per_10pc_E": extension(p, 1.1 * e, alpha) / base - 1})
        actuator.append(row)
    pressures, angles, labels = on_off_configurations(design, levels, (base_angle_deg,))
    meas = Measurements(pressures, angles, 0.0, (TipPositions(np.zeros((len(labels), 2)), 1.0),))
    nominal = predict(design, meas)
    both = (pressures[:, 0] > 0) & (pressures[:, 1] > 0)
    arm = []
    for name, change in SENSITIVITY_PARAMETERS.items():
        (p,) = parse_parameters(design, name)
        degrees = p.unit == "deg"
        value = p.nominal + change if degrees else p.nominal * (1.0 + change)
        changed = apply_parameters(design, (p,), [value])
        along = predict(changed, meas, start=nominal)  # continued from each nominal equilibrium
        cold = predict(changed, meas)
        d = 1e3 * np.hypot(*(along.tips - nominal.tips).T)
        ok = along.converged
        row = {"parameter": name, "change": f"+{change:g}°" if degrees else f"+{100 * change:g} %",
               "continued": int(ok.sum()),
               "switched_branch": int(np.sum(np.hypot(*(cold.tips - along.tips).T) > 0.01 * design.length)
                                      - np.sum(~ok))}
        for key, sel in (("all", ok), ("both_sides_on", ok & both)):
            row[key] = {"median_mm": float(np.median(d[sel])), "p90_mm": float(np.percentile(d[sel], 90)),
                        "max_mm": float(d[sel].max())}
        arm.append(row)
    return {"design": design.name, "base_angle_deg": base_angle_deg, "levels_psi": list(levels),
            "actuator": actuator, "arm": arm, "configurations": len(labels), "both_sides_on": int(both.sum())}


def format_sensitivity(result: dict) -> str:
    """Markdown tables of :func:`sensitivity`."""
    first = result["actuator"][0]["pressures"]
    head = " | ".join(f"λ at {r['pressure_psi']:g} psi, +1° of α" for r in first)
    lines = ["Extension λ − 1 of the OctArm V tube (E 2 MPa, Ri 9.3 mm, Ro 14 mm) against the braid angle α:",
             "", f"| α | λmax | dλmax/dα (per °) | {head} |", "|---|---|---|" + "---|" * len(first)]
    for r in result["actuator"]:
        cells = " | ".join(f"{q['stretch']:.4f}, {100 * q['per_degree_alpha']:+.1f} %"
                           for q in r["pressures"])
        lines.append(f"| {r['alpha_deg']:g}° | {r['max_stretch']:.3f} | "
                     f"{r['d_max_stretch_per_degree']:.3f} | {cells} |")
    at78 = next(r for r in result["actuator"] if r["alpha_deg"] == 78.0)["pressures"]
    lines.append("\n+10 % of E at α = 78°: " + ", ".join(
        f"{100 * q['per_10pc_E']:+.1f} % at {q['pressure_psi']:g} psi" for q in at78))
    lines += ["", f"Tip displacement of the {result['configurations']} on/off configurations (base "
              f"{result['base_angle_deg']:g}°) along their branch, mm: median / 90th percentile / largest",
              "",
              f"| change | all | s1_I and s1_II+III both on ({result['both_sides_on']}) | cold solve on "
              "another branch |", "|---|---|---|---|"]
    for r in result["arm"]:
        cells = [f"{c['median_mm']:.1f} / {c['p90_mm']:.1f} / {c['max_mm']:.0f}"
                 for c in (r["all"], r["both_sides_on"])]
        lines.append(f"| {r['parameter']} {r['change']} | {cells[0]} | {cells[1]} | {r['switched_branch']} |")
    return "\n".join(lines)


def benchmark(repeats: int = 3, levels=LEVELS_PSI, base_angle_deg: float = 90.0, progress=None) -> dict:
    """Fit time for the thesis's experiment size: 64 on/off configurations × 7 pressures at one
    base angle, tips and the two inner endplates measured (5 mm), nine parameters; each fit
    timed ``repeats`` times on the same data, beside batch solves of its configurations (cold,
    with backbones; eight before each fit, on threads or one as a ThreadPolicy finds faster,
    as in the fit; the median is reported).

    Returns:
        ``{"fit_seconds": [...], "median_s", "batch_seconds": [...], "fit_over_batch", ...}``.
    """
    design = solver.designs.octarm_v()
    meas = make_synthetic(design, PERTURBED_ARM, pressures_psi=levels, base_angles_deg=(base_angle_deg,),
                          sensor_noise=SensorNoise.off(), seed=0)[0]
    counter = _Cumulative(progress)
    fits, batches, runs = [], [], []
    policies = {"cold": solver.ThreadPolicy(solver.BatchStepper.PARALLEL_MIN)}  # as the fit's batches
    for _ in range(repeats):
        for _ in range(8):  # the first runs of each way load kernels and are not measured
            start = time.perf_counter()
            predict(design, meas, backbone=True, policies=policies)
            batches.append(time.perf_counter() - start)
        result = fit(design, meas, list(PERTURBED_ARM), progress=counter)
        counter.finish(result)
        fits.append(result.optimizer["seconds"])
        opt = result.optimizer
        runs.append({"evaluations": opt["evaluations"], "jacobians": opt["jacobians"]})
    median_fit, median_batch = statistics.median(fits), statistics.median(batches)
    return {"design": design.name, "configurations": meas.n, "fit_configurations": opt["fit_configurations"],
            "values": opt["fit_values"], "parameters": len(PERTURBED_ARM), "fit_seconds": fits,
            "median_s": median_fit, "target_s": 10.0, "met": median_fit <= 10.0, "batch_seconds": batches,
            "median_batch_s": median_batch, "fit_over_batch": median_fit / median_batch, "runs": runs}


def format_benchmark(result: dict) -> str:
    """One paragraph of :func:`benchmark`."""
    r = result
    times = ", ".join(f"{s:.2f}" for s in r["fit_seconds"])
    return (f"fit of {r['parameters']} parameters to {r['values']} values of {r['fit_configurations']} "
            f"configurations ({r['configurations']} with the held-out ones): median {r['median_s']:.2f} s of "
            f"{times} (target {r['target_s']:g} s: {'met' if r['met'] else 'NOT met'}); one batch solve of "
            f"the {r['configurations']} configurations {1e3 * r['median_batch_s']:.1f} ms, so the fit costs "
            f"{r['fit_over_batch']:.0f} batch solves ({r['runs'][0]['evaluations']} evaluations, "
            f"{r['runs'][0]['jacobians']} Jacobians)")
