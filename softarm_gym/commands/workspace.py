"""``softarm workspace``: the tip cloud over a pressure grid, and the thesis's workspace studies.

Default: the thesis grid (7 levels, 0 to the rated pressure, every planar channel) for one
design and scene. ``--reproduce`` reruns Table 2.2 (``table-2.2``), the Fig. 2.7/2.8 trio
(``fig-2.7``: unloaded, self-weight, self-weight + 0.25 kg at ``--base-angle``) or the
§5.3.1 comparison (``fig-5.4``).
"""

from __future__ import annotations

import math
import time

import solver
from softarm_gym.analysis import reproduce
from softarm_gym.analysis.sweep import DEFAULT_CHUNK, DEFAULT_SPATIAL_CHUNK
from softarm_gym.analysis.workspace import workspace_plan
from softarm_gym.cli import UsageError
from softarm_gym.commands.common import (
    add_design_arguments,
    add_payload_argument,
    add_quiet_argument,
    design_from_args,
)
from softarm_gym.commands.long_jobs import (
    add_job_arguments,
    check_outputs,
    finish,
    interruptible,
    runner_from_args,
    save_plot,
)

NAME = "workspace"
HELP = "sweep the pressure grid: tip cloud, area, density, highest and mean tip"
REPRODUCTIONS = ("table-2.2", "fig-2.7", "fig-5.4")


def add_arguments(p):
    add_design_arguments(p)
    add_grid_arguments(p)
    p.add_argument("--spatial", action="store_true",
                   help="one pressure per spatial channel, 3-D tips (area of the x-y projection)")
    p.add_argument("--alpha", type=float, default=None,
                   help="alpha-shape radius for the area (m; default 0.1 L)")
    add_job_arguments(p, f"grid rows per chunk (default {DEFAULT_CHUNK} planar, "
                         f"{DEFAULT_SPATIAL_CHUNK} spatial: ~1 s each)")
    p.add_argument("--reproduce", choices=REPRODUCTIONS, default=None,
                   help="rerun a thesis study instead of a single sweep")
    p.add_argument("--plot", metavar="FILE.png", default=None, help="save a picture")
    p.add_argument("--json", action="store_true", help="machine-readable output")


def add_grid_arguments(p):
    """Scene and grid options shared with ``softarm dexterity``."""
    p.add_argument("--base-angle", type=float, default=0.0,
                   help="deg from the downward vertical towards +x (0 hangs, 90 horizontal)")
    add_payload_argument(p)
    p.add_argument("--gravity", type=float, default=9.81, help="m/s^2 (0 switches it off)")
    p.add_argument("--model", default="full", choices=solver.MODELS)
    p.add_argument("--levels", type=int, default=7, help="pressure levels per channel (default 7)")
    p.add_argument("--max-psi", type=float, default=None,
                   help="top pressure level in psi (default: the design's rated maximum)")
    add_quiet_argument(p)


@interruptible
def run(args) -> int:
    check_outputs(args, images=("plot",))
    runner = runner_from_args(args, progress=not args.quiet)
    if args.reproduce == "table-2.2":
        return _table_2_2(args, runner)
    if args.reproduce == "fig-5.4":
        return _fig_5_4(args, runner)
    arm = design_from_args(args)
    max_pressure = None if args.max_psi is None else args.max_psi * solver.PSI
    options = dict(levels=args.levels, max_pressure=max_pressure, model=args.model,
                   planar=not args.spatial, alpha=args.alpha, chunk_size=args.chunk_size)
    if args.reproduce == "fig-2.7":
        return _fig_2_7(args, runner, arm, options)
    scene = solver.Scene(base_angle_deg=args.base_angle, payload_kg=args.payload_kg,
                         gravity=args.gravity)
    (ws,) = runner.run_plans([workspace_plan(arm, scene, **options)], desc=f"{arm.name} sweep")
    payload = ws.summary()
    if args.plot:
        from softarm_gym.analysis.figures import plot_workspaces

        save_plot(plot_workspaces, args.plot, [ws])
        payload["plot"] = args.plot
    finish(args, payload, _describe(ws), runner)
    return 0


def _describe(ws) -> str:
    tip = ", ".join(f"{v:+.4f}" for v in ws.mean_tip)
    top = ", ".join(f"{v:+.4f}" for v in ws.highest_tip)
    return (f"{ws.design} base {ws.scene.base_angle_deg:g} deg, {ws.model}: n = {ws.n} "
            f"({ws.n_failed} unconverged) in {ws.seconds:.2f} s\n"
            f"  mean tip ({tip}) m, highest tip ({top}) m\n"
            f"  area {ws.area_m2:.4f} m^2 = {ws.area_fraction:.3f} pi L^2 (alpha shape, "
            f"alpha {ws.alpha:.3g} m); convex hull {ws.hull_area_m2:.4f} m^2; "
            f"occupied 1 cm cells {ws.occupancy_area(0.01):.4f} m^2")


def _check_fixed_designs(args) -> None:
    if args.design_file or args.ei or args.spatial or args.alpha is not None:
        raise UsageError(f"--reproduce {args.reproduce} fixes the designs and the area method; "
                         "drop --design-file/--ei/--spatial/--alpha")


def _table_2_2(args, runner) -> int:
    _check_fixed_designs(args)
    start = time.perf_counter()
    rows = reproduce.table_2_2(levels=args.levels, runner=runner, chunk_size=args.chunk_size)
    rms = reproduce.closest_reading(rows)
    closest = min((v, k) for k, v in rms.items() if v is not None)[1] if rms else None
    lines = ["Table 2.2: mean tip y over the OctArm V workspace (m)",
             f"{'ei':8s} {'base':>5s} {'cc':>8s} {'full':>8s} {'diff':>7s} | thesis {'cc':>7s} "
             f"{'full':>7s} {'diff':>6s} | s(full) s(cc)"]
    for r in rows:
        th = (f"{r['thesis_cc']:7.3f} {r['thesis_full']:7.3f} {r['thesis_difference']:6.3f}"
              if r["thesis_cc"] is not None else f"{'-':>7s} {'-':>7s} {'-':>6s}")
        lines.append(f"{r['ei']:8s} {r['base_angle_deg']:5.0f} {r['cc_mean_y']:8.3f} "
                     f"{r['full_mean_y']:8.3f} {r['difference']:7.3f} |        {th} | "
                     f"{r['seconds_full']:6.1f} {r['seconds_cc']:5.1f}")
    lines.append("RMS difference from the thesis: " +
                 ", ".join(f"{k} {v:.3f} m" for k, v in rms.items() if v is not None) +
                 f"; closest: {closest}")
    finish(args, {"rows": rows, "rms_vs_thesis": rms, "closest": closest,
                  "seconds": time.perf_counter() - start}, "\n".join(lines), runner)
    return 0


def _fig_2_7(args, runner, arm, options) -> int:
    if args.payload_kg or args.gravity != 9.81:
        raise UsageError("--reproduce fig-2.7 sets gravity and payload itself; drop --payload/--gravity")
    scenes = {"no loading": solver.Scene(base_angle_deg=args.base_angle, gravity=0.0),
              "self-weight": solver.Scene(base_angle_deg=args.base_angle),
              "self-weight + 0.25 kg": solver.Scene(base_angle_deg=args.base_angle, payload_kg=0.25)}
    plans = [workspace_plan(arm, scene, **options) for scene in scenes.values()]
    spaces = dict(zip(scenes, runner.run_plans(plans, desc="fig 2.7 sweeps")))
    payload = {label: ws.summary() for label, ws in spaces.items()}
    if args.plot:
        from softarm_gym.analysis.figures import plot_workspaces

        save_plot(plot_workspaces, args.plot, spaces.values(), labels=list(spaces))
        payload["plot"] = args.plot
    finish(args, payload, "\n".join(f"[{label}] {_describe(ws)}" for label, ws in spaces.items()),
           runner)
    return 0


def _fig_5_4(args, runner) -> int:
    _check_fixed_designs(args)
    max_psi = 70.0 if args.max_psi is None else args.max_psi
    spaces = reproduce.ct_vs_octarm(levels=args.levels, max_psi=max_psi, runner=runner,
                                    chunk_size=args.chunk_size)
    payload = {"workspaces": {label: ws.summary() for label, ws in spaces.items()},
               "thesis": reproduce.THESIS_5_3_1, "endplate_mass_kg": reproduce.ENDPLATE_MASS}
    if args.plot:
        from softarm_gym.analysis.figures import plot_workspaces

        save_plot(plot_workspaces, args.plot, spaces.values(), labels=list(spaces))
        payload["plot"] = args.plot
    lines = [f"[{label}] {_describe(ws)}\n  convex hull "
             f"{ws.hull_area_m2 / (math.pi * ws.length**2):.3f} pi L^2" for label, ws in spaces.items()]
    lines.append("thesis: OctArm highest (+-0.31, -0.02) m, area 0.5 pi L^2; "
                 "CT highest (+-0.37, 0.11) m, area 0.6 pi L^2")
    finish(args, payload, "\n".join(lines), runner)
    return 0
