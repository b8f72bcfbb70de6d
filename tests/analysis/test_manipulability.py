"""Jacobian of the tip w.r.t. pressures: an analytic oracle, two stencils agreeing, measures."""

import dataclasses
import math

import numpy as np
import pytest

import solver
from softarm_gym.analysis import (
    MEASURES,
    alpha_shape_area,
    dexterity,
    dexterity_map,
    jacobian,
)

PSI = solver.PSI


def _arc_jacobian(arm, pressures):
    """Closed-form ∂tip/∂p of a one-section arm with no loads, horizontal base (θ0 = 0).

    The section is a circular arc of curvature u = u*(p) and stretch v = v*(p) (docs/design.md §1–4):
    tip = (v/u)(sin uL, 1 − cos uL). u*, v* are linear in the tube forces F = E·At·(λ − 1),
    and dλ/dp = 1/(dp/dλ) from the explicit actuator law p(λ) (Appendix A.1).
    """
    (sec,) = arm.sections
    mat = arm.tubes[0].material
    length = sec.length
    _, u_rest, v_rest = solver.rest_strains(arm, _spatial(arm, pressures))
    u, v = u_rest[0], v_rest[0]
    law = (mat.youngs_modulus, mat.inner_radius, mat.outer_radius, mat.wind_angle_deg)
    d_strain = np.empty((2, len(pressures)))
    for j, (_, channels) in enumerate(arm.planar_channels):
        lam = solver.stretch_from_pressure(pressures[j], *law)
        step = 1e-6
        dp_dlam = (solver.pressure_from_stretch(lam + step, *law)
                   - solver.pressure_from_stretch(lam - step, *law)) / (2 * step)
        dforce = mat.youngs_modulus * mat.area / dp_dlam  # dF/dp of one tube
        tubes = [t for t in arm.tubes if t.channel in channels]
        d_strain[0, j] = -dforce * sum(t.offset[0] for t in tubes) / sec.EI
        d_strain[1, j] = dforce * len(tubes) / sec.EA
    phi = u * length
    d_tip = np.array([
        [v * (length * math.cos(phi) * u - math.sin(phi)) / u**2, math.sin(phi) / u],
        [v * (length * math.sin(phi) * u - (1 - math.cos(phi))) / u**2, (1 - math.cos(phi)) / u],
    ])
    return d_tip @ d_strain


def _spatial(arm, planar_pressures):
    out = np.zeros(arm.n_channels)
    for value, (_, idx) in zip(planar_pressures, arm.planar_channels):
        out[list(idx)] = value
    return out


def test_central_differences_match_the_closed_form_arc():
    arm = solver.designs.pneumatic((6,), (0.3,), thickness=0.004)
    scene = solver.Scene(base_angle_deg=90.0, gravity=0.0)
    p = np.array([40.0, 15.0]) * PSI
    eq = solver.solve(arm, p, scene)
    expected = _arc_jacobian(arm, p)
    scale = np.abs(expected).max()
    # Truncation error falls as h²: ~8e-8 at the default step, ~1e-9 at a tenth of it.
    assert np.abs(jacobian(arm, eq) - expected).max() <= 1e-6 * scale
    assert np.abs(jacobian(arm, eq, rel_step=1e-5) - expected).max() <= 1e-8 * scale


@pytest.mark.parametrize("pressures_psi", [
    (30, 10, 50, 20, 40, 60),   # interior: central differences
    (0, 0, 0, 0, 0, 0),         # lower bounds: one-sided stencils
    (100, 0, 100, 100, 0, 100),  # mixed bounds
])
def test_central_and_richardson_stencils_agree_under_gravity(pressures_psi):
    arm = solver.designs.octarm_v()
    eq = solver.solve(arm, np.array(pressures_psi, dtype=float) * PSI, solver.Scene(base_angle_deg=45))
    central = jacobian(arm, eq)
    richardson = jacobian(arm, eq, method="richardson")
    assert np.linalg.norm(central - richardson) <= 1e-6 * np.linalg.norm(central)


def test_spatial_jacobian_has_a_row_per_coordinate():
    arm = solver.designs.octarm_two_section()
    eq = solver.solve(arm, np.array([20, 5, 0, 10, 0, 0]) * PSI, solver.Scene(), planar=False)
    jac = jacobian(arm, eq)
    assert jac.shape == (3, 6)
    # Out-of-plane pressure differences move the tip out of the plane.
    assert np.abs(jac[2]).max() > 0.1 * np.abs(jac).max()


def test_measures_of_known_matrices():
    d = dexterity(np.array([[3.0, 0.0, 0.0], [0.0, -1.0, 0.0]]))
    np.testing.assert_allclose(d.sigma, [3.0, 1.0])
    assert (d.sigma_max, d.sigma_min) == (3.0, 1.0)
    assert d.manipulability == pytest.approx(3.0)
    assert d.isotropy == pytest.approx(math.sqrt(3.0) / 2.0)
    assert d.condition == pytest.approx(3.0)
    singular = dexterity(np.array([[1.0, 2.0], [2.0, 4.0]]))
    assert singular.sigma_min == pytest.approx(0.0, abs=1e-15)
    assert singular.isotropy == pytest.approx(0.0, abs=1e-7)
    assert singular.condition > 1e15
    assert dexterity(np.eye(2) * 5).isotropy == pytest.approx(1.0)


def test_bad_jacobian_requests_are_rejected():
    arm = solver.designs.octarm_v()
    eq = solver.solve(arm, np.zeros(6), solver.Scene())
    with pytest.raises(ValueError, match="unknown method"):
        jacobian(arm, eq, method="forward")
    with pytest.raises(ValueError, match="rel_step"):
        jacobian(arm, eq, rel_step=0.0)
    with pytest.raises(ValueError, match="did not converge"):
        jacobian(arm, dataclasses.replace(eq, converged=False))
    with pytest.raises(ValueError, match="takes 4"):
        jacobian(solver.designs.ct(), eq)
    with pytest.raises(ValueError, match="Equilibrium"):
        jacobian(arm, eq.tip)
    with pytest.raises(ValueError, match="ArmDesign"):
        jacobian("octarm_v", eq)
    with pytest.raises(ValueError, match="finite"):
        dexterity(np.array([[np.nan, 1.0]]))


def test_dexterity_map_over_a_small_grid():
    arm = solver.designs.ct()
    dm = dexterity_map(arm, levels=3)
    assert dm.valid.all() and dm.tips.shape == (81, 2)
    tips, _ = solver.solve_batch(arm, dm.grid.rows(), solver.Scene())
    np.testing.assert_allclose(dm.tips, tips, atol=1e-9)  # the equilibria solve_batch returns
    assert np.all(np.diff(dm.sigma, axis=1) <= 0)
    np.testing.assert_allclose(dm.measure("condition"), dm.sigma[:, 0] / dm.sigma[:, 1])
    assert set(MEASURES) <= {k.removeprefix("median_") for k in dm.summary()}
    # Fig. 5.6: the area reachable with sigma_min >= t shrinks from the whole workspace to 0.
    smin = dm.measure("sigma_min")
    thresholds = np.linspace(0, smin.max() * 1.01, 6)
    areas = dm.dexterous_area(thresholds)
    assert areas[0] == pytest.approx(alpha_shape_area(dm.tips, dm.alpha))
    assert np.all(np.diff(areas) <= 1e-15) and areas[-1] == 0.0
    # Chunks of 7 points (12 chunks, the last short) give the same map bit for bit.
    again = dexterity_map(arm, levels=3, chunk_size=7)
    for name in ("tips", "valid", "sigma"):
        np.testing.assert_array_equal(getattr(again, name), getattr(dm, name))
    with pytest.raises(ValueError, match="unknown dexterity measure"):
        dm.measure("volume")
