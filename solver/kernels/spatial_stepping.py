"""The 3D steppers' row kernels in scenes with obstacles (cylinders, spheres): one warm step
of one copy by the lean path its state allows, and the same over many copies.

The spatial counterpart of :mod:`solver.kernels.stepping`. A copy's state lives on the
settings' grid (a contact-free equilibrium of the spatial single-shooting kernel
:func:`solver.kernels.spatial.follow`) or on the contact layout (an equilibrium of the
spatial contact kernels: its nodes, level, factored Jacobian and backbone).
:func:`spatial_contact_row` takes a step in the order of the general path
(:func:`solver.paths.spatial_contact.solve_contact_spatial`):

* from a state in contact, the lean contact step (:func:`solver.kernels.spatial_contact.lean_step`);
* from one that touches nothing, the contact-free step first, kept where its backbone
  clears every obstacle between every two samples and no sample came near one on the way
  (:func:`solver.kernels.obstacles.free_step_gap`); where the samples clear them but not
  so, that state corrected on the contact layout (:func:`_near_step`; not with friction,
  as the general path);
  where they do not clear them, the lean contact step from the start (put on the contact
  layout first, :func:`_enter_contact`, if it is not there).

A row it cannot step is reported unconverged with its state untouched: the caller's general
path takes it (:mod:`solver.paths.lean_spatial_contact`).

The argument tuples are flat (numba's parallel loops do not take nested tuples), their items
named by the ``F3_*`` and ``C3_*`` constants below; arrays with a first axis of n hold one
row per copy, and records a second axis of two slots: the current state's (0) and scratch
for the step's (1).

* ``free``: the settings' grid (base quaternion, secf, steps, 1/GJ), the tubes, dead loads
  (ns, 6), tip moment and path parameters; the samples' sections (N,), arc lengths (N,) and
  internal forces (N, 3), which depend on the scene alone; the grid check's |q| (ns,) and
  section-end rows (ns,); the copies' base moments (n, 3), backbones (positions
  (n, 2, N, 3), frames (n, 2, N, 3, 3), moments (n, 2, N, 3)), the rest strains of a
  contact-free state (n, 3, ns) and ``ok`` (n,) bool: copy k touches nothing, and the
  contact-free step may start from its base moment and positions.
* ``contact``: the contact layout tuple (``GS_*``, flattened), path parameters, the norms'
  weights and the tangent coordinates' scales; the level's loads (q, plate, target); the
  nodes' arc lengths and sections (K,); the grid check's (q (ns,), ends (ns,)); the copies'
  nodes (n, K, N_CSTATE), level pressures (n, nc), obstacles (n, k, N_OBSTACLE), rest
  strains (n, 3, ns), band factors (n, BAND_ROWS, N) and pivots (n, N), records
  (:func:`solver.kernels.spatial_contact.new_record`'s nine arrays, each (n, 2, ...)), ``ok``
  (n,) bool: copy k has a state on this layout, ``touching`` (n,) bool: it presses on an
  obstacle, and the copies' friction: μ per obstacle (n, k) and friction samples (n, rows,
  nodes, k, N_FS; no rows without friction), the tangential state their steps carry (as
  :mod:`solver.kernels.stepping`'s: anchors where the state lies on the contact layout, none
  where it is the contact-free kernel's).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit
from solver.kernels.contact import weighted_norm
from solver.kernels.grid import section_needs
from solver.kernels.obstacles import accept_friction, free_step_gap
from solver.kernels.spatial import follow as free_follow
from solver.kernels.spatial_contact import (
    JAC_VARIATIONAL,
    NO_TETHER,
    broyden,
    factor_state,
    lean_step,
    new_factors,
    newton_into,
    newton_system,
    nodes_from_record,
)
from solver.kernels.stepping import PATH_CONTACT, report_lean
from solver.layout import CA, CG, CI, CS_M, FS_A, L_FRICTION, MAX_ITER, MAX_STEP, N_CTANGENT, TOL
from solver.rod import rest_strains_into, spatial_strains_into

(F3_QUAT0, F3_SECF, F3_STEPS, F3_CJ, F3_TUBES_I, F3_TUBES_F, F3_LOADS, F3_M_TIP, F3_PARAMS,
 F3_SEG, F3_S, F3_FORCE, F3_CHECK_Q, F3_ENDS, F3_M0, F3_POS, F3_ROT, F3_MOM, F3_REST,
 F3_OK) = range(20)
N_FREE3 = 20

(C3_QUAT0, C3_SEGS, C3_SECF, C3_STEPS, C3_CJ, C3_START, C3_PARAMS, C3_WEIGHTS, C3_RES_WEIGHTS,
 C3_SCALES, C3_Q, C3_PLATE, C3_TARGET, C3_ARCS, C3_SECTIONS, C3_CHECK_Q, C3_CHECK_ENDS,
 C3_NODES, C3_P, C3_OBSTACLES, C3_REST, C3_LU, C3_PIV, C3_S, C3_POS, C3_ROT, C3_FORCE, C3_MOM,
 C3_CONTACT, C3_PEN, C3_V, C3_U, C3_OK, C3_TOUCHING, C3_MU, C3_FRICTION) = range(36)
N_CONTACT3 = 36


@njit(inline="always")
def _grid(contact):
    return (contact[C3_QUAT0], contact[C3_SEGS], contact[C3_SECF], contact[C3_STEPS],
            contact[C3_CJ], contact[C3_START])


@njit(inline="always")
def _record(contact, k, slot):
    """Copy k's contact record in ``slot`` (the tuple of
    :func:`solver.kernels.spatial_contact.new_record`)."""
    return (contact[C3_S][k, slot], contact[C3_POS][k, slot], contact[C3_ROT][k, slot],
            contact[C3_FORCE][k, slot], contact[C3_MOM][k, slot], contact[C3_CONTACT][k, slot],
            contact[C3_PEN][k, slot], contact[C3_V][k, slot], contact[C3_U][k, slot])


@njit(inline="always")
def _level(contact, k):
    return _level_at(contact[C3_P][k], contact, k)


@njit(inline="always")
def _level_at(p, contact, k):
    """Copy k's level tuple (``L_*``) at the pressures ``p``, with its friction: μ and its
    friction samples (no rows without friction)."""
    return (p, contact[C3_Q], contact[C3_PLATE], contact[C3_TARGET], contact[C3_OBSTACLES][k],
            contact[C3_MU][k], contact[C3_FRICTION][k])


@njit(inline="always")  # inlined: solver.jit says what a separate compile costs
def spatial_contact_row(k, free, contact, p_from, p_to, report):
    """One warm step of copy k from ``p_from[k]`` to ``p_to[k]`` (channel pressures, Pa),
    by the lean path its state allows (module docstring). ``report[k]``: (converged, stable,
    snapped, iterations, residual, path): path ``PATH_LEAN`` the contact-free kernel,
    ``PATH_CONTACT`` the contact layout's; unconverged: the state is as it was."""
    report[k, 0] = 0.0
    report[k, 3] = 0.0
    if contact[C3_OK][k] and contact[C3_TOUCHING][k]:
        _contact_step(k, free, contact, p_to, report)
        return
    if not free[F3_OK][k]:
        return
    gap = _free_step(k, free, contact, p_from, p_to, report)
    if report[k, 0] or math.isnan(gap):
        return
    if gap > 0.0 and contact[C3_FRICTION].shape[1] == 0:
        # (With friction the landing is the ramp's from the start, whose anchors form
        # there: Newton at the end would land without any, as if frictionless.)
        _near_step(k, free, contact, p_to, report)
        return
    entered = False
    if not contact[C3_OK][k]:
        entered = _enter_contact(k, free, contact, p_from[k])
    if contact[C3_OK][k]:
        _contact_step(k, free, contact, p_to, report)
        if not report[k, 0] and entered:
            contact[C3_OK][k] = False  # the copy's state stays the contact-free one


@njit
def spatial_contact_rows(free, contact, p_from, p_to, active, report):
    """:func:`spatial_contact_row` of every copy where ``active`` (n,)."""
    for k in range(p_to.shape[0]):
        if active[k]:
            spatial_contact_row(k, free, contact, p_from, p_to, report)


@njit(inline="always")
def _free_step(k, free, contact, p_from, p_to, report):
    """The contact-free step of copy k (the single-shooting kernel from its base moment, as
    the general path's contact-free solve takes it) into its scratch slot, and the smallest
    gap (m) of its start and end samples to an obstacle (−inf where a sample moving
    straight between them passes through one). Where the end state clears every obstacle
    chord by chord (:func:`solver.kernels.obstacles.chords_clear_3d`), no sample came within
    that state's chord allowance of one on the way and the grid resolves the state, it is
    copy k's new state (reported converged). NaN: it failed or snapped, or cleared the
    obstacles on a grid that does not resolve it (the general path's turn)."""
    m0 = free[F3_M0][k]
    m_start = m0.copy()
    ns = free[F3_SECF].shape[1]
    rest = np.empty((3, ns))
    pos, rot, mom = free[F3_POS][k], free[F3_ROT][k], free[F3_MOM][k]
    loads, m_tip, params = free[F3_LOADS], free[F3_M_TIP], free[F3_PARAMS]
    ok, stable, snapped, its, res, _, _ = free_follow(
        m0, (free[F3_QUAT0], free[F3_SECF], free[F3_STEPS], free[F3_CJ]),
        (free[F3_TUBES_I], free[F3_TUBES_F]), (p_from[k], loads, m_tip), (p_to[k], loads, m_tip),
        params, (rest, np.empty(p_to.shape[1]), np.empty(loads.shape), np.empty(3),
                 (pos[1], rot[1], mom[1]), True),
        (np.empty(0), np.empty((0, 4))))
    report[k, 3] += its
    gap = math.nan
    # A snap's way between the two states is not known: the contact path follows the
    # step with the obstacles present and lands it by its own branch switch.
    if ok and res <= 10.0 * params[TOL] and stable and not snapped:
        obstacles = contact[C3_OBSTACLES][k]
        gap, clear = free_step_gap(pos[0], pos[1], rot[1][:, :, 2], obstacles)
        if clear:
            if not _resolved(free, rest, pos[1], rot[1], mom[1]):
                gap = math.nan
            else:
                pos[0] = pos[1]
                rot[0] = rot[1]
                mom[0] = mom[1]
                free[F3_REST][k] = rest
                contact[C3_OK][k] = False  # its contact state is the one before this step
                # A contact-free state carries no anchors (the general path's shortcut either).
                contact[C3_FRICTION][k][:, :, :, FS_A:FS_A + 3] = math.nan
                report_lean(report, k, stable, snapped, res)
                return gap
    for d in range(3):
        m0[d] = m_start[d]
    return gap


@njit(inline="always")
def _resolved(free, rest, pos, rot, mom):
    """Whether the settings' grid resolves the contact-free backbone (positions, frames,
    moments) at the rest strains ``rest`` (the general path's grid check)."""
    n = pos.shape[0]
    secf = free[F3_SECF]
    strain_v = np.empty((n, 3))
    strain_u = np.empty((n, 3))
    spatial_strains_into(rot, free[F3_FORCE], mom, rest, free[F3_SEG], secf[CA], secf[CG],
                         secf[CI], free[F3_CJ], strain_v, strain_u)
    need = np.empty(secf.shape[1])
    return section_needs(strain_u, free[F3_FORCE], strain_v, free[F3_CHECK_Q], secf,
                         free[F3_ENDS], need) <= 1.0


@njit(inline="always")
def _contact_step(k, free, contact, p_to, report):
    """:func:`solver.kernels.spatial_contact.lean_step` of copy k from its state on the
    contact layout; on success that state (:func:`_took_contact`)."""
    level = _level(contact, k)
    ok, stable, its, res = lean_step(
        contact[C3_NODES][k], _grid(contact), (free[F3_TUBES_I], free[F3_TUBES_F]), level,
        p_to[k], contact[C3_PARAMS],
        (contact[C3_REST][k], contact[C3_WEIGHTS], contact[C3_RES_WEIGHTS], contact[C3_SCALES]),
        (contact[C3_LU][k], contact[C3_PIV][k]), (_record(contact, k, 0), _record(contact, k, 1)),
        (contact[C3_CHECK_Q], contact[C3_CHECK_ENDS]))
    report[k, 3] += its
    if ok:
        _took_contact(k, free, contact, stable, res, report)


@njit(inline="always")
def _took_contact(k, free, contact, stable, res, report):
    """Copy k's new state on the contact layout has its record in the scratch slot (its
    nodes, level and factors already in place): make it current (:func:`_on_layout`) and
    report the step."""
    _on_layout(k, free, contact)
    report[k, 0] = 1.0
    report[k, 1] = stable
    report[k, 2] = 0.0
    report[k, 4] = res
    report[k, 5] = PATH_CONTACT


@njit(inline="always")
def _on_layout(k, free, contact):
    """Copy k's state is the one on the contact layout, its record in the scratch slot
    (:func:`_current`); if it touches nothing, the next step starts with the contact-free
    one from it (:func:`free_start_of`)."""
    _current(k, contact)
    touching = contact[C3_TOUCHING][k]
    free[F3_OK][k] = not touching
    if not touching:
        free_start_of(k, free, contact)


@njit(inline="always")
def _current(k, contact):
    """Make copy k's scratch contact record current: its state lies on the contact layout,
    touching where it presses on an obstacle."""
    for array in (contact[C3_S], contact[C3_PEN]):
        array[k, 0] = array[k, 1]
    for array in (contact[C3_POS], contact[C3_FORCE], contact[C3_MOM], contact[C3_CONTACT],
                  contact[C3_V], contact[C3_U]):
        array[k, 0] = array[k, 1]
    contact[C3_ROT][k, 0] = contact[C3_ROT][k, 1]
    contact[C3_OK][k] = True
    contact[C3_TOUCHING][k] = contact[C3_PEN][k, 0].max() > 0.0


@njit
def free_start_of(k, free, contact):
    """Where copy k's state on the contact layout touches nothing, the contact-free step
    starts from it: its base moment, and its positions (at the settings' grid's arc lengths
    if the grids differ) as the start of the gap and tunnel checks."""
    nodes = contact[C3_NODES][k]
    for d in range(3):
        free[F3_M0][k, d] = nodes[0, CS_M + d]
    s, pos = contact[C3_S][k, 0], contact[C3_POS][k, 0]
    out = free[F3_POS][k, 0]
    if pos.shape[0] == out.shape[0]:
        out[:, :] = pos
    else:
        for d in range(3):
            out[:, d] = np.interp(free[F3_S], s, pos[:, d])


@njit(inline="always")
def _solve_from(k, contact, Z, level, rest, quasi):
    """Newton on the contact layout at ``level`` (``rest`` its rest strains) from the nodes
    ``Z``, in place: with ``quasi``, Broyden's corrections on copy k's factored Jacobian (of
    a nearby state) first. Returns (ok, passes): converged on a stable state."""
    params = contact[C3_PARAMS]
    weights, res_weights, scales = contact[C3_WEIGHTS], contact[C3_RES_WEIGHTS], contact[C3_SCALES]
    passes = 0
    if quasi:
        n = weights.shape[0]
        F = np.empty(n)
        start = Z.copy()
        finite = newton_system(Z, _grid(contact), rest, level, F, np.empty((0, 0)), False,
                               np.empty((0, N_CTANGENT, N_CTANGENT)), scales, NO_TETHER)
        passes += 1
        res = weighted_norm(F, res_weights) if finite else math.inf
        if res <= params[TOL]:
            return True, passes
        if math.isfinite(res):
            done, res, its, _ = broyden(Z, _grid(contact), rest, level, F, scales, res_weights,
                                        params[TOL], (contact[C3_LU][k], contact[C3_PIV][k]), res)
            passes += its
            if done:
                return True, passes
        Z[:, :] = start
    n = weights.shape[0]
    ok, its, _, stable = newton_into(Z, _grid(contact), rest, level, weights, res_weights, scales,
                                     params[TOL], int(params[MAX_ITER]), params[MAX_STEP], NO_TETHER,
                                     np.empty(n), np.empty((n, n)),
                                     np.empty((Z.shape[0], N_CTANGENT, N_CTANGENT)), JAC_VARIATIONAL,
                                     True, Z, math.inf, math.inf)
    return ok and stable, passes + its + 1


@njit(inline="always")
def _factored(k, contact, Z, level, rest, resolved):
    """Make the state ``Z`` at ``level`` (``rest`` its rest strains) copy k's on the contact
    layout if its Jacobian pass (:func:`solver.kernels.spatial_contact.factor_state`, which
    records it into the scratch slot) finds it converged, stable and regular — and, with
    ``resolved``, the grid resolves it: its nodes, pressures, rest strains and factors (the
    record is made current by the caller). Otherwise copy k's state is untouched. Returns
    (ok, stable, residual)."""
    params = contact[C3_PARAMS]
    n = contact[C3_WEIGHTS].shape[0]
    fresh = new_factors(n)
    F = np.empty(n)
    new = _record(contact, k, 1)
    regular, stable = factor_state(Z, _grid(contact), rest, level, F, np.empty((n, n)),
                                   np.empty((Z.shape[0], N_CTANGENT, N_CTANGENT)), new, fresh)
    res = weighted_norm(F, contact[C3_RES_WEIGHTS])
    ok = regular and stable and res <= params[TOL]
    if ok and resolved:
        need = np.empty(rest.shape[1])
        ok = section_needs(new[8], new[3], new[7], contact[C3_CHECK_Q], contact[C3_SECF],
                           contact[C3_CHECK_ENDS], need) <= 1.0
    if ok:
        contact[C3_NODES][k] = Z
        contact[C3_P][k] = level[0]
        contact[C3_REST][k] = rest
        contact[C3_LU][k] = fresh[0]
        contact[C3_PIV][k] = fresh[1]
    return ok, stable, res


@njit(inline="always")
def _near_step(k, free, contact, p_to, report):
    """The contact-free step of copy k (in its scratch slot) ends with its samples clear of
    the obstacles but not its chords by their allowance, and got there without passing
    through one: as the general path
    does, that state is corrected by Newton on the contact layout (where a stage point may
    graze the obstacle) — from Broyden's corrections on the factors of copy k's state there
    if it has one — and is the step's answer if converged, stable and resolved."""
    nodes = np.empty_like(contact[C3_NODES][k])
    nodes_from_record(free[F3_S], free[F3_POS][k, 1], free[F3_ROT][k, 1], free[F3_FORCE],
                      free[F3_MOM][k, 1], free[F3_ENDS], contact[C3_ARCS], contact[C3_SECTIONS],
                      contact[C3_QUAT0], nodes)
    p = p_to[k].copy()
    level = _level_at(p, contact, k)
    rest = np.empty_like(contact[C3_REST][k])
    rest_strains_into(p, free[F3_TUBES_I], free[F3_TUBES_F], contact[C3_SECF], rest)
    ok, passes = _solve_from(k, contact, nodes, level, rest, contact[C3_OK][k])
    report[k, 3] += passes
    if not ok:
        return
    ok, stable, res = _factored(k, contact, nodes, level, rest, True)
    report[k, 3] += 1
    if ok:
        accept_friction(level[L_FRICTION])  # the state is accepted: its samples take their anchors
        _took_contact(k, free, contact, stable, res, report)


@njit(inline="always")
def _enter_contact(k, free, contact, p_start):
    """Put copy k's contact-free state (its backbone on the settings' grid) on the contact
    layout at the pressures ``p_start`` it stands at, as the general path starts its ramp
    from it: nodes interpolated from its samples and corrected by Newton there, their
    factored Jacobian and record, and the anchors of its friction samples (none before: a
    state entering contact from one that touches nothing). Its contact-free state is kept.
    Returns whether that succeeded (``contact[C3_OK][k]``)."""
    nodes = np.empty_like(contact[C3_NODES][k])
    nodes_from_record(free[F3_S], free[F3_POS][k, 0], free[F3_ROT][k, 0], free[F3_FORCE],
                      free[F3_MOM][k, 0], free[F3_ENDS], contact[C3_ARCS], contact[C3_SECTIONS],
                      contact[C3_QUAT0], nodes)
    p = p_start.copy()
    level = _level_at(p, contact, k)
    rest = np.empty_like(contact[C3_REST][k])
    rest_strains_into(p, free[F3_TUBES_I], free[F3_TUBES_F], contact[C3_SECF], rest)
    fs = level[L_FRICTION]
    fs[:, :, :, FS_A:FS_A + 3] = math.nan
    ok, _ = _solve_from(k, contact, nodes, level, rest, False)
    if not (ok and _factored(k, contact, nodes, level, rest, False)[0]):
        return False
    accept_friction(fs)
    _current(k, contact)
    return True


@njit
def adopt_nodes(k, free, contact, Z, level, rest):
    """Make the equilibrium ``Z`` (K, N_CSTATE) on the contact layout at ``level`` (``rest``
    its rest strains), from the general path, copy k's state: its factored Jacobian and
    record from one Jacobian pass, and where it touches nothing the start of the
    contact-free step. Returns whether that pass found it converged, stable and regular
    (else copy k is left as it was)."""
    if not _factored(k, contact, Z, level, rest, False)[0]:
        return False
    _on_layout(k, free, contact)
    return True
