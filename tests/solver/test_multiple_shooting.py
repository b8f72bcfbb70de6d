"""Multiple shooting for dead-load solves, planar and spatial: the path for arms whose single
shooting is ill-conditioned (L·√(N/EI) large), checked against scipy's collocation solver,
against single shooting where both apply, and against the global moment balance."""

import dataclasses

import numpy as np
import pytest
from scipy.integrate import simpson

import solver
from solver import PSI, designs
from solver import layout as L
from solver.inputs import request
from solver.kernels import spatial_shooting as shooting_kernels
from solver.kernels.homotopy import ramp_crowding
from solver.paths.planar import solve_single
from solver.paths.shooting import solve_multiple
from solver.paths.spatial import solve_spatial_multiple, solve_spatial_single
from solver.problem import context, pack, shooting_layout
from solver.rod import base_rotation, rotation_to_quaternion
from tests.solver import naive


def _long(arm, factor):
    return dataclasses.replace(arm, sections=tuple(
        dataclasses.replace(s, length=s.length * factor) for s in arm.sections))


def _channel(arm, planar_psi):
    p = np.zeros(arm.n_channels)
    for value, (_, idx) in zip(planar_psi, arm.planar_channels):
        p[list(idx)] = value * PSI
    return p


def test_multiple_equals_single_shooting_on_a_well_conditioned_arm():
    """Both integrate the same ODE with the same RK4 steps: the same equilibrium."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=45, payload_kg=0.1)
    p = np.array([0, 60, 20, 0, 80, 10]) * PSI
    problem = request(arm, p, scene, "full", True, None, solver.Settings())
    single = solve_single(problem)
    multiple = solve_multiple(problem)
    assert single.converged and multiple.converged and multiple.stable
    np.testing.assert_allclose(multiple.positions, single.positions, atol=1e-9)
    np.testing.assert_allclose(multiple.internal_moment, single.internal_moment, atol=1e-8)


@pytest.mark.parametrize("factor, payload", [(4.0, 1.0), (5.5, 2.0)])
def test_long_heavy_arm_agrees_with_solve_bvp(factor, payload):
    """A 3.5-4.8 m OctArm VI with a payload, from a base 30° above horizontal: index
    (L·√(N/EI)) 100-190, where single shooting would amplify errors by e^100. Converges to
    scipy's collocation solution at fourth order in the RK4 step."""
    arm = _long(designs.octarm_vi(), factor)
    psi = [20, 0, 0, 30, 10, 0]
    scene = solver.Scene(base_angle_deg=120, payload_kg=payload)
    packed = pack(arm, "full", solver.Settings())
    assert context(arm, packed, scene, 2, solver.Settings()).shooting_index > 100
    errors = []
    for steps in (32, 64):
        # The grid pinned (no refinement), to see its order: the step-size check asks for
        # more steps here, so the result is flagged unconverged; Newton met its tolerance.
        settings = solver.Settings(steps_per_section=steps, max_refinement=1)
        eq = solver.solve(arm, np.array(psi) * PSI, scene, settings=settings)
        assert eq.residual <= settings.tol and eq.stable and eq.shooting_nodes.size
        if not errors:
            # Collocation needs a start near the hanging shape (from the straight rod it
            # refines without end): ours seeds it; the converged BVP solution is its own.
            tau = np.linspace(0.0, 1.0, 81)
            guess = np.zeros((6 * len(arm.sections), tau.size))
            state = np.column_stack([eq.positions, eq.angles, eq.internal_force,
                                     eq.internal_moment])
            start = 0
            for i, end in enumerate(eq.section_ends):
                local = (eq.s[start:end + 1] - eq.s[start]) / arm.sections[i].length
                for k in range(6):
                    guess[6 * i + k] = np.interp(tau, local, state[start:end + 1, k])
                start = end + 1
            tip, _, _ = naive.solve_bvp_planar(arm, _channel(arm, psi), scene, nodes=tau.size,
                                               guess=guess)
        errors.append(np.linalg.norm(eq.tip - tip))
    assert errors[1] < errors[0] / 8  # RK4: fourth order (16x), with room for the ends
    assert errors[1] < 1e-4 * arm.length
    # Warm steps continue from the shooting nodes.
    settings = solver.Settings(steps_per_section=64)
    warm = solver.solve(arm, np.array(psi) * 1.1 * PSI, scene, warm_start=eq, settings=settings)
    cold = solver.solve(arm, np.array(psi) * 1.1 * PSI, scene, settings=settings)
    assert warm.converged and warm.iterations < cold.iterations
    np.testing.assert_allclose(warm.tip, cold.tip, atol=1e-9)


# ----------------------------------------------------------------------------- spatial


def _spatial_paths(arm, pressures, scene, model="full"):
    problem = request(arm, pressures, scene, model, False, None, solver.Settings())
    return solve_spatial_single(problem), solve_spatial_multiple(problem)


def _global_moment_balance(arm, scene, eq):
    """|m(0) − Σ moments of the external loads about the base| over the load moment scale,
    from the recorded shape and the loads only (Simpson's rule for the self-weight)."""
    g = np.array([0.0, -scene.gravity, 0.0])
    force = scene.payload_kg * g
    total = np.cross(eq.positions[-1], force)
    scale = np.linalg.norm(force) * arm.length
    start = 0
    for section, end in zip(arm.sections, eq.section_ends):
        rows = slice(start, end + 1)
        total = total + simpson(np.cross(eq.positions[rows], section.mass_per_length * g),
                                x=eq.s[rows], axis=0)
        total = total + np.cross(eq.positions[end], section.endplate_mass * g)
        scale += (section.mass_per_length * section.length + section.endplate_mass) \
            * scene.gravity * arm.length
        start = end + 1
    return float(np.linalg.norm(eq.internal_moment[0] - total) / scale)


@pytest.mark.parametrize("design", ["octarm_v", "octarm_vi", "ct"])
def test_spatial_multiple_equals_single_shooting_on_well_conditioned_arms(design):
    """Random 3D scenes that single shooting solves: multiple shooting (another set of
    unknowns, the same RK4 steps) finds the same equilibrium and the same stability."""
    arm = designs.get(design)
    rng = np.random.default_rng(3)
    for _ in range(2):
        scene = solver.Scene(base_angle_deg=float(rng.uniform(0, 180)),
                             payload_kg=float(rng.uniform(0, 0.3)))
        p = rng.uniform(0, arm.max_pressure, arm.n_inputs(False))
        single, multiple = _spatial_paths(arm, p, scene)
        assert single.converged and multiple.converged
        assert single.stable == multiple.stable
        np.testing.assert_allclose(multiple.positions, single.positions, atol=1e-9 * arm.length)
        np.testing.assert_allclose(multiple.base_moment, single.base_moment, atol=1e-8)


def _soft(arm, factor):
    """``arm`` with every modulus and stiffness × ``factor`` (its weight unchanged)."""
    sections = tuple(dataclasses.replace(s, EA=s.EA * factor, GA=s.GA * factor, EI=s.EI * factor,
                                         GJ=s.GJ * factor) for s in arm.sections)
    tubes = tuple(dataclasses.replace(t, material=dataclasses.replace(
        t.material, youngs_modulus=t.material.youngs_modulus * factor,
        shear_modulus=t.material.shear_modulus * factor)) for t in arm.tubes)
    return dataclasses.replace(arm, sections=sections, tubes=tubes,
                               max_pressure=arm.max_pressure * factor)


def test_soft_arm_in_3d_needs_and_gets_multiple_shooting():
    """OctArm VI at 1/47 of its stiffness, curled out of plane (a `softarm stress` soft-class
    scene): L·√(N/EI) > 20, single shooting cannot converge, multiple shooting does, and the
    result passes the global moment balance, which does not use the shooting method."""
    arm = _soft(designs.octarm_vi(), 0.02146)
    scene = solver.Scene(base_angle_deg=76.9, payload_kg=0.095)
    p = np.array([0.801, 0.096, 0.194, 0.096, 0.244, 0.788, 0.206, 0.38, 0.653]) * arm.max_pressure
    settings = solver.Settings()
    assert context(arm, pack(arm, "full", settings), scene, 3, settings).shooting_index > 20
    single, multiple = _spatial_paths(arm, p, scene)
    assert not single.converged
    assert multiple.converged and multiple.stable
    eq = solver.solve(arm, p, scene, planar=False)
    assert eq.converged and eq.stable
    # (solve() refines the grid where the step-size check asks: same state, finer steps.)
    np.testing.assert_allclose(eq.tip, multiple.tip, atol=1e-3 * arm.length)
    assert np.abs(eq.base_moment[:2]).max() > 0.01 * np.abs(eq.base_moment).max()  # out of plane
    assert _global_moment_balance(arm, scene, eq) < 1e-5


@pytest.mark.parametrize("load, stable", [(2.3, True), (2.6, False)])  # π²/4 = 2.467
def test_spatial_multiple_shooting_stability_finds_the_euler_load(load, stable):
    """The straight upright column under a dead tip load: both bending planes reach their
    conjugate point together (det δφ only touches zero); the multiple-shooting test, which
    counts real negative eigenvalues while the fields are resolved, flags it as the
    single-shooting test does."""
    rod = designs.rod(length=1.0, EI=1.0, EA=1e10, GA=1e10, GJ=0.7)
    settings = solver.Settings(steps_per_section=100)
    scene = solver.Scene(base_angle_deg=180, tip_force=(0, -load, 0), gravity=0)
    packed = pack(rod, "full", settings)
    layout, segs, _ = shooting_layout(rod, packed)
    ctx = context(rod, layout, scene, 3, settings)
    quats = np.empty((segs.shape[0], 4))
    rotation_to_quaternion(base_rotation(scene.base_theta), quats[0])
    quats[1:] = quats[0]
    moms = np.zeros((segs.shape[0], 3))
    rest = np.array([[0.0], [0.0], [1.0]])
    work = np.empty((6, L.NSTATE))
    assert shooting_kernels.stability_test(quats, moms, segs, layout.secf, layout.sec_steps,
                                           layout.c_j, rest, ctx.loads, work) == stable


def _near_lockup(arm, fraction=0.999):
    """``arm`` re-rated so that its maximum pressure holds λ = fraction · λmax."""
    m = arm.tubes[0].material
    p = float(solver.pressure_from_stretch(fraction * m.max_stretch, m.youngs_modulus,
                                           m.inner_radius, m.outer_radius, m.wind_angle_deg))
    return dataclasses.replace(arm, max_pressure=p)


def test_ramp_crowding_measures_where_a_ramp_changes_the_strains():
    """Near braid lock-up most of a 0 → p_max ramp's curvature appears in its first 1/256
    (crowding in the hundreds); for the thesis's arms a ramp is nearly uniform."""
    settings = solver.Settings()
    for arm in (designs.octarm_v(), designs.ct()):
        packed = pack(arm, "full", settings)
        zero, full = np.zeros(arm.n_channels), np.full(arm.n_channels, arm.max_pressure)
        assert 1.0 <= ramp_crowding(zero, full, packed.tubes_i, packed.tubes_f) < 1.3
        assert ramp_crowding(full, full, packed.tubes_i, packed.tubes_f) == 1.0
    arm = _near_lockup(designs.octarm_v())
    packed = pack(arm, "full", settings)
    zero, full = np.zeros(arm.n_channels), np.full(arm.n_channels, arm.max_pressure)
    assert ramp_crowding(zero, full, packed.tubes_i, packed.tubes_f) > 100
    # Symmetric in the ramp's direction.
    assert ramp_crowding(full, zero, packed.tubes_i, packed.tubes_f) == \
        ramp_crowding(zero, full, packed.tubes_i, packed.tubes_f)


@pytest.mark.parametrize("model, base, payload, fractions", [
    ("unshearable", 64.78, 0.337, [0.955, 0.934, 0, 0, 0.924, 0.907, 0, 0, 0]),
    ("full", 17.17, 0.43, [0, 0, 0, 0.972, 0.993, 0, 0, 0, 0]),
    ("unshearable", 136.5, 0.22, [0, 0.99, 0.992, 0.996, 0.967, 0.906, 0.907, 0, 0.999]),
])
def test_near_lockup_spatial_solve_converges(model, base, payload, fractions):
    """`softarm stress` near-lock-up scenes that single shooting lost when its smallest
    continuation step was a fixed share of the pressure ramp (1/256, most of the curvature
    change): converged, stable, and balanced."""
    arm = _near_lockup(designs.octarm_v())
    scene = solver.Scene(base_angle_deg=base, payload_kg=payload)
    eq = solver.solve(arm, np.array(fractions) * arm.max_pressure, scene, model=model, planar=False)
    assert eq.converged and eq.stable
    # Curls of ~1 cm radius: Simpson's rule over the samples is itself good to ~2e-5 here.
    assert _global_moment_balance(arm, scene, eq) < 1e-4


def test_the_warmups_3d_solve_is_taken_by_spatial_multiple_shooting(monkeypatch):
    """``softarm warmup`` compiles spatial multiple shooting through a cold 3D solve that single
    shooting cannot take: solve() hands it to multiple shooting, which converges to a stable
    state there (else a user's first such solve compiled the kernels, ~20 s)."""
    import solver.paths.spatial as spatial
    from softarm_gym.commands.warmup import spatial_multiple_shooting_kernels

    taken = []

    def spy(problem):
        eq = solve_spatial_multiple(problem)
        taken.append(eq)
        return eq

    monkeypatch.setattr(spatial, "solve_spatial_multiple", spy)
    eq = spatial_multiple_shooting_kernels()
    assert len(taken) == 1
    assert eq.converged and eq.stable and taken[0].converged
    np.testing.assert_array_equal(eq.tip, taken[0].tip)
