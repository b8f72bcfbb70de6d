"""``softarm estimators``: the chapter-4 shape-estimation study on OctArm VI (Figs. 4.4–4.6)."""

from __future__ import annotations

import sys

import numpy as np
from tqdm import tqdm

from softarm_gym.cli import UsageError, emit
from softarm_gym.commands.common import (
    add_numba_threads_argument,
    add_output_argument,
    add_payload_argument,
    add_quiet_argument,
    parse_floats,
)
from softarm_gym.files import write_json

NAME = "estimators"
HELP = ("RMS tip error of every shape estimator over the 64 on/off configurations of OctArm VI "
        "(0-90 psi, horizontal and vertical base, with and without sensor noise, unknown payload)")

STUDY_PAYLOAD_N = 10.0
"""The unknown tip payload of the thesis's Fig. 4.6 study (N)."""
STANDARD_GRAVITY = 9.81
"""g (m/s²) turning ``--payload-kg`` into the study's payload weight."""

STYLE = {"model": ":", "constant_curvature": "-.", "cable_encoder": "-", "inclinometer": "--",
         "load_cell": (0, (5, 1, 1, 1))}
SENSING = {"perfect": "perfect sensors", "table4.3": "Table 4.3 resolution (simulated)",
           "bound": "Table 4.3, linearised bound (Eq. 4.12)"}


def add_arguments(p):
    p.add_argument("--pressures-psi", default="0,10,20,30,40,50,60,70,80,90",
                   help="pressure levels in psi (default %(default)s)")
    add_payload_argument(p, default=STUDY_PAYLOAD_N / STANDARD_GRAVITY,
                         help="mass of the unknown tip payload of the Fig. 4.6 study (kg; default "
                              f"{STUDY_PAYLOAD_N / STANDARD_GRAVITY:.4g}, the thesis's 10 N)")
    p.add_argument("--base-inclinometer-deg", type=float, default=None,
                   help="base inclinometer resolution (deg) of the noisy sensors (default: the "
                        "0.05 deg USD-T2 of §4.3; Table 4.3's 2.5 deg applies to the others)")
    add_output_argument(p, help="write the full result table as JSON", old=("--json-out",))
    p.add_argument("--plot", metavar="PATH", help="Figs. 4.4-4.5 style plot (PNG)")
    p.add_argument("--payload-plot", metavar="PATH", help="Fig. 4.6 style payload plot (PNG)")
    add_quiet_argument(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    add_numba_threads_argument(p)


def run(args) -> int:
    from softarm_gym.sensing.sensors import SensorNoise
    from softarm_gym.sensing.study import run_study, total_steps

    levels = parse_floats(args.pressures_psi, "--pressures-psi")
    if levels.size == 0:
        raise UsageError("--pressures-psi needs at least one level")
    overrides = {} if args.base_inclinometer_deg is None else {
        "base_inclinometer_resolution_deg": args.base_inclinometer_deg}
    try:
        noise = SensorNoise.thesis(**overrides)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    bar = tqdm(total=total_steps(levels.size), file=sys.stderr, disable=args.quiet,
               desc="estimators")
    try:
        result = run_study(pressures_psi=levels, payload_n=args.payload_kg * STANDARD_GRAVITY, noise=noise,
                           progress=bar)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    finally:
        bar.close()
    if args.output:
        write_json(args.output, result, indent=1)
    if args.plot:
        plot_study(result, args.plot)
    if args.payload_plot:
        plot_payload(result, args.payload_plot)
    emit(result, args.json, format_table(result))
    return 0


def format_table(result: dict) -> str:
    """Peak and per-level RMS tip error / L of every estimator, one block per case."""
    levels = result["pressures_psi"]
    head = "estimator".ljust(20) + "".join(f"{p:>7.0f}" for p in levels) + "   peak"
    lines = [f"{result['design']}: RMS tip error / L over the 64 configurations "
             f"(L = {result['length_m']:.3f} m, {result['seconds']:.0f} s)"]

    def block(title, table):
        lines.append("")
        lines.append(title)
        lines.append(head)
        for name, row in table.items():
            rms = np.array(row["rms_over_L"])
            lines.append(name.ljust(20) + "".join(f"{v:7.3f}" for v in rms) + f"{np.nanmax(rms):7.3f}")

    for label, data in result["orientations"].items():
        for key, title in SENSING.items():
            block(f"{label} base ({data['base_angle_deg']:.0f} deg), {title}", data[key])
        groups = [k.split(":", 1)[1] for k in data if k.startswith("bound:")]
        lines.append("")
        lines.append(f"{label} base, linearised bound by sensor: peak over pressure of the RMS / L")
        lines.append("estimator".ljust(20) + "".join(f"{g[:16]:>17}" for g in groups))
        for name in data["bound"]:
            if name != "model":
                lines.append(name.ljust(20) + "".join(
                    f"{np.nanmax(data['bound:' + g][name]['rms_over_L']):17.4f}" for g in groups))
        if data["excluded_truths"]:
            lines.append(f"  ({len(data['excluded_truths'])} truths left out: no stable converged solve)")
    for label, data in result["payload"].items():
        for key in ("perfect", "table4.3"):
            block(f"{label} base, unknown {data['payload_n']:g} N payload, {SENSING[key]}", data[key])
    return "\n".join(lines)


BANDS = ("Lines: RMS tip error / L over the 64 on/off configurations at each pressure level. "
         "Bands: ± one standard deviation of the tip error / L over those configurations.")
"""The caption of the study's figures (what the lines and the shaded bands are)."""


def _panel(ax, levels, table, names):
    for name in names:
        rms = np.array(table[name]["rms_over_L"])
        std = np.array(table[name]["std_over_L"])
        line, = ax.plot(levels, rms, linestyle=STYLE.get(name, "-"), label=name)
        ax.fill_between(levels, np.maximum(rms - std, 0), rms + std, color=line.get_color(), alpha=0.12)
    ax.set_xlabel("pressure (psi)")
    ax.grid(alpha=0.3)


def plot_study(result: dict, path):
    """Figs. 4.4–4.5 style: RMS tip error / L against pressure (±1 std shaded); returns the figure."""
    from softarm_gym.plotting import figure, save

    levels = result["pressures_psi"]
    orients = list(result["orientations"])
    fig, axes = figure(len(SENSING), len(orients), figsize=(5.5 * len(orients), 3.4 * len(SENSING)),
                       squeeze=False, sharex=True)
    for c, label in enumerate(orients):
        data = result["orientations"][label]
        names = [n for n in data["perfect"] if n != "model"]
        for r, (key, title) in enumerate(SENSING.items()):
            ax = axes[r, c]
            _panel(ax, levels, data[key], names)
            ax.set_title(f"{label} base: {title}", fontsize=9)
            ax.set_ylabel("RMS tip error / L (–)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(BANDS, fontsize=8, wrap=True)
    return save(fig, path)


def plot_payload(result: dict, path):
    """Fig. 4.6 style: estimators without and with an unknown tip payload; returns the figure."""
    from softarm_gym.plotting import figure, save

    levels = result["pressures_psi"]
    orients = list(result["payload"])
    fig, axes = figure(3, len(orients), figsize=(5.5 * len(orients), 9.5), squeeze=False, sharex=True)
    for c, label in enumerate(orients):
        pay = result["payload"][label]
        names = list(pay["perfect"])
        rows = ((result["orientations"][label]["perfect"], "no payload, perfect sensors"),
                (pay["perfect"], f"unknown {pay['payload_n']:g} N payload, perfect sensors"),
                (pay["table4.3"], f"unknown {pay['payload_n']:g} N payload, Table 4.3 resolution"))
        for r, (table, title) in enumerate(rows):
            ax = axes[r, c]
            _panel(ax, levels, table, names)
            ax.set_title(f"{label} base: {title}", fontsize=9)
            ax.set_ylabel("RMS tip error / L (–)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(BANDS, fontsize=8, wrap=True)
    return save(fig, path)
