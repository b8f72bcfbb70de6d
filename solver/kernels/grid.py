"""The step-size check: is an RK4 grid fine enough for the equilibrium solved on it?

The shooting and multiple-shooting kernels integrate with a fixed number of RK4 steps per
section. Newton's residual says the discrete equations are met, not that their solution is
near the rod's: a 100 N m tip moment on OctArm V turns the backbone by 5 rad per default
step, and the converged tip is metres off. So a result is checked on its own samples, step
by step (docs/design.md §11). Over a step of length h in section i the solution varies on
the shortest of three lengths, each a rate ω:

* the turn of the backbone, |u| (rad/m);
* the load's turn of it, √(|r'|·|n|/EI): m' = r' × n changes the curvature across a step
  by h·|m'|/EI, and the elastica bends over EI/|n|;
* the distributed load's, ∛(|r'|·|q|/EI) (the third derivative of θ).

RK4's local error is O((h·ω)⁵), so the check bounds h·ω ≤ :data:`STEP_TURN` at every sample.
Where it fails, the solve is repeated on a grid refined by powers of two in the sections that
need it (:func:`refined_steps`); where the refinement limit is reached first the result is
reported unconverged.
"""

from __future__ import annotations

import math

from solver.jit import njit
from solver.layout import CI, LEN, NX, NY, QX, QY, V1, V3, U

# Largest h·ω (rad) a step may take. Measured on OctArm V (`docs/design.md` §11): the tip
# error is 2e-6·L at h·ω = 0.54 under a pure tip moment and 5e-6·L at 0.55 under a tip
# force, and falls as (h·ω)⁴; the thesis's arms reach 0.31 at their rated pressures on the
# default grid, so the check refines nothing they do.
STEP_TURN = 0.5


@njit
def section_needs(curv, force, strain, q, secf, ends, need):
    """The largest h·ω / :data:`STEP_TURN` over every section's samples (> 1: too coarse).

    Args:
        curv: (N, 1|3) curvature (rad/m) at the samples (junctions repeated). force: (N, 2|3)
            internal force (N). strain: (N, 2|3) strain vector v (|r'| = |v|).
        q: (ns,) |distributed load| per reference length of each section (N/m).
        secf: (6, ns) section array. ends: (ns,) the samples' rows at the section ends.
        need: (ns,) written; infinite where a sample is not finite.

    Returns:
        The largest need (infinite if a sample is not finite).
    """
    row = 0
    most = 0.0
    for i in range(secf.shape[1]):
        need[i] = _section_need(curv, force, strain, row, ends[i], secf[LEN, i], secf[CI, i], q[i])
        most = max(most, need[i])
        row = ends[i] + 1
    return most


@njit(inline="always")
def _section_need(curv, force, strain, first, last, length, ci, q):
    """h·ω / :data:`STEP_TURN` of one section, samples ``first`` … ``last`` (rows)."""
    h = length / (last - first)
    qc2 = (q * ci) ** 2
    # The rates' powers free of roots, maximised over the samples; the roots (monotonic) are
    # taken once per section: turn², load⁴ = |v|²|n|²/EI², spread⁶ = |v|²(|q|/EI)².
    turn2 = load4 = spread6 = 0.0
    finite = True
    for row in range(first, last + 1):
        u2 = _square(curv[row])
        v2 = _square(strain[row])
        l4 = v2 * _square(force[row]) * ci * ci
        s6 = v2 * qc2
        finite = finite and u2 <= math.inf and l4 <= math.inf and s6 <= math.inf
        turn2 = max(turn2, u2)
        load4 = max(load4, l4)
        spread6 = max(spread6, s6)
    worst = h * max(math.sqrt(turn2), math.sqrt(math.sqrt(load4)), spread6 ** (1.0 / 6.0))
    return worst / STEP_TURN if finite else math.inf


@njit(inline="always")
def _square(v):
    acc = 0.0
    for x in v:
        acc += x * x
    return acc


@njit
def planar_fine(record, secf, steps, loads):
    """True when the grid resolves a planar dead-load record (every need ≤ 1); allocates
    nothing (it runs inside every warm step of the stepper).

    Args:
        record: (Σ(steps + 1), N_COLUMNS) a backbone record (:func:`solver.rod.integrate_planar`).
        secf, steps: its section array and RK4 steps. loads: (ns, 4) its dead loads.
    """
    curv = record[:, U:U + 1]
    force = record[:, NX:NY + 1]
    strain = record[:, V1:V3 + 1]
    first = 0
    for i in range(secf.shape[1]):
        last = first + steps[i]
        q = math.hypot(loads[i, QX], loads[i, QY])
        if not _section_need(curv, force, strain, first, last, secf[LEN, i], secf[CI, i], q) <= 1.0:
            return False
        first = last + 1
    return True
