"""Robust nonlinear least squares of a design's parameters, with uncertainty.

:func:`fit` minimises Σ ρ(((measured − predicted)/σ)²) over the asked parameters with
:func:`scipy.optimize.least_squares` (trust-region reflective, the parameters' physical bounds,
a robust loss ρ, ``soft_l1`` by default, so that a few bad measurements do not drag the fit).
The optimiser moves every parameter in units of its typical scale
(:mod:`solver.identify.parameters`).

**Predictions, and which equilibrium.** Where the arm is bistable (docs/design.md §6) the
measured arm may sit on either stable branch, as its history put it, and the cold solve
(the equilibrium reached quasi-statically from rest) jumps from one to the other as the
parameters cross a fold: an objective of cold solves alone is discontinuous there, and a
trust-region step that would cross such a cliff is refused (one of twelve recovery fits of
the tests stalled so, 14 σ from the truth). So every parameter vector is solved cold *and*
continued, warm-started, from the equilibria of the best point so far — Newton from each
configuration's base moment there, for the new design (:func:`~solver.identify.measurements.predict`
with ``start``) — and each configuration keeps the branch nearer its own measurements (the
branch is a property of the experiment's history, which the data record and the model
cannot know). Where both reach one equilibrium there is nothing to choose; the result counts
the configurations fitted on a continued branch (``optimizer["continued"]``, and per
configuration ``configurations["branch"]``). Held-out configurations are solved alongside
(outside the fit vector) and choose their branch by their own data too.

**Jacobian**: forward differences of step 1e-3 typical scales, one batched solve per
parameter, each configuration continued from its equilibrium at the base point, so that a
column is the derivative along the branch the residual was evaluated on. A step that does not
converge, or moves a tip by more than 1 % of the arm's length (another branch: a smooth change
moves it ~1e-4 of that), is taken backwards instead, and left at zero if that fails too
(counted in ``optimizer["branch_switches"]``). The batches run on numba's threads or on one,
whichever :class:`solver.ThreadPolicy` measures faster.

**Identifiability**: the singular values of the Jacobian in typical scales, J = U S Vᵀ, are
the data's information along the directions V: 1/s is the posterior standard deviation
along direction v, in typical scales. Before the fit (at the nominal design) and after it, a
direction with s < max(1e-6·s_max, 1e-4) (structurally unidentifiable: two parameters act the
same way on every measurement, or one acts on none) or 1/s > 10 (the data do not pin it to
within ten typical scales) makes the parameter that dominates it *unidentifiable*: it is named
in the result, held at its nominal value, and left out of the covariance and of the posterior;
the others are fitted.

**Uncertainty**: the covariance is (JᵀJ)⁻¹ at the solution (J modified by the robust loss,
as ``least_squares`` returns it), in the parameters' units; 95 % intervals are ±1.96 σ. With
``absolute_sigma=True`` (default) the given σ are taken as the true noise; with False the
covariance is scaled by the reduced χ², for σ that are only relative weights.

**Checks that do not trust the fit**: a χ² test of the weighted residuals (without the
robust loss) against their degrees of freedom flags a model that cannot explain the data
(wrong model variant, wrong design, or σ too small): ``misspecified`` when its p-value is
below 1e-3. Configurations held out of the fit (20 % at random by default) give the error on
unseen data, before and after the fit.
"""

from __future__ import annotations

import json
import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from solver.designs import ArmDesign, from_json
from solver.identify.measurements import Measurements, predict
from solver.identify.parameters import Parameter, apply_parameters, parse_parameters
from solver.settings import DEFAULT_SETTINGS, MODELS, Settings
from solver.stepper import BatchStepper, ThreadPolicy

__all__ = ["fit", "FitResult", "Posterior", "identifiable", "LOSSES", "FORMAT"]

LOSSES = ("linear", "soft_l1", "huber", "cauchy", "arctan")
"""Losses :func:`scipy.optimize.least_squares` offers."""
FORMAT = "softarm-fit/1"
"""The ``format`` field of a fit file."""
FD_STEP = 1e-3
"""Forward-difference step, in typical scales."""
JUMP_FRACTION = 0.01
"""A finite-difference step that moves a configuration's tip by more than this fraction of
the arm's length has crossed to another branch (a smooth change moves it ~1e-4 of that)."""
RCOND = 1e-6
"""Singular values below this fraction of the largest are structural non-identifiability."""
FD_FLOOR = 1e-4
"""...and so are those below this (σ per typical scale): the finite differences' resolution (a
parameter the planar solve ignores, GJ, still moves its converged state by ~1e-6 σ per step of
1e-3 typical scales, through the tolerance)."""
MAX_STD = 10.0
"""Directions the data leave more uncertain than this many typical scales are not identified."""
SAME_STATE = 1e-6
"""Tips nearer than this fraction of the arm's length are one equilibrium reached two ways."""
ALPHA = 1e-3
"""Level of the χ² misspecification test."""
DEFAULT_HOLDOUT = 0.2


def _num(v):
    """A float, or None for a non-finite one (JSON has no NaN)."""
    v = float(v)
    return v if math.isfinite(v) else None


def identifiable(jac: np.ndarray, names, rcond: float = RCOND, max_std: float = MAX_STD):
    """Which parameters a Jacobian identifies, by greedy elimination.

    While the weakest direction of ``jac`` (columns in typical scales) is too weak — its
    singular value s below ``rcond``·s_max or :data:`FD_FLOOR`, or 1/s above ``max_std`` — the
    parameter with the largest component in it is removed.

    Args:
        jac: (m, p) Jacobian of the weighted residuals, columns in typical scales.
        names: the p parameter names.
        rcond, max_std: thresholds (module docstring).

    Returns:
        ``(kept, dropped)``: indices of the identified parameters, and for each removed one a
        dict ``{"parameter", "reason", "with", "singular_value"}`` (``reason`` is
        ``"structural"`` or ``"practical"``; ``with`` names the parameters it is confounded with).
    """
    kept, dropped = list(range(jac.shape[1])), []
    while kept:
        a = jac[:, kept]
        if a.shape[0] < a.shape[1]:  # fewer rows than columns: pad, so that vt spans the null space
            a = np.vstack([a, np.zeros((a.shape[1] - a.shape[0], a.shape[1]))])
        _, s, vt = np.linalg.svd(a, full_matrices=False)
        weakest, v = s[-1], vt[-1]
        structural = not weakest > max(rcond * s[0], FD_FLOOR)
        if not structural and 1.0 / weakest <= max_std:
            break
        j = int(np.argmax(np.abs(v)))
        partners = [names[kept[i]] for i in range(len(kept))
                    if i != j and abs(v[i]) > 0.2 * abs(v[j])]
        dropped.append({"parameter": names[kept[j]], "reason": "structural" if structural else "practical",
                        "with": partners, "singular_value": float(weakest)})
        del kept[j]
    return kept, dropped


def robust_cost(r: np.ndarray, loss: str, f_scale: float) -> float:
    """The cost :func:`scipy.optimize.least_squares` minimises: ½·f²·Σ ρ((r/f)²), with ρ as
    scipy defines each of :data:`LOSSES`."""
    z = (np.asarray(r) / f_scale) ** 2
    rho = {"linear": lambda z: z, "soft_l1": lambda z: 2.0 * (np.sqrt(1.0 + z) - 1.0),
           "huber": lambda z: np.where(z <= 1.0, z, 2.0 * np.sqrt(z) - 1.0),
           "cauchy": np.log1p, "arctan": np.arctan}[loss](z)
    return 0.5 * f_scale**2 * float(np.sum(rho))


@dataclass
class _Evaluation:
    """The model at one parameter vector: shapes, predictions and normalised residuals of
    every configuration (NaN where unmeasured), the fit vector and its robust cost."""

    values: np.ndarray
    shapes: object
    preds: list
    z: list
    r: np.ndarray
    cost: float
    continued: np.ndarray


class _Objective:
    """The fit's weighted residuals as a function of the optimiser's variables.

    Every configuration is predicted (the held-out ones too, outside the fit vector) by a
    cold solve and, once there is a best point, also by continuation from the best point's
    equilibria; each keeps the one nearer its own measurements (module docstring). Jacobian
    columns continue from their base point's equilibria.
    """

    def __init__(self, design, params, meas: Measurements, fit_rows, model, settings, loss, f_scale,
                 progress):
        self.design, self.params, self.meas, self.fit_rows = design, params, meas, fit_rows
        self.model, self.settings, self.loss, self.f_scale = model, settings, loss, f_scale
        self.progress = progress
        self.nominal = np.array([p.nominal for p in params])
        self.scale = np.array([p.scale for p in params])
        self.active = np.arange(len(params))
        self.backbone = any(o.needs_backbone or o.needs_equilibria for o in meas.observations)
        fit_mask = np.zeros(meas.n, dtype=bool)
        fit_mask[fit_rows] = True
        # σ as weighed within each set (a reading repeated across a set's scene counts once there).
        self.sigmas = [o.sigma.copy() for o in meas.observations]
        for mask in (fit_mask, ~fit_mask):
            if mask.any():
                for sigma, part in zip(self.sigmas, meas.take(mask).effective_sigma()):
                    sigma[mask] = part
        index, start = [], 0
        for o in meas.observations:
            measured = np.isfinite(o.measured) & fit_mask[:, None]
            idx = np.full(measured.shape, -1)
            idx[measured] = np.arange(start, start + measured.sum())
            start += int(measured.sum())
            index.append(idx)
        self.index, self.m = index, start
        self.jump = JUMP_FRACTION * design.length
        self.cache: OrderedDict = OrderedDict()
        self.best: _Evaluation | None = None
        self.nominal_eval: _Evaluation | None = None
        self.nfev = self.njev = self.batches = self.switches = 0
        minimum = BatchStepper.PARALLEL_MIN
        self.policies = {"cold": ThreadPolicy(minimum), "warm": ThreadPolicy(minimum)}

    def values(self, x) -> np.ndarray:
        v = self.nominal.copy()
        v[self.active] += np.asarray(x) * self.scale[self.active]
        return v

    def solve(self, values, start=None, rows=None):
        """(shapes, predictions per observation) at ``values`` for ``rows`` (all), cold or
        continued from ``start`` (shapes of the same rows)."""
        arm = apply_parameters(self.design, self.params, values)
        meas = self.meas if rows is None else self.meas.take(rows)
        shapes = predict(arm, meas, self.model, self.backbone, self.settings, start, self.policies)
        self.batches += 1
        return shapes, self.predictions(arm, shapes, meas)

    @staticmethod
    def predictions(arm, shapes, meas) -> list:
        """Per observation of ``meas`` its (n, k) predictions from ``shapes``."""
        preds = []
        for o in meas.observations:
            p = np.asarray(o.predict(shapes, arm), dtype=float)
            bad = ~np.all(np.isfinite(p), axis=1) & shapes.converged
            if bad.any():
                raise ValueError(f"observation {o.name!r} predicts a non-finite value for configuration "
                                 f"{int(np.flatnonzero(bad)[0])}")
            preds.append(p)
        return preds

    def normalized(self, preds, rows=None) -> list:
        """Per observation (rows, k) (measured − predicted)/σ, NaN where unmeasured."""
        rows = slice(None) if rows is None else rows
        return [(o.measured[rows] - p) / sigma[rows]
                for o, sigma, p in zip(self.meas.observations, self.sigmas, preds)]

    def vector(self, z, rows=None) -> np.ndarray:
        """The fit vector of normalised residuals ``z`` of ``rows`` (all; NaN outside them)."""
        r = np.full(self.m, np.nan)
        for idx, zo in zip(self.index, z):
            sel = idx if rows is None else idx[rows]
            ok = sel >= 0
            r[sel[ok]] = zo[ok]
        return r

    def evaluate(self, x) -> _Evaluation:
        values = self.values(x)
        key = values.tobytes()
        if key in self.cache:
            self.cache.move_to_end(key)
            return self.cache[key]
        shapes, preds = self.solve(values)
        z = self.normalized(preds)
        continued = np.zeros(self.meas.n, dtype=bool)
        if self.best is not None:
            arm = shapes.design
            warm = predict(arm, self.meas, self.model, self.backbone, self.settings, self.best.shapes,
                           self.policies)
            self.batches += 1
            # Where both reach the same equilibrium (to far below the solver's tolerance) there
            # is nothing to choose; elsewhere each configuration keeps the branch nearer its data.
            other = np.flatnonzero(warm.converged & (np.hypot(*(warm.tips - shapes.tips).T) > SAME_STATE
                                                     * self.design.length))
            if other.size:
                warm_preds = self.predictions(arm, warm.take(other), self.meas.take(other))
                zw = self.normalized(warm_preds, other)
                better = _sse(zw) < _sse([zo[other] for zo in z])
                continued[other[better]] = True
                shapes = shapes.where(continued, warm)
                for k, (pw, zwo) in enumerate(zip(warm_preds, zw)):
                    preds[k][other[better]] = pw[better]
                    z[k][other[better]] = zwo[better]
        r = self.vector(z)
        ev = _Evaluation(values, shapes, preds, z, r, robust_cost(r, self.loss, self.f_scale), continued)
        self.cache[key] = ev
        if len(self.cache) > 4:
            self.cache.popitem(last=False)
        if self.nominal_eval is None:
            self.nominal_eval = ev
        if self.best is None or ev.cost < self.best.cost:
            self.best = ev
        self.nfev += 1
        if self.progress is not None:
            self.progress({"evaluations": self.batches, "jacobians": self.njev, "cost": ev.cost})
        return ev

    def residuals(self, x) -> np.ndarray:
        return self.evaluate(x).r

    def jacobian(self, x, lower=None, upper=None) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        base = self.evaluate(x)
        rows = self.fit_rows
        start = base.shapes.take(rows)
        jac = np.empty((self.m, x.size))
        for j in range(x.size):
            h = FD_STEP if upper is None or x[j] + FD_STEP <= upper[j] else -FD_STEP
            col = self._column(x, j, h, rows, start, base)
            bad = col[1]
            if bad.size:
                self.switches += bad.size
                col = self._column(x, j, -h, bad, base.shapes.take(bad), base, col[0])
            jac[:, j] = col[0]
        self.njev += 1
        if self.progress is not None:
            self.progress({"evaluations": self.batches, "jacobians": self.njev, "cost": base.cost})
        return jac

    def _column(self, x, j, h, rows, start, base, col=None):
        """A forward (h > 0) or backward difference for configurations ``rows``, continued from
        the base point's equilibria ``start``: (the column, the rows whose step did not
        converge or jumped branch — their entries are 0 in it)."""
        col = np.zeros(self.m) if col is None else col
        xj = x.copy()
        xj[j] += h
        if not self._inside(xj[j], j):
            return col, rows[:0]
        shapes, preds = self.solve(self.values(xj), start=start, rows=rows)
        z = self.normalized(preds, rows)
        moved = np.hypot(*(shapes.tips - base.shapes.tips[rows]).T)
        smooth = shapes.converged & (moved <= self.jump)
        r = self.vector([np.where(smooth[:, None], zo, np.nan) for zo in z], rows)
        ok = np.isfinite(r)
        col[ok] = (r[ok] - base.r[ok]) / h
        return col, rows[~smooth]

    def _inside(self, value, j) -> bool:
        k = self.active[j]
        p = self.params[k]
        return p.lower <= self.nominal[k] + value * self.scale[k] <= p.upper


def _sse(z) -> np.ndarray:
    """(n,) per configuration Σ z² over every measured value."""
    return sum(np.nansum(zo**2, axis=1) for zo in z)


@dataclass(frozen=True)
class Posterior:
    """The fitted parameters' distribution: a multivariate normal, clipped to their bounds.

    Attributes:
        design: the design the parameters were fitted from (samples are built from it).
        parameters: the identified parameters.
        mean: (p,) their fitted values.
        covariance: (p, p) their covariance (units of the parameters).
    """

    design: ArmDesign
    parameters: tuple[Parameter, ...]
    mean: np.ndarray
    covariance: np.ndarray

    def __post_init__(self):
        p = len(self.parameters)
        mean = np.array(self.mean, dtype=float).reshape(-1)
        cov = np.array(self.covariance, dtype=float)
        finite = np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))
        if mean.shape != (p,) or cov.shape != (p, p) or not finite:
            raise ValueError(f"a posterior of {p} parameters needs a finite mean ({p},) and covariance "
                             f"({p}, {p}); got {mean.shape} and {cov.shape}")
        if p and (not np.allclose(cov, cov.T, rtol=1e-10, atol=0) or np.linalg.eigvalsh(cov).min() <
                  -1e-10 * max(np.abs(cov).max(), 1e-300)):
            raise ValueError("the posterior covariance must be symmetric positive semi-definite")
        w, q = np.linalg.eigh(0.5 * (cov + cov.T))
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "_factor", q * np.sqrt(np.clip(w, 0.0, None)))

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    def sample_values(self, rng: np.random.Generator, size: int | None = None,
                      widen: float = 1.0) -> np.ndarray:
        """Parameter values drawn from N(mean, widen²·covariance), clipped to the bounds.

        Args:
            rng: the only source of randomness.
            size: number of draws (None: one, shape (p,)).
            widen: standard-deviation factor (1: the posterior as fitted).

        Returns:
            (p,) or (size, p) values.
        """
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
        z = rng.standard_normal((1 if size is None else int(size), len(self.parameters)))
        x = np.clip(self.mean + widen * z @ self._factor.T, self.lower, self.upper)
        return x[0] if size is None else x

    def sample(self, rng: np.random.Generator, widen: float = 1.0) -> ArmDesign:
        """One design drawn from the posterior (:meth:`sample_values`)."""
        return apply_parameters(self.design, self.parameters, self.sample_values(rng, widen=widen))

    @property
    def mean_design(self) -> ArmDesign:
        """The design at the posterior mean (the fitted design)."""
        return apply_parameters(self.design, self.parameters, self.mean)

    def to_dict(self) -> dict:
        """Plain JSON values (the ``posterior`` entry of a fit file)."""
        return {"design": json.loads(self.design.to_json()),
                "parameters": [p.to_dict() for p in self.parameters],
                "mean": self.mean.tolist(), "covariance": self.covariance.tolist()}

    @classmethod
    def from_dict(cls, data) -> Posterior:
        """Inverse of :meth:`to_dict`, validated (one-line ``ValueError``)."""
        if not isinstance(data, dict) or set(data) != {"design", "parameters", "mean", "covariance"}:
            raise ValueError("a posterior must be a JSON object with design, parameters, mean and covariance")
        design = from_json(json.dumps(data["design"]))
        if not isinstance(data["parameters"], list):
            raise ValueError("posterior parameters must be a list")
        params = tuple(Parameter.from_dict(p) for p in data["parameters"])
        try:
            return cls(design, params, np.asarray(data["mean"], dtype=float),
                       np.asarray(data["covariance"], dtype=float))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"posterior: {exc}") from None

    @classmethod
    def load(cls, path) -> Posterior:
        """The posterior of a fit file (written from :meth:`FitResult.to_dict`).

        Raises:
            OSError: the file cannot be read.
            ValueError: it is not a fit file, or its posterior is invalid (one line).
        """
        with open(path, "rb") as fh:
            raw = fh.read(64_000_000)
        try:
            data = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as exc:
            raise ValueError(f"{path}: not a JSON fit file ({exc})") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT or "posterior" not in data:
            raise ValueError(f"{path}: not a fit file (format {FORMAT!r} with a posterior)")
        return cls.from_dict(data["posterior"])


@dataclass(frozen=True)
class FitResult:
    """What :func:`fit` found.

    Attributes:
        design, fitted_design: the design fitted from, and with the fitted values.
        parameters: the parameters asked for.
        values: (p,) fitted values (nominal for an unidentifiable parameter).
        std: (p,) standard deviations (NaN for an unidentifiable parameter).
        covariance: (p, p) covariance (NaN rows and columns for unidentifiable ones).
        identified: (p,) bool.
        unidentifiable: one dict per parameter held at nominal or not identified at the
            solution (:func:`identifiable`), with ``stage`` ``"nominal"`` or ``"solution"``.
        singular_values: of the Jacobian at the solution, in typical scales (identified
            parameters).
        chi_square: the χ² test: ``{"statistic", "dof", "reduced", "p_value",
            "misspecified", "robust_scale", "by_observation"}``.
        holdout: error on the held-out configurations, before and after the fit (None
            without a hold-out set).
        configurations: per configuration: index, split, converged, the branch it was fitted
            on (``"cold"`` or ``"continued"``), and the error in metres of each position
            observation, nominal and fitted (columns as lists).
        residuals: per measured value: configuration, split, observation, quantity, unit,
            measured, sigma (as weighed: :meth:`Measurements.effective_sigma`), nominal, fitted,
            normalized (= (measured − fitted)/sigma).
        optimizer: success, status, message, residual evaluations, Jacobians, solve batches,
            Jacobian steps that switched branch, configurations on a continued branch, the
            unconverged configurations at the solution, fit-set size, seconds.
        model, loss, f_scale, absolute_sigma: how it was fitted.
        measurements: the data (not written to the fit file).
    """

    design: ArmDesign
    fitted_design: ArmDesign
    parameters: tuple[Parameter, ...]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    identified: np.ndarray
    unidentifiable: tuple
    singular_values: np.ndarray
    chi_square: dict
    holdout: dict | None
    configurations: dict
    residuals: dict
    optimizer: dict
    model: str
    loss: str
    f_scale: float
    absolute_sigma: bool
    measurements: Measurements = field(repr=False, compare=False)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def interval(self, level: float = 0.95) -> np.ndarray:
        """(p, 2) normal confidence intervals (NaN for unidentifiable parameters)."""
        from scipy import stats  # (seconds to import: only where a fit is used)

        z = float(stats.norm.ppf(0.5 + level / 2.0))
        return np.column_stack([self.values - z * self.std, self.values + z * self.std])

    @property
    def correlation(self) -> np.ndarray:
        """(p, p) correlation matrix of the fitted parameters."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.covariance / np.outer(self.std, self.std)

    @property
    def at_bound(self) -> np.ndarray:
        """(p,) whether a fitted value sits on its bound (its interval is then unreliable)."""
        lo = np.array([p.lower for p in self.parameters])
        hi = np.array([p.upper for p in self.parameters])
        tol = 1e-6 * np.array([p.scale for p in self.parameters])
        return self.identified & ((self.values - lo <= tol) | (hi - self.values <= tol))

    def posterior(self) -> Posterior:
        """The identified parameters' posterior, for domain randomisation."""
        keep = np.flatnonzero(self.identified)
        return Posterior(self.design, tuple(self.parameters[k] for k in keep), self.values[keep],
                         self.covariance[np.ix_(keep, keep)])

    def to_dict(self) -> dict:
        """Plain JSON values (non-finite numbers as None): the fit file."""
        ci = self.interval()
        params = []
        for k, p in enumerate(self.parameters):
            params.append({**p.to_dict(), "value": self.values[k], "std": _num(self.std[k]),
                           "ci95": [_num(ci[k, 0]), _num(ci[k, 1])], "identified": bool(self.identified[k]),
                           "at_bound": bool(self.at_bound[k])})
        cov = [[_num(v) for v in row] for row in self.covariance]
        s = self.singular_values
        return {"format": FORMAT, "model": self.model, "loss": self.loss, "f_scale": self.f_scale,
                "absolute_sigma": self.absolute_sigma,
                "design": json.loads(self.design.to_json()),
                "fitted_design": json.loads(self.fitted_design.to_json()),
                "parameters": params, "covariance": cov,
                "identifiability": {"singular_values": s.tolist(),
                                    "condition_number": _num(s[0] / s[-1]) if s.size else None,
                                    "unidentifiable": list(self.unidentifiable)},
                "chi_square": self.chi_square, "holdout": self.holdout, "optimizer": self.optimizer,
                "posterior": self.posterior().to_dict(),
                "configurations": self.configurations, "residuals": self.residuals}

    def summary(self) -> str:
        """A few lines for people: the parameters with intervals, then the checks."""
        opt = self.optimizer
        count = f"{len(self.parameters)} parameter{'s' if len(self.parameters) != 1 else ''}"
        lines = [f"{self.design.name}: {count} fitted to {opt['fit_values']} "
                 f"values of {opt['fit_configurations']} configurations ({self.model} model, {self.loss} "
                 f"loss) in {opt['seconds']:.2f} s",
                 f"{'parameter':22s} {'nominal':>12s} {'fitted':>12s} {'std':>10s}   95 % interval"]
        ci = self.interval()
        for k, p in enumerate(self.parameters):
            if self.identified[k]:
                flag = "  (at bound)" if self.at_bound[k] else ""
                lines.append(f"{p.name:22s} {p.nominal:12.6g} {self.values[k]:12.6g} {self.std[k]:10.3g}   "
                             f"[{ci[k, 0]:.6g}, {ci[k, 1]:.6g}] {p.unit}{flag}")
            else:
                lines.append(f"{p.name:22s} {p.nominal:12.6g} {'held':>12s} {'-':>10s}   not identified")
        for u in self.unidentifiable:
            partner = f", confounded with {', '.join(u['with'])}" if u["with"] else ""
            lines.append(f"  unidentifiable ({u['reason']}, at the {u['stage']}): {u['parameter']}{partner}")
        c = self.chi_square
        verdict = "MISSPECIFIED: the model does not explain the data" if c["misspecified"] else "consistent"
        lines.append(f"chi-square {c['statistic']:.1f} on {c['dof']} dof (reduced {c['reduced']:.3g}, "
                     f"p = {c['p_value']:.3g}): {verdict}")
        if self.holdout:
            for name, h in self.holdout["observations"].items():
                if h.get("mean_error_m") is not None:
                    lines.append(f"held out ({self.holdout['configurations']} configurations), {name}: mean "
                                 f"error {1e3 * h['nominal']['mean_error_m']:.1f} mm nominal -> "
                                 f"{1e3 * h['mean_error_m']:.1f} mm fitted")
                lines.append(f"held out, {name}: RMS normalized residual {h['nominal']['rms_normalized']:.3g}"
                             f" nominal -> {h['rms_normalized']:.3g} fitted")
        if self.optimizer["unconverged"]:
            lines.append(f"WARNING: {len(self.optimizer['unconverged'])} configurations have no converged "
                         f"equilibrium at the solution: {self.optimizer['unconverged'][:10]}")
        if not self.optimizer["success"]:
            lines.append(f"WARNING: the optimiser stopped without converging: {self.optimizer['message']}")
        return "\n".join(lines)


def _split(meas: Measurements, holdout, seed) -> np.ndarray:
    """(n,) bool: the held-out configurations."""
    n = meas.n
    if holdout is None:
        if meas.holdout is not None:
            return meas.holdout.copy()
        holdout = DEFAULT_HOLDOUT
    if isinstance(holdout, (float, int)) and not isinstance(holdout, bool):
        if not 0.0 <= holdout < 1.0:
            raise ValueError(f"holdout must be a fraction in [0, 1) or a bool mask; got {holdout!r}")
        mask = np.zeros(n, dtype=bool)
        mask[np.random.default_rng(seed).permutation(n)[:int(round(holdout * n))]] = True
        return mask
    mask = np.asarray(holdout)
    if mask.shape != (n,) or mask.dtype != bool:
        raise ValueError(f"holdout must be a fraction in [0, 1) or a ({n},) bool mask; got {holdout!r}")
    return mask.copy()


def _table(meas: Measurements, sigmas, rows, split: str, preds_nominal, preds_fitted) -> dict:
    cols: dict[str, list] = {k: [] for k in ("configuration", "split", "observation", "quantity", "unit",
                                             "measured", "sigma", "nominal", "fitted", "normalized")}
    for o, sigma, pn, pf in zip(meas.observations, sigmas, preds_nominal, preds_fitted):
        mask = np.isfinite(o.measured)
        r, c = np.nonzero(mask)
        cols["configuration"] += rows[r].tolist()
        cols["split"] += [split] * r.size
        cols["observation"] += [o.name] * r.size
        cols["quantity"] += [o.labels[j] for j in c]
        cols["unit"] += [o.units[j] for j in c]
        cols["measured"] += o.measured[mask].tolist()
        cols["sigma"] += sigma[mask].tolist()
        cols["nominal"] += pn[mask].tolist()
        cols["fitted"] += pf[mask].tolist()
        cols["normalized"] += ((o.measured - pf) / sigma)[mask].tolist()
    return cols


def _merge(a: dict, b: dict) -> dict:
    return {k: a[k] + b[k] for k in a}


def _distances(meas: Measurements, preds) -> dict[str, np.ndarray]:
    """Per position observation, (n,) the error in metres per configuration (NaN where a
    configuration has nothing measured)."""
    out = {}
    for o, p in zip(meas.observations, preds):
        d = o.distances(o.measured - p)
        if d is not None:
            out[o.name] = d
    return out


def _set_summary(meas: Measurements, sigmas, preds_nominal, preds_fitted) -> dict:
    """Per observation: RMS normalized residual and mean position error, nominal and fitted."""
    out = {}
    for o, sigma, pn, pf in zip(meas.observations, sigmas, preds_nominal, preds_fitted):
        entry = {}
        for key, p in (("fitted", pf), ("nominal", pn)):
            z = ((o.measured - p) / sigma)[np.isfinite(o.measured)]
            d = o.distances(o.measured - p)
            d = d[np.isfinite(d)] if d is not None else None
            stats_ = {"rms_normalized": _num(np.sqrt(np.mean(z**2))) if z.size else None,
                      "chi_square": _num(np.sum(z**2)), "values": int(z.size),
                      "mean_error_m": _num(np.mean(d)) if d is not None and d.size else None,
                      "rms_error_m": _num(np.sqrt(np.mean(d**2))) if d is not None and d.size else None}
            if key == "fitted":
                entry.update(stats_)
            else:
                entry["nominal"] = stats_
        out[o.name] = entry
    return out


def fit(design: ArmDesign, measurements: Measurements, parameters, *, model: str = "full",
        loss: str = "soft_l1", f_scale: float = 3.0, holdout=None, seed: int = 0,
        absolute_sigma: bool = True, max_nfev: int = 60, settings: Settings = DEFAULT_SETTINGS,
        progress=None) -> FitResult:
    """Fit ``parameters`` of ``design`` to ``measurements``.

    Args:
        design: the nominal design (the starting point, and the prior's centre).
        measurements: configurations and observations (:class:`Measurements`).
        parameters: names (``"wind_angle:s1,E"`` or a list; :mod:`solver.identify.parameters`).
        model: the solver model predictions use (:data:`solver.MODELS`).
        loss: robust loss of ``least_squares`` (:data:`LOSSES`).
        f_scale: where the loss turns robust, in standard deviations of the noise.
        holdout: configurations kept out of the fit: a fraction chosen at random with
            ``seed``, a (n,) bool mask, or None (``measurements.holdout`` if set, else 20 %).
        seed: seeds the random hold-out choice.
        absolute_sigma: take the observations' σ as the true noise (else as relative weights:
            the covariance is scaled by the reduced χ²).
        max_nfev: most residual evaluations of the optimiser.
        settings: numerical settings of the solves.
        progress: called after every batch evaluation with
            ``{"evaluations", "jacobians", "cost"}`` (e.g. to move a progress bar).

    Returns:
        The :class:`FitResult`.

    Raises:
        ValueError: (one line) unknown parameters, a model or loss name, measurements the
            design cannot take, or too few measured values for the parameters.
    """
    # One BLAS thread: the fit's algebra is small (SVDs of m × p), and BLAS threads that wait on
    # the batch solves' threads made each SVD ~100x slower on a 2-core machine.
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit(design, measurements, parameters, model, loss, f_scale, holdout, seed, absolute_sigma,
                    max_nfev, settings, progress)


def _fit(design, measurements, parameters, model, loss, f_scale, holdout, seed, absolute_sigma, max_nfev,
         settings, progress) -> FitResult:
    from scipy import optimize, stats  # (seconds to import: not on `import solver.identify`)

    start = time.perf_counter()
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}; choose one of {', '.join(LOSSES)}")
    if not (isinstance(f_scale, (int, float)) and math.isfinite(f_scale) and f_scale > 0):
        raise ValueError(f"f_scale must be a finite number > 0; got {f_scale!r}")
    if isinstance(max_nfev, bool) or not isinstance(max_nfev, int) or max_nfev < 1:
        raise ValueError(f"max_nfev must be an integer >= 1; got {max_nfev!r}")
    if not isinstance(measurements, Measurements):
        raise ValueError("measurements must be a solver.identify.Measurements; got "
                         f"{type(measurements).__name__}")
    params = parse_parameters(design, parameters)
    measurements.check(design)
    held = _split(measurements, holdout, seed)
    fit_rows, held_rows = np.flatnonzero(~held), np.flatnonzero(held)
    train = measurements.take(fit_rows)
    m, p = train.n_values, len(params)
    if m <= p:
        raise ValueError(f"{m} measured values in the fit set ({fit_rows.size} configurations) cannot "
                         f"determine {p} parameters; need at least {p + 1}")
    names = [q.name for q in params]
    nominal = np.array([q.nominal for q in params])
    scale = np.array([q.scale for q in params])
    lower = (np.array([q.lower for q in params]) - nominal) / scale
    upper = (np.array([q.upper for q in params]) - nominal) / scale

    # Identifiability at the nominal design: name what the data cannot determine, fit the rest.
    objective = _Objective(design, params, measurements, fit_rows, model, settings, loss, f_scale, progress)
    kept, dropped = identifiable(objective.jacobian(np.zeros(p), lower, upper), names)
    unidentifiable = [{**d, "stage": "nominal"} for d in dropped]
    active = np.array(kept, dtype=np.int64)
    objective.active = active
    values = nominal.copy()
    cov = np.full((p, p), np.nan)
    singular = np.empty(0)
    result = None
    if active.size:
        lo, hi = lower[active], upper[active]
        result = optimize.least_squares(
            objective.residuals, np.zeros(active.size), jac=lambda x: objective.jacobian(x, lo, hi),
            bounds=(lo, hi), method="trf", loss=loss, f_scale=f_scale, x_scale=1.0, max_nfev=max_nfev)
        values = objective.values(result.x)
        jac = result.jac
        kept2, dropped2 = identifiable(jac, [names[k] for k in active])
        unidentifiable += [{**d, "stage": "solution"} for d in dropped2]
        final = active[kept2]
        if kept2:
            u, s, vt = np.linalg.svd(jac[:, kept2], full_matrices=False)
            singular = s
            cov_x = (vt.T / s**2) @ vt
            dof = m - final.size
            if not absolute_sigma:
                cov_x = cov_x * (2.0 * result.cost / dof)
            cov[np.ix_(final, final)] = cov_x * np.outer(scale[final], scale[final])
    identified = np.isfinite(np.diag(cov))
    std = np.sqrt(np.diag(cov))

    # Residuals, nominal and fitted, on both sets; the χ² test on the fit set.
    fitted_design = from_json(apply_parameters(design, params, values).to_json())
    before = objective.nominal_eval
    after = objective.evaluate((values - nominal)[active] / scale[active]) if active.size else before
    unconverged = np.flatnonzero(~after.shapes.converged).tolist()
    residual_cols, per_config, summaries = None, {}, {}
    for split, rows in (("fit", fit_rows), ("holdout", held_rows)):
        if not rows.size:
            continue
        meas = measurements.take(rows)
        sigmas = [sigma[rows] for sigma in objective.sigmas]
        pn, pf = [q[rows] for q in before.preds], [q[rows] for q in after.preds]
        cols = _table(meas, sigmas, rows, split, pn, pf)
        residual_cols = cols if residual_cols is None else _merge(residual_cols, cols)
        summaries[split] = _set_summary(meas, sigmas, pn, pf)
        dn, df = _distances(meas, pn), _distances(meas, pf)
        per_config.setdefault("configuration", []).extend(rows.tolist())
        per_config.setdefault("split", []).extend([split] * rows.size)
        per_config.setdefault("converged", []).extend(after.shapes.converged[rows].tolist())
        per_config.setdefault("branch", []).extend(
            ["continued" if c else "cold" for c in after.continued[rows]])
        for name in dn:
            per_config.setdefault(f"{name}_error_nominal_m", []).extend(map(_num, dn[name]))
            per_config.setdefault(f"{name}_error_fitted_m", []).extend(map(_num, df[name]))
    z = np.array(residual_cols["normalized"])[np.array(residual_cols["split"]) == "fit"]
    n_fitted = int(identified.sum())
    dof = m - n_fitted
    statistic = float(np.sum(z**2))
    p_value = float(stats.chi2.sf(statistic, dof))
    chi = {"statistic": statistic, "dof": dof, "reduced": statistic / dof, "p_value": p_value,
           "misspecified": bool(p_value < ALPHA), "alpha": ALPHA,
           "robust_scale": float(np.median(np.abs(z)) / stats.norm.ppf(0.75)),
           "by_observation": {name: {"chi_square": s["chi_square"], "values": s["values"]}
                              for name, s in summaries["fit"].items()}}
    held_summary = None
    if "holdout" in summaries:
        held_summary = {"configurations": int(held_rows.size), "observations": summaries["holdout"]}
    optimizer = {"success": bool(result.status > 0) if result is not None else True,
                 "status": int(result.status) if result is not None else 0,
                 "message": result.message if result is not None else "nothing identifiable to fit",
                 "evaluations": objective.nfev, "jacobians": objective.njev,
                 "solve_batches": objective.batches, "branch_switches": objective.switches,
                 "continued": int(after.continued.sum()), "unconverged": unconverged,
                 "fit_configurations": int(fit_rows.size), "fit_values": int(m),
                 "fit": summaries["fit"], "seconds": time.perf_counter() - start}
    return FitResult(design=design, fitted_design=fitted_design, parameters=params, values=values, std=std,
                     covariance=cov, identified=identified, unidentifiable=tuple(unidentifiable),
                     singular_values=singular, chi_square=chi, holdout=held_summary,
                     configurations=per_config, residuals=residual_cols, optimizer=optimizer, model=model,
                     loss=loss, f_scale=float(f_scale), absolute_sigma=bool(absolute_sigma),
                     measurements=measurements)
