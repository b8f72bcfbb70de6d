"""n copies of one arm stepped in 3D: :class:`SpatialBatchStepper`."""

from __future__ import annotations

import numpy as np

from solver.designs import ArmDesign
from solver.results import Equilibrium
from solver.scene import Scene
from solver.settings import DEFAULT_SETTINGS, Settings
from solver.solve import solve
from solver.stepper import BatchReport, Stepper, StepReport, ThreadPolicy
from solver.threads import CopyPool

__all__ = ["SpatialBatchStepper"]


class SpatialBatchStepper:
    """Quasi-static steps of n copies of one arm in one scene in 3D (``planar=False``), with
    the interface of :class:`solver.BatchStepper`.

    The spatial solve has no lean kernel: each copy is a :class:`Stepper` of its own, so
    copy k gives, bit for bit, what a :class:`Stepper` fed copy k's pressures gives. Copies
    run on a thread pool of ``numba.get_num_threads()`` workers where :class:`ThreadPolicy`
    has measured that it pays (the kernels release the GIL; the Python around them does
    not), else one after another.

    Args:
        arm, scene, model, settings: as :class:`Stepper`.
        n: number of copies.

    Attributes:
        tips: (n, 3) tip positions (m). pressures: (n, n_inputs) input pressures (Pa).
        section_ends: sample indices of the section ends.
    """

    PARALLEL_MIN = 4
    """Batches smaller than this run on one thread."""

    def __init__(self, arm: ArmDesign, scene: Scene | None = None, n: int = 1, *,
                 model: str = "full", settings: Settings = DEFAULT_SETTINGS):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be an integer >= 1; got {n!r}")
        first = Stepper(arm, scene, model=model, planar=False, settings=settings)
        self.arm, self.scene, self.model, self.settings = arm, first.scene, model, settings
        self.n = int(n)
        self.n_inputs = first.n_inputs
        self._steppers = [first] + [Stepper(arm, scene, model=model, planar=False, settings=settings)
                                    for _ in range(self.n - 1)]
        self.tips = np.zeros((self.n, 3))
        self.pressures = np.zeros((self.n, self.n_inputs))
        self.section_ends = ()
        self.thread_policies = {"cold": ThreadPolicy(self.PARALLEL_MIN),
                                "step": ThreadPolicy(self.PARALLEL_MIN)}
        self._pool = CopyPool()

    def _map(self, kind: str, job, rows) -> list:
        """``job(i)`` for every i of ``rows``, on the pool or serially as the ``kind``
        policy decides (the results do not depend on it)."""
        rows = list(rows)
        return self.thread_policies[kind].run(self._pooled, self._serial, len(rows), job, rows)

    def _pooled(self, job, rows) -> list:
        return self._pool.map(job, rows)

    @staticmethod
    def _serial(job, rows) -> list:
        return [job(i) for i in rows]

    def _inputs(self, pressures, rows: int | None) -> np.ndarray:
        p = np.asarray(pressures, dtype=float)
        if p.ndim != 2 or p.shape[1] != self.n_inputs or (rows is not None and p.shape[0] != rows):
            raise ValueError(f"pressures must have shape ({'m' if rows is None else rows}, "
                             f"{self.n_inputs}) for channels "
                             f"{', '.join(self.arm.input_names(False))}; got {p.shape}")
        return p

    def _collect(self, rows, reports) -> BatchReport:
        for i in rows:
            stepper = self._steppers[i]
            self.tips[i] = stepper.tip
            self.pressures[i] = stepper.pressures
        if not self.section_ends and rows:
            self.section_ends = tuple(self._steppers[rows[0]].equilibrium.section_ends)
        return _report(reports)

    def solve_tips(self, pressures) -> tuple[np.ndarray, BatchReport]:
        """Tips (m, 3) of cold equilibria at ``pressures`` (m, n_inputs) Pa: what
        ``solve(arm, p, scene, planar=False, record=False)`` gives, row by row. The copies'
        states are untouched."""
        p = self._inputs(pressures, None)
        eqs = self._map("cold", lambda k: solve(self.arm, p[k], self.scene, model=self.model,
                                                planar=False, record=False,
                                                settings=self.settings), range(p.shape[0]))
        tips = np.array([eq.tip for eq in eqs]).reshape(-1, 3)
        return tips, _report([StepReport(eq.converged, eq.stable, eq.snapped, eq.iterations,
                                         eq.residual) for eq in eqs])

    def reset(self, pressures, rows=None) -> BatchReport:
        """Cold equilibria at ``pressures`` (len(rows), n_inputs) Pa become the states of
        ``rows`` (default: every copy), as :meth:`Stepper.reset` for each."""
        rows = np.arange(self.n) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
        if rows.size and (rows.min() < 0 or rows.max() >= self.n):
            raise ValueError(f"rows must index the {self.n} copies; got {rows.tolist()}")
        p = self._inputs(pressures, rows.size)
        reports = self._map("cold", lambda j: self._steppers[rows[j]].reset(p[j]), range(rows.size))
        return self._collect(rows.tolist(), reports)

    def step(self, pressures, active=None) -> BatchReport:
        """Move every copy (or the ``active`` ones, (n,) bool) to its row of ``pressures``
        (n, n_inputs) Pa, as :meth:`Stepper.step` for each; idle copies report converged
        with no iterations."""
        active = np.ones(self.n, dtype=bool) if active is None else np.asarray(active)
        if active.shape != (self.n,) or active.dtype != bool:
            raise ValueError(f"active must be a ({self.n},) bool array; got {active.dtype} {active.shape}")
        p = self._inputs(pressures, self.n)
        rows = np.flatnonzero(active).tolist()
        stepped = dict(zip(rows, self._map("step", lambda i: self._steppers[i].step(p[i]), rows)))
        idle = StepReport(True, True, False, 0, 0.0)
        return self._collect(rows, [stepped.get(i, idle) for i in range(self.n)])

    def equilibrium(self, k: int) -> Equilibrium:
        """Copy k's current equilibrium."""
        if not 0 <= k < self.n:
            raise ValueError(f"copy {k} does not exist; n = {self.n}")
        return self._steppers[k].equilibrium

    def __repr__(self) -> str:
        return f"SpatialBatchStepper({self.arm.name!r}, {self.scene}, n={self.n}, model={self.model!r})"


def _report(reports) -> BatchReport:
    """A BatchReport of a list of StepReports."""
    return BatchReport(np.array([r.converged for r in reports], dtype=bool),
                       np.array([r.stable for r in reports], dtype=bool),
                       np.array([r.snapped for r in reports], dtype=bool),
                       np.array([r.iterations for r in reports], dtype=np.int64),
                       np.array([r.residual for r in reports], dtype=float))
