"""3D rendering: spatial arms are drawn in three orthographic views (front x–y, side z–y, top x–z)."""

import numpy as np
import pytest

from softarm_gym.envs import ReachEnv
from softarm_gym.render import ESTIMATE_COLOUR, TARGET_COLOUR, TRUE_COLOUR, ArmRenderer3D, Cylinder, Sphere
from tests.frames import colour_mask, has_colour

OUT_OF_VIEW = np.full((2, 3), 50.0)  # an estimate far outside every view: nothing of it is drawn


def _pixels(renderer, frame, view, colour, tol=30):
    """World coordinates (M, 2), in the view's (horizontal, vertical) axes, of the pixels of
    ``colour`` inside the view's axes box, and the box's size in metres per pixel."""
    ax = renderer.axes[view]
    box = ax.get_window_extent()
    rows, cols = np.nonzero(colour_mask(frame, colour, tol))
    display = np.column_stack([cols + 0.5, frame.shape[0] - rows - 0.5])
    inside = (display[:, 0] > box.x0) & (display[:, 0] < box.x1) \
        & (display[:, 1] > box.y0) & (display[:, 1] < box.y1)
    metres_per_pixel = np.diff(ax.get_xlim())[0] / box.width
    return ax.transData.inverted().transform(display[inside]), metres_per_pixel


def _spatial_env(**kwargs):
    return ReachEnv("octarm_v", planar=False, observation="true", render_mode="rgb_array",
                    render_size=400, **kwargs)


def test_views_show_the_projections_of_a_spatial_backbone():
    s = np.linspace(0.0, 1.0, 41)
    # Away from the origin, where the base marker would hide the first pixels.
    backbone = np.column_stack([0.5 * s - 0.3, 0.2 - 0.3 * np.sin(np.pi * s), 0.4 * s ** 2 - 0.5])
    renderer = ArmRenderer3D(extent=1.0, size=400)
    frame = renderer.frame(backbone, backbone[[20, 40]], OUT_OF_VIEW, OUT_OF_VIEW[0])
    assert frame.shape == (400, 400, 3) and frame.dtype == np.uint8
    for view, (h, v) in {"front": (0, 1), "side": (2, 1), "top": (0, 2)}.items():
        seen, mpp = _pixels(renderer, frame, view, TRUE_COLOUR)
        assert len(seen) > 50, view
        for k, axis in enumerate((h, v)):
            # The line is 3 px wide and the section-end dots 5 px across.
            assert abs(seen[:, k].min() - backbone[:, axis].min()) < 4 * mpp, (view, axis)
            assert abs(seen[:, k].max() - backbone[:, axis].max()) < 4 * mpp, (view, axis)


def test_top_view_is_seen_from_above_with_z_pointing_down_the_frame():
    backbone = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.8]])
    renderer = ArmRenderer3D(extent=1.0, size=400)
    frame = renderer.frame(backbone, backbone[1:], OUT_OF_VIEW, OUT_OF_VIEW[0])
    ax = renderer.axes["top"]
    base_row = frame.shape[0] - ax.transData.transform((0.0, 0.0))[1]
    tip_row = frame.shape[0] - ax.transData.transform((0.0, 0.8))[1]
    assert tip_row > base_row + 50
    assert colour_mask(frame, TRUE_COLOUR)[int(tip_row), int(ax.transData.transform((0.0, 0.8))[0])]


def test_out_of_plane_reach_spans_z_in_the_top_view_and_an_in_plane_state_is_a_flat_line():
    env = _spatial_env()
    env.reset(seed=0, options={"target": (0.3, -0.4, 0.3)})
    action = -np.ones(9)
    action[env.input_names.index("s1_III")] = 0.2  # one off-plane channel: bends the arm towards +z
    env.step(action)
    z = env.unwrapped._eq.positions[:, 2]
    assert z.max() > 0.3  # the state is clearly out of plane
    frame = env.render()
    renderer = env.unwrapped._renderer
    seen, mpp = _pixels(renderer, frame, "top", TRUE_COLOUR)
    assert abs(seen[:, 1].max() - z.max()) < 6 * mpp and abs(seen[:, 1].min() - z.min()) < 6 * mpp
    side, _ = _pixels(renderer, frame, "side", TRUE_COLOUR)
    assert abs(side[:, 0].max() - z.max()) < 6 * mpp

    env.step(-np.ones(9))  # no pressure: the arm hangs in the x–y plane
    assert np.all(np.abs(env.unwrapped._eq.positions[:, 2]) < 1e-9)
    flat, mpp = _pixels(renderer, env.render(), "top", TRUE_COLOUR)
    assert len(flat) > 20
    assert np.ptp(flat[:, 1]) < 6 * mpp and np.abs(flat[:, 1]).max() < 3 * mpp
    assert np.ptp(flat[:, 0]) > 0.2  # a line along x, not a dot
    env.close()


def test_target_is_drawn_at_its_3d_position_in_every_view():
    env = _spatial_env()
    target = np.array([0.3, -0.4, 0.3])
    env.reset(seed=0, options={"target": tuple(target)})
    frame = env.render()
    renderer = env.unwrapped._renderer
    for view, (h, v) in {"front": (0, 1), "side": (2, 1), "top": (0, 2)}.items():
        seen, mpp = _pixels(renderer, frame, view, TARGET_COLOUR)
        assert len(seen) > 10, view
        np.testing.assert_allclose(seen.mean(axis=0), target[[h, v]], atol=2 * mpp, err_msg=view)
    env.close()


def test_spatial_frame_has_the_planar_frame_size_and_shows_truth_and_estimate():
    for size in (200, 333):
        planar = ReachEnv("octarm_v", render_mode="rgb_array", render_size=size)
        planar.reset(seed=0)
        spatial = ReachEnv("octarm_v", planar=False, observation="constant_curvature",
                           render_mode="rgb_array", render_size=size)
        spatial.reset(seed=0)
        spatial.step(np.linspace(-1.0, 0.5, 9))
        frame = spatial.render()
        assert frame.shape == planar.render().shape == (size, size, 3)
        assert has_colour(frame, TRUE_COLOUR) and has_colour(frame, ESTIMATE_COLOUR)
        assert has_colour(frame, TARGET_COLOUR)


def test_spatial_frames_are_deterministic():
    def episode():
        env = _spatial_env()
        env.reset(seed=3)
        first = env.render()
        env.step(np.linspace(-1.0, 1.0, 9))
        second = env.render()
        return env, first, second

    env, first, second = episode()
    _, first_again, second_again = episode()
    np.testing.assert_array_equal(first, first_again)
    np.testing.assert_array_equal(second, second_again)
    assert not np.array_equal(first, second)
    np.testing.assert_array_equal(env.render(), second)  # a repeated frame leaves no trace


def test_frame_depends_only_on_its_arguments():
    s = np.linspace(0.0, 1.0, 11)[:, None]
    a, b = s * [0.5, -0.5, 0.3], s * [-0.4, 0.2, -0.5]
    args = (a, a[-1:], a, a[-1])
    renderer = ArmRenderer3D(extent=1.0, size=160)
    first = renderer.frame(*args, target=(0.1, 0.2, 0.3), caption="a")
    renderer.frame(b, b[-1:], b, b[-1], objects=[Sphere((0.2, 0.0, 0.0), 0.1)], caption="b")
    np.testing.assert_array_equal(renderer.frame(*args, target=(0.1, 0.2, 0.3), caption="a"), first)
    fresh = ArmRenderer3D(extent=1.0, size=160)
    np.testing.assert_array_equal(fresh.frame(*args, target=(0.1, 0.2, 0.3), caption="a"), first)


def _is_object_grey(pixel) -> bool:
    r, g, b = (int(c) for c in pixel)
    return r == g == b and 150 < r < 230  # the translucent object colour over the white background


def test_objects_are_drawn_in_every_view():
    renderer = ArmRenderer3D(extent=1.0, size=400)
    backbone = np.zeros((2, 3))
    sphere = Sphere((0.5, 0.4, -0.5), 0.12)
    frame = renderer.frame(backbone, backbone[1:], OUT_OF_VIEW, OUT_OF_VIEW[0], objects=[sphere],
                           disc=((-0.5, -0.5), 0.1))
    for view, (h, v) in {"front": (0, 1), "side": (2, 1), "top": (0, 2)}.items():
        col, row = renderer.axes[view].transData.transform((sphere.center[h], sphere.center[v]))
        assert _is_object_grey(frame[int(frame.shape[0] - row), int(col)]), view
    # The disc of a planar task is a cylinder along z through the whole view: in the top view,
    # a band at x = −0.5 from z = −1 to 1.
    for z in (-0.9, 0.0, 0.9):
        col, row = renderer.axes["top"].transData.transform((-0.5, z))
        assert _is_object_grey(frame[int(frame.shape[0] - row), int(col)]), z


def _area(polygon):
    x, y = polygon.T
    return 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))


def test_object_outlines():
    sphere = Sphere((0.1, 0.2, 0.3), 0.2)
    for h, v in ((0, 1), (2, 1), (0, 2)):
        ring = sphere.outline(h, v)
        np.testing.assert_allclose(np.linalg.norm(ring - (sphere.center[h], sphere.center[v]), axis=1), 0.2)
    upright = Cylinder((0.1, 0.2, 0.3), (0.0, 0.0, 2.0), radius=0.05, length=0.4)
    assert upright.axis == (0.0, 0.0, 1.0)
    assert upright == Cylinder((0.1, 0.2, 0.3), (0.0, 0.0, 1.0), 0.05, 0.4) and len({upright, sphere}) == 2
    ring = upright.outline(0, 1)  # seen along its axis: a circle
    np.testing.assert_allclose(np.linalg.norm(ring - [0.1, 0.2], axis=1), 0.05)
    side = upright.outline(0, 2)  # seen from the side: a 2r × length rectangle
    np.testing.assert_allclose([side[:, 0].min(), side[:, 0].max(), side[:, 1].min(), side[:, 1].max()],
                               [0.05, 0.15, 0.1, 0.5], atol=1e-12)
    np.testing.assert_allclose(_area(side), 0.1 * 0.4, rtol=1e-3)
    tilted = Cylinder((0.0, 0.0, 0.0), (1.0, 1.0, 0.0), radius=0.05, length=0.4)
    np.testing.assert_allclose(_area(tilted.outline(0, 1)), 0.1 * 0.4, rtol=1e-2)  # axis in the view plane
    # Seen along z, an axis at 45° to the view: two ellipses (semi-axes r, r·cos 45°) joined
    # by their common tangents, area 2r·L·sin 45° + π r² cos 45°.
    slanted = Cylinder((0.0, 0.0, 0.0), (1.0, 0.0, 1.0), radius=0.05, length=0.4)
    c = np.sqrt(0.5)
    np.testing.assert_allclose(_area(slanted.outline(0, 1)), 0.1 * 0.4 * c + np.pi * 0.05 ** 2 * c, rtol=1e-2)


@pytest.mark.parametrize(("make", "match"), [
    (lambda: Sphere((0.0, 0.0), 0.1), "Sphere.center must be three finite numbers"),
    (lambda: Sphere((0.0, np.nan, 0.0), 0.1), "Sphere.center"),
    (lambda: Sphere((0.0, 0.0, 0.0), 0.0), "Sphere.radius must be a finite length > 0"),
    (lambda: Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.1, 1.0), "Cylinder.axis must be a non-zero"),
    (lambda: Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.1, np.inf), "Cylinder.length"),
    (lambda: Cylinder((0.0, 0.0, 0.0), "z", 0.1, 1.0), "Cylinder.axis must be three finite numbers"),
])
def test_objects_validate_their_arguments(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_renderer_3d_validates_its_arguments():
    with pytest.raises(ValueError, match="extent"):
        ArmRenderer3D(extent=-1.0)
    with pytest.raises(ValueError, match="size"):
        ArmRenderer3D(extent=1.0, size=32)
    renderer = ArmRenderer3D(extent=1.0, size=100)
    planar = np.zeros((5, 2))
    with pytest.raises(ValueError, match=r"backbone must be \(N, 3\) points \(m\); got shape \(5, 2\)"):
        renderer.frame(planar, planar, planar, planar[0])
    spatial = np.zeros((5, 3))
    with pytest.raises(ValueError, match=r"target must be a \(3,\) point"):
        renderer.frame(spatial, spatial, spatial, spatial[0], target=(0.1, 0.2))


def test_human_mode_shows_spatial_frames():
    pytest.importorskip("pygame")
    env = ReachEnv("ct", planar=False, render_mode="human", render_size=128)
    env.reset(seed=0)
    assert env.render() is None
    env.step(np.zeros(6))
    env.close()
