"""``softarm dexterity``: Jacobian-based dexterity measures over the workspace (thesis ch. 5).

Default: a dexterity map of one design over the thesis grid (σ_min, σ_max, manipulability,
isotropy, condition number at every point) and its dexterous area versus σ_min threshold.
``--reproduce fig-5.5`` compares the two-section OctArm with the CT arm (hanging, 7⁴ grid,
0–70 psi): ``--plot`` gets Fig. 5.5, ``--area-plot`` Fig. 5.6.
"""

from __future__ import annotations

import math

import numpy as np

import solver
from softarm_gym.analysis import reproduce
from softarm_gym.analysis.manipulability import (
    DEFAULT_DEXTERITY_CHUNK,
    DEFAULT_REL_STEP,
    MEASURES,
    dexterity_plan,
)
from softarm_gym.cli import UsageError
from softarm_gym.commands.common import add_design_arguments, design_from_args
from softarm_gym.commands.long_jobs import (
    add_job_arguments,
    check_outputs,
    finish,
    interruptible,
    runner_from_args,
    save_plot,
)
from softarm_gym.commands.workspace import add_grid_arguments

NAME = "dexterity"
HELP = "dexterity measures (singular values of the pressure-to-tip Jacobian) over the workspace"


def add_arguments(p):
    add_design_arguments(p)
    add_grid_arguments(p)
    p.add_argument("--rel-step", type=float, default=DEFAULT_REL_STEP,
                   help="finite-difference step as a fraction of the rated pressure (default %(default)g)")
    p.add_argument("--thresholds", type=int, default=21,
                   help="number of sigma_min thresholds for the dexterous-area curve (default 21)")
    p.add_argument("--reproduce", choices=("fig-5.5",), default=None,
                   help="compare the §5.3 OctArm and CT arms instead of one design")
    p.add_argument("--plot", metavar="FILE.png", default=None, help="save the dexterity maps")
    p.add_argument("--area-plot", metavar="FILE.png", default=None,
                   help="save the dexterous area versus sigma_min threshold (Fig. 5.6)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_job_arguments(p, "grid points per chunk (default %(default)s: ~2 s for OctArm V)",
                      DEFAULT_DEXTERITY_CHUNK)


@interruptible
def run(args) -> int:
    if args.thresholds < 2:
        raise UsageError(f"--thresholds must be >= 2; got {args.thresholds}")
    check_outputs(args, images=("plot", "area_plot"))
    runner = runner_from_args(args, progress=not args.quiet)
    if args.reproduce:
        if args.design_file or args.ei:
            raise UsageError("--reproduce fig-5.5 fixes the designs; drop --design-file/--ei")
        max_psi = 70.0 if args.max_psi is None else args.max_psi
        maps = reproduce.dexterity_comparison(levels=args.levels, max_psi=max_psi, runner=runner,
                                              chunk_size=args.chunk_size)
    else:
        arm = design_from_args(args)
        scene = solver.Scene(base_angle_deg=args.base_angle, payload_kg=args.payload_kg,
                             gravity=args.gravity)
        max_pressure = None if args.max_psi is None else args.max_psi * solver.PSI
        plan = dexterity_plan(arm, scene, levels=args.levels, max_pressure=max_pressure,
                              model=args.model, rel_step=args.rel_step, chunk_size=args.chunk_size)
        maps = {arm.name: runner.run_plans([plan], desc=f"{arm.name} dexterity")[0]}
    curves = reproduce.dexterous_area_curves(maps, args.thresholds)
    payload = {"maps": {}, "thresholds_m_per_pa": next(iter(curves.values()))[0]}
    lines = []
    for label, dm in maps.items():
        thresholds, areas, length = curves[label]
        summary = dm.summary()
        summary["dexterous_area_m2"] = areas
        summary["dexterous_fraction"] = areas / areas[0] if areas[0] > 0 else np.zeros_like(areas)
        summary["dexterous_area_pi_L2"] = areas / (math.pi * length**2)
        payload["maps"][label] = summary
        lines.append(f"{label}: {summary['n_valid']}/{summary['n']} valid points in "
                     f"{summary['seconds']:.2f} s")
        lines.append("  medians: " + ", ".join(f"{m} {summary['median_' + m]:.4g}" for m in MEASURES
                                               if summary["median_" + m] is not None))
        lines.append("  dexterous fraction at sigma_min >= " + ", ".join(
            f"{t / 1e-8:.3g}e-8: {f:.2f}" for t, f in
            list(zip(thresholds, summary["dexterous_fraction"]))[:: max(1, len(thresholds) // 5)]))
    if args.plot:
        from softarm_gym.analysis.figures import plot_dexterity

        save_plot(plot_dexterity, args.plot, maps.values(), labels=list(maps))
        payload["plot"] = args.plot
    if args.area_plot:
        from softarm_gym.analysis.figures import plot_dexterous_area

        save_plot(plot_dexterous_area, args.area_plot, curves)
        payload["area_plot"] = args.area_plot
    finish(args, payload, "\n".join(lines), runner)
    return 0
