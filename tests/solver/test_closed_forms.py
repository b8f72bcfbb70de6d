"""The solver against closed forms that do not depend on our code (docs/design.md §12)."""

import math

import numpy as np
import pytest

import solver
from solver import designs
from tests.solver import naive

FINE = solver.Settings(steps_per_section=200)
GENERAL = solver.Settings(steps_per_section=64, shortcuts=False)

# Bisshopp & Drucker (1945); Mattiasson (1981) Table 1: α = P L²/EI → (w/L, u/L, ψ).
ELASTICA = [(1, 0.301721, 0.056433, 0.461352), (2, 0.493457, 0.160642, 0.781750),
            (5, 0.713792, 0.387628, 1.215368), (10, 0.810609, 0.554996, 1.430286)]


@pytest.mark.parametrize("alpha, w, u, psi", ELASTICA)
@pytest.mark.parametrize("model", ["full", "unshearable"])
def test_elastica_cantilever(alpha, w, u, psi, model):
    rod = designs.rod(length=1.0, EI=1.0, EA=1e12, GA=1e12)
    scene = solver.Scene(base_angle_deg=90, tip_force=(0.0, -alpha), gravity=0.0)
    eq = solver.solve(rod, [], scene, model=model, settings=FINE)
    assert eq.converged and eq.stable
    ours = (-eq.tip[1], 1 - eq.tip[0], -eq.tip_angle)
    # The printed table, to half a unit of its sixth decimal...
    np.testing.assert_allclose(ours, (w, u, psi), rtol=0, atol=5e-7)
    # ...and the elliptic-integral quadrature at full precision.
    np.testing.assert_allclose(ours, naive.elastica_cantilever(alpha), rtol=1e-9)


@pytest.mark.parametrize("steps", [8, 16, 32, 64])
@pytest.mark.parametrize("phi", [0.5, 2.0, 5.0])
def test_end_moment_gives_exact_arc_over_resolutions(phi, steps):
    """End moment M on a free, weightless, shearable, extensible rod: an exact arc."""
    rod = designs.rod(length=0.8, EI=0.7, EA=50.0, GA=20.0)
    moment = phi * 0.7 / 0.8
    scene = solver.Scene(base_angle_deg=90, tip_moment=moment, gravity=0.0)
    eq = solver.solve(rod, [], scene, settings=solver.Settings(steps_per_section=steps))
    along = 0.8 / phi * math.sin(phi)
    across = 0.8 / phi * (1 - math.cos(phi))
    # RK4 on an arc: error decreases as steps⁻⁴; 5 rad at 8 steps is the coarsest case.
    tol = 2e-3 * (8 / steps) ** 4 * 0.8
    assert eq.converged and eq.stable
    assert np.hypot(eq.tip[0] - along, eq.tip[1] - across) < tol
    np.testing.assert_allclose(eq.internal_force, 0.0, atol=1e-12)
    np.testing.assert_allclose(eq.curvature, moment / 0.7, rtol=1e-9)


def test_pressurised_section_without_load_is_an_arc(monkeypatch):
    """Closed-form arcs (shortcut) and shooting (general path) both give the rest shape."""
    import importlib

    module = importlib.import_module("solver.paths.dispatch")
    calls = []
    original = module.closed_form
    monkeypatch.setattr(module, "closed_form", lambda *a: calls.append(1) or original(*a))
    arm = designs.octarm_v()
    p = np.array([80, 0, 0, 40, 20, 0]) * solver.PSI
    scene = solver.Scene(base_angle_deg=30, gravity=0.0)
    quick = solver.solve(arm, p, scene, settings=solver.Settings(steps_per_section=128))
    assert calls == [1]
    general = solver.solve(arm, p, scene, settings=solver.Settings(steps_per_section=128,
                                                                  shortcuts=False))
    assert calls == [1], "shortcuts=False must take the shooting path"
    np.testing.assert_allclose(general.tip, quick.tip, atol=1e-9)
    np.testing.assert_allclose(general.positions, quick.positions, atol=1e-9)


@pytest.mark.parametrize("ratio, buckled", [(0.95, False), (1.05, True)])
def test_euler_column(ratio, buckled):
    """Upright clamped rod, dead tip load: buckles past P L²/EI = π²/4, and comes back
    buckled and stable rather than balanced on the unstable straight state."""
    rod = designs.rod(length=1.0, EI=1.0, EA=1e10, GA=1e10)
    load = ratio * math.pi**2 / 4
    eq = solver.solve(rod, [], solver.Scene(base_angle_deg=180, tip_force=(0, -load), gravity=0))
    assert eq.converged and eq.stable
    assert (abs(eq.tip[0]) > 0.05) == buckled
    assert eq.snapped == buckled


@pytest.mark.parametrize("ratio, buckled", [(0.97, False), (1.03, True)])
def test_greenhill_column(ratio, buckled):
    """Self-weight buckling of an upright column at q L³/EI ≈ 7.837."""
    q = ratio * 7.8373
    rod = designs.rod(length=1.0, EI=1.0, EA=1e10, GA=1e10, mass_per_length=q / 9.81)
    eq = solver.solve(rod, [], solver.Scene(base_angle_deg=180))
    assert eq.converged and eq.stable
    assert (abs(eq.tip[0]) > 0.02) == buckled


def test_conjugate_point_test_flags_straight_column():
    """The straight state past Euler's load is an equilibrium, but unstable."""
    from solver import layout
    from solver.kernels import planar as planar_kernels
    from solver.problem import context, pack

    rod = designs.rod(length=1.0, EI=1.0, EA=1e10, GA=1e10)
    packed = pack(rod, "full", solver.Settings(steps_per_section=100))
    dummy = np.zeros((1, layout.N_COLUMNS))
    rest = np.array([[0.0], [0.0], [1.0]])  # no rest curvature, unit stretch
    for load, stable in ((2.3, True), (2.6, False)):  # π²/4 = 2.467
        scene = solver.Scene(base_angle_deg=180, tip_force=(0, -load), gravity=0)
        ctx = context(rod, packed, scene, 2, solver.Settings(steps_per_section=100))
        out = planar_kernels.newton(0.0, scene.base_theta, packed.secf, packed.sec_steps, rest, ctx.loads,
                                    ctx.m_tip, 1e-12, 5, 10.0, dummy)
        m0, ok, its, res, is_stable, bmin, x, y, theta = out
        assert ok and m0 == 0.0
        assert is_stable == stable
        # b(L) = cos(√P L) for the Euler column.
        assert bmin == pytest.approx(min(1.0, math.cos(math.sqrt(load))), abs=1e-6)


@pytest.mark.parametrize("alpha", [1, 5])
def test_spatial_elastica_out_of_plane(alpha):
    """A horizontal rod loaded along −z bends in the x–z plane: the 3D kernel against the
    elliptic-integral cantilever (no planar shortcut can apply to this load)."""
    rod = designs.rod(length=1.0, EI=1.0, EA=1e12, GA=1e12, GJ=0.7)
    scene = solver.Scene(base_angle_deg=90, tip_force=(0.0, 0.0, -alpha), gravity=0.0)
    eq = solver.solve(rod, [], scene, planar=False, settings=solver.Settings(steps_per_section=200))
    assert eq.converged and eq.stable
    w, u, psi = naive.elastica_cantilever(alpha)
    np.testing.assert_allclose(eq.tip, [1 - u, 0.0, -w], rtol=1e-8, atol=1e-10)
    d3 = eq.orientations[-1][:, 2]
    assert math.atan2(-d3[2], d3[0]) == pytest.approx(psi, rel=1e-8)


def test_spatial_pure_torsion():
    """A tip moment about the axis twists a straight rod uniformly: φ = M·L/GJ."""
    rod = designs.rod(length=0.8, EI=1.0, EA=1e9, GA=1e9, GJ=0.5)
    scene = solver.Scene(base_angle_deg=90, tip_moment=(0.3, 0.0, 0.0), gravity=0.0)
    eq = solver.solve(rod, [], scene, planar=False, settings=solver.Settings(steps_per_section=32))
    assert eq.converged
    np.testing.assert_allclose(eq.tip, [0.8, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(eq.curvature[:, 2], 0.3 / 0.5, rtol=1e-10)
    d1 = eq.orientations[-1][:, 0]  # starts along +y; twisted about +x by φ
    phi = 0.3 * 0.8 / 0.5
    np.testing.assert_allclose(d1, [0.0, math.cos(phi), math.sin(phi)], atol=1e-10)


def test_tip_only_solve_equals_recorded_tip():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=45, payload_kg=0.1)
    p = np.array([30, 0, 10, 50, 0, 20]) * solver.PSI
    quick = solver.solve(arm, p, scene, record=False)
    full = solver.solve(arm, p, scene)
    assert quick.s.size == 0 and full.s.size > 0
    np.testing.assert_array_equal(quick.tip, full.tip)


def test_closed_form_angles_are_continuous_like_the_shooting_kernel():
    """An unloaded OctArm V with channel I on everywhere turns ~419°: θ must not wrap."""
    arm = designs.octarm_v()
    p = np.array([100, 0, 100, 0, 100, 0]) * solver.PSI
    scene = solver.Scene(base_angle_deg=90, gravity=0.0)
    quick = solver.solve(arm, p, scene)
    general = solver.solve(arm, p, scene, settings=solver.Settings(shortcuts=False))
    assert quick.tip_angle < -2 * math.pi
    np.testing.assert_allclose(quick.angles, general.angles, atol=1e-9)
