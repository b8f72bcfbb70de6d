"""The steppers' row kernels in scenes with contact: one warm step of one copy, by the lean
path its state allows, and the same over many copies (numba ``prange``).

A copy's state lives on one of two grids: the settings' (a contact-free equilibrium, stepped
by the lean planar kernel :func:`solver.kernels.planar.warm_step`, guarded against touching)
or the contact layout (an equilibrium from the contact paths, stepped by
:func:`solver.kernels.contact.lean_step`). :func:`contact_row` takes them in the order the
general path does (:func:`solver.paths.contact.solve_contact`): from a state in contact,
contact; from one that touches nothing, the contact-free step first and contact where that
would touch. A row it cannot step is reported unconverged with its state untouched: the
caller's general path takes it (:mod:`solver.paths.lean_contact`). The single stepper runs
these kernels on a batch of one, so a batched copy and a single stepper agree bit for bit.

Argument tuples (arrays indexed by copy k first):

* ``free``: (grid (θ0, secf, steps), tubes, loads (ns, 4), m_tip, params, states (n, 4),
  records (n, rows, N_COLUMNS), scratch (n, rows, N_COLUMNS), rest (n, 3, ns),
  p_now (n, nc), loads_now (n, ns, 4), memo (p_seen, stretch, rest_a, grad; per copy),
  half (rows,), exclusion, ok (n,) bool): the lean planar path's grid, the copies' states
  on it and its guard (:func:`solver.kernels.planar.warm_step`); ``ok[k]``: copy k has a
  record there.
* ``contact``: (grid (``G_*``), params, weights (N,), res_weights (N,), nodes (n, N),
  p_level (n, nc), q, plate, target, discs (n, k, 4), rest (n, 3, ns), factors (per copy,
  :func:`solver.kernels.contact.new_factors`), records (n, rows_c, C_COLUMNS),
  scratch (n, rows_c, C_COLUMNS), check (q, ends), ok (n,) bool, touching (n,) bool): the
  contact layout, the copies' states on it; ``ok[k]``: copy k has one; ``touching[k]``: it
  presses on a disc or on itself.
"""

from __future__ import annotations

import math

from solver.jit import njit, prange
from solver.kernels.contact import lean_step
from solver.kernels.planar import warm_step
from solver.layout import C_PEN, D_THETA, S, U
from solver.rod import integrate_planar, planar_rest_gradient, rest_strains_into


@njit
def touches(record) -> bool:
    """Whether a contact record (rows, C_COLUMNS) presses anywhere (penetration > 0)."""
    for r in range(record.shape[0]):
        if record[r, C_PEN] > 0.0:
            return True
    return False


@njit
def free_record_of(crec, m0, p_channel, free, k):
    """Write copy k's record on the settings' grid (``free`` tuple, see the module) for the
    contact-layout state whose record is ``crec`` (rows_c, C_COLUMNS) and base moment
    ``m0``: its columns S … U where the grids agree, else the backbone of ``m0`` integrated
    on the settings' grid (where the general path's contact-free step starts it); with its
    rest strains and the predictor's gradient, the first variations NaN."""
    grid, tubes, loads = free[0], free[1], free[2]
    theta0, secf, steps = grid
    states, records = free[5], free[6]
    rest_a, grad = free[11][2], free[11][3]
    rec = records[k]
    rest_strains_into(p_channel, tubes[0], tubes[1], secf, rest_a[k])
    if crec.shape[0] == rec.shape[0]:
        for r in range(rec.shape[0]):
            for c in range(S, U + 1):
                rec[r, c] = crec[r, c]
    else:
        integrate_planar(m0, theta0, secf, steps, rest_a[k], loads, True, rec)
    rec[:, D_THETA:] = math.nan
    planar_rest_gradient(rec, secf, steps, rest_a[k], grad[k])
    states[k, 0] = m0


@njit(inline="always")
def contact_row(k, free, contact, p_from, p_to, report):
    """One warm step of copy k from ``p_from[k]`` to ``p_to[k]`` (channel pressures, Pa),
    by the lean path its state allows (module docstring). ``report[k]``: (converged, stable,
    snapped, iterations, residual, path): path 1 the lean planar kernel, 2 the lean contact
    one; unconverged: the state is as it was."""
    report[k, 0] = 0.0
    report[k, 3] = 0.0
    c_ok, touching = contact[15], contact[16]
    if c_ok[k] and touching[k]:
        _contact_step(k, free, contact, p_to, report)
        return
    f_ok = free[14]
    if not f_ok[k]:
        return
    grid, tubes, loads, m_tip, params, states, records, scratch = free[:8]
    m_start = states[k, 0]
    ok, stable, snapped, its, res, _, _ = warm_step(
        states[k], grid, tubes, (p_from[k], loads, m_tip), (p_to[k], loads, m_tip), params,
        (free[8][k], free[9][k], free[10][k], scratch[k], True),
        (free[11][0][k], free[11][1][k], free[11][2][k], free[11][3][k]),
        (contact[9][k], records[k], free[12], free[13]))
    report[k, 3] = its
    if ok:
        records[k, :, :] = scratch[k]
        c_ok[k] = False  # its contact state is the one before this step
        report[k, 0] = 1.0
        report[k, 1] = stable
        report[k, 2] = snapped
        report[k, 4] = res
        report[k, 5] = 1.0
        return
    states[k, 0] = m_start
    if c_ok[k]:
        _contact_step(k, free, contact, p_to, report)


@njit(inline="always")
def _contact_step(k, free, contact, p_to, report):
    """:func:`solver.kernels.contact.lean_step` of copy k; on success its state, and if it
    touches nothing any more, its record on the settings' grid too."""
    grid, params, weights, res_weights, nodes, p_level, q, plate, target, discs = contact[:10]
    rest, factors, records, scratch, check, c_ok, touching = contact[10:]
    level = (p_level[k], q, plate, target, discs[k])
    ok, stable, its, res = lean_step(
        nodes[k], grid, (free[1][0], free[1][1]), level, p_to[k], params,
        (rest[k], weights, res_weights),
        (factors[0][k], factors[1][k], factors[2][k], factors[3][k], factors[4][k]),
        (records[k], scratch[k]), check)
    report[k, 3] += its
    if not ok:
        return
    records[k, :, :] = scratch[k]
    report[k, 0] = 1.0
    report[k, 1] = stable
    report[k, 2] = 0.0
    report[k, 4] = res
    report[k, 5] = 2.0
    touching[k] = touches(records[k])
    free[14][k] = not touching[k]
    if not touching[k]:
        free_record_of(records[k], nodes[k][2], p_level[k], free, k)


@njit(parallel=True)
def contact_rows_parallel(free, contact, p_from, p_to, active, report):
    """:func:`contact_row` of every copy where ``active`` (n,), over numba's threads."""
    for k in prange(p_to.shape[0]):
        if active[k]:
            contact_row(k, free, contact, p_from, p_to, report)


@njit
def contact_rows_serial(free, contact, p_from, p_to, active, report):
    """:func:`contact_rows_parallel` on one thread: the same numbers."""
    for k in range(p_to.shape[0]):
        if active[k]:
            contact_row(k, free, contact, p_from, p_to, report)

