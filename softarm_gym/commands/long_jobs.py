"""Options and output handling shared by the sweep commands (workspace, dexterity, design, stress).

Every sweep command takes ``--backend local|ray``, ``--address``, ``--chunk-size``,
``--resume``, ``--chunk-dir``, ``--retries``, ``--output FILE.json`` and ``--numba-threads``. Output paths are
checked before any work starts; results and pictures are written atomically (temporary file
+ rename); finished chunks stay on disk until the output is written, so Ctrl-C, a killed
process or a lost Ray worker costs at most the chunks in flight (``--resume`` continues).
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import tempfile
from pathlib import Path

from softarm_gym.cli import UsageError, emit
from softarm_gym.commands.common import add_numba_threads_argument
from softarm_gym.jobs import (
    BACKENDS,
    DEFAULT_RETRIES,
    Interrupted,
    Runner,
    atomic_path,
    default_chunk_dir,
    write_atomic,
)


def add_job_arguments(p, chunk_help: str, chunk_default=None) -> None:
    """The backend, chunking, resume and ``--output`` options."""
    g = p.add_argument_group("long jobs")
    g.add_argument("--backend", choices=BACKENDS, default="local",
                   help="run the chunks in this process (local) or as Ray tasks (needs the ray extra)")
    g.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="Ray cluster to use with --backend ray (default: start a private local instance)")
    g.add_argument("--chunk-size", type=int, default=chunk_default, metavar="N", help=chunk_help)
    g.add_argument("--resume", action="store_true",
                   help="reuse the finished chunks of an interrupted run of the same command")
    g.add_argument("--chunk-dir", metavar="DIR", default=None,
                   help="where finished chunks are kept until the output is written "
                        f"(default $SOFTARM_CHUNK_DIR or {_tilde(default_chunk_dir())})")
    g.add_argument("--retries", type=int, default=DEFAULT_RETRIES, metavar="N",
                   help="times Ray reruns a chunk whose worker died (default %(default)s)")
    g.add_argument("--output", metavar="FILE.json", default=None,
                   help="also write the JSON result to FILE (atomically)")
    add_numba_threads_argument(g)


def _tilde(path: Path) -> str:
    home = str(Path.home())
    return "~" + str(path)[len(home):] if str(path).startswith(home) else str(path)


def runner_from_args(args, progress: bool) -> Runner:
    """The :class:`~softarm_gym.jobs.Runner` the options describe (checks the chunk directory)."""
    if args.chunk_size is not None and args.chunk_size < 1:
        raise UsageError(f"--chunk-size must be >= 1; got {args.chunk_size}")
    if args.retries < 0:
        raise UsageError(f"--retries must be >= 0; got {args.retries}")
    if args.address is not None and args.backend != "ray":
        raise UsageError("--address needs --backend ray")
    store = default_chunk_dir() if args.chunk_dir is None else Path(args.chunk_dir)
    return Runner(args.backend, args.address, store=store, resume=args.resume, progress=progress,
                  retries=args.retries)


def check_outputs(args, images=(), files=("output",)) -> None:
    """Fail now, not after the sweep, if an output cannot be written.

    Args:
        args: parsed options.
        images: option names (``"plot"``) whose value is a picture: its extension must be a
            format matplotlib writes.
        files: option names of other output files.
    """
    for name in (*images, *files):
        value = getattr(args, name, None)
        if value is None:
            continue
        flag = "--" + name.replace("_", "-")
        path = Path(value)
        if path.is_dir():
            raise UsageError(f"{flag} {value}: is a directory")
        if name in images:
            _check_image_format(flag, path)
        parent = path.parent
        if not parent.is_dir():
            raise UsageError(f"{flag} {value}: directory {str(parent)!r} does not exist")
        try:
            tempfile.NamedTemporaryFile(dir=parent, prefix=f".{path.name}.").close()
        except OSError as exc:
            raise UsageError(f"{flag} {value}: cannot write in {str(parent)!r}: "
                             f"{exc.strerror or exc}") from None


def _check_image_format(flag: str, path: Path) -> None:
    from matplotlib.figure import Figure

    formats = Figure().canvas.get_supported_filetypes()
    suffix = path.suffix.lower().lstrip(".")
    if suffix not in formats:
        what = f"unsupported image format {suffix!r}" if suffix else "no image extension"
        raise UsageError(f"{flag} {path}: {what}; use one of {', '.join(sorted(formats))}")


def save_plot(plot, path, *args, **kwargs) -> None:
    """``plot(*args, tmp, **kwargs)`` into a temporary file beside ``path``, renamed on success."""
    with atomic_path(path) as tmp:
        plot(*args, tmp, **kwargs)


def finish(args, payload: dict, text: str, runner: Runner) -> None:
    """Write ``--output`` (atomically), print the result, then delete the sweep's chunks."""
    if args.output:
        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            emit(payload, True, text)
        write_atomic(args.output, buffer.getvalue())
    emit(payload, args.json, text)
    runner.discard()


def interruptible(run):
    """Wrap a command's ``run(args)``: Ctrl-C after the sweep (while the output is assembled) is
    one line too, naming where the finished chunks are kept."""

    @functools.wraps(run)
    def wrapper(args):
        try:
            return run(args)
        except Interrupted:
            raise
        except KeyboardInterrupt:
            where = args.chunk_dir or os.fspath(default_chunk_dir())
            raise Interrupted(f"interrupted; finished chunks, if any, are kept in {where}; rerun "
                              "the same command with --resume to continue") from None
    return wrapper
