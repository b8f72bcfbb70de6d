"""Penalty contact against discs: agrees with the free rod when out of reach; balances forces."""

import numpy as np
import pytest

import solver
from solver import PSI, designs


def _ramp(arm, scene, final, n=11, settings=None):
    eq = None
    for frac in np.linspace(0, 1, n):
        eq = solver.solve(arm, frac * final, scene, warm_start=eq,
                          settings=settings or solver.Settings())
        assert eq.converged
    return eq


def test_far_obstacle_changes_nothing():
    arm = designs.octarm_v()
    p = np.array([30, 0, 0, 40, 60, 0]) * PSI
    far = solver.Scene(base_angle_deg=45, obstacles=(solver.Disc(center=(5, 5), radius=0.1),))
    a = solver.solve(arm, p, far)
    b = solver.solve(arm, p, solver.Scene(base_angle_deg=45))
    assert a.converged and a.stable
    np.testing.assert_allclose(a.tip, b.tip, atol=1e-10)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-10)
    assert not a.contact_force.any() and not a.penetration.any()


def _balance_error(eq, arm):
    """|n(0) − (weight + ∫ contact)|: global equilibrium, the contact integrated by trapezoid."""
    weight = np.array([0.0, -9.81 * arm.mass])
    contact = np.zeros(2)
    starts = (0,) + tuple(e + 1 for e in eq.section_ends[:-1])
    for start, end in zip(starts, eq.section_ends):
        contact += np.trapezoid(eq.contact_force[start:end + 1], eq.s[start:end + 1], axis=0)
    # n(s) = F_tip + ∫_s^L f: the base carries the whole weight and the contact reaction.
    return np.linalg.norm(eq.base_force - (weight + contact)), np.linalg.norm(weight)


def test_contact_force_balance_and_small_penetration():
    arm = designs.octarm_v()
    disc = solver.Disc(center=(0.07, -0.70), radius=0.05, stiffness=2e4)
    scene = solver.Scene(base_angle_deg=0, obstacles=(disc,))
    final = np.array([0, 0, 0, 0, 0, 100]) * PSI
    errors = []
    for steps in (32, 128):
        eq = _ramp(arm, scene, final, settings=solver.Settings(steps_per_section=steps))
        assert eq.stable
        pen = eq.penetration.max()
        assert 0 < pen < 0.01, "the arm must touch the disc, but only by millimetres"
        error, weight = _balance_error(eq, arm)
        errors.append(error)
    # The trapezoid rule over a contact patch with kinked edges converges at second order.
    assert errors[1] < errors[0] / 4
    assert errors[1] < 1e-3 * weight
    # The contact pushes the arm away from the disc centre.
    inside = eq.penetration > 0
    outward = np.einsum("ij,ij->i", eq.contact_force[inside], eq.positions[inside] - disc.center)
    assert np.all(outward > 0)


def test_stiffer_penalty_penetrates_less():
    arm = designs.octarm_v()
    final = np.array([0, 0, 0, 0, 0, 100]) * PSI
    depths = []
    for k in (1e4, 4e4):
        scene = solver.Scene(base_angle_deg=0,
                             obstacles=(solver.Disc(center=(0.07, -0.70), radius=0.05, stiffness=k),))
        depths.append(_ramp(arm, scene, final).penetration.max())
    assert depths[1] < 0.6 * depths[0]


def test_cold_contact_solve_matches_ramp():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=0,
                         obstacles=(solver.Disc(center=(0.07, -0.70), radius=0.05),))
    final = np.array([0, 0, 0, 0, 0, 100]) * PSI
    ramped = _ramp(arm, scene, final)
    cold = solver.solve(arm, final, scene)
    assert cold.converged
    np.testing.assert_allclose(cold.tip, ramped.tip, atol=1e-6)


def test_contact_is_planar_only():
    arm = designs.octarm_v()
    scene = solver.Scene(obstacles=(solver.Disc(),))
    with pytest.raises(ValueError, match="planar"):
        solver.solve(arm, np.zeros(9), scene, planar=False)


@pytest.mark.parametrize("kwargs, match", [
    (dict(center=(0, np.nan)), "center"), (dict(radius=0), "radius"),
    (dict(stiffness=-1), "stiffness"), (dict(center=(1, 2, 3)), "center")])
def test_bad_disc(kwargs, match):
    with pytest.raises(ValueError, match=match):
        solver.Disc(**kwargs)


def test_bad_obstacles():
    with pytest.raises(ValueError, match="obstacles"):
        solver.Scene(obstacles=((0, 0, 1),))


def test_deep_wrap_converges_with_a_stiff_penalty():
    """A long distal section curling around a disc with k = 1e5 N/m² (contact length ~0.3 m,
    decay length (EI/k)^¼ ≈ 3 cm): multiple shooting follows it to full pressure."""
    from softarm_gym.design_tools.sweep import fluid_params
    from softarm_gym.design_tools.template import build_arm, template

    tpl = template(fluid_params("pneumatic"), (6, 6, 3), 0.015, total_length=1.0)
    arm = build_arm(fluid_params("pneumatic"), tpl.tubes, tpl.section_lengths, tpl.thickness,
                    tpl.outer_radius)
    disc = solver.Disc(center=(-0.153, -0.1429), radius=0.151, stiffness=1e5)
    scene = solver.Scene(base_angle_deg=0, gravity=0.0, obstacles=(disc,))
    final = np.zeros(6)
    final[[2, 4]] = arm.max_pressure
    eq = _ramp(arm, scene, final, n=21)
    assert eq.stable and 0 < eq.penetration.max() < 0.01
    ds = np.diff(eq.s)
    contact_length = float(np.sum(ds[(eq.penetration[:-1] > 0) & (eq.penetration[1:] > 0)]))
    assert contact_length > 0.2


def test_contact_free_shortcut_is_the_contact_solution():
    """A ramp that first clears the disc, then presses on it, then leaves it again: with the
    contact-free shortcut and without it (multiple shooting throughout) the results agree,
    and the shortcut is taken exactly where nothing touches."""
    arm = designs.octarm_v()
    disc = solver.Disc(center=(0.07, -0.70), radius=0.05, stiffness=2e4)
    scene = solver.Scene(base_angle_deg=0, obstacles=(disc,))
    levels = np.r_[np.linspace(0, 1, 9), np.linspace(1, 0, 9)[1:]]
    final = np.array([0, 0, 0, 0, 0, 100]) * PSI
    fast = slow = None
    touched = []
    for frac in levels:
        fast = solver.solve(arm, frac * final, scene, warm_start=fast)
        slow = solver.solve(arm, frac * final, scene, warm_start=slow,
                            settings=solver.Settings(shortcuts=False))
        assert fast.converged and slow.converged and fast.in_contact == slow.in_contact
        np.testing.assert_allclose(fast.positions, slow.positions, atol=1e-8)
        np.testing.assert_allclose(fast.base_force, slow.base_force, atol=1e-7)
        assert fast.in_contact == bool(fast.penetration.max() > 0)
        touched.append(fast.in_contact)
    assert touched[0] is False and any(touched) and touched[-1] is False


def test_shortcut_not_taken_within_half_a_step_of_a_disc():
    """A disc whose surface passes just outside the free backbone (closer than half an RK4
    step) gets the full contact solve, with the same result."""
    arm = designs.octarm_v()
    p = np.array([30, 0, 0, 40, 60, 0]) * PSI
    free = solver.solve(arm, p, solver.Scene(base_angle_deg=45))
    mid = free.positions[len(free.positions) // 2]
    normal = np.array([-np.sin(free.angles[len(free.angles) // 2]),
                       np.cos(free.angles[len(free.angles) // 2])])
    radius, gap = 0.05, 2e-3  # clear of the samples, but closer than h/2 ≈ 9 mm
    scene = solver.Scene(base_angle_deg=45, obstacles=(
        solver.Disc(center=tuple(mid + (radius + gap) * normal), radius=radius),))
    fast = solver.solve(arm, p, scene)
    slow = solver.solve(arm, p, scene, settings=solver.Settings(shortcuts=False))
    assert fast.iterations == slow.iterations  # the multiple-shooting path, both times
    np.testing.assert_allclose(fast.positions, slow.positions, atol=1e-12)
