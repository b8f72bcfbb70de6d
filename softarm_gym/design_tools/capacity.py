"""Load capacity W (thesis §3, Fig. 3.1): the heaviest tip load an arm lifts to horizontal.

The arm is clamped horizontally (base angle 90°) with a dead tip load W (N, downwards)
hanging on it, and its lifting channels — II and III of every section, the two control
channels that planar operation drives together (§2.3.2.1) — are then pressurised from 0
to the test pressure, channel I staying at 0 (see ``docs/design_tools.md`` for why this is
the configuration §3.3 means). The tip height y(W) at the end of that pressurisation is
what the thesis's definition tests: W is the load "brought to horizontal by
pressurization", y(W) = 0.

That path is exactly what a cold :func:`solver.solve` follows (load the unactuated arm,
then ramp the pressures along the stable branch, docs/design.md §1–4), so each y(W) is one cold
solve. The root of y(W) is bracketed by doubling from an eighth of the arm's weight and
found by Brent's method. A negative W (an upward tip force is needed) means the arm cannot
lift even itself to horizontal. Where y(W) jumps across 0 (a snap during pressurisation)
W is the load at the jump and the result says ``fold_limited``.

Loading after pressurising is *not* equivalent for curled arms: a load hung on an arm
whose tip already points backwards rolls it up further, and the tip ends behind the base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

import solver
from softarm_gym.design_tools.template import lifting_pressures

__all__ = ["CapacityError", "LoadCapacity", "load_capacity"]

BASE_ANGLE_DEG = 90.0
"""The load-capacity test mounts the arm horizontally (§3)."""

FOLD_JUMP = 0.01
"""Tip-height jump (fraction of the arm length) across ±tol_n of W that marks a fold."""


class CapacityError(ValueError):
    """The search found no load capacity: the solver failed, or no load reaches y = 0."""


@dataclass(frozen=True)
class LoadCapacity:
    """Result of :func:`load_capacity`.

    Attributes:
        load_n: W, the tip load lifted to y = 0 (N); negative when the arm needs an upward
            tip force to reach horizontal (it cannot hold itself up).
        tip_unloaded: (2,) tip position at the test pressure without load (m).
        tip_at_capacity: (2,) tip position at the test pressure under W (m); x > 0 means the
            load is held in front of the base, as in Fig. 3.1.
        fold_limited: y(W) jumps across 0 at ``load_n`` (a snap during pressurisation), so
            W is the load at the jump rather than a smooth crossing.
        converged: every solve in the search converged.
        evaluations: number of solves.
    """

    load_n: float
    tip_unloaded: np.ndarray
    tip_at_capacity: np.ndarray
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
        ValueError: bad pressure, design or tolerance.
        CapacityError: no load up to ``max_load_n`` brings the tip to y = 0, or the solver
            returned a non-finite tip on the way.
    """
    if not (isinstance(tol_n, (int, float)) and tol_n > 0):
        raise ValueError(f"tol_n must be > 0 N; got {tol_n!r}")
    pressures = lifting_pressures(arm, test_pressure)
    evaluations = 0
    all_converged = True

    def tip(load: float) -> np.ndarray:
        nonlocal evaluations, all_converged
        scene = solver.Scene(base_angle_deg=BASE_ANGLE_DEG, gravity=gravity, tip_force=(0.0, -load))
        eq = solver.solve(arm, pressures, scene, model=model, record=False)
        evaluations += 1
        all_converged &= eq.converged
        if not np.all(np.isfinite(eq.tip)):
            raise CapacityError(f"the solver returned a non-finite tip for {arm.name!r} at a tip load "
                                f"of {load:.6g} N and {test_pressure:.6g} Pa")
        return eq.tip

    unloaded = tip(0.0)
    above = bool(unloaded[1] >= 0.0)
    direction = 1.0 if above else -1.0  # add load, or an upward force, until y crosses 0
    inner, outer = 0.0, direction * max(arm.mass * gravity, 1.0) / 8.0
    while bool(tip(outer)[1] >= 0.0) == above:
        if abs(outer) > max_load_n:
            raise CapacityError(f"no tip load up to {max_load_n:.3g} N brings the tip of {arm.name!r} "
                             f"to y = 0 at {test_pressure:.6g} Pa")
        inner, outer = outer, 2.0 * outer
    root = brentq(lambda w: float(tip(w)[1]), min(inner, outer), max(inner, outer), xtol=tol_n,
                  rtol=1e-10)
    jump = abs(float(tip(root - tol_n)[1] - tip(root + tol_n)[1]))
    return LoadCapacity(load_n=float(root), tip_unloaded=np.asarray(unloaded, dtype=float),
                        tip_at_capacity=np.asarray(tip(root), dtype=float),
                        fold_limited=bool(jump > FOLD_JUMP * arm.length),
                        converged=bool(all_converged), evaluations=evaluations)
