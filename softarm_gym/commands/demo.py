"""``softarm demo``: the main job of ``make demo``.

Runs a reach episode on ``SoftArm/OctArmReach-v1`` (a damped least-squares Jacobian
controller on the nominal model, acting on the estimator's observation), prints its metrics
and saves it as a GIF; then solves each named design under gravity at a few pressure
patterns and base angles and saves a picture of the shapes.
"""

from __future__ import annotations

import time

import numpy as np

import solver
from softarm_gym.cli import UsageError
from softarm_gym.plotting import draw_backbone, few_ticks, figure, save

NAME = "demo"
HELP = "run a reach episode (GIF) and picture every design's shapes under gravity"


def add_arguments(p):
    p.add_argument("--out-dir", default="demo", help="folder for the outputs (default %(default)s)")
    p.add_argument("--observation", default="true",
                   help="shape estimator the controller sees (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="episode seed (default %(default)s)")


def run(args) -> int:
    from pathlib import Path

    from softarm_gym.envs.demo import run_demo_episode

    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UsageError(f"--out-dir {str(out_dir)!r} exists and is not a folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    episode = run_demo_episode(out_dir / "reach_demo.gif", observation=args.observation,
                               seed=args.seed)
    distances = episode["distances"]
    print(f"reach episode ({args.observation} observations): distance {1000 * distances[0]:.1f} mm "
          f"-> {1000 * episode['final_distance']:.1f} mm in {len(distances) - 1} steps, "
          f"success={episode['success']}, median estimation error "
          f"{1000 * float(np.median(episode['estimation_errors'])):.1f} mm; wrote {episode['out']} "
          f"({time.perf_counter() - start:.1f} s)")
    shapes_figure(out_dir / "demo_shapes.png")
    return 0


def shapes_figure(out):
    """Every named design under gravity at a few pressure patterns and base angles; returns the figure."""
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
            # Equal scales by widening the data limits, not by shrinking a narrow panel.
            ax.set_aspect("equal", adjustable="datalim")
            few_ticks(ax, 4)
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.set_title(f"{arm.name}, base {angle:g} deg", fontsize=9)
            ax.grid(alpha=0.3)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncols=4, fontsize=8)
    save(fig, out)
    print(f"wrote {out} ({time.perf_counter() - start:.1f} s)")
    return fig
