"""Plots of workspaces and dexterity maps in the manner of the thesis's Figs. 2.7, 5.4–5.6."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.ticker import MaxNLocator
from scipy.ndimage import gaussian_filter

from softarm_gym.analysis.manipulability import MEASURES
from softarm_gym.analysis.workspace import Workspace
from softarm_gym.plotting import SEQUENTIAL_CMAP, few_ticks, figure, save

__all__ = ["draw_workspace", "plot_workspaces", "plot_dexterity", "plot_dexterous_area"]

_MEASURE_LABELS = {
    "sigma_min": ("(a) σ_min", 1e-8, "σ_min (1e-8 m/Pa)"),
    "sigma_max": ("(b) σ_max", 1e-6, "σ_max (1e-6 m/Pa)"),
    "manipulability": ("(c) √(σ1σ2)", 1e-8, "√(σ1σ2) (1e-8 m/Pa)"),
    "isotropy": ("(d) isotropy", 1.0, "σ_min/σ_max (–)"),
    "condition": ("(e) condition number", 1.0, "σ_max/σ_min (–)"),
}


def draw_workspace(ax, ws: Workspace, label: str | None = None, density_cell: float = 0.02) -> None:
    """Tips as grey dots with density contours (tips per cm², smoothed over one cell, with a
    colourbar ticked at round numbers), the base as a black square and the highest tip as a
    red triangle, both in a legend."""
    pts = ws.plane_tips
    ax.plot(pts[:, 0], pts[:, 1], ".", color="0.55", ms=1.0, alpha=0.6, rasterized=True)
    dens, xe, ye = ws.density(density_cell)
    dens = gaussian_filter(dens, 1.0)  # smooth over one cell so the contours are readable
    if dens.shape[0] > 1 and dens.shape[1] > 1 and dens.max() > 0:
        xc, yc = 0.5 * (xe[1:] + xe[:-1]), 0.5 * (ye[1:] + ye[:-1])
        # Round contour levels (MaxNLocator), so the colourbar reads 10, 20, 30 and not 12.62.
        levels = [v for v in MaxNLocator(6).tick_values(dens.max() / 6, dens.max())
                  if dens.max() / 8 <= v <= dens.max()]
        cs = ax.contour(xc, yc, dens.T, levels=levels, linewidths=0.9, cmap=SEQUENTIAL_CMAP)
        ax.figure.colorbar(cs, ax=ax, shrink=0.8, label="tip density (tips per cm²)")
    top = ws.highest_tip
    ax.plot([top[0]], [top[1]], "^", color="tab:red", ms=6, label="highest tip")
    ax.plot([0], [0], "ks", ms=5, label="base")
    ax.plot([], [], ".", color="0.55", label="tips of the grid")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncols=3, fontsize=7, frameon=False)
    ax.set_aspect("equal")
    few_ticks(ax)
    ax.grid(alpha=0.3)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{label}\n{_caption(ws)}" if label else _caption(ws), fontsize=8)


def _caption(ws: Workspace) -> str:
    gravity = "no gravity" if ws.scene.gravity == 0 else f"g, payload {ws.scene.payload_kg:g} kg"
    return (f"{ws.design}, base {ws.scene.base_angle_deg:g}°, {ws.model}, {gravity}\n"
            f"n={ws.n}, area {ws.area_fraction:.3f} πL² (alpha), "
            f"highest ({ws.highest_tip[0]:+.3f}, {ws.highest_tip[1]:+.3f}) m")


def plot_workspaces(workspaces, path, labels=None):
    """One panel per workspace, side by side, saved to ``path`` (``labels`` head the titles).

    Returns:
        The (closed) matplotlib figure.
    """
    workspaces = list(workspaces)
    fig, axes = figure(1, len(workspaces), figsize=(5.4 * len(workspaces), 4.8), squeeze=False)
    for k, ws in enumerate(workspaces):
        draw_workspace(axes[0, k], ws, labels[k] if labels else None)
    return save(fig, path)


def plot_dexterity(maps, path, labels=None):
    """The five measures of Fig. 5.5, one row per :class:`DexterityMap` and one column per
    measure, saved to ``path`` (``labels`` name the rows; default the design names).

    Returns:
        The (closed) matplotlib figure.
    """
    maps = list(maps)
    labels = list(labels) if labels else [dm.design for dm in maps]
    # One arm: its five measures on a 2 x 3 grid (not a 5-panel strip). Several arms: measures
    # in columns (named on each panel), arms in rows (named on the left). Each colourbar is a
    # slim bar under its panel.
    single = len(maps) == 1
    shape = (2, 3) if single else (len(maps), len(MEASURES))
    fig, axes = figure(*shape, figsize=(3.4 * shape[1], 3.3 * shape[0]), squeeze=False)
    if single:
        axes[1, 2].set_axis_off()
    for row, dm in enumerate(maps):
        pts = dm.tips[dm.valid, :2]
        for col, name in enumerate(MEASURES):
            label, scale, unit = _MEASURE_LABELS[name]
            values = dm.measure(name)[dm.valid]
            if name == "manipulability" and dm.sigma.shape[1] == 2:
                values = np.sqrt(values)  # the thesis plots the geometric mean √(σ1σ2)
            elif name == "manipulability":
                label, unit = "(c) σ1···σk", "σ1···σk ((m/Pa)^k)"
            ax = axes[divmod(col, 3)] if single else axes[row, col]
            hi = np.nanpercentile(values / scale, 98) if values.size else 1.0
            sc = ax.scatter(pts[:, 0], pts[:, 1], c=values / scale, s=2, cmap=SEQUENTIAL_CMAP,
                            vmin=np.nanmin(values / scale) if values.size else 0, vmax=hi,
                            rasterized=True)
            bar = fig.colorbar(sc, ax=ax, location="bottom", fraction=0.05, pad=0.02, aspect=30)
            bar.set_label(unit, fontsize=7)
            bar.ax.tick_params(labelsize=6)
            bar.ax.xaxis.set_major_locator(MaxNLocator(4))
            ax.set_aspect("equal")
            few_ticks(ax, 4)
            ax.tick_params(labelsize=7)
            ax.set_xlabel("x (m)", fontsize=7, labelpad=1)
            ax.set_ylabel("y (m)" if single or col else f"{labels[row]}\ny (m)", fontsize=8)
            ax.set_title(f"{labels[row]}: {label}" if single else label, fontsize=9)
            ax.grid(alpha=0.3)
    return save(fig, path)


def plot_dexterous_area(curves, path, normalise: str = "workspace"):
    """Fig. 5.6: dexterous area versus σ_min threshold.

    Args:
        curves: ``{label: (thresholds (m/Pa), areas (m²), length L (m))}``.
        path: image file.
        normalise: ``"workspace"`` (fraction of the area at threshold 0) or ``"pi_L2"``.

    Returns:
        The (closed) matplotlib figure.
    """
    fig, axes = figure(1, 1, figsize=(5.5, 4), squeeze=False)
    ax = axes[0, 0]
    for (label, (thresholds, areas, length)), style in zip(curves.items(), ("-", "--", ":", "-.")):
        denom = areas[0] if normalise == "workspace" else math.pi * length**2
        ax.plot(np.asarray(thresholds) / 1e-8, np.asarray(areas) / denom, style, label=label)
    ax.set_xlabel("σ_min threshold (1e-8 m/Pa)")
    ax.set_ylabel("dexterous area / workspace area (–)" if normalise == "workspace"
                  else "dexterous area / πL² (–)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, path)
