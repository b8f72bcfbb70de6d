"""Every CLI figure: axis labels with units, a colourbar and a uniform colormap where colour
encodes a value, and no overlapping tick labels or panels."""

import re

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

import solver
from softarm_gym.analysis import dexterity_map, workspace
from softarm_gym.analysis.figures import plot_dexterity, plot_dexterous_area, plot_workspaces
from softarm_gym.commands.demo import shapes_figure
from softarm_gym.commands.estimators import plot_payload, plot_study
from softarm_gym.design_tools.plots import plot_sweeps
from softarm_gym.design_tools.sweep import sweep
from softarm_gym.sensing.study import run_study

UNIFORM_CMAPS = {"viridis", "cividis", "plasma", "inferno", "magma"}
UNIT = re.compile(r"\(.+\)")


def _overlap(a, b, slack=1.0) -> bool:
    return (min(a.x1, b.x1) - max(a.x0, b.x0) > slack) and (min(a.y1, b.y1) - max(a.y0, b.y0) > slack)


def assert_readable(fig) -> int:
    """Check the figure; return how many colourbars it has."""
    canvas = FigureCanvasAgg(fig)  # the plotting functions return closed figures
    canvas.draw()
    renderer = canvas.get_renderer()
    colorbar_axes = [ax for ax in fig.axes if getattr(ax, "_colorbar", None) is not None]
    panels = [ax for ax in fig.axes if ax not in colorbar_axes]
    for ax in panels:
        for artist in ax.collections:
            if artist.get_array() is not None:  # colour encodes a value
                assert artist.get_cmap().name in UNIFORM_CMAPS, artist.get_cmap().name
                assert artist.colorbar is not None, f"no colourbar for the values in {ax.get_title()!r}"
    for ax in colorbar_axes:
        label = ax.get_ylabel() or ax.get_xlabel()
        assert UNIT.search(label), f"colourbar label without a unit: {label!r}"
    for ax in panels:
        siblings_x = ax.get_shared_x_axes().get_siblings(ax)
        xlabel = next((a.get_xlabel() for a in siblings_x if a.get_xlabel()), "")
        assert UNIT.search(xlabel), f"x label without a unit in {ax.get_title()!r}: {xlabel!r}"
        ylabel = ax.get_ylabel()
        assert UNIT.search(ylabel), f"y label without a unit in {ax.get_title()!r}: {ylabel!r}"
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [t.get_window_extent(renderer) for t in axis.get_ticklabels()
                     if t.get_visible() and t.get_text()]
            for i in range(len(boxes) - 1):
                assert not _overlap(boxes[i], boxes[i + 1]), f"tick labels overlap in {ax.get_title()!r}"
    boxes = [(ax, ax.get_tightbbox(renderer)) for ax in fig.axes]
    for i, (a, box_a) in enumerate(boxes):
        for b, box_b in boxes[i + 1:]:
            if a.get_position().bounds == b.get_position().bounds:  # twin axes share a panel
                continue
            assert not _overlap(box_a, box_b, slack=2.0), f"{a.get_title()!r} overlaps {b.get_title()!r}"
    return len(colorbar_axes)


@pytest.fixture(scope="module")
def ct_maps():
    arm = solver.designs.ct()
    return workspace(arm, levels=3), dexterity_map(arm, levels=3)


def test_workspace_figure(ct_maps, tmp_path):
    ws, _ = ct_maps
    fig = plot_workspaces([ws, ws], tmp_path / "ws.png", labels=["a", "b"])
    assert assert_readable(fig) == 2  # density contours in tips per cm², one bar per panel


def test_dexterity_figures(ct_maps, tmp_path):
    _, dm = ct_maps
    fig = plot_dexterity([dm, dm], tmp_path / "dex.png", labels=["a", "b"])
    assert assert_readable(fig) == 10  # five measures per map, each with its colourbar
    thresholds = np.linspace(0, 2e-7, 5)
    fig = plot_dexterous_area({"ct": (thresholds, np.linspace(1.0, 0.2, 5), 0.53)}, tmp_path / "area.png")
    assert assert_readable(fig) == 0


def test_design_figures(tmp_path):
    by_length = [sweep("pneumatic", "tube-ratio", n, [0.4, 0.6], tapered=True, progress=False)
                 for n in (1, 2)]
    assert assert_readable(plot_sweeps(by_length, tmp_path / "len.png")) == 0
    by_sections = [sweep("pneumatic", "base-ratio", n, [0.6], tapered=True, progress=False) for n in (1, 2)]
    assert assert_readable(plot_sweeps(by_sections, tmp_path / "sec.png")) == 0


def test_estimator_figures(tmp_path):
    result = run_study(pressures_psi=[0, 30])
    assert assert_readable(plot_study(result, tmp_path / "study.png")) == 0
    assert assert_readable(plot_payload(result, tmp_path / "payload.png")) == 0


def test_demo_shapes_figure(tmp_path):
    assert assert_readable(shapes_figure(tmp_path / "shapes.png")) == 0
