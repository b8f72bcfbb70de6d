"""Coulomb friction on disc contact (docs/design.md §9.1) against oracles that do not trust it.

- Capstan equation: a belt (very small EI) wrapped θ round a fixed drum and pulled at one
  end slips at T₁/T₂ = e^{μθ}; T₂ is read off the base clamp's reaction (global statics).
- Slip threshold: a rod lying on a flat, held by a soft spring, pulled along it: the flat
  holds the pull up to μN and no more (N and the friction from the clamp's reaction).
- μ = 0 is the code before friction bit for bit (tests/frictionless.py's hashes); small μ
  tends to the frictionless state.
- Dissipation never negative along a path; mirror symmetry of a mirrored scene.
- Bad μ: a clear error naming the field.

The capstan and slip scenes are built by softarm_gym/benchmarks/friction_bench.py, which
``softarm bench --friction`` times against the same closed forms.
"""

import functools
import json
import math
from dataclasses import replace

import numpy as np
import pytest

import solver
from softarm_gym.benchmarks.friction_bench import (
    SLED_WEIGHT_N,
    capstan_pulls,
    clamp_tension,
    drum_scene,
    sled,
    sled_forces,
    sled_scene,
    wrap_belt,
)
from solver import designs
from solver import layout as L
from solver.grasp import FreeObject
from tests.solver.test_lean_contact import contact_level, curl_walk

# ---------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("value", [-0.1, math.nan, math.inf, "0.5", True])
@pytest.mark.parametrize("make, field", [
    (lambda mu: solver.Disc((0.2, -0.5), 0.1, friction=mu), "Disc.friction"),
    (lambda mu: solver.Cylinder((0.2, -0.5, 0.0), (0, 0, 1), 0.1, friction=mu), "Cylinder.friction"),
    (lambda mu: solver.Sphere((0.2, -0.5, 0.0), 0.1, friction=mu), "Sphere.friction"),
    (lambda mu: FreeObject(radius=0.1, mass_kg=0.1, seat=(0.2, -0.5), friction=mu),
     "FreeObject.friction"),
])
def test_bad_friction_is_refused_naming_the_field(make, field, value):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        make(value)


# ---------------------------------------------------------------------------- μ = 0


def test_zero_friction_reproduces_the_frictionless_code_bit_for_bit():
    """Every hash of tests/frictionless.py (solves, steppers, env episodes) as the code
    before friction computed them."""
    from tests import frictionless
    expected = json.loads(frictionless.HASHES.read_text())["hashes"]
    assert frictionless.compute() == expected


# ---------------------------------------------------------------------------- capstan

def _wrapped(theta, t0, mirror=1.0):
    """The belt wrapped θ frictionless under the pull t0, every state of the wrapping converged
    and stable: (arm, the wrapped equilibrium)."""
    arm, path = wrap_belt(theta, t0, mirror)
    for eq in path[1:]:
        assert eq.converged and eq.stable
    return arm, path[-1]


@pytest.mark.parametrize("theta_deg, mu", [(90, 0.1), (180, 1.0), (270, 0.5), (360, 0.1),
                                           (360, 1.0)])
def test_capstan_equation_at_the_onset_of_slip(theta_deg, mu):
    """Wrapped frictionless under a small tension T₀ (the pull turned round in 10° steps),
    then held with friction and the pull T₁ raised past T₀·e^{μθ}: the clamp's side T₂ stays
    at T₀ while the wrap holds and rises once all of it slips, at T₁/T₂ = e^{μθ} (1 %)."""
    theta = math.radians(theta_deg)
    capstan = math.exp(mu * theta)
    t0, pulls = capstan_pulls(theta, mu)  # the largest pull 3 N: penetration below 0.3 mm
    assert pulls[-1] == pytest.approx(1.3 * capstan * t0)
    arm, eq = _wrapped(theta, t0)
    ratios = []
    for t1 in pulls:
        eq = solver.solve(arm, [], drum_scene(theta, t1, mu), warm_start=eq)
        assert eq.converged and eq.stable
        t2 = clamp_tension(eq)
        ratios.append(t1 / t2)
        assert ratios[-1] <= 1.01 * capstan  # friction never holds more than the capstan
    assert t2 > 1.1 * t0  # the clamp's side felt the pull: all of the wrap slipped
    assert abs(ratios[-1] / capstan - 1.0) < 0.01


PULLS = (1.0, 1.3, 1.7, 2.2, 1.6, 1.1, 1.5, 2.5)  # of T0: up, down, up again


@functools.cache
def _drum_path(mu, mirror=1.0):
    """The belt wrapped 90° (T0 = 0.5 N), then held with friction μ and pulled by PULLS·T0:
    (equilibria)."""
    theta, t0 = math.pi / 2, 0.5
    arm, eq = _wrapped(theta, t0, mirror)
    out = []
    for pull in PULLS:
        eq = solver.solve(arm, [], drum_scene(theta, pull * t0, mu, mirror), warm_start=eq)
        assert eq.converged and eq.stable
        out.append(eq)
    return tuple(out)


def test_small_friction_tends_to_the_frictionless_state():
    free = _drum_path(0.0)[-1]
    assert free.friction_samples.shape[0] == 0 and free.dissipated == 0.0
    gaps = [float(np.max(np.abs(_drum_path(mu)[-1].positions - free.positions)))
            for mu in (0.1, 0.01, 0.001)]
    assert gaps[0] > 1e-5  # friction does something
    assert gaps[1] < 0.2 * gaps[0] and gaps[2] < 0.2 * gaps[1]


def test_dissipation_is_never_negative_and_grows_along_a_path():
    """Pulled up, let back and pulled again: the work friction dissipates never falls."""
    path = _drum_path(0.5)
    work = np.array([eq.dissipated for eq in path])
    assert work[0] >= 0.0 and np.all(np.diff(work) >= 0.0)
    assert work[-1] > work[3] > 0.0  # it slid on the way up, and again past the first peak
    for eq in path:
        assert np.all(eq.friction_samples[..., L.FS_WORK] >= 0.0)
        assert np.all(eq.friction_samples[..., L.FS_SLIP] >= 0.0)


def test_mirrored_scene_gives_the_mirrored_answer():
    """The belt's path with friction and its mirror image in the x axis."""
    flip = np.array([1.0, -1.0])
    for eq, image in zip(_drum_path(0.5), _drum_path(0.5, -1.0)):
        assert np.max(np.abs(image.positions * flip - eq.positions)) < 1e-9
        assert np.max(np.abs(image.contact_force * flip - eq.contact_force)) < 1e-7
        assert abs(image.dissipated - eq.dissipated) <= 1e-9 * eq.dissipated + 1e-15


# ---------------------------------------------------------------------------- slip threshold


def test_a_rod_on_a_flat_slips_at_mu_times_the_normal_force():
    """A soft massless spring (0.2 m, EA 5 N) from the clamp, then a heavy stiff rod (0.5 m,
    0.2 kg/m) lying on a flat (a disc of radius 10 km), pulled along +x at its tip. From the
    clamp's reaction n(0): friction F = n_x(0) − T, normal N = n_y(0) + weight. The flat holds
    the pull (|F| ≈ T, the spring takes the rest) until T = μN, never more than μN, and
    exactly μN once the rod slides."""
    mu = 0.5
    arm = sled()
    weight = SLED_WEIGHT_N
    # Laid on the flat from where it is straight and weightless.
    eq = solver.solve(arm, [], sled_scene(mu, gravity=0.0))
    held = []
    for t in np.linspace(0.0, 2.0, 21) * mu * weight:
        eq = solver.solve(arm, [], sled_scene(mu, t), warm_start=eq)
        assert eq.converged and eq.stable
        friction, normal = sled_forces(eq, t)
        assert normal > 0.9 * weight
        assert abs(friction) <= mu * normal * (1 + 1e-3)
        held.append((t / (mu * normal), -friction / (mu * normal)))
    held = np.array(held)
    below = held[:, 0] < 0.9
    assert np.all(np.abs(held[below, 1] - held[below, 0]) < 0.02)  # it sticks: the flat holds T
    assert np.all(held[held[:, 0] > 1.2, 1] > 0.99)  # it slides: friction μN


# ---------------------------------------------------------------------------- steppers


def test_stepper_and_batch_stepper_carry_the_tangential_state_alike():
    """A random walk curling OctArm V onto a disc with μ = 0.5: the Stepper's lean contact
    path and every copy of a BatchStepper give the same states and dissipation (1e-9 L), the
    dissipation never falls (also where the arm leaves the disc), and friction changes the
    answer while it touches (against μ = 0)."""
    arm = designs.octarm_v()
    scene = _curl_scene(0.5)
    walk = curl_walk(arm, 25, seed=7)
    stepper = solver.Stepper(arm, scene)
    frictionless = solver.Stepper(arm, _curl_scene(0.0))
    batch = solver.BatchStepper(arm, scene, 2)
    for s in (stepper, frictionless):
        s.reset(walk[0])
    batch.reset(np.array([walk[0]] * 2))
    work, apart = [], []
    for p in walk[1:]:
        assert stepper.step(p).converged
        frictionless.step(p)
        apart.append(float(np.max(np.abs(stepper.tip - frictionless.tip))))
        report = batch.step(np.array([p, p]))
        assert np.all(report.converged)
        work.append(stepper.equilibrium.dissipated)
        for k in range(2):
            eq = batch.equilibrium(k)
            assert np.max(np.abs(eq.positions - stepper.equilibrium.positions)) < 1e-9 * arm.length
            assert abs(eq.dissipated - work[-1]) <= 1e-9 * max(work[-1], 1e-12)
    assert np.all(np.diff(work) >= 0.0) and work[-1] > 0.0
    assert max(apart) > 1e-4 * arm.length


def _curl_scene(mu):
    """OctArm V hanging beside a disc (the wrap task's geometry), friction μ."""
    return solver.Scene(base_angle_deg=0.0, obstacles=(solver.Disc((0.16, -0.55), 0.13, 2e4, friction=mu),))


# ---------------------------------------------------------------------------- free object


def test_a_held_object_balances_normal_and_tangential_point_forces():
    """tests/solver/test_grasp.py's held cylinder (OctArm V channel I at 90 %, 0.5 kg): found
    frictionless, then wrapped again with μ = 0.5 where it was held and let go. The object is
    held, and its balance summed independently of the solver's base reaction — the penalty
    law on a spline through the backbone (normal) plus the friction samples' impulses
    (tangential) — carries its weight; their moment about its axis vanishes (it turned until
    it did: the supports are frictionless)."""
    from scipy.interpolate import CubicSpline

    from solver.grasp import settle
    arm = designs.octarm_v()
    half = max(t.radius + t.material.outer_radius for t in arm.tubes if t.last_section == 2)
    k = min(t.material.ring_stiffness for t in arm.tubes if t.last_section == 2)
    center = (-0.16, -0.062)
    frictionless = FreeObject(radius=0.119 + half, mass_kg=0.5, seat=(center[0], center[1] - 0.3),
                              stiffness=k)
    p = np.zeros(arm.n_inputs(True))
    for obj in (frictionless, replace(frictionless, friction=0.5)):
        eq = None
        for fraction in np.arange(0.3, 0.901, 0.05):
            p[0::2] = fraction * arm.max_pressure
            eq = solver.solve(arm, p, solver.Scene(obstacles=(obj.disc(center),)), warm_start=eq)
        g = settle(arm, p, solver.Scene(), obj, center=center, warm_start=eq)
        assert g.converged and g.held
        center = g.center
    weight = obj.mass_kg * 9.81
    eq = g.arm
    distinct = np.concatenate([[True], np.diff(eq.s) > 0])
    s = np.linspace(0.0, eq.s[-1], 100_001)
    rel = CubicSpline(eq.s[distinct], eq.positions[distinct])(s) - g.center
    dist = np.hypot(rel[:, 0], rel[:, 1])
    normal = -np.trapezoid((k * np.maximum(obj.radius - dist, 0.0) / dist)[:, None] * rel, s, axis=0)
    fs = eq.friction_samples[:, :, 0]
    tangential = -np.array([np.nansum(fs[..., L.FS_F]), np.nansum(fs[..., L.FS_F + 1])])
    assert np.abs(tangential).max() > 1e-3 * weight  # friction carries part of it
    np.testing.assert_allclose(normal + tangential, [0.0, weight], atol=0.005 * weight)
    arm_r = fs[..., L.FS_R:L.FS_R + 2] - g.center
    moment = -np.nansum(arm_r[..., 0] * fs[..., L.FS_F + 1] - arm_r[..., 1] * fs[..., L.FS_F])
    assert abs(moment) <= 1e-3 * weight * obj.radius
    assert g.arm_moment == pytest.approx(moment, abs=1e-12)


# ---------------------------------------------------------------------------- self-contact


def test_self_contact_tracing_leaves_the_friction_samples_to_the_recording_pass():
    """With self-contact every pass first redraws the arm's pieces through an integration of
    its own (contact._prepare_partners), which records. Friction's samples — the anchors that
    accepting a state takes — are the recording pass's alone: a pass that records nothing, at
    a moved state (a Newton step's difference column), leaves them as they were."""
    from solver.kernels import contact as contact_kernels
    from solver.kernels import stepping
    from solver.paths.lean_contact import ContactRows
    from solver.problem import Problem, pack
    from solver.rod import rest_strains_into

    arm = designs.octarm_v()
    ring = arm.tubes[0].material.ring_stiffness
    scene = solver.Scene(base_angle_deg=13.44, self_contact=ring,
                         obstacles=(solver.Disc((-0.09, -0.395), 0.04, ring, friction=0.5),))
    p = np.array([60, 0, 60, 0, 60, 0]) * solver.PSI
    eq = solver.solve(arm, p, scene)
    assert eq.converged and eq.in_contact
    settings = solver.Settings()
    packed = pack(arm, "full", settings)
    rows = ContactRows(Problem(arm, packed, scene, "full", True, settings, np.zeros(arm.n_inputs(True)),
                               np.zeros(arm.n_channels)), 1, 1)
    rows.adopt(0, eq)
    contact = rows.contact
    assert contact[stepping.CT_OK][0]
    grid = tuple(contact[i] for i in range(stepping.CT_THETA0, stepping.CT_SELF + 1))
    level = contact_level(contact, 0)
    fs = level[L.L_FRICTION]
    assert np.any(np.isfinite(fs[..., L.FS_R]))  # samples near the disc
    before = fs.copy()
    rest = np.empty_like(contact[stepping.CT_REST][0])
    rest_strains_into(level[L.L_P], rows.layout.tubes_i, rows.layout.tubes_f, rows.layout.secf, rest)
    moved = contact[stepping.CT_NODES][0] + 1e-4
    F = np.empty_like(moved)
    contact_kernels.newton_system(moved, grid, rest, level, F, np.empty((0, 0)), False,
                                  np.empty((0, 6, 6)), contact_kernels.new_partners(grid))
    assert np.array_equal(fs, before, equal_nan=True)
