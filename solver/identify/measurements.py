"""What was measured, and what the model predicts for it.

A :class:`Measurements` holds n *configurations* — planar input pressures, base angle and
known payload, one row each — and any number of *observations* of them: measured values
with their standard deviations, one column per measured quantity, NaN where a configuration
was not measured. Two observations live here, :class:`TipPositions` (the tip, from a camera
or a tracker) and :class:`BackbonePoints` (markers at known reference arc lengths along the
backbone: endplates, tape marks on a photographed arm); sensor readings (cable encoders,
inclinometers, a base load cell) are the sensor models' business and live in
``softarm_gym.identify`` — any object with the :class:`Observation` interface works.

:func:`predict` solves every configuration of a design, grouped by scene, in batches
(:func:`solver.step_batch`): cold — the equilibrium the arm reaches quasi-statically from
rest at those pressures, as :func:`solver.solve` defines it — or continued from the
equilibria of a nearby design (where the batch kernel steps the scene; the others — closed
forms of an unloaded arm or of constant curvature, multiple shooting — are solved cold).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import partial

import numba
import numpy as np

import solver
from solver import layout as L
from solver.designs import ArmDesign
from solver.rod import hermite_resample
from solver.settings import DEFAULT_SETTINGS, Settings

__all__ = ["Measurements", "Observation", "TipPositions", "BackbonePoints", "Shapes", "predict",
           "PLANAR_ONLY"]

PLANAR_ONLY = "solver.identify fits planar measurements (the planar solver's inputs and shapes)"
"""Why a spatial design input is refused."""


def _finite_array(value, name: str, shape=None, allow_nan: bool = False) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers; got {type(value).__name__}") from None
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}; got {arr.shape}")
    bad = np.isinf(arr) if allow_nan else ~np.isfinite(arr)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{name} has a non-finite value at index {where}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Observation:
    """Measured quantities of every configuration, with their noise.

    Subclasses add what they need to predict their columns and implement :meth:`predict`.

    Attributes:
        measured: (n, k) measured values, one column per quantity (NaN: not measured).
        sigma: (n, k) standard deviations of the measurement noise (> 0, same units).
        name: what is observed (``"tip"``).
        labels: (k,) column names (``"tip_x"``).
        units: (k,) column units.
        needs_backbone: predictions need the backbone, not only the tip.
        needs_equilibria: predictions need each configuration's :class:`solver.Equilibrium`.
    """

    measured: np.ndarray
    sigma: np.ndarray

    name = "observation"
    needs_backbone = False
    needs_equilibria = False

    @property
    def labels(self) -> tuple[str, ...]:
        raise NotImplementedError

    @property
    def units(self) -> tuple[str, ...]:
        raise NotImplementedError

    def __post_init__(self):
        measured = _finite_array(self.measured, f"{self.name}: measured", allow_nan=True)
        if measured.ndim != 2 or measured.shape[1] != len(self.labels):
            raise ValueError(f"{self.name}: measured must have shape (n, {len(self.labels)}) for "
                             f"{', '.join(self.labels)}; got {measured.shape}")
        sigma = np.broadcast_to(np.asarray(self.sigma, dtype=float), measured.shape).copy() \
            if np.ndim(self.sigma) <= 1 else np.array(self.sigma, dtype=float)
        if sigma.shape != measured.shape or not np.all(np.isfinite(sigma) & (sigma > 0)):
            raise ValueError(f"{self.name}: sigma must be finite numbers > 0 broadcastable to "
                             f"{measured.shape}; got {np.shape(self.sigma)}")
        sigma.setflags(write=False)
        object.__setattr__(self, "measured", measured)
        object.__setattr__(self, "sigma", sigma)

    @property
    def n(self) -> int:
        """Number of configurations."""
        return self.measured.shape[0]

    def take(self, rows) -> Observation:
        """This observation of the configurations ``rows`` only."""
        return replace(self, measured=self.measured[rows], sigma=self.sigma[rows])

    def check(self, design: ArmDesign) -> None:
        """Raise ``ValueError`` if this observation cannot be predicted for ``design``."""

    def predict(self, shapes: Shapes, design: ArmDesign) -> np.ndarray:
        """(n, k) the model's values of the measured quantities.

        Args:
            shapes: the model's equilibria at every configuration (:func:`predict`).
            design: the design that was solved.
        """
        raise NotImplementedError

    def distances(self, values: np.ndarray) -> np.ndarray | None:
        """(n,) a per-configuration error in metres from (n, k) measured − predicted values,
        for observations of positions (None for others)."""
        return None


@dataclass(frozen=True)
class TipPositions(Observation):
    """Measured planar tip positions (x, y) (m)."""

    name = "tip"

    @property
    def labels(self):
        return ("tip_x", "tip_y")

    @property
    def units(self):
        return ("m", "m")

    def predict(self, shapes, design):
        return shapes.tips

    def distances(self, values):
        return np.hypot(values[:, 0], values[:, 1])


@dataclass(frozen=True)
class BackbonePoints(Observation):
    """Measured planar positions of markers at known reference arc lengths ``s`` (m).

    ``measured`` columns: x and y of the first marker, then of the second, and so on.
    The model's positions between its RK4 nodes are cubic Hermite interpolants of the
    nodes' positions and tangents r' = v1·d1 + v3·d3 (error ∝ h⁴, as the integrator's).
    """

    s: tuple = ()
    name = "points"
    needs_backbone = True

    def __post_init__(self):
        s = _finite_array(self.s, "points: s")
        if s.ndim != 1 or s.size == 0 or np.any(s < 0) or np.any(np.diff(s) <= 0):
            raise ValueError(f"points: s must be one or more increasing reference arc lengths >= 0 (m); "
                             f"got {self.s!r}")
        object.__setattr__(self, "s", tuple(float(v) for v in s))
        super().__post_init__()

    @property
    def labels(self):
        return tuple(f"{c}@{v:g}" for v in self.s for c in ("x", "y"))

    @property
    def units(self):
        return ("m",) * (2 * len(self.s))

    def check(self, design):
        if self.s[-1] > design.length * (1 + 1e-12):
            raise ValueError(f"points: marker at s = {self.s[-1]:g} m lies beyond design "
                             f"{design.name!r}'s length {design.length:g} m")

    def predict(self, shapes, design):
        return shapes.points(np.array(self.s)).reshape(shapes.tips.shape[0], -1)

    def distances(self, values):
        return np.mean(np.hypot(values[:, 0::2], values[:, 1::2]), axis=1)


@dataclass(frozen=True)
class Measurements:
    """Configurations and what was measured of them.

    Attributes:
        pressures: (n, n_inputs) planar input pressures (Pa), ordered as the design's
            ``input_names(planar=True)``.
        base_angle_deg: (n,) base angle of each configuration (deg).
        payload_kg: (n,) known tip payload of each configuration (kg).
        observations: what was measured (at least one).
        holdout: (n,) bool, configurations kept out of the fit to measure its error on
            unseen data; None lets :func:`solver.identify.fit` choose them.
        gravity: m/s².
    """

    pressures: np.ndarray
    base_angle_deg: np.ndarray
    payload_kg: np.ndarray
    observations: tuple = ()
    holdout: np.ndarray | None = None
    gravity: float = 9.81

    def __post_init__(self):
        p = _finite_array(self.pressures, "pressures")
        if p.ndim != 2 or p.shape[0] == 0:
            raise ValueError(f"pressures must have shape (n, n_inputs) with n >= 1; got {p.shape}")
        n = p.shape[0]
        object.__setattr__(self, "pressures", p)
        for name in ("base_angle_deg", "payload_kg"):
            arr = _finite_array(np.broadcast_to(np.asarray(getattr(self, name), dtype=float), (n,)), name)
            object.__setattr__(self, name, arr)
        if np.any(self.payload_kg < 0):
            raise ValueError(f"payload_kg must be >= 0; got {self.payload_kg.min():g} kg")
        obs = tuple(self.observations)
        if not obs or not all(isinstance(o, Observation) for o in obs):
            raise ValueError("observations must be one or more solver.identify.Observation objects")
        for o in obs:
            if o.n != n:
                raise ValueError(f"observation {o.name!r} has {o.n} configurations; pressures have {n}")
        names = [o.name for o in obs]
        if len(set(names)) != len(names):
            raise ValueError(f"observations must have distinct names; got {', '.join(names)}")
        object.__setattr__(self, "observations", obs)
        if self.holdout is not None:
            h = np.asarray(self.holdout)
            if h.shape != (n,) or h.dtype != bool:
                raise ValueError(f"holdout must be a ({n},) bool array; got {h.dtype} {h.shape}")
            h = h.copy()
            h.setflags(write=False)
            object.__setattr__(self, "holdout", h)
        if not (isinstance(self.gravity, (int, float)) and math.isfinite(self.gravity) and self.gravity >= 0):
            raise ValueError(f"gravity must be a finite number >= 0; got {self.gravity!r}")

    @property
    def n(self) -> int:
        """Number of configurations."""
        return self.pressures.shape[0]

    @property
    def n_values(self) -> int:
        """Number of measured (finite) values over every observation."""
        return int(sum(np.isfinite(o.measured).sum() for o in self.observations))

    def take(self, rows) -> Measurements:
        """The configurations ``rows`` (indices or a bool mask) only."""
        rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, dtype=np.int64)
        return replace(self, pressures=self.pressures[rows], base_angle_deg=self.base_angle_deg[rows],
                       payload_kg=self.payload_kg[rows],
                       observations=tuple(o.take(rows) for o in self.observations),
                       holdout=None if self.holdout is None else self.holdout[rows])

    def check(self, design: ArmDesign) -> None:
        """Raise a one-line ``ValueError`` if ``design`` cannot be solved at these configurations."""
        n_inputs = design.n_inputs(True)
        if not design.planar_channels:
            raise ValueError(f"design {design.name!r} defines no planar channels; {PLANAR_ONLY}")
        if self.pressures.shape[1] != n_inputs:
            raise ValueError(f"design {design.name!r} has {n_inputs} planar inputs "
                             f"({', '.join(design.input_names(True))}); the measurements have "
                             f"{self.pressures.shape[1]} pressures per configuration")
        for k, row in enumerate(self.pressures):
            try:
                solver.channel_pressures(design, row)
            except ValueError as exc:
                raise ValueError(f"configuration {k}: {exc}") from None
        for o in self.observations:
            o.check(design)

    def scenes(self) -> dict[tuple[float, float], np.ndarray]:
        """The distinct (base angle, payload) pairs and the configurations of each."""
        keys = np.column_stack([self.base_angle_deg, self.payload_kg])
        unique, inverse = np.unique(keys, axis=0, return_inverse=True)
        return {(float(a), float(m)): np.flatnonzero(inverse.reshape(-1) == g)
                for g, (a, m) in enumerate(unique)}

    def effective_sigma(self) -> list[np.ndarray]:
        """Per observation, (n, k) the standard deviations a fit weighs by: ``sigma``, except
        where a quantity reads one and the same value in every configuration of a scene.

        k equal readings of one quantity (a base load cell's force, which is the arm's weight
        whatever the pressures) are one true value rounded k times: k copies of one error,
        not k independent errors. They are weighed as one reading: each by σ·√k. (Readings
        that vary, or carry noise that varies them, are not touched.)
        """
        out = []
        for o in self.observations:
            sigma = o.sigma.copy()
            for rows in self.scenes().values():
                block = o.measured[rows]
                for j in range(block.shape[1]):
                    seen = block[np.isfinite(block[:, j]), j]
                    if seen.size > 1 and np.all(seen == seen[0]):
                        sigma[rows, j] *= math.sqrt(seen.size)
            out.append(sigma)
        return out


@dataclass
class Shapes:
    """The model's planar equilibria at n configurations.

    Attributes:
        design, model: what was solved.
        scenes: (n,) each configuration's :class:`solver.Scene`.
        pressures: (n, n_inputs) input pressures (Pa).
        tips: (n, 2) tip positions (m).
        converged: (n,) whether each solve converged.
        base_moment: (n,) each equilibrium's base moment (N m): with ``channel_pressures``
            (n, n_channels), the state a later solve continues from (:func:`predict`'s ``start``).
        records: (n, N, ``layout.N_COLUMNS``) backbone records (``layout.S`` … ``layout.U``) of
            the batch-solved configurations (NaN for the others), or None when only tips were
            solved.
        section_ends: the records' rows at the section ends.
        solved: configurations solved one by one (:func:`solver.solve`), with their equilibrium.
    """

    design: ArmDesign
    model: str
    scenes: list
    pressures: np.ndarray
    tips: np.ndarray
    converged: np.ndarray
    base_moment: np.ndarray
    channel_pressures: np.ndarray
    records: np.ndarray | None = None
    section_ends: tuple = ()
    solved: dict = field(default_factory=dict)

    def _records(self) -> np.ndarray:
        if self.records is None:
            raise ValueError("these shapes were solved for tips only; predict(..., backbone=True)")
        return self.records

    def samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The backbone samples of every configuration: ``(s (N,), positions (n, N, 2),
        angles θ (n, N), strains (v1, v3) (n, N, 2))``."""
        rec = self._records()
        pos, angles = rec[..., L.X:L.Y + 1].copy(), rec[..., L.THETA].copy()
        strains = rec[..., L.V1:L.V3 + 1].copy()
        for k, eq in self.solved.items():
            pos[k], angles[k], strains[k] = eq.positions, eq.angles, eq.shear_stretch
        batch = np.flatnonzero(~np.isin(np.arange(rec.shape[0]), list(self.solved)))
        s = rec[batch[0], :, L.S] if batch.size else next(iter(self.solved.values())).s
        return np.ascontiguousarray(s), pos, angles, strains

    def equilibrium(self, k: int) -> solver.Equilibrium:
        """Configuration k's recorded equilibrium (built from its record on demand; the
        record's flags are the batch's: ``stable`` as ``converged``)."""
        if k in self.solved:
            return self.solved[k]
        rec, ok = self._records()[k], bool(self.converged[k])  # (views: records are not written again)
        return solver.Equilibrium(
            tip=rec[-1, L.X:L.Y + 1], converged=ok, stable=ok, iterations=0, residual=0.0,
            s=rec[:, L.S], positions=rec[:, L.X:L.Y + 1], angles=rec[:, L.THETA],
            shear_stretch=rec[:, L.V1:L.V3 + 1], curvature=rec[:, L.U],
            internal_force=rec[:, L.NX:L.NY + 1], internal_moment=rec[:, L.M],
            section_ends=self.section_ends, base_force=rec[0, L.NX:L.NY + 1], pressures=self.pressures[k],
            model=self.model, planar=True, base_moment=self.base_moment[k:k + 1], scene=self.scenes[k],
            channel_pressures=self.channel_pressures[k], arm=self.design)

    def points(self, s: np.ndarray) -> np.ndarray:
        """(n, len(s), 2) backbone positions at reference arc lengths ``s`` (m), by cubic
        Hermite interpolation between the samples (positions and tangents r' = v1·d1 + v3·d3)."""
        grid, pos, angles, strains = self.samples()
        s = np.ascontiguousarray(s, dtype=float)
        c, sn = np.cos(angles), np.sin(angles)
        v1, v3 = strains[..., 0], strains[..., 1]
        tangent = np.stack([v3 * c - v1 * sn, v3 * sn + v1 * c], axis=-1)  # (n, N, 2)
        out = np.empty((pos.shape[0], s.size, 2))
        for k in range(out.shape[0]):
            hermite_resample(grid, pos[k], tangent[k], s, out[k])
        return out

    def take(self, rows) -> Shapes:
        """The configurations ``rows`` (indices) only."""
        rows = np.asarray(rows, dtype=np.int64)
        where = {int(k): j for j, k in enumerate(rows)}
        return replace(self, scenes=[self.scenes[k] for k in rows], pressures=self.pressures[rows],
                       tips=self.tips[rows], converged=self.converged[rows],
                       base_moment=self.base_moment[rows],
                       channel_pressures=self.channel_pressures[rows],
                       records=None if self.records is None else self.records[rows],
                       solved={where[k]: eq for k, eq in self.solved.items() if k in where})

    def where(self, mask: np.ndarray, other: Shapes) -> Shapes:
        """These shapes with the configurations in ``mask`` (n,) bool taken from ``other``."""
        pick = np.asarray(mask)
        solved = {k: eq for k, eq in self.solved.items() if not pick[k]}
        solved.update({k: eq for k, eq in other.solved.items() if pick[k]})
        records = None if self.records is None else np.where(pick[:, None, None], other.records, self.records)
        channel = np.where(pick[:, None], other.channel_pressures, self.channel_pressures)
        return replace(self, tips=np.where(pick[:, None], other.tips, self.tips),
                       converged=np.where(pick, other.converged, self.converged),
                       base_moment=np.where(pick, other.base_moment, self.base_moment),
                       channel_pressures=channel, records=records, solved=solved)


def _one_thread(call, *args, **kwargs):
    """``call(*args, **kwargs)`` with numba's parallel regions on one thread."""
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        return call(*args, **kwargs)
    finally:
        numba.set_num_threads(threads)


def predict(design: ArmDesign, measurements: Measurements, model: str = "full", backbone: bool = False,
            settings: Settings = DEFAULT_SETTINGS, start: Shapes | None = None,
            policies: dict | None = None) -> Shapes:
    """The model's equilibria at every configuration, batched by scene.

    Without ``start``, cold solves: the equilibrium the arm reaches quasi-statically from
    rest at each configuration's pressures, as :func:`solver.solve` returns it
    (:func:`solver.step_batch` from no state; a row it does not converge is solved by
    :func:`solver.solve`, with its fallbacks). With ``start`` — the equilibria of these
    configurations for another design of the same layout (a nearby parameter vector) — each
    configuration is continued from its state there: Newton from that base moment at the same
    pressures, for this design (:func:`solver.step_batch` given ``start``'s states as states
    of ``design``). That follows the branch each configuration was on where the arm is
    bistable (docs/design.md §6); a row that does not converge is flagged, not solved
    otherwise. Scenes the batch kernel does not step (constant curvature, an unloaded arm, an
    arm that needs multiple shooting) are solved cold by :func:`solver.solve` either way.

    Args:
        design: the design to solve (checked against ``measurements`` by the caller:
            :meth:`Measurements.check`).
        measurements: the configurations (their observations are not read).
        model: as in :func:`solver.solve`.
        backbone: record the backbones (for markers and sensors), not only the tips.
        settings: numerical settings.
        start: :class:`Shapes` of the same configurations to continue from (None: cold).
        policies: ``{"cold": ThreadPolicy, "warm": ThreadPolicy}`` shared between calls, which
            run each batch on numba's threads or on one, whichever they have measured faster
            (:class:`solver.ThreadPolicy`: on the busy 2-core machine a parallel region took
            ten times longer than one thread for 64 configurations); None: the threads.

    Returns:
        The :class:`Shapes` (unconverged solves included, flagged in ``converged``).
    """
    n = measurements.n
    tips, converged, base_moment = np.zeros((n, 2)), np.zeros(n, dtype=bool), np.zeros(n)
    channel = np.zeros((n, max(design.n_channels, 1)))
    scenes: list = [None] * n
    records, section_ends, solved = None, (), {}
    for (angle, payload), rows in measurements.scenes().items():
        scene = solver.Scene(base_angle_deg=angle, payload_kg=payload, gravity=measurements.gravity)
        for k in rows:
            scenes[k] = scene
        p = measurements.pressures[rows]
        if solver.Stepper(design, scene, model=model, settings=settings).lean:
            state = None if start is None else solver.BatchState(
                pressures=p, tips=start.tips[rows], converged=start.converged[rows],
                shapes=np.empty((rows.size, 1, L.N_COLUMNS)), section_ends=start.section_ends,
                base_moment=start.base_moment[rows], channel_pressures=start.channel_pressures[rows],
                arm=design, scene=scene)
            kwargs = dict(state=state, model=model, record=backbone, settings=settings)
            policy = None if policies is None else policies["cold" if start is None else "warm"]
            if policy is None:
                out = solver.step_batch(design, p, scene, **kwargs)
            else:
                out = policy.run(partial(solver.step_batch, **kwargs),
                                 partial(_one_thread, solver.step_batch, **kwargs), rows.size, design, p,
                                 scene)
            tips[rows], converged[rows], base_moment[rows] = out.tips, out.converged, out.base_moment
            channel[rows] = out.channel_pressures
            section_ends = tuple(out.section_ends)
            if backbone:
                if records is None:
                    records = np.full((n, *out.shapes.shape[1:]), np.nan)
                records[rows] = out.shapes
            retry = rows[~out.converged] if start is None else rows[:0]
        else:
            retry = rows
        for k in retry:
            eq = solver.solve(design, measurements.pressures[k], scene, model=model, record=backbone,
                              settings=settings)
            tips[k], converged[k] = eq.tip, eq.converged
            base_moment[k] = eq.base_moment[-1] if eq.base_moment.size else np.nan
            if design.n_channels:
                channel[k] = eq.channel_pressures
            if backbone:
                section_ends = tuple(eq.section_ends)
                if records is None:
                    records = np.full((n, eq.s.size, L.N_COLUMNS), np.nan)
                solved[int(k)] = eq
    return Shapes(design, model, scenes, measurements.pressures, tips, converged, base_moment, channel,
                  records, section_ends, solved)
