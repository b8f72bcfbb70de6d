"""Penalty contact against discs: agrees with the free rod when out of reach; balances forces."""

import math

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


@pytest.mark.parametrize("kwargs, match", [
    (dict(center=(0, np.nan)), "center"), (dict(radius=0), "radius"),
    (dict(stiffness=-1), "stiffness"), (dict(center=(1, 2, 3)), "center"),
    (dict(radius=1e300), "radius.*<= 10000 m"), (dict(center=(1e300, 0)), "center.*10000 m"),
    (dict(center="far"), "center")])
def test_bad_disc(kwargs, match):
    with pytest.raises(ValueError, match=match):
        solver.Disc(**kwargs)


def test_bad_obstacles():
    with pytest.raises(ValueError, match="obstacles"):
        solver.Scene(obstacles=((0, 0, 1),))
    # Issue #19: a disc over the clamp gave a NaN tip; it is no scene.
    with pytest.raises(ValueError, match=r"obstacles\[1\].*covers the arm's base"):
        solver.Scene(obstacles=(solver.Disc(center=(0.3, 0.0)), solver.Disc(center=(0, 0),
                                                                          radius=1e3)))


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
    contact-free shortcut and without it (multiple shooting throughout, at the finer contact
    resolution) the results agree to the default resolution's discretisation error, and the
    shortcut is taken exactly where nothing touches."""
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
        assert np.linalg.norm(fast.tip - slow.tip) <= 1e-6 * arm.length
        np.testing.assert_allclose(fast.base_force, slow.base_force, atol=1e-6)
        if fast.in_contact:  # both from the contact kernels
            np.testing.assert_allclose(fast.positions, slow.positions, atol=1e-8)
        assert fast.in_contact == bool(fast.penetration.max() > 0)
        touched.append(fast.in_contact)
    assert touched[0] is False and any(touched) and touched[-1] is False


def test_shortcut_not_taken_where_the_path_meets_a_disc_its_end_clears():
    """A disc 2 mm outside the free backbone at its end, on the cold ramp's way: the ramp
    meets it (the arm ends pressed on it), so the guarded contact-free shortcut must not
    answer; the full contact solve does, the same with shortcuts off."""
    arm = designs.octarm_v()
    p = np.array([30, 0, 0, 40, 60, 0]) * PSI
    free = solver.solve(arm, p, solver.Scene(base_angle_deg=45))
    mid = free.positions[len(free.positions) // 2]
    normal = np.array([-np.sin(free.angles[len(free.angles) // 2]),
                       np.cos(free.angles[len(free.angles) // 2])])
    radius, gap = 0.05, 2e-3
    scene = solver.Scene(base_angle_deg=45, obstacles=(
        solver.Disc(center=tuple(mid + (radius + gap) * normal), radius=radius),))
    fast = solver.solve(arm, p, scene)
    slow = solver.solve(arm, p, scene, settings=solver.Settings(shortcuts=False))
    assert slow.in_contact and slow.penetration.max() > 1e-3
    assert fast.iterations == slow.iterations  # the multiple-shooting path, both times
    np.testing.assert_allclose(fast.positions, slow.positions, atol=1e-12)


def test_shortcut_taken_short_of_a_disc_agrees_with_the_contact_solve():
    """A warm step that stops 2 mm short of a disc (a tenth of a sample spacing; the guard's
    allowance is under a millimetre here) is the contact-free step, in the general path and
    in the stepper: the full contact solve of the same step touches nothing and lands on the
    same state to the grids' discretisation error."""
    arm = designs.octarm_v()
    p = np.array([30, 0, 0, 40, 60, 0]) * PSI
    bare = solver.Scene(base_angle_deg=45)
    before = solver.solve(arm, 0.9 * p, bare)
    free = solver.solve(arm, p, bare, warm_start=before)
    i = len(free.positions) // 2
    move = free.positions[i] - before.positions[i]
    ahead = move / np.linalg.norm(move)  # the disc ahead of the step's motion
    radius, gap = 0.05, 2e-3
    scene = solver.Scene(base_angle_deg=45, obstacles=(
        solver.Disc(center=tuple(free.positions[i] + (radius + gap) * ahead), radius=radius),))
    start = solver.solve(arm, 0.9 * p, scene)
    assert not start.in_contact
    fast = solver.solve(arm, p, scene, warm_start=start)
    slow = solver.solve(arm, p, scene, warm_start=start, settings=solver.Settings(shortcuts=False))
    assert not slow.in_contact and not slow.penetration.any()
    np.testing.assert_array_equal(fast.positions, free.positions)  # the shortcut's answer
    assert np.abs(fast.positions - slow.positions).max() < 1e-7
    stepper = solver.Stepper(arm, scene)
    stepper.reset(0.9 * p)
    assert stepper.step(p).converged and stepper.last_path == "lean"
    np.testing.assert_allclose(stepper.tip, fast.tip, atol=1e-12)


def test_chord_guard_sees_a_disc_between_samples():
    """``chords_clear`` on an exact circular arc sampled every 20 mm: a disc on its convex
    side that the arc enters between two samples (both samples clear of it) is not clear; a
    disc the arc clears by more than the allowance ℓ·(|Δθ|/4 + CHORD_SLACK) at every chord is."""
    from solver.kernels.obstacles import CHORD_SLACK, chord_allowance, chords_clear
    from solver.layout import N_COLUMNS, THETA, X, Y

    bend, h = 0.2, 0.02  # arc radius (m), sample spacing along it (m)
    s = np.arange(0.0, 0.3 + 1e-12, h)
    rec = np.zeros((s.size, N_COLUMNS))
    rec[:, X], rec[:, Y] = bend * np.sin(s / bend), bend * (1.0 - np.cos(s / bend))
    rec[:, THETA] = s / bend
    allowance = h * (0.25 * h / bend + CHORD_SLACK)
    assert chord_allowance(rec) == pytest.approx(2.0 * bend * np.sin(0.5 * h / bend)
                                                 * (0.25 * h / bend + CHORD_SLACK), rel=1e-12)
    # Between samples 4 and 5, the arc's outward normal at their middle.
    phi = 4.5 * h / bend
    at, outward = np.array([np.sin(phi), 1 - np.cos(phi)]) * bend, np.array([np.sin(phi), -np.cos(phi)])
    radius = 0.04
    sag = bend * (1.0 - np.cos(0.5 * h / bend))  # the arc's departure from the chord there
    entering = np.array([[*(at + (radius - 0.5 * sag) * outward), radius, 1e5]])
    sample_gaps = np.hypot(rec[:, X] - entering[0, 0], rec[:, Y] - entering[0, 1]) - radius
    assert sample_gaps.min() > 0.0  # every sample clears it; the arc does not
    assert not chords_clear(rec, entering)
    clear = np.array([[*(at + (radius + 1.01 * allowance) * outward), radius, 1e5]])
    assert chords_clear(rec, clear)


def test_cold_solve_loads_the_arm_with_its_obstacles():
    """A horizontal arm with a payload sags onto a disc below it: the loading stage must
    meet the disc (it used to load the arm without it and start the ramp from inside the
    disc). An independent energy minimiser and a warm gravity ramp give (0.6128, −0.5183)."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90, payload_kg=0.25,
                         obstacles=(solver.Disc((0.40, -0.42), 0.13, 1e5),))
    eq = solver.solve(arm, np.zeros(6), scene)
    assert eq.converged and eq.stable and eq.in_contact
    np.testing.assert_allclose(eq.tip, [0.6128, -0.5183], atol=1e-4)


def test_cold_ramp_does_not_tunnel_through_a_soft_disc():
    """Hanging OctArm V curling to the left into a soft disc: a long continuation step used
    to land beyond the disc, where a penalty pushes no more. The warm ramp and an
    independent reference stop at the disc, (−0.292, −0.756)."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=0, obstacles=(solver.Disc((-0.20, -0.55), 0.12, 1e4),))
    p = np.array([60, 0, 60, 0, 60, 0]) * PSI
    eq = solver.solve(arm, p, scene)
    assert eq.converged and eq.stable and not eq.snapped
    np.testing.assert_allclose(eq.tip, [-0.292, -0.756], atol=1e-3)
    np.testing.assert_allclose(eq.tip, _ramp(arm, scene, p, n=101).tip, atol=1e-6 * arm.length)


def _disc_scene(arm, rng):
    """A disc the arm runs into on its way to random pressures, clear of the unactuated arm:
    hanging or horizontal base, soft to stiff penalty."""
    while True:
        base = float(rng.choice([0.0, 90.0]))
        p = rng.uniform(0, 1, 6) * arm.max_pressure * (rng.uniform(size=6) < 0.6)
        free = solver.solve(arm, p, solver.Scene(base_angle_deg=base))
        j = rng.integers(len(free.s) // 3, len(free.s))
        radius = rng.uniform(0.05, 0.15)
        side = rng.choice([-1.0, 1.0])
        normal = side * np.array([-np.sin(free.angles[j]), np.cos(free.angles[j])])
        center = free.positions[j] + normal * (radius - rng.uniform(0.0, 0.05))
        rest = solver.solve(arm, np.zeros(6), solver.Scene(base_angle_deg=base))
        if np.hypot(*(rest.positions - center).T).min() > radius + 0.01:
            disc = solver.Disc(tuple(center), radius, float(rng.choice([1e4, 1e5, 1e6])))
            return solver.Scene(base_angle_deg=base, obstacles=(disc,)), p


def test_cold_contact_solve_equals_a_fine_warm_ramp():
    """The quasi-static contract with obstacles: a cold solve (load with the obstacles in
    place, then ramp the pressures) lands where 100 warm steps of the same ramp do, to
    1e-6·L — including paths that snap over a fold on the way (the snap relaxes to the
    same equilibrium at the same pressures whatever the step)."""
    arm = designs.octarm_v()
    rng = np.random.default_rng(2)
    touched = 0
    for _ in range(10):
        scene, p = _disc_scene(arm, rng)
        cold = solver.solve(arm, p, scene)
        warm = _ramp(arm, scene, p, n=101)
        assert cold.converged and cold.stable
        assert np.linalg.norm(cold.tip - warm.tip) <= 1e-6 * arm.length
        touched += cold.in_contact
    assert touched >= 8


def test_warm_jump_does_not_sweep_through_a_disc():
    """An absolute jump whose contact-free path would sweep the arm through a disc: the
    guarded shortcut hands it to the contact solver, which stops at the disc, as the path
    without shortcuts does."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=0, obstacles=(solver.Disc((-0.20, -0.55), 0.095, 1e5),))
    start = solver.solve(arm, np.zeros(6), scene)
    p = np.array([60, 0, 60, 0, 60, 0]) * PSI
    free = solver.solve(arm, p, solver.Scene(base_angle_deg=0))
    assert np.hypot(*(free.positions - (-0.20, -0.55)).T).min() > 0.105  # the free arm ends clear
    fast = solver.solve(arm, p, scene, warm_start=start)
    slow = solver.solve(arm, p, scene, warm_start=start, settings=solver.Settings(shortcuts=False))
    assert fast.converged and fast.in_contact
    assert np.linalg.norm(fast.tip - free.tip) > 0.05
    np.testing.assert_allclose(fast.tip, slow.tip, atol=1e-9)


@pytest.mark.parametrize("where", [1.0, 0.9, 0.6])
def test_contact_tip_error_at_default_resolution(where):
    """Contact at the free tip or further in: at the default 16 RK4 steps per section the tip
    is within 1e-4·L of a 512-step solve (the steps are split where the backbone enters and
    leaves a disc, so the penalty's kink does not cost RK4 its order)."""
    arm = designs.octarm_v()
    rng = np.random.default_rng(5)
    fine = solver.Settings(steps_per_section=512)
    for base in (0.0, 90.0):
        p = rng.uniform(0, 1, 6) * arm.max_pressure * (rng.uniform(size=6) < 0.6)
        free = solver.solve(arm, p, solver.Scene(base_angle_deg=base))
        j = int(where * (len(free.s) - 1))
        normal = np.array([-np.sin(free.angles[j]), np.cos(free.angles[j])])
        scene = solver.Scene(base_angle_deg=base, obstacles=(
            solver.Disc(tuple(free.positions[j] + 0.07 * normal), 0.08, 1e5),))
        coarse = solver.solve(arm, p, scene)
        ref = solver.solve(arm, p, scene, settings=fine)
        assert coarse.converged and ref.converged and ref.in_contact
        assert np.linalg.norm(coarse.tip - ref.tip) <= 1e-4 * arm.length


@pytest.mark.parametrize("guess, stable", [(-0.039, False), (3.098, False), (6.557, True)])
def test_multiple_shooting_stability_test_agrees_with_the_planar_one(guess, stable):
    """Three planar dead-load equilibria of a soft arm with a heavy payload (two looped and
    unstable, one hanging and stable), judged by the planar single-shooting test
    (∂m(s)/∂m0 > 0, exact for dead loads) and by the multiple-shooting test (the free tip's
    Jacobi fields carried to the base), which must agree."""
    from solver import layout as L
    from solver.kernels import contact as contact_kernels
    from solver.kernels import planar as planar_kernels
    from solver.paths.friction import no_samples, start_self_samples
    from solver.paths.shooting import nodes_from_states, shooting_grid
    from solver.problem import context, pack, shooting_layout, shooting_terms
    from solver.rod import rest_strains_into

    arm = designs.get("octarm_vi")
    settings = solver.Settings()
    scene = solver.Scene(base_angle_deg=184.2557848920924, payload_kg=1.425695544488903)
    packed = pack(arm, "full", settings)
    ctx = context(arm, packed, scene, 2, settings)
    rest = np.empty((3, len(arm.sections)))
    rest_strains_into(np.zeros(arm.n_channels), packed.tubes_i, packed.tubes_f, packed.secf, rest)
    out = np.empty((packed.n_rows, L.N_COLUMNS))
    m0, ok, _, _, planar_stable, *_ = planar_kernels.newton(guess, scene.base_theta, packed.secf,
                                                            packed.sec_steps, rest, ctx.loads,
                                                            ctx.m_tip, 1e-9, 30, 5.0, out, True)
    assert ok and planar_stable == stable
    layout, segs, sec_start = shooting_layout(arm, packed)
    nodes = nodes_from_states(out[:, [L.X, L.Y, L.THETA, L.NX, L.NY, L.M]], segs)
    plate, target, state_w, *_ = shooting_terms(arm, layout, segs, scene, ctx, True)
    level = (np.zeros(arm.n_channels), ctx.q, plate, target, np.empty((0, 4)), np.empty(0),
             no_samples(0), start_self_samples(scene, segs, None))
    grid = shooting_grid(arm, scene, layout, segs, sec_start)
    F = np.empty(nodes.size)
    J = np.empty((contact_kernels.BAND_ROWS, nodes.size))
    blocks = np.empty((segs.shape[0], 6, 6))
    contact_kernels.newton_system(nodes, grid, rest, level, F, J, True, blocks,
                                  contact_kernels.new_partners(grid))
    measure = contact_kernels.stability_test(blocks)
    assert np.abs(F).max() < 1e-6  # the planar equilibrium, in multiple-shooting form
    assert (measure > 0) == stable


def _curl_into_disc(stiffness):
    return solver.Scene(base_angle_deg=0,
                        obstacles=(solver.Disc((-0.20, -0.55), 0.12, stiffness),))


def test_penalty_converges_to_the_hard_contact_limit():
    """As the penalty stiffens tenfold, the penetration falls about fivefold and the tip moves
    less and less (by 9 mm, 1.8 mm, 0.37 mm, 0.06 mm): the penalty solution converges to the
    hard-contact one, and a rigid disc (penalty continuation to 3e-5 m) lands on its limit."""
    arm = designs.octarm_v()
    p = np.array([60, 0, 60, 0, 60, 0]) * PSI
    tips, depths = [], []
    for k in (1e4, 1e5, 1e6, 1e7, 1e8):
        eq = solver.solve(arm, p, _curl_into_disc(k))
        assert eq.converged and eq.stable
        tips.append(eq.tip)
        depths.append(eq.penetration.max())
    moves = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    assert np.all(moves[1:] < moves[:-1] / 3)
    assert np.all(np.array(depths[1:]) < np.array(depths[:-1]) / 3)
    hard = solver.solve(arm, p, _curl_into_disc(math.inf), settings=solver.Settings(gap_tol=3e-5))
    assert hard.converged and hard.penetration.max() <= 3e-5
    assert np.linalg.norm(hard.tip - tips[-1]) <= moves[-1]


def test_rigid_disc_along_a_warm_ramp():
    """Warm steps against a rigid disc start at the penalty the last step ended with and keep
    every penetration within the gap tolerance."""
    arm = designs.octarm_v()
    scene = _curl_into_disc(math.inf)
    p = np.array([60, 0, 60, 0, 60, 0]) * PSI
    eq = None
    for frac in np.linspace(0, 1, 11):
        eq = solver.solve(arm, frac * p, scene, warm_start=eq)
        assert eq.converged
        assert eq.penetration.max() <= solver.Settings().gap_tol
        assert math.isfinite(eq.penalty_stiffness) or not eq.in_contact
    cold = solver.solve(arm, p, scene)
    assert cold.converged and eq.in_contact
    np.testing.assert_allclose(eq.tip, cold.tip, atol=2e-4)  # both within the gap tolerance


def test_rigid_disc_validation():
    assert solver.Disc(stiffness=math.inf).stiffness == math.inf
    with pytest.raises(ValueError, match="math.inf"):
        solver.Disc(stiffness=math.nan)
