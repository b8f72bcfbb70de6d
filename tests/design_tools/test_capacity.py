"""Load capacity W (§3, Fig. 3.1) against an independent fine load ramp, and its trends."""

import math
from dataclasses import replace

import numpy as np
import pytest

import solver
from softarm_gym import design_tools as dt

P = solver.designs.PNEUMATIC
H = solver.designs.HYDRAULIC


def _arm(params, tubes, length, constraint="tube-ratio"):
    ro = dt.outer_radius(params, constraint, tubes, length)
    tpl = dt.template(params, tubes, ro, total_length=length)
    return dt.build_arm(params, tubes, tpl.section_lengths, tpl.thickness, ro)


def _tip_after_pressurising(arm, pressure, load, steps=200):
    """Tip of the loaded arm after a fixed fine ramp of the lifting pressures from 0."""
    p = dt.lifting_pressures(arm, pressure)
    scene = solver.Scene(base_angle_deg=90.0, tip_force=(0.0, -load))
    eq = solver.solve(arm, np.zeros_like(p), scene, record=False)
    for fraction in np.linspace(1.0 / steps, 1.0, steps):
        eq = solver.solve(arm, fraction * p, scene, record=False, warm_start=eq)
    return eq.tip


def _scan_crossing(arm, pressure, loads):
    """Linear interpolation of the first sign change of tip y over a load grid."""
    heights = [_tip_after_pressurising(arm, pressure, w)[1] for w in loads]
    k = next(i for i in range(1, len(loads)) if heights[i] < 0 <= heights[i - 1])
    w0, w1, y0, y1 = loads[k - 1], loads[k], heights[k - 1], heights[k]
    return w0 + (w1 - w0) * y0 / (y0 - y1)


def test_lifting_pressures_drive_channels_two_and_three():
    arm = solver.designs.octarm_v()
    np.testing.assert_array_equal(dt.lifting_pressures(arm, 5.0), [0, 5, 0, 5, 0, 5])
    channels = dt.lifting_channels(arm, 5.0)
    np.testing.assert_array_equal(channels, [0, 5, 5] * 3)
    # II + III sit below a horizontal arm: they curl it upwards (counter-clockwise, u* > 0).
    _, u2, _ = solver.rest_strains(arm, channels)
    assert np.all(u2 > 0)
    # Both planar inputs at the same pressure only stretch the arm: nothing to lift with.
    _, u2_all, v3_all = solver.rest_strains(arm, np.full(arm.n_channels, 5e4))
    np.testing.assert_allclose(u2_all, 0.0, atol=1e-12)
    assert np.all(v3_all > 1)


def test_lifting_pressures_need_an_octarm_layout():
    with pytest.raises(ValueError, match="II\\+III"):
        dt.lifting_pressures(solver.designs.ct(), 1.0)


def test_capacity_matches_a_fixed_step_scan():
    arm = _arm(P, (12, 6), 0.8)
    cap = dt.load_capacity(arm, P.test_pressure, tol_n=1e-4)
    assert cap.converged and not cap.fold_limited and cap.self_supporting
    assert cap.tip_at_capacity[1] == pytest.approx(0.0, abs=1e-4 * arm.length)
    assert cap.tip_at_capacity[0] > 0  # held in front of the base, as in Fig. 3.1
    coarse = _scan_crossing(arm, P.test_pressure, np.arange(0.0, 60.0, 2.0))
    start = np.floor(coarse) - 1.0
    fine = _scan_crossing(arm, P.test_pressure, np.arange(start, start + 3.0, 0.25))
    # Linear interpolation over a 0.25 N step of a smooth curve: well inside 0.02 N.
    assert cap.load_n == pytest.approx(fine, abs=0.02)


def test_loading_a_curled_arm_after_pressurising_rolls_it_up():
    """Why W loads first and pressurises after: the other order rolls a curled arm up.

    Pressurised first, this arm's tip points backwards (tip angle > 90°); a load hung on
    it then curls it further and the tip ends behind the base. Loaded first and then
    pressurised, the same load is held in front of the base.
    """
    arm = _arm(P, (12, 6, 3), 0.8)
    cap = dt.load_capacity(arm, P.test_pressure)
    p = dt.lifting_pressures(arm, P.test_pressure)
    eq = solver.solve(arm, p, solver.Scene(base_angle_deg=90.0))
    assert eq.tip_angle > math.pi / 2
    for load in np.linspace(0.5, cap.load_n, 200):
        eq = solver.solve(arm, p, solver.Scene(base_angle_deg=90.0, tip_force=(0.0, -load)),
                          warm_start=eq)
    assert eq.tip[0] < 0 < cap.tip_at_capacity[0]


def test_payload_equivalent_and_tip_height_sign():
    """W in newtons is a tip force; the unloaded tip sits above y = 0 when W > 0."""
    arm = _arm(P, (12, 9), 0.6)
    cap = dt.load_capacity(arm, P.test_pressure)
    assert cap.load_n > 0 and cap.tip_unloaded[1] > 0


def test_an_arm_too_long_for_its_weight_has_negative_capacity():
    # Beyond the optimum the self-weight moment (∝ L⁴ at a fixed tube ratio) wins.
    arm = _arm(P, (12, 9, 3), 3.5)
    cap = dt.load_capacity(arm, P.test_pressure)
    assert cap.load_n < 0 and not cap.self_supporting and cap.tip_unloaded[1] < 0


def test_capacity_falls_with_length_beyond_the_optimum():
    loads = [dt.evaluate(P, "tube-ratio", (12, 9, 3), length).load_n for length in (2.0, 2.5, 3.0, 3.5)]
    assert np.all(np.diff(loads) < 0)


def test_without_gravity_a_stronger_test_pressure_lifts_more():
    arm = _arm(P, (9, 6), 0.6)
    low = dt.load_capacity(arm, 0.5 * P.test_pressure, gravity=0.0).load_n
    high = dt.load_capacity(arm, P.test_pressure, gravity=0.0).load_n
    assert 0 < low < high


def test_hydraulic_arm_carries_its_water():
    tubes, length = (6, 3), 1.0
    ro = dt.outer_radius(H, "tube-ratio", tubes, length)
    tpl = dt.template(H, tubes, ro, total_length=length)
    wet = dt.build_arm(H, tubes, tpl.section_lengths, tpl.thickness, ro)
    dry = dt.build_arm(replace(H, fluid_density=0.0), tubes, tpl.section_lengths, tpl.thickness, ro)
    assert wet.mass - dry.mass == pytest.approx(1000.0 * tpl.internal_volume, rel=1e-12)


@pytest.mark.parametrize("tol", [0.0, -1.0])
def test_capacity_rejects_bad_tolerance(tol):
    with pytest.raises(ValueError, match="tol_n"):
        dt.load_capacity(solver.designs.octarm_v(), 1.0, tol_n=tol)


def test_capacity_rejects_pressure_above_rating():
    arm = solver.designs.octarm_v()
    with pytest.raises(ValueError, match="rated maximum"):
        dt.load_capacity(arm, 2.0 * arm.max_pressure)


def test_capacity_is_not_nan_for_octarm_v():
    cap = dt.load_capacity(solver.designs.octarm_v(), 30 * solver.PSI)
    assert math.isfinite(cap.load_n) and cap.converged


def test_no_crossing_within_the_load_limit_is_a_capacity_error():
    arm = _arm(P, (12, 6), 0.8)
    with pytest.raises(dt.CapacityError, match="no tip load up to"):
        dt.load_capacity(arm, P.test_pressure, max_load_n=1.0)
