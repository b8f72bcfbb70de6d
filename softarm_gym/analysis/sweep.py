"""Pressure-grid sweeps: tip positions over a full factorial grid, chunked over
:func:`solver.solve_batch`, on this machine (numba) or on a Ray cluster.

The grid is never materialised whole: row ``k`` of a grid with ``levels`` per input is the
base-``levels`` expansion of ``k`` (last input fastest, as ``itertools.product``), so a
7⁹ = 40,353,607-point spatial sweep needs memory only for its tips and one chunk of
pressures at a time. Each chunk is one :func:`solver.solve_batch` call, whose rows are
independent cold solves: the result of a sweep does not depend on the chunking or on the
backend, so a Ray run returns exactly the local run's tips.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

import solver

__all__ = ["PressureGrid", "pressure_grid", "sweep_tips", "BACKENDS", "DEFAULT_CHUNK"]

BACKENDS = ("local", "ray")
DEFAULT_CHUNK = 8192
"""Rows per :func:`solver.solve_batch` call: large enough that the per-call Python overhead
(validation, packing) is negligible, small enough for a smooth progress bar."""


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
    """One chunk of the sweep: (tips (stop − start, dim), converged (stop − start,))."""
    return solver.solve_batch(arm, grid.rows(start, stop), scene, model=model, planar=planar)


def sweep_tips(arm: solver.designs.ArmDesign, grid: PressureGrid, scene: solver.Scene,
               model: str = "full", planar: bool = True, backend: str = "local",
               chunk_size: int = DEFAULT_CHUNK, address: str | None = None,
               progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Tip position of every grid row, chunked over :func:`solver.solve_batch`.

    Args:
        arm, scene, model, planar: as in :func:`solver.solve`.
        grid: the pressures (:func:`pressure_grid`).
        backend: ``"local"`` (numba threads on this machine) or ``"ray"`` (one Ray task per
            chunk; needs the ``ray`` extra).
        chunk_size: rows per :func:`solver.solve_batch` call.
        address: Ray cluster address (``"auto"``, ``"ray://host:10001"``); None starts or
            reuses a local Ray instance. Ignored by the local backend.
        progress: draw a progress bar on stderr.

    Returns:
        ``(tips, converged)``: (grid.size, 2|3) tips (m) and (grid.size,) bool.
    """
    _check_arm(arm)
    if not isinstance(grid, PressureGrid):
        raise ValueError(f"grid must be a PressureGrid (see pressure_grid); got {type(grid).__name__}")
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if isinstance(chunk_size, bool) or int(chunk_size) != chunk_size or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer >= 1; got {chunk_size!r}")
    if backend == "local" and address is not None:
        raise ValueError("a Ray address was given but the backend is 'local'; use backend='ray'")
    # Validate the arm/scene/model once, before any work is split up.
    solver.solve_batch(arm, grid.rows(0, 1), scene, model=model, planar=planar)
    n = grid.size
    tips = np.empty((n, 2 if planar else 3))
    converged = np.empty(n, dtype=bool)
    bounds = [(a, min(a + int(chunk_size), n)) for a in range(0, n, int(chunk_size))]
    bar = tqdm(total=n, unit="pt", file=sys.stderr, disable=not progress, desc=f"{arm.name} sweep")
    try:
        if backend == "local":
            for a, b in bounds:
                tips[a:b], converged[a:b] = _solve_chunk(arm, grid, a, b, scene, model, planar)
                bar.update(b - a)
        else:
            _ray_sweep(arm, grid, scene, model, planar, bounds, address, tips, converged, bar)
    finally:
        bar.close()
    return tips, converged


def _ray_sweep(arm, grid, scene, model, planar, bounds, address, tips, converged, bar):
    """Run the chunks as Ray tasks and write each result into its rows."""
    try:
        import ray
    except ImportError:
        raise ValueError("backend 'ray' needs Ray: pip install 'softarm-gym[ray]'") from None
    if not ray.is_initialized():
        if address is None:  # a private local instance, quiet
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address)
    task = ray.remote(_solve_chunk)
    shared = [ray.put(v) for v in (arm, grid, scene)]
    pending = {task.remote(shared[0], shared[1], a, b, shared[2], model, planar): (a, b)
               for a, b in bounds}
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        for ref in done:
            a, b = pending.pop(ref)
            tips[a:b], converged[a:b] = ray.get(ref)
            bar.update(b - a)
