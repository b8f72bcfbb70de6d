"""Matplotlib helpers shared by the demo, the analyses and the renderers (Agg backend)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def figure(*args, **kwargs):
    """A new figure on the non-interactive backend."""
    return plt.subplots(*args, **kwargs)


def save(fig, path) -> None:
    """Save and close ``fig``."""
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def draw_backbone(ax, positions, section_ends=(), **style):
    """Plot a planar backbone (N, 2) with dots at the section ends."""
    line, = ax.plot(positions[:, 0], positions[:, 1], **style)
    if len(section_ends):
        ends = positions[list(section_ends)]
        ax.plot(ends[:, 0], ends[:, 1], "o", color=line.get_color(), ms=3)
    return line
