"""The step-size check's Python side: a recorded result's needs, the next grid, and a fine
result sampled back on a coarse grid (the kernels and the check itself:
:mod:`solver.kernels.grid`)."""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from solver.kernels.grid import section_needs
from solver.results import SAMPLED


def needs(eq, secf, q) -> tuple[np.ndarray, float]:
    """:func:`section_needs` of a recorded :class:`~solver.results.Equilibrium` (planar or
    spatial, dead loads or contact).

    Args:
        secf: (6, ns) the section array. q: (ns,) |distributed load| (N/m).

    Returns:
        (ns,) need per section, and the largest.
    """
    curv = eq.curvature if eq.curvature.ndim == 2 else eq.curvature[:, None]
    need = np.empty(secf.shape[1])
    worst = section_needs(curv, eq.internal_force, eq.shear_stretch, q, secf,
                          section_rows(eq.section_ends), need)
    return need, worst


@lru_cache(maxsize=256)
def section_rows(section_ends: tuple) -> np.ndarray:
    """``section_ends`` as an int array (a solve's grid is one of a few; not to be written)."""
    return np.array(section_ends, dtype=np.int64)


def refined_steps(eq, base_steps, current, need, limit):
    """The grid to solve on next, or None where no finer one is allowed.

    Each section that needs it gets base_steps·2^k steps, the least k at which the steps
    ``eq`` was solved with (read from its section ends) times ``need`` are met; never
    fewer than ``current`` (the grid ``eq`` came from) and never more than
    ``limit``·base_steps.

    Args:
        eq: the result. base_steps: (ns,) the settings' grid. current: (ns,) the grid solved
            on. need: (ns,) :func:`needs` of ``eq``. limit: the largest refinement factor.

    Returns:
        (ns,) int steps, or None when the grid cannot be refined where it needs to be.
    """
    used = _steps_of(eq)
    wanted = np.where(need > 1.0, np.ceil(used * np.minimum(need, 1e9)), 0.0)
    factor = np.minimum(2.0 ** np.ceil(np.log2(np.maximum(wanted / base_steps, 1.0))), limit)
    steps = np.maximum(current, base_steps * factor).astype(np.int64)
    if np.any((need > 1.0) & (steps <= used)):
        return None
    return steps


def _steps_of(eq) -> np.ndarray:
    """(ns,) RK4 steps per section of a recorded result, from its section ends."""
    return np.diff(np.concatenate([[-1], np.asarray(eq.section_ends, dtype=np.int64)])) - 1


def on_grid(eq, fine_steps, steps):
    """The samples of ``eq`` (solved with ``fine_steps`` per section) at the nodes of the
    coarser grid ``steps``, each a power-of-two divisor of its fine count: a subset of the
    fine grid's nodes, so nothing is interpolated."""
    rows = []
    start = 0
    for fine, coarse in zip(fine_steps, steps):
        rows.append(start + np.arange(coarse + 1) * (fine // coarse))
        start += fine + 1
    rows = np.concatenate(rows)
    sampled = {name: getattr(eq, name)[rows] for name in SAMPLED if getattr(eq, name).shape[0]}
    ends = tuple(int(v) for v in np.cumsum(np.asarray(steps) + 1) - 1)
    return replace(eq, section_ends=ends, **sampled)
