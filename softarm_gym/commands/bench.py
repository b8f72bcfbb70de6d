"""``softarm bench``: speed against accuracy, measured side by side in one run.

Default: the solver (RK4 resolution sweep, warm and cold solves, scipy solve_bvp reference,
spatial, batch). ``--peer pyelastica`` settles the same OctArm V scenes with PyElastica.
``--env`` times the environments instead: every registered ID and observation mode, single
and vectorised; the single-env contact cases as multiples of a free reach step; the batched
reach env by size, and the batched wrap and obstacle-reach envs beside it at 1024 arms
(``--env --contact``: only the contact rows).
``--first-episode`` times the first episode of every registered ID in a fresh process after
``softarm warmup`` against its steady speed (``--cold`` adds the same with an empty numba
cache). ``--fit`` times the calibration (``softarm fit``) at the thesis's experiment size,
beside one batch of its solves, and tabulates parameter error against noise level
(docs/bench/fit.json). ``--friction`` times the friction oracles' load paths (capstan, slip
threshold) at several RK4 resolutions against their closed forms (docs/bench/friction.json);
``--friction --3d`` the 3D oracles' instead (the oblique stylus, the capstan round a tilted
drum; tens of minutes, with a progress bar; docs/bench/friction_3d.json).
``--output FILE.json`` also writes the result; ``--quiet`` hides the progress lines.
"""

from __future__ import annotations

import shlex
import sys

from softarm_gym.cli import UsageError, emit
from softarm_gym.commands.common import add_numba_threads_argument, add_output_argument, add_quiet_argument

NAME = "bench"
HELP = "benchmark solver speed against accuracy (and peers)"


def add_arguments(p):
    p.add_argument("--quick", action="store_true", help="fewer scenes and repeats (smoke run)")
    p.add_argument("--peer", choices=("pyelastica",), help="also settle the scenes with a peer simulator")
    p.add_argument("--env", action="store_true",
                   help="benchmark the environments (steps/s) instead of the solver")
    p.add_argument("--estimators", action="store_true",
                   help="benchmark sensor synthesis and every shape estimator instead")
    p.add_argument("--first-episode", action="store_true",
                   help="first episode of every ID in a fresh process (after softarm warmup) against "
                        "its steady speed")
    p.add_argument("--fit", action="store_true",
                   help="benchmark the calibration (softarm fit) instead: time for 64 x 7 configurations and "
                        "nine parameters, and parameter error against noise level")
    p.add_argument("--cold", action="store_true",
                   help="with --first-episode: also with an empty numba cache (compiles; slow)")
    p.add_argument("--ids", default=None,
                   help="with --env: comma-separated IDs to time (default: every registered ID and "
                        "the batched vector env)")
    p.add_argument("--contact", action="store_true",
                   help="with --env: only the contact rows (single-env contact ratios, batched contact "
                        "envs beside batched reach at 1024 arms)")
    p.add_argument("--contact-profile", action="store_true",
                   help="where a contact step's time goes: paths, passes, kernels against Python, "
                        "beside a free reach step")
    p.add_argument("--friction", action="store_true",
                   help="Coulomb friction's time against error instead: the capstan and slip-threshold "
                        "load paths at several RK4 resolutions against their closed forms")
    p.add_argument("--3d", dest="three_d", action="store_true",
                   help="with --friction: the 3D rows instead (the oblique stylus's slip threshold, the "
                        "capstan round a tilted drum at 90 and 180 degrees; tens of minutes)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_output_argument(p)
    add_quiet_argument(p, help="no progress lines on stderr")
    add_numba_threads_argument(p)


def run(args) -> int:
    from softarm_gym.benchmarks import solver_bench
    from softarm_gym.commands.long_jobs import check_outputs

    check_outputs(args)

    def progress(message):
        if not args.quiet:
            print(f"[bench] {message}", file=sys.stderr, flush=True)

    def report(result, text):
        """Print the result (JSON with --json), and write it to --output."""
        emit(result, args.json, text)
        if args.output:
            from softarm_gym.files import write_json

            write_json(args.output, result)

    if args.three_d and not args.friction:
        raise UsageError("--3d only applies to --friction")
    if args.friction and args.three_d:
        from tqdm import tqdm

        from softarm_gym.benchmarks import friction_bench

        with tqdm(total=friction_bench.solves_3d(), unit=" solve", file=sys.stderr,
                  disable=args.quiet, desc="3D friction") as bar:
            result = friction_bench.run_3d(
                progress=None if args.quiet else lambda line: tqdm.write(line, file=sys.stderr),
                tick=lambda: bar.update(1))
        result["measured"]["command"] = shlex.join(["softarm", *sys.argv[1:]])
        report(result, friction_bench.format_table_3d(result))
        return 0
    if args.friction:
        from softarm_gym.benchmarks import friction_bench

        result = friction_bench.run(quick=args.quick, progress=progress)
        result["measured"]["command"] = shlex.join(["softarm", *sys.argv[1:]])
        report(result, friction_bench.format_table(result))
        return 0

    if args.estimators:
        from softarm_gym.sensing.bench import bench_estimators

        rows = {"planar": bench_estimators(steps=50 if args.quick else 200),
                "spatial": bench_estimators(steps=20 if args.quick else 100, planar=False)}
        lines = ["| call | planar (µs, median) | spatial (µs, median) |", "|---|---|---|"]
        for name in rows["planar"]:
            if isinstance(rows["planar"][name], float):
                spatial = rows["spatial"].get(name)
                lines.append(f"| {name} | {1e6 * rows['planar'][name]:.0f} | "
                             f"{'—' if not isinstance(spatial, float) else f'{1e6 * spatial:.0f}'} |")
        report(rows, "\n".join(lines))
        return 0
    if args.contact_profile:
        from softarm_gym.benchmarks import contact_profile

        result = contact_profile.run(quick=args.quick, progress=progress)
        report(result, contact_profile.format_table(result))
        return 0
    if args.fit:
        from softarm_gym.identify import studies

        progress("fit time: 64 on/off configurations x 7 pressures, nine parameters")
        result = {"time": studies.benchmark(repeats=1 if args.quick else 3)}
        progress("parameter error against noise level")
        sigmas = (2.0, 10.0) if args.quick else (1.0, 2.0, 5.0, 10.0, 20.0)
        result["noise"] = studies.noise_study(sigmas_mm=sigmas, seeds=(0,) if args.quick else (0, 1, 2))
        report(result, studies.format_benchmark(result["time"]) + "\n\n"
             + studies.format_noise(result["noise"]))
        return 0
    if args.cold and not args.first_episode:
        raise UsageError("--cold only applies to --first-episode")
    if args.ids and not args.env:
        raise UsageError("--ids only applies to --env")
    if args.contact and not args.env:
        raise UsageError("--contact only applies to --env")
    if args.contact and args.ids:
        raise UsageError("--contact and --ids do not combine (--contact times fixed contact cases)")
    if args.first_episode:
        from softarm_gym.benchmarks import first_episode
        from softarm_gym.commands import warmup

        progress("softarm warmup (loads what is cached, compiles the rest)")
        warmup.warm()
        result = first_episode.run(episodes=1 if args.quick else 3, cold=args.cold, progress=progress)
        report(result, first_episode.format_table(result))
        return 0
    if args.env:
        from softarm_gym.benchmarks import envs, vector_bench

        if args.contact:
            result = _contact_rows(args.quick, progress)
            report(result, _contact_text(result))
            return 0
        ids = args.ids.split(",") if args.ids else None
        unknown = [i for i in ids or () if i not in envs.env_ids()]
        if unknown:
            raise UsageError(f"unknown ID(s) {', '.join(unknown)}; registered: {', '.join(envs.env_ids())}")
        result = envs.run(quick=args.quick, ids=ids, progress=progress)
        if ids:  # only the IDs asked for: not the batched vector env (a reach benchmark)
            report(result, envs.format_table(result))
            return 0
        sizes = (4, 256) if args.quick else (4, 16, 256, 1024, 4096)
        result["batched_vector"] = vector_bench.run(sizes, progress=progress)
        result.update(_contact_rows(args.quick, progress))
        result["batched_vector_3d"] = vector_bench.run_spatial((4,) if args.quick else (4, 16, 64),
                                                               progress=progress)
        report(result, envs.format_table(result) + "\n\n"
             + vector_bench.format_table(result["batched_vector"]) + "\n\n"
             + _contact_text(result) + "\n\n"
             + vector_bench.format_spatial_table(result["batched_vector_3d"]))
        return 0
    result = solver_bench.run(quick=args.quick, progress=progress)
    text = solver_bench.format_table(result)
    if args.peer == "pyelastica":
        try:
            from softarm_gym.benchmarks import pyelastica_peer
        except ImportError as exc:
            raise UsageError("--peer pyelastica needs PyElastica "
                             f"(pip install 'softarm-gym[bench]'): {exc}") from None
        result["pyelastica"] = pyelastica_peer.compare(progress=progress, quick=args.quick)
        text += "\n\n" + pyelastica_peer.format_table(result["pyelastica"])
    report(result, text)
    return 0


def _contact_rows(quick: bool, progress) -> dict:
    """The contact rows of ``--env``: single-env contact ratios, batched contact envs."""
    from softarm_gym.benchmarks import envs, vector_bench

    return {"contact_ratios": envs.contact_ratios(60 if quick else 300, progress=progress),
            "batched_contact": vector_bench.run_contact(64 if quick else 1024, steps=10 if quick else 40,
                                                        progress=progress)}


def _contact_text(result: dict) -> str:
    from softarm_gym.benchmarks import envs, vector_bench

    return (envs.format_ratio_table(result["contact_ratios"]) + "\n\n"
            + vector_bench.format_contact_table(result["batched_contact"]))
