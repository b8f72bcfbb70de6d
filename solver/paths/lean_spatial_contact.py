"""The 3D steppers' lean path in scenes with obstacles (cylinders, spheres, discs): what n
copies of one arm keep between steps so that a warm step is one kernel call
(:mod:`solver.kernels.spatial_stepping`).

The general path of such a step (:func:`solver.paths.spatial_contact.solve_contact_spatial`)
builds the contact layout, its levels and weights anew at every call, interpolates the
nodes of its start from the warm start's samples, and follows the quasi-static path by
continuation with a Jacobian formed afresh at every Newton iteration. :class:`SpatialContactRows`
builds the fixed parts once and keeps each copy's state on the grid it lives on — the
settings' grid for a contact-free state, the contact layout (nodes, level, factored
Jacobian, backbone) for one from the contact kernels — and the kernel takes the step from
there, or says it cannot, and the caller's general path takes it from the same state
(docs/design.md §9, "A lean 3D contact step"). :class:`solver.Stepper` keeps one copy.
"""

from __future__ import annotations

import numpy as np

from solver import layout as L
from solver.kernels import spatial_contact as contact_kernels
from solver.kernels import spatial_stepping as stepping
from solver.kernels.obstacles import clearance_3d
from solver.paths.contact import free_contact_result
from solver.paths.friction import new_samples
from solver.paths.grid import section_rows
from solver.paths.lean_contact import hold_rows, median_seconds
from solver.paths.planar import not_single
from solver.paths.shooting import shooting_params
from solver.paths.spatial import base_quaternion, spatial_result, spatial_samples
from solver.paths.spatial_contact import contact_result, grid_and_terms, node_arcs, out_of_reach
from solver.problem import Problem, contact_layout
from solver.results import Equilibrium
from solver.rod import rest_strains_into


def lean_spatial_contact_reason(problem: Problem) -> str | None:
    """Why 3D steppers in this problem's scene cannot take lean steps (None: they can):
    spatial penalty contact (cylinders, spheres, discs) within the arm's reach, the
    general path's shortcuts on, and a loaded arm with channels whose contact-free steps
    single shooting suits."""
    scene = problem.scene
    if problem.planar:
        return "a planar solve (the planar lean contact path)"
    if not scene.obstacles:
        return "a scene without obstacles"
    if scene.has_rigid_obstacles:
        return "rigid obstacles (penalty continuation)"
    if not problem.settings.shortcuts:
        return "Settings(shortcuts=False) (every step the contact ramp)"
    if out_of_reach(problem):
        return "obstacles out of the arm's reach (the contact-free solve)"
    return not_single(problem.in_scene(scene.without_contact))


class SpatialContactRows:
    """The lean 3D contact path of n copies of one arm in one scene.

    Args:
        problem: a spatial request in the scene (its pressures and warm start unused).
        n: copies.

    Attributes:
        free, contact: the kernels' argument tuples (:mod:`solver.kernels.spatial_stepping`).
        layout, contact_section_ends: the contact layout and its records' section-end rows.
    """

    def __init__(self, problem: Problem, n: int):
        reason = lean_spatial_contact_reason(problem)
        if reason is not None:
            raise ValueError(f"no lean 3D contact path for {reason}")
        arm, packed, scene, settings = problem.arm, problem.packed, problem.scene, problem.settings
        self._problem = problem
        self.n = n
        ns, nc, rows = len(arm.sections), arm.n_channels, packed.n_rows
        ctx = problem.ctx
        # Own writable copies of the shared, read-only samples: an unpickled copy of this
        # object holds writable arrays (pickle drops the flag), and a read-only array is
        # another type to numba, so every unpickled env compiled the kernel again.
        seg, s, force = (np.array(a) for a in spatial_samples(arm, packed, scene.without_contact, ctx))
        free = [None] * stepping.N_FREE3
        free[stepping.F3_QUAT0] = base_quaternion(scene.base_theta)
        free[stepping.F3_SECF], free[stepping.F3_STEPS] = packed.secf, packed.sec_steps
        free[stepping.F3_CJ] = packed.c_j
        free[stepping.F3_TUBES_I], free[stepping.F3_TUBES_F] = packed.tubes_i, packed.tubes_f
        free[stepping.F3_LOADS], free[stepping.F3_M_TIP] = ctx.loads, ctx.m_tip
        free[stepping.F3_PARAMS] = ctx.params
        free[stepping.F3_SEG], free[stepping.F3_S], free[stepping.F3_FORCE] = seg, s, force
        free[stepping.F3_CHECK_Q] = packed.mass_per_length * scene.gravity
        free[stepping.F3_ENDS] = section_rows(packed.section_ends)
        free[stepping.F3_M0] = np.zeros((n, 3))
        free[stepping.F3_POS] = np.zeros((n, 2, rows, 3))
        free[stepping.F3_ROT] = np.zeros((n, 2, rows, 3, 3))
        free[stepping.F3_MOM] = np.zeros((n, 2, rows, 3))
        free[stepping.F3_REST] = np.zeros((n, 3, ns))
        free[stepping.F3_OK] = np.zeros(n, dtype=bool)
        layout, segs, sec_start = contact_layout(arm, packed, scene)
        self.layout = layout
        self.contact_section_ends = layout.section_ends
        grid, (plate, target, weights, res_weights, scales) = grid_and_terms(
            arm, layout, segs, sec_start, scene, problem.on(layout).ctx)
        n_nodes = weights.shape[0]
        contact = [None] * stepping.N_CONTACT3
        (contact[stepping.C3_QUAT0], contact[stepping.C3_SEGS], contact[stepping.C3_SECF],
         contact[stepping.C3_STEPS], contact[stepping.C3_CJ], contact[stepping.C3_START]) = grid
        contact[stepping.C3_PARAMS] = shooting_params(scene, settings)
        contact[stepping.C3_WEIGHTS], contact[stepping.C3_RES_WEIGHTS] = weights, res_weights
        contact[stepping.C3_SCALES] = scales
        contact[stepping.C3_Q], contact[stepping.C3_PLATE] = problem.on(layout).ctx.q, plate
        contact[stepping.C3_TARGET] = target
        contact[stepping.C3_ARCS] = node_arcs(layout, segs, sec_start)
        contact[stepping.C3_SECTIONS] = np.ascontiguousarray(segs[:, L.SEG_SECTION])
        contact[stepping.C3_CHECK_Q] = layout.mass_per_length * scene.gravity
        contact[stepping.C3_CHECK_ENDS] = section_rows(layout.section_ends)
        contact[stepping.C3_NODES] = np.zeros((n, segs.shape[0], L.N_CSTATE))
        contact[stepping.C3_P] = np.zeros((n, nc))
        contact[stepping.C3_OBSTACLES] = np.repeat(scene.obstacles_array()[None], n, axis=0)
        contact[stepping.C3_REST] = np.zeros((n, 3, ns))
        contact[stepping.C3_LU] = np.zeros((n, contact_kernels.BAND_ROWS, n_nodes))
        contact[stepping.C3_PIV] = np.zeros((n, n_nodes), dtype=np.int64)
        record = contact_kernels.new_record(layout.n_rows)
        for index, array in zip(range(stepping.C3_S, stepping.C3_U + 1), record):
            contact[index] = np.zeros((n, 2, *array.shape))
        contact[stepping.C3_OK] = np.zeros(n, dtype=bool)
        contact[stepping.C3_TOUCHING] = np.zeros(n, dtype=bool)
        # Friction: the copies' tangential state (no rows without friction).
        contact[stepping.C3_MU] = np.repeat(scene.friction_array()[None], n, axis=0)
        contact[stepping.C3_FRICTION] = np.stack(
            [new_samples(layout.n_rows if scene.has_friction else 0, len(scene.obstacles))] * n)
        self.free, self.contact = tuple(free), tuple(contact)
        self._flags = np.zeros((n, 5))
        self._dissipated = np.zeros(n)  # each copy's dissipation before its samples' work

    # ------------------------------------------------------------------ copies

    def adopt(self, k: int, eq: Equilibrium) -> None:
        """Make ``eq`` (solved in the scene, with a record) copy k's state, as the general
        path left it: on the contact layout if it lies there (converged and stable), and —
        unless it touches — the start of the contact-free step, which tries first from a
        state that touches nothing."""
        free, contact = self.free, self.contact
        free[stepping.F3_OK][k] = contact[stepping.C3_OK][k] = False
        contact[stepping.C3_TOUCHING][k] = False
        self._flags[k] = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        self._dissipated[k] = eq.dissipated
        fs = contact[stepping.C3_FRICTION][k]
        if fs.shape[0]:
            fs[:] = new_samples(fs.shape[0], fs.shape[2])
            given = eq.friction_samples
            if given.shape == fs.shape:
                fs[:] = given
                fs[..., L.FS_WORK] = 0.0  # (counted in eq.dissipated)
        nodes = contact[stepping.C3_NODES][k]
        if eq.shooting_nodes.shape == (nodes.size,):
            if not (eq.converged and eq.stable):
                return
            z = eq.shooting_nodes.reshape(nodes.shape).copy()
            p_level = np.array(eq.channel_pressures, dtype=float)
            rest = np.empty((3, len(self._problem.arm.sections)))
            layout = self.layout
            rest_strains_into(p_level, layout.tubes_i, layout.tubes_f, layout.secf, rest)
            stepping.adopt_nodes(k, free, contact, z, self._level(k, p_level), rest)
            return
        if eq.in_contact or eq.s.size != free[stepping.F3_S].size:
            return
        free[stepping.F3_M0][k] = eq.base_moment
        free[stepping.F3_POS][k, 0] = eq.positions
        free[stepping.F3_ROT][k, 0] = eq.orientations
        free[stepping.F3_MOM][k, 0] = eq.internal_moment
        rest_strains_into(eq.channel_pressures, self.layout.tubes_i, self.layout.tubes_f,
                          self.layout.secf, free[stepping.F3_REST][k])
        free[stepping.F3_OK][k] = True

    def ready(self, k: int) -> bool:
        """Whether copy k has a state the lean path can step from."""
        return bool(self.free[stepping.F3_OK][k] or self.contact[stepping.C3_OK][k])

    def on_contact_layout(self, k: int) -> bool:
        """Whether copy k's state lies on the contact layout."""
        return bool(self.contact[stepping.C3_OK][k])

    def tip(self, k: int) -> np.ndarray:
        """Copy k's tip (3,) (m; a view)."""
        if self.contact[stepping.C3_OK][k]:
            return self.contact[stepping.C3_POS][k, 0, -1]
        return self.free[stepping.F3_POS][k, 0, -1]

    def step(self, p_from: np.ndarray, p_to: np.ndarray, active: np.ndarray, run=None) -> np.ndarray:
        """Warm steps of the ``active`` copies from the channel pressures ``p_from`` to
        ``p_to`` (n, n_channels) by the lean path (``run`` unused: the copies run serially,
        as the planar rows' signature has it); a copy stepped to its own pressures is held
        (:func:`solver.paths.lean_contact.hold_rows`).

        Returns:
            (n, 6) report rows (converged, stable, snapped, iterations, residual, path code
            of :data:`solver.paths.lean_contact.PATHS`); an unconverged row kept its state
            (the general path's turn).
        """
        report = np.zeros((self.n, 6))
        moving = hold_rows(self.free[stepping.F3_OK] | self.contact[stepping.C3_OK], p_from, p_to,
                           active, self._flags, report)
        if moving.any():
            stepping.spatial_contact_rows(self.free, self.contact, p_from, p_to, moving, report)
        done = moving & (report[:, 0] != 0.0)
        self._flags[done] = report[done, :5]
        return report

    def pass_costs(self, k: int, repeats: int) -> dict:
        """What one pass over copy k's contact state costs: a residual pass and a pass with
        the Jacobian by the variational equations (the lean step's; seconds, the median of
        ``repeats``), the unknowns, the RK4 rows and the fraction of them refined near an
        obstacle (a profile's figures; the state is untouched).

        Raises:
            ValueError: copy k's state is not on the contact layout.
        """
        contact = self.contact
        if not contact[stepping.C3_OK][k]:
            raise ValueError(f"copy {k} is not on the contact layout")
        grid = tuple(contact[i] for i in range(stepping.C3_QUAT0, stepping.C3_START + 1))
        nodes = contact[stepping.C3_NODES][k].copy()
        level = self._level(k, contact[stepping.C3_P][k])
        level = (*level[:L.L_FRICTION], level[L.L_FRICTION].copy())  # (passes record into it)
        rest = np.empty_like(contact[stepping.C3_REST][k])
        rest_strains_into(level[L.L_P], self.layout.tubes_i, self.layout.tubes_f, self.layout.secf,
                          rest)
        n = contact[stepping.C3_WEIGHTS].shape[0]
        F, J = np.empty(n), np.empty((n, n))
        blocks = np.empty((nodes.shape[0], L.N_CTANGENT, L.N_CTANGENT))
        passes = {
            "residual_pass_s": lambda: contact_kernels.newton_system(
                nodes, grid, rest, level, F, np.empty((0, 0)), False, blocks,
                contact[stepping.C3_SCALES], contact_kernels.NO_TETHER),
            "jacobian_pass_s": lambda: contact_kernels.tangent_system(nodes, grid, rest, level, F,
                                                                      J, blocks),
        }
        seconds = {name: median_seconds(one_pass, repeats) for name, one_pass in passes.items()}
        pos = contact[stepping.C3_POS][k, 0]
        obstacles = level[L.L_DISCS]
        gap = np.array([clearance_3d(r[0], r[1], r[2], obstacles) for r in pos])
        h = (self.layout.sec_len / self.layout.sec_steps)[np.minimum(
            np.searchsorted(np.asarray(self.layout.section_ends), np.arange(pos.shape[0])),
            len(self.layout.sec_steps) - 1)]
        speed = np.linalg.norm(contact[stepping.C3_V][k, 0], axis=1)
        return {**seconds, "unknowns": int(n), "rows": int(pos.shape[0]),
                "refined_fraction": float(np.mean(gap - h * speed < h))}

    def _level(self, k: int, p: np.ndarray) -> tuple:
        """Copy k's level tuple (``L_*``) at the channel pressures ``p``: the loads, its
        obstacles and friction."""
        contact = self.contact
        return (p, contact[stepping.C3_Q], contact[stepping.C3_PLATE], contact[stepping.C3_TARGET],
                contact[stepping.C3_OBSTACLES][k], contact[stepping.C3_MU][k],
                contact[stepping.C3_FRICTION][k])

    def contact_measures(self) -> np.ndarray:
        """(n, 2) every copy's deepest penetration at its samples (m) and total contact force
        ∫|f| ds (N, trapezoidal on the samples); zeros for a state that touches nothing."""
        out = np.zeros((self.n, 2))
        for k in np.flatnonzero(self.contact[stepping.C3_OK]):
            s = self.contact[stepping.C3_S][k, 0]
            force = np.linalg.norm(self.contact[stepping.C3_CONTACT][k, 0], axis=1)
            out[k] = (self.contact[stepping.C3_PEN][k, 0].max(),
                      float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(s))))
        return out

    def equilibrium(self, k: int, pressures: np.ndarray, channel_pressures: np.ndarray) -> Equilibrium:
        """Copy k's state as the Equilibrium the general path returns for it (arrays copied)."""
        converged, stable, snapped, iterations, residual = self._flags[k]
        flags = dict(converged=bool(converged), stable=bool(stable), snapped=bool(snapped),
                     iterations=int(iterations), residual=float(residual))
        problem = self._problem.with_inputs(np.array(pressures, dtype=float),
                                            np.array(channel_pressures, dtype=float))
        scene = problem.scene
        # The samples' work stays in them while the copy steps clear of contact (and when it
        # comes back): the dissipation along its path is always the two together.
        fs = self.contact[stepping.C3_FRICTION][k]
        dissipated = float(self._dissipated[k] + fs[..., L.FS_WORK].sum())
        if self.contact[stepping.C3_OK][k]:
            record = tuple(self.contact[i][k, 0].copy()
                           for i in range(stepping.C3_S, stepping.C3_U + 1))
            friction = dict(dissipated=dissipated)
            if fs.shape[0]:
                friction["friction_samples"] = fs.copy()
            return contact_result(record, self.contact[stepping.C3_NODES][k].copy(), scene,
                                  self.layout, model=problem.model, pressures=problem.p_inputs,
                                  channel_pressures=problem.p_channel, arm=problem.arm,
                                  **friction, **flags)
        free = self.free
        eq = spatial_result(problem.in_scene(scene.without_contact),
                            free[stepping.F3_POS][k, 0].copy(), free[stepping.F3_ROT][k, 0].copy(),
                            free[stepping.F3_MOM][k, 0].copy(), free[stepping.F3_REST][k],
                            free[stepping.F3_M0][k], **flags)
        return free_contact_result(eq, scene, dissipated)
