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
import time

import numba
import numpy as np

from solver import layout as L
from solver.kernels import contact as contact_kernels
from solver.kernels import stepping
from solver.paths.contact import free_contact_result
from solver.paths.friction import new_samples, start_self_samples, turn_anchors
from solver.paths.grid import section_rows
from solver.paths.planar import not_lean, single_result
from solver.paths.shooting import shooting_equilibrium, shooting_grid, shooting_params
from solver.problem import Problem, contact_layout, shooting_terms
from solver.results import Equilibrium
from solver.rod import forget_first_variations, planar_rest_gradient, rest_strains_into
from solver.scene import Scene, self_contact_exclusion
from solver.threads import CopyPool

# Where a copy with fewer obstacles than the most keeps its unused disc rows: so far away
# that no sample comes near one (its force is an exact zero, it never sets a step's
# refinement or a tunnel).
FAR = 1e6

# The kernels' path codes, and the code of a copy held at its own pressures (no kernel ran:
# :meth:`ContactRows.step`).
PATH_HELD = 3.0
PATHS = {int(stepping.PATH_LEAN): "lean", int(stepping.PATH_CONTACT): "lean contact",
         int(PATH_HELD): "held"}

# Blocks of copies per thread in a threaded batch (:meth:`ContactRows.step`), each one call of
# the row kernel (~5 µs to enter): a thread that finishes its block early takes the next. A
# lean contact row costs ~10 times a contact-free one, yet over 1,024 random-action copies the
# rows' costs leave an even split within 7 % of the ideal, so the count matters little.
BLOCKS_PER_THREAD = 4

# The active masks of a batch of one (writable: the row kernels are compiled for writable
# masks, and a read-only one would be another signature to compile). Nothing writes them.
ONE_COPY = np.ones(1, dtype=bool)
NO_COPY = np.zeros(1, dtype=bool)

# What the bits of a report's refusal column mean (solver.kernels.contact.lean_step).
REFUSALS = {contact_kernels.REFUSED_CONVERGENCE: "not converged",
            contact_kernels.REFUSED_UNSTABLE: "unstable",
            contact_kernels.REFUSED_JUMP: "branch jump",
            contact_kernels.REFUSED_SINGULAR: "singular or unconverged pass",
            contact_kernels.REFUSED_TUNNEL: "tunnel",
            contact_kernels.REFUSED_GRID: "grid refinement",
            contact_kernels.REFUSED_BUDGET: "budget spent"}


def hold_rows(ready: np.ndarray, p_from: np.ndarray, p_to: np.ndarray, active: np.ndarray,
              flags: np.ndarray, report: np.ndarray) -> np.ndarray:
    """Hold the ``active`` copies that are ``ready`` (n,) and stepped to the pressures they
    stand at (``p_to`` rows equal to ``p_from``'s): a quasi-static state nothing moves stands.
    Their ``report`` rows (n, ≥ 6) say converged, their ``flags`` (n, 5: the last solve's
    converged, stable, snapped, iterations, residual) stability and residual, no snap, no pass,
    path :data:`PATH_HELD`. Returns the active copies left to step."""
    if active.shape[0] == 1:
        # One copy (a single Stepper's every step): the test and the report on scalars, where
        # the array operations cost as much as a contact-free kernel call.
        if not (active[0] and ready[0] and p_from[0].tolist() == p_to[0].tolist()):
            return active
        report[0, 0], report[0, 1], report[0, 4], report[0, 5] = 1.0, flags[0, 1], flags[0, 4], PATH_HELD
        return NO_COPY
    else:
        held = active & ready & np.all(p_from == p_to, axis=1)
        if not held.any():
            return active
    report[held, 0] = 1.0
    report[held, 1] = flags[held, 1]
    report[held, 4] = flags[held, 4]
    report[held, 5] = PATH_HELD
    return active & ~held


def refusal_names(bits) -> tuple[str, ...]:
    """The names (:data:`REFUSALS`) of a report's refusal bits (its last column)."""
    return tuple(name for bit, name in REFUSALS.items() if int(bits) & bit)


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


def _fixed_parts(problem: Problem) -> tuple:
    """What :class:`ContactRows` needs of an arm and a scene law whatever the obstacles'
    places: the contact layout and its context, segments and layout tuple, the level's loads
    (endplates, tip target), the norms' weights, and the self-contact guard (half-thickness
    per sample of the settings' grid, exclusion)."""
    arm, packed, scene = problem.arm, problem.packed, problem.scene
    layout, segs, sec_start = contact_layout(arm, packed, scene)
    c_ctx = problem.on(layout).ctx
    plate, target, _, weights, res_weights = shooting_terms(arm, layout, segs, scene, c_ctx, False)
    if scene.self_contact is None:
        half, exclusion = np.empty(0), 0.0
    else:
        thick = np.array(arm.half_thickness())
        section = np.minimum(np.searchsorted(np.asarray(packed.section_ends),
                                             np.arange(packed.n_rows)), thick.size - 1)
        half, exclusion = thick[section], self_contact_exclusion(thick)
    grid = shooting_grid(arm, scene, layout, segs, sec_start)
    return layout, c_ctx, segs, grid, plate, target, weights, res_weights, half, exclusion


def median_seconds(one_pass, repeats: int) -> float:
    """The median of ``repeats`` timings (s) of ``one_pass()`` after one untimed call (the
    first may load the kernel)."""
    one_pass()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        one_pass()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


class ContactRows:
    """The lean paths of n copies of one arm, model and scene law (gravity, payload,
    mounting, penalty stiffness, self-contact), each copy with obstacles of its own.

    Args:
        problem: a request in the template scene (its pressures and warm start unused);
            its obstacles are every copy's until :meth:`set_scene`.
        n: copies. max_obstacles: the most obstacles a copy may hold.
        pool: the threads a threaded batch's rows run on (a batch's own, which its general
            path's solves share; None: a pool of its own, made on first use).

    Attributes:
        scenes: (n,) each copy's scene.
        section_ends, contact_section_ends: the records' rows at the section ends, on the
            settings' grid and on the contact layout.
    """

    def __init__(self, problem: Problem, n: int, max_obstacles: int, pool: CopyPool | None = None):
        reason = lean_contact_reason(problem)
        if reason is not None:
            raise ValueError(f"no lean contact path for {reason}")
        arm, packed, scene, settings = problem.arm, problem.packed, problem.scene, problem.settings
        self._problem = problem
        self.n = n
        self.max_obstacles = max_obstacles
        self.scenes = [scene] * n
        ns, nc, n_tubes = len(arm.sections), arm.n_channels, packed.tubes_i.shape[0]
        ctx = problem.ctx
        self.section_ends = packed.section_ends
        # What does not depend on the obstacles' places is built once per arm and law.
        law = (scene.without_contact, scene.self_contact, scene.self_friction,
               scene.obstacles[0].stiffness if scene.obstacles else None)
        layout, c_ctx, _, grid, plate, target, weights, res_weights, half, exclusion = \
            arm._solver_cache.get(("lean contact", packed.key, law), lambda: _fixed_parts(problem))
        self.layout = layout
        self.contact_section_ends = layout.section_ends
        n_nodes = weights.shape[0]
        free = [None] * stepping.N_FREE
        free[stepping.FR_THETA0] = scene.base_theta
        free[stepping.FR_SECF], free[stepping.FR_STEPS] = packed.secf, packed.sec_steps
        free[stepping.FR_TUBES_I], free[stepping.FR_TUBES_F] = packed.tubes_i, packed.tubes_f
        free[stepping.FR_LOADS], free[stepping.FR_M_TIP] = ctx.loads, ctx.m_tip
        free[stepping.FR_PARAMS] = ctx.params
        free[stepping.FR_STATES] = np.zeros((n, 4))
        free[stepping.FR_RECORDS] = np.zeros((n, packed.n_rows, L.N_COLUMNS))
        free[stepping.FR_SCRATCH] = np.zeros((n, packed.n_rows, L.N_COLUMNS))
        free[stepping.FR_REST] = np.empty((n, 3, ns))
        free[stepping.FR_P_NOW] = np.empty((n, nc))
        free[stepping.FR_LOADS_NOW] = np.empty((n, ns, 4))
        free[stepping.FR_P_SEEN] = np.full((n, n_tubes), np.nan)
        free[stepping.FR_STRETCH] = np.empty((n, n_tubes))
        free[stepping.FR_REST_A] = np.empty((n, 3, ns))
        free[stepping.FR_GRAD] = np.full((n, 2, ns), np.nan)
        free[stepping.FR_HALF], free[stepping.FR_EXCLUSION] = half, exclusion
        free[stepping.FR_OK] = np.zeros(n, dtype=bool)
        m = n_nodes if scene.self_contact is not None else 0  # the full Jacobian of touching parts
        contact = [None] * stepping.N_CONTACT
        (contact[stepping.CT_THETA0], contact[stepping.CT_SEGS], contact[stepping.CT_SECF],
         contact[stepping.CT_STEPS], contact[stepping.CT_START], contact[stepping.CT_SELF]) = grid
        contact[stepping.CT_PARAMS] = shooting_params(scene, settings)
        contact[stepping.CT_WEIGHTS], contact[stepping.CT_RES_WEIGHTS] = weights, res_weights
        contact[stepping.CT_NODES] = np.zeros((n, n_nodes))
        contact[stepping.CT_P] = np.zeros((n, max(nc, 1)))
        contact[stepping.CT_Q], contact[stepping.CT_PLATE] = c_ctx.q, plate
        contact[stepping.CT_TARGET] = target
        contact[stepping.CT_DISCS] = np.zeros((n, max_obstacles, 4))
        contact[stepping.CT_REST] = np.empty((n, 3, ns))
        contact[stepping.CT_LU] = np.empty((n, contact_kernels.BAND_ROWS, n_nodes))
        contact[stepping.CT_PIV] = np.empty((n, n_nodes), dtype=np.int64)
        contact[stepping.CT_DENSE] = np.empty((n, m, m))
        contact[stepping.CT_DENSE_PIV] = np.empty((n, m), dtype=np.int64)
        contact[stepping.CT_FLAGS] = np.zeros((n, 1), dtype=np.int64)
        contact[stepping.CT_RECORDS] = np.zeros((n, layout.n_rows, L.C_COLUMNS))
        contact[stepping.CT_SCRATCH] = np.zeros((n, layout.n_rows, L.C_COLUMNS))
        contact[stepping.CT_CHECK_Q] = layout.mass_per_length * scene.gravity
        contact[stepping.CT_CHECK_ENDS] = section_rows(layout.section_ends)
        contact[stepping.CT_OK] = np.zeros(n, dtype=bool)
        contact[stepping.CT_TOUCHING] = np.zeros(n, dtype=bool)
        # Friction: the copies' tangential state where the template's law has friction.
        self.friction = scene.has_friction
        contact[stepping.CT_MU] = np.zeros((n, max_obstacles))
        contact[stepping.CT_FRICTION] = np.stack(
            [new_samples(layout.n_rows if self.friction else 0, max_obstacles)] * n)
        contact[stepping.CT_SELF_FRICTION] = np.stack(
            [start_self_samples(scene, contact[stepping.CT_SEGS], None)] * n)
        self.free, self.contact = tuple(free), tuple(contact)
        self._flags = np.zeros((n, 5))
        self._pool = CopyPool() if pool is None else pool
        self._dissipated = np.zeros(n)  # each copy's dissipation before its samples' work
        # Every array with a row per copy (what copy_rows copies).
        self._per_copy = [free[i] for i in range(stepping.FR_STATES, stepping.FR_HALF)]
        self._per_copy += [free[stepping.FR_OK], self._flags, self._dissipated]
        self._per_copy += [contact[i] for i in (stepping.CT_NODES, stepping.CT_P, stepping.CT_DISCS)]
        self._per_copy += [contact[i] for i in range(stepping.CT_REST, stepping.CT_CHECK_Q)]
        self._per_copy += [contact[i] for i in (stepping.CT_OK, stepping.CT_TOUCHING, stepping.CT_MU,
                                                stepping.CT_FRICTION, stepping.CT_SELF_FRICTION)]
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
        if scene.has_friction and not self.friction:
            raise ValueError(f"copy {k}: obstacles with friction in a batch whose scene has "
                             f"none (its friction samples are not kept)")
        rows = self.contact[stepping.CT_DISCS][k]
        rows[:] = (FAR, FAR, 0.0, 0.0)
        rows[:discs.shape[0]] = discs
        mu = self.contact[stepping.CT_MU][k]
        mu[:] = 0.0
        mu[:discs.shape[0]] = scene.friction_array()
        self.scenes[k] = scene

    def adopt(self, k: int, eq: Equilibrium) -> None:
        """Make ``eq`` (solved in copy k's scene, with a record) copy k's state, as the
        general path left it: on the contact layout if it lies there (converged and stable),
        and — unless it touches — its record on the settings' grid for the contact-free
        step, which tries first from a state that touches nothing."""
        free, contact = self.free, self.contact
        free[stepping.FR_OK][k] = contact[stepping.CT_OK][k] = contact[stepping.CT_TOUCHING][k] = False
        self._flags[k] = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        self._dissipated[k] = eq.dissipated
        fs = contact[stepping.CT_FRICTION][k]
        if fs.shape[0]:
            fs[:] = new_samples(fs.shape[0], fs.shape[2])
            given = eq.friction_samples
            if given.ndim == 4 and given.shape[:2] == fs.shape[:2] and given.shape[2] <= fs.shape[2]:
                fs[:, :, :given.shape[2]] = given
                fs[..., L.FS_WORK] = 0.0  # (counted in eq.dissipated)
        sfs = contact[stepping.CT_SELF_FRICTION][k]
        if sfs.shape[0]:
            sfs[:] = start_self_samples(self.scenes[k], contact[stepping.CT_SEGS], eq)
        nodes = contact[stepping.CT_NODES][k]
        record = contact[stepping.CT_RECORDS][k]
        if eq.converged and eq.stable and eq.shooting_nodes.shape == nodes.shape:
            nodes[:] = eq.shooting_nodes
            p_level = contact[stepping.CT_P][k]
            p_level[:] = eq.channel_pressures
            rest = contact[stepping.CT_REST][k]
            layout = self.layout
            rest_strains_into(p_level, layout.tubes_i, layout.tubes_f, layout.secf, rest)
            level = self._level(k)
            factors = tuple(contact[i][k] for i in range(stepping.CT_LU, stepping.CT_FLAGS + 1))
            grid = tuple(contact[i] for i in range(stepping.CT_THETA0, stepping.CT_SELF + 1))
            blocks = np.empty((contact[stepping.CT_SEGS].shape[0], 6, 6))
            if contact_kernels.factor_state(nodes, grid, rest, level, contact[stepping.CT_WEIGHTS],
                                            np.empty_like(nodes), blocks, record, factors):
                contact[stepping.CT_OK][k] = True
                contact[stepping.CT_TOUCHING][k] = stepping.touches(record)
                if contact[stepping.CT_TOUCHING][k]:
                    return
        packed = self._problem.packed
        if eq.s.size == packed.n_rows:
            record_from_equilibrium(eq, packed, free[stepping.FR_RECORDS][k],
                                    free[stepping.FR_REST_A][k], free[stepping.FR_GRAD][k])
            free[stepping.FR_STATES][k, 0] = eq.base_moment[-1]
        elif contact[stepping.CT_OK][k]:
            stepping.free_record_of(record, float(eq.base_moment[-1]), eq.channel_pressures, free, k)
        else:
            return
        free[stepping.FR_OK][k] = True

    def copy_rows(self, src: int, dst) -> None:
        """Copies ``dst`` take copy ``src``'s scene and state."""
        for k in dst:
            self.scenes[k] = self.scenes[src]
        # One copy (a grasp's trial pose, at every contact solve): a plain row assignment,
        # several times faster than the fancy-indexed one over a list.
        dst = dst[0] if len(dst) == 1 else dst
        for array in self._per_copy:
            array[dst] = array[src]

    def turn(self, k: int, obstacle: int, angle: float) -> None:
        """Turn copy k's friction anchors on ``obstacle`` by ``angle`` (rad, counter-clockwise
        about its centre): the object they stick to turned (:mod:`solver.grasp`)."""
        fs = self.contact[stepping.CT_FRICTION][k]
        if fs.shape[0]:
            turn_anchors(fs, obstacle, angle)

    def backbones(self) -> np.ndarray:
        """(n, N, N_COLUMNS) every copy's record on the settings' grid, with the columns S …
        U of the copies on the contact layout copied in (the two grids must have the same
        rows)."""
        records = self.free[stepping.FR_RECORDS]
        crecords = self.contact[stepping.CT_RECORDS]
        if crecords.shape[1] != records.shape[1]:
            raise ValueError(f"the contact layout has {crecords.shape[1]} rows, the settings' grid "
                             f"{records.shape[1]}: backbones on one grid need a contact stiffness "
                             f"whose decay length the settings' steps resolve")
        out = records.copy()
        on = self.contact[stepping.CT_OK]
        out[on, :, L.S:L.U + 1] = crecords[on, :, L.S:L.U + 1]
        return out

    @property
    def free_records(self) -> np.ndarray:
        """(n, rows, N_COLUMNS) the copies' records on the settings' grid."""
        return self.free[stepping.FR_RECORDS]

    def pass_costs(self, k: int, repeats: int) -> dict:
        """What one pass over copy k's contact state costs: a residual pass and a pass with
        the Jacobian (seconds, the median of ``repeats``), the unknowns, the RK4 rows and the
        fraction of them refined near a disc (a profile's figures; the state is untouched)."""
        contact = self.contact
        if not contact[stepping.CT_OK][k]:
            raise ValueError(f"copy {k} is not on the contact layout")
        grid = tuple(contact[i] for i in range(stepping.CT_THETA0, stepping.CT_SELF + 1))
        nodes = contact[stepping.CT_NODES][k].copy()
        level = self._level(k)
        level = (*level[:L.L_FRICTION], *(fs.copy() for fs in level[L.L_FRICTION:]))  # (passes
        # record into them)
        rest = np.empty_like(contact[stepping.CT_REST][k])
        rest_strains_into(level[L.L_P], self.layout.tubes_i, self.layout.tubes_f, self.layout.secf,
                          rest)
        F = np.empty_like(nodes)
        J = np.empty((contact_kernels.BAND_ROWS, nodes.size))
        blocks = np.empty((contact[stepping.CT_SEGS].shape[0], 6, 6))
        partners = contact_kernels.new_partners(grid)
        seconds = {name: median_seconds(lambda jacobian=jacobian: contact_kernels.newton_system(
                       nodes, grid, rest, level, F, J, jacobian, blocks, partners), repeats)
                   for name, jacobian in (("residual_pass_s", False), ("jacobian_pass_s", True))}
        record = contact[stepping.CT_RECORDS][k]
        discs = level[L.L_DISCS]
        gap = np.min(np.hypot(record[:, L.C_X, None] - discs[None, :, L.CX],
                              record[:, L.C_Y, None] - discs[None, :, L.CY]) - discs[None, :, L.RADIUS],
                     axis=1)
        h = (self.layout.sec_len / self.layout.sec_steps)[np.minimum(
            np.searchsorted(np.asarray(self.layout.section_ends), np.arange(record.shape[0])),
            len(self.layout.sec_steps) - 1)]
        speed = np.hypot(record[:, L.C_V1], record[:, L.C_V3])
        return {**seconds, "unknowns": int(nodes.size), "rows": int(record.shape[0]),
                "refined_fraction": float(np.mean(gap - h * speed < h))}

    def _level(self, k: int) -> tuple:
        """Copy k's level tuple (``L_*``): its pressures, the loads, its discs and friction."""
        contact = self.contact
        return (contact[stepping.CT_P][k], contact[stepping.CT_Q], contact[stepping.CT_PLATE],
                contact[stepping.CT_TARGET], contact[stepping.CT_DISCS][k],
                contact[stepping.CT_MU][k], contact[stepping.CT_FRICTION][k],
                contact[stepping.CT_SELF_FRICTION][k])

    def contact_measures(self) -> np.ndarray:
        """(n, 2) every copy's deepest penetration (m) and total contact force (N)
        (:func:`solver.kernels.stepping.measure_contact`)."""
        out = np.zeros((self.n, 2))
        stepping.measure_contact(self.contact[stepping.CT_RECORDS], self.contact[stepping.CT_OK], out)
        return out

    def ready(self, k: int) -> bool:
        """Whether copy k has a state the lean paths can step from."""
        return bool(self.free[stepping.FR_OK][k] or self.contact[stepping.CT_OK][k])

    def touching(self, k: int) -> bool:
        """Whether copy k's state touches an obstacle (on the contact layout)."""
        return bool(self.contact[stepping.CT_TOUCHING][k])

    def full_factor_age(self, k: int) -> int:
        """How many accepted states copy k's full factored Jacobian (where parts of the arm
        touch each other) has served: 1 formed at this state, more where lean steps kept it
        (:data:`solver.kernels.contact.LEAN_REUSE_AGE`); 0 for band factors or a state off
        the contact layout."""
        return int(self.contact[stepping.CT_FLAGS][k][0]) if self.contact[stepping.CT_OK][k] else 0

    def on_contact_layout(self, k: int) -> bool:
        """Whether copy k's state lies on the contact layout."""
        return bool(self.contact[stepping.CT_OK][k])

    def record(self, k: int) -> np.ndarray:
        """Copy k's record: on the contact layout (rows, C_COLUMNS) or the settings' grid
        (rows, N_COLUMNS); columns S … U are the same either way (a view)."""
        if self.contact[stepping.CT_OK][k]:
            return self.contact[stepping.CT_RECORDS][k]
        return self.free[stepping.FR_RECORDS][k]

    def step(self, p_from: np.ndarray, p_to: np.ndarray, active: np.ndarray, run) -> np.ndarray:
        """Warm steps of the ``active`` copies from the channel pressures ``p_from`` to
        ``p_to`` (n, n_channels) by the lean paths; ``run`` calls the parallel or the serial
        kernel (a :meth:`ThreadPolicy.run`-like callable, or None: serial). A ready copy whose
        ``p_to`` equals its ``p_from`` is held: a quasi-static state nothing moves stands, so no
        kernel runs for it and its row reports it converged as it was, path :data:`PATH_HELD`
        (a scripted curl holding p_max, or a delta policy pushing against a bound on every
        channel, would otherwise pay a full contact step that returns the same state).

        Returns:
            (n, 7) report rows (converged, stable, snapped, iterations, residual, path code
            of :data:`PATHS`, the lean contact step's refusal bits, :data:`REFUSALS`); an
            unconverged row kept its state (the general path's turn).
        """
        if self.n == 1 and run is None and active[0]:
            return self.step_one(p_from[0], p_to[0])[None]
        report = np.zeros((self.n, 7))
        free, contact = self.free, self.contact
        active = hold_rows(free[stepping.FR_OK] | contact[stepping.CT_OK], p_from, p_to, active,
                           self._flags, report)
        if not active.any():
            return report
        args = (self.free, self.contact, p_from, p_to, active, report, stepping.ROW_STEP,
                contact[stepping.CT_DISCS][0])  # (the discs_to a ROW_STEP does not use)
        if run is None:
            stepping.contact_rows(*args)
        else:
            run(self._threaded_rows, stepping.contact_rows, int(active.sum()), *args)
        # (the converged rows that moved: a held one keeps the flags of the solve that reached it)
        np.copyto(self._flags, report[:, :5], where=(report[:, :1] != 0.0) & (report[:, 5:6] != PATH_HELD))
        return report

    def step_one(self, p_from: np.ndarray, p_to: np.ndarray) -> np.ndarray:
        """:meth:`step` of a batch of one (a single :class:`solver.Stepper`'s every step) from
        the channel pressures ``p_from`` to ``p_to`` (n_channels,): its report row (7,).

        The same kernels in the same order as :meth:`step`, so the same numbers, with the
        tests on scalars: for one copy the batch form's array operations cost as much as the
        contact-free kernel itself (docs/design.md §10.1, "A self-contact reach step's
        bookkeeping"). A copy touching nothing steps by the contact-free kernel alone, which
        unboxes only the settings' grid; where that would touch, by the contact row."""
        report = np.zeros((1, 7))
        free, contact = self.free, self.contact
        p_from, p_to = p_from[None], p_to[None]
        if not hold_rows(free[stepping.FR_OK] | contact[stepping.CT_OK], p_from, p_to, ONE_COPY,
                         self._flags, report)[0]:
            return report[0]
        discs = contact[stepping.CT_DISCS]
        if free[stepping.FR_OK][0] and not (contact[stepping.CT_OK][0] and contact[stepping.CT_TOUCHING][0]):
            if not stepping.free_row(free, discs, contact[stepping.CT_OK], p_from, p_to, report):
                stepping.contact_rows(free, contact, p_from, p_to, ONE_COPY, report, stepping.ROW_ENTER,
                                      discs[0])
        else:
            stepping.contact_rows(free, contact, p_from, p_to, ONE_COPY, report, stepping.ROW_STEP,
                                  discs[0])
        if report[0, 0]:
            self._flags[0] = report[0, :5]
        return report[0]

    def _threaded_rows(self, free, contact, p_from, p_to, active, report, kind, discs_to) -> None:
        """:func:`solver.kernels.stepping.contact_rows` over the ``active`` copies on the
        pool's threads, BLOCKS_PER_THREAD blocks of them a thread: each row is its own copy's
        work, so the numbers are the one-thread call's."""
        rows = np.flatnonzero(active)
        blocks = np.array_split(rows, min(rows.size, BLOCKS_PER_THREAD * numba.get_num_threads()))

        def step_block(block):
            mask = np.zeros_like(active)
            mask[block] = True
            stepping.contact_rows(free, contact, p_from, p_to, mask, report, kind, discs_to)

        self._pool.map(step_block, blocks)

    def step_moved(self, k: int, p_channel: np.ndarray, scene: Scene) -> np.ndarray:
        """The lean contact step of copy k (a state on the contact layout) to the channel
        pressures ``p_channel`` with its discs moved to those of ``scene`` (the same count
        and law): an object the arm holds, moved quasi-statically. Returns the report row
        (as :meth:`step`'s); on success the copy's scene is ``scene``."""
        report = np.zeros((self.n, 7))
        discs = np.full((self.max_obstacles, 4), (FAR, FAR, 0.0, 0.0))
        given = scene.discs_array()
        discs[:given.shape[0]] = given
        p_to = np.zeros_like(self.contact[stepping.CT_P])
        p_to[k] = p_channel
        row = np.zeros(self.n, dtype=bool)
        row[k] = True
        stepping.contact_rows(self.free, self.contact, p_to, p_to, row, report, stepping.ROW_MOVED, discs)
        if report[k, 0]:
            self.scenes[k] = scene
            self._flags[k] = report[k, :5]
        return report[k]

    def equilibrium(self, k: int, pressures: np.ndarray, channel_pressures: np.ndarray) -> Equilibrium:
        """Copy k's state as the Equilibrium the general path returns for it (arrays copied)."""
        converged, stable, snapped, iterations, residual = self._flags[k]
        flags = dict(converged=bool(converged), stable=bool(stable), snapped=bool(snapped),
                     iterations=int(iterations), residual=float(residual))
        problem = self._problem.in_scene(self.scenes[k]).with_inputs(
            np.array(pressures, dtype=float), np.array(channel_pressures, dtype=float))
        # The samples' work stays in them while the copy steps clear of contact (and when it
        # comes back): the dissipation along its path is always the two together.
        fs = self.contact[stepping.CT_FRICTION][k]
        sfs = self.contact[stepping.CT_SELF_FRICTION][k]
        dissipated = float(self._dissipated[k] + fs[..., L.FS_WORK].sum()
                           + sfs[..., L.FS_WORK].sum())
        if self.contact[stepping.CT_OK][k]:
            friction = dict(dissipated=dissipated)
            if fs.shape[0]:
                friction["friction_samples"] = fs[:, :, :len(self.scenes[k].obstacles)].copy()
            if sfs.shape[0]:
                friction["self_friction_samples"] = sfs.copy()
            return shooting_equilibrium(self.contact[stepping.CT_RECORDS][k],
                                        self.contact[stepping.CT_NODES][k].copy(),
                                        self.scenes[k], self.layout, model=problem.model,
                                        pressures=problem.p_inputs,
                                        channel_pressures=problem.p_channel, arm=problem.arm,
                                        **friction, **flags)
        eq = single_result(problem, self.free[stepping.FR_RECORDS][k].copy(),
                           self.free[stepping.FR_STATES][k, 0], **flags)
        return free_contact_result(eq, self.scenes[k], dissipated)
