"""The lean stepper (:class:`solver.Stepper`) against the friendly API it shortcuts.

Oracle: ``solve(arm, p, scene, warm_start=previous)``, which validates and looks up
everything on every call and never uses the stepper's predictor; a step must land on the
same equilibrium to the solver's tolerance, on the lean path and on every general one.
"""

import math
from dataclasses import replace

import numpy as np
import pytest

import solver
from solver import PSI, designs
from solver import layout as L
from solver.problem import context, pack
from solver.rod import integrate_planar
from tests.solver import naive


def _walk(arm, n, scale, seed, planar=True):
    """n pressure vectors: a random walk of steps ``scale``·p_max per input, clipped."""
    rng = np.random.default_rng(seed)
    k = arm.n_inputs(planar)
    p = [rng.uniform(0.0, 0.5, k) * arm.max_pressure]
    for _ in range(n - 1):
        p.append(np.clip(p[-1] + rng.uniform(-scale, scale, k) * arm.max_pressure, 0.0,
                         arm.max_pressure))
    return p


@pytest.mark.parametrize("design, scene, scale", [
    ("octarm_v", solver.Scene(payload_kg=0.1), 0.02),
    ("octarm_v", solver.Scene(base_angle_deg=0.0), 1.0),
    ("ct", solver.Scene(base_angle_deg=45.0), 0.1),
    ("octarm_vi", solver.Scene(base_angle_deg=180.0, payload_kg=0.05), 0.1),
])
def test_lean_steps_equal_warm_solves(design, scene, scale):
    """Small steps, jumps anywhere in the pressure range (folds and snaps included), and an
    upright arm under load: every step lands where the warm-started solve() does."""
    arm = designs.get(design)
    pressures = _walk(arm, 25, scale, seed=3)
    stepper = solver.Stepper(arm, scene)
    assert stepper.lean
    stepper.reset(pressures[0])
    eq = solver.solve(arm, pressures[0], scene)
    for p in pressures[1:]:
        report = stepper.step(p)
        eq = solver.solve(arm, p, scene, warm_start=eq)
        assert report.converged == eq.converged
        assert report.snapped == eq.snapped
        got = stepper.equilibrium
        np.testing.assert_allclose(got.positions, eq.positions, atol=1e-8 * arm.length)
        np.testing.assert_allclose(got.internal_moment, eq.internal_moment, atol=1e-7)
        np.testing.assert_array_equal(stepper.tip, got.tip)
        np.testing.assert_array_equal(got.pressures, p)


@pytest.mark.parametrize("case", ["spatial", "unloaded", "constant_curvature"])
def test_general_steps_equal_warm_solves(case):
    arm = designs.octarm_v()
    planar = case != "spatial"
    scene = {"spatial": solver.Scene(payload_kg=0.1),
             "unloaded": solver.Scene(gravity=0.0),
             "constant_curvature": solver.Scene()}[case]
    model = "constant_curvature" if case == "constant_curvature" else "full"
    pressures = _walk(arm, 6, 0.05, seed=5, planar=planar)
    stepper = solver.Stepper(arm, scene, model=model, planar=planar)
    assert not stepper.lean
    stepper.reset(pressures[0])
    eq = solver.solve(arm, pressures[0], scene, model=model, planar=planar)
    for p in pressures[1:]:
        report = stepper.step(p)
        eq = solver.solve(arm, p, scene, model=model, planar=planar, warm_start=eq)
        assert report.converged and eq.converged
        np.testing.assert_allclose(stepper.tip, eq.tip, atol=1e-9)
        np.testing.assert_allclose(stepper.equilibrium.positions, eq.positions, atol=1e-9)


def test_rest_gradient_predicts_the_base_moment():
    """The predictor's gradient against central differences of converged solves: the base
    moment's change over a small pressure step, to second order in the step."""
    arm = designs.octarm_v()
    scene = solver.Scene(payload_kg=0.2, base_angle_deg=60.0)
    p = np.array([40, 10, 25, 8, 5, 30]) * PSI
    stepper = solver.Stepper(arm, scene)
    stepper.reset(p)
    grad = stepper._memo[3].copy()
    rest0 = np.vstack(solver.rest_strains(arm, stepper.channel_pressures))
    for k in range(6):
        dp = np.zeros(6)
        dp[k] = 0.002 * arm.max_pressure
        up = solver.solve(arm, p + dp, scene, warm_start=stepper.equilibrium)
        down = solver.solve(arm, p - dp, scene, warm_start=stepper.equilibrium)
        measured = (up.base_moment[0] - down.base_moment[0]) / 2
        d_rest = (np.vstack(solver.rest_strains(arm, up.channel_pressures))
                  - np.vstack(solver.rest_strains(arm, down.channel_pressures))) / 2
        predicted = grad[0] @ d_rest[L.REST_U2] + grad[1] @ d_rest[L.REST_V3]
        assert predicted == pytest.approx(measured, rel=1e-2, abs=1e-9)
        assert rest0.shape == d_rest.shape


@pytest.mark.parametrize("design, payload, angle", [("octarm_v", 0.2, 60.0), ("ct", 0.0, 0.0),
                                                    ("octarm_v", 0.0, 180.0)])
def test_rest_gradient_adjoint_equals_forward_sensitivities(design, payload, angle):
    """The kernel's one adjoint sweep against one forward integration per parameter of the
    same Heun scheme (naive.py): equal to rounding, on arms that bend, hang and stand."""
    arm = getattr(designs, design)()
    stepper = solver.Stepper(arm, solver.Scene(payload_kg=payload, base_angle_deg=angle))
    rng = np.random.default_rng(3)
    stepper.reset(rng.uniform(0.0, 0.6, arm.n_inputs(True)) * arm.max_pressure)
    eq = stepper.equilibrium
    rest = np.vstack(solver.rest_strains(arm, eq.channel_pressures))
    forward = naive.rest_gradient_forward(arm, eq, rest)
    np.testing.assert_allclose(stepper._memo[3], forward, rtol=1e-9, atol=1e-12 * np.abs(forward).max())


def test_small_steps_take_one_newton_iteration():
    """With the first-order prediction a 1 % step needs one correction (two passes)."""
    arm = designs.octarm_v()
    stepper = solver.Stepper(arm, solver.Scene(payload_kg=0.1))
    pressures = _walk(arm, 21, 0.01, seed=9)
    stepper.reset(pressures[0])
    iterations = [stepper.step(p).iterations for p in pressures[1:]]
    assert np.mean(iterations) <= 1.5, iterations


@pytest.mark.parametrize("design", ["octarm_v", "ct"])
def test_halley_steps_meet_tol_on_the_second_pass(design):
    """Newton's step corrected by Halley's factor converges cubically: from the first-order
    prediction, nine 1 % steps in ten meet tol at the second pass (plain Newton's step: about
    half), on arms hanging, bent sideways and upright, with and without a payload."""
    arm = getattr(designs, design)()
    iterations = []
    for k, (angle, payload) in enumerate([(90.0, 0.0), (45.0, 0.1), (0.0, 0.1), (135.0, 0.0)]):
        stepper = solver.Stepper(arm, solver.Scene(payload_kg=payload, base_angle_deg=angle))
        pressures = _walk(arm, 31, 0.01, seed=20 + k)
        stepper.reset(pressures[0])
        iterations += [stepper.step(p).iterations for p in pressures[1:]]
    assert np.mean(np.array(iterations) == 1) >= 0.85, iterations


@pytest.mark.parametrize("design, angle, payload", [
    ("octarm_v", 135.0, 0.0), ("octarm_v", 150.0, 0.2), ("ct", 180.0, 0.1)])
def test_jumps_land_where_a_fine_march_does(design, angle, payload):
    """Jumps between random pressures anywhere in the range: the direct attempt is often
    rejected there, and the continuation gives up on a step as soon as Newton leaves twice
    its acceptance radius. Every jump lands on the root a plain 400-step march along the same
    ramp reaches (``naive.march_planar``), wherever that march stays on one stable branch."""
    arm = getattr(designs, design)()
    scene = solver.Scene(base_angle_deg=angle, payload_kg=payload)
    settings = solver.Settings()
    packed = pack(arm, "full", settings)
    ctx = context(arm, packed, scene, 2, settings)
    out = np.empty((packed.n_rows, L.N_COLUMNS))
    stepper = solver.Stepper(arm, scene)
    rng = np.random.default_rng(5)
    compared = continued = 0
    for _ in range(40):
        p_a, p_b = rng.uniform(0.0, 1.0, (2, arm.n_inputs(True))) * arm.max_pressure
        stepper.reset(p_a)
        m_start = stepper.equilibrium.internal_moment[0]
        c_a = stepper.channel_pressures.copy()
        rest_a = np.vstack(solver.rest_strains(arm, c_a))
        gradient = naive.rest_gradient_forward(arm, stepper.equilibrium, rest_a)
        assert stepper.step(p_b).converged
        c_b = stepper.channel_pressures
        change = np.vstack(solver.rest_strains(arm, c_b)) - rest_a
        predicted = m_start + gradient[0] @ change[1] + gradient[1] @ change[2]

        def residual(t, m0, c_a=c_a, c_b=c_b):
            rest = np.vstack(solver.rest_strains(arm, c_a + t * (c_b - c_a)))
            _, m, b, _, _, bmin, *_ = integrate_planar(m0, scene.base_theta, packed.secf,
                                                      packed.sec_steps, rest, ctx.loads, False, out,
                                                      False)
            return m - ctx.m_tip, b, bmin > 0.0

        marched = naive.march_planar(residual, m_start, max_move=ctx.params[L.JUMP])
        if marched is None:
            continue
        m_end = stepper.equilibrium.internal_moment[0]
        compared += 1
        # Farther from the prediction than a direct attempt may land: the continuation ran.
        continued += abs(m_end - predicted) > ctx.params[L.JUMP] + 0.5 * abs(predicted - m_start)
        assert m_end == pytest.approx(marched, abs=1e-8 * packed.moment_scale)
    assert compared >= 25 and continued >= 10, (compared, continued)


def test_failed_step_keeps_the_state():
    arm = designs.octarm_v()
    settings = solver.Settings.without_fallback(max_iter=1)
    stepper = solver.Stepper(arm, solver.Scene(base_angle_deg=0.0), settings=settings)
    stepper.reset(np.zeros(6))
    tip, record = stepper.tip.copy(), stepper.record.copy()
    eq = stepper.equilibrium
    report = stepper.step(np.array([1.0, 0.0, 1.0, 0.0, 1.0, 0.0]) * arm.max_pressure)
    assert not report.converged and report.iterations >= 1
    np.testing.assert_array_equal(stepper.tip, tip)
    np.testing.assert_array_equal(stepper.record, record)
    np.testing.assert_array_equal(stepper.pressures, np.zeros(6))
    assert stepper.equilibrium is eq


def test_equilibria_handed_out_do_not_change():
    arm = designs.octarm_v()
    stepper = solver.Stepper(arm)
    stepper.reset(np.zeros(6))
    first = stepper.equilibrium
    positions = first.positions.copy()
    for p in _walk(arm, 4, 0.2, seed=1):
        stepper.step(p)
    np.testing.assert_array_equal(first.positions, positions)


@pytest.mark.parametrize("self_contact", [False, True], ids=["free", "self-contact"])
def test_bad_input_is_named(self_contact):
    # (With self-contact a step takes the contact rows' path, which checks its pressures too.)
    arm = designs.octarm_v()
    scene = solver.Scene(self_contact=arm.tubes[0].material.ring_stiffness if self_contact else None)
    stepper = solver.Stepper(arm, scene)
    with pytest.raises(RuntimeError, match="reset"):
        stepper.step(np.zeros(6))
    stepper.reset(np.zeros(6))
    with pytest.raises(ValueError, match="expects 6 pressures"):
        stepper.step(np.zeros(5))
    with pytest.raises(ValueError, match="expects 6 pressures"):
        stepper.step(["a"] * 6)
    with pytest.raises(ValueError, match="not finite"):
        stepper.step([0, 0, math.nan, 0, 0, 0])
    with pytest.raises(ValueError, match="negative"):
        stepper.step([0, -1.0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="exceeds the design's rated maximum"):
        stepper.step(np.full(6, 2 * arm.max_pressure))
    np.testing.assert_array_equal(stepper.pressures, np.zeros(6))
    other = solver.solve(arm, np.zeros(6), solver.Scene(payload_kg=0.3, self_contact=scene.self_contact))
    with pytest.raises(ValueError, match="not in this stepper's scene"):
        stepper.adopt(other)
    with pytest.raises(ValueError, match="settings"):
        solver.Stepper(arm, settings={"tol": 1e-9})


# ----------------------------------------------------------------------------- BatchStepper


@pytest.mark.parametrize("n", [3, solver.BatchStepper.PARALLEL_MIN + 1])  # one thread, parallel
@pytest.mark.parametrize("design", [designs.octarm_v, designs.ct])
def test_batch_copies_are_steppers_bit_for_bit(design, n):
    """Copy k of a BatchStepper gives the records, tips and reports a Stepper gives."""
    arm, scene = design(), solver.Scene(base_angle_deg=60.0, payload_kg=0.05)
    rng = np.random.default_rng(n)
    p_max = arm.max_pressure
    batch = solver.BatchStepper(arm, scene, n)
    singles = [solver.Stepper(arm, scene) for _ in range(n)]
    start = rng.uniform(0.0, 0.2, (n, arm.n_inputs(True))) * p_max
    report = batch.reset(start)
    for k, single in enumerate(singles):
        assert single.reset(start[k]) == tuple(field[k] for field in report)
    targets = rng.uniform(0.0, 1.0, (n, arm.n_inputs(True))) * p_max
    tips, _ = batch.solve_tips(targets)
    for k in range(n):
        np.testing.assert_array_equal(tips[k], solver.solve(arm, targets[k], scene, record=False).tip)
    for step in range(6):
        # Jumps across the whole range: some steps snap or fall back to the general path.
        p = rng.uniform(0.0, 1.0, (n, arm.n_inputs(True))) * p_max
        active = rng.uniform(size=n) < 0.8
        report = batch.step(p, active=active)
        for k, single in enumerate(singles):
            if active[k]:
                assert single.step(p[k]) == tuple(field[k] for field in report), (step, k)
            np.testing.assert_array_equal(batch.records[k], single.record)
            np.testing.assert_array_equal(batch.pressures[k], single.pressures)
    np.testing.assert_array_equal(batch.tips, [s.tip for s in singles])
    assert batch.equilibrium(0).tip.tolist() == singles[0].equilibrium.tip.tolist()


def test_batch_refuses_what_it_cannot_step():
    arm = designs.octarm_v()
    with pytest.raises(ValueError, match="rigid contact"):
        solver.BatchStepper(arm, solver.Scene(obstacles=(solver.Disc((0.1, -0.3), 0.05, math.inf),)), 2)
    with pytest.raises(ValueError, match="spatial|planar"):
        solver.BatchStepper(arm, solver.Scene(obstacles=(solver.Sphere((0.1, -0.3, 0.0), 0.05),)), 2)
    with pytest.raises(ValueError, match="unloaded"):
        solver.BatchStepper(arm, solver.Scene(gravity=0.0), 2)
    with pytest.raises(ValueError, match="n must be"):
        solver.BatchStepper(arm, solver.Scene(), 0)
    batch = solver.BatchStepper(arm, solver.Scene(), 2)
    with pytest.raises(RuntimeError, match="reset"):
        batch.step(np.zeros((2, 6)))
    batch.reset(np.zeros((2, 6)))
    bad = np.zeros((2, 6))
    bad[1, 2] = -1.0
    with pytest.raises(ValueError, match="row 1"):
        batch.step(bad)
    with pytest.raises(ValueError, match=r"shape \(2, 6\)"):
        batch.step(np.zeros((3, 6)))
    with pytest.raises(ValueError, match="rows"):
        batch.reset(np.zeros((1, 6)), rows=[5])


def _drive(policy, threaded_cost, serial_cost, calls, rows=64):
    """Run ``calls`` batches through ``policy`` with the given seconds per row; the choices."""
    choices = []
    for k in range(calls):
        threaded = policy.choose(rows)
        choices.append(threaded)
        policy.record(threaded, rows, rows * (threaded_cost(k) if threaded else serial_cost(k)))
    return choices


def test_thread_policy_picks_the_faster_way_and_probes_rarely_when_threads_lose(monkeypatch):
    monkeypatch.setattr(solver.stepper.numba, "get_num_threads", lambda: 2)
    policy = solver.ThreadPolicy(min_rows=8)
    # Threads ten times slower (a busy machine): after calibrating, serial, with probes
    # whose interval doubles each time they lose.
    choices = _drive(policy, lambda k: 1e-4, lambda k: 1e-5, 2000)
    assert choices[:4] == [False, False, True, True]  # first of each is the kernel's load
    assert sum(choices[4:]) <= 8  # probes at 16, 32, 64, ... 1024 batches apart
    assert policy.per_row_s[0] == pytest.approx(1e-5) and policy.per_row_s[1] == pytest.approx(1e-4)
    # The machine frees up: threads twice as fast. The next probe wins and threads stay.
    choices = _drive(policy, lambda k: 0.5e-5, lambda k: 1e-5, 3000)
    assert all(choices[-500:])
    # Small batches and a single-thread configuration always run serially.
    assert not policy.choose(7)
    monkeypatch.setattr(solver.stepper.numba, "get_num_threads", lambda: 1)
    assert not policy.choose(1000)


@pytest.mark.parametrize("slowdown", [3.0, 36.0])
@pytest.mark.parametrize("calls", [2_000, 20_000])
def test_on_a_contended_machine_threads_cost_at_most_the_probe_budget_over_one_thread(monkeypatch, slowdown,
                                                                                     calls):
    """Threaded batches ``slowdown`` times slower than serial ones (36x: measured for 64 arms
    with two busy processes on this 2-core machine), over a short run (a PPO rollout phase)
    and a long one: the policy's choices cost at most ``PROBE_BUDGET`` (plus the calibration
    batches) more than one thread."""
    monkeypatch.setattr(solver.stepper.numba, "get_num_threads", lambda: 2)
    policy = solver.ThreadPolicy(min_rows=8)
    serial = 1e-5
    choices = _drive(policy, lambda k: slowdown * serial, lambda k: serial, calls)
    cost = sum(slowdown * serial if threaded else serial for threaded in choices)
    calibration = 2 * slowdown * serial  # the first threaded load and measurement
    assert cost - calibration <= (1 + solver.ThreadPolicy.PROBE_BUDGET) * calls * serial
    # ... and it still re-checks: the threads are tried again during the run.
    assert sum(choices[4:]) >= 2


def test_pickled_steppers_continue_identically():
    import pickle

    arm, scene = designs.octarm_v(), solver.Scene(base_angle_deg=90.0)
    p = np.full(6, 0.2 * arm.max_pressure)
    stepper, batch = solver.Stepper(arm, scene), solver.BatchStepper(arm, scene, 2)
    stepper.reset(p)
    batch.reset(np.stack([p, p]))
    for original in (stepper, batch):
        clone = pickle.loads(pickle.dumps(original))
        for k in range(3):
            q = p * (1.0 + 0.1 * (k + 1))
            if original is stepper:
                assert clone.step(q) == original.step(q)
                np.testing.assert_array_equal(clone.tip, original.tip)
                np.testing.assert_array_equal(clone.tip, clone.record[-1, L.X:L.Y + 1])
            else:
                clone.step(np.stack([q, q]))
                original.step(np.stack([q, q]))
                np.testing.assert_array_equal(clone.tips, original.tips)
                np.testing.assert_array_equal(clone.tips, clone.records[:, -1, L.X:L.Y + 1])


def test_adopt_moved_is_with_scene_then_adopt():
    """A free object the arm presses on, moved by the arm (:mod:`solver.grasp`): adopting the
    arm's equilibrium solved there keeps the stepper and gives what a new stepper in that
    scene adopting it gives (the next steps bit for bit); a scene that differs in more than
    the discs' centres is refused, naming the way that takes it."""
    from solver.grasp import FreeObject, settle

    arm = designs.octarm_v()
    obj = FreeObject(radius=0.1, mass_kg=0.3, seat=(-0.16, -0.25), stiffness=2e4)
    free = solver.Scene(self_contact=2e4)
    p = np.zeros(arm.n_inputs(True))
    p[0::2] = 0.6 * arm.max_pressure
    before = settle(arm, p, free, obj)
    stepper = solver.Stepper(arm, before.arm.scene)
    stepper.adopt(before.arm)
    p[0::2] = 0.62 * arm.max_pressure
    after = settle(arm, p, free, obj, center=before.center, warm_start=before.arm)
    assert after.converged and after.arm.in_contact and np.all(after.center != before.center)
    fresh = stepper.with_scene(after.arm.scene)
    fresh.adopt(after.arm)
    stepper.adopt_moved(after.arm)
    assert stepper.scene == after.arm.scene
    for q in (0.63, 0.65, 0.5):
        p[0::2] = q * arm.max_pressure
        assert stepper.step(p) == fresh.step(p)
        np.testing.assert_array_equal(stepper.record, fresh.record)
        np.testing.assert_array_equal(stepper.equilibrium.positions, fresh.equilibrium.positions)
    disc = stepper.scene.obstacles[0]
    for other in (solver.Scene(obstacles=(replace(disc, radius=0.11),), self_contact=2e4),
                  solver.Scene(obstacles=(disc,), self_contact=2e4, payload_kg=0.1),
                  solver.Scene(obstacles=(disc, replace(disc, center=(0.3, -0.3))), self_contact=2e4)):
        eq = solver.solve(arm, p, other)
        with pytest.raises(ValueError, match="with_scene"):
            stepper.adopt_moved(eq)
    assert stepper.scene == after.arm.scene  # a refused equilibrium changed nothing
    with pytest.raises(ValueError, match="record=False"):
        stepper.adopt_moved(solver.solve(arm, p, after.arm.scene, record=False))
    assert stepper.scene == after.arm.scene
    spatial = solver.Stepper(arm, solver.Scene(obstacles=(solver.Disc((-0.3, -0.3), 0.1),)), planar=False)
    with pytest.raises(ValueError, match="planar stepper"):
        spatial.adopt_moved(solver.solve(arm, np.zeros(arm.n_inputs(False)),
                                         solver.Scene(obstacles=(solver.Disc((-0.31, -0.3), 0.1),)),
                                         planar=False))
