"""The ``softarm`` command line: one subcommand per module in :mod:`softarm_gym.commands`.

Each command module defines ``NAME``, ``HELP``, ``add_arguments(parser)`` and
``run(args) -> int``. Long work shows a progress bar on stderr (``--quiet`` hides it), so
``--json`` output on stdout stays machine-readable; ``--output FILE.json`` also writes it to a
file; masses are ``--payload-kg``; long commands take ``--numba-threads N``. Bad input exits
with status 2 and a one-line message.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys

from softarm_gym.files import json_text

COMMANDS = ("solve", "bench", "demo", "warmup", "design", "workspace", "dexterity", "estimators", "stress",
            "fit")
"""Command modules under :mod:`softarm_gym.commands`, in help order."""


class UsageError(ValueError):
    """Bad command-line input: reported as one line, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="softarm", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        module = importlib.import_module(f"softarm_gym.commands.{name}")
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


_NEGATIVE_VALUE = re.compile(r"-(\d|\.\d|inf|nan)", re.IGNORECASE)


def _attach_negative_values(argv: list[str]) -> list[str]:
    """``--opt -5,0`` → ``--opt=-5,0``: argparse takes a value starting with ``-`` for an option
    unless it is one plain number, so a list such as ``--pressures-psi -5,0`` would fail with
    "expected one argument" before the command could say what is wrong with it."""
    out: list[str] = []
    for token in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and _NEGATIVE_VALUE.match(token):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(_attach_negative_values(sys.argv[1:] if argv is None else list(argv)))
    try:
        if getattr(args, "numba_threads", None) is not None:
            from softarm_gym.commands.common import apply_numba_threads

            apply_numba_threads(args.numba_threads)
        code = int(args._run(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return code
    except BrokenPipeError:
        # The reader went away (``softarm solve --json | head -1``): stop quietly, as a command
        # killed by SIGPIPE would; stdout goes to /dev/null so the exit-time flush cannot fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + 13
    except (UsageError, ValueError) as exc:
        print(f"softarm {args.command}: error: {exc}", file=sys.stderr)
        return 2


def emit(payload: dict, as_json: bool, text: str) -> None:
    """Print ``payload`` as strict JSON (a non-finite number is ``null``, see
    :func:`softarm_gym.files.json_text`), or ``text`` for people."""
    if as_json:
        print(json_text(payload))
    else:
        print(text)


if __name__ == "__main__":
    sys.exit(main())
