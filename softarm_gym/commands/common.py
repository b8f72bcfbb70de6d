"""Argument helpers shared by the ``softarm`` subcommands."""

from __future__ import annotations

import argparse
import re

import numpy as np

import solver
from softarm_gym.cli import UsageError


def add_design_arguments(parser, default="octarm_v"):
    """``--design NAME`` / ``--design-file FILE.json`` and ``--ei``."""
    parser.add_argument("--design", default=default, choices=solver.designs.DESIGN_NAMES,
                        help="named design (default %(default)s)")
    parser.add_argument("--design-file", metavar="FILE.json",
                        help="custom design as JSON (overrides --design)")
    parser.add_argument("--ei", choices=("eq2.32", "tubes"), default=None,
                        help="bending-stiffness formula for named OctArm V / CT designs")


def design_from_args(args) -> solver.designs.ArmDesign:
    if args.design_file:
        try:
            return solver.designs.load(args.design_file)
        except OSError as exc:
            raise UsageError(f"cannot read design file {args.design_file!r}: {exc.strerror}") from None
        except ValueError as exc:
            raise UsageError(f"{args.design_file}: {exc}") from None
    kwargs = {"ei": args.ei} if args.ei and args.design in ("octarm_v", "ct", "octarm_2s") else {}
    return solver.designs.get(args.design, **kwargs)


def parse_floats(text: str, what: str) -> np.ndarray:
    """A comma-separated list of numbers (empty string → empty array)."""
    if text is None or text.strip() == "":
        return np.empty(0)
    try:
        return np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise UsageError(f"{what} must be comma-separated numbers; got {text!r}") from None


def parse_seeds(text: str) -> list[int]:
    """``"0-9"``, ``"0,3,5"`` or ``"0-4,10"`` → sorted distinct seeds (integers >= 0)."""
    seeds = set()
    for part in str(text).split(","):
        match = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if not match or (match.group(2) is not None and int(match.group(2)) < int(match.group(1))):
            raise ValueError(f"--seeds {text!r}: expected seeds >= 0 and ranges A-B with A <= B, "
                             "separated by commas (e.g. 0-9 or 0,3,5)")
        first = int(match.group(1))
        seeds.update(range(first, int(match.group(2) or first) + 1))
    return sorted(seeds)


# One vocabulary across the commands (and ``python -m baselines.*``): ``--json`` prints the
# result on stdout, ``--output FILE.json`` also writes it, ``--quiet`` hides progress, masses
# are ``--payload-kg``. Older spellings stay as hidden aliases of the same option.

def add_quiet_argument(parser, help="no progress bar on stderr") -> None:
    """``--quiet`` (and its older spelling ``--no-progress``, hidden) into ``args.quiet``."""
    parser.add_argument("--quiet", action="store_true", help=help)
    parser.add_argument("--no-progress", dest="quiet", action="store_true", help=argparse.SUPPRESS)


def add_output_argument(parser, help="also write the JSON result to FILE", old=()) -> None:
    """``--output FILE.json`` into ``args.output``; ``old`` spellings (``"--json-out"``) hidden."""
    parser.add_argument("--output", metavar="FILE.json", default=None, help=help)
    for spelling in old:
        parser.add_argument(spelling, dest="output", default=None, help=argparse.SUPPRESS)


def add_payload_argument(parser, default=0.0, help="tip payload (kg)") -> None:
    """``--payload-kg KG`` (and its older spelling ``--payload``, hidden) into ``args.payload_kg``."""
    parser.add_argument("--payload-kg", type=float, default=default, metavar="KG", help=help)
    parser.add_argument("--payload", dest="payload_kg", type=float, help=argparse.SUPPRESS)


def add_numba_threads_argument(parser) -> None:
    """``--numba-threads N``: threads of the solver's parallel kernels in this process."""
    parser.add_argument("--numba-threads", type=int, default=None, metavar="N",
                        help="threads for the solver's parallel kernels (default: every core; 1 on a "
                             "busy machine, where a parallel step waits for descheduled threads)")


def apply_numba_threads(value) -> None:
    """Set numba's thread count from ``--numba-threads`` (None keeps it); a bad value is a
    :class:`~softarm_gym.cli.UsageError`."""
    if value is None:
        return
    import numba

    top = numba.config.NUMBA_NUM_THREADS
    if isinstance(value, bool) or not 1 <= int(value) <= top:
        raise UsageError(f"--numba-threads must be between 1 and {top} (this machine's threads, or "
                         f"NUMBA_NUM_THREADS); got {value}")
    numba.set_num_threads(int(value))


def pressures_from_psi(text: str, arm, planar: bool, option: str = "--pressures-psi") -> np.ndarray:
    """Channel pressures (Pa) from a comma-separated list in psi, checked in psi: the count,
    and each value finite, >= 0 and at most the design's rated pressure. Empty → all zero."""
    psi = parse_floats(text, option)
    n = arm.n_inputs(planar)
    if psi.size == 0:
        psi = np.zeros(n)
    names = arm.input_names(planar)
    if psi.size != n:
        raise UsageError(f"{option}: design {arm.name!r} expects {n} pressures in "
                         f"{'planar' if planar else 'spatial'} mode ({', '.join(names)}); got {psi.size} "
                         f"({text} psi)")
    top = arm.max_pressure / solver.PSI
    for name, value in zip(names, psi):
        if not np.isfinite(value):
            raise UsageError(f"{option}: pressure for channel {name!r} is not finite: {value}")
        if value < 0:
            raise UsageError(f"{option}: pressure for channel {name!r} is negative ({value:g} psi); "
                             "channel pressures are gauge pressures >= 0")
        if value > top * (1 + 1e-12):
            raise UsageError(f"{option}: pressure for channel {name!r} ({value:g} psi) exceeds the design's "
                             f"rated maximum {top:.4g} psi")
    return psi * solver.PSI
