"""Wrap task: the wrap-angle measure, disc placement, contact, rewards."""

import math

import numpy as np
import pytest

import solver
from softarm_gym.envs import WrapEnv, arm_half_thickness, wrap_angle
from softarm_gym.render import OBJECT_COLOUR
from tests.frames import has_colour


def _arc(center, radius, start, stop, n=200):
    phi = np.linspace(start, stop, n)
    return np.column_stack([center[0] + radius * np.cos(phi), center[1] + radius * np.sin(phi)])


@pytest.mark.parametrize("extent_deg", [30.0, 180.0, 270.0, 359.0, 420.0])
def test_wrap_angle_of_an_arc_is_its_extent(extent_deg):
    pts = _arc((0.3, -0.2), 0.1, 2.0, 2.0 - math.radians(extent_deg))
    assert wrap_angle(pts, (0.3, -0.2), 0.1, 1e-3) == pytest.approx(math.radians(extent_deg), rel=1e-9)


def test_wrap_angle_counts_only_samples_within_the_margin():
    on = _arc((0.0, 0.0), 0.1, 0.0, math.pi / 2, 50)
    off = _arc((0.0, 0.0), 0.12, math.pi / 2, math.pi, 50)
    pts = np.vstack([on, off])
    assert wrap_angle(pts, (0, 0), 0.1, 0.005) == pytest.approx(math.pi / 2)
    assert wrap_angle(pts, (0, 0), 0.1, 0.03) == pytest.approx(math.pi)
    assert wrap_angle(off, (0, 0), 0.1, 0.005) == 0.0


def test_half_thickness_is_the_distal_tube_ring_plus_tube_radius():
    arm = solver.designs.octarm_v()
    ro = arm.tubes[0].material.outer_radius
    assert arm_half_thickness(arm) == pytest.approx(ro / math.sin(math.pi / 3) + ro)


@pytest.mark.parametrize("design, kwargs", [("octarm_v", {}),
                                            ("ct", {"object_radius": (0.15, 0.2), "placement_wrap_deg": 180.0,
                                                    "base_angle_deg": 90.0})])
def test_disc_is_placed_within_reach_and_clear_of_the_start(design, kwargs):
    env = WrapEnv(design, **kwargs)
    for seed in range(4):
        obs, info = env.reset(seed=seed)
        center, contact = info["object_center"], info["contact_radius"]
        assert contact == pytest.approx(info["object_radius"] + env.half_thickness)
        lo, hi = env.object_radius_range
        assert lo <= info["object_radius"] <= hi
        clearance = np.hypot(*(env._eq.positions - center).T).min() - contact
        assert clearance >= 0.5 * env.placement_gap
        assert info["penetration"] == 0.0 and info["wrap_angle_deg"] == 0.0
        assert info["gap"] == pytest.approx(clearance)
        assert np.hypot(*center) < env.arm.length * 1.2
        np.testing.assert_allclose(obs[env._slices["goal"]], [*center, contact], atol=1e-6)


def test_curling_towards_the_disc_wraps_it():
    # Hanging OctArm V, seed 0: the disc sits on the clockwise side (channel I curls that way).
    env = WrapEnv("octarm_v")
    _, info = env.reset(seed=0)
    start_gap = info["gap"]
    theta = env._eq.angles[np.argmin(np.hypot(*(env._eq.positions - info["object_center"]).T))]
    normal = np.array([-math.sin(theta), math.cos(theta)])
    side = np.sign(np.dot(info["object_center"] - env._eq.tip, normal))
    assert side < 0
    curl = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    wraps = []
    for frac in np.linspace(0.1, 1.0, 10):
        _, reward, _, _, info = env.step(-1.0 + frac * (curl + 1.0))
        assert info["converged"]
        wraps.append(info["wrap_angle_deg"])
    assert wraps[-1] > 180.0 and wraps[-1] == max(wraps)
    assert 0.0 < info["penetration"] < env.penetration_tolerance
    assert info["gap"] == 0.0 < start_gap
    assert info["reward_wrap"] == pytest.approx(math.radians(wraps[-1]) / (2 * math.pi))
    assert info["is_success"] == (wraps[-1] >= 270.0)


def test_reward_terms_sum_and_success_rule():
    env = WrapEnv("octarm_v", success_wrap_deg=10.0, penetration_tolerance=0.02)
    env.reset(seed=0)
    for frac in np.linspace(0.2, 1.0, 5):
        _, reward, _, _, info = env.step(-1.0 + frac * np.array([2.0, 0, 2.0, 0, 2.0, 0]))
        terms = [v for k, v in info.items() if k.startswith("reward_")]
        assert len(terms) == 6
        total = 0.0
        for t in terms:
            total += t
        assert total == reward
        assert info["is_success"] == (info["wrap_angle_deg"] >= 10.0 and info["penetration"] <= 0.02)
        assert info["reward_penetration"] == pytest.approx(-0.1 * info["penetration"] / 0.02)
    assert info["is_success"]


def test_object_option_and_validation():
    env = WrapEnv("octarm_v")
    _, info = env.reset(seed=0, options={"object": (0.2, -0.4, 0.05)})
    np.testing.assert_array_equal(info["object_center"], [0.2, -0.4])
    assert info["object_radius"] == 0.05 and env.touch_arc_length is None
    with pytest.raises(ValueError, match="object"):
        env.reset(seed=0, options={"object": (0.2, -0.4, -1.0)})
    with pytest.raises(ValueError, match="radius within ±"):
        env.reset(seed=0, options={"object": (100.0, 100.0, 0.05)})
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) 'target'; .* accepts 'object'"):
        env.reset(seed=0, options={"target": (0.2, -0.4)})
    for kwargs, match in (({"object_radius": 0.0}, "object_radius"),
                          ({"contact_stiffness": 0.0}, "stiffness"),
                          ({"penetration_tolerance": 0.0}, "penetration_tolerance"),
                          ({"object_radius": (0.2, 0.1)}, "high < low")):
        with pytest.raises(ValueError, match=match):
            WrapEnv("octarm_v", **kwargs)


def test_rgb_frame_shows_the_object():
    env = WrapEnv("ct", object_radius=(0.15, 0.2), placement_wrap_deg=180.0, base_angle_deg=90.0,
                  render_mode="rgb_array", render_size=160)
    env.reset(seed=0)
    assert has_colour(env.render(), OBJECT_COLOUR, tol=60)


@pytest.mark.parametrize("x, channels", [(-0.144, (0, 2, 4)), (0.144, (1, 3, 5))])
def test_full_curl_onto_the_disc_converges_on_both_sides(x, channels):
    """The hanging OctArm V curled onto a disc in 10 absolute steps, with channels I (disc on
    the left) or II+III (its mirror on the right, twice the axial force): every step of the
    ramp reaches its pressures and the arm ends wrapped far round the disc on either side."""
    import gymnasium as gym

    env = gym.make("SoftArm/OctArmWrap-v0", initial_pressure_fraction=0.0)
    env.reset(seed=0, options={"object": (x, -0.139, 0.102)})
    for k in range(1, 11):
        action = -np.ones(6, dtype=np.float32)
        action[list(channels)] = -1.0 + 2.0 * k / 10
        _, _, _, _, info = env.step(action)
        assert info["converged"], (k, info["solver"])
    assert info["wrap_angle_deg"] > 240.0


@pytest.mark.parametrize("env_id", ["SoftArm/OctArmWrap-v0", "SoftArm/CTWrap-v0"])
def test_random_absolute_jumps_converge(env_id):
    """Jumps between unrelated random pressures (the hardest contact paths) all converge."""
    import gymnasium as gym

    env = gym.make(env_id, max_episode_steps=50)
    rng = np.random.default_rng(1)
    env.reset(seed=1)
    for step in range(150):
        _, _, term, trunc, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        assert info["converged"], (step, info["solver"])
        if term or trunc:
            env.reset(seed=step)


# ------------------------------------------------------------------ 3D wrap


def test_wrap_angle_about_a_tilted_axis_is_the_arcs_extent():
    """An arc of 200° about a skew axis (in the plane normal to it, shifted along it) with
    samples far from it: the 3D measure is the arc's extent."""
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    e1 = np.cross(axis, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    centre = np.array([0.1, -0.4, 0.2])
    phi = np.linspace(0.5, 0.5 + math.radians(200.0), 120)
    along = np.linspace(-0.05, 0.05, phi.size)
    arc = centre + 0.1 * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2) + along[:, None] * axis
    far = centre + 0.3 * e1 + np.linspace(0, 0.2, 20)[:, None] * e2
    pts = np.vstack([far, arc])
    assert wrap_angle(pts, centre, 0.1, 1e-3, axis) == pytest.approx(math.radians(200.0), rel=1e-9)
    assert wrap_angle(pts, centre + 0.7 * axis, 0.1, 1e-3, -axis) == pytest.approx(
        math.radians(200.0), rel=1e-9)


def test_3d_wrap_places_a_cylinder_normal_to_the_curl_clear_of_the_start():
    env = WrapEnv("octarm_v", planar=False, object_radius=(0.11, 0.125))
    goal = env.observation_slices["goal"]
    headings = []
    for seed in range(4):
        obs, info = env.reset(seed=seed)
        eq = env._eq
        centre, axis = info["object_center"], info["object_axis"]
        k = int(np.searchsorted(eq.s, env.touch_arc_length))
        tangent = eq.orientations[k][:, 2]
        assert abs(axis @ tangent) < 1e-6 and np.linalg.norm(axis) == pytest.approx(1.0)
        rel = eq.positions - centre
        distance = np.linalg.norm(rel - (rel @ axis)[:, None] * axis, axis=1)
        assert distance.min() >= info["contact_radius"] + 0.5 * env.placement_gap
        np.testing.assert_allclose(obs[goal], np.concatenate(
            [centre, axis, [info["contact_radius"]]]).astype(np.float32))
        assert info["wrap_angle_deg"] == 0.0 and not eq.in_contact
        headings.append(math.atan2(axis[2], axis[0]))
    assert np.ptp(headings) > 0.5  # the side is drawn at random about the arm


def test_3d_wrap_object_option_and_validation():
    env = WrapEnv("octarm_v", planar=False)
    obs, info = env.reset(seed=0, options={"object": (-0.2, -0.55, 0.05, 0.0, 0.0, 2.0, 0.12)})
    np.testing.assert_allclose(info["object_axis"], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(info["object_center"], [-0.2, -0.55, 0.05])
    for bad in [(-0.2, -0.55, 0.12), (-0.2, -0.55, 0.05, 0.0, 0.0, 0.0, 0.12),
                (-0.2, -0.55, 0.05, 0.0, 0.0, 1.0, -0.1)]:
        with pytest.raises(ValueError, match="options\\['object'\\]"):
            env.reset(seed=0, options={"object": bad})


def test_3d_wrap_curl_towards_the_cylinder_wraps_it():
    """A cylinder along z beside the hanging arm (the planar geometry in 3D): ramping the
    proximal channel I curls the arm around it, every step converged."""
    env = WrapEnv("octarm_v", planar=False, initial_pressure_fraction=0.0)
    env.reset(seed=0, options={"object": (-0.144, -0.139, 0.0, 0.0, 0.0, 1.0, 0.102 - env.half_thickness)})
    action = -np.ones(9)
    for t in np.linspace(0.1, 1.0, 10):
        action[0] = 2.0 * t - 1.0
        _, _, _, _, info = env.step(action)
        assert info["converged"]
    assert info["wrap_angle_deg"] > 45.0 and info["penetration"] < env.penetration_tolerance


def test_3d_wrap_step_whose_free_step_snaps_is_the_contact_path():
    """OctArmWrap3D-v0 seed 8 under its reference curl: at step 6 the contact-free step snaps,
    ending clear of the cylinder. A snap's way is not known, so the stepper's answer must be
    the contact path's — the same solve with the shortcuts off (the tree before kept the free
    kernel's landing, 0.23 m away)."""
    import gymnasium as gym

    from softarm_gym.controllers import CurlController

    env = gym.make("SoftArm/OctArmWrap3D-v0")
    controller = CurlController(env)
    obs, _ = env.reset(seed=8)
    controller.reset()
    for _ in range(5):
        obs = env.step(controller.act(obs))[0]
    stepper = env.unwrapped.stepper
    start = stepper.equilibrium
    env.step(controller.act(obs))
    eq = env.unwrapped.stepper.equilibrium
    slow = solver.solve(env.unwrapped.simulated_arm, eq.pressures, stepper.scene, planar=False,
                        warm_start=start, settings=solver.Settings(shortcuts=False))
    assert eq.converged and eq.snapped and slow.converged
    np.testing.assert_allclose(eq.positions, slow.positions, rtol=0, atol=1e-12)


def test_grasp_is_planar_only():
    from softarm_gym.envs import GraspEnv

    with pytest.raises(ValueError, match="planar"):
        GraspEnv(planar=False)


def test_wrap_measure_is_numpy_unwrap_of_the_contact_angles():
    """The batch-first rule against an independent numpy formulation (np.unwrap of the polar
    angles of the samples within the margin) on random spirals and scribbles."""
    rng = np.random.default_rng(0)
    for trial in range(200):
        n = int(rng.integers(2, 80))
        turns = rng.uniform(-2.5, 2.5) * 2 * math.pi
        phi = np.linspace(0.0, turns, n) + rng.normal(0.0, 0.3 if trial % 2 else 0.01, n)
        radius = 0.1 + rng.normal(0.0, 0.01, n)
        pts = np.column_stack([radius * np.cos(phi), radius * np.sin(phi)]) + [0.3, -0.2]
        x, y = (pts - [0.3, -0.2]).T
        near = np.hypot(x, y) <= 0.1 + 0.005
        expected = 0.0
        if near.sum() >= 2:
            unwrapped = np.unwrap(np.arctan2(y[near], x[near]))
            expected = unwrapped.max() - unwrapped.min()
        assert wrap_angle(pts, (0.3, -0.2), 0.1, 0.005) == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_true_observation_follows_the_record_onto_a_finer_contact_layout():
    """At a contact stiffness whose contact layout has more rows than the settings' grid, the
    state moves between the two; the ``true`` observation and the wrap measures read from
    the record stay those of the equilibrium (to float32 rounding)."""
    from softarm_gym.envs.terms import fill_shape
    from softarm_gym.sensing import shape_from_equilibrium

    env = WrapEnv("octarm_v", contact_stiffness=1e6)
    rows = set()
    curl = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    for frac in [None, *np.linspace(0.1, 1.0, 10)]:
        if frac is None:
            obs, info = env.reset(seed=0)  # on the settings' grid; the steps on the contact layout
        else:
            obs, _, _, _, info = env.step(-1.0 + frac * (curl + 1.0))
        assert info["converged"]
        rows.add(None if env.stepper.record is None else env.stepper.record.shape[0])
        eq = env._eq
        expected = np.zeros(obs.size)
        fill_shape(expected, env.observation_slices, shape_from_equilibrium(eq, env.n_backbone), True)
        shape = slice(0, env.observation_slices["pressures"].start)
        np.testing.assert_allclose(obs[shape], expected[shape], atol=2e-7, rtol=0)
        wrap = wrap_angle(eq.positions, info["object_center"], info["contact_radius"], env.contact_margin)
        assert info["wrap_angle_deg"] == pytest.approx(math.degrees(wrap), abs=1e-9)
        assert info["penetration"] == (float(eq.penetration.max()) if eq.penetration.size else 0.0)
    assert len(rows - {None}) == 2  # both grids were visited
