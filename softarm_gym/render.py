"""Frames of a planar soft arm for the environments' ``render()``.

:class:`ArmRenderer` draws, on one reusable matplotlib figure (Agg canvas, no pyplot
state): the true backbone with its section ends, the estimated backbone and tip overlaid in
another colour, and the task (a reach target or a disc to wrap). ``rgb_array`` returns
the frame; ``human`` shows it in a pygame window (``pip install pygame``).
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle

__all__ = ["ArmRenderer", "HumanWindow"]

TRUE_COLOUR = "#1f4e9c"
ESTIMATE_COLOUR = "#e8710a"
TARGET_COLOUR = "#2ca02c"
OBJECT_COLOUR = "#7f7f7f"


class ArmRenderer:
    """Draws frames of a planar arm; artists are created once and updated per frame.

    Args:
        extent: half-width of the square view around the base (m).
        size: frame width and height (pixels).
    """

    def __init__(self, extent: float, size: int = 400):
        if not (np.isfinite(extent) and extent > 0):
            raise ValueError(f"extent must be a finite length > 0 (m); got {extent!r}")
        if int(size) != size or size < 64:
            raise ValueError(f"size must be an integer >= 64 pixels; got {size!r}")
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
        self._text = ax.text(0.02, 0.98, "", transform=ax.transAxes, va="top", ha="left",
                             fontsize=8, family="monospace", zorder=6)

    def frame(self, backbone: np.ndarray, section_ends: np.ndarray, estimate: np.ndarray,
              estimate_tip: np.ndarray, target: np.ndarray | None = None,
              disc: tuple[np.ndarray, float] | None = None, caption: str = "") -> np.ndarray:
        """Draw one frame.

        Args:
            backbone: (N, 2) true backbone samples (m).
            section_ends: (n_sections, 2) true section-end positions (m).
            estimate: (K, 2) estimated backbone samples (m).
            estimate_tip: (2,) estimated tip (m).
            target: (2,) reach target (m), or None.
            disc: ``(centre (2,), radius)`` of an object to wrap (m), or None.
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
        self._text.set_text(caption)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()


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
