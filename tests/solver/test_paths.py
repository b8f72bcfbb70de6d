"""Quasi-static path following: warm starts follow the branch; folds snap and say so."""

import importlib

import numpy as np
import pytest

import solver
from solver import PSI, designs, layout


def _sweep(arm, scene, channel, levels, eq=None):
    out = []
    for level in levels:
        p = np.zeros(arm.n_inputs())
        p[channel] = level * PSI
        eq = solver.solve(arm, p, scene, warm_start=eq)
        out.append(eq)
    return out


def test_snap_through_and_hysteresis():
    """Horizontal OctArm V lifting section 1: it snaps over the top on the way up and stays
    there on the way down — two stable equilibria for the same pressures."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    levels = np.linspace(0, 100, 21)
    up = _sweep(arm, scene, 1, levels)
    down = _sweep(arm, scene, 1, levels[::-1], eq=up[-1])[::-1]
    assert all(e.converged and e.stable for e in up + down)
    assert any(e.snapped for e in up)
    gaps = [np.linalg.norm(u.tip - d.tip) for u, d in zip(up, down)]
    assert max(gaps) > 0.5
    assert gaps[0] < 1e-9  # back at zero pressure both paths meet again
    # A cold solve ramps pressure from zero, so it lands on the upward branch.
    for k in (8, 12, 16):
        cold = solver.solve(arm, up[k].pressures, scene)
        np.testing.assert_allclose(cold.tip, up[k].tip, atol=1e-9)


def test_warm_step_equals_cold_solve_on_a_single_branch():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=45, payload_kg=0.1)
    p1 = np.array([20, 0, 0, 30, 10, 0]) * PSI
    p2 = np.array([25, 5, 0, 35, 15, 0]) * PSI
    warm = solver.solve(arm, p2, scene, warm_start=solver.solve(arm, p1, scene))
    cold = solver.solve(arm, p2, scene)
    assert warm.converged and warm.iterations < cold.iterations
    np.testing.assert_allclose(warm.tip, cold.tip, atol=1e-10)


def _same(a, b):
    """Equal Equilibria, arrays bit for bit (NaN equal to NaN)."""
    assert a.__dict__.keys() == b.__dict__.keys()
    for name, value in a.__dict__.items():
        other = b.__dict__[name]
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, other, err_msg=name)
        else:
            assert value == other or (value != value and other != other), name


@pytest.mark.parametrize("record", [True, False])
def test_solve_in_one_kernel_call_is_the_general_path(monkeypatch, record):
    """solve()'s fast path (solver.paths.planar.solve_lean), warm and cold, returns exactly
    what the general path returns, and hands over to it where it does not apply (a snap, a
    scene it does not solve, a grid too coarse)."""
    rng = np.random.default_rng(5)
    default, coarse = solver.Settings(), solver.Settings(steps_per_section=2)
    cases = []
    for arm, scene in [(designs.octarm_v(), solver.Scene(base_angle_deg=45, payload_kg=0.1)),
                       (designs.ct(), solver.Scene(base_angle_deg=90)),
                       (designs.octarm_v(), solver.Scene(base_angle_deg=90)),
                       (designs.octarm_v(), solver.Scene(gravity=0.0))]:  # closed form
        eq = solver.solve(arm, np.zeros(arm.n_inputs()), scene)
        for step in (0.01, 0.01, 0.3, 1.0):  # small env steps, then jumps across the box
            p = np.clip(eq.pressures + rng.normal(0, step * arm.max_pressure, eq.pressures.shape),
                        0, arm.max_pressure)
            cases += [(arm, p, scene, eq, default), (arm, p, scene, None, default)]
            eq = solver.solve(arm, p, scene, warm_start=eq)
    # On a coarse grid the kernel's check refuses what the general path refines.
    arm, scene = designs.octarm_v(), solver.Scene(base_angle_deg=90)
    start = solver.solve(arm, np.full(6, 0.5 * arm.max_pressure), scene, settings=coarse)
    cases += [(arm, np.full(6, arm.max_pressure), scene, start, coarse),
              (arm, np.full(6, arm.max_pressure), scene, None, coarse)]
    # The snap of test_snap_through_and_hysteresis, approached in one step.
    up = _sweep(designs.octarm_v(), solver.Scene(base_angle_deg=90), 1, np.linspace(0, 40, 9))
    p = up[-1].pressures.copy()
    p[1] = 100 * PSI
    cases.append((up[-1].arm, p, up[-1].scene, up[-1], default))

    _fast_path_is_the_general_path(monkeypatch, "solve_lean", cases, record, planar=True)


def _fast_path_is_the_general_path(monkeypatch, name, cases, record, planar):
    """Solve ``cases`` (arm, pressures, scene, warm start, settings) with solve()'s fast path
    ``name`` (in solver.paths.dispatch) and without it: the same results bit for bit, the fast path
    returning some and handing the others over."""
    solve_module = importlib.import_module("solver.paths.dispatch")
    outcomes = []
    fast_path = getattr(solve_module, name)

    def spy(*args):
        eq = fast_path(*args)
        outcomes.append(eq is not None)
        return eq

    monkeypatch.setattr(solve_module, name, spy)
    fast = [solver.solve(arm, p, scene, warm_start=eq, record=record, settings=s, planar=planar)
            for arm, p, scene, eq, s in cases]
    monkeypatch.setattr(solve_module, name, lambda *args: None)
    general = [solver.solve(arm, p, scene, warm_start=eq, record=record, settings=s,
                            planar=planar) for arm, p, scene, eq, s in cases]
    for a, b in zip(fast, general):
        _same(a, b)
    assert any(outcomes) and not all(outcomes)  # both the fast path and the hand-over ran
    assert all(e.converged for e in fast)


@pytest.mark.parametrize("record", [True, False])
def test_spatial_warm_solve_in_one_kernel_call_is_the_general_path(monkeypatch, record):
    """solve()'s spatial fast path (solver.paths.spatial.solve_spatial_lean) returns exactly
    what the general path returns, and hands over to it where it does not apply (a cold
    solve, a warm start in the plane or from another scene, a grid too coarse)."""
    rng = np.random.default_rng(6)
    default, coarse = solver.Settings(), solver.Settings(steps_per_section=2)
    cases = []
    for arm, scene in [(designs.octarm_v(), solver.Scene(base_angle_deg=90, payload_kg=0.1)),
                       (designs.ct(), solver.Scene(base_angle_deg=45)),
                       (designs.octarm_v(), solver.Scene())]:
        n = arm.n_inputs(False)
        eq = solver.solve(arm, np.zeros(n), scene, planar=False)  # in the plane: handed over
        for step in (0.01, 0.01, 0.1, 0.5):
            p = np.clip(eq.pressures + rng.normal(0, step * arm.max_pressure, n), 0,
                        arm.max_pressure)
            cases += [(arm, p, scene, eq, default), (arm, p, scene, None, default)]
            eq = solver.solve(arm, p, scene, warm_start=eq, planar=False)
    # From another scene (the loads ramp), and on a coarse grid the check refuses.
    arm, scene = designs.octarm_v(), solver.Scene(base_angle_deg=90)
    p = rng.uniform(0, 0.5, 9) * arm.max_pressure
    here = solver.solve(arm, p, scene, planar=False)
    cases.append((arm, 0.9 * p, solver.Scene(base_angle_deg=90, payload_kg=0.2), here, default))
    start = solver.solve(arm, p, scene, planar=False, settings=coarse)
    cases.append((arm, np.full(9, 0.6 * arm.max_pressure) - p, scene, start, coarse))
    _fast_path_is_the_general_path(monkeypatch, "solve_spatial_lean", cases, record,
                                   planar=False)


@pytest.mark.parametrize("floor", [0.0, 1.0 / 256.0, 0.003])
@pytest.mark.parametrize("t", [0.0, 0.625, 0.75, 0.9375, 1.0 - 3.0 / 64.0, 1.0 - 1.0 / 512.0])
def test_a_failed_try_is_halved_to_the_next_different_try(t, floor):
    """After a failed try, the continuation loops' next step is the one plain halving reaches
    at its first try that differs from the failed one, or at the floor if that comes first:
    a try past the ramp's end is clipped at t = 1, and halving a step that still reaches past
    it would repeat the same try from the same state (and its failure)."""
    from solver.kernels.homotopy import halved
    for dt in (1.0, 0.5, 0.25, 0.125, 0.0625):
        t_new = min(1.0, t + dt)
        step = dt
        while step > floor:  # plain halving, each try made as a loop makes it
            step *= 0.5
            if min(1.0, t + step) != t_new:
                break
        assert halved(dt, t_new - t, floor) == step


def test_warm_start_across_payload_change():
    arm = designs.octarm_v()
    p = np.array([20, 0, 0, 30, 10, 0]) * PSI
    light = solver.solve(arm, p, solver.Scene(base_angle_deg=60))
    heavy_scene = solver.Scene(base_angle_deg=60, payload_kg=0.2)
    warm = solver.solve(arm, p, heavy_scene, warm_start=light)
    np.testing.assert_allclose(warm.tip, solver.solve(arm, p, heavy_scene).tip, atol=1e-10)


def test_batch_is_the_cold_solve_in_any_order():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    rng = np.random.default_rng(3)
    P = rng.uniform(0, arm.max_pressure, (40, 6))
    tips, ok = solver.solve_batch(arm, P, scene)
    order = rng.permutation(40)
    tips2, ok2 = solver.solve_batch(arm, P[order], scene)
    np.testing.assert_array_equal(tips2, tips[order])
    for k in range(0, 40, 7):
        eq = solver.solve(arm, P[k], scene, record=False)
        np.testing.assert_array_equal(eq.tip, tips[k])
        assert eq.converged == ok[k]
    assert ok.all()


def test_spatial_warm_start():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    p1 = np.array([20, 10, 0, 30, 0, 5, 10, 0, 0]) * PSI
    p2 = p1 + 3 * PSI
    e1 = solver.solve(arm, p1, scene, planar=False)
    warm = solver.solve(arm, p2, scene, planar=False, warm_start=e1)
    cold = solver.solve(arm, p2, scene, planar=False)
    assert warm.converged and warm.stable and abs(warm.tip[2]) > 1e-3
    np.testing.assert_allclose(warm.tip, cold.tip, atol=1e-9)


def test_strict_raises_when_unconverged():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90, payload_kg=0.2)
    settings = solver.Settings.without_fallback(max_iter=1)
    eq = solver.solve(arm, np.full(6, 80 * PSI), scene, settings=settings)
    assert not eq.converged and eq.residual > 0
    assert np.all(np.isfinite(eq.positions))
    with pytest.raises(solver.SolverError, match="no converged equilibrium"):
        solver.solve(arm, np.full(6, 80 * PSI), scene, settings=settings, strict=True)


def test_step_batch_equals_solve_cold_and_warm():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    rng = np.random.default_rng(5)
    P = rng.uniform(0, arm.max_pressure, (6, 6))
    state = solver.step_batch(arm, P, scene, record=True)
    P2 = np.clip(P + rng.normal(0, 0.02 * arm.max_pressure, P.shape), 0, arm.max_pressure)
    state2 = solver.step_batch(arm, P2, scene, state=state, record=True)
    for k in range(6):
        cold = solver.solve(arm, P[k], scene)
        np.testing.assert_array_equal(state.tips[k], cold.tip)
        warm = solver.solve(arm, P2[k], scene, warm_start=cold)
        np.testing.assert_array_equal(state2.tips[k], warm.tip)
        np.testing.assert_array_equal(state2.shapes[k][:, 1:3], warm.positions)
    assert state2.converged.all()
    np.testing.assert_array_equal(state2.pressures, P2)


def test_step_batch_failed_rows_keep_their_state():
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90)
    start = solver.step_batch(arm, np.full((3, 6), 0.2 * arm.max_pressure), scene)
    # One plain Newton attempt cannot follow a jump across the snap-through fold.
    far = np.array([[0, 1, 0, 0, 0, 0], [0.2] * 6, [0, 1, 0, 0, 0, 0]]) * arm.max_pressure
    step = solver.step_batch(arm, far, scene, state=start, record=True,
                             settings=solver.Settings.without_fallback())
    failed = ~step.converged
    assert failed[0] and failed[2] and not failed[1]
    np.testing.assert_array_equal(step.tips[failed], start.tips[failed])
    np.testing.assert_array_equal(step.pressures[failed], start.pressures[failed])
    np.testing.assert_array_equal(step.base_moment[failed], start.base_moment[failed])
    # Kept and new records alike: the solver's scratch columns hold nothing (solver.layout).
    assert np.isnan(step.shapes[:, :, layout.D_THETA:]).all()
    assert np.isfinite(step.shapes[:, :, :layout.D_THETA]).all()


@pytest.mark.parametrize("model, gravity", [("constant_curvature", 9.81), ("full", 0.0)])
def test_batch_closed_form_equals_solve(model, gravity):
    arm = designs.ct()
    scene = solver.Scene(base_angle_deg=30, gravity=gravity)
    P = np.random.default_rng(2).uniform(0, arm.max_pressure, (25, 4))
    tips, ok = solver.solve_batch(arm, P, scene, model=model)
    assert ok.all()
    for k in range(0, 25, 6):
        np.testing.assert_allclose(tips[k], solver.solve(arm, P[k], scene, model=model).tip,
                                   atol=1e-12)


def test_both_methods_failing_fall_back_to_finer_continuation():
    """A soft OctArm V (moduli × 0.046) pointing up, folding over under its own weight: with
    the default continuation single shooting leaves its grid unresolved and multiple
    shooting loses the path; the finer continuation (:meth:`Settings.finer`) follows it, so
    the default solve converges — to the stable equilibrium the finer settings find alone."""
    from dataclasses import replace

    from softarm_gym.benchmarks.stress import scaled
    from solver.inputs import request
    from solver.paths.planar import solve_single
    from solver.paths.shooting import solve_multiple

    arm = scaled(designs.octarm_v(), stiffness=0.0322149580125922 / 0.6961461434850154)
    scene = solver.Scene(base_angle_deg=178.7332626375461, payload_kg=0.04136377153946509)
    p = np.array([11728.26612917, 18468.84957647, 28964.7243914, 11622.80110374, 29000.42015825,
                  17154.45569641])
    settings = solver.Settings()
    problem = request(arm, p, scene, "full", True, None, settings)
    for method in (solve_single, solve_multiple):
        plain = method(problem)
        assert not plain.converged
    eq = solver.solve(arm, p, scene)
    assert eq.converged and eq.stable
    finer = solver.solve(arm, p, scene, settings=settings.finer())
    assert finer.converged and finer.stable
    np.testing.assert_allclose(eq.tip, finer.tip, atol=1e-9 * arm.length)
    assert settings.finer() == replace(settings, dt_min=1.0 / 4096.0, max_iter=40, n_scan=384)
    assert settings.finer().finer() == settings.finer()
