"""``softarm solve``: one equilibrium, printed for people or as JSON."""

from __future__ import annotations

import solver
from softarm_gym.cli import UsageError, emit
from softarm_gym.commands.common import (
    add_design_arguments,
    add_output_argument,
    add_payload_argument,
    design_from_args,
    pressures_from_psi,
)
from softarm_gym.files import write_json

NAME = "solve"
HELP = "solve one static equilibrium of a soft arm"


def add_arguments(p):
    add_design_arguments(p)
    p.add_argument("--pressures-psi", default="", help="channel pressures in psi, comma separated "
                   "(planar order s1_I,s1_II+III,...; spatial with --spatial)")
    p.add_argument("--base-angle", type=float, default=0.0,
                   help="deg from the downward vertical towards +x (0 hangs, 90 horizontal)")
    add_payload_argument(p)
    p.add_argument("--gravity", type=float, default=9.81, help="m/s^2 (0 switches it off)")
    p.add_argument("--model", default="full", choices=solver.MODELS)
    p.add_argument("--spatial", action="store_true", help="3D solve (one pressure per channel)")
    p.add_argument("--shape", action="store_true", help="include backbone samples in the output")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_output_argument(p)


def run(args) -> int:
    arm = design_from_args(args)
    planar = not args.spatial
    pressures = pressures_from_psi(args.pressures_psi, arm, planar)
    try:
        scene = solver.Scene(base_angle_deg=args.base_angle, payload_kg=args.payload_kg,
                             gravity=args.gravity)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    try:
        eq = solver.solve(arm, pressures, scene, model=args.model, planar=planar,
                          record=args.shape)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    payload = {"design": arm.name, "tip": eq.tip, "converged": eq.converged,
               "stable": eq.stable, "snapped": eq.snapped, "iterations": eq.iterations,
               "residual": eq.residual, "model": eq.model, "planar": eq.planar}
    if args.shape:
        payload["s"] = eq.s
        payload["positions"] = eq.positions
    tip = ", ".join(f"{v:+.4f}" for v in eq.tip)
    text = (f"{arm.name} tip = ({tip}) m   converged={eq.converged} stable={eq.stable} "
            f"snapped={eq.snapped} iterations={eq.iterations} residual={eq.residual:.2e} N m")
    if args.output:
        write_json(args.output, payload)
    emit(payload, args.json, text)
    return 0 if eq.converged else 1
