"""PyElastica peer: the same planar arm and scene, settled by PyElastica's damped dynamics.

:func:`settle` builds a PyElastica ``CosseratRod`` equivalent to our planar model of an arm
(docs/design.md §1–4) and integrates its damped dynamics until the tip stops moving; :func:`run_peer`
does that for the fixed OctArm V scene set of :func:`peer_scenes`, and :func:`compare` adds
our converged reference so the two can be read side by side (``softarm bench --peer
pyelastica``).

How the rod is made equivalent to ours:

- one rod of the total reference length, elements distributed over the sections in
  proportion to their lengths so that every section end is a node; base at the origin,
  d3 = (cos θ0, sin θ0, 0), d1 = (−sin θ0, cos θ0, 0), d2 = +z (θ0 = base_angle − 90°);
  the base node and first element are clamped (``OneEndFixedBC``);
- per element, ``shear_matrix = diag(GA, GA, EA)`` of its section; per Voronoi node,
  ``bend_matrix = diag(EI, EI, GJ)`` combined from the two adjacent elements as compliances
  in series (so the rotation across a section junction is exact for a given moment);
- PyElastica scales the internal force by 1/e (element dilatation) and the couple by 1/ε³
  (Voronoi dilatation), its model of an incompressible rod whose cross-section shrinks as
  it stretches. Our sections keep their stiffness, so (``match_stiffness=True``) both
  matrices are multiplied by e and ε³: from the rest stretch v3* while the pressures ramp,
  then from the current dilatation once per settling window (rescaling at every step feeds
  back into the dynamics and was seen to diverge). At the settled state PyElastica then
  carries exactly ``n = D (v − v*)``, ``m = C (u − u*)``. Measured on OctArm V at 90° with
  gravity: with the rescaling, the Richardson extrapolation of the 60/120-element tips lies
  0.013 % of L from ours; without it, 1.4 % (a different rod). At finite resolution the two
  errors happen to partly cancel there (0.78 % instead of 2.17 % at 60 elements), which is
  no reason to compare a different constitutive law;
- mass per reference length from the section, lumped on the nodes (PyElastica's own
  lumping), endplates added to the section-end nodes, gravity by ``GravityForces``, the
  payload weight and any tip force by ``EndpointForces``. Rotational inertia (which does not
  affect statics) is :data:`ROTATIONAL_INERTIA_FACTOR` times that of a disc with the
  section's EI/EA, for a clean settle at fine resolution;
- actuation as rest strains from :func:`solver.rest_strains`: ``rest_sigma[2] = v3* − 1``
  per element and ``rest_kappa = (u1*, u2*, 0)`` per Voronoi node (length-weighted across a
  junction, so the rest rotation over the node's Voronoi domain is exact). PyElastica's κ is
  expressed in the director frame like ours, so no sign change is needed (checked against
  the closed-form arc in the tests);
- loading follows our quasi-static path: gravity and payload act from t = 0 on the straight
  unactuated rod, then the channel pressures are ramped proportionally from zero over
  ``ramp_time`` (rest strains recomputed from the pressures at every control update), then
  the rod is left to settle. ``AnalyticalLinearDamper`` (uniform damping constant) removes
  the kinetic energy; ``PositionVerlet`` integrates.

Settled means: over the last settling window the tip moved less than ``tol`` and no node
moves faster than ``tol / window``; tips settled with different damping agree to ~3e-5 m.

Accuracy (``validate()``; tip error / L against a closed form, 30 / 60 / 120 elements):
OctArm V unloaded arc 8.69 / 4.34 / 2.17 %; cantilever elastica PL²/EI = 2 1.99 / 0.99 /
0.49 % (our solver: 0.02 %, its extensibility). PyElastica is first order in its element
count, and for a clamped rod the leading term is its clamp convention: the first element
keeps the base orientation, so the rod lags the continuum by half an element's rotation,
u(0)·dx/2, which accounts for 99 % of the arc error at 20 elements. On the 18 gravity
scenes of :func:`peer_scenes` (``compare()``) the tip lands 0.76 % of L from our converged
solution (median; max 1.63 %) at 60 elements, 0.37 % (max 0.81 %) at 120, every scene
settled; a settle takes ~2 s (60 elements, ~17,000 steps) and ~5 s (120) of wall time on
this 2-core machine, against ~10 ms for our 512-steps/section reference solve (<1 ms at
default settings).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import numpy as np

import solver

try:
    import elastica as ea
except ImportError as exc:  # pragma: no cover - exercised only without the bench extra
    raise ImportError("softarm_gym.benchmarks.pyelastica_peer needs PyElastica: "
                      "pip install 'softarm-gym[bench]'") from exc

REFERENCE = solver.Settings(steps_per_section=512)
"""Settings of our converged reference solve that the peer is compared against."""

ROTATIONAL_INERTIA_FACTOR = 10.0
"""Rotational inertia per length = factor · μ·EI/EA (the value for a solid disc of the same EI/EA
is factor 1). Rotational inertia does not change an equilibrium, only the way to it. At factor
1 the settled OctArm V rod at 90° was unstable at 120 elements (an in-plane rotational mode
grew ~e^{6.5 t} after settling, independently of dt) and barely damped at 60; at 3 (120
elements) and 10 (up to 240 elements) it settles cleanly."""


@dataclass(frozen=True)
class PeerResult:
    """Static equilibrium reached by PyElastica's damped dynamics.

    Attributes:
        tip: (2,) tip position (m), planar frame of docs/design.md §1–4.
        seconds: wall time of the integration (s), excluding building the rod.
        steps: number of PositionVerlet time steps taken.
        settled: whether the settling criterion was met before ``max_time``.
        final_velocity: largest node speed at the end (m/s).
        simulated_time: simulated time at the end (s).
        n_elem: number of rod elements.
        dt: time step (s).
    """

    tip: np.ndarray
    seconds: float
    steps: int
    settled: bool
    final_velocity: float
    simulated_time: float
    n_elem: int
    dt: float

    def __post_init__(self):
        tip = np.asarray(self.tip, dtype=float)
        if tip.shape != (2,):
            raise ValueError(f"PeerResult.tip must have shape (2,); got {tip.shape}")
        tip.setflags(write=False)
        object.__setattr__(self, "tip", tip)
        for name in ("seconds", "final_velocity", "simulated_time", "dt"):
            if not math.isfinite(getattr(self, name)) or getattr(self, name) < 0:
                raise ValueError(f"PeerResult.{name} must be finite and >= 0; got {getattr(self, name)}")
        if self.steps < 0 or self.n_elem < 2:
            raise ValueError(
                f"PeerResult: steps must be >= 0 and n_elem >= 2; got {self.steps}, {self.n_elem}")

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {"tip": [float(v) for v in self.tip], "seconds": self.seconds, "steps": self.steps,
                "settled": bool(self.settled), "final_velocity": self.final_velocity,
                "simulated_time": self.simulated_time, "n_elem": self.n_elem, "dt": self.dt}


class _Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
    """PyElastica system collection with the modules the peer uses."""


def elements_per_section(arm, n_elem: int) -> np.ndarray:
    """Element counts per section, proportional to length, at least 2 each, summing to n_elem."""
    lengths = np.array([s.length for s in arm.sections])
    counts = np.maximum(2, np.round(n_elem * lengths / lengths.sum()).astype(int))
    while counts.sum() != n_elem:
        share = counts / lengths
        if counts.sum() > n_elem:
            k = int(np.argmax(np.where(counts > 2, share, -np.inf)))
            counts[k] -= 1
        else:
            counts[int(np.argmin(share))] += 1
    return counts


@dataclass(frozen=True)
class _Model:
    """The built PyElastica system and the per-element data needed to drive it."""

    sim: _Simulator
    rod: ea.CosseratRod
    section_of_element: np.ndarray  # (n_elem,) int
    shear_diag: np.ndarray  # (3, n_elem) GA, GA, EA (N)
    bend_diag: np.ndarray  # (3, n_elem - 1) series-combined EI, EI, GJ (N m²)
    rest_lengths: np.ndarray  # (n_elem,) m


def _build(arm, scene: solver.Scene, n_elem: int, damping: float, dt: float) -> _Model:
    counts = elements_per_section(arm, n_elem)
    section_of_element = np.repeat(np.arange(len(arm.sections)), counts)
    secs = arm.sections
    ea_ = np.array([s.EA for s in secs])[section_of_element]
    ga = np.array([s.GA for s in secs])[section_of_element]
    ei = np.array([s.EI for s in secs])[section_of_element]
    gj = np.array([s.GJ for s in secs])[section_of_element]
    mu = np.array([s.mass_per_length for s in secs])[section_of_element]

    theta0 = scene.base_theta
    direction = np.array([math.cos(theta0), math.sin(theta0), 0.0])
    normal = np.array([-math.sin(theta0), math.cos(theta0), 0.0])
    s_nodes = np.concatenate([[0.0], np.cumsum(np.repeat([s.length / c for s, c in zip(secs, counts)],
                                                          counts))])
    position = direction[:, None] * s_nodes[None, :]
    # Disc radius r with r²/4 = ROTATIONAL_INERTIA_FACTOR·EI/EA: sets the rotational inertia only.
    radius = 2.0 * np.sqrt(ROTATIONAL_INERTIA_FACTOR * ei / ea_)
    density = mu / (math.pi * radius**2)  # so that density × area = mass per reference length
    rod = ea.CosseratRod.straight_rod(
        n_elem, np.zeros(3), direction, normal, float(s_nodes[-1]), radius, density,
        youngs_modulus=secs[0].EA / (math.pi * radius[0] ** 2),
        shear_modulus=secs[0].GA / (math.pi * radius[0] ** 2), position=position)
    lengths = np.diff(s_nodes)
    # Endplates on the section-end nodes (PyElastica already lumped μ·l on the nodes).
    ends = np.cumsum(counts)
    for sec, node in zip(secs, ends):
        rod.mass[node] += sec.endplate_mass
    shear_diag = np.vstack([ga, ga, ea_])
    bend_diag = np.empty((3, n_elem - 1))
    for row, stiff in enumerate((ei, ei, gj)):
        compliance = 0.5 * (lengths[:-1] / stiff[:-1] + lengths[1:] / stiff[1:])
        bend_diag[row] = 0.5 * (lengths[:-1] + lengths[1:]) / compliance
    for k in range(3):
        rod.shear_matrix[k, k, :] = shear_diag[k]
        rod.bend_matrix[k, k, :] = bend_diag[k]

    sim = _Simulator()
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    if scene.gravity > 0:
        sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, -scene.gravity, 0.0]))
    tip_force = scene.tip_force_3d() + np.array([0.0, -scene.gravity * scene.payload_kg, 0.0])
    if np.any(tip_force):
        sim.add_forcing_to(rod).using(ea.EndpointForces, start_force=np.zeros(3), end_force=tip_force,
                                      ramp_up_time=dt)
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=damping, time_step=dt)
    sim.finalize()
    return _Model(sim, rod, section_of_element, shear_diag, bend_diag, lengths)


def _set_rest_strains(model: _Model, u1, u2, v3) -> None:
    """Write per-section rest strains into the rod (elements: stretch; Voronoi nodes: curvature)."""
    rod, sec, l = model.rod, model.section_of_element, model.rest_lengths
    rod.rest_sigma[0, :] = 0.0
    rod.rest_sigma[1, :] = 0.0
    rod.rest_sigma[2, :] = v3[sec] - 1.0
    for row, u in ((0, u1), (1, u2)):
        ue = u[sec] * l
        rod.rest_kappa[row, :] = (ue[:-1] + ue[1:]) / (l[:-1] + l[1:])
    rod.rest_kappa[2, :] = 0.0


def _match_stiffness(model: _Model, stretch: np.ndarray) -> None:
    """Undo PyElastica's 1/e and 1/ε³ stiffness scaling (see module doc).

    Args:
        model: the built system.
        stretch: (n_elem,) element stretch e to scale for: the rest stretch v3* while the
            pressures ramp, the current dilatation once they are held.
    """
    rod = model.rod
    l = model.rest_lengths
    voronoi = (stretch[:-1] * l[:-1] + stretch[1:] * l[1:]) / (l[:-1] + l[1:])
    for k in range(3):
        rod.shear_matrix[k, k, :] = model.shear_diag[k] * stretch
        rod.bend_matrix[k, k, :] = model.bend_diag[k] * voronoi**3


def stable_time_step(arm, n_elem: int, safety: float = 0.5) -> float:
    """A PositionVerlet time step (s) below the stability limit of the rod built by :func:`settle`.

    Per section with element length dx: axial waves have ω² ≤ 4·EA/(μ·dx²); the element
    rotations, with rotational inertia J = f·μ·dx·EI/EA (f = :data:`ROTATIONAL_INERTIA_FACTOR`),
    have ω² ≤ (4·EA/dx² (bending) + GA·EA/EI (shear)) / (f·μ). The step is ``safety``·2/ω_max;
    the margin covers the stiffness scaled by the stretch (up to v3*³ for bending, see the
    module doc). Measured on OctArm V at 60 elements (inertia factor 1, where the axial limit
    dominates): stable at 0.8× the limit, divergent at 1.05×.
    """
    counts = elements_per_section(arm, n_elem)
    omega2 = []
    for s, c in zip(arm.sections, counts):
        axial = 4.0 * s.EA / (s.length / c) ** 2
        rotation = (axial + s.GA * s.EA / s.EI) / ROTATIONAL_INERTIA_FACTOR
        omega2.append(max(axial, rotation) / s.mass_per_length)
    return safety * 2.0 / math.sqrt(max(omega2))


def default_damping(arm, scene: solver.Scene) -> float:
    """Uniform damping constant (1/s) near critical for the arm's slowest mode.

    γ = 2·ω with ω² = ω_b² + ω_g²: ω_b = 1.875²·√(EI/μ)/L² the first cantilever bending mode
    (length-averaged EI and μ), ω_g = √(g/L) the hanging-pendulum mode. On OctArm V (γ ≈ 8.4/s
    with gravity) this settled the test scenes in ~3.5 s of simulated time, against ~5.5 s at
    γ = 4/s and ~4.5 s at 12/s.
    """
    lengths = np.array([s.length for s in arm.sections])
    ei = np.dot(lengths, [s.EI for s in arm.sections]) / arm.length
    mu = np.dot(lengths, [s.mass_per_length for s in arm.sections]) / arm.length
    omega_bend = 1.875**2 * math.sqrt(ei / mu) / arm.length**2
    return 2.0 * math.sqrt(omega_bend**2 + scene.gravity / arm.length)


def settle(arm, pressures_pa, scene: solver.Scene | None = None, n_elem: int = 60, *,
           tol: float = 1e-6, window: float = 0.05, ramp_time: float = 0.5, max_time: float = 30.0,
           damping: float | None = None, dt: float | None = None, match_stiffness: bool = True,
           control_interval: float = 1e-3) -> PeerResult:
    """Settle the planar arm with PyElastica and return the equilibrium it reaches.

    Args:
        arm: a design with planar channels (or a passive rod), masses > 0.
        pressures_pa: (n_inputs,) planar channel pressures (Pa).
        scene: base angle, payload, gravity, tip force (no tip moment or obstacles).
        n_elem: number of rod elements (>= 2 per section).
        tol: settling threshold on the tip displacement over ``window`` (m).
        window: settling window (simulated s).
        ramp_time: time over which the pressures are ramped from zero, after an equal time
            of loading by gravity alone (simulated s).
        max_time: give up (``settled=False``) after this much simulated time (s).
        damping: uniform damping constant (1/s); default :func:`default_damping`.
        dt: time step (s); default :func:`stable_time_step`.
        match_stiffness: cancel PyElastica's 1/e and 1/ε³ stiffness scaling (module doc).
        control_interval: how often rest strains and stiffness are updated (simulated s).

    Returns:
        :class:`PeerResult`.

    Raises:
        ValueError: bad pressures, an unsupported scene, or bad settings.
    """
    scene = solver.Scene() if scene is None else scene
    if not isinstance(scene, solver.Scene):
        raise ValueError(f"scene must be a solver.Scene; got {type(scene).__name__}")
    if np.any(scene.tip_moment_3d()) or scene.obstacles or scene.tip_force_3d()[2] != 0:
        raise ValueError("the PyElastica peer supports gravity, payload and in-plane tip force only "
                         "(no tip moment, out-of-plane force or obstacles)")
    if any(s.mass_per_length <= 0 for s in arm.sections):
        raise ValueError(f"design {arm.name!r}: the PyElastica peer needs mass_per_length > 0 in every "
                         "section (its dynamics divide by node masses)")
    if not isinstance(n_elem, (int, np.integer)) or n_elem < 2 * len(arm.sections):
        raise ValueError(
            f"n_elem must be an integer >= {2 * len(arm.sections)} (2 per section); got {n_elem!r}")
    for name, value in (("tol", tol), ("window", window), ("max_time", max_time),
                        ("control_interval", control_interval)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0; got {value!r}")
    if not (math.isfinite(ramp_time) and ramp_time >= 0):
        raise ValueError(f"ramp_time must be a finite number >= 0; got {ramp_time!r}")
    target = solver.channel_pressures(arm, pressures_pa)
    dt = stable_time_step(arm, n_elem) if dt is None else float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite number > 0; got {dt!r}")
    damping = default_damping(arm, scene) if damping is None else float(damping)
    if not (math.isfinite(damping) and damping > 0):
        raise ValueError(f"damping must be a finite number > 0 (1/s); got {damping!r}")

    model = _build(arm, scene, int(n_elem), float(damping), dt)
    rod, sim = model.rod, model.sim
    stepper = ea.PositionVerlet()
    steps_per_update = max(1, round(control_interval / dt))
    updates_per_window = max(1, round(window / (steps_per_update * dt)))
    ramp_start, ramp_end = ramp_time, 2.0 * ramp_time

    def ramp(t: float) -> None:
        fraction = 1.0 if ramp_time == 0 else min(max((t - ramp_start) / ramp_time, 0.0), 1.0)
        u1, u2, v3 = solver.rest_strains(arm, fraction * target)
        _set_rest_strains(model, u1, u2, v3)
        if match_stiffness:
            _match_stiffness(model, v3[model.section_of_element])

    t = np.float64(0.0)
    steps = updates = 0
    settled = False
    tip_history = [rod.position_collection[:2, -1].copy()]
    start = time.perf_counter()
    ramp(0.0)
    while t < max_time:
        for _ in range(steps_per_update):
            t = stepper.step(sim, t, dt)
        steps += steps_per_update
        updates += 1
        if t <= ramp_end + control_interval:
            ramp(float(t))
        tip = rod.position_collection[:2, -1].copy()
        if not np.all(np.isfinite(tip)):
            break
        tip_history.append(tip)
        if t >= ramp_end and len(tip_history) > updates_per_window:
            moved = np.linalg.norm(tip - tip_history[-1 - updates_per_window])
            speed = float(np.max(np.linalg.norm(rod.velocity_collection, axis=0)))
            if moved < tol and speed < tol / window:
                settled = True
                break
            if match_stiffness and updates % updates_per_window == 0:
                _match_stiffness(model, rod.dilatation)
        del tip_history[:-updates_per_window - 1]
    seconds = time.perf_counter() - start
    tip = rod.position_collection[:2, -1].copy()
    speed = float(np.max(np.linalg.norm(rod.velocity_collection, axis=0)))
    if not (np.all(np.isfinite(tip)) and math.isfinite(speed)):
        raise RuntimeError(f"PyElastica diverged at t = {float(t):.4g} s with dt = {dt:.3g} s; "
                           "use a smaller dt")
    return PeerResult(tip=tip, seconds=seconds, steps=steps, settled=settled, final_velocity=speed,
                      simulated_time=float(t), n_elem=int(n_elem), dt=dt)


# ----------------------------------------------------------------------------- validation

ELASTICA_ALPHA2_TIP = (1.0 - 0.160642, -0.493457)
"""Inextensible cantilever, horizontal clamp, dead tip load α = P·L²/EI = 2: tip (x, y)/L
(docs/design.md §12)."""


def arc_tip(arm, pressures_pa, base_angle_deg: float) -> np.ndarray:
    """Closed-form tip (2,) (m) of an unloaded arm: each section an arc of curvature u2*, stretch v3*.

    With no loads the internal force and the moment beyond the rest curvature vanish, so every
    section is exactly a circular arc (docs/design.md §12) — independent of the rod discretisation.
    """
    _, u2, v3 = solver.rest_strains(arm, solver.channel_pressures(arm, pressures_pa))
    theta = math.radians(base_angle_deg - 90.0)
    tip = np.zeros(2)
    for sec, u, v in zip(arm.sections, u2, v3):
        phi = u * sec.length
        if abs(phi) < 1e-12:
            tip += v * sec.length * np.array([math.cos(theta), math.sin(theta)])
        else:
            tip += v / u * np.array([math.sin(theta + phi) - math.sin(theta),
                                     math.cos(theta) - math.cos(theta + phi)])
        theta += phi
    return tip


def validation_cases():
    """Cases with a closed form: (label, arm, planar pressures (Pa), Scene, exact tip (2,) m)."""
    arm = solver.designs.octarm_v()
    p = np.array([60.0, 0.0, 0.0, 40.0, 30.0, 0.0]) * solver.PSI
    rod = solver.designs.rod(length=1.0, EI=1.0, EA=1.0e4, GA=1.0e4, mass_per_length=1.0)
    return [
        ("OctArm V arc, no gravity", arm, p, solver.Scene(base_angle_deg=90.0, gravity=0.0),
         arc_tip(arm, p, 90.0)),
        ("cantilever elastica, PL²/EI = 2 (EA = GA = 1e4 EI/L²)", rod, np.empty(0),
         solver.Scene(base_angle_deg=90.0, gravity=0.0, tip_force=(0.0, -2.0)),
         np.array(ELASTICA_ALPHA2_TIP)),
    ]


def validate(n_elems=(30, 60, 120), progress=True) -> list[dict]:
    """PyElastica against closed forms at several element counts (first-order convergence).

    Returns one row per (case, n_elem): tip, exact tip, error / L, our solver's error / L at
    :data:`REFERENCE` (for the cantilever it includes our extensibility and shear, which the
    inextensible closed form lacks), settle wall time and steps.
    """
    rows = []
    report = _reporter(progress, len(validation_cases()) * len(n_elems), "validate")
    for label, arm, p, scene, exact in validation_cases():
        ours = solver.solve(arm, p, scene, settings=REFERENCE, record=False).tip
        for n in n_elems:
            r = settle(arm, p, scene, n_elem=n)
            rows.append({"case": label, "n_elem": n, "tip": r.tip.tolist(), "exact": exact.tolist(),
                         "error_over_L": float(np.linalg.norm(r.tip - exact) / arm.length),
                         "solver_error_over_L": float(np.linalg.norm(ours - exact) / arm.length),
                         "seconds": r.seconds, "steps": r.steps, "settled": r.settled})
            report(f"{label} n={n}")
    return rows


# ----------------------------------------------------------------------------- benchmark

PRESSURE_PATTERNS_PSI = {
    "unactuated": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    "curl I": (40.0, 0.0, 40.0, 0.0, 40.0, 0.0),
    "S": (0.0, 60.0, 30.0, 0.0, 60.0, 0.0),
}
"""Planar OctArm V pressure patterns (psi), inputs ``[s1_I, s1_II+III, s2_I, s2_II+III, s3_I, s3_II+III]``."""


def peer_scenes(quick: bool = False):
    """The fixed OctArm V scene set: (label, design name, planar pressures (6,) Pa, Scene).

    Gravity on; base angles 0/45/90°; payloads 0 and 0.1 kg; the patterns of
    :data:`PRESSURE_PATTERNS_PSI` (18 scenes). ``quick``: base angles 0 and 90°, no payload,
    two patterns (4 scenes).
    """
    angles, payloads, patterns = (0.0, 45.0, 90.0), (0.0, 0.1), tuple(PRESSURE_PATTERNS_PSI)
    if quick:
        angles, payloads, patterns = (0.0, 90.0), (0.0,), ("unactuated", "S")
    return [(f"{angle:g}deg {payload:g}kg {name}", "octarm_v",
             np.array(PRESSURE_PATTERNS_PSI[name]) * solver.PSI,
             solver.Scene(base_angle_deg=angle, payload_kg=payload))
            for angle in angles for payload in payloads for name in patterns]


def _reporter(progress, total: int, desc: str):
    """A tick(message) callable: tqdm on stderr (progress=True), a user callable, or nothing."""
    if callable(progress):
        return progress
    if not progress:
        return lambda _message: None
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, file=sys.stderr, leave=False)

    def tick(message):
        bar.set_postfix_str(message)
        bar.update()
        if bar.n >= total:
            bar.close()
    return tick


def _compile(n_elem: int) -> None:
    """Run PyElastica's numba kernels once so that no timed settle includes compilation."""
    settle(solver.designs.octarm_v(), np.zeros(6), solver.Scene(payload_kg=0.1), n_elem=n_elem,
           max_time=0.01)


def run_peer(n_elem: int = 60, progress=True, quick: bool = False) -> list[dict]:
    """Settle every scene of :func:`peer_scenes` with PyElastica.

    Args:
        n_elem: rod elements.
        progress: True for a tqdm bar on stderr, a callable(message) per scene, or False.
        quick: the 4-scene subset.

    Returns:
        One dict per scene: label, design, pressures_psi, base_angle_deg, payload_kg, and
        :meth:`PeerResult.to_dict` (tip, seconds, steps, settled, ...); a scene where
        PyElastica diverged has ``tip: None``, ``settled: False`` and ``error``.
    """
    scenes = peer_scenes(quick)
    tick = _reporter(progress, len(scenes), "pyelastica")
    _compile(n_elem)
    rows = []
    for label, design, p, scene in scenes:
        row = {"label": label, "design": design, "pressures_psi": (p / solver.PSI).tolist(),
               "base_angle_deg": scene.base_angle_deg, "payload_kg": scene.payload_kg}
        try:
            row.update(settle(solver.designs.get(design), p, scene, n_elem=n_elem).to_dict())
        except RuntimeError as exc:
            row.update(tip=None, settled=False, error=str(exc))
        rows.append(row)
        tick(f"pyelastica {label}")
    return rows


def compare(n_elem: int = 60, progress=True, quick: bool = False) -> dict:
    """:func:`run_peer` plus our converged reference (:data:`REFERENCE`) and the tip difference.

    Returns:
        {"n_elem", "reference_steps_per_section", "rows": [... + reference_tip, difference_m,
        difference_over_L, reference_seconds], "median_difference_over_L",
        "max_difference_over_L", "median_seconds", "settled_fraction"}.
    """
    rows = run_peer(n_elem=n_elem, progress=progress, quick=quick)
    for row in rows:
        arm = solver.designs.get(row["design"])
        scene = solver.Scene(base_angle_deg=row["base_angle_deg"], payload_kg=row["payload_kg"])
        p = np.array(row["pressures_psi"]) * solver.PSI
        start = time.perf_counter()
        ref = solver.solve(arm, p, scene, settings=REFERENCE, record=False)
        row["reference_seconds"] = time.perf_counter() - start
        row["reference_tip"] = ref.tip.tolist()
        row["reference_snapped"] = bool(ref.snapped)
        if row["tip"] is None:
            row["difference_m"] = row["difference_over_L"] = None
            continue
        diff = float(np.linalg.norm(np.asarray(row["tip"]) - ref.tip))
        row["difference_m"] = diff
        row["difference_over_L"] = diff / arm.length
    diffs = [r["difference_over_L"] for r in rows if r["difference_over_L"] is not None]
    return {"n_elem": n_elem, "reference_steps_per_section": REFERENCE.steps_per_section, "rows": rows,
            "median_difference_over_L": float(np.median(diffs)) if diffs else None,
            "max_difference_over_L": float(np.max(diffs)) if diffs else None,
            "median_seconds": float(np.median([r["seconds"] for r in rows if "seconds" in r])),
            "settled_fraction": float(np.mean([r["settled"] for r in rows]))}


def format_table(result: dict) -> str:
    """Markdown table of a :func:`compare` result."""
    lines = [f"PyElastica ({result['n_elem']} elements, damped PositionVerlet) against our solver "
             f"({result['reference_steps_per_section']} RK4 steps/section), OctArm V:", "",
             "| scene | PyElastica tip (m) | our tip (m) | difference / L | settle (s) | steps | settled |",
             "|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        tip = "diverged" if r["tip"] is None else f"({r['tip'][0]:.4f}, {r['tip'][1]:.4f})"
        diff = "–" if r["difference_over_L"] is None else f"{100 * r['difference_over_L']:.2f}%"
        seconds = f"{r['seconds']:.1f}" if "seconds" in r else "–"
        lines.append(f"| {r['label']} | {tip} | ({r['reference_tip'][0]:.4f}, {r['reference_tip'][1]:.4f}) "
                     f"| {diff} | {seconds} | {r.get('steps', '–')} | {'yes' if r['settled'] else 'no'} |")
    if result["median_difference_over_L"] is not None:
        lines += ["", f"Median difference {100 * result['median_difference_over_L']:.2f}% of L "
                      f"(max {100 * result['max_difference_over_L']:.2f}%); median settle "
                      f"{result['median_seconds']:.1f} s; settled {100 * result['settled_fraction']:.0f}%."]
    return "\n".join(lines)
