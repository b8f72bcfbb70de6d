"""A lean quasi-static stepper: one arm in one scene, validated once, stepped many times.

:func:`solver.solve` is the friendly API: every call validates its inputs, looks up the
packed design and the scene, and builds an :class:`~solver.results.Equilibrium`. An
environment calls it thousands of times a second with the same arm and scene, so a
:class:`Stepper` does all of that once and keeps, between steps, what a warm step needs:
the current equilibrium's backbone, base moment and rest strains, the actuator's λ(p) per
tube (solved again only for channels whose pressure changed) and the base moment's gradient
with respect to the rest strains, which predicts the next equilibrium to first order
(:func:`solver.kernels.planar.warm_step`).

Planar scenes without obstacles, solved by single shooting, take this lean path; any other
scene (spatial, contact, constant curvature, unloaded, arms that need multiple shooting) is
stepped by the same paths as :func:`solver.solve`, through the same interface. Either way a
step gives the equilibrium ``solve(arm, p, scene, warm_start=previous)`` would give, to the
solver's tolerance.
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import numba
import numpy as np

from solver import layout as L
from solver.designs import ArmDesign
from solver.inputs import (
    channels_of,
    check_request,
    check_warm_start,
    checked_pressures,
    explain_bad_pressures,
)
from solver.kernels import planar as planar_kernels
from solver.paths.dispatch import dispatch
from solver.paths.planar import loaded_base_moment, not_lean, single_result
from solver.problem import Problem, pack
from solver.results import Equilibrium
from solver.rod import forget_first_variations, planar_rest_gradient, rest_strains_into
from solver.scene import Scene
from solver.settings import DEFAULT_SETTINGS, Settings

__all__ = ["Stepper", "StepReport", "BatchStepper", "BatchReport", "ThreadPolicy"]


class StepReport(NamedTuple):
    """What became of a step (or reset): the attempted solve's flags and figures.

    Attributes:
        converged: the step reached the new pressures (otherwise the arm kept its previous
            equilibrium).
        stable, snapped, iterations, residual: as the fields of
            :class:`~solver.results.Equilibrium`, for the attempted solve.
    """

    converged: bool
    stable: bool
    snapped: bool
    iterations: int
    residual: float


def _record_equilibrium(record, flags, m0, pressures, channel_pressures,
                        problem: Problem) -> Equilibrium:
    """The planar :class:`Equilibrium` of a lean-path backbone record (arrays copied), at
    ``pressures`` in the arm, scene and grid of ``problem``."""
    converged, stable, snapped, iterations, residual = flags
    at = problem.with_inputs(np.array(pressures, dtype=float),
                             np.array(channel_pressures, dtype=float))
    return single_result(at, record.copy(), m0,
                         converged=bool(converged), stable=bool(stable), iterations=int(iterations),
                         residual=float(residual), snapped=bool(snapped))


def _write_record(eq: Equilibrium, packed, rec, rest, grad) -> None:
    """Write a recorded planar equilibrium into a lean-path record (N, N_COLUMNS), with its
    rest strains ``rest`` (3, ns) and the predictor's gradient ``grad`` (2, ns)."""
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


class Stepper:
    """Quasi-static steps of one arm in one scene.

    Example::

        stepper = solver.Stepper(solver.designs.octarm_v(), solver.Scene(payload_kg=0.1))
        stepper.reset(np.zeros(6))                 # the cold equilibrium at these pressures
        report = stepper.step(p)                   # warm step to new pressures (Pa)
        if not report.converged: ...               # the arm kept its previous equilibrium
        stepper.tip, stepper.equilibrium           # the current state

    Args:
        arm: the design. scene: mounting, loads and obstacles (default :class:`Scene`).
        model, planar, settings: as in :func:`solver.solve`.

    Attributes:
        tip: (2|3,) tip position of the current equilibrium (m); read-only view.
        pressures: (n_inputs,) its input pressures (Pa), ``channel_pressures`` per channel.
        record: planar lean path: (N, ``layout.N_COLUMNS``) its backbone record (columns
            ``layout.S`` … ``layout.U``; read-only, replaced at every converged step), else
            None.
        section_ends: the record's rows at the section ends.
        lean: whether steps take the lean planar path.
    """

    def __init__(self, arm: ArmDesign, scene: Scene | None = None, *, model: str = "full",
                 planar: bool = True, settings: Settings = DEFAULT_SETTINGS):
        scene = Scene() if scene is None else scene
        check_request(arm, scene, model, planar, settings)
        self.arm, self.scene, self.model, self.planar, self.settings = arm, scene, model, planar, settings
        self.n_inputs = arm.n_inputs(planar)
        self._packed = packed = pack(arm, model, settings)
        # The request at rest: each step's is this one at its pressures (the same context).
        self._problem = problem = Problem(arm, packed, scene, model, planar, settings,
                                          np.zeros(self.n_inputs), np.zeros(arm.n_channels))
        ctx = problem.ctx
        self.lean = not_lean(problem) is None
        self.section_ends = packed.section_ends
        self._p_max = arm.max_pressure * (1 + 1e-12)
        self._eq = None
        self.record = None
        self.tip = np.zeros(2 if planar else 3)
        self.tip.flags.writeable = False
        self.pressures = np.zeros(self.n_inputs)
        self.channel_pressures = np.zeros(arm.n_channels)
        if not self.lean:
            return
        ns = len(arm.sections)
        n_tubes = packed.tubes_i.shape[0]
        self._ctx = ctx
        self._index = packed.spatial_of_planar
        self._grid = (scene.base_theta, packed.secf, packed.sec_steps)
        self._tubes = (packed.tubes_i, packed.tubes_f)
        self._state = np.zeros(4)  # m0, tip x, y, θ
        self._buffers = [np.empty((packed.n_rows, L.N_COLUMNS)) for _ in range(2)]
        self._works = [(np.empty((3, ns)), np.empty(arm.n_channels), np.empty((ns, 4)), buf, True)
                       for buf in self._buffers]
        self._spare = 0
        self._memo = (np.full(n_tubes, np.nan), np.empty(n_tubes), np.empty((3, ns)),
                      np.full((2, ns), np.nan))
        self._p_new = np.empty(arm.n_channels)
        self._target = (self._p_new, ctx.loads, ctx.m_tip)  # the kernel's goal levels
        self._bind_tips()
        self._flags = (True, True, False, 0, 0.0)  # of the current equilibrium

    # ------------------------------------------------------------------ state

    @property
    def equilibrium(self) -> Equilibrium:
        """The current equilibrium (built on first access after a step; its arrays are
        copies, unaffected by later steps)."""
        if self._eq is None and self.record is not None:
            self._eq = _record_equilibrium(self.record, self._flags, self._state[0], self.pressures,
                                           self.channel_pressures, self._problem)
        if self._eq is None:
            raise RuntimeError("call reset() before reading the stepper's equilibrium")
        return self._eq

    # ------------------------------------------------------------------ stepping

    def reset(self, pressures, warm_start: Equilibrium | None = None) -> StepReport:
        """Solve for the equilibrium at ``pressures`` (Pa, the ``arm.input_names(planar)``
        order) and make it the current state: cold (the quasi-static path from the loaded,
        unactuated arm), or along the path from ``warm_start`` (an equilibrium of the same
        arm, model and mode, in this or another scene). The state is adopted even if the
        solve did not converge (the report says so)."""
        p_inputs, p_channel = checked_pressures(self.arm, pressures, self.planar, self._packed)
        if warm_start is not None:
            check_warm_start(warm_start, self.arm, self.scene, self.model, self.planar)
        eq = dispatch(self._problem.with_inputs(p_inputs, p_channel, warm_start), True)
        self._adopt(eq)
        return StepReport(eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)

    def step(self, pressures) -> StepReport:
        """Move the arm quasi-statically from the current equilibrium to ``pressures`` (Pa).

        A step that does not converge leaves the current equilibrium as it was.

        Raises:
            ValueError: wrong count, non-finite, negative or over-rated pressures.
            RuntimeError: before :meth:`reset`.
        """
        if self._eq is None and self.record is None:
            raise RuntimeError("call reset() before step()")
        if not self.lean:
            return self._step_general(pressures)
        p = np.asarray(pressures, dtype=float)
        if p.shape != (self.n_inputs,) or not channels_of(p, self._index, self._p_max, self._p_new):
            checked_pressures(self.arm, pressures, True, self._packed)  # raises, naming the fault
            explain_bad_pressures(self.arm, p, True)
        ctx = self._ctx
        work = self._works[self._spare]
        m_start = self._state[0]
        ok, stable, snapped, its, res, _, _ = planar_kernels.warm_step(
            self._state, self._grid, self._tubes, (self.channel_pressures, ctx.loads, ctx.m_tip),
            self._target, ctx.params, work, self._memo)
        if not ok:
            # The lean path failed (rare: see softarm stress); the general one has fallbacks
            # (multiple shooting) the single-shooting kernel does not.
            self._state[0] = m_start
            report = self._step_general(p)
            return report._replace(iterations=report.iterations + int(its))
        self.record = work[3]
        self._spare ^= 1
        self.pressures = p.copy()
        self.channel_pressures = self._p_new.copy()
        self.tip = self._tips[self._spare ^ 1]
        self._flags = report = StepReport(True, stable, snapped, its, res)
        self._eq = None
        return report

    def _step_general(self, pressures) -> StepReport:
        p_inputs, p_channel = checked_pressures(self.arm, pressures, self.planar, self._packed)
        eq = dispatch(self._problem.with_inputs(p_inputs, p_channel, self.equilibrium), True)
        report = StepReport(eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        if eq.converged:
            self._adopt(eq)
        return report

    def adopt(self, eq: Equilibrium) -> None:
        """Make ``eq``, an equilibrium of this arm, model and mode solved in this scene (with
        ``record=True``), the current state."""
        if not isinstance(eq, Equilibrium):
            raise ValueError("adopt() takes an Equilibrium returned by solve()")
        check_warm_start(eq, self.arm, self.scene, self.model, self.planar)
        if eq.scene != self.scene:
            raise ValueError(f"the equilibrium was solved in {eq.scene}, not in this stepper's "
                             f"scene {self.scene}")
        if not eq.s.size:
            raise ValueError("the equilibrium was solved with record=False; adopt needs its backbone")
        self._adopt(eq)

    def _adopt(self, eq: Equilibrium) -> None:
        """Make ``eq`` the current state (and, on the lean path, its record and predictor)."""
        self._eq = eq
        self.pressures = eq.pressures.copy()
        self.channel_pressures = eq.channel_pressures.copy()
        self.tip = eq.tip.copy()
        self.tip.flags.writeable = False
        if not self.lean:
            return
        rec = self._buffers[self._spare]
        _write_record(eq, self._packed, rec, self._memo[2], self._memo[3])
        self.record = rec
        self._spare ^= 1
        self._state[0] = eq.base_moment[-1]
        self._flags = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)

    def _bind_tips(self) -> None:
        """Read-only tip views into the two record buffers (a pickle copies views apart:
        unpickling binds them again)."""
        self._tips = [buf[-1, L.X:L.Y + 1] for buf in self._buffers]
        for tip in self._tips:
            tip.flags.writeable = False

    def __setstate__(self, state):
        self.__dict__.update(state)
        if self.lean:
            self._target = (self._p_new, self._ctx.loads, self._ctx.m_tip)
            self._bind_tips()
            if self.record is not None:
                self.tip = self._tips[next(k for k, b in enumerate(self._buffers) if b is self.record)]

    def with_scene(self, scene: Scene) -> Stepper:
        """A stepper of the same arm, model, mode and settings in another scene."""
        return Stepper(self.arm, scene, model=self.model, planar=self.planar, settings=self.settings)

    def __repr__(self) -> str:
        return (f"Stepper({self.arm.name!r}, {self.scene}, model={self.model!r}, "
                f"planar={self.planar}, lean={self.lean})")


class ThreadPolicy:
    """Whether a batch of ``rows`` copies runs on numba's threads or on one thread.

    Threads pay off only when the machine has idle cores: on a shared machine a parallel
    region waits at its barrier for a thread the OS has descheduled, and a batch can take
    ten times longer on two threads than on one. So the choice is measured, not assumed:
    the first batches run once each way (the very first run of each only loads its kernel
    and is not counted), then the faster per-row time wins, and the other way is tried
    again after ``interval`` batches — an interval that doubles (up to ``MAX_INTERVAL``)
    each time the other way loses again, so a losing probe costs little, and resets when
    it wins. Batches below ``min_rows`` and single-thread configurations run serially.

    Args:
        min_rows: the smallest batch that may run threaded.

    Attributes:
        per_row_s: [serial, threaded] smoothed seconds per row (NaN: not measured yet).
    """

    START_INTERVAL = 16
    MAX_INTERVAL = 1024
    SMOOTHING = 0.3

    def __init__(self, min_rows: int):
        self.min_rows = min_rows
        self.per_row_s = [math.nan, math.nan]
        self._seen = [False, False]
        self._interval = self.START_INTERVAL
        self._countdown = self.START_INTERVAL
        self._probing = False

    def choose(self, rows: int) -> bool:
        """True: run this batch of ``rows`` copies on the threads."""
        if rows < self.min_rows or numba.get_num_threads() < 2:
            return False
        serial, threaded = self.per_row_s
        if math.isnan(serial) or math.isnan(threaded):
            self._probing = False
            return math.isnan(threaded) and not math.isnan(serial)
        best = threaded < serial
        self._countdown -= 1
        self._probing = self._countdown <= 0
        return best != self._probing

    def run(self, parallel, serial, rows: int, *args):
        """``parallel(*args)`` or ``serial(*args)`` (two ways of one job over ``rows``
        copies, with the same result), as :meth:`choose` decides, timed for :meth:`record`.
        Returns what the chosen one returns."""
        threaded = self.choose(rows)
        start = time.perf_counter()
        out = (parallel if threaded else serial)(*args)
        self.record(threaded, rows, time.perf_counter() - start)
        return out

    def record(self, threaded: bool, rows: int, seconds: float) -> None:
        """The batch ``choose`` allowed ran ``seconds`` on ``rows`` copies."""
        if rows < self.min_rows or not rows:
            return
        k = int(threaded)
        if not self._seen[k]:  # the first run loads the kernel: not a measurement
            self._seen[k] = True
            return
        per_row = seconds / rows
        old = self.per_row_s[k]
        # A probe's estimate is stale (the machine's load may have changed since): replaced.
        fresh = self._probing or math.isnan(old)
        self.per_row_s[k] = per_row if fresh else old + self.SMOOTHING * (per_row - old)
        if self._probing:
            serial, par = self.per_row_s
            won = (par < serial) == threaded
            self._interval = self.START_INTERVAL if won else min(2 * self._interval, self.MAX_INTERVAL)
            self._countdown = self._interval
            self._probing = False


class BatchReport(NamedTuple):
    """What became of a batch of steps (or resets), one entry per copy: the fields of
    :class:`StepReport` as (n,) arrays."""

    converged: np.ndarray
    stable: np.ndarray
    snapped: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray


class BatchStepper:
    """Quasi-static steps of n copies of one arm in one scene, in parallel.

    Each copy is stepped by the kernel of a lean :class:`Stepper` (and, where that fails, by
    the same fallback), so copy k gives, bit for bit, the equilibria a :class:`Stepper` fed
    copy k's pressures gives: a batched environment and n single ones agree exactly. Only
    scenes a stepper steps lean are accepted (planar, channels, no obstacles, loaded, single
    shooting); the constructor says which condition fails otherwise.

    Example::

        batch = solver.BatchStepper(solver.designs.octarm_v(), solver.Scene(), n=1024)
        batch.reset(np.zeros((1024, 6)))       # cold equilibria
        report = batch.step(p)                  # (1024, 6) Pa; report.converged (1024,)
        batch.tips, batch.records               # (1024, 2) m, (1024, N, layout.N_COLUMNS)

    Args:
        arm, scene, model, settings: as :class:`Stepper` (planar only).
        n: number of copies.

    Attributes:
        records: (n, N, ``layout.N_COLUMNS``) every copy's backbone record (read-only).
        tips: (n, 2) tip positions (m), a view of ``records``.
        pressures: (n, n_inputs) input pressures (Pa); ``channel_pressures`` (n, n_channels).
        section_ends: the records' rows at the section ends.
    """

    PARALLEL_MIN = 64
    """Batches smaller than this run on one thread: sharing them never paid on the 2-core
    machine (``softarm bench --env``: 16 arms, 21k env-steps/s on one thread, 10k with the
    policy's threaded probes counted; 256 arms, 56k threaded against 37k), and a threaded
    probe costs more than such a batch's whole step. Larger ones run on the threads or on
    one, whichever :class:`ThreadPolicy` has measured faster."""

    def __init__(self, arm: ArmDesign, scene: Scene | None = None, n: int = 1, *,
                 model: str = "full", settings: Settings = DEFAULT_SETTINGS):
        scene = Scene() if scene is None else scene
        check_request(arm, scene, model, True, settings)
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be an integer >= 1; got {n!r}")
        self.arm, self.scene, self.model, self.settings, self.n = arm, scene, model, settings, int(n)
        self._packed = packed = pack(arm, model, settings)
        n_inputs = arm.n_inputs(True)
        self._problem = problem = Problem(arm, packed, scene, model, True, settings,
                                          np.zeros(n_inputs), np.zeros(arm.n_channels))
        self._ctx = problem.ctx
        reason = not_lean(problem)
        if reason is not None:
            raise ValueError(f"BatchStepper steps the lean planar path only, not {reason}; use "
                             "a Stepper (or solve()) per copy")
        self._loaded = loaded_base_moment(problem)  # as solve_single's stage 1
        ns, nc, n_tubes = len(arm.sections), arm.n_channels, packed.tubes_i.shape[0]
        self.n_inputs = n_inputs
        self.section_ends = packed.section_ends
        self._index = packed.spatial_of_planar
        self._p_max = arm.max_pressure * (1 + 1e-12)
        self._grid = (scene.base_theta, packed.secf, packed.sec_steps)
        self._tubes = (packed.tubes_i, packed.tubes_f)
        self._p_zero = np.zeros(nc)
        n = self.n
        self.records = np.zeros((n, packed.n_rows, L.N_COLUMNS))
        self.tips = self.records[:, -1, L.X:L.Y + 1]  # a view (rebound on unpickling)
        self.pressures = np.zeros((n, n_inputs))
        self.channel_pressures = np.zeros((n, nc))
        self._states = np.zeros((n, 4))
        self._flags = np.zeros((n, 5))
        self._work = (np.empty((n, 3, ns)), np.empty((n, nc)), np.empty((n, ns, 4)),
                      np.empty((n, packed.n_rows, L.N_COLUMNS)))
        self._memo = (np.full((n, n_tubes), np.nan), np.empty((n, n_tubes)), np.empty((n, 3, ns)),
                      np.full((n, 2, ns), np.nan))
        self._ready = np.zeros(n, dtype=bool)
        # Cold solves and warm steps cost very different times per row: one policy each.
        self.thread_policies = {"cold": ThreadPolicy(self.PARALLEL_MIN),
                                "step": ThreadPolicy(self.PARALLEL_MIN)}

    # ------------------------------------------------------------------ inputs

    def _inputs(self, pressures, rows: int | None) -> tuple[np.ndarray, np.ndarray]:
        """Validated (input pressures (rows, n_inputs), channel pressures (rows, n_channels));
        ``rows`` None: any number of rows."""
        p = np.asarray(pressures, dtype=float)
        if p.ndim != 2 or p.shape[1] != self.n_inputs or (rows is not None and p.shape[0] != rows):
            raise ValueError(f"pressures must have shape ({'m' if rows is None else rows}, "
                             f"{self.n_inputs}) for channels "
                             f"{', '.join(self.arm.input_names(True))}; got {p.shape}")
        bad = ~np.all((p >= 0) & (p <= self._p_max), axis=1)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            try:
                explain_bad_pressures(self.arm, p[k], True)
            except ValueError as exc:
                raise ValueError(f"row {k}: {exc}") from None
        return p, np.ascontiguousarray(p[:, self._index])

    def _report(self, report: np.ndarray) -> BatchReport:
        return BatchReport(report[:, 0] != 0, report[:, 1] != 0, report[:, 2] != 0,
                           report[:, 3].astype(np.int64), report[:, 4].copy())

    # ------------------------------------------------------------------ cold solves

    def _cold(self, p_channel, states, records, record, rest_a, grad) -> np.ndarray:
        m = p_channel.shape[0]
        states[:, 0] = self._loaded.m0
        report = np.zeros((m, 5))
        work = tuple(w[:m] if w.shape[0] >= m else np.empty((m, *w.shape[1:])) for w in self._work[:3])
        self.thread_policies["cold"].run(
            planar_kernels.cold_rows_parallel, planar_kernels.cold_rows_serial, m, self._grid, self._tubes,
            self._p_zero, p_channel, self._ctx.loads, self._ctx.m_tip, self._ctx.params, work,
            states, records, record, rest_a, grad, report)
        # As solve_single: the loaded stage's iterations count, and a snap there is a snap; a
        # loaded state beyond the grid leaves every row to the general path (which refines).
        report[:, 3] += self._loaded.iterations
        report[:, 2] = np.maximum(report[:, 2], float(self._loaded.snapped))
        if not self._loaded.resolved:
            report[:, 0] = 0.0
        return report

    def _solve_row(self, p_inputs, p_channel, warm_start, record) -> Equilibrium:
        return dispatch(self._problem.with_inputs(p_inputs, p_channel, warm_start), record)

    def solve_tips(self, pressures) -> tuple[np.ndarray, BatchReport]:
        """Tips of cold equilibria at ``pressures`` (m, n_inputs) Pa, in parallel: the tips
        ``solve(arm, p, scene, record=False)`` gives, row by row, bit for bit. The copies'
        states are untouched.

        Returns:
            (tips (m, 2) m, :class:`BatchReport`).
        """
        p, channel = self._inputs(pressures, None)
        m = p.shape[0]
        states = np.zeros((m, 4))
        report = self._cold(channel, states, np.empty((m, 1, L.N_COLUMNS)), False,
                            np.empty((m, 3, 0)), np.empty((m, 2, 0)))
        tips = states[:, 1:3].copy()
        for k in np.flatnonzero((report[:, 0] == 0) | (report[:, 1] == 0)):
            # solve() tries its other method (multiple shooting) on these: so do we.
            eq = self._solve_row(p[k], channel[k], None, False)
            tips[k] = eq.tip
            report[k] = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        return tips, self._report(report)

    def reset(self, pressures, rows=None) -> BatchReport:
        """Cold equilibria at ``pressures`` (len(rows), n_inputs) Pa become the current
        states of ``rows`` (default: every copy), as :meth:`Stepper.reset` does for each: a
        state is adopted even if its solve did not converge (the report says so)."""
        rows = np.arange(self.n) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
        if rows.size and (rows.min() < 0 or rows.max() >= self.n):
            raise ValueError(f"rows must index the {self.n} copies; got {rows.tolist()}")
        p, channel = self._inputs(pressures, rows.size)
        states = np.zeros((rows.size, 4))
        records = np.empty((rows.size, *self.records.shape[1:]))
        rest_a = self._memo[2][rows]
        grad = self._memo[3][rows]
        report = self._cold(channel, states, records, True, rest_a, grad)
        for j in np.flatnonzero((report[:, 0] == 0) | (report[:, 1] == 0)):
            eq = self._solve_row(p[j], channel[j], None, True)
            _write_record(eq, self._packed, records[j], rest_a[j], grad[j])
            states[j, 0] = eq.base_moment[-1]
            report[j] = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        self.records[rows] = records
        self._states[rows] = states
        self._memo[2][rows] = rest_a
        self._memo[3][rows] = grad
        self.pressures[rows] = p
        self.channel_pressures[rows] = channel
        self._flags[rows] = report
        self._ready[rows] = True
        return self._report(report)

    def adopt(self, eq: Equilibrium, rows=None) -> None:
        """Make ``eq`` (an equilibrium of this arm and model solved in this scene with
        ``record=True``) the current state of ``rows`` (default: every copy) — e.g. to roll
        candidate steps out from one state."""
        if not isinstance(eq, Equilibrium):
            raise ValueError("adopt() takes an Equilibrium returned by solve()")
        check_warm_start(eq, self.arm, self.scene, self.model, True)
        if eq.scene != self.scene:
            raise ValueError(f"the equilibrium was solved in {eq.scene}, not in {self.scene}")
        if not eq.s.size:
            raise ValueError("the equilibrium was solved with record=False; adopt needs its backbone")
        rows = np.arange(self.n) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
        first = int(rows[0])
        _write_record(eq, self._packed, self.records[first], self._memo[2][first], self._memo[3][first])
        self.records[rows] = self.records[first]
        self.pressures[rows] = eq.pressures
        self.channel_pressures[rows] = eq.channel_pressures
        self._memo[2][rows] = self._memo[2][first]
        self._memo[3][rows] = self._memo[3][first]
        self._states[rows, 0] = eq.base_moment[-1]
        self._flags[rows] = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        self._ready[rows] = True

    # ------------------------------------------------------------------ warm steps

    def step(self, pressures, active=None) -> BatchReport:
        """Move every copy quasi-statically to its row of ``pressures`` (n, n_inputs) Pa. A
        copy whose step does not converge keeps its equilibrium.

        ``active`` (n,) bool, optional: step only these copies; the others keep their state
        (their rows of ``pressures`` are ignored, their report entries say converged with no
        iterations).

        Raises:
            ValueError: wrong shape, non-finite, negative or over-rated pressures (naming the
                row and channel).
            RuntimeError: a copy that was never reset.
        """
        if not self._ready.all():
            raise RuntimeError(f"reset copies {np.flatnonzero(~self._ready).tolist()[:10]} before step()")
        if active is None:
            active = np.ones(self.n, dtype=bool)
        active = np.asarray(active)
        if active.shape != (self.n,) or active.dtype != bool:
            raise ValueError(f"active must be a ({self.n},) bool array; got {active.dtype} {active.shape}")
        p = np.asarray(pressures, dtype=float)
        if p.shape == (self.n, self.n_inputs) and not active.all():
            p = np.where(active[:, None], p, self.pressures)  # idle rows: no check, no step
        p, channel = self._inputs(p, self.n)
        report = np.zeros((self.n, 5))
        report[~active, :2] = 1.0
        self.thread_policies["step"].run(
            planar_kernels.step_rows_parallel, planar_kernels.step_rows_serial, int(active.sum()), self._grid,
            self._tubes, self.channel_pressures, channel, self._ctx.loads, self._ctx.m_tip,
            self._ctx.params, self._work, self._states, self.records, self._memo, active, report)
        ok = report[:, 0] != 0
        for k in np.flatnonzero(~ok):
            # As Stepper.step: the general path (with its fallbacks) from the kept equilibrium.
            eq = self._solve_row(p[k], channel[k], self.equilibrium(k), True)
            report[k] = (eq.converged, eq.stable, eq.snapped, eq.iterations + report[k, 3],
                         eq.residual)
            if eq.converged:
                _write_record(eq, self._packed, self.records[k], self._memo[2][k], self._memo[3][k])
                self._states[k, 0] = eq.base_moment[-1]
                ok[k] = True
        moved = ok & active
        self.pressures[moved] = p[moved]
        self.channel_pressures[moved] = channel[moved]
        self._flags[moved] = report[moved]
        return self._report(report)

    def equilibrium(self, k: int) -> Equilibrium:
        """Copy k's current equilibrium (arrays copied)."""
        if not 0 <= k < self.n:
            raise ValueError(f"copy {k} does not exist; n = {self.n}")
        if not self._ready[k]:
            raise RuntimeError(f"copy {k} was never reset")
        return _record_equilibrium(self.records[k], self._flags[k], self._states[k, 0],
                                   self.pressures[k], self.channel_pressures[k], self._problem)

    def __setstate__(self, state):
        self.__dict__.update(state)
        self.tips = self.records[:, -1, L.X:L.Y + 1]

    def __repr__(self) -> str:
        return f"BatchStepper({self.arm.name!r}, {self.scene}, n={self.n}, model={self.model!r})"
