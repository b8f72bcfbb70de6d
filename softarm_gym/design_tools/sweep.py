"""Optimal configurations (thesis §3.3–3.4, Appendix B): exhaustive search over tube counts.

For every candidate layout (tubes per section drawn from {3, 6, 9, 12}, Eq. 3.12) and every
value of the swept size, the tube outer radius follows from the constraint case, the wall
thickness and section lengths from the dexterity template (:mod:`.template`), and the load
capacity from the solver (:mod:`.capacity`). The best layout at each size is the one with
the largest load capacity. The (size, layout) pairs are evaluated in chunks of
:data:`DEFAULT_DESIGN_CHUNK` through :class:`softarm_gym.jobs.Runner` (locally or on Ray,
resumable); each evaluation is independent, so the result does not depend on the chunking.

Constraint cases, all read with β = 0.09 as a *diameter* ratio (the thesis writes
``R_o = βL`` but calls R "diameter" throughout §3 and quotes "base diameter/length = 0.09";
the internal volumes of §3.4.3 confirm the diameter reading, see ``docs/design_tools.md``):

* ``tube-ratio`` (§3.4.2, Figs. 3.4–3.5): tube diameter 2Ro = β·L; sweep L.
* ``base-ratio`` (§3.4.3, Figs. B.5–B.6): overall diameter max 2(δ_i + Ro) = β·L, with
  δ = Ro/sin(π/N_t) the tube ring radius — the base section's for a tapered arm (Fig. B.5's
  caption says "overall diameter/length"; reading it as the base section alone would let a
  middle section bulge wider than the base); sweep L.
* ``diameter`` (Appendix B.1, Fig. B.3): the widest section's diameter max 2(δ_i + Ro) fixed
  at β × the Table 3.1 length (0.09 m); sweep L.
* ``gripping-radius`` (Appendix B.3, Figs. B.1–B.2): Ro from Table 3.1 (15 mm), the distal
  section length L_N fixed (its 360° wrap sets the gripping radius L_N/2π); sweep L_N.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import asdict, dataclass, replace

import numpy as np

import solver
from softarm_gym.design_tools.capacity import CapacityError, load_capacity
from softarm_gym.design_tools.template import (
    TUBE_COUNTS,
    InfeasibleDesign,
    build_arm,
    template,
)
from softarm_gym.jobs import Chunk, Plan, Runner, chunk_bounds
from solver.designs import FluidDesign

__all__ = [
    "CONSTRAINTS", "FLUIDS", "TEMPLATE_PRESSURES", "DEFAULT_SIZES", "Candidate", "Sweep",
    "fluid_params", "configurations", "outer_radius", "evaluate", "sweep", "sweep_plan",
    "DEFAULT_DESIGN_CHUNK",
]

CONSTRAINTS = ("tube-ratio", "base-ratio", "diameter", "gripping-radius")
FLUIDS = {"pneumatic": solver.designs.PNEUMATIC, "hydraulic": solver.designs.HYDRAULIC}
TEMPLATE_PRESSURES = ("max", "test")
"""Pressure of the dexterity template: p_max as Eq. (3.3) says, or p_test (see docs)."""

DEFAULT_SIZES = {
    "tube-ratio": tuple(np.round(np.arange(0.25, 4.001, 0.25), 3)),
    "base-ratio": tuple(np.round(np.arange(0.25, 4.001, 0.25), 3)),
    "diameter": tuple(np.round(np.arange(0.25, 4.001, 0.25), 3)),
    "gripping-radius": tuple(np.round(np.arange(0.1, 1.001, 0.1), 3)),
}
"""Swept size per constraint: total length L (m), or distal length L_N for gripping-radius."""
DEFAULT_DESIGN_CHUNK = 128
"""(size, layout) evaluations per chunk: one takes ~8 ms, so a chunk ~1 s."""


@dataclass(frozen=True)
class Candidate:
    """One layout at one size.

    Attributes:
        tubes: tubes per section, base to tip.
        size: the swept value (total length, or distal length for gripping-radius) (m).
        feasible: the template could be met (else only ``reason`` is meaningful).
        length_m: total reference length (m).
        section_lengths_m: reference length of each section (m).
        thickness_m, outer_radius_m: tube wall thickness and outer radius (m).
        mass_kg: arm mass including fluid (kg).
        internal_volume_l: fluid volume of all tubes (litres).
        load_n: load capacity W (N); negative: cannot lift itself to horizontal.
        tip_x_m: horizontal tip position under W (m); < 0: the tip ends behind the base.
        fold_limited, converged: see :class:`~.capacity.LoadCapacity`.
        reason: why the layout is infeasible, or why its load capacity could not be found
            ("" otherwise).
    """

    tubes: tuple[int, ...]
    size: float
    feasible: bool
    length_m: float = math.nan
    section_lengths_m: tuple[float, ...] = ()
    thickness_m: float = math.nan
    outer_radius_m: float = math.nan
    mass_kg: float = math.nan
    internal_volume_l: float = math.nan
    load_n: float = math.nan
    tip_x_m: float = math.nan
    fold_limited: bool = False
    converged: bool = False
    reason: str = ""

    def to_dict(self) -> dict:
        """A JSON-ready dict (NaN → None)."""
        return {k: (None if isinstance(v, float) and math.isnan(v) else v)
                for k, v in asdict(self).items()}


@dataclass(frozen=True)
class Sweep:
    """Result of :func:`sweep`.

    Attributes:
        fluid, constraint, n_sections, template_pressure: what was swept.
        params: the Table 3.1 parameters used.
        sizes: (n_sizes,) swept values (m).
        configurations: the layouts tried.
        candidates: ``candidates[i][j]``: layout j at size i.
    """

    fluid: str
    constraint: str
    n_sections: int
    template_pressure: str
    params: FluidDesign
    sizes: tuple[float, ...]
    configurations: tuple[tuple[int, ...], ...]
    candidates: tuple[tuple[Candidate, ...], ...]

    def best_at(self, i: int) -> Candidate | None:
        """The feasible layout with the largest load capacity at size index ``i``."""
        ok = [c for c in self.candidates[i] if c.feasible and c.converged]
        return max(ok, key=lambda c: c.load_n) if ok else None

    @property
    def best_per_size(self) -> tuple[Candidate | None, ...]:
        """:meth:`best_at` for every size."""
        return tuple(self.best_at(i) for i in range(len(self.sizes)))

    @property
    def best(self) -> Candidate | None:
        """The best layout over all sizes (None if nothing was feasible)."""
        ok = [c for c in self.best_per_size if c is not None]
        return max(ok, key=lambda c: c.load_n) if ok else None

    def to_dict(self) -> dict:
        """JSON-ready summary: best overall, best per size and every candidate."""
        best = self.best
        return {
            "fluid": self.fluid, "constraint": self.constraint, "sections": self.n_sections,
            "template_pressure": self.template_pressure,
            "youngs_modulus_pa": self.params.youngs_modulus,
            "best": None if best is None else {
                "tubes": list(best.tubes), "length_m": best.length_m, "load_n": best.load_n,
                "size": best.size, "thickness_m": best.thickness_m,
                "section_lengths_m": list(best.section_lengths_m)},
            "best_per_size": [None if c is None else c.to_dict() for c in self.best_per_size],
            "sweep": [c.to_dict() for row in self.candidates for c in row],
        }


def fluid_params(fluid: str, youngs_modulus: float | None = None) -> FluidDesign:
    """Table 3.1 parameters of ``fluid``, optionally with another Young's modulus (Pa)."""
    if fluid not in FLUIDS:
        raise ValueError(f"unknown fluid {fluid!r}; choose one of {', '.join(FLUIDS)}")
    params = FLUIDS[fluid]
    if youngs_modulus is None:
        return params
    if not (math.isfinite(youngs_modulus) and youngs_modulus > 0):
        raise ValueError(f"Young's modulus must be a finite number > 0 Pa; got {youngs_modulus!r}")
    return replace(params, youngs_modulus=float(youngs_modulus))


def configurations(n_sections: int, tapered: bool = False) -> tuple[tuple[int, ...], ...]:
    """All layouts of ``n_sections`` sections with 3, 6, 9 or 12 tubes each (4^N).

    Args:
        n_sections: N ≥ 1.
        tapered: keep only layouts whose tube count never grows towards the tip
            (C(N + 3, 3) of them), for large N.
    """
    if isinstance(n_sections, bool) or int(n_sections) != n_sections or n_sections < 1:
        raise ValueError(f"number of sections must be an integer >= 1; got {n_sections!r}")
    layouts = itertools.product(TUBE_COUNTS, repeat=int(n_sections))
    if tapered:
        layouts = (c for c in layouts if all(a >= b for a, b in zip(c, c[1:])))
    return tuple(layouts)


def _ring_diameter_factor(n_tubes: int) -> float:
    """Section diameter over Ro: 2(δ + Ro)/Ro with δ = Ro/sin(π/N_t)."""
    return 2.0 * (1.0 + 1.0 / math.sin(math.pi / n_tubes))


def outer_radius(params: FluidDesign, constraint: str, tubes, size: float) -> float:
    """Tube outer radius Ro (m) that the constraint case imposes (module docstring)."""
    if constraint == "tube-ratio":
        return params.beta * size / 2.0
    if constraint == "base-ratio":
        return params.beta * size / _ring_diameter_factor(max(tubes))
    if constraint == "diameter":
        return params.beta * params.length / _ring_diameter_factor(max(tubes))
    if constraint == "gripping-radius":
        return params.outer_radius
    raise ValueError(f"unknown constraint {constraint!r}; choose one of {', '.join(CONSTRAINTS)}")


def evaluate(params: FluidDesign, constraint: str, tubes, size: float, *,
             template_pressure: str = "max", model: str = "full") -> Candidate:
    """Template and load capacity of one layout at one size.

    Args:
        params: Table 3.1 parameters.
        constraint: one of :data:`CONSTRAINTS`.
        tubes: (N,) tubes per section.
        size: total length (m), or the distal length for ``gripping-radius``.
        template_pressure: ``"max"`` (Eq. 3.3) or ``"test"``.
        model: solver model.
    """
    if template_pressure not in TEMPLATE_PRESSURES:
        raise ValueError(f"template_pressure must be one of {TEMPLATE_PRESSURES}; got {template_pressure!r}")
    if not (isinstance(size, (int, float, np.floating)) and math.isfinite(size) and size > 0):
        raise ValueError(f"size must be a finite length > 0 m; got {size!r}")
    tubes = tuple(int(t) for t in tubes)
    ro = outer_radius(params, constraint, tubes, float(size))
    p_template = params.max_pressure if template_pressure == "max" else params.test_pressure
    length_kw = ({"distal_length": float(size)} if constraint == "gripping-radius"
                 else {"total_length": float(size)})
    try:
        tpl = template(params, tubes, ro, pressure=p_template, **length_kw)
    except InfeasibleDesign as exc:
        return Candidate(tubes=tubes, size=float(size), feasible=False, outer_radius_m=ro,
                         reason=str(exc))
    arm = build_arm(params, tubes, tpl.section_lengths, tpl.thickness, ro)
    geometry = dict(tubes=tubes, size=float(size), feasible=True, length_m=tpl.length,
                    section_lengths_m=tuple(float(v) for v in tpl.section_lengths),
                    thickness_m=tpl.thickness, outer_radius_m=ro, mass_kg=arm.mass,
                    internal_volume_l=tpl.internal_volume * 1e3)
    try:
        cap = load_capacity(arm, params.test_pressure, model=model)
    except CapacityError as exc:  # reported like an unconverged solve: excluded from the optimum
        return Candidate(**geometry, converged=False, reason=str(exc))
    return Candidate(
        **geometry, load_n=cap.load_n, tip_x_m=float(cap.tip_at_capacity[0]), fold_limited=cap.fold_limited,
        converged=cap.converged)


def sweep(fluid: str, constraint: str, n_sections: int, sizes=None, *, tapered: bool = False,
          template_pressure: str = "max", youngs_modulus: float | None = None,
          model: str = "full", progress: bool = True, backend: str = "local",
          address: str | None = None, chunk_size: int = DEFAULT_DESIGN_CHUNK) -> Sweep:
    """Exhaustive search over layouts at every size (thesis §3.3).

    Args:
        fluid: ``"pneumatic"`` or ``"hydraulic"`` (Table 3.1).
        constraint: one of :data:`CONSTRAINTS`.
        n_sections: N ≥ 1.
        sizes: swept values (m); default :data:`DEFAULT_SIZES` of the constraint.
        tapered: only layouts with non-increasing tube counts (see :func:`configurations`).
        template_pressure: ``"max"`` (Eq. 3.3) or ``"test"``.
        youngs_modulus: override Table 3.1's E (Pa), e.g. for §3.4.5.
        model: solver model.
        progress: tqdm bar on stderr.
        backend, address: ``"local"`` or ``"ray"`` and the Ray cluster (see
            :class:`softarm_gym.jobs.Runner`).
        chunk_size: evaluations per chunk (a Ray task).

    For chunks kept on disk, resuming, or several sweeps under one progress bar, run
    :func:`sweep_plan` with a :class:`~softarm_gym.jobs.Runner`.
    """
    plan = sweep_plan(fluid, constraint, n_sections, sizes, tapered=tapered,
                      template_pressure=template_pressure, youngs_modulus=youngs_modulus,
                      model=model, chunk_size=chunk_size)
    runner = Runner(backend, address, progress=progress)
    return runner.run_plans([plan], desc=f"{fluid} {constraint} N={n_sections}", unit="design")[0]


def _evaluate_chunk(params, constraint, pairs, template_pressure, model):
    """Evaluate ``(tubes, size)`` pairs: ``{"candidates": JSON list of Candidate fields}``.

    JSON keeps every float exactly (shortest repr, NaN included), so a chunk kept on disk
    reads back as the same candidates.
    """
    out = [asdict(evaluate(params, constraint, tubes, size, template_pressure=template_pressure,
                           model=model)) for tubes, size in pairs]
    return {"candidates": np.array(json.dumps(out))}


def _candidates(result) -> list[Candidate]:
    fields = json.loads(str(result["candidates"]))
    return [Candidate(**{**f, "tubes": tuple(f["tubes"]),
                         "section_lengths_m": tuple(f["section_lengths_m"])}) for f in fields]


def sweep_plan(fluid: str, constraint: str, n_sections: int, sizes=None, *, tapered: bool = False,
               template_pressure: str = "max", youngs_modulus: float | None = None,
               model: str = "full", chunk_size: int = DEFAULT_DESIGN_CHUNK) -> Plan:
    """The chunks of :func:`sweep` (same arguments); the plan's result is the :class:`Sweep`."""
    params = fluid_params(fluid, youngs_modulus)
    if constraint not in CONSTRAINTS:
        raise ValueError(f"unknown constraint {constraint!r}; choose one of {', '.join(CONSTRAINTS)}")
    if template_pressure not in TEMPLATE_PRESSURES:
        raise ValueError(f"template_pressure must be one of {TEMPLATE_PRESSURES}; got {template_pressure!r}")
    if model not in solver.MODELS:
        raise ValueError(f"unknown model {model!r}; choose one of {', '.join(solver.MODELS)}")
    sizes = DEFAULT_SIZES[constraint] if sizes is None else tuple(float(s) for s in sizes)
    if not sizes or any(not (math.isfinite(s) and s > 0) for s in sizes):
        raise ValueError(f"sizes must be finite lengths > 0 m; got {sizes!r}")
    layouts = configurations(n_sections, tapered)
    pairs = [(tubes, size) for size in sizes for tubes in layouts]
    chunks = [Chunk(_evaluate_chunk, (params, constraint, tuple(pairs[a:b]), template_pressure, model),
                    size=b - a) for a, b in chunk_bounds(len(pairs), chunk_size)]

    def finish(results, seconds):
        flat = [c for r in results for c in _candidates(r)]
        rows = tuple(tuple(flat[i * len(layouts):(i + 1) * len(layouts)]) for i in range(len(sizes)))
        return Sweep(fluid=fluid, constraint=constraint, n_sections=int(n_sections),
                     template_pressure=template_pressure, params=params, sizes=sizes,
                     configurations=layouts, candidates=rows)
    return Plan(chunks, finish)
