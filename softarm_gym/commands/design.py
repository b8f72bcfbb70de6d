"""``softarm design``: optimal tube layouts by exhaustive search (thesis chapter 3)."""

from __future__ import annotations

import numpy as np

from softarm_gym import design_tools
from softarm_gym.cli import UsageError
from softarm_gym.commands.common import add_quiet_argument, parse_floats
from softarm_gym.commands.long_jobs import (
    add_job_arguments,
    check_outputs,
    finish,
    interruptible,
    runner_from_args,
    save_plot,
)
from softarm_gym.design_tools.sweep import DEFAULT_DESIGN_CHUNK, sweep_plan

NAME = "design"
HELP = "optimal tubes per section that maximise load capacity (thesis ch. 3, Figs. 3.4-3.7)"


def add_arguments(p):
    p.add_argument("--fluid", choices=tuple(design_tools.FLUIDS), default="pneumatic",
                   help="Table 3.1 design (default %(default)s)")
    p.add_argument("--constraint", choices=design_tools.CONSTRAINTS, default="tube-ratio",
                   help="how the tube size is fixed (default %(default)s)")
    p.add_argument("--sections", default="3",
                   help="number of sections, or a comma-separated list (one curve each)")
    p.add_argument("--lengths", default=None,
                   help="swept sizes in m, comma separated: total length, or the distal section "
                        "length for gripping-radius (default: 0.25..4 m, or 0.1..1 m)")
    p.add_argument("--youngs-modulus", default=None,
                   help="tube Young's modulus in Pa, or a comma-separated list (default Table 3.1)")
    p.add_argument("--template-pressure", choices=design_tools.TEMPLATE_PRESSURES, default="max",
                   help="pressure of the dexterity template: p_max as Eq. 3.3, or p_test")
    p.add_argument("--tapered", action="store_true",
                   help="only layouts whose tube count never grows towards the tip")
    p.add_argument("--plot", metavar="FILE.png", help="plot the load capacity of the best layouts")
    add_quiet_argument(p)
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_job_arguments(p, "(size, layout) evaluations per chunk (default %(default)s: ~1 s)",
                      DEFAULT_DESIGN_CHUNK)


MAX_SECTIONS = 8
"""Largest ``--sections``: the exhaustive search tries 4^N layouts at every size (65,536 at N = 8)."""


def _sections(text: str) -> list[int]:
    values = parse_floats(text, "--sections")
    if values.size == 0 or np.any(values != np.round(values)) or np.any(values < 1):
        raise UsageError(f"--sections must be integers >= 1; got {text!r}")
    if np.any(values > MAX_SECTIONS):
        raise UsageError(f"--sections must be at most {MAX_SECTIONS} (MAX_SECTIONS: the exhaustive search "
                         f"tries 4^N layouts per size, 4^{MAX_SECTIONS} = {4 ** MAX_SECTIONS:,}); "
                         f"got {text!r}")
    return [int(v) for v in values]


@interruptible
def run(args) -> int:
    sections = _sections(args.sections)
    sizes = None if args.lengths is None else parse_floats(args.lengths, "--lengths")
    moduli = [None] if args.youngs_modulus is None else list(
        parse_floats(args.youngs_modulus, "--youngs-modulus"))
    check_outputs(args, images=("plot",))
    runner = runner_from_args(args, progress=not args.quiet)
    plans = [sweep_plan(args.fluid, args.constraint, n, sizes, tapered=args.tapered,
                        template_pressure=args.template_pressure, youngs_modulus=modulus,
                        chunk_size=args.chunk_size)
             for n in sections for modulus in moduli]
    sweeps = runner.run_plans(plans, desc=f"{args.fluid} {args.constraint} designs", unit="design")
    runs = [s.to_dict() for s in sweeps]
    best = max((s.best for s in sweeps if s.best is not None), key=lambda c: c.load_n, default=None)
    best_dict = None if best is None else {"tubes": list(best.tubes), "length_m": best.length_m,
                                           "load_n": best.load_n}
    payload = dict(runs[0]) if len(runs) == 1 else {"best": best_dict, "runs": runs}
    payload["best"] = best_dict
    if args.plot:
        from softarm_gym.design_tools.plots import plot_sweeps

        save_plot(plot_sweeps, args.plot, sweeps)
    finish(args, payload, _text(sweeps, best), runner)
    return 0 if best is not None else 1


def _text(sweeps, best) -> str:
    lines = []
    for s in sweeps:
        lines.append(f"{s.fluid} {s.constraint} N={s.n_sections} E={s.params.youngs_modulus:.3g} Pa "
                     f"(template at p_{s.template_pressure}):")
        size_name = "L_N" if s.constraint == "gripping-radius" else "L"
        for size, c in zip(s.sizes, s.best_per_size):
            if c is None:
                lines.append(f"  {size_name} = {size:6.3f} m   no feasible layout")
                continue
            fold = "  (fold)" if c.fold_limited else ""
            # The swept size is the length itself except under the gripping-radius constraint.
            length = "" if size_name == "L" else f"   L = {c.length_m:6.3f} m"
            lines.append(f"  {size_name} = {size:6.3f} m   best {'-'.join(map(str, c.tubes)):>14}"
                         f"{length}   t = {c.thickness_m * 1e3:6.2f} mm"
                         f"   W = {c.load_n:9.2f} N{fold}")
    if best is None:
        lines.append("no feasible layout")
    else:
        lines.append(f"best: {'-'.join(map(str, best.tubes))} at L = {best.length_m:.3f} m, "
                     f"W = {best.load_n:.2f} N")
    return "\n".join(lines)
