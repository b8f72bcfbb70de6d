"""Spatial contact: cylinders, spheres and discs in 3D (solver.kernels.spatial_contact)."""

import math
import pickle
import types
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401  (registers the ids)
import solver
from solver import designs
from solver.kernels import spatial_contact
from solver.paths import spatial_contact as spatial_paths
from tests.solver.naive import solve_bvp_rod_on_obstacle


def _in_plane_scenes():
    """OctArm V curled with channel I into an obstacle in its plane: (pressure fraction,
    scene) pairs, hanging and horizontal, whose in-plane equilibrium is stable in 3D too
    (pressed harder, an arm slides off sideways: see
    :func:`test_an_arm_pressed_on_an_obstacle_in_its_plane_slides_out_of_it`)."""
    stiffness = 2e5
    return [
        (0.6, solver.Scene(obstacles=(solver.Disc((-0.144, -0.139), 0.102, stiffness),))),
        (1.0, solver.Scene(obstacles=(solver.Disc((-0.144, -0.139), 0.102, stiffness),))),
        (0.6, solver.Scene(obstacles=(solver.Sphere((-0.144, -0.139, 0.0), 0.102, stiffness),))),
        (0.8, solver.Scene(base_angle_deg=90, payload_kg=0.2,
                           obstacles=(solver.Cylinder((0.5, 0.2, 0.3), (0, 0, -2), 0.1, 1e5),))),
    ]


@pytest.mark.parametrize("fraction, scene", _in_plane_scenes())
def test_in_plane_contact_in_3d_matches_the_planar_contact_solve(fraction, scene):
    """An obstacle whose x–y section is a disc the planar arm meets in its plane (a disc, a
    cylinder along z, a sphere centred in the plane), all loads in-plane: the spatial
    contact solve is the planar one embedded, to 1e-6·L, with the same flags and contact."""
    arm = designs.octarm_v()
    p = np.zeros(6)
    p[0] = fraction * arm.max_pressure
    o = scene.obstacles[0]
    centre = o.center[:2] if not isinstance(o, solver.Cylinder) else o.point[:2]
    planar_scene = solver.Scene(base_angle_deg=scene.base_angle_deg, payload_kg=scene.payload_kg,
                                obstacles=(solver.Disc(centre, o.radius, o.stiffness),))
    flat = solver.solve(arm, p, planar_scene)
    eq = solver.solve(arm, solver.channel_pressures(arm, p), scene, planar=False)
    assert flat.converged and eq.converged
    assert (eq.stable, eq.in_contact) == (flat.stable, flat.in_contact)
    assert np.linalg.norm(eq.tip - np.append(flat.tip, 0.0)) <= 1e-6 * arm.length
    assert np.abs(eq.positions[:, 2]).max() <= 1e-9 * arm.length
    assert eq.penetration.max() == pytest.approx(flat.penetration.max(), rel=1e-4, abs=1e-9)


@pytest.mark.parametrize("obstacle", [
    solver.Sphere((0.7, -0.3, 0.12), 0.2, 2e3),
    solver.Cylinder((0.6, -0.3, 0.0), (1.0, 0.3, 1.0), 0.15, 2e3),
])
def test_rod_pressed_on_a_sphere_or_cylinder_matches_an_independent_bvp(obstacle):
    """A passive rod, held horizontal, pushed down and sideways by a tip force onto a sphere
    off its plane or a skew cylinder: the tip against scipy's ``solve_bvp`` of the same
    equations written with directors as vectors (tests/solver/naive.py) — 1e-4·L at the
    default resolution, 1e-6·L at 256 RK4 steps."""
    rod = designs.rod(length=1.0, EI=1.0, EA=1e3, GA=1e3, GJ=0.7)
    scene = solver.Scene(base_angle_deg=90, gravity=0.0, tip_force=(0.0, -3.0, 0.5),
                         obstacles=(obstacle,))
    eq = solver.solve(rod, [], scene, planar=False)
    fine = solver.solve(rod, [], scene, planar=False, settings=solver.Settings(steps_per_section=256))
    assert eq.converged and eq.stable and eq.in_contact and fine.converged
    reference = solve_bvp_rod_on_obstacle(rod, scene, obstacle, fine)
    assert np.linalg.norm(fine.tip - reference) <= 1e-6 * rod.length
    assert np.linalg.norm(eq.tip - reference) <= 1e-4 * rod.length


@pytest.mark.parametrize("obstacle, out_of_plane_at", [
    (solver.Disc((-0.2, -0.55), 0.12, 1e5), 0.7),
    (solver.Sphere((-0.2, -0.55, 0.0), 0.12, 1e5), 0.45),
])
def test_an_arm_pressed_on_an_obstacle_in_its_plane_slides_out_of_it(obstacle, out_of_plane_at):
    """Curled harder into a cylinder along z (free to slide along it) or a sphere (whose
    normal turns as the arm moves sideways), the in-plane state loses stability in 3D. A
    real arm is never perfect: with a 1e-3 imperfection (channel II) the quasi-static ramp
    leaves the plane by more than a tenth of the arm. The perfect solve must not return the
    unstable in-plane state: it snaps (a gentle pitchfork for the cylinder, a jump for the
    sphere) onto the +z mirror image of the imperfect state, to the imperfection's size."""
    arm = designs.octarm_v()
    scene = solver.Scene(obstacles=(obstacle,))
    stepper = solver.Stepper(arm, scene, planar=False)
    stepper.reset(np.zeros(9))
    for frac in np.linspace(0.05, out_of_plane_at, int(round(out_of_plane_at / 0.05))):
        p = np.zeros(9)
        p[0], p[1] = frac * arm.max_pressure, 1e-3 * frac * arm.max_pressure
        assert stepper.step(p).converged
    imperfect = stepper.equilibrium.positions
    assert np.abs(imperfect[:, 2]).max() > 0.1 * arm.length
    perfect = np.zeros(9)
    perfect[0] = out_of_plane_at * arm.max_pressure
    eq = solver.solve(arm, perfect, scene, planar=False)
    assert eq.converged and eq.stable and eq.snapped
    assert eq.positions[np.argmax(np.abs(eq.positions[:, 2])), 2] > 0.1 * arm.length
    mirror = min(np.abs(eq.positions - imperfect).max(),
                 np.abs(eq.positions * [1, 1, -1] - imperfect).max())
    assert mirror < 1e-3 * arm.length


@pytest.mark.parametrize("model, base, payload, obstacle", [
    # A horizontal arm loaded onto a stiff sphere under it: it slides off (and hangs free).
    ("unshearable", 95.07653166320691, 0.049426809813120684,
     solver.Sphere((0.36776906641306, -0.11554974440963495, 0.0), 0.10737251379050622, 511173.8)),
    # A stiff skew cylinder pressed by a curl, which slides along it past a fold.
    ("unshearable", 10.699935900401458, 0.26209498971417583,
     solver.Cylinder((0.10460203587953945, -0.5475680762119925, 0.0),
                     (0.28131600500456516, 0.3821969774030357, 0.8802197315399463),
                     0.060812627916281614, 324467.14)),
])
def test_snaps_against_an_obstacle_land_on_a_stable_state(model, base, payload, obstacle):
    """Two wrap_press cases of ``softarm stress`` (seed 0) that used to stop at a fold: a
    snap where a small push along the critical mode lands on another fold, and one it does
    not help at all. The proximal relaxation (springs tying the arm to where it is,
    slackened as it settles) finds where the arm comes to rest; every step of the ramp of
    the curling channels II+III converges, stable, without penetrating beyond 5 mm."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=base, payload_kg=payload, obstacles=(obstacle,))
    eq, snapped = None, False
    for k in range(8):
        p = np.array([0, 1, 1, 0, 1, 1, 0, 1, 1.0]) * arm.max_pressure * k / 7
        eq = solver.solve(arm, p, scene, model=model, planar=False, warm_start=eq)
        assert eq.converged and eq.stable, k
        assert eq.penetration.max() < 5e-3
        snapped |= eq.snapped
    assert snapped


def _pressed_on(arm, p, where, axis, radius=0.08, depth=0.02, stiffness=1e5):
    """A cylinder of ``radius`` along ``axis`` that overlaps the free backbone at pressures
    ``p`` by ``depth`` at the fraction ``where`` of its samples."""
    free = solver.solve(arm, p, solver.Scene(), planar=False)
    j = int(where * (free.s.size - 1))
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    normal = np.cross(a, free.orientations[j][:, 2])
    normal /= np.linalg.norm(normal)
    return solver.Cylinder(tuple(free.positions[j] + (radius - depth) * normal), tuple(a),
                           radius, stiffness)


def test_contact_is_mirror_symmetric():
    """Mirroring the scene in the x–y plane (a skew cylinder's axis and point, z → −z) and
    swapping channels II and III mirrors the equilibrium."""
    arm = designs.octarm_v()
    p = np.array([0.2, 0.9, 0.1, 0.3, 0.0, 0.6, 0.0, 0.2, 0.0]) * arm.max_pressure
    swap = np.array([0, 2, 1, 3, 5, 4, 6, 8, 7])
    cyl = _pressed_on(arm, p, 0.5, (0.3, 0.2, 1.0))
    mirrored = solver.Cylinder(tuple(np.array(cyl.point) * [1, 1, -1]),
                               tuple(np.array(cyl.axis) * [1, 1, -1]), cyl.radius, cyl.stiffness)
    a = solver.solve(arm, p, solver.Scene(obstacles=(cyl,)), planar=False)
    b = solver.solve(arm, p[swap], solver.Scene(obstacles=(mirrored,)), planar=False)
    assert a.converged and b.converged and a.in_contact
    assert np.abs(a.positions[:, 2]).max() > 0.05  # out of plane: the test is not vacuous
    np.testing.assert_allclose(b.positions * [1, 1, -1], a.positions, atol=1e-9 * arm.length)


@pytest.mark.parametrize("load, stable", [(0.9, True), (1.1, False)])
def test_stability_flags_a_compressed_column_past_eulers_load(load, stable):
    """The straight column under an axial tip load of ``load`` × Euler's π²EI/4L² has a
    double conjugate point (in-plane and out-of-plane at once), whose signs cancel in a
    determinant: the contact kernels' test must still call it unstable past the load."""
    from solver import layout as L
    from solver.kernels import spatial_contact as sc
    from solver.paths.friction import no_samples
    from solver.problem import contact_layout, pack

    rod = designs.rod(length=1.0, EI=1.0, EA=1e8, GA=1e8, GJ=0.7)
    force = load * math.pi ** 2 / 4.0
    scene = solver.Scene(base_angle_deg=180, gravity=0.0, tip_force=(0.0, -force, 0.0),
                         obstacles=(solver.Sphere((0.5, 0.5, 0.0), 0.1, 1e4),))
    packed = pack(rod, "full", solver.Settings())
    layout, segs, sec_start = contact_layout(rod, packed, scene)
    quat0 = np.empty(4)
    solver.rod.rotation_to_quaternion(solver.rod.base_rotation(scene.base_theta), quat0)
    arcs = sec_start[segs[:, L.SEG_SECTION]] + segs[:, L.SEG_FIRST] * (layout.sec_len / layout.sec_steps)[0]
    nodes = np.zeros((segs.shape[0], L.N_CSTATE))
    nodes[:, L.CS_R + 1] = arcs * (1.0 - force / 1e8)
    nodes[:, L.CS_Q:L.CS_Q + 4] = quat0
    nodes[:, L.CS_N + 1] = -force
    grid = (quat0, segs, layout.secf, layout.sec_steps, layout.c_j, sec_start)
    level = (np.zeros(1), np.zeros((1, 3)), np.zeros((1, 3)), np.array([0, -force, 0, 0, 0, 0.0]),
             scene.obstacles_array(), scene.friction_array(), no_samples(1))
    n = sc.n_unknowns(segs.shape[0])
    F, J = np.empty(n), np.empty((n, n))
    blocks = np.empty((segs.shape[0], L.N_CTANGENT, L.N_CTANGENT))
    rest = np.array([[0.0], [0.0], [1.0]])
    assert sc.newton_system(nodes, grid, rest, level, F, J, True, blocks, np.repeat([1.0, 1.0, 3.0, 1.0], 3),
                            sc.NO_TETHER)
    assert np.abs(F).max() < 1e-9  # the straight column is an equilibrium at every load
    assert sc.stability_test(blocks) == stable


@pytest.mark.parametrize("where", [0.6, 0.8])
def test_cold_solve_equals_a_warm_ramp_through_contact(where):
    """A cold solve ramps the pressures from the loaded arm; ten warm steps along the same
    ramp reach the same state (no fold on the way)."""
    arm = designs.octarm_v()
    goal = np.array([0.45, 0.0, 0.15, 0.25, 0.0, 0.0, 0.3, 0.0, 0.1]) * arm.max_pressure
    scene = solver.Scene(obstacles=(_pressed_on(arm, 0.6 * goal, where, (0.2, 0.0, 1.0)),))
    cold = solver.solve(arm, goal, scene, planar=False)
    stepper = solver.Stepper(arm, scene, planar=False)
    stepper.reset(np.zeros(9))
    for t in np.linspace(0.1, 1.0, 10):
        assert stepper.step(t * goal).converged
    assert cold.converged and cold.in_contact and stepper.equilibrium.in_contact
    np.testing.assert_allclose(stepper.tip, cold.tip, atol=1e-6 * arm.length)


def test_out_of_reach_obstacle_takes_the_contact_free_solve():
    arm = designs.octarm_v()
    p = np.array([0.3, 0.0, 0.5, 0.2, 0.1, 0.0, 0.0, 0.4, 0.0]) * arm.max_pressure
    far = solver.solve(arm, p, solver.Scene(obstacles=(solver.Sphere((0, -3.0, 0), 0.5),)),
                       planar=False)
    free = solver.solve(arm, p, solver.Scene(), planar=False)
    assert far.converged and not far.in_contact
    np.testing.assert_array_equal(far.tip, free.tip)
    assert far.contact_force.shape == (far.s.size, 3) and not far.contact_force.any()


def test_a_warm_start_at_another_resolution_loads_one_kernel_signature_whatever_its_arrays():
    """A 3D contact solve from a warm start whose nodes do not fit the contact grid (another
    resolution) takes its nodes from the warm start's record: read-only arrays (a stepper's)
    and writable ones (a solve's) must reach the kernel as the same signature, or the one
    ``softarm warmup`` compiled does not serve the other (a 3D wrap planner's first episode
    compiled a second one). Both solves give the same state."""
    arm = designs.octarm_v()
    cylinder = solver.Cylinder((0.10460203587953945, -0.5475680762119925, 0.0),
                               (0.28131600500456516, 0.3821969774030357, 0.8802197315399463),
                               0.060812627916281614, 324467.14)
    scene = solver.Scene(base_angle_deg=10.7, payload_kg=0.26, obstacles=(cylinder,))
    p = np.array([0, 1, 1, 0, 1, 1, 0, 1, 1.0]) * arm.max_pressure / 7
    warm = solver.solve(arm, np.zeros(9), scene, model="unshearable", planar=False,
                        settings=solver.Settings(steps_per_section=32))

    def read_only(a):
        a = a.copy()
        a.flags.writeable = False
        return a

    frozen = replace(warm, **{name: read_only(getattr(warm, name)) for name in (
        "s", "positions", "orientations", "internal_force", "internal_moment")})
    results = [solver.solve(arm, p, scene, model="unshearable", planar=False, warm_start=start)
               for start in (warm, frozen)]
    assert warm.shooting_nodes.shape != results[0].shooting_nodes.shape  # (the record's branch)
    assert all(eq.converged and eq.in_contact for eq in results)
    np.testing.assert_array_equal(results[0].tip, results[1].tip)
    assert len(spatial_contact.nodes_from_record.signatures) == 1


@pytest.mark.parametrize("make, match", [
    (lambda: solver.Cylinder(axis=(0, 0, 0)), "axis.*nonzero"),
    (lambda: solver.Cylinder(point=(0, np.nan, 0)), "point"),
    (lambda: solver.Sphere(center=(1, 2)), "center"),
    (lambda: solver.Sphere(radius=-1), "radius"),
    (lambda: solver.Cylinder(stiffness=0), "stiffness"),
    (lambda: solver.Scene(obstacles=(solver.Sphere((0, -0.1, 0), 0.2),)), "covers the arm's base"),
    (lambda: solver.Scene(obstacles=(solver.Cylinder((0.1, 0, 0), (0, 1, 0), 0.2),)),
     "covers the arm's base"),
])
def test_bad_spatial_obstacles(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_planar_solve_refuses_cylinders_and_spheres():
    arm = designs.octarm_v()
    scene = solver.Scene(obstacles=(solver.Sphere((0.1, -0.4, 0.0), 0.1),))
    assert not scene.is_planar
    with pytest.raises(ValueError, match="planar=False"):
        solver.solve(arm, np.zeros(6), scene)


@pytest.mark.parametrize("shape", ["cylinder", "sphere"])
def test_shortcut_taken_short_of_an_obstacle_agrees_with_the_contact_solve(shape):
    """A warm 3D step that stops 2 mm short of a cylinder or sphere (an eighth of a sample
    spacing; the chord guard's allowance is under a millimetre here) is the contact-free
    step, in the general path and in the stepper: the full contact solve of the same step
    touches nothing and lands on the same state to the grids' discretisation error."""
    arm = designs.octarm_v()
    p = np.array([0.45, 0.0, 0.15, 0.25, 0.0, 0.0, 0.3, 0.0, 0.1]) * arm.max_pressure
    before = solver.solve(arm, 0.9 * p, solver.Scene(), planar=False)
    free = solver.solve(arm, p, solver.Scene(), planar=False, warm_start=before)
    i = free.s.size // 2
    move = free.positions[i] - before.positions[i]
    ahead = move / np.linalg.norm(move)  # the obstacle ahead of the step's motion
    radius, gap = 0.08, 2e-3
    centre = tuple(free.positions[i] + (radius + gap) * ahead)
    if shape == "cylinder":
        axis = np.cross(ahead, free.orientations[i][:, 2])
        obstacle = solver.Cylinder(centre, tuple(axis / np.linalg.norm(axis)), radius, 1e5)
    else:
        obstacle = solver.Sphere(centre, radius, 1e5)
    scene = solver.Scene(obstacles=(obstacle,))
    start = solver.solve(arm, 0.9 * p, scene, planar=False)
    assert not start.in_contact
    fast = solver.solve(arm, p, scene, planar=False, warm_start=start)
    slow = solver.solve(arm, p, scene, planar=False, warm_start=start,
                        settings=solver.Settings(shortcuts=False))
    assert slow.converged and not slow.in_contact and not slow.penetration.any()
    # The shortcut's answer (the starts differ in round-off: a cold solve against a warm one).
    np.testing.assert_allclose(fast.positions, free.positions, rtol=0, atol=1e-12)
    assert np.abs(fast.tip - slow.tip).max() < 1e-7
    stepper = solver.Stepper(arm, scene, planar=False)
    stepper.reset(0.9 * p)
    assert stepper.step(p).converged and stepper.last_path == "lean"
    np.testing.assert_allclose(stepper.tip, fast.tip, atol=1e-12)


def _tilted_arc(bend, h, length):
    """An exact circular arc of radius ``bend`` in a tilted plane, sampled every ``h`` along
    it: (points (N, 3), unit tangents (N, 3), the plane's unit normal, its in-plane axes)."""
    s = np.arange(0.0, length + 1e-12, h)
    e1 = np.array([1.0, 0.5, 0.2]) / np.linalg.norm([1.0, 0.5, 0.2])
    e2 = np.cross(np.array([0.3, -0.2, 1.0]), e1)
    e2 /= np.linalg.norm(e2)
    points = bend * (np.sin(s / bend)[:, None] * e1 + (1.0 - np.cos(s / bend))[:, None] * e2)
    tangents = np.cos(s / bend)[:, None] * e1 + np.sin(s / bend)[:, None] * e2
    return points, tangents, np.cross(e1, e2), e1, e2


@pytest.mark.parametrize("shape", ["cylinder", "sphere"])
def test_chord_guard_3d_sees_an_obstacle_between_samples(shape):
    """``chords_clear_3d`` on an exact circular arc in a tilted plane sampled every 20 mm: an
    obstacle on its convex side that the arc enters between two samples (both samples clear
    of it) is not clear; one the arc clears by more than the allowance ℓ·(|Δθ|/4 +
    CHORD_SLACK) at every chord is. The cylinder's axis is normal to the arc's plane."""
    from solver.kernels.obstacles import CHORD_SLACK, chord_allowance_3d, chords_clear_3d

    bend, h = 0.2, 0.02
    points, tangents, normal, e1, e2 = _tilted_arc(bend, h, 0.3)
    assert chord_allowance_3d(points, tangents) == pytest.approx(
        2.0 * bend * np.sin(0.5 * h / bend) * (0.25 * h / bend + CHORD_SLACK), rel=1e-12)
    phi = 4.5 * h / bend  # between samples 4 and 5
    at = bend * (np.sin(phi) * e1 + (1 - np.cos(phi)) * e2)
    outward = np.sin(phi) * e1 - np.cos(phi) * e2
    radius = 0.04
    sag = bend * (1.0 - np.cos(0.5 * h / bend))
    allowance = h * (0.25 * h / bend + CHORD_SLACK)

    def obstacle(distance):
        centre = at + distance * outward
        axis = normal if shape == "cylinder" else np.zeros(3)
        return np.array([[*centre, *axis, radius, 1e5]])

    entering = obstacle(radius - 0.5 * sag)
    offsets = points - entering[0, :3]
    offsets -= np.outer(offsets @ entering[0, 3:6], entering[0, 3:6])
    assert (np.linalg.norm(offsets, axis=1) - radius).min() > 0.0  # every sample clears it
    assert not chords_clear_3d(points, tangents, entering)
    assert chords_clear_3d(points, tangents, obstacle(radius + 1.01 * allowance))


def test_tunnel_test_3d_is_the_segments_deepest_point():
    """``tunnels_3d`` against a brute-force depth along each sample's straight move (10⁴
    points): skew cylinders and spheres, random moves; the closed form decides the same
    wherever the brute force's depth is not within 1e-9 m of the limit."""
    from solver.kernels.obstacles import tunnels_3d

    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 1.0, 10_001)[:, None]
    decided = {True: 0, False: 0}
    for _ in range(400):
        axis = rng.normal(size=3) * rng.integers(0, 2)  # zero: a sphere
        if axis.any():
            axis /= np.linalg.norm(axis)
        radius = rng.uniform(0.05, 0.2)
        obstacles = np.array([[*rng.normal(scale=0.2, size=3), *axis, radius, 1e5]])
        prev, new = rng.normal(scale=0.3, size=(2, 1, 3))
        slack = rng.uniform(-0.02, 0.02)
        path = prev + t * (new - prev)
        offsets = path - obstacles[0, :3]
        offsets -= np.outer(offsets @ axis, axis)
        depth = radius - np.linalg.norm(offsets, axis=1)
        limit = max(depth[0], depth[-1], 0.0) + slack
        if abs(depth.max() - limit) < 1e-9:
            continue
        expected = bool(depth.max() > limit)
        assert tunnels_3d(prev, new, obstacles, slack) == expected
        decided[expected] += 1
    assert min(decided.values()) > 20  # both answers were exercised


def _counting_tethered_solves(monkeypatch):
    """Count the proximal relaxation's tethered Newton solves (spatial_contact.kernel.newton
    with a spring), through a stand-in for the kernel module that the path module calls."""
    count = [0]
    kernels = types.ModuleType("kernels")
    kernels.__dict__.update(vars(spatial_paths.kernel))

    def newton(*args):
        count[0] += args[-1][0][0] > 0.0
        return spatial_contact.newton(*args)

    kernels.newton = newton
    monkeypatch.setattr(spatial_paths, "kernel", kernels)
    return count


def test_the_proximal_relaxation_strides_down_a_straight_slide_to_where_it_crept(monkeypatch):
    """Where a 3D snap relaxes (springs tying the arm to where it is, slackened as it
    settles), the arm may slide a long way at an even pace: in this OctArmWrap3D-v0 episode
    (seed 0, step 214) it crept ~1 mm an iteration for 250 of them, each move just over the
    pace under which the springs slacken. Each tethered solve is an implicit Euler step of the
    energy's gradient flow, and the springs' pull is its downhill force: the springs halve
    while the pull keeps within RELAX_STRAIGHT of the last iteration's. The arm lands on the
    state the crawl lands on (1e-9 m) in under a third of its tethered solves."""
    env = gym.make("SoftArm/OctArmWrap3D-v0")
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(214)]
    for action in actions[:-1]:
        env.step(action)
    before = pickle.dumps(env.unwrapped.stepper)
    env.step(actions[-1])
    pressures = env.unwrapped.stepper.pressures.copy()
    count = _counting_tethered_solves(monkeypatch)
    landed = {}
    for straight in (0.0, spatial_paths.RELAX_STRAIGHT):
        monkeypatch.setattr(spatial_paths, "RELAX_STRAIGHT", straight)
        stepper, count[0] = pickle.loads(before), 0
        report = stepper.step(pressures)
        assert stepper.last_path == "general" and report.converged and stepper.equilibrium.snapped
        landed[straight] = (stepper.equilibrium.positions, count[0])
    (crept, crawl), (strode, strides) = landed.values()
    assert np.abs(strode - crept).max() < 1e-9
    assert crawl > 100 and strides < crawl / 3


def _ramp_on_a_cylinder(monkeypatch):
    """The arguments of the first 3D continuation (:func:`solver.kernels.spatial_contact.follow`)
    of a warm solve of OctArm V pressed on a cylinder, channels I from 30 to 39 % of p_max."""
    arm = designs.octarm_v()
    ring = arm.tubes[0].material.ring_stiffness
    scene = solver.Scene(obstacles=(
        solver.Cylinder((-0.17, -0.5, 0.0), (0.0, 0.0, 1.0), 0.12, ring),))
    p = np.zeros(arm.n_channels)
    p[::3] = 0.3 * arm.max_pressure
    pressed = solver.solve(arm, p, scene, planar=False)
    assert pressed.converged and pressed.in_contact
    ramps = []

    def follow(*args):
        ramps.append(tuple(a.copy() if isinstance(a, np.ndarray) else a for a in args))
        return spatial_contact.follow(*args)

    kernels = types.ModuleType("kernels")
    kernels.__dict__.update(vars(spatial_contact))
    kernels.follow = follow
    monkeypatch.setattr(spatial_paths, "kernel", kernels)
    solver.solve(arm, 1.3 * p, scene, planar=False, warm_start=pressed)
    return ramps[0]


def _one_solve_on_a_cylinder(monkeypatch):
    """One Newton solve's arguments: the start of :func:`_ramp_on_a_cylinder` (channels I at
    30 % of p_max, pressed on the cylinder) at channels I of 90 %: (Z, grid, rest, level,
    weights, res_weights, scales, tol)."""
    (Z, grid, tubes_i, tubes_f, a, _, weights, res_weights, scales, tol, *_) = \
        _ramp_on_a_cylinder(monkeypatch)
    secf = grid[spatial_contact.GS_SECF]
    level = tuple(x.copy() for x in a)
    level[spatial_contact.L_P][:] *= 3.0
    rest = np.empty((3, secf.shape[1]))
    solver.rod.rest_strains_into(level[spatial_contact.L_P], tubes_i, tubes_f, secf, rest)
    return Z, grid, rest, level, weights, res_weights, scales, tol


def test_the_initial_tangent_predicts_nearby_equilibria_to_second_order(monkeypatch):
    """The 3D continuation's tangent at the start of a ramp (dZ/dt = −J⁻¹ ∂F/∂t, from which it
    decides which first steps are worth trying) against equilibria Newton finds at small
    steps δ along the ramp of a solve pressed on a cylinder: the start moved by δ·slope
    misses them by O(δ²) — a quarter as far at half the step — and by under a thousandth of
    the move itself at δ = 2e-3."""
    (Z, grid, tubes_i, tubes_f, a, b, weights, res_weights, scales, tol, max_iter, max_step,
     *_) = _ramp_on_a_cylinder(monkeypatch)
    secf = grid[spatial_contact.GS_SECF]
    now = tuple(x.copy() for x in a)
    rest = np.empty((3, secf.shape[1]))

    def at(t):
        spatial_contact.set_level(t, a, b, now)
        solver.rod.rest_strains_into(now[spatial_contact.L_P], tubes_i, tubes_f, secf, rest)

    def equilibrium(t, start):
        at(t)
        nodes = start.copy()
        assert spatial_contact.newton(nodes, grid, rest, now, weights, res_weights, scales,
                                      1e-3 * tol, max_iter, max_step, spatial_contact.NO_TETHER)[0]
        return nodes

    start = equilibrium(0.0, Z)
    n = weights.shape[0]
    F, J, slope = np.empty(n), np.empty((n, n)), np.empty(n)
    blocks = np.empty((start.shape[0], spatial_contact.N_CTANGENT, spatial_contact.N_CTANGENT))
    assert spatial_contact.tangent_system(start, grid, rest, now, F, J, blocks)
    spatial_contact.initial_tangent(start, grid, tubes_i, tubes_f, a, b, rest, now, scales, F,
                                    J, slope)
    assert np.abs(slope).max() > 0.0
    misses, moves = [], []
    for step in (2e-3, 1e-3):
        exact = equilibrium(step, start)
        predicted = np.empty_like(start)
        spatial_contact.retract(start, slope, step, predicted)
        misses.append(np.abs(predicted[:, :3] - exact[:, :3]).max())
        moves.append(np.abs(exact[:, :3] - start[:, :3]).max())
    assert misses[0] < 1e-3 * moves[0]
    assert 3.0 < misses[0] / misses[1] < 5.0


@pytest.mark.parametrize("past_kinks", [True, False])
def test_newton_forming_first_trials_with_their_jacobians_takes_the_textbook_iterates(
        monkeypatch, past_kinks):
    """The 3D contact Newton forms an iteration's first trial with its Jacobian in one pass
    where the iteration before accepted its first trial: every iterate, the residual, the
    Jacobian and the segment maps it ends with are the textbook line search's to the last bit
    (a residual pass per trial, then a Jacobian pass at the accepted one:
    ``tests/solver/naive.py``). OctArm V pressed on a cylinder, channels I from 30 to 90 % of
    p_max in one Newton solve: six iterations, two of whose first trials are refused."""
    from tests.solver.naive import newton_spatial_contact_plain

    (Z, grid, rest, level, weights, res_weights, scales, tol) = _one_solve_on_a_cylinder(monkeypatch)
    n = weights.shape[0]
    kernel_nodes, plain_nodes = Z.copy(), Z.copy()
    F, J = np.empty(n), np.empty((n, n))
    blocks = np.empty((Z.shape[0], spatial_contact.N_CTANGENT, spatial_contact.N_CTANGENT))
    ok, its, res, _ = spatial_contact.newton_into(
        kernel_nodes, grid, rest, level, weights, res_weights, scales, tol, 40, 2.0,
        spatial_contact.NO_TETHER, F, J, blocks, spatial_contact.JAC_VARIATIONAL, past_kinks,
        kernel_nodes, math.inf, math.inf)
    plain = newton_spatial_contact_plain(plain_nodes, grid, rest, level, weights, res_weights,
                                         scales, tol, 40, 2.0, past_kinks)
    assert (ok, its, res) == plain[:3] and ok
    assert plain[6] > 0 and plain[7] > 0  # first trials taken and refused
    assert np.array_equal(kernel_nodes, plain_nodes)
    assert np.array_equal(F, plain[3]) and np.array_equal(J, plain[4])
    assert np.array_equal(blocks, plain[5])


def _fenced_newton(solve, nodes, fence, plateau=math.inf):
    """``newton_into`` on ``solve`` (:func:`_one_solve_on_a_cylinder`'s arguments) from
    ``nodes`` (changed in place), fenced round the solve's start with ``fence`` and
    ``plateau``."""
    (Z, grid, rest, level, weights, res_weights, scales, tol) = solve
    n = weights.shape[0]
    F, J = np.empty(n), np.empty((n, n))
    blocks = np.empty((Z.shape[0], spatial_contact.N_CTANGENT, spatial_contact.N_CTANGENT))
    return spatial_contact.newton_into(
        nodes, grid, rest, level, weights, res_weights, scales, tol, 40, 2.0,
        spatial_contact.NO_TETHER, F, J, blocks, spatial_contact.JAC_VARIATIONAL, True, Z, fence,
        plateau)


def _from_start(solve, nodes):
    """Weighted RMS distance of ``nodes`` from ``solve``'s start."""
    Z, weights = solve[0], solve[4]
    moved = np.empty(weights.shape[0])
    spatial_contact.between(nodes, Z, moved)
    return spatial_contact.weighted_norm(moved, weights)


@pytest.mark.parametrize("reach", [0.5, 0.8, 1.2, 2.0])
def test_newton_gives_up_behind_a_fence_its_root_lies_beyond(monkeypatch, reach):
    """A path refuses a converged try that lies too far from its prediction, so its Newton
    is fenced: it gives up once an iterate lies beyond the fence by more than twice its
    Newton step (``FENCE_STEPS``), there already beyond the fence, where its root lies too.
    OctArm V pressed on a cylinder, channels I from 30 to 90 % of p_max in one Newton solve,
    fenced round the start at ``reach`` times the root's distance: a fence short of the root
    stops Newton before it converges; one past it changes no iterate."""
    solve = _one_solve_on_a_cylinder(monkeypatch)
    Z = solve[0]
    root = Z.copy()
    ok, its, *_ = _fenced_newton(solve, root, math.inf)
    assert ok and its >= 4
    distance = _from_start(solve, root)
    fenced = Z.copy()
    fenced_ok, fenced_its, *_ = _fenced_newton(solve, fenced, reach * distance)
    if reach < 1.0:
        assert not fenced_ok and fenced_its < its and _from_start(solve, fenced) > reach * distance
    else:
        assert fenced_ok and fenced_its == its and np.array_equal(fenced, root)


def test_newton_gives_up_where_its_step_is_longer_than_plateau_fences(monkeypatch):
    """The lean step's Newton also gives up where a Newton step is longer than ``plateau``
    fences (``PLATEAU_FENCES``: a fold's plateau). The same solve as above, fenced at twice its
    root's distance (where the fence alone changes no iterate); its first Newton step, worked out
    here by a dense forward-difference Jacobian, is its longest: a plateau 2 % short of that step
    stops Newton at the start, one 2 % past it changes no iterate."""
    solve = _one_solve_on_a_cylinder(monkeypatch)
    (Z, grid, rest, level, weights, res_weights, scales, tol) = solve
    n = weights.shape[0]

    def residual(nodes):
        F = np.empty(n)
        blocks = np.empty((0, spatial_contact.N_CTANGENT, spatial_contact.N_CTANGENT))
        assert spatial_contact.newton_system(nodes, grid, rest, level, F, np.empty((0, 0)), False,
                                             blocks, scales, spatial_contact.NO_TETHER)
        return F

    F0, h, jacobian, unit = residual(Z), 1e-7, np.empty((n, n)), np.eye(n)
    for k in range(n):
        moved = Z.copy()
        spatial_contact.retract(Z, unit[k], h, moved)
        jacobian[:, k] = (residual(moved) - F0) / h
    first_step = spatial_contact.weighted_norm(np.linalg.solve(jacobian, F0), weights)

    root = Z.copy()
    ok, its, *_ = _fenced_newton(solve, root, math.inf)
    fence = 2.0 * _from_start(solve, root)
    short = Z.copy()
    assert _fenced_newton(solve, short, fence, 0.98 * first_step / fence)[:2] == (False, 0)
    assert np.array_equal(short, Z)
    past = Z.copy()
    assert _fenced_newton(solve, past, fence, 1.02 * first_step / fence)[:2] == (True, its) and ok
    assert np.array_equal(past, root)
