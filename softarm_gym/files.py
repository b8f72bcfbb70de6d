"""Output files that are always valid: strict JSON, and writes that are all-or-nothing.

* :func:`json_text` — JSON that standard parsers accept: numpy arrays and scalars become lists
  and numbers, a non-finite float becomes ``null`` (JSON has no NaN or Infinity), and
  ``allow_nan=False`` guarantees nothing else slips through.
* :func:`atomic_write` — write to a temporary file in the target's folder, flush it to disk,
  then rename it over the target: a reader, a crash or a ``kill -9`` sees the old file or the
  new one, never half of one.
* :func:`signals_deferred` — hold Ctrl-C (and other stop signals) while files are written,
  and deliver them once the block ends.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["jsonable", "json_text", "atomic_write", "write_json", "signals_deferred"]


def jsonable(obj):
    """``obj`` with numpy values as Python ones and non-finite floats as None (recursively)."""
    if isinstance(obj, dict):
        return {key: jsonable(value) for key, value in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [jsonable(value) for value in obj]
    if isinstance(obj, (np.generic, float)):
        obj = obj.item() if isinstance(obj, np.generic) else obj
        return obj if not isinstance(obj, float) or math.isfinite(obj) else None
    return obj


def json_text(obj, indent: int | None = 2) -> str:
    """Strict JSON of ``obj`` (see the module docstring); raises TypeError for non-data objects."""
    return json.dumps(jsonable(obj), indent=indent, allow_nan=False)


@contextmanager
def atomic_write(path: str | Path, mode: str = "w", **open_kwargs) -> Iterator:
    """Open a temporary file for writing; on success it replaces ``path`` in one rename.

    On an exception (or interrupt) inside the block the temporary file is removed and ``path``
    is untouched. The file is created with the usual permissions (umask), unlike ``mkstemp``.

    Args:
        path: the final file.
        mode: ``"w"`` or ``"wb"``.
        **open_kwargs: passed to :func:`open` (e.g. ``encoding``).
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write mode must be 'w' or 'wb'; got {mode!r}")
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, mode.replace("w", "x"), **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if os.name == "posix":  # make the rename itself durable
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_json(path: str | Path, obj, indent: int | None = 2) -> None:
    """Write ``obj`` as strict JSON (:func:`json_text`) to ``path``, atomically."""
    text = json_text(obj, indent) + "\n"
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(text)


@contextmanager
def signals_deferred(*signums: int) -> Iterator[None]:
    """Hold ``signums`` (default SIGINT) for the block, then deliver each one that arrived.

    A stop landing inside a zip or ``np.savez`` writer breaks the writer's clean-up, which then
    raises in place of the ``KeyboardInterrupt``, and the interrupted save is lost. Outside the
    main thread signals are not Python's to hold, and the block runs unguarded.

    A held signal is delivered by calling the handler restored after the block, not by
    re-raising the OS signal: Ray's gentle ``ray.cancel`` interrupts a task with a simulated
    SIGINT while its worker's main thread blocks the real one, so a re-raised SIGINT stayed
    pending for ever and the cancelled training ran on to its end. Only a signal whose restored
    handler is the default action (e.g. SIGTERM terminating) is re-raised.
    """
    signums = signums or (signal.SIGINT,)
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived = []
    previous = {s: signal.signal(s, lambda signum, frame: arrived.append(signum)) for s in signums}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        for s in dict.fromkeys(arrived):
            handler = previous[s]
            if callable(handler):
                handler(s, None)
            elif handler in (signal.SIG_DFL, None):
                signal.raise_signal(s)
