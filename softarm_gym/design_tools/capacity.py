"""Load capacity W (thesis §3, Fig. 3.1): the heaviest tip load an arm lifts to horizontal.

The arm is clamped horizontally (base angle 90°) and its lifting channels — II and III of
every section, the two control channels that planar operation drives together
(§2.3.2.1) — are pressurised to the test pressure, channel I staying at 0 (see
``docs/design_tools.md`` for why this is the configuration §3.3 means). A dead tip load W
(N, downwards) is then raised quasi-statically; W is the load at which the tip reaches
height y = 0. Where the equilibrium is unique this is the same as loading first and
pressurising afterwards ("brought to horizontal by pressurization").

The path is followed with warm-started :func:`solver.solve` steps of adaptive size: a step
whose tip moves more than ``MAX_TIP_STEP``·L is halved, so the search cannot jump to a
distant equilibrium branch; the crossing of y = 0 is then bisected, each trial starting
from the last equilibrium on the path. A negative W (an upward tip force is needed) means
the arm cannot lift even itself to horizontal. Where the loading path passes a fold the
tip jumps across y = 0 even at the smallest step, W is the fold load and the result says
``fold_limited``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import solver
from softarm_gym.design_tools.template import lifting_pressures

__all__ = ["LoadCapacity", "load_capacity"]

BASE_ANGLE_DEG = 90.0
"""The load-capacity test mounts the arm horizontally (§3)."""

MAX_TIP_STEP = 0.05
"""Largest tip move per continuation step, as a fraction of the arm length."""

MIN_PRESSURE_STEP = 1.0 / 1024.0
"""Smallest pressure step (fraction of p_test) before a jump is accepted as a snap."""

FOLD_JUMP = 0.01
"""Tip jump (fraction of the arm length) across the final W bracket that marks a fold."""


@dataclass(frozen=True)
class LoadCapacity:
    """Result of :func:`load_capacity`.

    Attributes:
        load_n: W, the tip load lifted to y = 0 (N); negative when the arm needs an upward
            tip force to reach horizontal (it cannot hold itself up).
        tip_unloaded: (2,) tip position at the test pressure without load (m).
        fold_limited: the tip height jumps across y = 0 at ``load_n`` (a fold on the
            loading path), so W is the fold load rather than a smooth crossing.
        converged: every solve in the search converged.
        evaluations: number of solves.
    """

    load_n: float
    tip_unloaded: np.ndarray
    fold_limited: bool
    converged: bool
    evaluations: int

    @property
    def self_supporting(self) -> bool:
        """True when the arm lifts a non-negative load to horizontal."""
        return self.load_n >= 0.0


def load_capacity(arm: solver.designs.ArmDesign, test_pressure: float, *, model: str = "full",
                  gravity: float = 9.81, tol_n: float = 1e-3, max_load_n: float = 1e7) -> LoadCapacity:
    """Load capacity W of ``arm`` at ``test_pressure`` (§3, Fig. 3.1).

    Args:
        arm: an OctArm-layout design (planar channels ``s{k}_I``, ``s{k}_II+III``).
        test_pressure: p_test (Pa), applied to every section's II + III channels.
        model: solver model (``"full"``, ``"unshearable"``, ``"constant_curvature"``).
        gravity: m/s².
        tol_n: absolute tolerance on W (N).
        max_load_n: give up when |W| would exceed this (N).

    Returns:
        The :class:`LoadCapacity`.

    Raises:
        ValueError: bad pressure, design or tolerance, or no load up to ``max_load_n``
            brings the tip to y = 0.
    """
    if not (isinstance(tol_n, (int, float)) and tol_n > 0):
        raise ValueError(f"tol_n must be > 0 N; got {tol_n!r}")
    pressures = lifting_pressures(arm, test_pressure)
    max_move = MAX_TIP_STEP * arm.length
    solves = 0
    all_converged = True

    def solve(load: float, fraction: float, start) -> solver.Equilibrium:
        nonlocal solves, all_converged
        scene = solver.Scene(base_angle_deg=BASE_ANGLE_DEG, gravity=gravity, tip_force=(0.0, -load))
        eq = solver.solve(arm, fraction * pressures, scene, model=model, record=False, warm_start=start)
        solves += 1
        all_converged &= eq.converged
        return eq

    def moved(a: solver.Equilibrium, b: solver.Equilibrium) -> float:
        return float(np.hypot(*(a.tip - b.tip)))

    # Pressurise the unloaded arm along the quasi-static path.
    eq = solve(0.0, 0.0, None)
    fraction, step = 0.0, 0.25
    while fraction < 1.0:
        trial_fraction = min(1.0, fraction + step)
        trial = solve(0.0, trial_fraction, eq)
        if moved(trial, eq) > max_move and step > MIN_PRESSURE_STEP:
            step /= 2.0
            continue
        fraction, eq, step = trial_fraction, trial, min(2.0 * step, 0.25)
    unloaded = eq
    above = bool(unloaded.tip[1] >= 0.0)
    direction = 1.0 if above else -1.0  # add load, or an upward force, until y crosses 0

    def crossed(eq_: solver.Equilibrium) -> bool:
        return bool(eq_.tip[1] >= 0.0) != above

    # March the load from 0 with adaptive steps until the tip crosses y = 0. A step that
    # moves the tip too far is halved; one that still jumps at tol_n is a genuine snap.
    first_step = max(arm.mass * gravity, 1.0) / 8.0
    lo, eq_lo, step = 0.0, unloaded, first_step
    while True:
        if abs(lo) > max_load_n:
            raise ValueError(f"no tip load up to {max_load_n:.3g} N brings the tip of {arm.name!r} "
                             f"to y = 0 at {test_pressure:.6g} Pa")
        load = lo + direction * step
        trial = solve(load, 1.0, eq_lo)
        if moved(trial, eq_lo) > max_move and step > tol_n:
            step /= 2.0
            continue
        if crossed(trial):
            hi, eq_hi = load, trial
            break
        lo, eq_lo, step = load, trial, min(2.0 * step, first_step)
    # Bisect the crossing, always continuing from the last equilibrium before it.
    while abs(hi - lo) > tol_n:
        mid = 0.5 * (lo + hi)
        trial = solve(mid, 1.0, eq_lo)
        if crossed(trial):
            hi, eq_hi = mid, trial
        else:
            lo, eq_lo = mid, trial
    return LoadCapacity(load_n=float(0.5 * (lo + hi)), tip_unloaded=np.asarray(unloaded.tip, dtype=float),
                        fold_limited=bool(moved(eq_hi, eq_lo) > FOLD_JUMP * arm.length),
                        converged=bool(all_converged), evaluations=solves)
