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
from solver.paths.lean_contact import (
    ONE_COPY,
    PATH_HELD,
    PATHS,
    ContactRows,
    lean_contact_reason,
    record_from_equilibrium,
    refusal_names,
)
from solver.paths.lean_spatial_contact import SpatialContactRows, lean_spatial_contact_reason
from solver.paths.planar import loaded_base_moment, not_lean, single_result
from solver.problem import Problem, pack
from solver.results import Equilibrium
from solver.scene import Disc, Scene
from solver.settings import DEFAULT_SETTINGS, Settings
from solver.threads import CopyPool

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


_NO_GUARD = (np.empty((0, 4)), np.empty((1, L.N_COLUMNS)), np.empty(0), 0.0)  # no contact


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
        record: the current state's backbone record where a lean path keeps one, else None:
            (N, ``layout.N_COLUMNS``) on the settings' grid, (N, ``layout.C_COLUMNS``) on the
            contact layout; either way columns ``layout.S`` … ``layout.U`` are the samples'
            s, x, y, θ, m, n, v and u (read-only, replaced at every converged step).
        section_ends: the record's rows at the section ends.
        lean: whether steps take the lean planar path (in a scene with contact, the steps
            that touch nothing; in 3D, the spatial single-shooting kernel).
        lean_contact: whether steps in contact take the lean contact path
            (:mod:`solver.paths.lean_contact`: planar penalty contact;
            :mod:`solver.paths.lean_spatial_contact`: cylinders, spheres and discs in 3D).
        last_path: the path of the last step or reset: ``"lean"`` (the lean planar kernel,
            or in 3D the spatial one), ``"lean contact"``, ``"general"``
            (:func:`solver.solve`'s paths) or, in a scene with contact, ``"held"``
            (the same pressures again: the state stands, no solve).
        last_refusals: why the planar lean contact step of the last step refused a try
            (names of :data:`solver.paths.lean_contact.REFUSALS`, e.g. ``("not converged",
            "budget spent")`` before a snap the general path took; empty where it refused
            none or took no part).
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
        # With contact, one copy of the batch machinery (the same kernels as BatchStepper).
        self._rows = ContactRows(problem, 1, len(scene.obstacles)) \
            if lean_contact_reason(problem) is None else \
            SpatialContactRows(problem, 1) if lean_spatial_contact_reason(problem) is None else None
        self.lean_contact = self._rows is not None
        self._row_views = {}  # read-only record and tip views of the rows' copy, per grid
        self.lean = self.lean_contact or not_lean(problem) is None
        self._section_ends = packed.section_ends
        self._p_max = arm.max_pressure * (1 + 1e-12)
        self._index = packed.spatial_of_planar  # the scalar check of a planar step's pressures
        self._p_new = np.empty(arm.n_channels)
        self._eq = None
        self.record = None
        self.last_path = "general"
        self._refusal_bits = 0
        self.tip = np.zeros(2 if planar else 3)
        self.tip.flags.writeable = False
        self.pressures = np.zeros(self.n_inputs)
        self.channel_pressures = np.zeros(arm.n_channels)
        if not self.lean or self.lean_contact:
            return
        ns = len(arm.sections)
        n_tubes = packed.tubes_i.shape[0]
        self._ctx = ctx
        self._grid = (scene.base_theta, packed.secf, packed.sec_steps)
        self._tubes = (packed.tubes_i, packed.tubes_f)
        self._state = np.zeros(4)  # m0, tip x, y, θ
        self._buffers = [np.empty((packed.n_rows, L.N_COLUMNS)) for _ in range(2)]
        self._works = [(np.empty((3, ns)), np.empty(arm.n_channels), np.empty((ns, 4)), buf, True)
                       for buf in self._buffers]
        self._spare = 0
        self._memo = (np.full(n_tubes, np.nan), np.empty(n_tubes), np.empty((3, ns)),
                      np.full((2, ns), np.nan))
        self._target = (self._p_new, ctx.loads, ctx.m_tip)  # the kernel's goal levels
        self._bind_tips()
        self._flags = (True, True, False, 0, 0.0)  # of the current equilibrium

    # ------------------------------------------------------------------ state

    @property
    def section_ends(self) -> tuple:
        """The rows of :attr:`record` at the section ends (of the settings' grid where there
        is no record)."""
        if self._rows is not None and self._rows.on_contact_layout(0):
            return self._rows.contact_section_ends
        return self._section_ends

    @property
    def equilibrium(self) -> Equilibrium:
        """The current equilibrium (built on first access after a step; its arrays are
        copies, unaffected by later steps)."""
        if self._eq is None and self._rows is not None and self._rows.ready(0):
            self._eq = self._rows.equilibrium(0, self.pressures, self.channel_pressures)
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
        self.last_path = "general"
        self._refusal_bits = 0
        self._adopt(eq)
        return StepReport(eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)

    def step(self, pressures) -> StepReport:
        """Move the arm quasi-statically from the current equilibrium to ``pressures`` (Pa).

        A step that does not converge leaves the current equilibrium as it was.

        Raises:
            ValueError: wrong count, non-finite, negative or over-rated pressures.
            RuntimeError: before :meth:`reset`.
        """
        if self._eq is None and self.record is None and not (
                self._rows is not None and self._rows.ready(0)):
            raise RuntimeError("call reset() before step()")
        if self._rows is not None:
            return self._step_rows(pressures)
        if not self.lean:
            return self._step_general(pressures)
        p = self._planar_inputs(pressures)
        ctx = self._ctx
        work = self._works[self._spare]
        m_start = self._state[0]
        ok, stable, snapped, its, res, _, _ = planar_kernels.warm_step(
            self._state, self._grid, self._tubes, (self.channel_pressures, ctx.loads, ctx.m_tip),
            self._target, ctx.params, work, self._memo, _NO_GUARD)
        if not ok:
            # The lean path failed (rare: see softarm stress); the general one has fallbacks
            # (multiple shooting) the single-shooting kernel does not.
            self._state[0] = m_start
            report = self._step_general(p)
            return report._replace(iterations=report.iterations + int(its))
        self.last_path = "lean"
        self.record = work[3]
        self._spare ^= 1
        self.pressures = p.copy()
        self.channel_pressures = self._p_new.copy()
        self.tip = self._tips[self._spare ^ 1]
        self._flags = report = StepReport(True, stable, snapped, its, res)
        self._eq = None
        return report

    def _planar_inputs(self, pressures) -> np.ndarray:
        """A planar step's input pressures as an array (Pa), their channels' into
        ``_p_new``: the scalar check, ``checked_pressures``' error where it fails."""
        try:
            p = np.asarray(pressures, dtype=float)
        except (TypeError, ValueError):
            p = None
        if p is None or p.shape != (self.n_inputs,) or not channels_of(p, self._index, self._p_max,
                                                                       self._p_new):
            checked_pressures(self.arm, pressures, True, self._packed)  # raises, naming the fault
            explain_bad_pressures(self.arm, p, True)
        return p

    def _step_rows(self, pressures) -> StepReport:
        """A step in a scene with contact: the lean paths of :class:`ContactRows` or, in 3D,
        :class:`SpatialContactRows` (one copy), or where they cannot take it, the general
        path from the same state."""
        rows = self._rows
        planar = isinstance(rows, ContactRows)
        if planar:
            p_inputs = self._planar_inputs(pressures).copy()
            p_channel = self._p_new.copy()
        else:
            p_inputs, p_channel = checked_pressures(self.arm, pressures, self.planar, self._packed)
        if not rows.ready(0):
            return self._step_general(p_inputs)
        report = rows.step_one(self.channel_pressures, p_channel) if planar else \
            rows.step(self.channel_pressures[None], p_channel[None], ONE_COPY, None)[0]
        converged, stable, snapped, iterations, residual, path, *refused = report.tolist()
        # (The 3D rows report no refusal column: their lean step is a continuation of its own.)
        self._refusal_bits = int(refused[0]) if planar else 0
        if path == PATH_HELD:  # the same pressures: the state stands as it is
            self.last_path = PATHS[int(PATH_HELD)]
            return StepReport(True, bool(stable), False, 0, residual)
        if not converged:
            general = self._step_general(p_inputs)
            return general._replace(iterations=general.iterations + int(iterations))
        self.last_path = PATHS[int(path)]
        self.pressures = p_inputs
        self.channel_pressures = p_channel
        self._eq = None
        self._bind_row_record()
        return StepReport(True, bool(stable), bool(snapped), int(iterations), residual)

    def contact_measures(self) -> tuple[float, float]:
        """The current state's deepest penetration at its samples (m) and total contact
        force ∫|f| ds (N, trapezoidal on the samples): zeros without contact (the numbers
        :meth:`BatchStepper.contact_measures` gives a copy). Steppers with the lean contact
        path only (:attr:`lean_contact`).

        Raises:
            ValueError: a stepper without it.
        """
        if self._rows is None:
            raise ValueError(f"contact_measures needs the lean contact path; {self!r} has none")
        measures = self._rows.contact_measures()[0]
        return float(measures[0]), float(measures[1])

    @property
    def last_refusals(self) -> tuple[str, ...]:
        """Why the planar lean contact step of the last step refused a try (names of
        :data:`solver.paths.lean_contact.REFUSALS`; the class docstring's Attributes); named
        when read, not at every step."""
        return refusal_names(self._refusal_bits)

    @property
    def full_factor_age(self) -> int:
        """Planar lean contact steppers: how many accepted states the factored full Jacobian
        of the current state (where parts of the arm touch each other) has served
        (:meth:`solver.paths.lean_contact.ContactRows.full_factor_age`); 0 otherwise."""
        return self._rows.full_factor_age(0) if isinstance(self._rows, ContactRows) else 0

    def pass_costs(self, repeats: int = 20) -> dict:
        """A profile of the current contact state (lean contact steppers whose state lies on
        the contact layout): the seconds of a residual pass and of one with the Jacobian
        (medians of ``repeats``), the shooting unknowns, RK4 rows and the fraction of them
        refined near a disc. The state is untouched.

        Raises:
            ValueError: no lean contact path, or a state off the contact layout.
        """
        if self._rows is None:
            raise ValueError(f"pass_costs needs the lean contact path; {self!r} has none")
        return self._rows.pass_costs(0, repeats)

    def _bind_row_record(self) -> None:
        """The record and tip of the one copy of :attr:`_rows` (read-only views; in 3D the
        tip alone: :attr:`record` is planar)."""
        if not self.planar:
            tip = self._rows.tip(0).view()
            tip.flags.writeable = False
            self.tip = tip
            return
        on_layout = self._rows.on_contact_layout(0)
        views = self._row_views.get(on_layout)
        if views is None:  # (the rows step in place: a view per grid serves every step)
            record = self._rows.record(0).view()
            record.flags.writeable = False
            views = self._row_views[on_layout] = (record, record[-1, L.X:L.Y + 1])
        self.record, self.tip = views

    def _step_general(self, pressures) -> StepReport:
        self.last_path = "general"
        p_inputs, p_channel = checked_pressures(self.arm, pressures, self.planar, self._packed)
        eq = dispatch(self._problem.with_inputs(p_inputs, p_channel, self.equilibrium), True)
        report = StepReport(eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        if eq.converged:
            self._adopt(eq)
        return report

    def adopt(self, eq: Equilibrium) -> None:
        """Make ``eq``, an equilibrium of this arm, model and mode solved in this scene (with
        ``record=True``), the current state."""
        self._check_adoptable(eq, self.scene)
        self._adopt(eq)

    def _check_adoptable(self, eq, scene: Scene) -> None:
        """ValueError unless ``eq`` is an equilibrium of this arm, model and mode solved in
        ``scene`` with a record (what :meth:`adopt` and :meth:`adopt_moved` take)."""
        if not isinstance(eq, Equilibrium):
            raise ValueError("adopt() takes an Equilibrium returned by solve()")
        check_warm_start(eq, self.arm, scene, self.model, self.planar)
        if eq.scene != scene:
            raise ValueError(f"the equilibrium was solved in {eq.scene}, not in this stepper's "
                             f"scene {scene}")
        if not eq.s.size:
            raise ValueError("the equilibrium was solved with record=False; adopt needs its backbone")

    def adopt_moved(self, eq: Equilibrium) -> None:
        """Make ``eq`` the current state where it was solved in this stepper's scene with its
        discs moved — their centres only, as a free object the arm carries moves
        (:mod:`solver.grasp`) — and its scene this stepper's: what ``with_scene(eq.scene)``
        then ``adopt(eq)`` give, without building a stepper at every move."""
        if not isinstance(eq, Equilibrium):
            raise ValueError("adopt_moved() takes an Equilibrium returned by solve()")
        old, new = self.scene, eq.scene
        if not self.planar:
            raise ValueError("adopt_moved() moves the discs of a planar stepper; a spatial one's "
                             "contact rows keep their obstacles: use with_scene(eq.scene)")
        if new is not old and not (
                new.without_contact == old.without_contact and len(new.obstacles) == len(old.obstacles)
                and (new.self_contact, new.self_friction) == (old.self_contact, old.self_friction)
                and all(type(a) is Disc and type(b) is Disc
                        and (a.radius, a.stiffness, a.friction) == (b.radius, b.stiffness, b.friction)
                        for a, b in zip(new.obstacles, old.obstacles))):
            raise ValueError(f"the equilibrium was solved in {new}, which is not this stepper's "
                             f"scene {old} with its discs moved; use with_scene(eq.scene)")
        self._check_adoptable(eq, new)  # before anything changes
        self.scene = new
        self._problem = self._problem.in_scene(new)
        if self._rows is not None:
            self._rows.set_scene(0, new)
        self._adopt(eq)

    def _adopt(self, eq: Equilibrium) -> None:
        """Make ``eq`` the current state (and, on the lean path, its record and predictor)."""
        self._eq = eq
        self.pressures = eq.pressures.copy()
        self.channel_pressures = eq.channel_pressures.copy()
        self.tip = eq.tip.copy()
        self.tip.flags.writeable = False
        if self._rows is not None:
            self._rows.adopt(0, eq)
            self.record = None
            if self._rows.ready(0) and self.planar:  # (in 3D the tip stays eq's)
                self._bind_row_record()
            return
        if not self.lean:
            return
        rec = self._buffers[self._spare]
        record_from_equilibrium(eq, self._packed, rec, self._memo[2], self._memo[3])
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
        self._row_views = {}
        if self._rows is not None:
            if self._rows.ready(0) and (self.planar or self._eq is None):
                self._bind_row_record()  # (a pickle copies views apart)
            return
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
                f"planar={self.planar}, lean={self.lean}, lean_contact={self.lean_contact})")


class ThreadPolicy:
    """Whether a batch of ``rows`` copies runs on threads (numba's parallel loops; for the
    contact rows, :class:`solver.threads.CopyPool`'s Python threads) or on one thread.

    Threads pay off only when the machine has idle cores: on a shared machine a parallel
    region waits at its barrier for a thread the OS has descheduled, and a batch can take
    ten times longer on two threads than on one. So the choice is measured, not assumed:
    the first batches run once each way (the very first run of each only loads its kernel
    and is not counted), then the faster per-row time wins, and the choice is re-checked
    while the batches run: the way in use is timed at every batch, and the other way is tried
    again after ``interval`` batches. The interval doubles (up to ``MAX_INTERVAL``) each time
    the other way loses again, and is at least the loser's slowdown over ``PROBE_BUDGET``:
    a threaded probe on a contended machine can take tens of serial batches, and probing
    it every 16 batches would then cost more than the threads could ever save. So on a busy
    machine the threads cost at most ``PROBE_BUDGET`` over one thread, and when they win
    again (the machine got quiet) the next probe finds it and the interval resets.
    Batches below ``min_rows`` and single-thread configurations run serially.

    Args:
        min_rows: the smallest batch that may run threaded.

    Attributes:
        per_row_s: [serial, threaded] smoothed seconds per row (NaN: not measured yet).
    """

    START_INTERVAL = 16
    MAX_INTERVAL = 4096
    PROBE_BUDGET = 0.05
    """Most of the run time losing probes may take: a probe of a way ``r`` times slower waits
    at least ``r / PROBE_BUDGET`` batches."""
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
            slowdown = max(serial, par) / min(serial, par)
            self._interval = self.START_INTERVAL if won else min(
                max(2 * self._interval, math.ceil(slowdown / self.PROBE_BUDGET)), self.MAX_INTERVAL)
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
    scenes a stepper steps lean are accepted (planar, channels, loaded, single shooting;
    contact by penalty); the constructor says which condition fails otherwise.

    With contact (discs, self-contact) every copy may hold obstacles of its own, up to
    ``max_obstacles``, under the scene's law (its gravity, payload, mounting, self-contact
    and obstacle stiffness): :meth:`reset` and :meth:`adopt` take the copies' scenes. A copy
    touching nothing is stepped by the lean planar kernel, guarded; one on the contact
    layout by the lean contact kernel (:mod:`solver.kernels.stepping`); cold solves and the
    steps those cannot take by the general path, copy by copy on Python threads (its kernels
    release the GIL; the equilibria are those of one copy after another, bit for bit).

    Example::

        batch = solver.BatchStepper(solver.designs.octarm_v(), solver.Scene(), n=1024)
        batch.reset(np.zeros((1024, 6)))       # cold equilibria
        report = batch.step(p)                  # (1024, 6) Pa; report.converged (1024,)
        batch.tips, batch.records               # (1024, 2) m, (1024, N, layout.N_COLUMNS)

    Args:
        arm, scene, model, settings: as :class:`Stepper` (planar only).
        n: number of copies.
        max_obstacles: with contact, the most obstacles a copy may hold (default: the
            scene's count).

    Attributes:
        records: (n, N, ``layout.N_COLUMNS``) every copy's backbone record (read-only); with
            contact, the records of the copies on the settings' grid (see
            :meth:`backbones`).
        tips: (n, 2) tip positions (m).
        pressures: (n, n_inputs) input pressures (Pa); ``channel_pressures`` (n, n_channels).
        section_ends: the records' rows at the section ends.
        contact: whether the scene has contact (discs or self-contact).
    """

    PARALLEL_MIN = 64
    """Batches smaller than this run on one thread: sharing them never paid on the 2-core
    machine (``softarm bench --env``: 16 arms, 21k env-steps/s on one thread, 10k with the
    policy's threaded probes counted; 256 arms, 56k threaded against 37k), and a threaded
    probe costs more than such a batch's whole step. Larger ones run on the threads or on
    one, whichever :class:`ThreadPolicy` has measured faster."""

    def __init__(self, arm: ArmDesign, scene: Scene | None = None, n: int = 1, *,
                 model: str = "full", settings: Settings = DEFAULT_SETTINGS,
                 max_obstacles: int | None = None):
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
        self.contact = scene.has_contact
        reason = lean_contact_reason(problem) if self.contact else not_lean(problem)
        if reason is not None:
            raise ValueError(f"BatchStepper steps the lean planar and contact paths only, not "
                             f"{reason}; use a Stepper (or solve()) per copy")
        if max_obstacles is None:
            max_obstacles = len(scene.obstacles)
        if isinstance(max_obstacles, bool) or not isinstance(max_obstacles, (int, np.integer)) \
                or max_obstacles < len(scene.obstacles):
            raise ValueError(f"max_obstacles must be an integer >= the scene's {len(scene.obstacles)} "
                             f"obstacles; got {max_obstacles!r}")
        if max_obstacles and not scene.obstacles:
            raise ValueError("max_obstacles needs a scene with an obstacle: its stiffness is the "
                             "copies' law")
        self._general_pool = CopyPool()  # (the contact rows' threaded batches share it)
        self._rows = ContactRows(problem, self.n, int(max_obstacles), self._general_pool) \
            if self.contact else None
        if not self.contact:
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
        self.records = self._rows.free_records if self.contact else np.zeros((n, packed.n_rows, L.N_COLUMNS))
        self.tips = np.zeros((n, 2)) if self.contact else self.records[:, -1, L.X:L.Y + 1]
        self.pressures = np.zeros((n, n_inputs))
        self.channel_pressures = np.zeros((n, nc))
        self._states = np.zeros((n, 4))
        self._flags = np.zeros((n, 5))
        self._work = (np.empty((n, 3, ns)), np.empty((n, nc)), np.empty((n, ns, 4)),
                      np.empty((n, packed.n_rows, L.N_COLUMNS)))
        self._memo = (np.full((n, n_tubes), np.nan), np.empty((n, n_tubes)), np.empty((n, 3, ns)),
                      np.full((n, 2, ns), np.nan))
        self._ready = np.zeros(n, dtype=bool)
        self._no_guard = (np.empty((n, 0, 4)), np.empty(0), 0.0)
        self._eqs = [None] * n  # with contact: each copy's Equilibrium, once built
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

    def reset(self, pressures, rows=None, scenes=None) -> BatchReport:
        """Cold equilibria at ``pressures`` (len(rows), n_inputs) Pa become the current
        states of ``rows`` (default: every copy), as :meth:`Stepper.reset` does for each: a
        state is adopted even if its solve did not converge (the report says so). With
        contact, ``scenes`` (one per row, or None: keep each copy's) gives the copies their
        obstacles (the scene's law; at most ``max_obstacles``)."""
        rows = self._rows_of(rows)
        p, channel = self._inputs(pressures, rows.size)
        if self.contact:
            return self._reset_contact(rows, p, channel, scenes)
        if scenes is not None:
            raise ValueError("scenes apply to a scene with contact; this batch has none")
        states = np.zeros((rows.size, 4))
        records = np.empty((rows.size, *self.records.shape[1:]))
        rest_a = self._memo[2][rows]
        grad = self._memo[3][rows]
        report = self._cold(channel, states, records, True, rest_a, grad)
        for j in np.flatnonzero((report[:, 0] == 0) | (report[:, 1] == 0)):
            eq = self._solve_row(p[j], channel[j], None, True)
            record_from_equilibrium(eq, self._packed, records[j], rest_a[j], grad[j])
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
        ``record=True``; with contact, in a scene of its law, whose obstacles the rows take)
        the current state of ``rows`` (default: every copy) — e.g. to roll candidate steps
        out from one state."""
        if not isinstance(eq, Equilibrium):
            raise ValueError("adopt() takes an Equilibrium returned by solve()")
        check_warm_start(eq, self.arm, self.scene, self.model, True)
        if self.contact:
            self._check_copy_scene(eq.scene)
        elif eq.scene != self.scene:
            raise ValueError(f"the equilibrium was solved in {eq.scene}, not in {self.scene}")
        if not eq.s.size:
            raise ValueError("the equilibrium was solved with record=False; adopt needs its backbone")
        rows = self._rows_of(rows)
        if self.contact:
            self._adopt_contact(eq, rows)
            return
        first = int(rows[0])
        record_from_equilibrium(eq, self._packed, self.records[first], self._memo[2][first],
                                self._memo[3][first])
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
        if self.contact:
            return self._step_contact(p, channel, active)
        report = np.zeros((self.n, 5))
        report[~active, :2] = 1.0
        self.thread_policies["step"].run(
            planar_kernels.step_rows_parallel, planar_kernels.step_rows_serial, int(active.sum()), self._grid,
            self._tubes, self.channel_pressures, channel, self._ctx.loads, self._ctx.m_tip,
            self._ctx.params, self._work, self._states, self.records, self._memo, self._no_guard,
            active, report)
        ok = report[:, 0] != 0
        for k in np.flatnonzero(~ok):
            # As Stepper.step: the general path (with its fallbacks) from the kept equilibrium.
            eq = self._solve_row(p[k], channel[k], self.equilibrium(k), True)
            report[k] = (eq.converged, eq.stable, eq.snapped, eq.iterations + report[k, 3],
                         eq.residual)
            if eq.converged:
                record_from_equilibrium(eq, self._packed, self.records[k], self._memo[2][k], self._memo[3][k])
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
        if self.contact:
            if self._eqs[k] is None:
                self._eqs[k] = self._rows.equilibrium(k, self.pressures[k], self.channel_pressures[k])
            return self._eqs[k]
        return _record_equilibrium(self.records[k], self._flags[k], self._states[k, 0],
                                   self.pressures[k], self.channel_pressures[k], self._problem)

    def __setstate__(self, state):
        self.__dict__.update(state)
        if not self.contact:
            self.tips = self.records[:, -1, L.X:L.Y + 1]

    # ------------------------------------------------------------------ contact

    def _rows_of(self, rows) -> np.ndarray:
        """``rows`` (None: every copy) as an index array, checked."""
        rows = np.arange(self.n) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
        if rows.size and (rows.min() < 0 or rows.max() >= self.n):
            raise ValueError(f"rows must index the {self.n} copies; got {rows.tolist()}")
        return rows

    def _check_copy_scene(self, scene) -> None:
        """A copy's scene must be the batch scene's law with obstacles of its own: the same
        mounting, loads and self-contact, discs of the template's stiffness, at most
        ``max_obstacles``."""
        if not isinstance(scene, Scene):
            raise ValueError(f"a copy's scene must be a solver.Scene; got {type(scene).__name__}")
        if scene.without_contact != self.scene.without_contact or \
                scene.self_contact != self.scene.self_contact or \
                scene.self_friction != self.scene.self_friction:
            raise ValueError(f"a copy's scene may differ from the batch's only in its obstacles; "
                             f"got {scene} for {self.scene}")
        law = self.scene.obstacles[0].stiffness if self.scene.obstacles else None
        bad = [d for d in scene.obstacles if not isinstance(d, Disc) or d.stiffness != law]
        if bad:
            raise ValueError(f"a copy's obstacles must be discs of the batch's stiffness {law}; "
                             f"got {bad[0]}")
        if len(scene.obstacles) > self._rows.max_obstacles:
            raise ValueError(f"a copy's scene holds {len(scene.obstacles)} obstacles; this batch "
                             f"takes at most {self._rows.max_obstacles} (max_obstacles)")

    @property
    def contact_rows(self):
        """The lean contact path of every copy (:class:`solver.paths.lean_contact.ContactRows`:
        its ``step`` is the one kernel call of a batched contact step), None without contact.
        For instrumentation (``softarm bench --contact-profile`` times its steps)."""
        return self._rows

    def solve_copy(self, k: int, p_inputs, p_channel, warm_start, scene) -> Equilibrium:
        """The general path's solve for copy k (the steps its lean path cannot take, and a
        contact reset): the equilibrium at the pressures ``p_inputs`` (n_inputs,) and
        ``p_channel`` (n_channels,) (Pa) in ``scene``, from ``warm_start`` (an Equilibrium, or
        None: cold). The copy's state is not changed."""
        problem = self._problem.in_scene(scene).with_inputs(p_inputs, p_channel, warm_start)
        return dispatch(problem, True)

    def _solve_copies(self, jobs) -> list[Equilibrium]:
        """:meth:`solve_copy` of every ``(k, p_inputs, p_channel, warm_start, scene)`` in
        ``jobs``, on up to ``numba.get_num_threads()`` Python threads. The general path's
        kernels release the GIL, and each copy's solve reads only its own arguments and the
        batch's read-only layout, so the equilibria are, bit for bit, those of solving the
        copies one after another; the caller takes them in order. Wrap candidates that snap
        (a planner's corners, a batch of arms curling) reach the general path together: their
        solves are most of such a step's time."""
        return self._general_pool.map(lambda job: self.solve_copy(*job), jobs)

    def _take(self, k, eq: Equilibrium) -> None:
        """Copy k's state becomes ``eq`` (solved in its scene by the general path)."""
        self._rows.adopt(k, eq)
        self._eqs[k] = eq
        self.tips[k] = eq.tip
        self.pressures[k] = eq.pressures
        self.channel_pressures[k] = eq.channel_pressures

    def _reset_contact(self, rows, p, channel, scenes) -> BatchReport:
        if scenes is not None:
            scenes = list(scenes)
            if len(scenes) != rows.size:
                raise ValueError(f"scenes must hold one scene per row ({rows.size}); got {len(scenes)}")
            for scene in scenes:
                self._check_copy_scene(scene)
        report = np.zeros((rows.size, 5))
        if scenes is not None:
            for j, k in enumerate(rows):
                self._rows.set_scene(k, scenes[j])
        jobs = [(k, p[j], channel[j], None, self._rows.scenes[k]) for j, k in enumerate(rows)]
        for j, (k, eq) in enumerate(zip(rows, self._solve_copies(jobs))):
            self._take(k, eq)
            report[j] = (eq.converged, eq.stable, eq.snapped, eq.iterations, eq.residual)
        self._ready[rows] = True
        return self._report(report)

    def _adopt_contact(self, eq, rows) -> None:
        first = int(rows[0])
        self._rows.set_scene(first, eq.scene)
        self._take(first, eq)
        self._rows.copy_rows(first, rows[1:])
        for k in rows[1:]:
            self._eqs[k] = eq
            self.tips[k] = eq.tip
            self.pressures[k] = eq.pressures
            self.channel_pressures[k] = eq.channel_pressures
        self._ready[rows] = True

    def _step_contact(self, p, channel, active) -> BatchReport:
        lean = active & np.array([self._rows.ready(k) for k in range(self.n)])
        full = self._rows.step(self.channel_pressures, channel, lean, self.thread_policies["step"].run)
        report = full[:, :5]
        report[~active, :2] = 1.0
        held = lean & (full[:, 5] == PATH_HELD)  # (standing as it was)
        moved = lean & (report[:, 0] != 0) & ~held
        for k in np.flatnonzero(moved):
            self._eqs[k] = None
            self.tips[k] = self._rows.record(k)[-1, L.X:L.Y + 1]
        self.pressures[moved] = p[moved]
        self.channel_pressures[moved] = channel[moved]
        # As Stepper.step: the general path (with its fallbacks) from the kept equilibrium.
        general = np.flatnonzero(active & ~moved & ~held)
        jobs = [(k, p[k], channel[k], self.equilibrium(k), self._rows.scenes[k]) for k in general]
        for k, eq in zip(general, self._solve_copies(jobs)):
            report[k] = (eq.converged, eq.stable, eq.snapped, eq.iterations + report[k, 3],
                         eq.residual)
            if eq.converged:
                self._take(k, eq)
        return self._report(report)

    def scene_of(self, k: int) -> Scene:
        """Copy k's scene (with its obstacles)."""
        return self._rows.scenes[k] if self.contact else self.scene

    def contact_measures(self) -> np.ndarray:
        """(n, 2) every copy's deepest penetration at its samples (m) and total contact force
        ∫|f| ds (N, trapezoidal on the samples); zeros without contact."""
        if not self.contact:
            return np.zeros((self.n, 2))
        return self._rows.contact_measures()

    def recorded(self) -> np.ndarray:
        """(n,) bool: the copies whose current state a lean path records — their rows of
        :meth:`backbones` and :meth:`contact_measures` are current (as a :class:`Stepper`'s
        ``record`` is not None); read the others' from :meth:`equilibrium` (a state the
        general path left on a grid of its own)."""
        if not self.contact:
            return self._ready.copy()
        return np.array([self._rows.ready(k) for k in range(self.n)], dtype=bool)

    def backbones(self) -> np.ndarray:
        """(n, N, ``layout.N_COLUMNS``) every copy's current backbone in the columns
        ``layout.S`` … ``layout.U`` (with contact, those on the contact layout copied in; the
        grids must have the same rows, as they do at the tube stiffness of OctArm V and CT)."""
        if not self.contact:
            return self.records
        return self._rows.backbones()

    def __repr__(self) -> str:
        return f"BatchStepper({self.arm.name!r}, {self.scene}, n={self.n}, model={self.model!r})"
