"""The steppers' lean paths in scenes with contact: what n copies of one arm keep between
steps so that a warm step is one kernel call (:mod:`solver.kernels.stepping`).

The general path of such a step (:func:`solver.paths.contact.solve_contact`) builds the
contact layout, the level tuples, the norms' weights and the start state's Jacobian anew at
every call and follows the quasi-static path from the warm start by continuation; a step of
an environment is a small move from the last equilibrium. :class:`ContactRows` builds the
fixed parts once and keeps each copy's state on the grid it lives on — the settings' grid
for a state that touches nothing (stepped by the lean planar kernel, guarded), the contact
layout for one that came from the contact paths (its nodes, level, factored Jacobian and
backbone) — and the kernel takes the step from there, or says it cannot, and the caller's
general path takes it from the same state (docs/design.md §10). :class:`solver.Stepper`
keeps one copy, :class:`solver.BatchStepper` n of them: one kernel, the same numbers.
"""

from __future__ import annotations

import math

import numpy as np

from solver import layout as L
from solver.kernels import contact as contact_kernels
from solver.kernels import stepping
from solver.paths.contact import free_contact_result
from solver.paths.grid import section_rows
from solver.paths.planar import not_lean, single_result
from solver.paths.shooting import shooting_equilibrium, shooting_grid, shooting_params
from solver.problem import Problem, contact_layout, shooting_terms
from solver.results import Equilibrium
from solver.rod import forget_first_variations, planar_rest_gradient, rest_strains_into
from solver.scene import Scene, self_contact_exclusion

# Where a copy with fewer obstacles than the most keeps its unused disc rows: so far away
# that no sample comes near one (its force is an exact zero, it never sets a step's
# refinement or a tunnel).
FAR = 1e6

# Path codes of the kernels' reports.
PATHS = {1: "lean", 2: "lean contact"}


def lean_contact_reason(problem: Problem) -> str | None:
    """Why steppers in this problem's scene cannot take lean steps with contact (None:
    they can): planar penalty contact (discs, self-contact) of a loaded arm with channels
    that single shooting suits, on the full or unshearable model."""
    scene = problem.scene
    if not problem.planar:
        return "a spatial solve (planar=False)"
    if not scene.has_contact:
        return "a scene without obstacles or self-contact"
    if scene.has_rigid_obstacles or scene.self_contact == math.inf:
        return "rigid contact (penalty continuation)"
    return not_lean(problem.in_scene(scene.without_contact))


def record_from_equilibrium(eq: Equilibrium, packed, rec, rest, grad) -> None:
    """Write a recorded planar equilibrium on the settings' grid into a lean-path record
    ``rec`` (N, N_COLUMNS), with its rest strains ``rest`` (3, ns) and the predictor's
    gradient ``grad`` (2, ns)."""
    rec[:, L.S] = eq.s
    rec[:, L.X:L.Y + 1] = eq.positions
    rec[:, L.THETA] = eq.angles
    rec[:, L.M] = eq.internal_moment
    rec[:, L.NX:L.NY + 1] = eq.internal_force
    rec[:, L.V1:L.V3 + 1] = eq.shear_stretch
    rec[:, L.U] = eq.curvature
    forget_first_variations(rec)  # as a record Newton returns
    rest_strains_into(eq.channel_pressures, packed.tubes_i, packed.tubes_f, packed.secf, rest)
    planar_rest_gradient(rec, packed.secf, packed.sec_steps, rest, grad)


class ContactRows:
    """The lean paths of n copies of one arm, model and scene law (gravity, payload,
    mounting, penalty stiffness, self-contact), each copy with obstacles of its own.

    Args:
        problem: a request in the template scene (its pressures and warm start unused);
            its obstacles are every copy's until :meth:`set_scene`.
        n: copies. max_obstacles: the most obstacles a copy may hold.

    Attributes:
        scenes: (n,) each copy's scene.
        section_ends, contact_section_ends: the records' rows at the section ends, on the
            settings' grid and on the contact layout.
    """

    def __init__(self, problem: Problem, n: int, max_obstacles: int):
        reason = lean_contact_reason(problem)
        if reason is not None:
            raise ValueError(f"no lean contact path for {reason}")
        arm, packed, scene, settings = problem.arm, problem.packed, problem.scene, problem.settings
        self._problem = problem
        self.n = n
        self.max_obstacles = max_obstacles
        self.scenes = [scene] * n
        self._stiffness = scene.obstacles[0].stiffness if scene.obstacles else None
        ns, nc, n_tubes = len(arm.sections), arm.n_channels, packed.tubes_i.shape[0]
        ctx = problem.ctx
        self.section_ends = packed.section_ends
        layout, segs, sec_start = contact_layout(arm, packed, scene)
        self.layout = layout
        self.contact_section_ends = layout.section_ends
        c_ctx = problem.on(layout).ctx
        plate, target, _, weights, res_weights = shooting_terms(arm, layout, segs, scene, c_ctx,
                                                                False)
        n_nodes = weights.shape[0]
        if scene.self_contact is None:
            half, exclusion = np.empty(0), 0.0
        else:
            thick = np.array(arm.half_thickness())
            section = np.minimum(np.searchsorted(np.asarray(packed.section_ends),
                                                 np.arange(packed.n_rows)), thick.size - 1)
            half, exclusion = thick[section], self_contact_exclusion(thick)
        self.free = (
            (scene.base_theta, packed.secf, packed.sec_steps), (packed.tubes_i, packed.tubes_f),
            ctx.loads, ctx.m_tip, ctx.params, np.zeros((n, 4)),
            np.zeros((n, packed.n_rows, L.N_COLUMNS)), np.zeros((n, packed.n_rows, L.N_COLUMNS)),
            np.empty((n, 3, ns)), np.empty((n, nc)), np.empty((n, ns, 4)),
            (np.full((n, n_tubes), np.nan), np.empty((n, n_tubes)), np.empty((n, 3, ns)),
             np.full((n, 2, ns), np.nan)),
            half, exclusion, np.zeros(n, dtype=bool))
        coupled = scene.self_contact is not None
        m = n_nodes if coupled else 0
        self.contact = (
            shooting_grid(arm, scene, layout, segs, sec_start), shooting_params(scene, settings),
            weights, res_weights, np.zeros((n, n_nodes)), np.zeros((n, max(nc, 1))), c_ctx.q,
            plate, target, np.zeros((n, max_obstacles, 4)), np.empty((n, 3, ns)),
            (np.empty((n, contact_kernels.BAND_ROWS, n_nodes)), np.empty((n, n_nodes), dtype=np.int64),
             np.empty((n, m, m)), np.empty((n, m), dtype=np.int64), np.zeros((n, 1), dtype=np.int64)),
            np.zeros((n, layout.n_rows, L.C_COLUMNS)), np.zeros((n, layout.n_rows, L.C_COLUMNS)),
            (layout.mass_per_length * scene.gravity, section_rows(layout.section_ends)),
            np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))
        self._flags = np.zeros((n, 5))
        for k in range(n):
            self.set_scene(k, scene)

    # ------------------------------------------------------------------ copies

    def set_scene(self, k: int, scene: Scene) -> None:
        """Give copy k the obstacles of ``scene`` (the template's law; checked by the
        caller). Its state is not changed: adopt one solved in that scene next."""
        discs = scene.discs_array()
        if discs.shape[0] > self.max_obstacles:
            raise ValueError(f"copy {k}: {discs.shape[0]} obstacles, more than the "
                             f"{self.max_obstacles} this batch holds")
        rows = self.contact[9][k]
        rows[:] = (FAR, FAR, 0.0, 0.0)
        rows[:discs.shape[0]] = discs
        self.scenes[k] = scene

    def adopt(self, k: int, eq: Equilibrium) -> None:
        """Make ``eq`` (solved in copy k's scene, with a record) copy k's state, as the
        general path left it: on the contact layout if it lies there (converged and stable),
        and — unless it touches — its record on the settings' grid for the contact-free
        step, which tries first from a state that touches nothing."""
        free, contact = self.free, self.contact
        free[14][k] = contact[15][k] = contact[16][k] = False
        self._flags[k] = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        nodes = contact[4][k]
        if eq.converged and eq.stable and eq.shooting_nodes.shape == nodes.shape:
            nodes[:] = eq.shooting_nodes
            p_level = contact[5][k]
            p_level[:] = eq.channel_pressures
            rest = contact[10][k]
            rest_strains_into(p_level, self.layout.tubes_i, self.layout.tubes_f, self.layout.secf, rest)
            level = (p_level, contact[6], contact[7], contact[8], contact[9][k])
            factors = tuple(f[k] for f in contact[11])
            blocks = np.empty((contact[0][L.G_SEGS].shape[0], 6, 6))
            if contact_kernels.factor_state(nodes, contact[0], rest, level, contact[2],
                                            np.empty_like(nodes), blocks, contact[12][k], factors):
                contact[15][k] = True
                contact[16][k] = stepping.touches(contact[12][k])
                if contact[16][k]:
                    return
        packed = self._problem.packed
        if eq.s.size == packed.n_rows:
            memo = free[11]
            record_from_equilibrium(eq, packed, free[6][k], memo[2][k], memo[3][k])
            free[5][k, 0] = eq.base_moment[-1]
        elif contact[15][k]:
            stepping.free_record_of(contact[12][k], float(eq.base_moment[-1]), eq.channel_pressures,
                                    free, k)
        else:
            return
        free[14][k] = True

    def ready(self, k: int) -> bool:
        """Whether copy k has a state the lean paths can step from."""
        return bool(self.free[14][k] or self.contact[15][k])

    def on_contact_layout(self, k: int) -> bool:
        """Whether copy k's state lies on the contact layout."""
        return bool(self.contact[15][k])

    def record(self, k: int) -> np.ndarray:
        """Copy k's record: on the contact layout (rows, C_COLUMNS) or the settings' grid
        (rows, N_COLUMNS); columns S … U are the same either way (a view)."""
        return self.contact[12][k] if self.contact[15][k] else self.free[6][k]

    def step(self, p_from: np.ndarray, p_to: np.ndarray, active: np.ndarray, run) -> np.ndarray:
        """Warm steps of the ``active`` copies from the channel pressures ``p_from`` to
        ``p_to`` (n, n_channels) by the lean paths; ``run`` calls the parallel or the serial
        kernel (a :meth:`ThreadPolicy.run`-like callable, or None: serial).

        Returns:
            (n, 6) report rows (converged, stable, snapped, iterations, residual, path code
            of :data:`PATHS`); an unconverged row kept its state (the general path's turn).
        """
        report = np.zeros((self.n, 6))
        args = (self.free, self.contact, p_from, p_to, active, report)
        if run is None:
            stepping.contact_rows_serial(*args)
        else:
            run(stepping.contact_rows_parallel, stepping.contact_rows_serial, int(active.sum()), *args)
        done = report[:, 0] != 0.0
        self._flags[done] = report[done, :5]
        return report

    def equilibrium(self, k: int, pressures: np.ndarray, channel_pressures: np.ndarray) -> Equilibrium:
        """Copy k's state as the Equilibrium the general path returns for it (arrays copied)."""
        converged, stable, snapped, iterations, residual = self._flags[k]
        flags = dict(converged=bool(converged), stable=bool(stable), snapped=bool(snapped),
                     iterations=int(iterations), residual=float(residual))
        problem = self._problem.in_scene(self.scenes[k]).with_inputs(
            np.array(pressures, dtype=float), np.array(channel_pressures, dtype=float))
        if self.contact[15][k]:
            return shooting_equilibrium(self.contact[12][k], self.contact[4][k].copy(),
                                        self.scenes[k], self.layout, model=problem.model,
                                        pressures=problem.p_inputs,
                                        channel_pressures=problem.p_channel, arm=problem.arm,
                                        **flags)
        eq = single_result(problem, self.free[6][k].copy(), self.free[5][k, 0], **flags)
        return free_contact_result(eq, self.scenes[k])
