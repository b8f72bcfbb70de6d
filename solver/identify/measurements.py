"""What was measured, and what the model predicts for it.

A :class:`Measurements` holds n *configurations* — planar input pressures, base angle and
known payload, one row each — and any number of *observations* of them: measured values
with their standard deviations, one column per measured quantity, NaN where a configuration
was not measured. Two observations live here, :class:`TipPositions` (the tip, from a camera
or a tracker) and :class:`BackbonePoints` (markers at known reference arc lengths along the
backbone: endplates, tape marks on a photographed arm); sensor readings (cable encoders,
inclinometers, a base load cell) are the sensor models' business and live in
``softarm_gym.identify`` — any object with the :class:`Observation` interface works.

:func:`predict` solves every configuration of a design, grouped by scene, in parallel
batches (:func:`solver.solve_batch` for tips, :class:`solver.BatchStepper` where the
backbone is needed), each a cold solve: the equilibrium the arm reaches quasi-statically
from rest at those pressures, as :func:`solver.solve` defines it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

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
        tips: (n, 2) tip positions (m).
        converged: (n,) whether each solve converged.
        s: (N,) reference arc length of the backbone samples (m); empty when only tips
            were solved.
        positions: (n, N, 2) backbone samples (m).
        angles: (n, N) θ of d3 from +x (rad).
        stretch: (n, N, 2) strains (v1, v3) in the body frame.
        sources: where the equilibria come from: per scene a :class:`solver.BatchStepper`
            or a list of :class:`solver.Equilibrium` (empty when only tips were solved).
        source_rows: (n, 2) per configuration its source and its row there.
    """

    tips: np.ndarray
    converged: np.ndarray
    s: np.ndarray = field(default_factory=lambda: np.empty(0))
    positions: np.ndarray | None = None
    angles: np.ndarray | None = None
    stretch: np.ndarray | None = None
    sources: list = field(default_factory=list)
    source_rows: np.ndarray | None = None

    def equilibrium(self, k: int) -> solver.Equilibrium:
        """Configuration k's equilibrium (a recorded one, built on demand)."""
        if self.source_rows is None:
            raise ValueError("these shapes were solved for tips only; predict(..., backbone=True)")
        source, row = self.sources[self.source_rows[k, 0]], int(self.source_rows[k, 1])
        return source.equilibrium(row) if isinstance(source, solver.BatchStepper) else source[row]

    def points(self, s: np.ndarray) -> np.ndarray:
        """(n, len(s), 2) backbone positions at reference arc lengths ``s`` (m), by cubic
        Hermite interpolation between the samples (positions and tangents r' = v1·d1 + v3·d3)."""
        if self.positions is None:
            raise ValueError("these shapes were solved for tips only; predict(..., backbone=True)")
        s = np.ascontiguousarray(s, dtype=float)
        c, sn = np.cos(self.angles), np.sin(self.angles)
        v1, v3 = self.stretch[..., 0], self.stretch[..., 1]
        tangent = np.stack([v3 * c - v1 * sn, v3 * sn + v1 * c], axis=-1)  # (n, N, 2)
        out = np.empty((self.tips.shape[0], s.size, 2))
        for k in range(out.shape[0]):
            hermite_resample(self.s, np.ascontiguousarray(self.positions[k]), tangent[k], s, out[k])
        return out


def _record_fields(eq: solver.Equilibrium):
    return eq.positions, eq.angles, eq.shear_stretch


def predict(design: ArmDesign, measurements: Measurements, model: str = "full", backbone: bool = False,
            settings: Settings = DEFAULT_SETTINGS, thread_policies: dict | None = None) -> Shapes:
    """The model's equilibria at every configuration: cold solves, batched by scene.

    Args:
        design: the design to solve (checked against ``measurements`` by the caller:
            :meth:`Measurements.check`).
        measurements: the configurations (their observations are not read).
        model: as in :func:`solver.solve`.
        backbone: also return the backbones (and equilibria on demand), not only the tips.
        settings: numerical settings.
        thread_policies: a dict shared between calls, in which the batch steppers keep
            their measured choice of threads (:class:`solver.ThreadPolicy`); None: fresh.

    Returns:
        The :class:`Shapes` (unconverged solves included, flagged in ``converged``).
    """
    n = measurements.n
    tips, converged = np.empty((n, 2)), np.zeros(n, dtype=bool)
    if not backbone:
        for (angle, payload), rows in measurements.scenes().items():
            scene = solver.Scene(base_angle_deg=angle, payload_kg=payload, gravity=measurements.gravity)
            tips[rows], converged[rows] = solver.solve_batch(design, measurements.pressures[rows], scene,
                                                             model=model, settings=settings)
        return Shapes(tips, converged)
    positions = angles = stretch = grid = None
    sources, source_rows = [], np.empty((n, 2), dtype=np.int64)
    for (angle, payload), rows in measurements.scenes().items():
        scene = solver.Scene(base_angle_deg=angle, payload_kg=payload, gravity=measurements.gravity)
        p = measurements.pressures[rows]
        if solver.Stepper(design, scene, model=model, settings=settings).lean:
            batch = solver.BatchStepper(design, scene, n=rows.size, model=model, settings=settings)
            if thread_policies is not None:
                batch.thread_policies = thread_policies.setdefault(scene, batch.thread_policies)
            report = batch.reset(p)
            rec = batch.records
            ok = report.converged
            got = (rec[:, :, L.X:L.Y + 1], rec[:, :, L.THETA], rec[:, :, L.V1:L.V3 + 1])
            s = rec[0, :, L.S]
            sources.append(batch)
        else:
            eqs = [solver.solve(design, row, scene, model=model, settings=settings) for row in p]
            ok = np.array([e.converged for e in eqs])
            got = tuple(np.stack(a) for a in zip(*map(_record_fields, eqs)))
            s = eqs[0].s
            sources.append(eqs)
        source_rows[rows] = np.column_stack([np.full(rows.size, len(sources) - 1), np.arange(rows.size)])
        if positions is None:
            grid = np.array(s)
            positions, angles = np.empty((n, grid.size, 2)), np.empty((n, grid.size))
            stretch = np.empty((n, grid.size, 2))
        positions[rows], angles[rows], stretch[rows] = got
        tips[rows] = got[0][:, -1]
        converged[rows] = ok
    return Shapes(tips, converged, grid, positions, angles, stretch, sources, source_rows)
