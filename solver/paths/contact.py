"""Solves with obstacles: the contact-free shortcuts, penalty contact by multiple shooting,
and rigid obstacles by penalty continuation (docs/design.md §9–10)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from solver import layout as L
from solver.kernels.self_contact import far_parts_clear
from solver.paths.planar import solve_planar, solve_single
from solver.paths.shooting import solve_shooting
from solver.problem import Problem, contact_layout, reach
from solver.results import Equilibrium, peak_penetration
from solver.scene import self_contact_exclusion

# Penalty continuation for rigid obstacles (Disc(stiffness=math.inf)): the first penalty
# makes the decay length (EI/k)^¼ a twentieth of the arm; each stage stiffens it tenfold, up
# to RIGID_MAX_STIFFNESS (OctArm V pressed into a disc: 1e-5 m of penetration at 1.2e8 N/m²,
# 2e-7 m at 1.2e10).
RIGID_GROWTH = 10.0
RIGID_MAX_STIFFNESS = 1e11


def solve_rigid(problem: Problem, contact=None) -> Equilibrium:
    """A solve with rigid obstacles or rigid self-contact (hard contact) by penalty
    continuation, each stage solved by ``contact`` (a penalty-contact path:
    :func:`solve_contact`, the default, or the spatial
    :func:`solver.paths.spatial_contact.solve_contact_spatial`).

    The rigid discs (and the self-contact, if rigid) get a finite penalty k: from a warm
    start its final one, else the k at which the decay length (EI_min/k)^¼ is L/20. After
    each solve, while the deepest penetration into a rigid obstacle (or, with rigid
    self-contact, into the arm itself) anywhere along the backbone — between the samples
    too (:func:`solver.results.peak_penetration`) — exceeds ``settings.gap_tol``, k is multiplied
    by RIGID_GROWTH and the solve continues from the last state, the penalty ramped up along
    the path (the homotopy of :func:`solver.paths.shooting.solve_shooting`). The
    penetration falls as 1/k and the state converges to the hard-contact limit (tested).
    If the penetration is still above ``gap_tol`` where the next stage would pass
    RIGID_MAX_STIFFNESS, or a stage does not converge (the last converged stage is then
    returned), the result is reported unconverged.
    """
    arm, scene, warm_start, settings = problem.arm, problem.scene, problem.warm_start, problem.settings
    warm_k = warm_start.penalty_stiffness if warm_start is not None else math.nan
    stiffness = warm_k if math.isfinite(warm_k) else min(
        s.EI for s in arm.sections) * (20.0 / arm.length) ** 4
    eq = warm_start
    iterations = 0
    while True:
        stage = replace(scene, obstacles=tuple(
            replace(d, stiffness=stiffness) if d.stiffness == math.inf else d
            for d in scene.obstacles),
            self_contact=stiffness if scene.self_contact == math.inf else scene.self_contact)
        attempt = (contact or solve_contact)(problem.in_scene(stage, eq))
        iterations += attempt.iterations
        if not attempt.converged:
            # Keep the last stage that converged (stiffness one step back), reported as not
            # meeting the tolerance; a first stage that fails is returned as it is.
            if eq is None or eq is warm_start:
                eq, met = attempt, False
            else:
                stiffness /= RIGID_GROWTH
                met = False
            break
        eq = attempt
        # The deepest penetration anywhere, between the samples too (docs/design.md §9).
        met = peak_penetration(eq, rigid_only=True, scene=scene) <= settings.gap_tol
        if met or stiffness * RIGID_GROWTH > RIGID_MAX_STIFFNESS:
            break
        stiffness *= RIGID_GROWTH
    return replace(eq, scene=scene, penalty_stiffness=stiffness, iterations=iterations,
                   converged=bool(eq.converged and met))


def solve_contact(problem: Problem, moving: bool = False) -> Equilibrium:
    """Planar solve with penalty contact against the scene's discs (:mod:`solver.kernels.contact`).

    Multiple shooting at the contact resolution (:func:`solver.problem.contact_layout`),
    obstacles present all along the quasi-static path
    (:func:`solver.paths.shooting.solve_shooting`).

    Shortcuts (``settings.shortcuts``), each exact:

    * no disc within the arm's reach (:func:`solver.problem.reach`): the contact-free solve,
      if no part of its backbone comes near another (:func:`clear_of_itself`; always, without
      self-contact);
    * a cold solve, or a warm step from a state that touched nothing: single shooting
      without contact, guarded — if the backbone stays clear of every disc between every
      two samples (:func:`solver.kernels.obstacles.chords_clear`) at every accepted state
      (loading stage included) and no sample passes through a disc between them
      (:func:`solver.kernels.planar.follow`), the contact-free path *is* the
      path with obstacles (every penalty force is zero along it), obtained in tens of
      microseconds instead of milliseconds. Otherwise the contact kernels follow the path.
      The shortcut solves at the settings' resolution, the contact kernels at the finer
      contact resolution; the two agree to the coarser one's discretisation error.

    ``moving``: the warm start's discs are ramped to the scene's positions
    (:func:`solver.paths.shooting.solve_shooting`); the guarded shortcut, which checks the
    path against the final discs only, is then skipped.
    """
    arm, packed, scene, warm_start = problem.arm, problem.packed, problem.scene, problem.warm_start
    free_scene = scene.without_contact
    if problem.settings.shortcuts:
        discs = scene.discs_array()
        before = warm_start.dissipated if warm_start is not None else 0.0
        # (No disc, only self-contact: nothing to bound, and working out the bound is not free.)
        if discs.shape[0] == 0 or np.all(np.hypot(discs[:, L.CX], discs[:, L.CY]) - discs[:, L.RADIUS]
                                         > reach(arm, packed, scene)):
            free = solve_planar(problem.in_scene(free_scene, warm_start))
            if clear_of_itself(arm, scene, free):
                return free_contact_result(free, scene, before)
        elif not moving and (warm_start is None or not warm_start.in_contact):
            free = solve_single(problem.in_scene(free_scene, warm_start), guard_discs=discs)
            if free.converged and free.stable and clear_of_itself(arm, scene, free):
                return free_contact_result(free, scene, before)
    return solve_shooting(problem, contact_layout(arm, packed, scene), load_moments=False,
                          moving=moving)


def clear_of_itself(arm, scene, eq) -> bool:
    """Whether no two parts of the backbone of ``eq`` farther apart along the arc than the
    self-contact exclusion come within their summed half-thicknesses plus one RK4 step (the
    samples' spacing) of each other — always True without self-contact. Checked on the
    returned state only: a contact-free path that crossed itself on the way and came out
    clear is not caught (a quasi-static ramp between two clear states seldom does)."""
    if scene.self_contact is None or eq.s.size < 2:
        return True
    half = np.array(arm.half_thickness())
    section = np.minimum(np.searchsorted(np.asarray(eq.section_ends), np.arange(eq.s.size)),
                         half.size - 1)
    return bool(far_parts_clear(np.ascontiguousarray(eq.positions), eq.s, half[section],
                                self_contact_exclusion(half), float(np.max(np.diff(eq.s)))))


def free_contact_result(eq, scene, dissipated: float = 0.0):
    """A contact-free equilibrium (planar or spatial) as the result of a solve in ``scene``
    (zero contact; no tangential state; ``dissipated``: the friction's work on the path
    before it, J)."""
    n, dim = eq.positions.shape
    return replace(eq, scene=scene, contact_force=np.zeros((n, dim)), penetration=np.zeros(n),
                   dissipated=dissipated)
