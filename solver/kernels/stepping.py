"""The steppers' row kernels in scenes with contact: one warm step of one copy, by the lean
path its state allows, and the same over many copies (:func:`contact_rows`).

A copy's state lives on one of two grids: the settings' (a contact-free equilibrium, stepped
by the lean planar kernel :func:`solver.kernels.planar.warm_step`, guarded against touching)
or the contact layout (an equilibrium from the contact paths, stepped by
:func:`solver.kernels.contact.lean_step`). :func:`contact_row` takes them in the order the
general path does (:func:`solver.paths.contact.solve_contact`): from a state in contact,
contact; from one that touches nothing, the contact-free step first and contact where that
would touch (the state moved onto the contact layout first, :func:`_enter_contact`, as the
general path starts its ramp from it). A row it cannot step is reported unconverged with its
state untouched: the caller's general path takes it (:mod:`solver.paths.lean_contact`). The
single stepper runs these kernels on a batch of one, so a batched copy and a single stepper
agree bit for bit.

The two argument tuples are flat (numba's parallel loops do not take nested tuples), their
items named by the ``FR_*`` and ``CT_*`` constants below; arrays with a first axis of n hold
one row per copy:

* ``free``: the settings' grid (θ0, secf, steps), the tubes, dead loads (ns, 4), tip
  moment and path parameters; the copies' states (n, 4), records and scratch (n, rows,
  N_COLUMNS), rest strains (n, 3, ns), pressures (n, nc) and loads (n, ns, 4) of the
  returned state, the λ(p) memo and predictor (p_seen, stretch (n, n_tubes), rest_a
  (n, 3, ns), grad (n, 2, ns)), the self-contact guard (half (rows,), exclusion) and
  ``ok`` (n,) bool: copy k has a state on this grid (:func:`solver.kernels.planar.warm_step`).
* ``contact``: the contact layout tuple (``G_*``, flattened), path parameters, the norms'
  weights (N,); the copies' nodes (n, N), level pressures (n, nc), the level's loads (q,
  plate, target), discs (n, k, 4), rest strains (n, 3, ns), factors
  (:func:`solver.kernels.contact.new_factors`, one row per copy), records and scratch
  (n, rows_c, C_COLUMNS), the grid check's (q (ns,), ends (ns,)), ``ok`` (n,) bool: copy k
  has a state on this layout, ``touching`` (n,) bool: it presses on a disc or on itself, and
  the copies' friction: μ per disc (n, k) and friction samples (n, rows_c, nodes, k, N_FS;
  no rows without friction), and the self-contact friction samples (n, M, c + 1, SUBPOINTS,
  N_FS; ``layout.L_SELF_FRICTION``; no rows without), the tangential state their steps carry.
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.contact import factor_state, lean_step, newton
from solver.kernels.obstacles import accept_friction
from solver.kernels.planar import warm_step
from solver.layout import (
    C_FX,
    C_FY,
    C_PEN,
    D_THETA,
    FS_A,
    MAX_ITER,
    MAX_STEP,
    NX,
    NY,
    SEG_FIRST,
    SEG_ROW0,
    THETA,
    TOL,
    M,
    S,
    U,
    X,
    Y,
)
from solver.rod import integrate_planar, planar_rest_gradient, rest_strains_into

(FR_THETA0, FR_SECF, FR_STEPS, FR_TUBES_I, FR_TUBES_F, FR_LOADS, FR_M_TIP, FR_PARAMS, FR_STATES,
 FR_RECORDS, FR_SCRATCH, FR_REST, FR_P_NOW, FR_LOADS_NOW, FR_P_SEEN, FR_STRETCH, FR_REST_A,
 FR_GRAD, FR_HALF, FR_EXCLUSION, FR_OK) = range(21)
N_FREE = 21

(CT_THETA0, CT_SEGS, CT_SECF, CT_STEPS, CT_START, CT_SELF, CT_PARAMS, CT_WEIGHTS,
 CT_RES_WEIGHTS, CT_NODES, CT_P, CT_Q, CT_PLATE, CT_TARGET, CT_DISCS, CT_REST, CT_LU, CT_PIV,
 CT_DENSE, CT_DENSE_PIV, CT_FLAGS, CT_RECORDS, CT_SCRATCH, CT_CHECK_Q, CT_CHECK_ENDS, CT_OK,
 CT_TOUCHING, CT_MU, CT_FRICTION, CT_SELF_FRICTION) = range(30)
N_CONTACT = 30

# Path codes of the report's last column.
PATH_LEAN, PATH_CONTACT = 1.0, 2.0

# What :func:`contact_rows` does with each active copy (its ``kind``): the whole warm step
# (:func:`contact_row`); the rest of it where :func:`free_row` did not step (the state put on
# the contact layout unless it is there, and the lean contact step); the lean contact step of
# a copy on the contact layout with its discs moved (an object the arm holds, moved
# quasi-statically: :mod:`solver.grasp`).
ROW_STEP, ROW_ENTER, ROW_MOVED = 0, 1, 2


@njit
def touches(record) -> bool:
    """Whether a contact record (rows, C_COLUMNS) presses anywhere (penetration > 0)."""
    for r in range(record.shape[0]):
        if record[r, C_PEN] > 0.0:
            return True
    return False


@njit
def measure_contact(records, on, out):
    """Per copy, the deepest penetration (m) and the total contact force ∫|f| ds (N, the
    trapezoidal rule on the samples) of its contact record; zeros where ``on`` (n,) is False
    (a state on the settings' grid touches nothing).

    Args:
        records: (n, rows, C_COLUMNS) contact records. on: (n,) bool. out: (n, 2) written.
    """
    for k in range(records.shape[0]):
        deepest = 0.0
        force = 0.0
        if on[k]:
            rec = records[k]
            previous = math.hypot(rec[0, C_FX], rec[0, C_FY])
            deepest = rec[0, C_PEN]
            for r in range(1, rec.shape[0]):
                f = math.hypot(rec[r, C_FX], rec[r, C_FY])
                force += 0.5 * (f + previous) * (rec[r, S] - rec[r - 1, S])
                previous = f
                deepest = max(deepest, rec[r, C_PEN])
        out[k, 0] = deepest
        out[k, 1] = force


@njit
def free_record_of(crec, m0, p_channel, free, k):
    """Write copy k's record on the settings' grid (``free``) for the contact-layout state
    whose record is ``crec`` (rows_c, C_COLUMNS) and base moment ``m0``: its columns S … U
    where the grids agree, else the backbone of ``m0`` integrated on the settings' grid
    (where the general path's contact-free step starts it); with its rest strains and the
    predictor's gradient, the first variations NaN."""
    secf, steps = free[FR_SECF], free[FR_STEPS]
    rest_a, grad = free[FR_REST_A][k], free[FR_GRAD][k]
    rec = free[FR_RECORDS][k]
    rest_strains_into(p_channel, free[FR_TUBES_I], free[FR_TUBES_F], secf, rest_a)
    if crec.shape[0] == rec.shape[0]:
        for r in range(rec.shape[0]):
            for c in range(S, U + 1):
                rec[r, c] = crec[r, c]
    else:
        integrate_planar(m0, free[FR_THETA0], secf, steps, rest_a, free[FR_LOADS], True, rec, False)
    rec[:, D_THETA:] = math.nan
    planar_rest_gradient(rec, secf, steps, rest_a, grad)
    free[FR_STATES][k, 0] = m0


@njit(inline="always")
def contact_row(k, free, contact, p_from, p_to, report, kind, discs_to):
    """One warm step of copy k from ``p_from[k]`` to ``p_to[k]`` (channel pressures, Pa),
    by the lean path its state allows (module docstring), or the part of it ``kind`` names
    (``ROW_*``; with ``ROW_MOVED`` its discs move to ``discs_to`` (k, 4), else they stand
    still and ``discs_to`` is unused). ``report[k]``: (converged, stable, snapped,
    iterations, residual, path, refused): path ``PATH_LEAN`` the lean planar kernel,
    ``PATH_CONTACT`` the lean contact one; unconverged: the state is as it was; refused: the
    lean contact step's ``REFUSED_*`` bits (:func:`solver.kernels.contact.lean_step`). Each
    step kernel has one call site here: an inlined one is compiled once per site."""
    if kind != ROW_ENTER:  # (after free_row, whose iterations the report keeps)
        clear_report(report, k)
    if kind == ROW_MOVED or (kind == ROW_STEP and contact[CT_OK][k] and contact[CT_TOUCHING][k]):
        if contact[CT_OK][k]:
            discs = discs_to if kind == ROW_MOVED else contact[CT_DISCS][k]
            _contact_step(k, free, contact, p_to, discs, report)
        return
    if kind == ROW_STEP and (not free[FR_OK][k] or _free_step(k, free, contact[CT_DISCS],
                                                              contact[CT_OK], p_from, p_to, report)):
        return
    _enter_and_step(k, free, contact, p_from, p_to, report)


@njit(inline="always")
def _enter_and_step(k, free, contact, p_from, p_to, report):
    """:func:`contact_row` of copy k after its guarded contact-free step would touch: the
    state put on the contact layout (unless it is there) and the lean contact step."""
    entered = False
    if not contact[CT_OK][k] and free[FR_RECORDS].shape[1] == contact[CT_RECORDS].shape[1]:
        entered = _enter_contact(k, free, contact, p_from[k])
    if contact[CT_OK][k]:
        _contact_step(k, free, contact, p_to, contact[CT_DISCS][k], report)
        if not report[k, 0] and entered:
            contact[CT_OK][k] = False  # the copy's state stays the contact-free one


@njit(inline="always")
def _free_step(k, free, discs, contact_ok, p_from, p_to, report) -> bool:
    """The guarded lean planar step of copy k (a state on the settings' grid;
    :func:`solver.kernels.planar.warm_step` with ``discs`` (n, k, 4) and the self-contact
    guard); on success its state and report (``contact_ok[k]`` cleared: its contact state is
    the one before this step). Returns whether it stepped; where not, the state is as it
    was."""
    states, records, scratch = free[FR_STATES], free[FR_RECORDS], free[FR_SCRATCH]
    loads, m_tip = free[FR_LOADS], free[FR_M_TIP]
    m_start = states[k, 0]
    ok, stable, snapped, its, res, _, _ = warm_step(
        states[k], (free[FR_THETA0], free[FR_SECF], free[FR_STEPS]),
        (free[FR_TUBES_I], free[FR_TUBES_F]), (p_from[k], loads, m_tip), (p_to[k], loads, m_tip),
        free[FR_PARAMS],
        (free[FR_REST][k], free[FR_P_NOW][k], free[FR_LOADS_NOW][k], scratch[k], True),
        (free[FR_P_SEEN][k], free[FR_STRETCH][k], free[FR_REST_A][k], free[FR_GRAD][k]),
        (discs[k], records[k], free[FR_HALF], free[FR_EXCLUSION]))
    report[k, 3] = its
    if not ok:
        states[k, 0] = m_start
        return False
    records[k, :, :] = scratch[k]
    contact_ok[k] = False
    report_lean(report, k, stable, snapped, res)
    return True


@njit(inline="always")
def clear_report(report, k):
    """``report[k]`` before a step of copy k: not converged, no iterations, no refusals (the
    other columns are written only where it converges)."""
    report[k, 0] = 0.0
    report[k, 3] = 0.0
    report[k, 6] = 0.0


@njit(inline="always")
def report_lean(report, k, stable, snapped, res):
    """``report[k]`` of a converged contact-free step (path ``PATH_LEAN``), planar or 3D; its
    iterations are the caller's."""
    report[k, 0] = 1.0
    report[k, 1] = stable
    report[k, 2] = snapped
    report[k, 4] = res
    report[k, 5] = PATH_LEAN


@njit
def free_row(free, discs, contact_ok, p_from, p_to, report) -> bool:
    """:func:`contact_row` of copy 0, a state on the settings' grid that touches nothing, as
    far as its guarded contact-free step: the single :class:`solver.stepper.Stepper`'s common
    step, with a third of the arrays to unbox. Returns whether it stepped; where not (a step
    that would touch), :func:`contact_rows` with ``ROW_ENTER`` goes on from there."""
    clear_report(report, 0)
    return _free_step(0, free, discs, contact_ok, p_from, p_to, report)


@njit(inline="always")
def _contact_step(k, free, contact, p_to, discs_to, report):
    """:func:`solver.kernels.contact.lean_step` of copy k to ``p_to[k]`` and the discs
    ``discs_to`` (k, 4) (its own where they stand still); on success its state, and if it
    touches nothing any more, its record on the settings' grid too."""
    grid = (contact[CT_THETA0], contact[CT_SEGS], contact[CT_SECF], contact[CT_STEPS],
            contact[CT_START], contact[CT_SELF])
    nodes, p_level, records = contact[CT_NODES], contact[CT_P], contact[CT_RECORDS]
    level = (p_level[k], contact[CT_Q], contact[CT_PLATE], contact[CT_TARGET], contact[CT_DISCS][k],
             contact[CT_MU][k], contact[CT_FRICTION][k], contact[CT_SELF_FRICTION][k])
    ok, stable, its, res, refused = lean_step(
        nodes[k], grid, (free[FR_TUBES_I], free[FR_TUBES_F]), level, p_to[k], discs_to,
        contact[CT_PARAMS],
        (contact[CT_REST][k], contact[CT_WEIGHTS], contact[CT_RES_WEIGHTS]),
        (contact[CT_LU][k], contact[CT_PIV][k], contact[CT_DENSE][k], contact[CT_DENSE_PIV][k],
         contact[CT_FLAGS][k]),
        (records[k], contact[CT_SCRATCH][k]), (contact[CT_CHECK_Q], contact[CT_CHECK_ENDS]))
    report[k, 3] += its
    report[k, 6] = refused
    if not ok:
        return
    records[k, :, :] = contact[CT_SCRATCH][k]
    report[k, 0] = 1.0
    report[k, 1] = stable
    report[k, 2] = 0.0
    report[k, 4] = res
    report[k, 5] = PATH_CONTACT
    touching = touches(records[k])
    contact[CT_TOUCHING][k] = touching
    free[FR_OK][k] = not touching
    if not touching:
        free_record_of(records[k], nodes[k][2], p_level[k], free, k)


@njit
def nodes_of_record(rec, segs, Z):
    """Multiple-shooting nodes ``Z`` (N,) of a record on the contact layout's rows (its
    columns S … U): (n0, m0), then the 6-state at every segment start — as
    :func:`solver.paths.shooting.nodes_from_states` takes them from an equilibrium."""
    row = segs[0, SEG_ROW0] + segs[0, SEG_FIRST]
    Z[0] = rec[row, NX]
    Z[1] = rec[row, NY]
    Z[2] = rec[row, M]
    for seg in range(1, segs.shape[0]):
        row = segs[seg, SEG_ROW0] + segs[seg, SEG_FIRST]
        base = 3 + 6 * (seg - 1)
        Z[base] = rec[row, X]
        Z[base + 1] = rec[row, Y]
        Z[base + 2] = rec[row, THETA]
        Z[base + 3] = rec[row, NX]
        Z[base + 4] = rec[row, NY]
        Z[base + 5] = rec[row, M]


@njit(inline="always")
def _enter_contact(k, free, contact, p_start):
    """Put copy k's contact-free state (its record on the settings' grid, which has the
    contact layout's rows) on the contact layout, at the pressures ``p_start`` it stands at:
    its nodes, corrected by Newton there (refinement near the discs moves them a little, as
    the general path corrects a warm start at the ramp's start), their factored Jacobian
    and record. Returns whether that succeeded (``contact[CT_OK][k]``)."""
    nodes, p_level, rest = contact[CT_NODES][k], contact[CT_P][k], contact[CT_REST][k]
    grid = (contact[CT_THETA0], contact[CT_SEGS], contact[CT_SECF], contact[CT_STEPS],
            contact[CT_START], contact[CT_SELF])
    nodes_of_record(free[FR_RECORDS][k], contact[CT_SEGS], nodes)
    for c in range(p_start.shape[0]):
        p_level[c] = p_start[c]
    rest_strains_into(p_level, free[FR_TUBES_I], free[FR_TUBES_F], contact[CT_SECF], rest)
    fs = contact[CT_FRICTION][k]
    sfs = contact[CT_SELF_FRICTION][k]
    level = (p_level, contact[CT_Q], contact[CT_PLATE], contact[CT_TARGET], contact[CT_DISCS][k],
             contact[CT_MU][k], fs, sfs)
    fs[:, :, :, FS_A:FS_A + 3] = math.nan  # from a state that touched nothing: no anchors
    sfs[:, :, :, FS_A:FS_A + 3] = math.nan
    params = contact[CT_PARAMS]
    weights = contact[CT_WEIGHTS]
    ok, _, _, stable = newton(nodes, grid, rest, level, weights, contact[CT_RES_WEIGHTS],
                              params[TOL], int(params[MAX_ITER]), params[MAX_STEP])
    if not (ok and stable):
        return False
    factors = (contact[CT_LU][k], contact[CT_PIV][k], contact[CT_DENSE][k],
               contact[CT_DENSE_PIV][k], contact[CT_FLAGS][k])
    blocks = np.empty((contact[CT_SEGS].shape[0], 6, 6))
    if not factor_state(nodes, grid, rest, level, weights, np.empty(nodes.shape[0]), blocks,
                        contact[CT_RECORDS][k], factors):
        return False
    accept_friction(fs)
    accept_friction(sfs)
    contact[CT_OK][k] = True
    contact[CT_TOUCHING][k] = touches(contact[CT_RECORDS][k])
    return True


@njit
def contact_rows(free, contact, p_from, p_to, active, report, kind, discs_to):
    """:func:`contact_row` (``kind``, ``discs_to``) of every copy where ``active`` (n,), in
    order: batches, and the single stepper's steps that :func:`free_row` does not take or that
    move its discs, in one compiled kernel (each caller compiled apart would link and optimise
    the whole lean contact step again: :mod:`solver.jit`). Batches run it on Python threads,
    each over its own copies (:class:`solver.threads.CopyPool`)."""
    for k in range(p_to.shape[0]):
        if active[k]:
            contact_row(k, free, contact, p_from, p_to, report, kind, discs_to)
