"""Frames of a soft arm for the environments' ``render()``.

:class:`ArmRenderer` draws a planar arm, :class:`ArmRenderer3D` a spatial one in three
orthographic views (front x–y, top x–z, side z–y). Both draw on one reusable matplotlib
figure (Agg canvas, no pyplot state): the true backbone with its section ends, the estimated
backbone and tip overlaid in another colour, and the task (a reach target or an object to
wrap). They take plain arrays, never solver objects. ``rgb_array`` returns the frame;
``human`` shows it in a pygame window (``pip install pygame``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon
from matplotlib.ticker import MaxNLocator
from scipy.spatial import ConvexHull

__all__ = ["ArmRenderer", "ArmRenderer3D", "Cylinder", "HumanWindow", "Sphere"]

TRUE_COLOUR = "#1f4e9c"
ESTIMATE_COLOUR = "#e8710a"
TARGET_COLOUR = "#2ca02c"
OBJECT_COLOUR = "#7f7f7f"


def _check_view(extent, size) -> None:
    if not (np.isfinite(extent) and extent > 0):
        raise ValueError(f"extent must be a finite length > 0 (m); got {extent!r}")
    if int(size) != size or size < 64:
        raise ValueError(f"size must be an integer >= 64 pixels; got {size!r}")


class ArmRenderer:
    """Draws frames of a planar arm; artists are created once and updated per frame.

    Args:
        extent: half-width of the square view around the base (m).
        size: frame width and height (pixels).
    """

    def __init__(self, extent: float, size: int = 400):
        _check_view(extent, size)
        dpi = 100
        self.figure = Figure(figsize=(size / dpi, size / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        ax = self.figure.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_xlim(-extent, extent)
        ax.set_ylim(-extent, extent)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.axhline(0.0, color="0.85", lw=0.8, zorder=0)
        ax.axvline(0.0, color="0.85", lw=0.8, zorder=0)
        ax.plot([0.0], [0.0], "ks", ms=7, zorder=5)
        self.axes = ax
        self._true, = ax.plot([], [], "-", color=TRUE_COLOUR, lw=4, solid_capstyle="round", zorder=3)
        self._ends, = ax.plot([], [], "o", color=TRUE_COLOUR, ms=6, zorder=4)
        self._estimate, = ax.plot([], [], "--", color=ESTIMATE_COLOUR, lw=2, zorder=4)
        self._estimate_tip, = ax.plot([], [], "x", color=ESTIMATE_COLOUR, ms=9, mew=2, zorder=4)
        self._target, = ax.plot([], [], "*", color=TARGET_COLOUR, ms=16, zorder=2)
        self._disc = Circle((0.0, 0.0), 0.0, color=OBJECT_COLOUR, alpha=0.5, visible=False, zorder=1)
        ax.add_patch(self._disc)
        self._obstacles = []
        self._text = ax.text(0.02, 0.98, "", transform=ax.transAxes, va="top", ha="left",
                             fontsize=8, family="monospace", zorder=6)

    def frame(self, backbone: np.ndarray, section_ends: np.ndarray, estimate: np.ndarray,
              estimate_tip: np.ndarray, target: np.ndarray | None = None,
              disc: tuple[np.ndarray, float] | None = None, obstacles=(),
              caption: str = "") -> np.ndarray:
        """Draw one frame.

        Args:
            backbone: (N, 2) true backbone samples (m).
            section_ends: (n_sections, 2) true section-end positions (m).
            estimate: (K, 2) estimated backbone samples (m).
            estimate_tip: (2,) estimated tip (m).
            target: (2,) reach target (m), or None.
            disc: ``(centre (2,), radius)`` of an object to wrap (m), or None.
            obstacles: ``(centre (2,), radius)`` pairs of obstacle discs (m), drawn like ``disc``.
            caption: text in the top-left corner.

        Returns:
            (size, size, 3) uint8 RGB image.
        """
        self._true.set_data(backbone[:, 0], backbone[:, 1])
        self._ends.set_data(section_ends[:, 0], section_ends[:, 1])
        self._estimate.set_data(estimate[:, 0], estimate[:, 1])
        self._estimate_tip.set_data([estimate_tip[0]], [estimate_tip[1]])
        if target is None:
            self._target.set_data([], [])
        else:
            self._target.set_data([target[0]], [target[1]])
        if disc is None:
            self._disc.set_visible(False)
        else:
            self._disc.set_center((float(disc[0][0]), float(disc[0][1])))
            self._disc.set_radius(float(disc[1]))
            self._disc.set_visible(True)
        while len(self._obstacles) < len(obstacles):
            patch = Circle((0.0, 0.0), 0.0, color=OBJECT_COLOUR, alpha=0.5, zorder=1)
            self._obstacles.append(self.axes.add_patch(patch))
        for k, patch in enumerate(self._obstacles):
            patch.set_visible(k < len(obstacles))
            if k < len(obstacles):
                patch.set_center((float(obstacles[k][0][0]), float(obstacles[k][0][1])))
                patch.set_radius(float(obstacles[k][1]))
        self._text.set_text(caption)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()


def _vector(name: str, value) -> tuple[float, float, float]:
    try:
        v = np.array(value, dtype=float).ravel()
    except (TypeError, ValueError):
        v = np.empty(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be three finite numbers (m); got {value!r}")
    return tuple(float(c) for c in v)


def _length(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a finite length > 0 (m); got {value!r}")
    return float(value)


def _circle(center, radius: float, n: int = 64) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.column_stack([center[0] + radius * np.cos(t), center[1] + radius * np.sin(t)])


@dataclass(frozen=True)
class Sphere:
    """A sphere for :class:`ArmRenderer3D` (an object to wrap or an obstacle).

    Attributes:
        center: (x, y, z) of the centre (m).
        radius: radius (m), > 0.
    """

    center: tuple[float, float, float]
    radius: float

    def __post_init__(self):
        object.__setattr__(self, "center", _vector("Sphere.center", self.center))
        object.__setattr__(self, "radius", _length("Sphere.radius", self.radius))

    def outline(self, h: int, v: int) -> np.ndarray:
        """(M, 2) outline of the sphere seen along the third axis, in coordinates ``h``, ``v`` (m)."""
        return _circle((self.center[h], self.center[v]), self.radius)


@dataclass(frozen=True)
class Cylinder:
    """A finite circular cylinder for :class:`ArmRenderer3D`, its axis in any direction.

    Attributes:
        center: (x, y, z) of the middle of the axis (m).
        axis: direction of the axis (any non-zero vector; stored normalised).
        radius: radius (m), > 0.
        length: length along the axis (m), > 0.
    """

    center: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius: float
    length: float

    def __post_init__(self):
        object.__setattr__(self, "center", _vector("Cylinder.center", self.center))
        axis = np.array(_vector("Cylinder.axis", self.axis))
        norm = float(np.linalg.norm(axis))
        if norm == 0.0:
            raise ValueError("Cylinder.axis must be a non-zero direction; got (0, 0, 0)")
        object.__setattr__(self, "axis", tuple(float(c) for c in axis / norm))
        object.__setattr__(self, "radius", _length("Cylinder.radius", self.radius))
        object.__setattr__(self, "length", _length("Cylinder.length", self.length))

    def outline(self, h: int, v: int) -> np.ndarray:
        """(M, 2) outline of the cylinder seen along the third axis, in coordinates ``h``, ``v`` (m).

        A convex body's silhouette is the convex hull of its projection; for a cylinder,
        the hull of its two end circles.
        """
        a = np.array(self.axis)
        e1 = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(a, e1)
        t = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
        rim = self.radius * (np.outer(np.cos(t), e1) + np.outer(np.sin(t), e2))
        ends = self.center + 0.5 * self.length * np.array([[a], [-a]])  # (2, 1, 3)
        points = (ends + rim).reshape(-1, 3)[:, [h, v]]
        return points[ConvexHull(points).vertices]


# Each view: title, horizontal and vertical world axes (0 = x, 1 = y, 2 = z), whether the
# vertical axis points down the frame, and where the eye is. Every view is what a camera at
# that place sees (none mirrored): seen from +y with x to the right, +z points down.
_VIEWS = (
    ("front", 0, 1, False, "+z"),
    ("side", 2, 1, False, "−x"),
    ("top", 0, 2, True, "+y"),
)
_AXIS_NAMES = "xyz"
# The moving artists of every view, in drawing order (sizes in points of the 4 in figure).
_STYLES = {
    "target": {"ls": "", "marker": "*", "color": TARGET_COLOUR, "ms": 9},
    "true": {"ls": "-", "color": TRUE_COLOUR, "lw": 2.2, "solid_capstyle": "round"},
    "ends": {"ls": "", "marker": "o", "color": TRUE_COLOUR, "ms": 3.5},
    "estimate": {"ls": "--", "color": ESTIMATE_COLOUR, "lw": 1.3},
    "estimate_tip": {"ls": "", "marker": "x", "color": ESTIMATE_COLOUR, "ms": 5.5, "mew": 1.4},
    "base": {"ls": "", "marker": "s", "color": "k", "ms": 4.5},
}
_OBJECT_STYLE = {"color": OBJECT_COLOUR, "alpha": 0.45, "lw": 0}
# Panel boxes (left, bottom, width, height) in figure fractions of the 4 in × 4 in figure:
# front top-left, side to its right (sharing y rows), top below it (sharing x columns),
# legend and caption bottom-right.
_PANEL = 1.45 / 4
_LEFT, _RIGHT = 0.42 / 4, (0.42 + 1.45 + 0.45) / 4
_UPPER, _LOWER = 1.0 - (0.2 + 1.45) / 4, 0.35 / 4
_BOXES = {"front": (_LEFT, _UPPER), "side": (_RIGHT, _UPPER), "top": (_LEFT, _LOWER)}
_KEY_BOX = (_RIGHT, _LOWER, 1.0 - _RIGHT - 0.05 / 4, _PANEL)


class ArmRenderer3D:
    """Draws frames of a spatial arm in three orthographic views.

    Front (x–y, seen from +z), side (z–y, seen from −x, looking along +x) and top (x–z,
    seen from +y, so +z points down the frame) views, each ±``extent`` around the base with
    axes in metres, and a panel with the legend and the caption. The figure is 4 in square
    at ``size``/4 dpi, so lines and text keep their proportions at every ``size``. The
    axes are drawn once; a frame restores them and draws only the moving artists over
    them, so it depends on its arguments alone.

    Args:
        extent: half-width of each square view around the base (m).
        size: frame width and height (pixels).
    """

    def __init__(self, extent: float, size: int = 400):
        _check_view(extent, size)
        self.extent = float(extent)
        self.figure = Figure(figsize=(4.0, 4.0), dpi=size / 4.0)
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes = {}
        self._views = []
        for name, h, v, flip, eye in _VIEWS:
            ax = self.figure.add_axes((*_BOXES[name], _PANEL, _PANEL))
            ax.set_xlim(-extent, extent)
            ax.set_ylim((extent, -extent) if flip else (-extent, extent))
            ax.set_aspect("equal")
            ax.xaxis.set_major_locator(MaxNLocator(5))
            ax.yaxis.set_major_locator(MaxNLocator(5))
            ax.tick_params(labelsize=5.5, length=2, pad=1.5)
            ax.set_xlabel(f"{_AXIS_NAMES[h]} (m)", fontsize=6.5, labelpad=1)
            ax.set_ylabel(f"{_AXIS_NAMES[v]} (m)", fontsize=6.5, labelpad=1)
            ax.set_title(f"{name}, seen from {eye}", fontsize=6.5, pad=3)
            ax.axhline(0.0, color="0.85", lw=0.6, zorder=0)
            ax.axvline(0.0, color="0.85", lw=0.6, zorder=0)
            self.axes[name] = ax
            view = {"ax": ax, "axes": (h, v), "objects": []}
            view.update({part: ax.plot([], [], animated=True, **style)[0] for part, style in _STYLES.items()})
            view["base"].set_data([0.0], [0.0])
            self._views.append(view)
        key = self.figure.add_axes(_KEY_BOX)
        key.set_axis_off()
        self._key = key
        self._legend = None
        self._legend_for = None
        self._background = None
        self._text = key.text(0.0, 0.38, "", transform=key.transAxes, va="top", ha="left",
                              fontsize=6, family="monospace", animated=True)

    def frame(self, backbone: np.ndarray, section_ends: np.ndarray, estimate: np.ndarray,
              estimate_tip: np.ndarray, target: np.ndarray | None = None,
              disc: tuple[np.ndarray, float] | None = None,
              objects: Sequence[Sphere | Cylinder] = (), caption: str = "") -> np.ndarray:
        """Draw one frame.

        Args:
            backbone: (N, 3) true backbone samples (m).
            section_ends: (n_sections, 3) true section-end positions (m).
            estimate: (K, 3) estimated backbone samples (m).
            estimate_tip: (3,) estimated tip (m).
            target: (3,) reach target (m), or None.
            disc: ``(center (2,), radius)`` of a planar task's disc in the x–y plane (m), or
                None: drawn as what planar contact models, a cylinder along z through the
                whole view.
            objects: further objects to draw (anything with ``outline(h, v)`` returning an
                (M, 2) polygon, such as :class:`Sphere` and :class:`Cylinder`).
            caption: text under the legend.

        Returns:
            (size, size, 3) uint8 RGB image.
        """
        backbone = _points("backbone", backbone)
        section_ends = _points("section_ends", section_ends)
        estimate = _points("estimate", estimate)
        estimate_tip = _points("estimate_tip", estimate_tip, single=True)
        if target is not None:
            target = _points("target", target, single=True)
        shapes = list(objects)
        if disc is not None:
            shapes.insert(0, Cylinder(center=(disc[0][0], disc[0][1], 0.0), axis=(0.0, 0.0, 1.0),
                                      radius=disc[1], length=4.0 * self.extent))
        self._update_legend(target is not None, bool(shapes))
        if self._background is None:
            self.canvas.draw()
            self._background = self.canvas.copy_from_bbox(self.figure.bbox)
        else:
            self.canvas.restore_region(self._background)
        for view in self._views:
            h, v = view["axes"]
            view["true"].set_data(backbone[:, h], backbone[:, v])
            view["ends"].set_data(section_ends[:, h], section_ends[:, v])
            view["estimate"].set_data(estimate[:, h], estimate[:, v])
            view["estimate_tip"].set_data(estimate_tip[[h]], estimate_tip[[v]])
            view["target"].set_data(*(([], []) if target is None else (target[[h]], target[[v]])))
            patches = view["objects"]
            while len(patches) < len(shapes):
                patch = Polygon(np.zeros((3, 2)), animated=True, **_OBJECT_STYLE)
                patches.append(view["ax"].add_patch(patch))
            for patch, shape in zip(patches, shapes):
                patch.set_xy(np.asarray(shape.outline(h, v), dtype=float))
                self.figure.draw_artist(patch)
            for name in _STYLES:
                self.figure.draw_artist(view[name])
        self._text.set_text(caption)
        self.figure.draw_artist(self._text)
        return np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()

    def _update_legend(self, has_target: bool, has_objects: bool) -> None:
        """Show the legend entries of what the frame holds (the axes are drawn anew on a change)."""
        if self._legend_for == (has_target, has_objects):
            return
        if self._legend is not None:
            self._legend.remove()
        entries = [(("ends", "true"), "true backbone, section ends"),
                   (("estimate_tip", "estimate"), "estimated backbone, tip"), (("base",), "base")]
        if has_target:
            entries.append((("target",), "target"))
        handles = [Line2D([], [], label=label, **{k: v for name in names for k, v in _STYLES[name].items()})
                   for names, label in entries]
        if has_objects:
            handles.append(Polygon(np.zeros((3, 2)), label="object", **_OBJECT_STYLE))
        self._legend = self._key.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, 1.0),
                                        fontsize=6, frameon=False, borderaxespad=0.0, handlelength=2.2)
        self._legend_for = (has_target, has_objects)
        self._background = None


def _points(name: str, value, single: bool = False) -> np.ndarray:
    """``value`` as float (N, 3) points, or (3,) with ``single``; a one-line error otherwise."""
    a = np.asarray(value, dtype=float)
    if (a.shape != (3,)) if single else (a.ndim != 2 or a.shape[1] != 3):
        raise ValueError(f"{name} must be {'a (3,) point' if single else '(N, 3) points'} (m); "
                         f"got shape {a.shape}")
    return a


class HumanWindow:
    """A pygame window that shows RGB frames at a fixed rate (``render_mode="human"``)."""

    def __init__(self, size: int, fps: int, title: str):
        try:
            import pygame
        except ImportError:
            from gymnasium.error import DependencyNotInstalled

            raise DependencyNotInstalled(
                'render_mode="human" needs pygame: pip install "softarm-gym[render]"') from None
        self._pygame = pygame
        pygame.display.init()
        pygame.display.set_caption(title)
        self._screen = pygame.display.set_mode((size, size))
        self._clock = pygame.time.Clock()
        self._fps = fps

    def show(self, rgb: np.ndarray) -> None:
        """Blit an (H, W, 3) uint8 frame and wait for the next tick."""
        pygame = self._pygame
        pygame.event.pump()
        surface = pygame.surfarray.make_surface(np.transpose(rgb, (1, 0, 2)))
        self._screen.blit(surface, (0, 0))
        pygame.display.flip()
        self._clock.tick(self._fps)

    def close(self) -> None:
        """Close the window."""
        self._pygame.display.quit()
        self._pygame.quit()
