"""Bad input gets a clear ValueError naming the problem, never a numba traceback."""

import pickle
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

import solver
from solver import PSI, designs

ARM = designs.octarm_v()


@pytest.mark.parametrize("pressures, match", [
    (np.zeros(5), "expects 6 pressures"),
    (np.zeros((2, 6)), "expects 6 pressures"),
    ("30,0", "expects 6 pressures"),
    ([0, 0, np.nan, 0, 0, 0], "s2_I.*not finite"),
    ([0, 0, 0, np.inf, 0, 0], "s2_II\\+III.*not finite"),
    ([0, -1.0, 0, 0, 0, 0], "s1_II\\+III.*negative"),
    ([0, 0, 0, 0, 0, 101 * PSI], "s3_II\\+III.*rated maximum"),
    ([[1], 2, 3, 4, 5, 6], "expects 6 pressures"),
])
def test_bad_pressures(pressures, match):
    with pytest.raises(ValueError, match=match):
        solver.solve(ARM, pressures, solver.Scene())


def test_spatial_pressure_count():
    with pytest.raises(ValueError, match="9 pressures in spatial"):
        solver.solve(ARM, np.zeros(6), solver.Scene(), planar=False)


@pytest.mark.parametrize("kwargs, match", [
    (dict(base_angle_deg=np.nan), "base_angle_deg"), (dict(payload_kg=-1), "payload_kg"),
    (dict(gravity=-9.81), "gravity"), (dict(tip_force=(1, 2, 3, 4)), "tip_force"),
    (dict(tip_moment=(1, 2)), "tip_moment"), (dict(base_angle_deg="90"), "base_angle_deg"),
])
def test_bad_scene(kwargs, match):
    with pytest.raises(ValueError, match=match):
        solver.Scene(**kwargs)


def test_scene_without_contact_is_built_once_and_pickles():
    scene = solver.Scene(payload_kg=0.1, obstacles=(solver.Disc((0.2, -0.3), 0.05),), self_contact=1e5)
    free = scene.without_contact
    assert free == solver.Scene(payload_kg=0.1) and not free.has_contact
    assert scene.without_contact is free and free.without_contact is free
    copy = pickle.loads(pickle.dumps(scene))
    assert copy == scene and copy.without_contact == free


@pytest.mark.parametrize("scene", [
    solver.Scene(payload_kg=0.1, obstacles=(solver.Disc((0.2, -0.3), 0.05),), self_contact=1e5),
    solver.Scene(base_angle_deg=30.0),
    solver.Scene(tip_force=(0.0, 0.0, 1.0)),
])
def test_with_obstacles_is_replace_sharing_the_scene_without_contact(scene):
    """``with_obstacles`` gives the scene ``replace`` gives (planarity worked out again), shares
    ``without_contact``, keeps the original as it was and checks the obstacles as the
    constructor does."""
    own = scene.obstacles
    for obstacles in ((), (solver.Disc((-0.3, -0.2), 0.1),),
                      (solver.Sphere((0.1, -0.4, 0.2), 0.05), solver.Disc((0.3, 0.1), 0.02))):
        moved = scene.with_obstacles(obstacles)
        expected = replace(scene, obstacles=obstacles)
        assert moved == expected and moved.is_planar == expected.is_planar
        assert moved.has_contact == expected.has_contact
        assert moved.without_contact is scene.without_contact
        assert moved.without_contact == expected.without_contact
        assert moved.obstacles == expected.obstacles and moved.base_theta == expected.base_theta
        assert pickle.loads(pickle.dumps(moved)) == expected
    assert scene.obstacles is own and scene.is_planar == replace(scene).is_planar
    with pytest.raises(ValueError, match=r"obstacles\[0\].*covers the arm's base"):
        scene.with_obstacles((solver.Disc((0.0, -0.05), 0.1),))
    with pytest.raises(ValueError, match="must be a tuple of solver.Disc"):
        scene.with_obstacles(({"center": (0.3, 0.3)},))


def test_problem_in_scene_keeps_the_context_only_where_obstacles_alone_differ():
    """Obstacles do not enter a context: a problem moved to a scene that differs only in them
    keeps its context (the same object); one that differs in anything else gets the context
    ``replace`` builds."""
    from solver.problem import Problem, pack
    from solver.settings import DEFAULT_SETTINGS

    scene = solver.Scene(payload_kg=0.1, self_contact=1e5)
    packed = pack(ARM, "full", DEFAULT_SETTINGS)
    problem = Problem(ARM, packed, scene, "full", True, DEFAULT_SETTINGS, np.zeros(6),
                      np.zeros(ARM.n_channels))
    moved = problem.in_scene(scene.with_obstacles((solver.Disc((-0.3, -0.2), 0.1),)))
    assert moved.ctx is problem.ctx and moved.scene.obstacles and moved.warm_start is None
    assert problem.in_scene(replace(scene, obstacles=(solver.Disc((0.3, -0.2), 0.1),))).ctx is problem.ctx
    heavier = problem.in_scene(replace(scene, payload_kg=0.2))
    rebuilt = replace(problem, scene=replace(scene, payload_kg=0.2))
    assert heavier.ctx is not problem.ctx
    np.testing.assert_array_equal(heavier.ctx.loads, rebuilt.ctx.loads)
    assert not np.array_equal(heavier.ctx.loads, problem.ctx.loads)


def test_bad_model_arm_scene_and_mode():
    with pytest.raises(ValueError, match="unknown model"):
        solver.solve(ARM, np.zeros(6), model="pcc")
    with pytest.raises(ValueError, match="ArmDesign"):
        solver.solve("octarm_v", np.zeros(6))
    with pytest.raises(ValueError, match="Scene"):
        solver.solve(ARM, np.zeros(6), scene={"base_angle_deg": 0})
    with pytest.raises(ValueError, match="out-of-plane"):
        solver.solve(ARM, np.zeros(6), solver.Scene(tip_force=(0, 0, 1.0)))
    with pytest.raises(ValueError, match="steps_per_section"):
        solver.Settings(steps_per_section=0)


def test_bad_warm_start():
    eq = solver.solve(ARM, np.zeros(6), solver.Scene(base_angle_deg=30))
    with pytest.raises(ValueError, match="base angle"):
        solver.solve(ARM, np.zeros(6), solver.Scene(base_angle_deg=60), warm_start=eq)
    with pytest.raises(ValueError, match="planar 'full' solve, not a planar 'unshearable'"):
        solver.solve(ARM, np.zeros(6), solver.Scene(base_angle_deg=30), model="unshearable",
                     warm_start=eq)
    with pytest.raises(ValueError, match="Equilibrium"):
        solver.solve(ARM, np.zeros(6), warm_start={"tip": [0, 0]})


def test_warm_start_from_another_arm_or_scene_is_refused():
    """Same channel count, another design (or a variant of this one): refused by name. A
    scene may differ in its loads (they are ramped), not in an obstacle across the arm."""
    scene = solver.Scene(base_angle_deg=90)
    eq = solver.solve(ARM, np.zeros(6), scene)
    for other in (designs.octarm_vi(), designs.octarm_v(endplate_mass=0.1)):
        with pytest.raises(ValueError, match="solved for design 'octarm_v?i?', not for this"):
            solver.solve(other, np.zeros(6), scene, warm_start=eq)
    with pytest.raises(ValueError, match="which arm and scene"):
        solver.solve(ARM, np.zeros(6), scene, warm_start=replace(eq, scene=None))
    across = solver.Disc(center=tuple(eq.positions[20]), radius=0.05)
    with pytest.raises(ValueError, match="inside obstacle 0"):
        solver.solve(ARM, np.zeros(6), replace(scene, obstacles=(across,)), warm_start=eq)
    clear = solver.Disc(center=(0.4, 0.3), radius=0.05)
    heavier = replace(scene, payload_kg=0.3, obstacles=(clear,))
    assert solver.solve(ARM, np.zeros(6), heavier, warm_start=eq).converged
    stepper = solver.Stepper(designs.octarm_vi(), scene)
    with pytest.raises(ValueError, match="solved for design 'octarm_v'"):
        stepper.reset(np.zeros(6), warm_start=eq)


def test_step_batch_state_from_another_arm_or_scene_is_refused():
    scene = solver.Scene(base_angle_deg=90)
    state = solver.step_batch(ARM, np.zeros((2, 6)), scene)
    with pytest.raises(ValueError, match="stepped for design 'octarm_v', not for this 'octarm_vi'"):
        solver.step_batch(designs.octarm_vi(), np.zeros((2, 6)), scene, state=state)
    with pytest.raises(ValueError, match="stepped in .* keeps the loads"):
        solver.step_batch(ARM, np.zeros((2, 6)), replace(scene, payload_kg=0.1), state=state)
    with pytest.raises(ValueError, match="BatchState"):
        solver.step_batch(ARM, np.zeros((2, 6)), scene, state=replace(state, arm=None))
    assert solver.step_batch(ARM, np.zeros((2, 6)), scene, state=state).converged.all()


def test_bad_batch():
    with pytest.raises(ValueError, match="shape"):
        solver.solve_batch(ARM, np.zeros(6))
    with pytest.raises(ValueError, match="negative"):
        solver.solve_batch(ARM, np.array([[0, 0, 0, 0, 0, 0], [0, -1, 0, 0, 0, 0.0]]))


def test_solver_never_imports_gymnasium():
    """One-way dependencies: solver/ uses numpy, scipy and numba only."""
    code = ("import sys, solver; solver.solve(solver.designs.octarm_v(), [0]*6); "
            "bad = [m for m in sys.modules if m.split('.')[0] in "
            "('gymnasium', 'softarm_gym', 'torch', 'stable_baselines3', 'matplotlib')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_unconverged_solves_stay_finite_and_consistent():
    """Regressions found by softarm stress: an upright heavy payload past buckling and a long
    weak arm pushed up by a tip force. Unconverged results are flagged, finite, and the
    recorded shape is the same state as the tip-only result."""
    cases = [
        (designs.octarm_vi(), np.array([4.525037, 7.937383, 6.787301, 8.219912, 3.025237,
                                        3.838539]) * PSI,
         solver.Scene(base_angle_deg=180, payload_kg=0.8398565455056872), "unshearable"),
        (designs.pneumatic((12, 6), (0.4754809471605518, 1.7745190528341515), 0.01198887518679231,
                           outer_radius=0.02081747048440628),
         np.array([0, 0.14e6, 0, 0.14e6]), solver.Scene(base_angle_deg=90, tip_force=(0, 100.178)),
         "full"),
    ]
    for arm, p, scene, model in cases:
        eq = solver.solve(arm, p, scene, model=model)
        tip = solver.solve(arm, p, scene, model=model, record=False).tip
        assert np.all(np.isfinite(eq.positions)) and np.all(np.isfinite(tip))
        np.testing.assert_allclose(eq.tip, tip, atol=1e-12)
        if not eq.converged:
            assert eq.residual > 0


@pytest.mark.parametrize("failure", ["raise", "nan"])
def test_no_exception_and_no_nan_escapes_a_solve(monkeypatch, failure):
    """A kernel that fails outright (issue #19: LinAlgError from a singular matrix) or gives a
    NaN state: an unconverged, unstable, finite result (the unloaded shape), SolverError with
    strict=True, and the same from a stepper (which keeps the state)."""
    import importlib

    api = importlib.import_module("solver.paths.dispatch")  # where solve() picks its path

    def breaking(path):
        def broken(*args):
            if failure == "raise":
                raise np.linalg.LinAlgError("Singular matrix")
            eq = path(*args)
            return eq if eq is None else replace(eq, tip=np.full_like(eq.tip, np.nan))
        return broken

    # Both paths to the kernels: the general one and the one-call planar one.
    monkeypatch.setattr(api, "path", breaking(api.path))
    monkeypatch.setattr(api, "solve_lean", breaking(api.solve_lean))
    scene = solver.Scene(base_angle_deg=90, payload_kg=0.2)
    p = np.array([30, 0, 0, 0, 0, 0]) * PSI
    for planar in (True, False):
        pressures = p if planar else np.zeros(9)
        eq = solver.solve(ARM, pressures, scene, planar=planar)
        assert not eq.converged and not eq.stable and eq.residual == np.inf
        assert np.all(np.isfinite(eq.tip)) and np.all(np.isfinite(eq.positions))
        with pytest.raises(solver.SolverError):
            solver.solve(ARM, pressures, scene, planar=planar, strict=True)
    report = solver.Stepper(ARM, scene, planar=False).reset(np.zeros(9))
    assert not report.converged
