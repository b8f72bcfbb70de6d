"""The spatial conjugate-point test (:func:`solver.kernels.spatial.stability_test`) and fold passing.

Oracles: Euler's critical load (with its double conjugate point in 3D, which a determinant
test cannot see) and the planar solver's own conjugate-point test on planar equilibria,
which is valid in the plane and independent of the 3D kernels.
"""

import math

import numpy as np
import pytest

import solver
from solver import designs
from solver import layout as L
from solver.kernels import planar as planar_kernels
from solver.kernels import spatial as spatial_kernels
from solver.problem import context, pack
from solver.rod import (
    base_rotation,
    det3,
    integrate_spatial,
    rest_strains_into,
    rotation_to_quaternion,
)
from tests.solver import naive


def _kernel_inputs(arm, scene, settings):
    packed = pack(arm, "full", settings)
    ctx = context(arm, packed, scene, 3, settings)
    quat0 = np.empty(4)
    rotation_to_quaternion(base_rotation(scene.base_theta), quat0)
    work = np.empty((6, L.NSTATE))
    dummy = (np.empty((1, 3)), np.empty((1, 3, 3)), np.empty((1, 3)))
    return packed, ctx, quat0, work, dummy


@pytest.mark.parametrize("load, stable", [(2.3, True), (2.6, False)])  # π²/4 = 2.467
def test_straight_column_in_3d_loses_stability_at_euler_load(load, stable):
    """Upright column, dead tip load: both bending planes reach their conjugate point
    together, so det δφ only touches zero; counting real negative eigenvalues flags it."""
    rod = designs.rod(length=1.0, EI=1.0, EA=1e10, GA=1e10, GJ=0.7)
    settings = solver.Settings(steps_per_section=100)
    scene = solver.Scene(base_angle_deg=180, tip_force=(0, -load, 0), gravity=0)
    packed, ctx, quat0, work, dummy = _kernel_inputs(rod, scene, settings)
    rest = np.array([[0.0], [0.0], [1.0]])
    m0 = np.zeros(3)
    ok, its, res, is_stable = spatial_kernels.newton(m0, quat0, packed.secf, packed.sec_steps,
                                                     packed.c_j, rest, ctx.loads, ctx.m_tip, 1e-12, 5,
                                                     10.0, work, dummy)
    assert ok and np.all(m0 == 0.0)
    assert is_stable == stable


def test_negative_eigenvalue_test_against_numpy():
    """The stability pass's node test against the eigenvalues numpy finds: random matrices,
    and the cases the sign of the determinant alone gets wrong (two negative eigenvalues, a
    complex pair left of zero beside a positive one, a double negative eigenvalue)."""
    rng = np.random.default_rng(3)
    cases = [rng.normal(size=(3, 3)) for _ in range(400)]
    for eig in ([-1.0, -2.0, 3.0], [-1.0, -1.0, 0.5], [2.0, 1.0, -0.2], [1.0, 2.0, 3.0]):
        q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        cases.append(q @ np.diag(eig) @ q.T)
    for re in (-1.0, 1.0):  # a complex pair re ± 2i beside eigenvalue 2
        block = np.array([[re, 2.0, 0.0], [-2.0, re, 0.0], [0.0, 0.0, 2.0]])
        basis = rng.normal(size=(3, 3))
        cases.append(basis @ block @ np.linalg.inv(basis))
    seen = set()
    for d in cases:
        ev = np.linalg.eigvals(d)
        expected = bool(np.any((np.abs(ev.imag) < 1e-9) & (ev.real < 0)))
        seen.add((expected, bool(np.linalg.det(d) < 0)))
        cols = d.T.ravel().copy()
        assert spatial_kernels.has_negative_eigenvalue(cols, det3(cols)) == expected, ev
    assert seen == {(True, True), (True, False), (False, False)}


@pytest.mark.parametrize("guess, stable", [(-0.039, False), (3.098, False), (6.557, True)])
def test_3d_test_agrees_with_planar_test_on_planar_equilibria(guess, stable):
    """A soft arm with a heavy payload, base near horizontal: three planar equilibria at the
    same load (two looped, one hanging). Solved by the planar kernel, judged by the planar
    test (b = ∂m/∂m0 > 0) and by the 3D test on the same state."""
    arm = designs.get("octarm_vi")
    settings = solver.Settings(shortcuts=False)
    scene = solver.Scene(base_angle_deg=184.2557848920924, payload_kg=1.425695544488903)
    packed, ctx, quat0, work, dummy = _kernel_inputs(arm, scene, settings)
    ctx2 = context(arm, packed, scene, 2, settings)
    rest = np.empty((3, len(arm.sections)))
    rest_strains_into(np.zeros(arm.n_channels), packed.tubes_i, packed.tubes_f, packed.secf, rest)
    out = planar_kernels.newton(guess, scene.base_theta, packed.secf, packed.sec_steps, rest,
                                ctx2.loads, ctx2.m_tip, 1e-9, 30, 5.0, np.empty((1, L.N_COLUMNS)))
    assert out[1] and out[4] == stable
    m0 = np.array([0.0, 0.0, out[0]])
    ok, its, res, is_stable = spatial_kernels.newton(m0, quat0, packed.secf, packed.sec_steps,
                                                     packed.c_j, rest, ctx.loads, ctx.m_tip, 1e-8, 30,
                                                     5.0, work, dummy)
    assert ok and m0[2] == pytest.approx(out[0], abs=1e-4)
    assert is_stable == stable


def test_spatial_solve_of_planar_scenes_matches_planar_solver_or_buckles_sideways():
    """Random planar scenes solved by the 3D kernels: where the planar solver's equilibrium
    is stable in 3D too, the 3D solve lands on it (before the eigenvalue test, the loading
    stage settled on looped unstable states); where it is not — a curled arm buckling out
    of its plane — the 3D solve leaves the plane for a stable buckled state."""
    arm = designs.get("octarm_vi")
    settings = solver.Settings(shortcuts=False)
    rng = np.random.default_rng(1)
    n_in = len(arm.input_names(True))
    buckled = 0
    for _ in range(12):
        scene = solver.Scene(base_angle_deg=rng.uniform(0, 360), payload_kg=rng.uniform(0, 0.5))
        p = rng.uniform(0, 1, n_in) * arm.max_pressure
        planar = solver.solve(arm, p, scene, settings=settings)
        p_channel = solver.channel_pressures(arm, p, True)
        spatial = solver.solve(arm, p_channel, scene, planar=False, settings=settings)
        assert planar.converged and planar.stable
        assert spatial.converged and spatial.stable
        packed, ctx, quat0, work, dummy = _kernel_inputs(arm, scene, settings)
        rest = np.empty((3, len(arm.sections)))
        rest_strains_into(p_channel, packed.tubes_i, packed.tubes_f, packed.secf, rest)
        m0 = np.array([0.0, 0.0, planar.base_moment[-1]])
        ok, _, _, stable_in_3d = spatial_kernels.newton(m0, quat0, packed.secf, packed.sec_steps,
                                                        packed.c_j, rest, ctx.loads, ctx.m_tip, 1e-8,
                                                        30, 5.0, work, dummy)
        assert ok and abs(m0[2] - planar.base_moment[-1]) < 1e-4
        if stable_in_3d:
            np.testing.assert_allclose(spatial.tip, [*planar.tip, 0.0], atol=1e-5)
        else:
            buckled += 1
            assert abs(spatial.tip[2]) > 1e-3 and spatial.snapped
    assert buckled == 1  # seed 1 holds one sideways buckle (the 11th scene)


def test_stress_repro_crosses_to_the_stable_branch():
    """The case that failed the stress random set: the 3D loading stage used to settle on
    an unstable branch that a determinant test passed; now the solve converges to a state
    the 3D test finds stable, in moment balance."""
    arm = designs.get("octarm_vi")
    psi = [89.693998, 76.330564, 49.804883, 81.027896, 69.855109, 83.200145, 72.544408,
           56.948692, 75.015311]
    scene = solver.Scene(base_angle_deg=142.623867, payload_kg=0.350943)
    eq = solver.solve(arm, np.array(psi) * solver.PSI, scene, planar=False)
    assert eq.converged and eq.stable
    assert math.isfinite(eq.residual) and eq.residual < 1e-8


def test_cramer_solve_matches_lapack_and_flags_singular():
    rng = np.random.default_rng(0)
    x = np.empty(3)
    for _ in range(50):
        a, b = rng.normal(size=(3, 3)), rng.normal(size=3)
        spatial_kernels.cramer3(a.T.ravel().copy(), b, x)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    singular = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    assert spatial_kernels.cramer3(singular.T.ravel().copy(), np.ones(3), x) == 0.0
    assert not np.isfinite(x).any()


def test_octarm_lifting_its_base_section_buckles_sideways_before_it_snaps_over():
    """Horizontal OctArm V, pressure on one side of the proximal section: the planar solver
    snaps over the top at ~90 psi (test_paths.py); in 3D the curled arm loses stability
    sideways first and leaves its plane, stable, and comes back to it on the way down."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    settings = solver.Settings(shortcuts=False)
    levels = np.linspace(0, 100, 21)
    up, eq = [], None
    for level in levels:
        p = np.zeros(arm.n_inputs())
        p[1] = level * solver.PSI
        eq = solver.solve(arm, solver.channel_pressures(arm, p, True), scene, planar=False,
                          warm_start=eq, settings=settings)
        assert eq.converged and eq.stable
        up.append(eq)
    out_of_plane = [abs(e.tip[2]) > 0.05 for e in up]
    first = out_of_plane.index(True)
    assert 30 <= levels[first] <= 60 and up[first].snapped
    assert not any(out_of_plane[:first])
    planar = [solver.solve(arm, np.eye(arm.n_inputs())[1] * lv * solver.PSI, scene)
              for lv in levels[:first]]
    for e2, e3 in zip(planar, up[:first]):  # in the plane, the two solvers agree
        np.testing.assert_allclose(e3.tip, [*e2.tip, 0.0], atol=1e-6)
    for level in levels[::-1]:
        p = np.zeros(arm.n_inputs())
        p[1] = level * solver.PSI
        eq = solver.solve(arm, solver.channel_pressures(arm, p, True), scene, planar=False,
                          warm_start=eq, settings=settings)
        assert eq.converged and eq.stable
    np.testing.assert_allclose(eq.tip, up[0].tip, atol=1e-6)  # back in the plane at rest


def test_in_plane_shortcut_returns_the_sideways_buckle():
    """Horizontal OctArm V, channels II and III of section 1 at 60 psi, solved in 3D: the
    planar state (0.729, −0.310, 0) passes the planar test but is unstable out of its
    plane; the shortcut must not return it. An independent 3D reference found the buckled
    state (0.313, −0.440, ±0.470)."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    p = np.array([0, 60, 60, 0, 0, 0, 0, 0, 0]) * solver.PSI
    fast = solver.solve(arm, p, scene, planar=False)
    general = solver.solve(arm, p, scene, planar=False, settings=solver.Settings(shortcuts=False))
    for eq in (fast, general):
        assert eq.converged and eq.stable and eq.snapped
        np.testing.assert_allclose(eq.tip, [0.313, -0.440, 0.470], atol=1e-3)
    np.testing.assert_array_equal(fast.tip, general.tip)


def _in_plane_scene(arm, rng):
    base = float(rng.choice([0.0, 45.0, 90.0, 135.0, 180.0]))
    payload = float(rng.uniform(0, 0.3)) if rng.uniform() < 0.5 else 0.0
    active = rng.uniform(size=arm.n_inputs(True)) < 0.6
    p_in = rng.uniform(0, 1, arm.n_inputs(True)) * arm.max_pressure * active
    return solver.Scene(base_angle_deg=base, payload_kg=payload), solver.channel_pressures(arm, p_in)


@pytest.mark.parametrize("design", ["octarm_v", "octarm_vi", "ct"])
def test_in_plane_shortcut_never_changes_the_answer(design):
    """Random in-plane scenes (channels II = III) solved in 3D, cold and along warm paths:
    the shortcut and the general path give the same tip (1e-6·L) and the same flags. The
    sample holds states the shortcut must hand to the spatial kernels: folds and sideways
    buckles (about a fifth of the OctArm V scenes snap or end out of the plane)."""
    arm = designs.get(design)
    rng = np.random.default_rng(7)
    general = solver.Settings(shortcuts=False)
    handed_over = 0
    for _ in range(15):
        scene, p = _in_plane_scene(arm, rng)
        a = solver.solve(arm, p, scene, planar=False)
        b = solver.solve(arm, p, scene, planar=False, settings=general)
        assert np.linalg.norm(a.tip - b.tip) <= 1e-6 * arm.length
        assert (a.converged, a.stable, a.snapped) == (b.converged, b.stable, b.snapped)
        handed_over += b.snapped or abs(b.tip[2]) > 1e-6
    scene = solver.Scene(base_angle_deg=90.0)
    a = b = None
    for _ in range(10):
        p = solver.channel_pressures(arm, rng.uniform(0, 1, arm.n_inputs(True)) * arm.max_pressure)
        a = solver.solve(arm, p, scene, planar=False, warm_start=a)
        b = solver.solve(arm, p, scene, planar=False, warm_start=b, settings=general)
        assert np.linalg.norm(a.tip - b.tip) <= 1e-6 * arm.length
        assert (a.converged, a.stable, a.snapped) == (b.converged, b.stable, b.snapped)
        handed_over += b.snapped or abs(b.tip[2]) > 1e-6
    if design == "octarm_v":
        assert handed_over >= 3


def test_sideways_buckle_takes_the_plus_z_mirror_image():
    """Both mirror images of a sideways buckle are stable equilibria (reflection z → −z maps
    the base moment to (−m_x, −m_y, m_z)); the solver documents and returns the +z one."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    p = np.array([0, 60, 60, 0, 0, 0, 0, 0, 0]) * solver.PSI
    eq = solver.solve(arm, p, scene, planar=False)
    assert eq.tip[2] > 0.1
    settings = solver.Settings()
    packed, ctx, quat0, work, dummy = _kernel_inputs(arm, scene, settings)
    rest = np.empty((3, len(arm.sections)))
    rest_strains_into(p, packed.tubes_i, packed.tubes_f, packed.secf, rest)
    mirror = eq.base_moment * np.array([-1.0, -1.0, 1.0])
    ok, _, res, stable = spatial_kernels.newton(mirror, quat0, packed.secf, packed.sec_steps, packed.c_j,
                                                rest, ctx.loads, ctx.m_tip, 1e-9, 2, 1.0, work, dummy)
    assert ok and stable
    integrate_spatial(mirror, quat0, packed.secf, packed.sec_steps, packed.c_j, rest, ctx.loads,
                      False, *dummy, work)
    np.testing.assert_allclose(work[0, L.SP_R:L.SP_R + 3], eq.tip * np.array([1, 1, -1]), atol=1e-9)


@pytest.mark.parametrize("angle, payload", [(0.0, 0.0), (90.0, 0.1)])
def test_spatial_jumps_land_where_a_fine_march_does(angle, payload):
    """Spatial jumps between random pressures of the 3D OctArm: each lands on the root a
    plain 400-step march along the same ramp reaches (``naive.march_planar``'s spatial
    twin), wherever that march stays on one stable branch. Continuation steps give up once
    Newton leaves twice their acceptance radius; before they did, Newton could wander from a
    rejected step onto another branch and have it accepted (a hanging arm landed 0.47 m
    from the march, mirrored across the x–y plane, unflagged)."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=angle, payload_kg=payload)
    packed, ctx, quat0, work, dummy = _kernel_inputs(arm, scene, solver.Settings())
    rng = np.random.default_rng(5)
    compared = 0
    end = solver.solve(arm, rng.uniform(0.0, 0.5, 9) * arm.max_pressure, scene, planar=False)
    for _ in range(40):  # a walk of jumps of 30 % of the rated pressure per channel
        start, p_a = end, end.pressures
        p_b = np.clip(p_a + rng.normal(0.0, 0.3 * arm.max_pressure, 9), 0.0, arm.max_pressure)
        end = solver.solve(arm, p_b, scene, planar=False, warm_start=start)
        assert end.converged and end.stable

        def residual(t, m0, p_a=p_a, p_b=p_b):
            rest = np.vstack(solver.rest_strains(arm, p_a + t * (p_b - p_a)))
            integrate_spatial(m0, quat0, packed.secf, packed.sec_steps, packed.c_j, rest,
                              ctx.loads, False, *dummy, work)
            y = work[0].copy()
            stable = spatial_kernels.stability_test(packed.secf, packed.sec_steps, packed.c_j, rest,
                                                    ctx.loads, work)
            return (y[L.SP_M:L.SP_M + 3] - ctx.m_tip, y[L.SP_DM:L.SP_DM + 9].reshape(3, 3).T,
                    stable)

        marched = naive.march_spatial(residual, start.base_moment, max_move=ctx.params[L.JUMP])
        if marched is None:
            continue
        compared += 1
        np.testing.assert_allclose(end.base_moment, marched, rtol=0,
                                   atol=1e-7 * packed.moment_scale)
    assert compared >= 15, compared
