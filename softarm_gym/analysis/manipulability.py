"""Manipulability and dexterity of a soft arm (thesis chapter 5, §5.2, Figs. 5.5–5.6).

The Jacobian J = ∂tip/∂p (m/Pa) of the tip position with respect to the channel pressures at
an equilibrium is taken by finite differences of warm-started solves, which follow the
quasi-static path from that equilibrium (docs/design.md §1–4), so the derivative is the one of the
branch the arm is on:

* ``method="central"`` (default): (f(p + h) − f(p − h)) / 2h, error O(h²); at a pressure
  bound, where p ± h leaves [0, p_max], the second-order one-sided formula
  (−3f(p) + 4f(p ± h) − f(p ± 2h)) / 2h pointing into the admissible range.
* ``method="richardson"``: Richardson-extrapolated one-sided differences,
  2·D(h/2) − D(h) with D(h) = (f(p ± h) − f(p)) / h, error O(h²): a different stencil,
  used to check the central differences.

Step: h = ``rel_step``·p_max with ``DEFAULT_REL_STEP`` = 1e-4 (69 Pa for OctArm V). The
truncation error of a second-order difference is ~h²·|f‴|/6 and the round-off error
~ε/h, where ε is the tip error a solve leaves (the perturbed solves use a tight Newton
tolerance, :data:`FD_SETTINGS`, so ε ~ 1e-13 m). The tip varies on the scale of p_max, so
the relative error is ~c·r² + ε/(r·p_max·|J|). Measured on OctArm V (``docs/analysis.md``,
:func:`step_study`): 2.2e-3 at r = 1e-1, 2.2e-7 at 1e-3, 2.2e-9 at 1e-4 (truncation, falling
as r²), a minimum ~2e-10 near 1e-5, then round-off: ~2e-9 at 1e-6, ~1e-7 at 1e-8.
r = 1e-4 sits a decade on the truncation side of the optimum: its error is ~1e-9, and the
round-off term stays negligible where |J| is ten times smaller than at the test point
(directions of small σ_min) or near a fold, where the step must stay small.

Measures of J with singular values σ₁ ≥ … ≥ σ_k (k = min(dim, n_inputs)):
σ_max = σ₁, σ_min = σ_k (m/Pa); manipulability = σ₁···σ_k = √det(J Jᵀ) (Yoshikawa; the
thesis's Fig. 5.5(c) plots its square root, the geometric mean, for k = 2); isotropy =
geometric mean / arithmetic mean of the σᵢ (1 when isotropic, 0 at a singularity, as the
thesis's text defines it); condition number = σ₁/σ_k.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

import solver
from softarm_gym.analysis.sweep import PressureGrid, pressure_grid
from softarm_gym.analysis.workspace import alpha_complex, sweep_inputs
from softarm_gym.jobs import Chunk, Plan, Runner, chunk_bounds

__all__ = ["jacobian", "dexterity", "Dexterity", "dexterity_map", "dexterity_plan", "DexterityMap",
           "step_study", "MEASURES", "METHODS", "DEFAULT_REL_STEP", "DEFAULT_DEXTERITY_CHUNK"]

DEFAULT_REL_STEP = 1e-4
"""Finite-difference step as a fraction of the design's rated pressure (module docstring)."""
DEFAULT_DEXTERITY_CHUNK = 64
"""Grid points per chunk of :func:`dexterity_map`: a point costs 1 + 2·n_inputs solves
(~35 ms for OctArm V), so a chunk takes ~2 s."""
METHODS = ("central", "richardson")
MEASURES = ("sigma_min", "sigma_max", "manipulability", "isotropy", "condition")
"""Dexterity measures, in the order of the thesis's Fig. 5.5 (a)–(e)."""


FD_SETTINGS = solver.Settings(tol=1e-13)
"""Solver settings of the perturbed solves: a Newton tolerance 1000× tighter than the default,
so that the tip error ε a solve leaves (~1e-10 m at the default tolerance, a 1e-4 relative
error in J at h = 1e-4·p_max) drops to ~1e-13 m. Newton converges quadratically from the
warm start, so this costs at most one more iteration."""


def _perturbed_tip(arm, eq, pressures):
    """Tip of the solve warm-started from ``eq`` at ``pressures`` (tight tolerance).

    Raises:
        solver.SolverError: the solve snapped to another branch or did not converge.
    """
    moved = solver.solve(arm, pressures, eq.scene, model=eq.model, planar=eq.planar,
                         warm_start=eq, record=False, settings=FD_SETTINGS)
    if not moved.converged or moved.snapped:
        raise solver.SolverError(
            f"the equilibrium at {np.round(pressures / solver.PSI, 4).tolist()} psi "
            f"{'snapped to another branch' if moved.snapped else 'did not converge'}: the "
            "tip is not differentiable there (a fold of the quasi-static path)")
    return moved.tip


def jacobian(arm: solver.designs.ArmDesign, eq: solver.Equilibrium, *,
             rel_step: float = DEFAULT_REL_STEP, method: str = "central") -> np.ndarray:
    """Jacobian of the tip position with respect to the input pressures at ``eq``.

    Args:
        arm: the design ``eq`` was solved for.
        eq: a converged equilibrium from :func:`solver.solve` (its scene, model and planar
            mode are reused).
        rel_step: step h as a fraction of ``arm.max_pressure``, in (0, 0.1].
        method: ``"central"`` or ``"richardson"`` (module docstring).

    Returns:
        (dim, n_inputs) ∂tip/∂p (m/Pa), dim = 2 planar or 3 spatial.

    Raises:
        ValueError: bad arguments, or ``eq`` is not a converged equilibrium of ``arm``.
        solver.SolverError: a perturbed solve snapped or failed (``eq`` sits on a fold).
    """
    if not isinstance(arm, solver.designs.ArmDesign):
        raise ValueError(f"arm must be a solver.designs.ArmDesign; got {type(arm).__name__}")
    if not isinstance(eq, solver.Equilibrium) or eq.scene is None:
        raise ValueError("eq must be an Equilibrium returned by solver.solve()")
    if not eq.converged:
        raise ValueError("eq did not converge: its Jacobian is meaningless")
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if not (isinstance(rel_step, (int, float)) and math.isfinite(rel_step) and 0 < rel_step <= 0.1):
        raise ValueError(f"rel_step must lie in (0, 0.1]; got {rel_step!r}")
    n_inputs = arm.n_inputs(eq.planar)
    if eq.pressures.shape != (n_inputs,):
        raise ValueError(f"eq has {eq.pressures.size} pressures but design {arm.name!r} takes "
                         f"{n_inputs} in {'planar' if eq.planar else 'spatial'} mode")
    p_max = arm.max_pressure
    h = rel_step * p_max
    f0 = _perturbed_tip(arm, eq, eq.pressures)  # eq re-converged to the tight tolerance
    jac = np.empty((f0.size, n_inputs))
    for j in range(n_inputs):
        unit = np.zeros(n_inputs)
        unit[j] = 1.0
        p = eq.pressures
        # Direction into the admissible range for one-sided stencils (2h must fit).
        sign = 1.0 if p[j] + 2 * h <= p_max else -1.0

        def tip(offset, unit=unit, p=p):
            return _perturbed_tip(arm, eq, np.clip(p + offset * unit, 0.0, p_max))

        if method == "central" and p[j] - h >= 0.0 and p[j] + h <= p_max:
            jac[:, j] = (tip(h) - tip(-h)) / (2 * h)
        elif method == "central":
            jac[:, j] = sign * (-3 * f0 + 4 * tip(sign * h) - tip(sign * 2 * h)) / (2 * h)
        else:
            d_h = (tip(sign * h) - f0) / h
            d_half = (tip(sign * h / 2) - f0) / (h / 2)
            jac[:, j] = sign * (2 * d_half - d_h)
    return jac


@dataclass(frozen=True)
class Dexterity:
    """Dexterity measures of one Jacobian (module docstring).

    Attributes:
        sigma: (k,) singular values, descending (m/Pa).
    """

    sigma: np.ndarray

    @property
    def sigma_max(self) -> float:
        return float(self.sigma[0])

    @property
    def sigma_min(self) -> float:
        return float(self.sigma[-1])

    @property
    def manipulability(self) -> float:
        """σ₁···σ_k = √det(J Jᵀ) ((m/Pa)^k)."""
        return float(np.prod(self.sigma))

    @property
    def isotropy(self) -> float:
        """Geometric over arithmetic mean of the singular values, in [0, 1]."""
        mean = float(np.mean(self.sigma))
        return float(np.prod(self.sigma) ** (1.0 / self.sigma.size) / mean) if mean > 0 else 0.0

    @property
    def condition(self) -> float:
        """σ_max / σ_min (inf at a singularity)."""
        return self.sigma_max / self.sigma_min if self.sigma_min > 0 else math.inf


def dexterity(jac: np.ndarray) -> Dexterity:
    """The :class:`Dexterity` measures of a (dim, n_inputs) Jacobian (m/Pa)."""
    jac = np.asarray(jac, dtype=float)
    if jac.ndim != 2 or jac.size == 0 or not np.all(np.isfinite(jac)):
        raise ValueError(f"the Jacobian must be a finite, non-empty 2-D array; got shape {jac.shape}")
    return Dexterity(np.linalg.svd(jac, compute_uv=False))


@dataclass(frozen=True)
class DexterityMap:
    """Dexterity measures at every point of a pressure grid (thesis Fig. 5.5).

    Attributes:
        design: design name.
        grid: the pressures (row k gave ``tips[k]``).
        tips: (n, 2|3) tip positions (m).
        valid: (n,) the point converged and its Jacobian exists (no fold within the step).
        sigma: (n, k) singular values, descending (m/Pa); NaN where not ``valid``.
        scene, model, planar: what was solved.
        length: arm length L (m).
        alpha: alpha-shape radius for the dexterous areas (m).
        seconds: compute time (s), the sum of the chunks' times (see
            :attr:`~softarm_gym.analysis.workspace.Workspace.seconds`).
    """

    design: str
    grid: PressureGrid
    tips: np.ndarray
    valid: np.ndarray
    sigma: np.ndarray
    scene: solver.Scene
    model: str
    planar: bool
    length: float
    alpha: float
    seconds: float = field(default=0.0, compare=False)

    @cached_property
    def _measures(self) -> dict:
        out = {name: np.full(self.tips.shape[0], np.nan) for name in MEASURES}
        for k in np.flatnonzero(self.valid):
            d = Dexterity(self.sigma[k])
            for name in MEASURES:
                out[name][k] = getattr(d, name)
        return out

    def measure(self, name: str) -> np.ndarray:
        """(n,) values of one of :data:`MEASURES` (NaN where not ``valid``)."""
        if name not in MEASURES:
            raise ValueError(f"unknown dexterity measure {name!r}; choose one of {', '.join(MEASURES)}")
        return self._measures[name]

    def dexterous_area(self, thresholds) -> np.ndarray:
        """Area (m²) of the workspace that the arm reaches with σ_min at or above each threshold.

        The alpha shape of the valid tips (radius ``alpha``, the workspace area at t = 0),
        keeping at threshold t the triangles whose three corners are reached with σ_min ≥ t
        (a corner reached by several pressure vectors counts with its best σ_min). The area
        therefore never grows with t. This is the thesis's Fig. 5.6 quantity before
        normalisation: divide by ``dexterous_area([0])`` for the fraction of the workspace,
        or by πL² for the thesis's area unit.

        Args:
            thresholds: (m,) σ_min thresholds (m/Pa).

        Returns:
            (m,) areas (m²).
        """
        t = np.asarray(thresholds, dtype=float).ravel()
        if not np.all(np.isfinite(t)):
            raise ValueError("thresholds must be finite")
        unique, inverse, triangles, areas = alpha_complex(self.tips[self.valid, :2], self.alpha)
        best = np.full(unique.shape[0], -np.inf)
        np.maximum.at(best, inverse, self.measure("sigma_min")[self.valid])
        corner_min = best[triangles].min(axis=1) if triangles.size else np.empty(0)
        return np.array([areas[corner_min >= v].sum() for v in t])

    def summary(self) -> dict:
        """The JSON payload of ``softarm dexterity`` (medians over the valid points)."""
        out = {"design": self.design, "model": self.model, "planar": self.planar,
               "base_angle_deg": self.scene.base_angle_deg, "payload_kg": self.scene.payload_kg,
               "levels": int(self.grid.levels.size), "max_psi": float(self.grid.levels[-1] / solver.PSI),
               "n": int(self.tips.shape[0]), "n_valid": int(np.count_nonzero(self.valid)),
               "length_m": self.length, "seconds": self.seconds}
        for name in MEASURES:
            values = self.measure(name)[self.valid]
            out[f"median_{name}"] = float(np.median(values)) if values.size else None
        return out


def _dexterity_rows(arm, grid, start, stop, scene, model, planar, rel_step):
    """Grid rows ``start..stop-1``: ``{"tips", "valid", "sigma"}`` (see :class:`DexterityMap`)."""
    rows = grid.rows(start, stop)
    dim = 2 if planar else 3
    tips = np.full((rows.shape[0], dim), np.nan)
    valid = np.zeros(rows.shape[0], dtype=bool)
    sigma = np.full((rows.shape[0], min(dim, grid.n_inputs)), np.nan)
    for k, p in enumerate(rows):
        eq = solver.solve(arm, p, scene, model=model, planar=planar, record=False)
        tips[k] = eq.tip
        if not eq.converged:
            continue
        try:
            sigma[k] = dexterity(jacobian(arm, eq, rel_step=rel_step)).sigma
        except solver.SolverError:
            continue
        valid[k] = True
    return {"tips": tips, "valid": valid, "sigma": sigma}


def dexterity_map(arm: solver.designs.ArmDesign, scene: solver.Scene | None = None, *,
                  levels: int = 7, max_pressure: float | None = None, model: str = "full",
                  planar: bool = True, rel_step: float = DEFAULT_REL_STEP, alpha: float | None = None,
                  backend: str = "local", chunk_size: int = DEFAULT_DEXTERITY_CHUNK,
                  address: str | None = None, progress: bool = False) -> DexterityMap:
    """Jacobian and dexterity measures at every point of the thesis's pressure grid.

    Each point is the equilibrium a cold :func:`solver.solve` returns (the one
    :func:`solver.solve_batch` returns, independent of sweep order); its Jacobian comes from
    :func:`jacobian`. Points that do not converge, or sit within a step of a fold, are
    marked not ``valid``.

    Args:
        arm, scene, model, planar: as in :func:`solver.solve` (default scene: hanging).
        levels, max_pressure: the grid (:func:`~softarm_gym.analysis.sweep.pressure_grid`).
        rel_step: finite-difference step (fraction of the rated pressure).
        alpha: alpha-shape radius for dexterous areas (m); default 0.1·L.
        backend, address: ``"local"`` or ``"ray"`` and the Ray cluster (see
            :func:`~softarm_gym.analysis.sweep.sweep_tips`).
        chunk_size: grid points per chunk (a Ray task).
        progress: progress bar on stderr.

    Returns:
        The :class:`DexterityMap`. For chunks kept on disk, resuming, or several maps under
        one progress bar, run :func:`dexterity_plan` with a :class:`~softarm_gym.jobs.Runner`.
    """
    plan = dexterity_plan(arm, scene, levels=levels, max_pressure=max_pressure, model=model,
                          planar=planar, rel_step=rel_step, alpha=alpha, chunk_size=chunk_size)
    runner = Runner(backend, address, progress=progress)
    return runner.run_plans([plan], desc=f"{arm.name} dexterity")[0]


def dexterity_plan(arm: solver.designs.ArmDesign, scene: solver.Scene | None = None, *,
                   levels: int = 7, max_pressure: float | None = None, model: str = "full",
                   planar: bool = True, rel_step: float = DEFAULT_REL_STEP,
                   alpha: float | None = None, chunk_size: int = DEFAULT_DEXTERITY_CHUNK) -> Plan:
    """The chunks of :func:`dexterity_map` (same arguments); the result is the :class:`DexterityMap`."""
    scene, alpha = sweep_inputs(arm, scene, alpha)
    if not (isinstance(rel_step, (int, float)) and math.isfinite(rel_step) and 0 < rel_step <= 0.1):
        raise ValueError(f"rel_step must lie in (0, 0.1]; got {rel_step!r}")
    grid = pressure_grid(arm, levels, max_pressure, planar)
    solver.solve_batch(arm, grid.rows(0, 1), scene, model=model, planar=planar)  # validate once
    chunks = [Chunk(_dexterity_rows, (arm, grid, a, b, scene, model, planar, float(rel_step)), b - a)
              for a, b in chunk_bounds(grid.size, chunk_size)]

    def finish(results, seconds):
        return DexterityMap(design=arm.name, grid=grid,
                            tips=np.concatenate([r["tips"] for r in results]),
                            valid=np.concatenate([r["valid"] for r in results]),
                            sigma=np.concatenate([r["sigma"] for r in results]),
                            scene=scene, model=model, planar=planar, length=arm.length,
                            alpha=float(alpha), seconds=float(sum(seconds)))
    return Plan(chunks, finish)


def step_study(arm: solver.designs.ArmDesign, eq: solver.Equilibrium, rel_steps) -> np.ndarray:
    """Relative error of the central-difference Jacobian versus the step size.

    The reference is the fourth-order Richardson combination (4·J(h) − J(2h))/3 of central
    differences at h = 1e-3·p_max: truncation ~h⁴ (~1e-12 relative) and round-off
    ~ε/(h·p_max·|J|) (~1e-9 for OctArm V), below the best a single central difference
    reaches, so the study shows where truncation (large h) and round-off (small h) take
    over. Use an interior ``eq`` (no pressure within 2e-3·p_max of a bound).

    Args:
        arm, eq: as in :func:`jacobian`.
        rel_steps: (m,) steps as fractions of the rated pressure.

    Returns:
        (m,) ‖J(h) − J_ref‖_F / ‖J_ref‖_F.
    """
    reference = (4 * jacobian(arm, eq, rel_step=1e-3) - jacobian(arm, eq, rel_step=2e-3)) / 3
    scale = np.linalg.norm(reference)
    return np.array([np.linalg.norm(jacobian(arm, eq, rel_step=float(r)) - reference) / scale
                     for r in np.asarray(rel_steps, dtype=float).ravel()])
