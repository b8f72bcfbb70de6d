"""The path a request needs, and the grid its result needs (docs/design.md §6–11).

:func:`dispatch` is the one entry of :mod:`solver.paths`: :func:`solver.solve`,
:class:`solver.Stepper` (its general path) and :mod:`solver.grasp` call it with a validated
:class:`~solver.problem.Problem` (:func:`solver.inputs.request`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from solver.blas import single_blas_thread
from solver.paths import grid
from solver.paths.contact import solve_contact, solve_rigid
from solver.paths.planar import closed_form, solve_lean, solve_planar
from solver.paths.spatial import (
    in_plane,
    in_plane_shortcut,
    in_plane_state,
    solve_spatial,
    solve_spatial_lean,
)
from solver.paths.spatial_contact import solve_contact_spatial
from solver.problem import Problem, refined
from solver.results import Equilibrium, tip_only


def dispatch(problem: Problem, record: bool, moving: bool = False) -> Equilibrium:
    """The solve of a validated request by the path its scene needs (:func:`path`), on an
    RK4 grid fine enough for its result, returned on the settings' grid (the finer grid's
    nodes include it). ``record``: with backbone samples (else the tip only). ``moving``: the
    warm start's obstacles move to the scene's (penalty contact only;
    :func:`solver.paths.contact.solve_contact`). Never raises (:mod:`solver.solve`)."""
    scene, settings, packed = problem.scene, problem.settings, problem.packed
    if problem.model == "constant_curvature" or (
            not scene.has_contact and settings.shortcuts and not problem.ctx.has_load):
        return closed_form(problem, record)
    if not moving:
        lean = solve_lean if problem.planar else solve_spatial_lean
        try:
            eq = lean(problem, record)
        except (ArithmeticError, np.linalg.LinAlgError):
            eq = None  # the general path meets it again, and reports it
        if eq is not None and all(map(math.isfinite, eq.tip)):
            return eq
    q = packed.mass_per_length * scene.gravity
    on_layout = problem
    while True:
        try:
            eq = path(on_layout, moving)
            need, worst = grid.needs(eq, on_layout.packed.secf, q)  # infinite at a sample not finite
        except (ArithmeticError, np.linalg.LinAlgError):
            eq = None
        if eq is None or not (math.isfinite(worst) and all(map(math.isfinite, eq.tip))):
            # No finite state: the unloaded shape at these pressures, flagged (finite, so that
            # a stepper can keep it).
            eq = closed_form(problem, record)
            return replace(eq, converged=False, stable=False, residual=np.inf)
        if worst <= 1.0:
            break
        steps = grid.refined_steps(eq, packed.sec_steps, on_layout.packed.sec_steps, need,
                                   settings.max_refinement)
        if steps is None:  # the finest grid allowed does not resolve this state
            eq = replace(eq, converged=False)
            break
        on_layout = problem.on(refined(problem.arm, packed, steps))
    if on_layout is not problem and not scene.has_contact:  # (contact keeps its own finer layout)
        eq = grid.on_grid(eq, on_layout.packed.sec_steps, packed.sec_steps)
    return eq if record else tip_only(eq)


def path(problem: Problem, moving: bool = False) -> Equilibrium:
    """The recorded solve by the path the scene needs (contact, planar, the in-plane
    shortcut of a spatial solve, spatial)."""
    scene, planar, warm_start = problem.scene, problem.planar, problem.warm_start
    if scene.has_contact:
        contact = solve_contact if planar else solve_contact_spatial
        with single_blas_thread():  # dense Newton and relaxation steps (docs/design.md §8)
            if scene.has_rigid_obstacles:
                return solve_rigid(problem, contact)
            if not planar:
                return contact(problem)
            return contact(problem, moving)
    if planar:
        return solve_planar(problem)
    if problem.settings.shortcuts and scene.is_planar and (
            warm_start is None or in_plane_state(warm_start)) and in_plane(problem):
        eq = in_plane_shortcut(problem)
        if eq is not None:
            return eq
    return solve_spatial(problem)
