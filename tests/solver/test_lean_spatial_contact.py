"""The 3D stepper's lean contact path (:mod:`solver.paths.lean_spatial_contact`: cylinders
and spheres) and its guarded contact-free steps, against the friendly API they shortcut.

Oracle: ``solve(arm, p, scene, planar=False, warm_start=previous)``, which builds the
contact layout and levels anew and follows the quasi-static path by continuation with a
Jacobian of forward differences at every Newton iteration. A step must land on the same
equilibrium to the solver's tolerance on every path the stepper takes — lean contact, lean
contact-free, general — and the walks below must take the lean ones.
"""

import pickle

import numpy as np
import pytest

import solver
from solver import designs

K_TUBE = designs.octarm_v().tubes[0].material.ring_stiffness


def curl_walk_3d(arm, n, seed, scale=0.1, drift=0.03):
    """n channel pressures (the ``planar=False`` inputs): a random walk of ``scale``·p_max
    per channel that drifts towards the channels of planar channel I of every section (the
    hanging arm curls towards −x, onto what lies on that side) and wanders out of the plane."""
    rng = np.random.default_rng(seed)
    k = arm.n_inputs(False)
    planar = np.zeros(arm.n_inputs(True))
    planar[::2] = drift
    toward = solver.channel_pressures(arm, planar)
    p = [np.zeros(k)]
    for _ in range(n - 1):
        step = rng.uniform(-scale, scale, k) + toward
        p.append(np.clip(p[-1] + step * arm.max_pressure, 0.0, arm.max_pressure))
    return p


# (design, base angle, obstacles, walk step, walk drift)
SCENES = {
    # The hanging arm curling onto a cylinder beside it, its axis out of the plane (3D wrap).
    "cylinder": ("octarm_v", 0.0,
                 (solver.Cylinder((-0.4, -0.7, 0.1), (0.0, 0.3, 1.0), 0.13, K_TUBE),), 0.1, 0.03),
    # Onto a sphere off the plane.
    "sphere": ("octarm_v", 0.0, (solver.Sphere((-0.4, -0.7, 0.1), 0.13, K_TUBE),), 0.1, 0.03),
    # CT horizontal, bending up onto a stiff sphere, past a skew cylinder it never reaches.
    "two": ("ct", 90.0, (solver.Sphere((0.45, -0.12, 0.28), 0.1, 1e6),
                         solver.Cylinder((0.2, -0.4, 0.0), (1.0, 0.2, 1.0), 0.08, K_TUBE)),
            0.1, 0.03),
}


def _stepper(name):
    design, base, obstacles, scale, drift = SCENES[name]
    arm = getattr(designs, design)()
    scene = solver.Scene(base_angle_deg=base, obstacles=obstacles)
    return arm, scene, solver.Stepper(arm, scene, planar=False), scale, drift


@pytest.mark.parametrize("name", list(SCENES))
def test_3d_contact_steps_equal_warm_solves(name):
    arm, scene, stepper, scale, drift = _stepper(name)
    assert stepper.lean and stepper.lean_contact
    pressures = curl_walk_3d(arm, 40, seed=7, scale=scale, drift=drift)
    stepper.reset(pressures[0])
    eq = stepper.equilibrium
    paths = []
    for p in pressures[1:]:
        report = stepper.step(p)
        paths.append(stepper.last_path)
        ref = solver.solve(arm, p, scene, planar=False, warm_start=eq)
        assert report.converged == ref.converged
        if not report.converged:
            continue
        got = stepper.equilibrium
        np.testing.assert_allclose(stepper.tip, ref.tip, atol=1e-9)
        np.testing.assert_allclose(got.positions, ref.positions, atol=1e-9)
        np.testing.assert_allclose(got.penetration, ref.penetration, atol=1e-10)
        np.testing.assert_allclose(got.contact_force, ref.contact_force, atol=1e-5)
        assert (got.in_contact, got.stable) == (ref.in_contact, ref.stable)
        np.testing.assert_array_equal(stepper.tip, got.tip)
        eq = got
    assert "lean contact" in paths, paths


def _walk_into_contact(name, n=40):
    """A stepper of ``SCENES[name]`` walked until a lean contact step, and the rest of the
    walk."""
    arm, scene, stepper, scale, drift = _stepper(name)
    pressures = curl_walk_3d(arm, n, seed=7, scale=scale, drift=drift)
    stepper.reset(pressures[0])
    k = 1
    while stepper.last_path != "lean contact":
        stepper.step(pressures[k])
        k += 1
    return arm, scene, stepper, pressures[k:]


def test_a_failed_lean_3d_contact_step_leaves_the_state_and_the_general_path_takes_it():
    """A jump across the pressure range from a state in contact, which the lean step cannot
    follow within its budget (every channel I to p_max; channels II or III alone it follows,
    to solve()'s state): the general path takes it from the same state, as solve() does, and
    the state is the one solve() returns."""
    arm, scene, stepper, _ = _walk_into_contact("cylinder")
    start = stepper.equilibrium
    jump = np.zeros(arm.n_inputs(False))
    jump[0::3] = arm.max_pressure
    report = stepper.step(jump)
    assert stepper.last_path == "general"
    ref = solver.solve(arm, jump, scene, planar=False, warm_start=start)
    assert report.converged == ref.converged
    np.testing.assert_array_equal(stepper.tip, ref.tip if ref.converged else start.tip)
    np.testing.assert_array_equal(stepper.equilibrium.positions,
                                  (ref if ref.converged else start).positions)


def test_a_pickled_3d_contact_stepper_steps_as_the_original():
    """Pickling keeps the lean 3D contact state: the copy's next steps are the original's."""
    _, _, stepper, rest = _walk_into_contact("cylinder")
    copy = pickle.loads(pickle.dumps(stepper))
    np.testing.assert_array_equal(copy.tip, stepper.tip)
    for p in rest[:10]:
        a, b = stepper.step(p), copy.step(p)
        assert a == b and copy.last_path == stepper.last_path
        np.testing.assert_array_equal(copy.tip, stepper.tip)
        np.testing.assert_array_equal(copy.equilibrium.positions, stepper.equilibrium.positions)


def test_pass_costs_of_a_3d_contact_state():
    """The profile's pass costs of a state on the contact layout, and a clear error off it."""
    _, _, stepper, _ = _walk_into_contact("cylinder")
    costs = stepper.pass_costs(repeats=3)
    assert costs["residual_pass_s"] > 0 and costs["jacobian_pass_s"] > costs["residual_pass_s"]
    assert costs["unknowns"] % 12 == 6 and 0.0 < costs["refined_fraction"] <= 1.0
    free = solver.Stepper(designs.octarm_v(), solver.Scene(), planar=False)
    with pytest.raises(ValueError, match="lean contact path"):
        free.pass_costs()


def test_3d_same_pressures_again_hold_the_state_a_warm_solve_returns():
    arm, scene, stepper, scale, drift = _stepper("cylinder")
    pressures = curl_walk_3d(arm, 25, seed=7, scale=scale, drift=drift)
    stepper.reset(pressures[0])
    for p in pressures[1:]:
        stepper.step(p)
    before = stepper.equilibrium
    assert before.in_contact
    tip = stepper.tip.copy()
    report = stepper.step(stepper.pressures.copy())
    assert stepper.last_path == "held" and report.converged and report.iterations == 0
    np.testing.assert_array_equal(stepper.tip, tip)
    ref = solver.solve(arm, before.channel_pressures, scene, planar=False, warm_start=before)
    np.testing.assert_allclose(stepper.equilibrium.positions, ref.positions, atol=1e-9)
