"""The contact stepper's lean path: what a warm step of an arm pressed on discs keeps between
steps, so that the step is one kernel call (:func:`solver.kernels.contact.lean_step`).

The general path of such a step (:func:`solver.paths.contact.solve_contact`) builds the
contact layout, the level tuples, the norms' weights and the start state's Jacobian anew at
every call, and follows the quasi-static path from the warm start in a continuation of
several Newton solves; a step of an environment is a small move from the last equilibrium.
:class:`LeanContact` builds the fixed parts once per arm and scene and keeps the current
state's nodes, level, factored Jacobian and backbone, and the kernel takes the step from
there — or says it cannot, and the caller's general path takes it from the same state
(docs/design.md §10).
"""

from __future__ import annotations

import numpy as np

from solver import layout as L
from solver.kernels import contact as contact_kernels
from solver.paths.grid import section_rows
from solver.paths.shooting import shooting_equilibrium, shooting_grid, shooting_params
from solver.problem import Problem, contact_layout, shooting_terms
from solver.results import Equilibrium
from solver.rod import rest_strains_into


def lean_contact_reason(problem: Problem) -> str | None:
    """Why a stepper in this problem's scene cannot take lean contact steps (None: it can):
    they are planar penalty contact (discs, self-contact) of an arm with channels, on the
    full or unshearable model."""
    scene = problem.scene
    if not problem.planar:
        return "a spatial solve (planar=False)"
    if not scene.has_contact:
        return "a scene without obstacles or self-contact"
    if scene.has_rigid_obstacles or scene.self_contact == float("inf"):
        return "rigid contact (penalty continuation)"
    if not problem.arm.n_channels:
        return "a passive arm (no channels)"
    if problem.model == "constant_curvature":
        return "the constant_curvature model"
    return None


class LeanContact:
    """The lean contact path of one arm, model and scene, and its current state.

    Args:
        problem: a request in the scene (its pressures and warm start are not used).

    Attributes:
        ready: the current state is an equilibrium on the contact layout, from which
            :meth:`step` can start (else the caller's general path takes the step).
        record: (rows, C_COLUMNS) the current state's backbone (read-only view; its columns
            S … U are those of a planar record, :mod:`solver.layout`).
        section_ends: its rows at the section ends.
    """

    def __init__(self, problem: Problem):
        arm, scene = problem.arm, problem.scene
        layout, segs, sec_start = contact_layout(arm, problem.packed, scene)
        ctx = problem.on(layout).ctx
        plate, target, _, weights, res_weights = shooting_terms(arm, layout, segs, scene, ctx,
                                                                False)
        self.layout = layout
        self.section_ends = layout.section_ends
        self._scene = scene
        self._grid = shooting_grid(arm, scene, layout, segs, sec_start)
        self._tubes = (layout.tubes_i, layout.tubes_f)
        self._params = shooting_params(scene, problem.settings)
        n = weights.shape[0]
        self._nodes = np.zeros(n)
        self._level = (np.zeros(max(arm.n_channels, 1)), ctx.q, plate, target, scene.discs_array())
        self._work = (np.empty((3, len(arm.sections))), weights, res_weights)
        self._factors = contact_kernels.new_factors(n, scene.self_contact is not None)
        self._records = (np.zeros((layout.n_rows, L.C_COLUMNS)),
                         np.zeros((layout.n_rows, L.C_COLUMNS)))
        self._check = (layout.mass_per_length * scene.gravity, section_rows(layout.section_ends))
        self._flags = (True, True, False, 0, 0.0)
        self.ready = False

    @property
    def record(self) -> np.ndarray:
        view = self._records[0].view()
        view.flags.writeable = False
        return view

    @property
    def in_contact(self) -> bool:
        """Whether the current state presses on a disc or on itself."""
        return bool(self._records[0][:, L.C_PEN].max() > 0.0)

    def adopt(self, eq: Equilibrium) -> bool:
        """Make ``eq`` (a result of the general path in this scene) the current state, if the
        lean path can start from it: converged and stable, on this contact layout. Returns
        :attr:`ready`."""
        self.ready = False
        if not (eq.converged and eq.stable and eq.shooting_nodes.shape == self._nodes.shape):
            return False
        self._nodes[:] = eq.shooting_nodes
        self._level[L.L_P][:] = eq.channel_pressures
        rest = self._work[0]
        rest_strains_into(self._level[L.L_P], self._tubes[0], self._tubes[1], self.layout.secf,
                          rest)
        blocks = np.empty((self._grid[L.G_SEGS].shape[0], 6, 6))
        if not contact_kernels.factor_state(self._nodes, self._grid, rest, self._level,
                                            self._work[1], np.empty_like(self._nodes), blocks,
                                            self._records[0], self._factors):
            return False
        self._flags = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        self.ready = True
        return True

    def step(self, p_channel: np.ndarray) -> tuple[bool, bool, int, float]:
        """Try the warm step to the channel pressures ``p_channel`` (Pa, validated).

        Returns:
            (ok, stable, iterations, residual) of :func:`solver.kernels.contact.lean_step`;
            on failure the state is as it was.
        """
        ok, stable, its, res = contact_kernels.lean_step(
            self._nodes, self._grid, self._tubes, self._level, p_channel, self._params,
            self._work, self._factors, self._records, self._check)
        if ok:
            self._records = self._records[::-1]
            self._flags = (True, bool(stable), False, int(its), float(res))
        return bool(ok), bool(stable), int(its), float(res)

    def equilibrium(self, problem: Problem) -> Equilibrium:
        """The current state as the Equilibrium the general path returns for it; ``problem``
        carries its pressures."""
        converged, stable, snapped, iterations, residual = self._flags
        return shooting_equilibrium(self._records[0], self._nodes.copy(), self._scene, self.layout,
                                    converged=converged, stable=stable, snapped=snapped,
                                    iterations=iterations, residual=residual, model=problem.model,
                                    pressures=problem.p_inputs, channel_pressures=problem.p_channel,
                                    arm=problem.arm)
