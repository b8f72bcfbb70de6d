"""The stepper's lean contact path (:mod:`solver.paths.lean_contact`) and its guarded
contact-free steps, against the friendly API they shortcut.

Oracle: ``solve(arm, p, scene, warm_start=previous)``, which builds the contact layout and
levels anew and follows the quasi-static path by continuation. A step must land on the same
equilibrium to the solver's tolerance on every path the stepper takes — lean contact, guarded
lean, general — and the walks below must take each of them.
"""

import math

import numpy as np
import pytest

import solver
from solver import PSI, designs
from solver import layout as L

K_TUBE = designs.octarm_v().tubes[0].material.ring_stiffness


def curl_walk(arm, n, seed, scale=0.1, drift=0.03):
    """n pressures: a random walk of ``scale``·p_max per input that drifts towards channel
    I of every section (curls the arm one way, onto what lies on that side)."""
    rng = np.random.default_rng(seed)
    k = arm.n_inputs(True)
    toward = np.zeros(k)
    toward[::2] = drift
    p = [np.zeros(k)]
    for _ in range(n - 1):
        step = rng.uniform(-scale, scale, k) + toward
        p.append(np.clip(p[-1] + step * arm.max_pressure, 0.0, arm.max_pressure))
    return p


def assert_lands_on(stepper, ref):
    """The stepper's state is ``ref`` (a warm solve()'s) to the solver's tolerance; returns
    the stepper's equilibrium."""
    got = stepper.equilibrium
    np.testing.assert_allclose(stepper.tip, ref.tip, atol=1e-9)
    np.testing.assert_allclose(got.positions, ref.positions, atol=1e-9)
    np.testing.assert_allclose(got.penetration, ref.penetration, atol=1e-10)
    np.testing.assert_allclose(got.contact_force, ref.contact_force, atol=1e-5)
    assert (got.in_contact, got.stable) == (ref.in_contact, ref.stable)
    return got


# (base angle, scene arguments, walk step, walk drift)
SCENES = {
    # The hanging arm curling onto a disc beside it (the wrap task's geometry).
    "wrap": (0.0, dict(obstacles=(solver.Disc((0.16, -0.55), 0.13, K_TUBE),)), 0.1, 0.03),
    # A horizontal arm bending onto two discs (obstacle reach), one of a stiffer penalty.
    "obstacles": (90.0, dict(obstacles=(solver.Disc((0.2, -0.45), 0.07, 1e6),
                                        solver.Disc((0.45, -0.75), 0.05, K_TUBE))), 0.1, 0.03),
    # Curled onto itself (self-contact, the full Jacobian of touching parts), past a disc.
    "self": (13.44, dict(obstacles=(solver.Disc((0.1, -0.3), 0.04, K_TUBE),),
                         self_contact=K_TUBE), 0.05, 0.05),
}


def contact_level(contact, k):
    """Copy k's level tuple (``layout.L_*``) from the contact tuple of a
    :class:`solver.paths.lean_contact.ContactRows` (its arrays, not copies)."""
    from solver.kernels import stepping

    return (contact[stepping.CT_P][k], contact[stepping.CT_Q], contact[stepping.CT_PLATE],
            contact[stepping.CT_TARGET], contact[stepping.CT_DISCS][k], contact[stepping.CT_MU][k],
            contact[stepping.CT_FRICTION][k], contact[stepping.CT_SELF_FRICTION][k])


def walked_stepper(name, steps):
    """(arm, scene, stepper): a stepper in ``SCENES[name]`` after the first ``steps``
    pressures of its curl walk (seed 7)."""
    base, kwargs, scale, drift = SCENES[name]
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=base, **kwargs)
    stepper = solver.Stepper(arm, scene)
    walk = curl_walk(arm, steps, seed=7, scale=scale, drift=drift)
    stepper.reset(walk[0])
    for p in walk[1:]:
        stepper.step(p)
    return arm, scene, stepper


@pytest.mark.parametrize("name", list(SCENES))
def test_contact_steps_equal_warm_solves(name):
    base, kwargs, scale, drift = SCENES[name]
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=base, **kwargs)
    stepper = solver.Stepper(arm, scene)
    assert stepper.lean and stepper.lean_contact
    pressures = curl_walk(arm, 45, seed=7, scale=scale, drift=drift)
    stepper.reset(pressures[0])
    eq = stepper.equilibrium
    paths = []
    for p in pressures[1:]:
        report = stepper.step(p)
        paths.append(stepper.last_path)
        ref = solver.solve(arm, p, scene, warm_start=eq)
        assert report.converged == ref.converged
        if not report.converged:
            continue
        got = assert_lands_on(stepper, ref)
        np.testing.assert_array_equal(stepper.record[:, L.C_X:L.C_Y + 1], got.positions)
        eq = got
    assert {"lean", "lean contact"} <= set(paths), paths


@pytest.mark.parametrize("name", ["wrap", "obstacles"])
def test_large_jumps_in_contact_take_the_lean_continuation_and_equal_warm_solves(name):
    """Random absolute pressures, as an env's random actions give them: jumps across much of
    the pressure range from states in contact. The lean step follows them as a short
    continuation (sub-steps predicted from the stored factors) and every step lands where
    solve() from the previous equilibrium lands."""
    arm, scene, stepper = walked_stepper(name, 30)
    rng = np.random.default_rng(11)
    eq = stepper.equilibrium
    jumps = []  # the largest channel change (× p_max) of lean contact steps from contact
    for _ in range(30):
        p = rng.uniform(0.0, 1.0, arm.n_inputs(True)) * arm.max_pressure
        touching = eq.in_contact
        jump = np.max(np.abs(p - stepper.pressures)) / arm.max_pressure
        report = stepper.step(p)
        ref = solver.solve(arm, p, scene, warm_start=eq)
        assert report.converged == ref.converged
        if not report.converged:
            continue
        if touching and stepper.last_path == "lean contact":
            jumps.append(jump)
        got = assert_lands_on(stepper, ref)
        eq = got
    assert jumps and max(jumps) > 0.5, jumps


def test_self_touching_steps_keep_the_full_factors_and_equal_warm_solves():
    """An arm curled onto itself (the full Jacobian of touching parts, a residual pass per
    column of a node in contact), then small steps as an env's delta actions give them: the
    lean steps keep the full factors of the state before where Broyden's corrections alone
    converge (``full_factor_age`` > 1), and every step still lands where solve() from the
    previous equilibrium lands."""
    arm, scene, stepper = walked_stepper("self", 45)
    assert stepper.full_factor_age >= 1  # curled onto itself: full factors
    rng = np.random.default_rng(5)
    eq = stepper.equilibrium
    ages = []
    for _ in range(12):
        p = np.clip(stepper.pressures + rng.uniform(-0.02, 0.02, arm.n_inputs(True)) * arm.max_pressure,
                    0.0, arm.max_pressure)
        report = stepper.step(p)
        ref = solver.solve(arm, p, scene, warm_start=eq)
        assert report.converged == ref.converged
        if not report.converged:
            continue
        ages.append((stepper.last_path, stepper.full_factor_age))
        eq = assert_lands_on(stepper, ref)
    assert any(path == "lean contact" and age > 1 for path, age in ages), ages


@pytest.mark.parametrize("name", ["wrap", "obstacles"])
def test_a_lean_contact_step_keeps_the_record_and_band_factors_of_the_state_it_reached(name):
    """After every lean contact step from contact — random absolute jumps, where Broyden's
    corrections mostly fail and damped Newton converges the tries — the copy's record and
    band LU factors are those of its state, bit for bit: what
    :func:`solver.kernels.contact.factor_state` makes of the copy's nodes at its level. (The
    acceptance takes them from Newton's last pass where Newton converged; they must not be a
    nearby iterate's.)"""
    from solver.inputs import checked_pressures
    from solver.kernels import contact as contact_kernels
    from solver.kernels import stepping
    from solver.paths.lean_contact import ContactRows
    from solver.problem import Problem, pack
    from solver.rod import rest_strains_into

    arm, scene, stepper = walked_stepper(name, 30)
    settings = solver.Settings()
    packed = pack(arm, "full", settings)
    rows = ContactRows(Problem(arm, packed, scene, "full", True, settings,
                               np.zeros(arm.n_inputs(True)), np.zeros(arm.n_channels)), 1,
                       len(scene.obstacles))
    rows.adopt(0, stepper.equilibrium)
    contact = rows.contact
    grid = tuple(contact[i] for i in range(stepping.CT_THETA0, stepping.CT_SELF + 1))
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(30):
        touching = bool(contact[stepping.CT_OK][0] and contact[stepping.CT_TOUCHING][0])
        p_inputs = rng.uniform(0.0, 1.0, arm.n_inputs(True)) * arm.max_pressure
        p_channel = checked_pressures(arm, p_inputs, True, packed)[1]
        if not contact[stepping.CT_OK][0]:  # off the contact layout: hand the copy a solved state
            rows.adopt(0, solver.solve(arm, p_inputs, scene))
            continue
        p_from = contact[stepping.CT_P][:1].copy()
        report = rows.step(p_from, p_channel[None], np.ones(1, dtype=bool), None)[0]
        if not report[0]:  # the general path's step: walk on from a solved state
            rows.adopt(0, solver.solve(arm, p_inputs, scene))
            continue
        if not (touching and report[5] == stepping.PATH_CONTACT):
            continue
        level = contact_level(contact, 0)  # (frictionless scenes: no samples to record into)
        rest = np.empty_like(contact[stepping.CT_REST][0])
        rest_strains_into(level[L.L_P], packed.tubes_i, packed.tubes_f, packed.secf, rest)
        nodes = contact[stepping.CT_NODES][0].copy()
        record = np.empty_like(contact[stepping.CT_RECORDS][0])
        factors = contact_kernels.new_factors(nodes.size, False)
        blocks = np.empty((contact[stepping.CT_SEGS].shape[0], 6, 6))
        assert contact_kernels.factor_state(nodes, grid, rest, level, contact[stepping.CT_WEIGHTS],
                                            np.empty_like(nodes), blocks, record, factors)
        np.testing.assert_array_equal(contact[stepping.CT_RECORDS][0], record)
        np.testing.assert_array_equal(contact[stepping.CT_LU][0], factors[0])
        np.testing.assert_array_equal(contact[stepping.CT_PIV][0], factors[1])
        checked += 1
    assert checked >= 5, checked


def test_contact_record_columns_are_the_planar_record_columns():
    """What reads a planar record's backbone (the envs' true observations) reads a contact
    record's: the columns s … u share their places."""
    assert (L.C_S, L.C_X, L.C_Y, L.C_TH, L.C_M, L.C_NX, L.C_NY, L.C_V1, L.C_V3, L.C_U) == (
        L.S, L.X, L.Y, L.THETA, L.M, L.NX, L.NY, L.V1, L.V3, L.U)


def test_a_failed_lean_contact_step_leaves_the_state_and_the_general_path_takes_it():
    """A jump across the pressure range from a state in contact that snaps (the arm curls
    through a fold, which the lean continuation's stability test refuses): the general path
    takes it from the same state, as solve() does."""
    arm = designs.octarm_v()
    base, kwargs, _, _ = SCENES["wrap"]
    scene = solver.Scene(base_angle_deg=base, **kwargs)
    stepper = solver.Stepper(arm, scene)
    pressures = curl_walk(arm, 30, seed=7)
    stepper.reset(pressures[0])
    for p in pressures[1:]:
        stepper.step(p)
    assert stepper.last_path == "lean contact"
    start = stepper.equilibrium
    jump = np.array([100, 0, 100, 0, 100, 0]) * PSI
    report = stepper.step(jump)
    assert stepper.last_path == "general"
    # The lean continuation halved its way to the fold and spent its budget there.
    assert {"not converged", "budget spent"} <= set(stepper.last_refusals), stepper.last_refusals
    ref = solver.solve(arm, jump, scene, warm_start=start)
    assert ref.snapped
    assert report.converged == ref.converged
    np.testing.assert_allclose(stepper.tip, ref.tip, atol=1e-9)


def test_a_pickled_contact_stepper_steps_as_the_original():
    """Pickling keeps the lean contact state: the copy's next steps are the original's."""
    import pickle

    base, kwargs, scale, drift = SCENES["wrap"]
    arm = designs.octarm_v()
    stepper = solver.Stepper(arm, solver.Scene(base_angle_deg=base, **kwargs))
    pressures = curl_walk(arm, 45, seed=7, scale=scale, drift=drift)
    stepper.reset(pressures[0])
    k = 1
    while stepper.last_path != "lean contact":
        stepper.step(pressures[k])
        k += 1
    copy = pickle.loads(pickle.dumps(stepper))
    np.testing.assert_array_equal(copy.tip, stepper.tip)
    for p in pressures[k:]:
        a, b = stepper.step(p), copy.step(p)
        assert a == b and copy.last_path == stepper.last_path
        np.testing.assert_array_equal(copy.tip, stepper.tip)
        np.testing.assert_array_equal(copy.record, stepper.record)


@pytest.mark.parametrize("name", list(SCENES))
def test_the_same_pressures_again_hold_the_state_a_warm_solve_returns(name):
    # A hold runs no kernel ("held"): the state must be the one a warm solve from it at the
    # same pressures lands on, and stay the same arrays; a step elsewhere then goes on as usual.
    arm, scene, stepper = walked_stepper(name, 30)
    before = stepper.equilibrium
    tip = stepper.tip.copy()
    report = stepper.step(stepper.pressures.copy())
    assert stepper.last_path == "held" and report.converged and report.iterations == 0
    assert report.stable == before.stable and not report.snapped
    np.testing.assert_array_equal(stepper.tip, tip)
    assert stepper.equilibrium is before
    assert_lands_on(stepper, solver.solve(arm, before.pressures, scene, warm_start=before))
    moved = np.clip(stepper.pressures + 0.02 * arm.max_pressure, 0.0, arm.max_pressure)
    stepper.step(moved)
    assert stepper.last_path != "held"
    assert_lands_on(stepper, solver.solve(arm, moved, scene, warm_start=before))


def test_a_batch_holds_the_copies_whose_pressures_stay_and_steps_the_others():
    arm, scene, single = walked_stepper("wrap", 20)
    batch = solver.BatchStepper(arm, scene, 2)
    batch.adopt(single.equilibrium)
    tips = batch.tips.copy()
    moved = np.clip(single.pressures + 0.05 * arm.max_pressure, 0.0, arm.max_pressure)
    report = batch.step(np.stack([single.pressures, moved]))
    assert report.converged.all() and report.iterations[0] == 0 and report.iterations[1] > 0
    np.testing.assert_array_equal(batch.tips[0], tips[0])
    single.step(moved)
    np.testing.assert_allclose(batch.tips[1], single.tip, atol=1e-12)


@pytest.mark.parametrize("reach", [0.5, 0.95, 1.05, 2.0])
def test_newton_gives_up_behind_a_fence_its_root_lies_beyond(reach):
    """The planar contact Newton under a fence (the paths' branch-jump bound round their
    prediction) gives up once an iterate lies beyond it by more than twice its Newton step
    (``FENCE_STEPS``), there already beyond the fence, where its root lies too. The wrap
    scene's arm pressed on its disc, every channel's pressure doubled (plus a tenth of p_max)
    in one solve, fenced round the start at ``reach`` times the root's distance: a fence short
    of the root stops Newton before it converges; one past it changes no iterate."""
    from solver.kernels import contact as contact_kernels
    from solver.kernels import stepping
    from solver.rod import rest_strains_into

    arm, _, stepper = walked_stepper("wrap", 30)
    contact, layout = stepper._rows.contact, stepper._rows.layout
    assert contact[stepping.CT_OK][0] and contact[stepping.CT_TOUCHING][0]
    grid = tuple(contact[i] for i in range(stepping.CT_THETA0, stepping.CT_SELF + 1))
    level = tuple(np.array(x, copy=True) for x in contact_level(contact, 0))
    level[L.L_P][:] = np.minimum(2.0 * level[L.L_P] + 0.1 * arm.max_pressure, arm.max_pressure)
    rest = np.empty_like(contact[stepping.CT_REST][0])
    rest_strains_into(level[L.L_P], layout.tubes_i, layout.tubes_f, layout.secf, rest)
    start = contact[stepping.CT_NODES][0].copy()
    weights, params = contact[stepping.CT_WEIGHTS], contact[stepping.CT_PARAMS]

    def newton(fence):
        nodes = start.copy()
        ok, its, *_ = contact_kernels.damped_newton(
            nodes, grid, rest, level, weights, contact[stepping.CT_RES_WEIGHTS], params[L.TOL],
            40, params[L.MAX_STEP], True, np.zeros(1, dtype=np.int64),
            contact_kernels.newton_work(nodes.size, grid), start, fence)
        return nodes, ok, its, np.sqrt(np.mean(((nodes - start) / weights) ** 2))

    root, ok, its, distance = newton(math.inf)
    assert ok and its >= 4
    fenced, fenced_ok, fenced_its, where = newton(reach * distance)
    if reach < 1.0:
        assert not fenced_ok and fenced_its < its and where > reach * distance
    else:
        assert fenced_ok and fenced_its == its and np.array_equal(fenced, root)
