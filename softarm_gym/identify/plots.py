"""The figure of a fit (``softarm fit --plot``): shapes, error against pressure, residuals, parameters.

Top row: measured and model backbones of four configurations (held-out ones when there are
any), from a typical one to the worst after the fit — the measured markers and tip, the
nominal model dashed, the fitted model solid. Bottom row: the mean position error against
pressure level per base angle, before and after the fit, on the fit and held-out sets (the
thesis's Fig. 2.6); the normalised residuals against the standard normal they should follow;
and every parameter's change from nominal with its 95 % interval, in typical scales.
"""

from __future__ import annotations

import math

import numpy as np

import solver
from softarm_gym.plotting import draw_backbone, figure, save
from solver.identify import BackbonePoints, FitResult, TipPositions

__all__ = ["plot_fit", "config_errors"]

NOMINAL = dict(color="0.45", linestyle="--", linewidth=1.3)
FITTED = dict(color="C0", linestyle="-", linewidth=1.6)
HELD = dict(color="C1", linestyle=":", marker="o", linewidth=1.6)


def config_errors(result: FitResult) -> tuple[np.ndarray, np.ndarray, str]:
    """Per configuration the error before and after the fit, and what it measures.

    The tip error (m) if the tip was measured, else the mean marker error (m), else the RMS
    normalised residual over every measured value (dimensionless).

    Returns:
        ``(nominal (n,), fitted (n,), label)`` ordered by configuration index.
    """
    cfg = result.configurations
    order = np.argsort(cfg["configuration"])
    for name in ("tip", "points"):
        key = f"{name}_error_fitted_m"
        if key in cfg:
            nominal = np.array(cfg[f"{name}_error_nominal_m"], dtype=float)[order]
            fitted = np.array(cfg[key], dtype=float)[order]
            return nominal, fitted, ("tip error (mm)" if name == "tip" else "mean marker error (mm)")
    res = result.residuals
    k = np.array(res["configuration"])
    n = result.measurements.n
    out = []
    for key in ("nominal", "fitted"):
        z = ((np.array(res["measured"]) - np.array(res[key])) / np.array(res["sigma"])) ** 2
        out.append(np.sqrt(np.bincount(k, z, minlength=n) / np.maximum(np.bincount(k, minlength=n), 1)))
    return out[0], out[1], "RMS normalised residual"


def _level_psi(pressures: np.ndarray) -> np.ndarray:
    return np.round(pressures.max(axis=1) / solver.PSI, 1)


def _shape_panel(ax, result: FitResult, k: int, label: str, rank: str, errors) -> None:
    meas = result.measurements
    scene = solver.Scene(base_angle_deg=float(meas.base_angle_deg[k]), payload_kg=float(meas.payload_kg[k]),
                         gravity=meas.gravity)
    models = ((result.design, NOMINAL, "nominal"), (result.fitted_design, FITTED, "fitted"))
    for design, style, name in models:
        eq = solver.solve(design, meas.pressures[k], scene, model=result.model)
        draw_backbone(ax, eq.positions, eq.section_ends, label=f"{name} model", **style)
    for o in meas.observations:
        if isinstance(o, BackbonePoints) and np.isfinite(o.measured[k]).any():
            ax.plot(o.measured[k, 0::2], o.measured[k, 1::2], "o", mfc="none", mec="k", ms=6,
                    label="measured markers")
        if isinstance(o, TipPositions) and np.isfinite(o.measured[k]).all():
            ax.plot(*o.measured[k], "*", color="C3", ms=10, label="measured tip")
    ax.plot(0, 0, "ks", ms=5)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    nominal, fitted, what = errors
    unit = 1e3 if "mm" in what else 1.0
    split = result.configurations["split"][result.configurations["configuration"].index(k)]
    short = {"tip error (mm)": "tip error", "mean marker error (mm)": "marker error"}.get(what,
                                                                                          "RMS residual/σ")
    ax.set_title(f"{label}\n{split}, {rank}\n{short} {unit * nominal[k]:.3g} → {unit * fitted[k]:.3g}"
                 f"{' mm' if unit != 1.0 else ''} (nominal → fitted)", fontsize=8)
    ax.set_xlabel("x (m)")


def _pressure_panel(ax, result: FitResult, angle: float, errors) -> None:
    meas = result.measurements
    nominal, fitted, what = errors
    unit = 1e3 if "mm" in what else 1.0
    cfg = result.configurations
    split = np.empty(meas.n, dtype=object)
    split[cfg["configuration"]] = cfg["split"]
    levels = _level_psi(meas.pressures)
    here = meas.base_angle_deg == angle
    xs = np.unique(levels[here])
    series = [(nominal, None, "nominal model", dict(NOMINAL, marker="s", mfc="white")),
              (fitted, "fit", "fitted, fit set", dict(FITTED, marker="s")),
              (fitted, "holdout", "fitted, held out", HELD)]
    for values, which, name, style in series:
        rows = here if which is None else here & (split == which)
        if not rows.any():
            continue
        mean = np.array([np.nanmean(values[rows & (levels == x)]) if (rows & (levels == x)).any() else np.nan
                         for x in xs])
        ax.plot(xs, unit * mean, label=name, ms=5, **style)
    ax.set_xlabel("pressure level (psi, largest input)")
    ax.set_ylabel(f"mean {what}")
    ax.set_ylim(bottom=0)
    ax.set_title(f"error against pressure, base {angle:g}°", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)


def _residual_panel(ax, result: FitResult) -> None:
    res = result.residuals
    fit_rows = np.array(res["split"]) == "fit"
    z = np.array(res["normalized"])
    names = np.array(res["observation"])
    bins = np.linspace(-5, 5, 41)
    for name in dict.fromkeys(names):
        sel = fit_rows & (names == name)
        ax.hist(np.clip(z[sel], -5, 5), bins=bins, density=True, histtype="step", linewidth=1.4,
                label=f"{name} ({sel.sum()})")
    x = np.linspace(-5, 5, 201)
    ax.plot(x, np.exp(-0.5 * x**2) / math.sqrt(2 * math.pi), "k--", linewidth=1, label="N(0, 1)")
    c = result.chi_square
    ax.set_title(f"fit residuals / σ: χ²/dof = {c['reduced']:.3g}, p = {c['p_value']:.2g}"
                 f"{' (misspecified)' if c['misspecified'] else ''}", fontsize=9)
    ax.set_xlabel("(measured − fitted) / σ  (clipped to ±5)")
    ax.set_ylabel("density")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def _parameter_panel(ax, result: FitResult) -> None:
    params = result.parameters
    y = np.arange(len(params))[::-1]
    scale = np.array([p.scale for p in params])
    nominal = np.array([p.nominal for p in params])
    shift = (result.values - nominal) / scale
    half = 1.96 * result.std / scale
    ok = result.identified
    ax.errorbar(shift[ok], y[ok], xerr=half[ok], fmt="o", color="C0", capsize=3, ms=4, label="fitted ± 95 %")
    if (~ok).any():
        ax.plot(np.zeros((~ok).sum()), y[~ok], "x", color="0.5", ms=6, label="not identified (held)")
    ax.axvline(0.0, color="0.45", linestyle="--", linewidth=1)
    ax.set_yticks(y)
    ax.set_ylim(-0.7, len(params) - 0.3)
    ax.set_yticklabels([p.name for p in params], fontsize=8)
    for k, p in enumerate(params):
        text = (f"{result.values[k]:.4g} ± {1.96 * result.std[k]:.2g} {p.unit}".replace(" -", "")
                if ok[k] else "held at nominal")
        ax.annotate(text, (1.0, y[k]), xycoords=("axes fraction", "data"), xytext=(4, 0),
                    textcoords="offset points", va="center", fontsize=7)
    ax.set_xlabel("change from nominal (typical scales:\n1° of α, 10 % of a modulus or factor)")
    ax.set_title("parameters: fitted − nominal, 95 % intervals", fontsize=9)
    ax.grid(alpha=0.3, axis="x")
    ax.legend(fontsize=7, loc="lower left")


def plot_fit(result: FitResult, path, labels=None):
    """Save the figure of ``result`` (module docstring) to ``path``.

    Args:
        result: a :class:`solver.identify.FitResult`.
        path: the image file.
        labels: per configuration a name for the panel titles (default its index).

    Returns:
        The (closed) matplotlib figure.
    """
    meas = result.measurements
    errors = config_errors(result)
    angles = list(dict.fromkeys(np.unique(meas.base_angle_deg).tolist()))[:2]
    cfg = result.configurations
    held = np.array(cfg["configuration"])[np.array(cfg["split"]) == "holdout"]
    pool = held if held.size else np.arange(meas.n)
    pool = pool[np.isfinite(errors[1][pool])]
    pool = pool[np.argsort(errors[1][pool])]
    ranks = {"25th percentile": 0.25, "median": 0.5, "90th percentile": 0.9, "worst": 1.0}
    picks = {}
    for rank, q in ranks.items():
        picks.setdefault(int(pool[int(round(q * (pool.size - 1)))]), rank)
    n_bottom = len(angles) + 2
    fig, axes = figure(2, max(4, n_bottom), figsize=(3.6 * max(4, n_bottom), 8.2),
                       gridspec_kw={"height_ratios": [1.0, 1.0]})
    for j, (k, rank) in enumerate(picks.items()):
        name = labels[k] if labels is not None and labels[k] else f"configuration {k}"
        p_psi = ", ".join(f"{v:g}" for v in np.round(meas.pressures[k] / solver.PSI, 1))
        _shape_panel(axes[0, j], result, k, f"{name}\n({p_psi} psi, base {meas.base_angle_deg[k]:g}°)", rank,
                     errors)
    axes[0, 0].set_ylabel("y (m)")
    axes[0, 0].legend(fontsize=7, loc="best")
    for j in range(len(picks), axes.shape[1]):
        axes[0, j].set_visible(False)
    for j, angle in enumerate(angles):
        _pressure_panel(axes[1, j], result, angle, errors)
    _residual_panel(axes[1, len(angles)], result)
    _parameter_panel(axes[1, len(angles) + 1], result)
    for j in range(n_bottom, axes.shape[1]):
        axes[1, j].set_visible(False)
    fig.suptitle(f"{result.design.name}: {len(result.parameters)} parameters fitted to "
                 f"{result.optimizer['fit_values']} values of {result.optimizer['fit_configurations']} "
                 f"configurations ({result.model} model)", fontsize=11)
    return save(fig, path)
