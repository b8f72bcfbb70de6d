"""Coulomb friction against its closed forms: time against error (``softarm bench --friction``).

The scenes of the friction oracles (``tests/solver/test_friction.py`` builds its cases from
this module, docs/design.md §9.1), and the benchmark that times them at several resolutions:

* **Capstan.** A belt (EI = 1e-6 N m², so small against T R² that it bends like a rope)
  clamped tangent to a fixed drum (R = 0.1 m, k = 1e5 N/m²), wrapped θ frictionless under a
  small pull T₀ (the pull turned round in 10° steps), then held with friction μ and pulled
  harder, T₁ from T₀ to 1.3·T₀·e^{μθ}. Once the whole wrap slips, the clamp's tension T₂ (read
  off the base reaction: global statics) satisfies T₁/T₂ = e^{μθ}.
* **Slip threshold.** A soft massless spring from the clamp, then a heavy stiff rod lying on a
  flat (a 10 km disc), pulled along it at its tip from 0 to 2 μW (W its weight): once it
  slides the flat's friction (the clamp's reaction less the pull) is μ times its normal force.
* **Self-contact slip threshold** (``tests/solver/test_self_friction.py``). A hairpin: a stiff
  straight layer clamped horizontal, a fold curled by pressure, and a heavy straight layer
  lying back on the first, pulled along the layers at its tip: flat on flat, so one tangent
  splits the contact's resultant (the statics of the upper layer) into friction and normal
  force, and friction is μ times the normal force once the upper layer slides.

The benchmark's error is the relative error against the closed form at the end of the load
path (capstan: T₁/T₂ against e^{μθ}; slip: the largest |F/(μN) − 1| over the loads past
1.2 μN); its time is a warm solve along that path (each increment solved ``repeat`` times
from the same start, the median kept; the table gives the median over the increments and
their sum).
"""

from __future__ import annotations

import math
import os
import time
from datetime import datetime, timezone

import numpy as np

import solver
from solver.actuator import pressure_from_stretch
from solver.designs import ArmDesign, Section, Tube, TubeMaterial
from solver.settings import DEFAULT_SETTINGS, Settings

R_DRUM, LEAD, TAIL, K_DRUM = 0.1, 0.1, 0.15, 1e5
"""The drum's radius (m), the belt's straight lengths before and after the wrap (m) and the
drum's penalty stiffness (N/m²)."""

CAPSTAN_MAX_PULL = 3.0
"""The largest pull of a capstan path (N): penetration below 0.3 mm."""

CAPSTAN_OVERSHOOT = 1.3
"""The last pull of a capstan path, as a multiple of T₀·e^{μθ}: past the onset of slip."""

CAPSTAN_PULLS = 24
"""Pulls of a capstan path, T₀ (the wrapped state) included."""

SLED_WEIGHT_N = 0.2 * 0.5 * 9.81
"""The sled rod's weight (N): 0.5 m at 0.2 kg/m."""

CAPSTAN_CASES = ((90.0, 0.3), (180.0, 0.3), (360.0, 0.3), (90.0, 1.0), (180.0, 1.0), (360.0, 1.0))
"""(θ in degrees, μ) of the benchmark's capstan rows."""

SLIP_FRICTION = 0.5
"""μ of the benchmark's slip rows."""

STEPS = (16, 64, 256)
"""RK4 steps per section of the benchmark's slip rows (16: the default)."""

CAPSTAN_CONFIGS = ((K_DRUM, 16), (K_DRUM, 64), (K_DRUM, 256), (10 * K_DRUM, 16))
"""(drum stiffness (N/m²), RK4 steps per section) of the benchmark's capstan rows: the
resolution at the tests' drum, then a ten times stiffer drum (less compliance)."""


# ------------------------------------------------------------------------------ the capstan

def belt(theta: float) -> ArmDesign:
    """A belt long enough to wrap ``theta`` (rad) round the drum: four sections (so that the
    contact grid resolves it), EI = GJ = 1e-6 N m², EA = GA = 200 N, massless."""
    length = LEAD + R_DRUM * theta + TAIL
    return ArmDesign(name="belt", source="capstan test belt", sections=tuple(
        Section(length=length / 4, EA=200.0, GA=200.0, EI=1e-6, GJ=1e-6, mass_per_length=0.0)
        for _ in range(4)))


def drum_scene(direction: float, tension: float, mu: float, mirror: float = 1.0,
               stiffness: float = K_DRUM) -> solver.Scene:
    """The belt clamped along +x, tangent to the drum's top, no gravity; the tip pulled along
    ``direction`` (rad, clockwise from +x) with ``tension`` (N); the drum's friction ``mu`` and
    penalty ``stiffness`` (N/m²).
    ``mirror`` −1: all of it mirrored in the x axis (the drum above the belt, the pull turned
    counter-clockwise)."""
    return solver.Scene(base_angle_deg=90.0, gravity=0.0,
                        tip_force=(tension * math.cos(direction), -mirror * tension * math.sin(direction)),
                        obstacles=(solver.Disc((LEAD, -mirror * R_DRUM), R_DRUM, stiffness, friction=mu),))


def wrap_belt(theta: float, t0: float, mirror: float = 1.0, settings: Settings = DEFAULT_SETTINGS,
              stiffness: float = K_DRUM) -> tuple[ArmDesign, list]:
    """The belt wrapped ``theta`` (rad) frictionless under the pull ``t0`` (N) round a drum of
    penalty ``stiffness`` (N/m²), the pull turned round in 10° steps (at least four).

    Returns:
        ``(arm, path)``: the :func:`belt` and the equilibria of the wrapping, the straight belt
        first and the wrapped one last (check ``converged`` and ``stable`` on each).
    """
    arm = belt(theta)
    path = [solver.solve(arm, [], drum_scene(0.0, t0, 0.0, mirror, stiffness), settings=settings)]
    for direction in np.linspace(0.0, theta, max(4, round(math.degrees(theta)) // 10) + 1)[1:]:
        path.append(solver.solve(arm, [], drum_scene(direction, t0, 0.0, mirror, stiffness),
                                 warm_start=path[-1], settings=settings))
    return arm, path


def capstan_pulls(theta: float, mu: float) -> tuple[float, np.ndarray]:
    """The loads of a capstan path: ``(t0, pulls)``, the wrapping's pull T₀ (N) and the
    (CAPSTAN_PULLS − 1,) pulls T₁ (N) after it, geometric from T₀ to
    CAPSTAN_OVERSHOOT·T₀·e^{μθ} = CAPSTAN_MAX_PULL."""
    capstan = math.exp(mu * theta)
    t0 = CAPSTAN_MAX_PULL / (CAPSTAN_OVERSHOOT * capstan)
    return t0, np.geomspace(t0, CAPSTAN_MAX_PULL, CAPSTAN_PULLS)[1:]


def clamp_tension(eq) -> float:
    """The belt's tension at the clamp, T₂ (N): the magnitude of the in-plane base reaction."""
    return float(np.hypot(*eq.base_force[:2]))


# ---------------------------------------------------------------------------- the slip case

def sled() -> ArmDesign:
    """A soft massless spring (0.2 m, EA = GA = 5 N) from the clamp, then a heavy stiff rod
    (0.5 m, EA = GA = 1e4 N, EI = 1e-2 N m², 0.2 kg/m) to lie on the flat."""
    return ArmDesign(name="sled", source="slip threshold test sled", sections=(
        Section(length=0.2, EA=5.0, GA=5.0, EI=1e-3, GJ=1e-3, mass_per_length=0.0),
        Section(length=0.5, EA=1e4, GA=1e4, EI=1e-2, GJ=1e-2, mass_per_length=0.2)))


def sled_scene(mu: float, pull: float = 0.0, gravity: float = 9.81) -> solver.Scene:
    """The sled clamped along +x on a flat (a disc of radius 10 km, k = 1e4 N/m², friction
    ``mu``), its tip pulled along +x with ``pull`` (N)."""
    flat = solver.Disc((0.45, -1e4), 1e4, 1e4, friction=mu)
    return solver.Scene(base_angle_deg=90.0, gravity=gravity, tip_force=(pull, 0.0), obstacles=(flat,))


def sled_forces(eq, pull: float) -> tuple[float, float]:
    """``(friction, normal)`` (N) on the sled from the clamp's reaction n(0) under ``pull``:
    F = n_x(0) − pull (positive along +x), N = n_y(0) + the rod's weight."""
    return float(eq.base_force[0] - pull), float(eq.base_force[1] + SLED_WEIGHT_N)


# ------------------------------------------------------------------ the self-contact hairpin

HAIRPIN_HALF, HAIRPIN_LOWER, HAIRPIN_UPPER, HAIRPIN_FOLD_EI = 0.01, 0.3, 0.25, 1e-3
"""The hairpin's half-thickness (m: its fold's radius, so the layers' backbones stand 2 × it
apart), the lengths of its lower (clamped) and upper layers (m) and its fold's bending
stiffness (N m²)."""

HAIRPIN_CONTACT = 1e5
"""The hairpin's self-contact penalty stiffness (N/m², the drum's)."""

HAIRPIN_OVERCURL = 1.3
"""How far the fold's rest curvature curls it, in half turns: past 180°, so the fold itself
presses the upper layer onto the lower one before gravity does."""

HAIRPIN_STEPS = (16, 32, 64)
"""RK4 steps per section of the benchmark's self-contact slip rows."""

_HAIRPIN_MUSCLE = TubeMaterial(youngs_modulus=1e8, shear_modulus=3e7, density=1000.0,
                               inner_radius=0.003, outer_radius=0.004, wind_angle_deg=70.0)
_HAIRPIN_MUSCLE_RADIUS = 0.005


def hairpin() -> ArmDesign:
    """A rod that folds back onto itself: a stiff massless lower layer (0.3 m, EI = 1e3 N m²)
    to be clamped horizontal, a fold (π × 1 cm long, EI = 1e-3 N m²) curled by a muscle
    (channel ``fold``, one tube 5 mm off the axis, in the fold only) and a heavy upper layer
    (0.25 m, EI = 0.1 N m², 0.4 kg/m) that the fold lays back on the lower one; EA = GA =
    1e5 N throughout. A passive ``skin`` tube on the axis (Ro = 1 cm, never pressurised:
    :func:`hairpin_pressures` leaves it at 0) makes it 2 cm thick for the self-contact law."""
    skin = TubeMaterial(youngs_modulus=1e6, shear_modulus=3e5, density=1000.0,
                        inner_radius=0.9 * HAIRPIN_HALF, outer_radius=HAIRPIN_HALF, wind_angle_deg=70.0)
    fold = math.pi * HAIRPIN_HALF
    return ArmDesign(
        name="hairpin", source="self-contact slip threshold test hairpin", max_pressure=1e7,
        sections=(Section(HAIRPIN_LOWER, 1e5, 1e5, 1e3, 1e3, 0.0),
                  Section(fold, 1e5, 1e5, HAIRPIN_FOLD_EI, HAIRPIN_FOLD_EI, 0.0),
                  Section(HAIRPIN_UPPER, 1e5, 1e5, 0.1, 0.1, 0.4)),
        tubes=(Tube(0, 0.0, 0.0, 0, 2, skin), Tube(1, 180.0, _HAIRPIN_MUSCLE_RADIUS, 1, 1, _HAIRPIN_MUSCLE)),
        channels=("skin", "fold"), planar_channels=(("skin", (0,)), ("fold", (1,))))


def hairpin_pressures(fraction: float = 1.0) -> np.ndarray:
    """The planar pressures (skin, fold) (Pa) at ``fraction`` of the fold's: the muscle's
    pressure whose force F = E·At·(λ − 1) (the actuator model) gives the fold the rest
    curvature HAIRPIN_OVERCURL·π over its length (F × its offset = EI × the curvature)."""
    m = _HAIRPIN_MUSCLE
    force = HAIRPIN_FOLD_EI * HAIRPIN_OVERCURL / HAIRPIN_HALF / _HAIRPIN_MUSCLE_RADIUS
    lam = 1.0 + force / (m.youngs_modulus * m.area)
    p = pressure_from_stretch(lam, m.youngs_modulus, m.inner_radius, m.outer_radius, m.wind_angle_deg)
    return np.array([0.0, fraction * p])


def hairpin_scene(mu: float, pull: float = 0.0, gravity: float = 9.81) -> solver.Scene:
    """The hairpin clamped along +x, self-contact at HAIRPIN_CONTACT with friction ``mu``, the
    upper layer's tip pulled along −x (along the layers, away from the fold) with ``pull`` (N)."""
    return solver.Scene(base_angle_deg=90.0, gravity=gravity, tip_force=(-pull, 0.0),
                        self_contact=HAIRPIN_CONTACT, self_friction=mu)


def fold_hairpin(mu: float, settings: Settings = DEFAULT_SETTINGS) -> tuple[ArmDesign, list]:
    """The hairpin folded and laid on itself with friction ``mu``: the fold's pressure ramped
    in without gravity (to 90 % in tenths, the last tenth, where the layers meet, in
    hundredths: a longer step would pass the upper layer through the lower one before the
    self-contact law sees them touch), then gravity switched on.

    Returns:
        ``(arm, path)``: the :func:`hairpin` and the equilibria of the folding, the laid
        hairpin last (check ``converged`` and ``stable`` on each).
    """
    arm = hairpin()
    path = [solver.solve(arm, hairpin_pressures(0.0), hairpin_scene(mu, gravity=0.0), settings=settings)]
    for fraction in np.r_[np.linspace(0.1, 0.9, 9), np.linspace(0.91, 1.0, 10)]:
        path.append(solver.solve(arm, hairpin_pressures(fraction), hairpin_scene(mu, gravity=0.0),
                                 warm_start=path[-1], settings=settings))
    path.append(solver.solve(arm, hairpin_pressures(), hairpin_scene(mu), warm_start=path[-1],
                             settings=settings))
    return arm, path


def hairpin_forces(eq, pull: float) -> tuple[float, float, float]:
    """``(friction, normal, spread)`` of the lower layer on the upper one, from the statics of
    the upper layer cut at its first sample (the fold's end, where nothing touches: the
    self-contact exclusion keeps the fold's neighbours apart): the contact's resultant
    C = n(cut) − the tip force − the upper layer's weight, split along the layers' mean
    direction t (the mean of the tangents of both layers where they touch, the upper one's
    turned by π) into friction C·t (N, positive along +x: against the pull) and normal
    force C·n̂ (n̂ = t turned +90°, N). ``spread`` (rad) is how far the touching samples'
    tangents spread: no single direction is better defined than that."""
    arm = eq.arm
    cut = eq.section_ends[1]
    upper = np.arange(cut + 1, eq.s.size)
    lower = np.arange(eq.section_ends[0] + 1)
    weight = arm.sections[2].mass_per_length * (arm.length - eq.s[cut]) * eq.scene.gravity
    contact = eq.internal_force[cut] - np.array([-pull, 0.0]) - np.array([0.0, -weight])
    angles = np.r_[eq.angles[lower][eq.penetration[lower] > 0],
                   eq.angles[upper][eq.penetration[upper] > 0] + math.pi]
    if angles.size == 0:
        return 0.0, 0.0, math.nan
    mean = math.atan2(np.sin(angles).sum(), np.cos(angles).sum())
    t = np.array([math.cos(mean), math.sin(mean)])
    spread = np.ptp((angles - mean + math.pi) % (2.0 * math.pi) - math.pi)
    return float(contact @ t), float(contact @ np.array([-t[1], t[0]])), float(spread)


# --------------------------------------------------------------------------------- in 3D

TILT_DEG = 30.0
"""The tilt (degrees) of the 3D capstan's drum axis out of the base plane, about the clamp's
axis (+x)."""

STYLUS_PRESS, STYLUS_HEADING_DEG, FLAT_RADIUS, FLAT_DROP, K_FLAT = 1.0, 40.0, 1e3, 0.01, 1e5
"""The 3D slip case: the stylus's press on the flat (N, along −y), the pull's heading (degrees
from +x towards +z, out of the base plane), the flat's radius (m; a sphere, flat to 1e-3 over
the stylus's reach), how far below the clamp its top lies (m) and its penalty stiffness
(N/m²)."""

STYLUS_STEPS = 256
"""RK4 steps per section of the 3D slip case: its contact patch (~2 cm) is a step long at the
default 16, where the normal force (RK4) and the friction samples (trapezoid on the
refinement's nodes) are summed by different quadratures (|F|/μN = 1.003 while sliding; 1.002
at 64 steps, 1.0001 at 256)."""


def tilted(tilt_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The planar capstan's +y and +z turned by ``tilt_deg`` about +x: the wrap plane's
    normal direction (the drum's top normal) and the drum's axis (3,)."""
    a = math.radians(tilt_deg)
    return np.array([0.0, math.cos(a), -math.sin(a)]), np.array([0.0, math.sin(a), math.cos(a)])


def drum_scene_3d(direction: float, tension: float, mu: float, tilt_deg: float = TILT_DEG,
                  stiffness: float = K_DRUM) -> solver.Scene:
    """:func:`drum_scene` turned by ``tilt_deg`` about the clamp's axis (+x): the drum a
    :class:`solver.Cylinder` whose axis leaves the base plane, the pull (``tension`` N along
    ``direction`` rad, clockwise from +x) in the tilted wrap plane; for the 3D solver
    (``planar=False``). The belt is isotropic (EI = GJ), so the answer is the planar one
    turned: T₁/T₂ = e^{μθ} at the onset of slip."""
    normal, axis = tilted(tilt_deg)
    centre = np.array([LEAD, 0.0, 0.0]) - R_DRUM * normal
    pull = tension * (math.cos(direction) * np.array([1.0, 0.0, 0.0]) - math.sin(direction) * normal)
    return solver.Scene(base_angle_deg=90.0, gravity=0.0, tip_force=tuple(pull),
                        obstacles=(solver.Cylinder(tuple(centre), tuple(axis), R_DRUM, stiffness,
                                                   friction=mu),))


def wrap_belt_3d(theta: float, t0: float, tilt_deg: float = TILT_DEG, degrees_per_step: float = 10.0,
                 settings: Settings = DEFAULT_SETTINGS, tick=None) -> tuple[ArmDesign, list]:
    """:func:`wrap_belt` in 3D round the tilted drum: the belt wrapped ``theta`` (rad)
    frictionless under ``t0`` (N) by warm solves, the pull turned ``degrees_per_step`` a
    solve; ``tick`` (or None) is called after every solve. Returns ``(arm, path)`` as
    :func:`wrap_belt`."""
    tick = tick or (lambda: None)
    arm = belt(theta)
    path = [solver.solve(arm, [], drum_scene_3d(0.0, t0, 0.0, tilt_deg), planar=False,
                         settings=settings)]
    tick()
    steps = max(4, round(math.degrees(theta) / degrees_per_step))
    for direction in np.linspace(0.0, theta, steps + 1)[1:]:
        path.append(solver.solve(arm, [], drum_scene_3d(direction, t0, 0.0, tilt_deg),
                                 planar=False, warm_start=path[-1], settings=settings))
        tick()
    return arm, path


def belt_tension(eq) -> float:
    """The belt's tension at the clamp, T₂ (N), in 3D: |n(0)| (the base reaction)."""
    return float(np.linalg.norm(eq.base_force))


def stylus() -> ArmDesign:
    """A massless cantilever (0.3 m, EA = GA = 10 N, EI = GJ = 1e-2 N m²) whose tip is
    pressed on a flat and dragged over it: its contact patch lies at the tip, where the
    loads act, so the patch slides as one (no yaw of a long contact to spread the friction's
    directions); soft enough along its axis that the flat holds ~97 % of a pull while it
    sticks."""
    return ArmDesign(name="stylus", source="3D slip threshold test stylus", sections=(
        Section(length=0.3, EA=10.0, GA=10.0, EI=1e-2, GJ=1e-2, mass_per_length=0.0),))


def stylus_scene(mu: float, pull: float, heading_deg: float = STYLUS_HEADING_DEG,
                 press: float = STYLUS_PRESS, mirror: float = 1.0) -> solver.Scene:
    """The stylus clamped along +x, no gravity, its tip pressed with ``press`` (N) on a flat
    (a sphere of radius FLAT_RADIUS, k = K_FLAT, friction ``mu``, its top FLAT_DROP below
    the clamp's line under the tip) and pulled with ``pull`` (N) along ``heading_deg`` from
    +x towards +z (out of the base plane). ``mirror`` −1: all of it mirrored in z = 0."""
    a = math.radians(heading_deg)
    flat = solver.Sphere((0.3, -FLAT_RADIUS - FLAT_DROP, 0.0), FLAT_RADIUS, K_FLAT, friction=mu)
    return solver.Scene(base_angle_deg=90.0, gravity=0.0,
                        tip_force=(pull * math.cos(a), -press, mirror * pull * math.sin(a)),
                        obstacles=(flat,))


def stylus_forces(eq) -> tuple[np.ndarray, float]:
    """``(friction (3,), normal)`` (N) of the flat on the stylus from global statics: the
    contact force C = n(0) − the tip force (no gravity), split along the flat's normal at
    the tip (from the sphere's centre) into N = C·n̂ and the friction C − N n̂."""
    centre = np.asarray(eq.scene.obstacles[0].center)
    normal = (eq.tip - centre) / np.linalg.norm(eq.tip - centre)
    contact = eq.base_force - eq.scene.tip_force_3d()
    n = float(contact @ normal)
    return contact - n * normal, n


# ------------------------------------------------------------------------------ the benchmark

def _timed(repeat, arm, scene, warm_start, settings, pressures=()):
    """The solve of ``scene`` at ``pressures`` from ``warm_start`` and the median of
    ``repeat`` timings (s)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        eq = solver.solve(arm, pressures, scene, warm_start=warm_start, settings=settings)
        times.append(time.perf_counter() - start)
    return eq, float(np.median(times))


def _summary(times, ok) -> dict:
    return {"increments": len(times), "median_solve_ms": 1e3 * float(np.median(times)),
            "path_seconds": float(np.sum(times)), "converged_fraction": float(np.mean(ok))}


def capstan(theta_deg: float, mu: float, steps: int = 16, repeat: int = 3, stiffness: float = K_DRUM) -> dict:
    """One capstan row: the belt wrapped ``theta_deg`` round a drum of penalty ``stiffness``
    (N/m²) and pulled past slip with friction ``mu`` at ``steps`` RK4 steps per section.

    Returns:
        The row: ``ratio`` T₁/T₂ at the last pull, ``capstan`` e^{μθ}, ``relative_error``
        |ratio/capstan − 1|, ``max_ratio_over_capstan`` (the most friction held along the
        path), ``slipped`` (T₂ rose past 1.1 T₀: the whole wrap slid), the warm solves' times
        and the share of solves (wrapping included) converged and stable.
    """
    theta = math.radians(theta_deg)
    settings = solver.Settings(steps_per_section=steps)
    t0, pulls = capstan_pulls(theta, mu)
    arm, path = wrap_belt(theta, t0, settings=settings, stiffness=stiffness)
    ok = [eq.converged and eq.stable for eq in path]
    eq, times, ratios = path[-1], [], []
    for t1 in pulls:
        eq, seconds = _timed(repeat, arm, drum_scene(theta, t1, mu, stiffness=stiffness), eq, settings)
        times.append(seconds)
        ok.append(eq.converged and eq.stable)
        ratios.append(t1 / clamp_tension(eq))
    expected = math.exp(mu * theta)
    return {"theta_deg": theta_deg, "mu": mu, "stiffness": stiffness, "steps_per_section": steps,
            "capstan": expected,
            "ratio": ratios[-1], "relative_error": abs(ratios[-1] / expected - 1.0),
            "max_ratio_over_capstan": max(ratios) / expected, "slipped": clamp_tension(eq) > 1.1 * t0,
            **_summary(times, ok)}


def slip(mu: float = SLIP_FRICTION, steps: int = 16, repeat: int = 3) -> dict:
    """One slip-threshold row: the sled laid on the flat (weightless, then loaded in the first
    increment) and pulled from 0 to 2 μW in 20 increments, at ``steps`` RK4 steps per section.

    Returns:
        The row: ``relative_error`` the largest |F/(μN) − 1| over the pulls past 1.2 μN
        (sliding), ``max_friction_over_mu_normal`` the most friction held along the path, the
        warm solves' times and the share of solves converged and stable.
    """
    settings = solver.Settings(steps_per_section=steps)
    arm = sled()
    eq = solver.solve(arm, [], sled_scene(mu, gravity=0.0), settings=settings)
    ok, times, sliding, held = [eq.converged and eq.stable], [], [], []
    for pull in np.linspace(0.0, 2.0, 21) * mu * SLED_WEIGHT_N:
        eq, seconds = _timed(repeat, arm, sled_scene(mu, pull), eq, settings)
        times.append(seconds)
        ok.append(eq.converged and eq.stable)
        friction, normal = sled_forces(eq, pull)
        held.append(abs(friction) / (mu * normal))
        if pull > 1.2 * mu * normal:
            sliding.append(abs(-friction / (mu * normal) - 1.0))
    return {"mu": mu, "steps_per_section": steps, "relative_error": max(sliding),
            "max_friction_over_mu_normal": max(held), **_summary(times, ok)}


def self_slip(mu: float = SLIP_FRICTION, steps: int = 16, repeat: int = 3) -> dict:
    """One self-contact slip-threshold row: the :func:`hairpin` folded with friction ``mu``
    (:func:`fold_hairpin`, not timed) and its upper layer pulled from 0.1 to 2 μN₀ (N₀ the
    normal force at no pull) in 20 increments, at ``steps`` RK4 steps per section.

    Returns:
        The row: ``relative_error`` the largest |F/(μN) − 1| over the pulls past 1.2 μN
        (sliding; :func:`hairpin_forces`), ``max_friction_over_mu_normal`` the most friction
        held along the path, ``spread`` the largest spread of the touching tangents (rad: the
        split's resolution is spread/μ), the warm solves' times and the share of solves
        (folding included) converged, stable and not snapped.
    """
    settings = solver.Settings(steps_per_section=steps)
    arm, path = fold_hairpin(mu, settings)
    eq = path[-1]
    ok = [e.converged and e.stable and not e.snapped for e in path]
    n0 = hairpin_forces(eq, 0.0)[1]
    times, sliding, held, spreads = [], [], [], []
    for pull in np.linspace(0.1, 2.0, 20) * mu * n0:
        eq, seconds = _timed(repeat, arm, hairpin_scene(mu, pull), eq, settings,
                             hairpin_pressures())
        times.append(seconds)
        ok.append(eq.converged and eq.stable and not eq.snapped)
        friction, normal, spread = hairpin_forces(eq, pull)
        held.append(friction / (mu * normal))
        spreads.append(spread)
        if pull > 1.2 * mu * normal:
            sliding.append(abs(friction / (mu * normal) - 1.0))
    return {"mu": mu, "steps_per_section": steps, "relative_error": max(sliding, default=math.nan),
            "max_friction_over_mu_normal": max(held), "spread": max(spreads), **_summary(times, ok)}


def run(quick: bool = False, progress=None, cases=CAPSTAN_CASES, configs=CAPSTAN_CONFIGS, steps=STEPS,
        repeat=None, hairpin_steps=HAIRPIN_STEPS) -> dict:
    """The friction benchmark: every capstan case of ``cases`` in every configuration of
    ``configs``, the slip case at every resolution of ``steps``, and the self-contact slip
    case at every resolution of ``hairpin_steps``.

    Args:
        quick: two capstan cases in the first and last configurations, 16 and 64 steps for
            the slip case, 16 for the self-contact one, one repeat (a smoke run).
        progress: called with a line per row (or None).
        cases: (θ in degrees, μ) of the capstan rows.
        configs: (drum stiffness (N/m²), RK4 steps per section) of the capstan rows.
        steps: RK4 steps per section of the slip rows.
        repeat: timings per increment (default 3, 1 when ``quick``).
        hairpin_steps: RK4 steps per section of the self-contact slip rows.

    Returns:
        A JSON-able dict: ``capstan``, ``slip`` and ``self_slip`` rows (:func:`capstan`,
        :func:`slip`, :func:`self_slip`) and ``measured`` (UTC date, load average before and
        after).
    """
    tick = progress or (lambda *_: None)
    if quick:
        cases, configs, steps = cases[::3][:2], (configs[0], configs[-1]), steps[:2]
        hairpin_steps = hairpin_steps[:1]
    repeat = repeat or (1 if quick else 3)
    load_before = os.getloadavg()
    slip(steps=steps[0], repeat=1)  # compiles what a first solve compiles; not timed
    rows = {"capstan": [], "slip": []}
    for stiffness, n in configs:
        for theta_deg, mu in cases:
            rows["capstan"].append(capstan(theta_deg, mu, n, repeat, stiffness))
            tick(f"capstan {theta_deg:g}° μ={mu:g}, drum {stiffness:.0e} N/m², {n} steps/section")
    for n in steps:
        rows["slip"].append(slip(SLIP_FRICTION, n, repeat))
        tick(f"slip μ={SLIP_FRICTION:g}, {n} steps/section")
    rows["self_slip"] = []
    for n in hairpin_steps:
        rows["self_slip"].append(self_slip(SLIP_FRICTION, n, repeat))
        tick(f"self-contact slip μ={SLIP_FRICTION:g}, {n} steps/section")
    rows["measured"] = {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d"), "repeat": repeat,
                        "load_before": list(load_before), "load_after": list(os.getloadavg())}
    return rows


# --------------------------------------------------------------------------- the 3D rows

CAPSTAN_3D_CASES = ((90.0, 0.3), (180.0, 0.3), (90.0, 1.0), (180.0, 1.0))
"""(θ in degrees, μ) of the 3D benchmark's capstan rows (the tilted drum, :func:`drum_scene_3d`)."""

STYLUS_PULLS = tuple(np.linspace(0.0, 2.0, 21))
"""The 3D slip path's pulls, as multiples of μ × STYLUS_PRESS (``tests/solver/test_friction_3d.py``'s)."""

STYLUS_STEPS_SWEEP = (16, 64, STYLUS_STEPS)
"""RK4 steps per section of the 3D benchmark's slip rows."""


def solves_3d(cases=CAPSTAN_3D_CASES, steps=STYLUS_STEPS_SWEEP, degrees_per_step: float = 10.0) -> int:
    """How many solves :func:`run_3d` takes for these rows (a progress bar's total)."""
    wraps = sum(1 + max(4, round(theta / degrees_per_step)) for theta, _ in cases)
    return wraps + len(cases) * (CAPSTAN_PULLS - 1) + len(steps) * (1 + len(STYLUS_PULLS))


def stylus_3d(steps: int = STYLUS_STEPS, mu: float = SLIP_FRICTION, tick=None) -> dict:
    """One 3D slip-threshold row: the stylus pressed on the flat and pulled out of the base
    plane from 0 to 2 μN (:data:`STYLUS_PULLS`), one timed warm 3D solve a pull, at ``steps``
    RK4 steps per section; ``tick`` (or None) is called after every solve.

    Returns:
        The row: ``relative_error`` the largest ||F|/μN − 1| over the pulls past 1.2 μN
        (sliding), ``max_friction_over_mu_normal`` the most friction held along the path,
        ``worst_cos_to_sliding`` the largest cosine between the friction and the tip's
        sliding while it slides (−1: anti-parallel), the warm solves' times and the share of
        solves converged and stable.
    """
    tick = tick or (lambda: None)
    settings = solver.Settings(steps_per_section=steps)
    arm = stylus()
    eq = solver.solve(arm, [], stylus_scene(mu, 0.0), planar=False, settings=settings)
    tick()
    ok, times, sliding, held, cosines = [eq.converged and eq.stable], [], [], [], []
    for t in STYLUS_PULLS:
        before = eq
        start = time.perf_counter()
        eq = solver.solve(arm, [], stylus_scene(mu, t * mu * STYLUS_PRESS), planar=False,
                          warm_start=before, settings=settings)
        times.append(time.perf_counter() - start)
        tick()
        ok.append(eq.converged and eq.stable)
        friction, normal = stylus_forces(eq)
        size = float(np.linalg.norm(friction))
        held.append(size / (mu * normal))
        if t * STYLUS_PRESS > 1.2 * normal:
            slide = eq.tip - before.tip
            sliding.append(abs(size / (mu * normal) - 1.0))
            cosines.append(float(friction @ slide / (size * np.linalg.norm(slide))))
    return {"mu": mu, "steps_per_section": steps, "relative_error": max(sliding),
            "max_friction_over_mu_normal": max(held), "worst_cos_to_sliding": max(cosines),
            **_summary(times, ok)}


def capstan_3d(theta_deg: float, mu: float, degrees_per_step: float = 10.0, tick=None) -> dict:
    """One 3D capstan row: the belt wrapped ``theta_deg`` round the tilted drum by warm 3D
    solves (:func:`wrap_belt_3d`, the pull turned ``degrees_per_step`` a solve), then pulled
    past slip with friction ``mu``, one timed warm 3D solve a pull; ``tick`` (or None) is
    called after every solve.

    Returns:
        The row as :func:`capstan`'s (T₂ = |n(0)|), with ``wrap_seconds`` the wrapping's time.
    """
    tick = tick or (lambda: None)
    theta = math.radians(theta_deg)
    t0, pulls = capstan_pulls(theta, mu)
    start = time.perf_counter()
    arm, path = wrap_belt_3d(theta, t0, degrees_per_step=degrees_per_step, tick=tick)
    wrap_seconds = time.perf_counter() - start
    ok = [eq.converged and eq.stable for eq in path]
    eq, times, ratios = path[-1], [], []
    for t1 in pulls:
        start = time.perf_counter()
        eq = solver.solve(arm, [], drum_scene_3d(theta, t1, mu), planar=False, warm_start=eq)
        times.append(time.perf_counter() - start)
        tick()
        ok.append(eq.converged and eq.stable)
        ratios.append(t1 / belt_tension(eq))
    expected = math.exp(mu * theta)
    return {"theta_deg": theta_deg, "mu": mu, "tilt_deg": TILT_DEG, "capstan": expected,
            "ratio": ratios[-1], "relative_error": abs(ratios[-1] / expected - 1.0),
            "max_ratio_over_capstan": max(ratios) / expected, "slipped": belt_tension(eq) > 1.1 * t0,
            "wrap_seconds": wrap_seconds, **_summary(times, ok)}


def run_3d(cases=CAPSTAN_3D_CASES, steps=STYLUS_STEPS_SWEEP, progress=None, tick=None) -> dict:
    """The 3D friction benchmark (``softarm bench --friction --3d``): the oblique stylus's
    slip threshold at every resolution of ``steps``, then every capstan case of ``cases``
    round the tilted drum (minutes each: the 3D contact solves of a belt whose contact
    grid is ~1,000 RK4 steps).

    Args:
        cases: (θ in degrees, μ) of the capstan rows.
        steps: RK4 steps per section of the slip rows.
        progress: called with a line per row (or None).
        tick: called after every solve (or None): :func:`solves_3d` of the same rows in all.

    Returns:
        A JSON-able dict: ``capstan_3d`` and ``slip_3d`` rows (:func:`capstan_3d`,
        :func:`stylus_3d`) and ``measured`` (UTC date, load average before and after).
    """
    say = progress or (lambda *_: None)
    load_before = os.getloadavg()
    rows = {"slip_3d": [], "capstan_3d": []}
    for n in steps:
        rows["slip_3d"].append(stylus_3d(n, SLIP_FRICTION, tick))
        say(f"3D slip μ={SLIP_FRICTION:g}, {n} steps/section")
    for theta_deg, mu in cases:
        rows["capstan_3d"].append(capstan_3d(theta_deg, mu, tick=tick))
        say(f"3D capstan {theta_deg:g}° μ={mu:g}, drum tilted {TILT_DEG:g}°")
    rows["measured"] = {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d"), "repeat": 1,
                        "load_before": list(load_before), "load_after": list(os.getloadavg())}
    return rows


def format_table_3d(result: dict) -> str:
    """The Markdown tables of a :func:`run_3d` result."""
    lines = ["| 3D capstan θ | μ | drum tilt | T₁/T₂ | e^{μθ} | relative error | most held / e^{μθ} "
             "| wrapping (s) | warm solve (s, median) | path (s) | converged |", "|---" * 11 + "|"]
    for r in result["capstan_3d"]:
        slipped = "" if r["slipped"] else " (did not slip)"
        lines.append(f"| {r['theta_deg']:g}° | {r['mu']:g} | {r['tilt_deg']:g}° | {r['ratio']:.4g} | "
                     f"{r['capstan']:.4g} | {r['relative_error']:.1e}{slipped} | "
                     f"{r['max_ratio_over_capstan']:.4f} | {r['wrap_seconds']:.0f} | "
                     f"{r['median_solve_ms'] / 1e3:.2f} | {r['path_seconds']:.1f} | "
                     f"{r['converged_fraction']:.0%} |")
    lines += _slip_table("3D slip threshold μ", "\\|F\\|/μN", "worst cos(F, sliding)", result["slip_3d"],
                         lambda r: f"{r['worst_cos_to_sliding']:.5f}")
    return "\n".join(lines)


def _slip_table(title: str, ratio: str, extra: str, rows, cell) -> list[str]:
    """The lines (a blank one first) of a slip-threshold table of ``rows``: ``ratio`` the
    friction ratio's Markdown, ``extra`` a column's title between it and the timings and
    ``cell`` its text for a row."""
    lines = ["", f"| {title} | RK4 steps/section | sliding: max \\|{ratio} − 1\\| | most held {ratio} "
             f"| {extra} | warm solve (ms, median) | path (s) | converged |", "|---" * 8 + "|"]
    for r in rows:
        lines.append(f"| {r['mu']:g} | {r['steps_per_section']} | {r['relative_error']:.1e} | "
                     f"{r['max_friction_over_mu_normal']:.4f} | {cell(r)} | "
                     f"{r['median_solve_ms']:.1f} | {r['path_seconds']:.2f} | "
                     f"{r['converged_fraction']:.0%} |")
    return lines


def format_table(result: dict) -> str:
    """The Markdown tables of a :func:`run` result."""
    lines = ["| capstan θ | μ | drum k (N/m²) | RK4 steps/section | T₁/T₂ | e^{μθ} | relative error "
             "| most held / e^{μθ} | warm solve (ms, median) | path (s) | converged |", "|---" * 11 + "|"]
    order = ("mu", "theta_deg", "stiffness", "steps_per_section")
    for r in sorted(result["capstan"], key=lambda r: tuple(r[k] for k in order)):
        slipped = "" if r["slipped"] else " (did not slip)"
        lines.append(f"| {r['theta_deg']:g}° | {r['mu']:g} | {r['stiffness']:.0e} | "
                     f"{r['steps_per_section']} | {r['ratio']:.4g} | {r['capstan']:.4g} | "
                     f"{r['relative_error']:.1e}{slipped} | "
                     f"{r['max_ratio_over_capstan']:.4f} | {r['median_solve_ms']:.1f} | "
                     f"{r['path_seconds']:.2f} | {r['converged_fraction']:.0%} |")
    lines += ["", "| slip threshold μ | RK4 steps/section | sliding: max \\|F/μN − 1\\| | most held F/μN "
              "| warm solve (ms, median) | path (s) | converged |", "|---|---|---|---|---|---|---|"]
    for r in result["slip"]:
        lines.append(f"| {r['mu']:g} | {r['steps_per_section']} | {r['relative_error']:.1e} | "
                     f"{r['max_friction_over_mu_normal']:.4f} | {r['median_solve_ms']:.2f} | "
                     f"{r['path_seconds']:.2f} | {r['converged_fraction']:.0%} |")
    if result.get("self_slip"):
        lines += _slip_table("self-contact slip (hairpin) μ", "F/μN", "tangents' spread / μ",
                             result["self_slip"], lambda r: f"{r['spread'] / r['mu']:.1e}")
    return "\n".join(lines)
