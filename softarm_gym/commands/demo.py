"""``softarm demo``: the main job of ``make demo``.

Solves each named design under gravity at a few pressure patterns and base angles and
saves a picture of the shapes.
"""

from __future__ import annotations

import time

import numpy as np

import solver
from softarm_gym.plotting import draw_backbone, figure, save

NAME = "demo"
HELP = "solve each design under gravity and save a picture of the shapes"


def add_arguments(p):
    p.add_argument("--out", default="demo.png", help="image file to write (default %(default)s)")


def run(args) -> int:
    designs = [solver.designs.octarm_v(), solver.designs.octarm_vi(), solver.designs.ct()]
    angles = (0.0, 90.0)
    fig, axes = figure(len(angles), len(designs), figsize=(4 * len(designs), 7.5))
    start = time.perf_counter()
    for col, arm in enumerate(designs):
        n = arm.n_inputs(True)
        patterns = {"unactuated": np.zeros(n),
                    "channel I at 60%": np.where(np.arange(n) % 2 == 0, 0.6, 0.0),
                    "II+III at 60%": np.where(np.arange(n) % 2 == 1, 0.6, 0.0),
                    "all at 100%": np.ones(n)}
        for row, angle in enumerate(angles):
            ax = axes[row, col]
            scene = solver.Scene(base_angle_deg=angle)
            for label, frac in patterns.items():
                eq = solver.solve(arm, frac * arm.max_pressure, scene)
                draw_backbone(ax, eq.positions, eq.section_ends, label=label)
                print(f"{arm.name:10s} base {angle:5.1f} deg  {label:18s} tip "
                      f"({eq.tip[0]:+.3f}, {eq.tip[1]:+.3f}) m  converged={eq.converged} "
                      f"stable={eq.stable}")
            ax.plot([0], [0], "ks")
            ax.set_aspect("equal")
            ax.set_title(f"{arm.name}, base {angle:g} deg", fontsize=9)
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    save(fig, args.out)
    print(f"wrote {args.out} ({time.perf_counter() - start:.1f} s)")
    return 0
