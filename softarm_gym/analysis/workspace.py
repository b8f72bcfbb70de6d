"""Reachable workspace of a soft arm: the tip cloud over a pressure grid and its statistics.

Area, two documented methods on the tip cloud (projected onto the x–y plane for a spatial
sweep):

* **alpha shape** (default, ``area_m2``): the Delaunay triangulation of the distinct tips,
  keeping the triangles whose circumradius is at most ``alpha``; the area is the sum of the
  kept triangles. It follows concave boundaries and leaves holes larger than ``alpha``
  open, and unlike a cell count it does not shrink when the grid is coarse, as long as
  ``alpha`` exceeds the largest gap between neighbouring tips inside the workspace.
  ``alpha`` defaults to ``DEFAULT_ALPHA_FRACTION`` of the arm length.
* **convex hull** (``hull_area_m2``): the area enclosed by the outer envelope with every
  concavity filled in. Not a reachable area (it includes the unreachable region around the
  base), but it is the measure the thesis's §5.3.1 areas (0.5πL², 0.6πL²) match.
* **occupancy grid** (``occupancy_area(cell)``): the number of ``cell``×``cell`` squares that
  hold at least one tip, times the cell area. It depends on the cell size (cells finer than
  the gaps between tips undercount, coarse cells overcount the boundary); reported beside
  the alpha shape for comparison.

Density (``density(cell)``) is tips per cm² on the same square cells, as the contours of the
thesis's Figs. 2.7 and 5.4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial import ConvexHull, Delaunay, QhullError

import solver
from softarm_gym.analysis.sweep import PressureGrid, pressure_grid, tips_plan
from softarm_gym.jobs import Plan, Runner

__all__ = ["Workspace", "workspace", "workspace_plan", "alpha_shape_area", "alpha_complex",
           "occupancy_area", "DEFAULT_ALPHA_FRACTION"]

DEFAULT_ALPHA_FRACTION = 0.1
"""Default alpha-shape radius as a fraction of the arm length (5.3 cm for a 53 cm arm)."""


def alpha_complex(points: np.ndarray, alpha: float):
    """The triangles of the 2-D alpha shape of ``points``, by index.

    Args:
        points: (n, 2) points (m); duplicates (to 1e-9 m) are merged.
        alpha: largest circumradius of a kept Delaunay triangle (m), > 0.

    Returns:
        ``(unique, inverse, triangles, areas)``: (u, 2) distinct points, (n,) index of each
        input point in ``unique``, (k, 3) kept triangles as indices into ``unique`` and their
        (k,) areas (m²). No triangles when the points span no area.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2); got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite (drop unconverged tips first)")
    if not (isinstance(alpha, (int, float)) and math.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha must be a finite length > 0 m; got {alpha!r}")
    unique, inverse = np.unique(np.round(pts, 9), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    none = np.empty((0, 3), dtype=np.int64), np.empty(0)
    if unique.shape[0] < 3:
        return unique, inverse, *none
    try:
        simplices = Delaunay(unique).simplices
    except QhullError:  # all points on a line: no area
        return unique, inverse, *none
    tri = unique[simplices]
    a = np.linalg.norm(tri[:, 1] - tri[:, 2], axis=1)
    b = np.linalg.norm(tri[:, 0] - tri[:, 2], axis=1)
    c = np.linalg.norm(tri[:, 0] - tri[:, 1], axis=1)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    radius = np.full(area.shape, np.inf)
    np.divide(a * b * c, 4.0 * area, out=radius, where=area > 0)
    keep = radius <= alpha
    return unique, inverse, simplices[keep], area[keep]


def alpha_shape_area(points: np.ndarray, alpha: float) -> float:
    """Area (m²) of the 2-D alpha shape of ``points`` (see :func:`alpha_complex`)."""
    return float(alpha_complex(points, alpha)[3].sum())


def occupancy_area(points: np.ndarray, cell: float) -> float:
    """Area (m²) of the ``cell``-sized squares (aligned to the origin) holding a point."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or not np.all(np.isfinite(pts)):
        raise ValueError(f"points must be a finite (n, 2) array; got shape {pts.shape}")
    if not (isinstance(cell, (int, float)) and math.isfinite(cell) and cell > 0):
        raise ValueError(f"cell must be a finite length > 0 m; got {cell!r}")
    cells = np.unique(np.floor(pts / cell).astype(np.int64), axis=0)
    return float(cells.shape[0] * cell * cell)


@dataclass(frozen=True)
class Workspace:
    """The tips of an arm over a pressure grid, with the statistics of the converged ones.

    Attributes:
        design: design name.
        grid: the pressures swept (row k of ``grid.rows()`` gave ``tips[k]``).
        tips: (n, 2|3) tip positions (m).
        converged: (n,) the solve converged; statistics use converged tips only.
        scene: mounting and loads.
        model: solver model.
        planar: planar or spatial sweep.
        length: arm reference length L (m), for normalised areas.
        alpha: alpha-shape radius used by :attr:`area_m2` (m).
        seconds: compute time of the sweep (s): the sum of its chunks' times, which is the
            wall time on the local backend (chunks of a resumed sweep count with the time
            they took when they ran; on Ray, chunks overlap).
    """

    design: str
    grid: PressureGrid
    tips: np.ndarray
    converged: np.ndarray
    scene: solver.Scene
    model: str
    planar: bool
    length: float
    alpha: float
    seconds: float = field(default=0.0, compare=False)

    @property
    def n(self) -> int:
        """Number of grid points."""
        return int(self.tips.shape[0])

    @property
    def n_failed(self) -> int:
        """Grid points whose solve did not converge (excluded from the statistics)."""
        return int(self.n - np.count_nonzero(self.converged))

    @cached_property
    def good_tips(self) -> np.ndarray:
        """(k, 2|3) converged tips (m)."""
        return self.tips[self.converged]

    @property
    def plane_tips(self) -> np.ndarray:
        """(k, 2) converged tips projected onto the x–y plane (m)."""
        return self.good_tips[:, :2]

    @property
    def mean_tip(self) -> np.ndarray:
        """Mean converged tip position (m), (2,) or (3,)."""
        return self.good_tips.mean(axis=0)

    @property
    def highest_tip(self) -> np.ndarray:
        """The converged tip with the largest y (m); of mirror-image ties, the one with x ≥ 0."""
        tips = self.good_tips
        top = tips[:, 1].max()
        ties = tips[tips[:, 1] >= top - 1e-9]
        return ties[np.argmax(ties[:, 0])].copy()

    @cached_property
    def area_m2(self) -> float:
        """Alpha-shape area of the (projected) tip cloud (m²)."""
        return alpha_shape_area(self.plane_tips, self.alpha)

    @cached_property
    def hull_area_m2(self) -> float:
        """Convex-hull area of the (projected) tip cloud (m²); 0 if the tips are collinear."""
        try:
            return float(ConvexHull(np.unique(np.round(self.plane_tips, 9), axis=0)).volume)
        except (QhullError, ValueError):
            return 0.0

    @property
    def area_fraction(self) -> float:
        """:attr:`area_m2` in units of πL², the unit of the thesis's §5.3.1."""
        return self.area_m2 / (math.pi * self.length**2)

    def occupancy_area(self, cell: float = 0.01) -> float:
        """Occupancy-grid area of the (projected) tip cloud on ``cell`` squares (m²)."""
        return occupancy_area(self.plane_tips, cell)

    def density(self, cell: float = 0.01):
        """Tips per cm² on ``cell`` squares covering the (projected) tip cloud.

        Returns:
            ``(density, x_edges, y_edges)``: (nx, ny) points/cm² and the cell edges (m).
        """
        if not (isinstance(cell, (int, float)) and math.isfinite(cell) and cell > 0):
            raise ValueError(f"cell must be a finite length > 0 m; got {cell!r}")
        pts = self.plane_tips
        lo = np.floor(pts.min(axis=0) / cell) * cell
        hi = np.ceil(pts.max(axis=0) / cell) * cell + cell
        x_edges = np.arange(lo[0], hi[0] + 0.5 * cell, cell)
        y_edges = np.arange(lo[1], hi[1] + 0.5 * cell, cell)
        counts, _, _ = np.histogram2d(pts[:, 0], pts[:, 1], bins=(x_edges, y_edges))
        return counts / (cell * 100.0) ** 2, x_edges, y_edges

    def summary(self) -> dict:
        """The JSON payload of ``softarm workspace``."""
        return {
            "design": self.design, "model": self.model, "planar": self.planar,
            "base_angle_deg": self.scene.base_angle_deg, "payload_kg": self.scene.payload_kg,
            "gravity": self.scene.gravity, "levels": int(self.grid.levels.size),
            "max_psi": float(self.grid.levels[-1] / solver.PSI), "n": self.n,
            "n_failed": self.n_failed, "mean_tip": self.mean_tip.tolist(),
            "highest_tip": self.highest_tip.tolist(), "area_m2": self.area_m2,
            "area_method": f"alpha shape, alpha = {self.alpha:.4g} m",
            "area_pi_L2": self.area_fraction, "hull_area_m2": self.hull_area_m2,
            "hull_area_pi_L2": self.hull_area_m2 / (math.pi * self.length**2),
            "occupancy_area_m2_1cm": self.occupancy_area(0.01), "length_m": self.length,
            "seconds": self.seconds,
        }


def workspace(arm: solver.designs.ArmDesign, scene: solver.Scene | None = None, *, levels: int = 7,
              max_pressure: float | None = None, model: str = "full", planar: bool = True,
              alpha: float | None = None, backend: str = "local", chunk_size: int | None = None,
              address: str | None = None, progress: bool = False) -> Workspace:
    """Sweep the pressure grid and collect the tip cloud (the thesis's workspace, §2.4, §5.3.1).

    Args:
        arm: the design.
        scene: base angle, payload, gravity (``Scene(gravity=0)`` for the unloaded arm);
            default hanging under gravity.
        levels: pressure levels per input (7 in the thesis).
        max_pressure: top level (Pa); default the design's rated maximum.
        model: ``"full"``, ``"unshearable"`` or ``"constant_curvature"``.
        planar: planar inputs, or one per spatial channel (tips are then 3-D).
        alpha: alpha-shape radius for the area (m); default ``DEFAULT_ALPHA_FRACTION``·L.
        backend, chunk_size, address, progress: see
            :func:`~softarm_gym.analysis.sweep.sweep_tips`.

    Returns:
        The :class:`Workspace`. For chunks kept on disk, resuming, or several workspaces under
        one progress bar, run :func:`workspace_plan` with a :class:`~softarm_gym.jobs.Runner`.
    """
    plan = workspace_plan(arm, scene, levels=levels, max_pressure=max_pressure, model=model,
                          planar=planar, alpha=alpha, chunk_size=chunk_size)
    return Runner(backend, address, progress=progress).run_plans([plan], desc=f"{arm.name} sweep")[0]


def workspace_plan(arm: solver.designs.ArmDesign, scene: solver.Scene | None = None, *,
                   levels: int = 7, max_pressure: float | None = None, model: str = "full",
                   planar: bool = True, alpha: float | None = None,
                   chunk_size: int | None = None) -> Plan:
    """The chunks of :func:`workspace` (same arguments); the plan's result is the :class:`Workspace`.

    Raises:
        ValueError: bad arguments; when the plan finishes, no grid point converged.
    """
    scene, alpha = sweep_inputs(arm, scene, alpha)
    grid = pressure_grid(arm, levels, max_pressure, planar)
    tips = tips_plan(arm, grid, scene, model, planar, chunk_size)

    def finish(results, seconds):
        points, converged = tips.finish(results, seconds)
        if not converged.any():
            raise ValueError(f"no grid point of design {arm.name!r} converged; nothing to analyse")
        return Workspace(design=arm.name, grid=grid, tips=points, converged=converged, scene=scene,
                         model=model, planar=planar, length=arm.length, alpha=float(alpha),
                         seconds=float(sum(seconds)))
    return Plan(tips.chunks, finish)


def sweep_inputs(arm, scene, alpha):
    """Validated (scene, alpha) of a sweep: default scene, alpha-shape radius default 0.1·L."""
    scene = solver.Scene() if scene is None else scene
    if not isinstance(arm, solver.designs.ArmDesign):
        raise ValueError(f"arm must be a solver.designs.ArmDesign; got {type(arm).__name__}")
    alpha = DEFAULT_ALPHA_FRACTION * arm.length if alpha is None else alpha
    if not (isinstance(alpha, (int, float)) and math.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha must be a finite length > 0 m; got {alpha!r}")
    return scene, alpha
