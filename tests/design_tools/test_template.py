"""Dexterity template: wrap angles (Eq. 3.2), section lengths (Eq. 3.3), thickness (Eq. 3.9)."""

import math

import numpy as np
import pytest

import solver
from softarm_gym import design_tools as dt

P = solver.designs.PNEUMATIC


def test_wrap_angles_follow_eq_3_2():
    np.testing.assert_allclose(np.degrees(dt.wrap_angles(3)), [120.0, 180.0, 360.0])
    np.testing.assert_allclose(np.degrees(dt.wrap_angles(1)), [360.0])
    np.testing.assert_allclose(np.degrees(dt.wrap_angles(5)), [72.0, 90.0, 120.0, 180.0, 360.0])


@pytest.mark.parametrize("bad", [0, -1, 2.5, True])
def test_wrap_angles_reject_bad_section_counts(bad):
    with pytest.raises(ValueError, match="sections"):
        dt.wrap_angles(bad)


@pytest.mark.parametrize("n_tubes, lever", [(3, 1.0), (6, math.sqrt(3.0)), (12, None)])
def test_curvature_is_the_geometric_moment_over_ei(n_tubes, lever):
    """|u*| = F·|Σ y_k| / EI with F = E·At·(λ − 1), the tube ring of radius Ro/sin(π/N_t)."""
    ro, t = 15e-3, 2e-3
    ri = ro - t
    lam = solver.stretch_from_pressure(P.max_pressure, P.youngs_modulus, ri, ro, P.wind_angle_deg)
    area = math.pi * (ro**2 - ri**2)
    force = P.youngs_modulus * area * (lam - 1.0)
    delta = ro / math.sin(math.pi / n_tubes)
    # Channels II + III: every tube whose centre is 120° or 240° from +d1, offsets δ·cos(angle).
    per = n_tubes // 3
    angles = [c + 360.0 / n_tubes * (i - (per - 1) / 2) for c in (120.0, 240.0) for i in range(per)]
    moment = force * abs(sum(delta * math.cos(math.radians(a)) for a in angles))
    if lever is not None:  # the closed forms for 3 and 6 tubes: δ and √3·δ times F
        assert moment == pytest.approx(force * lever * delta, rel=1e-12)
    ei = P.youngs_modulus * n_tubes * (math.pi * (ro**4 - ri**4) / 4 + area * ro**2 / 2)
    got = dt.section_curvatures(P, (n_tubes,), t, ro, P.max_pressure)
    assert got[0] == pytest.approx(moment / ei, rel=1e-9)


def test_template_meets_total_length_and_wrap_angles():
    tpl = dt.template(P, (12, 9, 3), 0.05, total_length=1.2)
    assert tpl.length == pytest.approx(1.2, rel=1e-9)
    assert 0 < tpl.thickness < 0.05
    np.testing.assert_allclose(tpl.section_lengths * tpl.curvatures, dt.wrap_angles(3), rtol=1e-12)
    # The curvatures are those of the solver at p_max for that thickness.
    np.testing.assert_allclose(
        tpl.curvatures, dt.section_curvatures(P, (12, 9, 3), tpl.thickness, 0.05, P.max_pressure))


def test_equal_sections_have_lengths_in_the_ratio_of_their_wrap_angles():
    tpl = dt.template(P, (6, 6, 6), 0.02, total_length=1.0)
    np.testing.assert_allclose(tpl.section_lengths / tpl.section_lengths[0], [1.0, 1.5, 3.0], rtol=1e-12)


def test_thicker_walls_give_longer_sections():
    lengths = [dt.section_lengths(P, (6, 3), t, 0.015).sum() for t in (1e-3, 3e-3, 6e-3, 10e-3)]
    assert np.all(np.diff(lengths) > 0)


def test_distal_length_constraint_fixes_the_last_section():
    tpl = dt.template(P, (9, 6, 3), P.outer_radius, distal_length=0.4)
    assert tpl.section_lengths[-1] == pytest.approx(0.4, rel=1e-9)


def test_too_short_an_arm_is_infeasible():
    # Even the thinnest wall curls the tube ring faster than 660° in 5 cm.
    with pytest.raises(dt.InfeasibleDesign, match="thinnest wall"):
        dt.template(P, (3, 3, 3), 0.02, total_length=0.05)


def test_template_pressure_test_needs_thinner_walls():
    at_max = dt.template(P, (3, 3, 3), 0.0167, total_length=0.8)
    at_test = dt.template(P, (3, 3, 3), 0.0167, total_length=0.8, pressure=P.test_pressure)
    assert at_test.thickness < at_max.thickness


def test_internal_volume_is_the_bore_volume():
    tpl = dt.template(P, (6, 6, 3), 0.012, total_length=0.8)
    ri = 0.012 - tpl.thickness
    expected = math.pi * ri**2 * (6 * tpl.section_lengths[0] + 6 * tpl.section_lengths[1]
                                  + 3 * tpl.section_lengths[2])
    assert tpl.internal_volume == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("kwargs, match", [
    ({}, "exactly one"),
    ({"total_length": 1.0, "distal_length": 0.3}, "exactly one"),
    ({"total_length": -1.0}, "length"),
    ({"total_length": 1.0, "pressure": 1e9}, "template pressure"),
])
def test_template_rejects_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        dt.template(P, (3, 3), 0.015, **kwargs)


@pytest.mark.parametrize("tubes", [(), (4, 3), (3, 15)])
def test_tube_counts_must_be_multiples_of_three_up_to_twelve(tubes):
    with pytest.raises(ValueError, match="tube counts"):
        dt.section_curvatures(P, tubes, 1e-3, 0.015, P.max_pressure)
