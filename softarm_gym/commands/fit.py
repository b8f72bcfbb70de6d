"""``softarm fit``: calibrate a design to measured shapes (docs/identification.md).

Default: fit ``--params`` of the design to the data file ``--data`` (the CSV format of
:mod:`softarm_gym.identify.data`) by robust least squares (:func:`solver.identify.fit`):
the fitted values with 95 % intervals, what the data cannot identify, the χ² test of the
model, the error on held-out configurations. ``--output`` writes the fit file (also the
``randomization=`` of the environments), ``--save-design`` the fitted design (a design
file for ``--design-file``), ``--plot`` the residual figure.

``--make-synthetic FILE.csv`` writes data of a perturbed arm instead (``--truth``), made by
the solver at the thesis's on/off configurations; ``--reproduce`` reruns a validation study:
``fig-2.6`` (mean tip error against pressure before and after the fit), ``noise``
(parameter error against noise level) or ``sensitivity`` (why the wind angle dominates).
"""

from __future__ import annotations

import json
import sys

import numpy as np
from tqdm import tqdm

import solver
import solver.identify
from softarm_gym.cli import UsageError, emit
from softarm_gym.commands.common import (
    add_design_arguments,
    add_numba_threads_argument,
    design_from_args,
    parse_floats,
)
from softarm_gym.commands.long_jobs import check_outputs, save_plot

NAME = "fit"
HELP = "calibrate a design to measured shapes: fitted parameters, uncertainty, residual plot"
REPRODUCTIONS = ("fig-2.6", "noise", "sensitivity")
DEFAULT_PARAMS = "wind_angle,E"
DEFAULT_LEVELS = "30,40,50,60,70,80,90"


def add_arguments(p):
    add_design_arguments(p)
    p.add_argument("--data", metavar="FILE.csv", default=None,
                   help="measured configurations (format: softarm_gym.identify.data, docs/identification.md)")
    p.add_argument("--params", default=DEFAULT_PARAMS,
                   help="parameters to fit, comma separated: wind_angle, offset (each optionally "
                        ":group, a channel, planar channel, section s1.. or tube0..), E, G, EA_scale, "
                        "GA_scale, EI_scale, GJ_scale, mass_scale (optionally :s1..), endplate_mass:sK, "
                        "payload (default %(default)s)")
    p.add_argument("--model", default="full", choices=solver.MODELS, help="solver model (default full)")
    p.add_argument("--loss", default="soft_l1", choices=solver.identify.LOSSES,
                   help="robust loss of the least squares (default %(default)s)")
    p.add_argument("--f-scale", type=float, default=3.0,
                   help="where the loss turns robust, in noise standard deviations (default %(default)s)")
    p.add_argument("--tip-sigma-mm", type=float, default=5.0,
                   help="standard deviation of measured tip positions (mm, default %(default)s)")
    p.add_argument("--point-sigma-mm", type=float, default=5.0,
                   help="standard deviation of measured backbone markers (mm, default %(default)s)")
    p.add_argument("--sensor-noise-std", type=float, default=0.0,
                   help="Gaussian sensor noise before the Table 4.3 rounding, in resolutions (default 0: "
                        "rounding only); sets the readings' sigma, and their noise with --make-synthetic")
    p.add_argument("--holdout", type=float, default=None,
                   help="fraction of configurations held out to measure the error on unseen data (default: "
                        "the file's split column, else 0.2)")
    p.add_argument("--seed", type=int, default=0, help="seeds the hold-out choice and synthetic noise")
    p.add_argument("--relative-sigma", action="store_true",
                   help="the sigmas are relative weights: scale the covariance by the reduced chi-square")
    p.add_argument("--max-nfev", type=int, default=60,
                   help="most residual evaluations of the optimiser (each a batch solve; the Jacobians come "
                        "on top; default %(default)s)")
    p.add_argument("--payload-kg", type=float, default=0.0,
                   help="known tip payload of every configuration when the file has no payload_kg column "
                        "(and of the synthetic data)")
    g = p.add_argument_group("synthetic data (--make-synthetic)")
    g.add_argument("--make-synthetic", metavar="FILE.csv", default=None,
                   help="write synthetic measured data of the --truth arm and exit")
    g.add_argument("--truth", default=None,
                   help="true parameter values NAME=VALUE,... (default: softarm_gym.identify.PERTURBED_ARM, "
                        "nine parameters of a perturbed OctArm V)")
    g.add_argument("--pressures-psi", default=DEFAULT_LEVELS,
                   help="pressure levels of the on/off configurations (psi, default %(default)s)")
    g.add_argument("--base-angles", default="0,90", help="base angles (deg, default %(default)s)")
    g.add_argument("--markers", default=None,
                   help="reference arc lengths of backbone markers (m, default: the inner section ends)")
    g.add_argument("--no-sensors", action="store_true", help="leave the sensor readings out")
    p.add_argument("--reproduce", choices=REPRODUCTIONS, default=None, help="rerun a validation study")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--output", metavar="FILE.json", default=None,
                   help="write the fit file (the JSON output; randomization='FILE.json' samples its "
                        "posterior)")
    p.add_argument("--save-design", metavar="FILE.json", default=None,
                   help="write the fitted design (a design file for --design-file)")
    p.add_argument("--plot", metavar="FILE.png", default=None, help="save the residual figure")
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr")
    add_numba_threads_argument(p)


def _noise(args):
    from softarm_gym.sensing import SensorNoise

    if not (np.isfinite(args.sensor_noise_std) and args.sensor_noise_std >= 0):
        raise UsageError(f"--sensor-noise-std must be a finite number >= 0; got {args.sensor_noise_std}")
    return SensorNoise.thesis(gaussian_std=args.sensor_noise_std)


def _sigma_m(value: float, flag: str) -> float:
    if not (np.isfinite(value) and value >= 0):
        raise UsageError(f"{flag} must be a finite number >= 0 (mm); got {value}")
    return value / 1000.0


def _truth(args, design) -> dict:
    from softarm_gym.identify import PERTURBED_ARM

    if args.truth is None:
        if design.name != "octarm_v":
            raise UsageError(f"--truth is needed for design {design.name!r} (the default perturbs OctArm V)")
        return dict(PERTURBED_ARM)
    truth = {}
    for item in args.truth.split(","):
        name, eq, value = item.partition("=")
        try:
            truth[name.strip()] = float(value)
        except ValueError:
            raise UsageError(f"--truth takes NAME=VALUE pairs separated by commas; got {item!r}") from None
        if not eq or not np.isfinite(truth[name.strip()]):
            raise UsageError(f"--truth takes NAME=VALUE pairs with finite values; got {item!r}")
    return truth


def run(args) -> int:
    design = design_from_args(args)
    levels = parse_floats(args.pressures_psi, "--pressures-psi")
    angles = parse_floats(args.base_angles, "--base-angles")
    markers = None if args.markers is None else parse_floats(args.markers, "--markers")
    tip_sigma = _sigma_m(args.tip_sigma_mm, "--tip-sigma-mm")
    point_sigma = _sigma_m(args.point_sigma_mm, "--point-sigma-mm")
    noise = _noise(args)
    check_outputs(args, images=("plot",), files=("output", "save_design", "make_synthetic"))
    if args.reproduce:
        return _reproduce(args, design)
    if args.make_synthetic:
        return _make_synthetic(args, design, levels, angles, markers, tip_sigma, point_sigma, noise)
    if args.data is None:
        raise UsageError("--data FILE.csv is required (or --make-synthetic FILE.csv, or --reproduce)")
    return _fit(args, design, tip_sigma, point_sigma, noise)


def _progress_bar(args, desc: str):
    bar = tqdm(desc=desc, unit=" batch", file=sys.stderr, disable=args.quiet, leave=False)

    def update(info):
        bar.update(info["evaluations"] - bar.n)
        bar.set_postfix(cost=f"{info['cost']:.4g}", jacobians=info["jacobians"], refresh=False)

    return bar, update


def _fit(args, design, tip_sigma, point_sigma, noise) -> int:
    from softarm_gym.files import write_json
    from softarm_gym.identify import read_csv
    from softarm_gym.identify.plots import plot_fit

    if tip_sigma <= 0 or point_sigma <= 0:
        raise UsageError("--tip-sigma-mm and --point-sigma-mm must be > 0 to weigh measurements")
    try:
        meas, labels = read_csv(args.data, design, tip_sigma=tip_sigma, point_sigma=point_sigma,
                                sensor_noise=noise, payload_kg=args.payload_kg)
    except OSError as exc:
        raise UsageError(f"cannot read data file {args.data!r}: {exc.strerror}") from None
    bar, update = _progress_bar(args, "fit")
    try:
        result = solver.identify.fit(design, meas, args.params, model=args.model, loss=args.loss,
                                     f_scale=args.f_scale, holdout=args.holdout, seed=args.seed,
                                     absolute_sigma=not args.relative_sigma, max_nfev=args.max_nfev,
                                     progress=update)
    finally:
        bar.close()
    payload = result.to_dict()
    payload["data"] = args.data
    payload["labels"] = labels
    if args.save_design:
        from softarm_gym.files import atomic_write

        with atomic_write(args.save_design, "w", encoding="utf-8") as fh:
            fh.write(result.fitted_design.to_json() + "\n")
        payload["saved_design"] = args.save_design
    if args.plot:
        save_plot(plot_fit, args.plot, result, labels=labels)
        payload["plot"] = args.plot
    if args.output:
        write_json(args.output, payload)
    emit(payload, args.json, result.summary())
    return 0 if result.optimizer["success"] and not result.optimizer["unconverged"] else 1


def _make_synthetic(args, design, levels, angles, markers, tip_sigma, point_sigma, noise) -> int:
    from softarm_gym.identify import make_synthetic, write_csv
    from softarm_gym.sensing import SensorNoise

    if not levels.size or not angles.size:
        raise UsageError("--pressures-psi and --base-angles need at least one value each")
    truth = _truth(args, design)
    meas, labels, true_arm = make_synthetic(
        design, truth, pressures_psi=levels, base_angles_deg=angles, payload_kg=args.payload_kg,
        tip_sigma=tip_sigma, point_sigma=point_sigma,
        markers="section_ends" if markers is None else tuple(markers),
        sensor_noise=SensorNoise.off() if args.no_sensors else noise, model=args.model,
        holdout=0.2 if args.holdout is None else args.holdout, seed=args.seed)
    comments = [f"synthetic data of design {design.name} made by softarm fit --make-synthetic "
                f"(model {args.model}, seed {args.seed})",
                "truth: " + ", ".join(f"{k}={v:g}" for k, v in truth.items()),
                f"noise: tip sigma {1e3 * tip_sigma:g} mm, marker sigma {1e3 * point_sigma:g} mm, "
                + ("no sensors" if args.no_sensors else f"sensors at Table 4.3 resolution with "
                   f"{args.sensor_noise_std:g} resolutions of Gaussian noise")]
    write_csv(args.make_synthetic, design, meas, labels, comments=comments)
    payload = {"data": args.make_synthetic, "configurations": meas.n, "values": meas.n_values,
               "observations": [o.name for o in meas.observations], "truth": truth,
               "true_design": json.loads(true_arm.to_json())}
    if args.output:
        from softarm_gym.files import write_json

        write_json(args.output, payload)
    emit(payload, args.json, f"wrote {meas.n} configurations ({meas.n_values} measured values: "
         f"{', '.join(o.name for o in meas.observations)}) to {args.make_synthetic}\n"
         f"truth: {comments[1][7:]}")
    return 0


def _reproduce(args, design) -> int:
    from softarm_gym.files import write_json
    from softarm_gym.identify import studies

    if args.design_file or args.design != "octarm_v":
        raise UsageError(f"--reproduce {args.reproduce} runs on OctArm V; drop --design/--design-file")
    if args.plot and args.reproduce != "fig-2.6":
        raise UsageError(f"--plot applies to fits and to --reproduce fig-2.6, not to {args.reproduce}")
    bar, update = _progress_bar(args, args.reproduce)
    try:
        if args.reproduce == "fig-2.6":
            result = studies.fig_2_6(seed=args.seed, progress=update)
            text = studies.format_fig_2_6(result)
        elif args.reproduce == "noise":
            result = studies.noise_study(progress=update)
            text = studies.format_noise(result)
        else:
            result = studies.sensitivity()
            text = studies.format_sensitivity(result)
    finally:
        bar.close()
    if args.plot and args.reproduce == "fig-2.6":
        save_plot(studies.plot_fig_2_6, args.plot, result)
        result["plot"] = args.plot
    if args.output:
        write_json(args.output, result)
    emit(result, args.json, text)
    return 0
