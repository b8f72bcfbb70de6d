"""Argument helpers shared by the ``softarm`` subcommands."""

from __future__ import annotations

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
