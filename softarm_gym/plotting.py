"""Matplotlib helpers shared by the demo, the analyses and the renderers (Agg backend)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

SEQUENTIAL_CMAP = "viridis"
"""Colour map of every value-coded plot: perceptually uniform and readable in grey."""


def figure(*args, **kwargs):
    """A new figure on the non-interactive backend, ``plt.subplots`` arguments.

    Constrained layout by default, so titles, tick labels and colourbars do not overlap.
    """
    kwargs.setdefault("layout", "constrained")
    return plt.subplots(*args, **kwargs)


def few_ticks(ax, n: int = 5) -> None:
    """At most ``n`` major ticks per axis (dense panels otherwise run their tick labels together)."""
    ax.xaxis.set_major_locator(MaxNLocator(n))
    ax.yaxis.set_major_locator(MaxNLocator(n))


def save(fig, path):
    """Save and close ``fig``; return it (closed figures can still be inspected)."""
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return fig


def draw_backbone(ax, positions, section_ends=(), **style):
    """Plot a planar backbone (N, 2) with dots at the section ends."""
    line, = ax.plot(positions[:, 0], positions[:, 1], **style)
    if len(section_ends):
        ends = positions[list(section_ends)]
        ax.plot(ends[:, 0], ends[:, 1], "o", color=line.get_color(), ms=3)
    return line
