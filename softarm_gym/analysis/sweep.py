"""Pressure-grid sweeps: tip positions over a full factorial grid, chunked over
:func:`solver.solve_batch`, on this machine (numba) or on a Ray cluster.

The grid is never materialised whole: row ``k`` of a grid with ``levels`` per input is the
base-``levels`` expansion of ``k`` (last input fastest, as ``itertools.product``), so a
7⁹ = 40,353,607-point spatial sweep needs memory only for its tips and one chunk of
pressures at a time. Each chunk is one :func:`solver.solve_batch` call, whose rows are
independent cold solves: the result of a sweep does not depend on the chunking or on the
backend, so a Ray run returns exactly the local run's tips. Chunks run through
:class:`softarm_gym.jobs.Runner` (progress bar, Ray, chunks kept on disk, resume).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import solver
from softarm_gym.jobs import BACKENDS, Chunk, Plan, Runner, chunk_bounds

__all__ = ["PressureGrid", "pressure_grid", "sweep_tips", "tips_plan", "default_chunk_size",
           "BACKENDS", "DEFAULT_CHUNK", "DEFAULT_SPATIAL_CHUNK"]

DEFAULT_CHUNK = 8192
"""Rows per planar :func:`solver.solve_batch` call: ~0.4 s for OctArm V at base 45° on this
machine, so the per-call overhead (validation, packing, a Ray task) is negligible."""
DEFAULT_SPATIAL_CHUNK = 2048
"""Rows per spatial call: ~2 s (spatial rows cost ~1 ms each, one core, against ~50 µs planar)."""


def default_chunk_size(planar: bool) -> int:
    """:data:`DEFAULT_CHUNK` for planar sweeps, :data:`DEFAULT_SPATIAL_CHUNK` for spatial ones."""
    return DEFAULT_CHUNK if planar else DEFAULT_SPATIAL_CHUNK


@dataclass(frozen=True)
class PressureGrid:
    """A full factorial grid of channel pressures.

    Attributes:
        levels: (n_levels,) pressure levels shared by every input (Pa), ascending.
        n_inputs: number of channel pressures per row.
    """

    levels: np.ndarray
    n_inputs: int

    def __post_init__(self):
        levels = np.asarray(self.levels, dtype=float)
        if levels.ndim != 1 or levels.size < 1 or not np.all(np.isfinite(levels)):
            raise ValueError(f"grid levels must be a non-empty 1-D array of finite pressures; "
                             f"got {self.levels!r}")
        if np.any(np.diff(levels) <= 0) or levels[0] < 0:
            raise ValueError(f"grid levels must be ascending and >= 0 Pa; got {levels}")
        if int(self.n_inputs) != self.n_inputs or self.n_inputs < 1:
            raise ValueError(f"n_inputs must be an integer >= 1; got {self.n_inputs!r}")
        object.__setattr__(self, "levels", levels)
        object.__setattr__(self, "n_inputs", int(self.n_inputs))

    @property
    def size(self) -> int:
        """Number of rows, ``n_levels ** n_inputs``."""
        return self.levels.size ** self.n_inputs

    def rows(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Pressure rows ``start..stop-1`` (Pa), shape (stop − start, n_inputs)."""
        stop = self.size if stop is None else stop
        if not 0 <= start <= stop <= self.size:
            raise ValueError(f"row range [{start}, {stop}) outside the grid of {self.size} rows")
        index = np.arange(start, stop, dtype=np.int64)
        digits = np.empty((index.size, self.n_inputs), dtype=np.int64)
        base = self.levels.size
        for col in range(self.n_inputs - 1, -1, -1):
            index, digits[:, col] = np.divmod(index, base)
        return self.levels[digits]


def pressure_grid(arm: solver.designs.ArmDesign, levels: int = 7, max_pressure: float | None = None,
                  planar: bool = True) -> PressureGrid:
    """The thesis's workspace grid: ``levels`` equally spaced pressures 0..max on every input.

    Args:
        arm: the design (its input count and rated maximum are used).
        levels: pressure levels per input, >= 2 (7 in the thesis: 0, 1/6, ..., 1 of the maximum).
        max_pressure: top level (Pa); default the design's rated maximum.
        planar: planar inputs (``arm.n_inputs(True)``) or one per spatial channel.

    Returns:
        The :class:`PressureGrid` (``levels ** n_inputs`` rows).
    """
    _check_arm(arm)
    if isinstance(levels, bool) or int(levels) != levels or levels < 2:
        raise ValueError(f"levels must be an integer >= 2; got {levels!r}")
    top = arm.max_pressure if max_pressure is None else float(max_pressure)
    if not (math.isfinite(top) and top > 0):
        raise ValueError(f"max_pressure must be a finite pressure > 0 Pa; got {max_pressure!r}")
    if top > arm.max_pressure * (1 + 1e-12):
        raise ValueError(f"max_pressure {top:.6g} Pa exceeds design {arm.name!r}'s rated maximum "
                         f"{arm.max_pressure:.6g} Pa")
    n_inputs = arm.n_inputs(planar)
    if n_inputs == 0:
        raise ValueError(f"design {arm.name!r} has no pressure inputs to sweep")
    grid_levels = np.linspace(0.0, min(top, arm.max_pressure), int(levels))
    return PressureGrid(grid_levels, n_inputs)


def _check_arm(arm) -> None:
    if not isinstance(arm, solver.designs.ArmDesign):
        raise ValueError(f"arm must be a solver.designs.ArmDesign; got {type(arm).__name__}")


def _solve_chunk(arm, grid, start, stop, scene, model, planar):
    """One chunk of the sweep: ``{"tips": (stop − start, dim), "converged": (stop − start,)}``."""
    tips, converged = solver.solve_batch(arm, grid.rows(start, stop), scene, model=model, planar=planar)
    return {"tips": tips, "converged": converged}


def tips_plan(arm: solver.designs.ArmDesign, grid: PressureGrid, scene: solver.Scene,
              model: str = "full", planar: bool = True, chunk_size: int | None = None) -> Plan:
    """The chunks of :func:`sweep_tips`; the plan's result is ``(tips, converged)``.

    Validates the arm, scene and model with one solve before any work is split up.
    """
    _check_arm(arm)
    if not isinstance(grid, PressureGrid):
        raise ValueError(f"grid must be a PressureGrid (see pressure_grid); got {type(grid).__name__}")
    bounds = chunk_bounds(grid.size, default_chunk_size(planar) if chunk_size is None else chunk_size)
    solver.solve_batch(arm, grid.rows(0, 1), scene, model=model, planar=planar)
    chunks = [Chunk(_solve_chunk, (arm, grid, a, b, scene, model, planar), size=b - a) for a, b in bounds]

    def finish(results, seconds):
        return (np.concatenate([r["tips"] for r in results]),
                np.concatenate([r["converged"] for r in results]))
    return Plan(chunks, finish)


def sweep_tips(arm: solver.designs.ArmDesign, grid: PressureGrid, scene: solver.Scene,
               model: str = "full", planar: bool = True, backend: str = "local",
               chunk_size: int | None = None, address: str | None = None,
               progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Tip position of every grid row, chunked over :func:`solver.solve_batch`.

    Args:
        arm, scene, model, planar: as in :func:`solver.solve`.
        grid: the pressures (:func:`pressure_grid`).
        backend: ``"local"`` (numba threads on this machine) or ``"ray"`` (one Ray task per
            chunk; needs the ``ray`` extra).
        chunk_size: rows per :func:`solver.solve_batch` call (default
            :func:`default_chunk_size`).
        address: Ray cluster address (``"auto"``, ``"HOST:PORT"``, ``"ray://HOST:10001"``);
            None starts or reuses a local Ray instance. Only with the Ray backend.
        progress: draw a progress bar on stderr.

    Returns:
        ``(tips, converged)``: (grid.size, 2|3) tips (m) and (grid.size,) bool.

    For chunks kept on disk and resuming, run :func:`tips_plan` with a
    :class:`~softarm_gym.jobs.Runner`.
    """
    runner = Runner(backend, address, progress=progress)
    plan = tips_plan(arm, grid, scene, model, planar, chunk_size)
    return runner.run_plans([plan], desc=f"{arm.name} sweep")[0]
