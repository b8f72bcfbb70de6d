"""Coulomb friction in 3D (cylinders, spheres; docs/design.md §9.1) against oracles that do not
trust it, and the 3D stepper's lean path with friction (§10.1).

- Slip threshold, oblique: a stylus pressed on a flat and pulled out of the base plane. From
  global statics (the clamp's reaction less the tip force, split along the flat's normal):
  the friction never exceeds μN; while the tip holds it opposes the pull; once the tip
  slides it is μN in magnitude and anti-parallel to the sliding (which is not the pull's
  direction: the stylus's elasticity turns it).
- Capstan with the drum's axis tilted out of the base plane: T₁/T₂ = e^{μθ} at the onset of
  slip (the belt is isotropic, so the answer is the planar one turned).
- Mirror symmetry: the oblique stylus path mirrored in z = 0 gives the mirrored answer.
- Dissipation never negative, never decreasing along a load–unload–reload path and a 3D
  stepper walk.
- The segment maps' Jacobian by the variational equations carries friction's consistent
  tangent: it agrees with forward differences where friction dominates the Jacobian.

The scenes live in softarm_gym/benchmarks/friction_bench.py.
"""

import functools
import math

import numpy as np
import pytest

import solver
from softarm_gym.benchmarks.friction_bench import (
    STYLUS_HEADING_DEG,
    STYLUS_PRESS,
    STYLUS_STEPS,
    belt_tension,
    capstan_pulls,
    drum_scene_3d,
    stylus,
    stylus_forces,
    stylus_scene,
    wrap_belt_3d,
)
from solver import designs
from solver import layout as L
from solver.kernels import spatial_contact as kernels
from solver.kernels import spatial_stepping as stepping
from solver.paths.lean_spatial_contact import SpatialContactRows
from solver.problem import Problem, pack
from solver.rod import rest_strains_into
from tests.solver.test_lean_spatial_contact import K_TUBE, curl_walk_3d

MU = 0.5
STYLUS_SETTINGS = solver.Settings(steps_per_section=STYLUS_STEPS)


@functools.cache
def _stylus_path(mirror: float = 1.0, pulls: tuple = tuple(np.linspace(0.0, 2.0, 21))) -> list:
    """The stylus pressed on the flat (friction MU), then pulled by ``pulls`` × μ·press
    along the oblique heading, one warm solve a pull: the equilibria (the pressed one first)."""
    arm = stylus()
    path = [solver.solve(arm, [], stylus_scene(MU, 0.0, mirror=mirror), planar=False,
                         settings=STYLUS_SETTINGS)]
    for t in pulls:
        path.append(solver.solve(arm, [], stylus_scene(MU, t * MU * STYLUS_PRESS, mirror=mirror),
                                 planar=False, warm_start=path[-1], settings=STYLUS_SETTINGS))
    return path


def _pull_vector(pull: float) -> np.ndarray:
    a = math.radians(STYLUS_HEADING_DEG)
    return pull * np.array([math.cos(a), 0.0, math.sin(a)])


def test_an_obliquely_pulled_stylus_slips_at_mu_n_against_its_sliding():
    path = _stylus_path()
    pulls = np.linspace(0.0, 2.0, 21) * MU * STYLUS_PRESS
    held, slid = 0, 0
    for before, eq, pull in zip(path[:-1], path[1:], pulls):
        assert eq.converged and eq.stable
        friction, normal = stylus_forces(eq)
        assert normal > 0.9 * STYLUS_PRESS
        size = float(np.linalg.norm(friction))
        assert size <= MU * normal * (1 + 5e-4)  # never outside the cone
        slip = eq.tip - before.tip
        t = pull / (MU * normal)
        if 0.2 < t < 0.9:  # it holds: the tip barely moves, friction opposes the pull
            held += 1
            assert np.linalg.norm(slip) < 2e-4
            pull_vector = _pull_vector(pull)
            assert friction @ pull_vector / (size * pull) < -0.99
            assert np.linalg.norm(friction + pull_vector) < 0.1 * pull
        if t > 1.2:  # it slides: friction is μN, anti-parallel to the sliding
            slid += 1
            assert np.linalg.norm(slip) > 2e-3
            assert abs(size / (MU * normal) - 1.0) < 5e-4
            assert friction @ slip / (size * np.linalg.norm(slip)) < -0.9995
            # ... which is not the pull's direction (more than 10° off it).
            assert friction @ _pull_vector(pull) / (size * pull) > math.cos(math.radians(170.0))
    assert held >= 5 and slid >= 5


def test_the_mirrored_oblique_stylus_gives_the_mirrored_answer():
    flip = np.array([1.0, 1.0, -1.0])
    path, mirrored = _stylus_path(), _stylus_path(-1.0)
    for eq, image in zip(path, mirrored):
        assert np.max(np.abs(image.positions * flip - eq.positions)) < 1e-9 * 0.3
        assert np.max(np.abs(image.contact_force * flip - eq.contact_force)) < 1e-6
        # The work sums |F|·(|d| − μ pen), differences of nearly equal numbers, so it agrees
        # to a share of the whole path's dissipation, not of its partial sums: early in the
        # stick phase (1e-6 J of the path's 2.5e-2) the mirrored Newton iterates leave
        # 1e-14 J (2.8e-8 of it) after Newton steps past a kink (measured up to 4.3e-9 of the
        # path's total at any pull; a mirror asymmetry in the friction would show at O(1)).
        assert abs(image.dissipated - eq.dissipated) <= 1e-8 * path[-1].dissipated


def test_dissipation_in_3d_is_never_negative_and_grows_along_a_path():
    """The stylus pulled past slip, let back, and pulled again."""
    pulls = tuple(np.concatenate([np.linspace(0.0, 1.6, 9), np.linspace(1.2, 0.0, 4),
                                  np.linspace(0.4, 1.8, 8)]))
    path = _stylus_path(1.0, pulls)
    work = np.array([eq.dissipated for eq in path])
    assert all(eq.converged for eq in path)
    assert work[0] >= 0.0 and np.all(np.diff(work) >= 0.0)
    assert work[-1] > work[9] > 0.0  # it slid on the way out, and again on the way back
    for eq in path:
        assert np.all(eq.friction_samples[..., L.FS_WORK] >= 0.0)
        assert np.all(eq.friction_samples[..., L.FS_SLIP] >= 0.0)


# ---------------------------------------------------------------------------- the capstan


@pytest.mark.long_oracle  # 10-15 min a case on the 2-core machine: .ci/run runs it after make test
@pytest.mark.parametrize("theta_deg, mu", [(90.0, 0.3), (180.0, 1.0)])
def test_capstan_round_a_tilted_drum(theta_deg, mu):
    """The belt wrapped θ round a drum whose axis leaves the base plane by 30°, by warm
    solves turning the pull, then pulled past T₀ e^{μθ} with friction."""
    theta = math.radians(theta_deg)
    t0, pulls = capstan_pulls(theta, mu)
    arm, path = wrap_belt_3d(theta, t0)
    assert all(eq.converged and eq.stable for eq in path)
    eq, ratios = path[-1], []
    for t1 in pulls:
        eq = solver.solve(arm, [], drum_scene_3d(theta, t1, mu), planar=False, warm_start=eq)
        assert eq.converged and eq.stable
        ratios.append(t1 / belt_tension(eq))
    capstan = math.exp(mu * theta)
    assert belt_tension(eq) > 1.1 * t0  # the whole wrap slid
    assert max(ratios) <= 1.01 * capstan
    assert abs(ratios[-1] / capstan - 1.0) < 0.01


# ---------------------------------------------------------------------------- the 3D stepper


def _cylinder_scene(mu):
    """OctArm V hanging beside a cylinder whose axis leaves the plane (the 3D wrap's
    geometry, tests/solver/test_lean_spatial_contact.py), friction μ."""
    return solver.Scene(base_angle_deg=0.0, obstacles=(
        solver.Cylinder((-0.4, -0.7, 0.1), (0.0, 0.3, 1.0), 0.13, K_TUBE, friction=mu),))


@functools.cache
def _walk():
    """A seeded 3D walk of OctArm V onto and along the cylinder with friction, by the 3D
    Stepper: every step's (last path, equilibrium)."""
    arm = designs.octarm_v()
    stepper = solver.Stepper(arm, _cylinder_scene(MU), planar=False)
    pressures = curl_walk_3d(arm, 30, seed=7)
    stepper.reset(pressures[0])
    out = []
    for p in pressures[1:]:
        assert stepper.step(p).converged
        out.append((stepper.last_path, stepper.equilibrium))
    return arm, pressures[1:], out


def test_the_3d_stepper_takes_friction_on_its_lean_path():
    """The 3D lean path carries the tangential state: with μ = 0.5 the walk's contact steps
    are lean; each lands on an equilibrium of the frictional problem with its own anchors
    (the general path, warm-started from it at the same pressures, stays there); the
    dissipation never falls; friction changes the answer against μ = 0."""
    arm, pressures, walk = _walk()
    scene = _cylinder_scene(MU)
    assert solver.Stepper(arm, scene, planar=False).lean_contact
    lean = [(p, eq) for p, (path, eq) in zip(pressures, walk) if path == "lean contact"]
    assert len(lean) >= 5
    assert max(eq.dissipated for _, eq in lean if eq.in_contact) > 0.0
    for p, eq in lean:
        again = solver.solve(arm, p, scene, planar=False, warm_start=eq)
        assert again.converged and again.in_contact == eq.in_contact
        np.testing.assert_allclose(again.positions, eq.positions, atol=1e-9)
        assert abs(again.dissipated - eq.dissipated) <= 1e-9 * max(eq.dissipated, 1e-12)
    work = [eq.dissipated for _, eq in walk]
    assert np.all(np.diff(work) >= 0.0)
    frictionless = solver.Stepper(arm, _cylinder_scene(0.0), planar=False)
    frictionless.reset(curl_walk_3d(arm, 30, seed=7)[0])
    apart = 0.0
    for p, (_, eq) in zip(pressures, walk):
        frictionless.step(p)
        apart = max(apart, float(np.max(np.abs(frictionless.tip - eq.tip))))
    assert apart > 1e-3 * arm.length


# ---------------------------------------------------------------------------- the Jacobian


def test_the_variational_jacobian_carries_frictions_consistent_tangent():
    """At a state pressed on the cylinder with anchors (some samples sticking, some
    slipping), moved a little off the accepted state so that no sample sits on the cone's
    edge: the Jacobian by the variational equations equals the forward differences' (as it
    does without friction), where friction makes most of it."""
    arm, _, walk = _walk()
    eq = next(eq for path, eq in walk if path == "lean contact" and eq.in_contact
              and np.any(eq.friction_samples[..., L.FS_SLIP] > 0.0))
    scene = _cylinder_scene(MU)
    packed = pack(arm, "full", solver.Settings())
    rows = SpatialContactRows(Problem(arm, packed, scene, "full", False, solver.Settings(),
                                      np.zeros(arm.n_inputs(False)), np.zeros(arm.n_channels)), 1)
    rows.adopt(0, eq)
    assert rows.on_contact_layout(0)
    contact = rows.contact
    grid = tuple(contact[i] for i in range(stepping.C3_QUAT0, stepping.C3_START + 1))
    nodes = contact[stepping.C3_NODES][0].copy()
    nodes[1:, L.CS_R:L.CS_R + 3] += np.random.default_rng(1).normal(size=(nodes.shape[0] - 1, 3)) * 1e-6
    fs = contact[stepping.C3_FRICTION][0].copy()
    level = (contact[stepping.C3_P][0], contact[stepping.C3_Q], contact[stepping.C3_PLATE],
             contact[stepping.C3_TARGET], contact[stepping.C3_OBSTACLES][0],
             contact[stepping.C3_MU][0], fs)
    frictionless = (*level[:L.L_MU], np.zeros(1), fs[:0])
    rest = np.empty_like(contact[stepping.C3_REST][0])
    rest_strains_into(level[L.L_P], rows.layout.tubes_i, rows.layout.tubes_f, rows.layout.secf, rest)
    n = contact[stepping.C3_WEIGHTS].shape[0]
    F = np.empty(n)
    blocks = np.empty((nodes.shape[0], L.N_CTANGENT, L.N_CTANGENT))

    def jacobians(lvl):
        variational, differences = np.empty((n, n)), np.empty((n, n))
        kernels.tangent_system(nodes, grid, rest, lvl, F, variational, blocks)
        kernels.newton_system(nodes, grid, rest, lvl, F, differences, True, blocks.copy(),
                              contact[stepping.C3_SCALES], kernels.NO_TETHER)
        return variational, differences

    variational, differences = jacobians(level)
    without = jacobians(frictionless)[1]
    size = np.linalg.norm(differences)
    assert np.linalg.norm(differences - without) > 0.3 * size  # friction's share
    assert np.linalg.norm(variational - differences) < 1e-3 * size
