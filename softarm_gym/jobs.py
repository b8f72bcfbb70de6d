"""Long jobs: chunked, resumable sweeps on this machine or a Ray cluster, and safe output files.

A sweep is a list of :class:`Chunk` s. A chunk is one call ``fn(*args)`` of a module-level
function that returns a dict of NumPy arrays and takes about a second; its result must
depend on its arguments only (every sweep here is a list of independent cold solves), so a
sweep gives the same numbers whatever the chunking, the order or the backend.
:class:`Runner` runs the chunks:

* ``backend="local"``: one after another in this process (``solver.solve_batch`` still uses
  every core through numba threads);
* ``backend="ray"``: one Ray task per chunk (one CPU each) on a local Ray instance or on the
  cluster at ``address``, a bounded number in flight, results written back by chunk index.

One progress bar covers the whole sweep. With a chunk directory (``store``), every finished
chunk is saved at once (``<key>.npz``, written to a temporary name and renamed, loaded
without pickle), named by a SHA-256 key of the function, its arguments and the source code
of ``solver`` and ``softarm_gym``; ``resume=True`` loads the chunks already there instead of
recomputing them, so a sweep interrupted by Ctrl-C, a killed driver or a lost Ray worker
continues where it stopped, and gives bit-for-bit the uninterrupted result. A changed
argument or changed code changes the key, so stale chunks are never mixed in. Once the
caller has written its output it calls :meth:`Runner.discard` to delete the chunks.

Failures that end a sweep (Ctrl-C, an unreachable cluster, a Ray version mismatch, a worker
that died more often than ``retries``, workers running other code) raise :class:`JobError`
(a ``ValueError``: the ``softarm`` commands print it as one line and exit with status 2),
saying how many chunks are kept and how to resume. Ctrl-C raises :class:`Interrupted`,
which is also a ``KeyboardInterrupt``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import json
import logging
import os
import pickle
import re
import socket
import sys
import tempfile
import time
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache, cached_property
from pathlib import Path

import numpy as np
from tqdm import tqdm

from softarm_gym.files import signals_deferred

__all__ = ["BACKENDS", "DEFAULT_RETRIES", "Chunk", "Plan", "Runner", "ChunkStore", "JobError",
           "Interrupted", "default_chunk_dir", "code_fingerprint", "chunk_bounds", "atomic_path",
           "write_atomic", "ray_session", "ray_payload", "cancel_unfinished", "first_line"]

BACKENDS = ("local", "ray")
DEFAULT_RETRIES = 3
"""Times Ray reruns a chunk whose worker process or node died (Ray's own default)."""
CONNECT_TIMEOUT = 5.0
"""Seconds to wait for a TCP connection to a Ray address before calling it unreachable."""


class JobError(ValueError):
    """A sweep that could not finish; the message is one line and says what is kept."""


class Interrupted(JobError, KeyboardInterrupt):
    """Ctrl-C in a sweep: a :class:`JobError` for the command line, a ``KeyboardInterrupt`` too."""


# ----------------------------------------------------------------------------- keys


@cache
def code_fingerprint(packages: tuple[str, ...] = ("solver", "softarm_gym")) -> str:
    """SHA-256 (16 hex digits) of the ``.py`` sources of ``packages`` (importable package names).

    With the default, part of every chunk key, and compared with what each Ray worker
    computes, so chunks are never reused or mixed across code versions.
    """
    digest = hashlib.sha256()
    for name in packages:
        root = Path(importlib.import_module(name).__file__).parent
        for path in sorted(root.rglob("*.py")):
            digest.update(str(path.relative_to(root.parent)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _canonical(obj):
    """A JSON-ready, exact description of a chunk argument (for its key)."""
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    if isinstance(obj, float):
        return {"float": obj.hex()}
    if isinstance(obj, (np.bool_, np.integer, np.floating)):
        return _canonical(obj.item())
    if isinstance(obj, np.ndarray):
        data = np.ascontiguousarray(obj)
        if data.dtype.hasobject:
            raise TypeError("object arrays cannot be part of a chunk key")
        return {"ndarray": data.dtype.str, "shape": list(data.shape),
                "sha256": hashlib.sha256(data.tobytes()).hexdigest()}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        # The fields that take part in equality: caches (compare=False) change with use.
        return {"dataclass": f"{type(obj).__module__}.{type(obj).__qualname__}",
                "fields": {f.name: _canonical(getattr(obj, f.name))
                           for f in dataclasses.fields(obj) if f.compare}}
    if isinstance(obj, (tuple, list)):
        return [_canonical(v) for v in obj]
    if isinstance(obj, dict):
        return {"dict": [[_canonical(k), _canonical(v)] for k, v in obj.items()]}
    if callable(obj) and hasattr(obj, "__qualname__"):
        return {"callable": f"{obj.__module__}.{obj.__qualname__}"}
    raise TypeError(f"cannot key a chunk argument of type {type(obj).__name__}")


@dataclass(frozen=True)
class Chunk:
    """One unit of a sweep: ``fn(*args)``, returning ``{name: ndarray}``.

    Attributes:
        fn: a module-level function (Ray pickles it by reference); deterministic.
        args: its arguments (dataclasses, arrays, numbers, strings, tuples).
        size: work units it holds (grid points, designs, trials), for the progress bar.
    """

    fn: Callable
    args: tuple
    size: int = 1

    @cached_property
    def key(self) -> str:
        """SHA-256 of the function, the arguments and :func:`code_fingerprint` (hex)."""
        text = json.dumps([code_fingerprint(), _canonical(self.fn), _canonical(self.args)],
                          sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()


def chunk_bounds(n: int, chunk_size: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``range(n)`` in pieces of ``chunk_size``."""
    if isinstance(chunk_size, bool) or int(chunk_size) != chunk_size or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer >= 1; got {chunk_size!r}")
    return [(a, min(a + int(chunk_size), n)) for a in range(0, n, int(chunk_size))]


@dataclass(frozen=True)
class Plan:
    """The chunks of one result and how to assemble it.

    Attributes:
        chunks: the work.
        finish: ``finish(results, seconds)`` builds the result from the chunks' outputs and
            their compute times (s), both lists in chunk order.
    """

    chunks: Sequence[Chunk]
    finish: Callable

    @staticmethod
    def combine(plans: Sequence[Plan], finish: Callable) -> Plan:
        """One plan running all of ``plans``; its result is ``finish([result of each plan])``."""
        plans = list(plans)
        return Plan([c for p in plans for c in p.chunks],
                    lambda results, seconds: finish(_finish_each(plans, results, seconds)))


def _finish_each(plans, results, seconds) -> list:
    """``[plan.finish(its results, its seconds), ...]`` from the concatenated chunk outputs."""
    out, start = [], 0
    for p in plans:
        stop = start + len(p.chunks)
        out.append(p.finish(results[start:stop], seconds[start:stop]))
        start = stop
    return out


# ----------------------------------------------------------------------------- chunk store


def default_chunk_dir() -> Path:
    """``$SOFTARM_CHUNK_DIR``, else ``$XDG_CACHE_HOME/softarm/chunks`` (``~/.cache/...``)."""
    if os.environ.get("SOFTARM_CHUNK_DIR"):
        return Path(os.environ["SOFTARM_CHUNK_DIR"])
    cache_home = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(cache_home) / "softarm" / "chunks"


_SECONDS = "__seconds__"


class ChunkStore:
    """Finished chunks on disk: ``<key>.npz`` per chunk, written atomically, read without pickle."""

    def __init__(self, directory):
        self.directory = Path(directory)
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            probe = tempfile.NamedTemporaryFile(dir=self.directory, prefix=".probe-")
            probe.close()
        except OSError as exc:
            raise JobError(f"cannot use chunk directory {str(self.directory)!r}: "
                           f"{exc.strerror or exc}") from None

    def path(self, key: str) -> Path:
        return self.directory / f"{key}.npz"

    def has(self, key: str) -> bool:
        return self.path(key).is_file()

    def load(self, key: str):
        """``(result, seconds)``, or None if absent or unreadable (an unreadable file is removed)."""
        try:
            with np.load(self.path(key), allow_pickle=False) as data:
                result = {name: data[name] for name in data.files if name != _SECONDS}
                return result, float(data[_SECONDS])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            self.path(key).unlink(missing_ok=True)
            return None

    def save(self, key: str, result: dict, seconds: float) -> None:
        """Write one chunk; a Ctrl-C meanwhile takes effect once the file is complete."""
        with signals_deferred(), atomic_path(self.path(key)) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, **result, **{_SECONDS: np.float64(seconds)})

    def remove(self, keys) -> None:
        """Delete these chunks, and temporary files a killed process left while writing them."""
        for key in keys:
            self.path(key).unlink(missing_ok=True)
            for tmp in self.directory.glob(f".{key}.npz.*"):
                tmp.unlink(missing_ok=True)


# ----------------------------------------------------------------------------- runner


def _check_result(result, chunk: Chunk) -> dict:
    if not isinstance(result, dict) or not all(
            isinstance(v, np.ndarray) and not v.dtype.hasobject for v in result.values()):
        raise TypeError(f"chunk function {chunk.fn.__qualname__} must return a dict of "
                        "non-object NumPy arrays")
    return result


def ray_payload(args) -> bytes:
    """``args`` pickled in band with protocol 5, which keeps each array's read-only flag, so a
    Ray worker unpickles the arrays the local backend would pass (:func:`_ray_call`)."""
    return pickle.dumps(args, protocol=5)


def timed_call(fn, args):
    """``(fn(*args), seconds)``: every chunk of either backend is computed here (the local
    backend in this process, Ray in its worker)."""
    start = time.perf_counter()
    result = fn(*args)
    return result, time.perf_counter() - start


def _ray_call(fn, payload: bytes):
    """A chunk in a Ray worker: one numba thread (the task holds one CPU), timed, with the
    worker's code fingerprint and node address for the driver to check.

    The arguments come pickled by the driver (:func:`ray_payload`), not by Ray: Ray hands numpy
    arrays over as read-only views of its object store, and numba types a read-only array apart
    from a writable one, so every kernel an argument reached was compiled again in every worker
    (a minute and more each) instead of loaded from the cache the local backend fills."""
    import numba
    import ray

    numba.set_num_threads(1)
    result, seconds = timed_call(fn, pickle.loads(payload))
    return result, seconds, code_fingerprint(), ray.util.get_node_ip_address()


@dataclass
class Runner:
    """Runs sweeps chunk by chunk (module docstring).

    Attributes:
        backend: ``"local"`` or ``"ray"``.
        address: Ray cluster address (``"auto"``, ``"HOST:PORT"``, ``"ray://HOST:PORT"``). None:
            the Ray session this process already has, else Ray's default (the cluster
            ``ray start`` left on this machine, else a private instance for the run).
        store: chunk directory (None: results are kept in memory only).
        resume: reuse the chunks already in ``store``.
        progress: a progress bar on stderr.
        retries: times Ray reruns a chunk whose worker died.
        in_flight: most Ray tasks submitted at once (default twice the cluster's CPUs).
    """

    backend: str = "local"
    address: str | None = None
    store: str | os.PathLike | None = None
    resume: bool = False
    progress: bool = False
    retries: int = DEFAULT_RETRIES
    in_flight: int | None = None
    _written: set = field(default_factory=set, init=False, repr=False)

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown backend {self.backend!r}; choose one of {', '.join(BACKENDS)}")
        if self.backend == "local" and self.address is not None:
            raise ValueError("a Ray address was given but the backend is 'local'; use backend='ray'")
        if isinstance(self.retries, bool) or int(self.retries) != self.retries or self.retries < 0:
            raise ValueError(f"retries must be an integer >= 0; got {self.retries!r}")
        if self.in_flight is not None and (int(self.in_flight) != self.in_flight or self.in_flight < 1):
            raise ValueError(f"in_flight must be an integer >= 1; got {self.in_flight!r}")
        if self.resume and self.store is None:
            raise ValueError("resume needs a chunk directory (store)")
        self._store = None if self.store is None else ChunkStore(self.store)

    # ------------------------------------------------------------------ public

    def run_plans(self, plans: Sequence[Plan], desc: str = "sweep", unit: str = "pt") -> list:
        """Run the chunks of every plan under one progress bar; ``[plan.finish(...), ...]``."""
        outputs = self.run([c for p in plans for c in p.chunks], desc, unit)
        return _finish_each(plans, [r for r, _ in outputs], [s for _, s in outputs])

    def run(self, chunks: Sequence[Chunk], desc: str = "sweep", unit: str = "pt") -> list:
        """``[(result, seconds), ...]`` of every chunk, in order (``seconds``: its compute time)."""
        chunks = list(chunks)
        outputs = [None] * len(chunks)
        copies = {}  # key -> indices of the chunks with that key; the first one computes it
        for i, c in enumerate(chunks):
            copies.setdefault(c.key, []).append(i)
        self._load(chunks, outputs, copies)

        def record(i, result, seconds):
            result = _check_result(result, chunks[i])
            if self._store is not None:
                self._store.save(chunks[i].key, result, seconds)
                self._written.add(chunks[i].key)
            for j in copies[chunks[i].key]:
                outputs[j] = (result, seconds)
                bar.update(chunks[j].size)

        todo = [idx[0] for idx in copies.values() if outputs[idx[0]] is None]
        with contextlib.ExitStack() as stack:
            ray = stack.enter_context(ray_session(self.address)) if todo and self.backend == "ray" else None
            bar = stack.enter_context(tqdm(
                total=sum(c.size for c in chunks), unit=unit, desc=desc, file=sys.stderr,
                initial=sum(c.size for c, o in zip(chunks, outputs) if o is not None),
                disable=not self.progress, dynamic_ncols=True))
            try:
                if self.backend == "local":
                    for i in todo:
                        record(i, *timed_call(chunks[i].fn, chunks[i].args))
                elif todo:
                    self._run_ray(ray, chunks, todo, record, outputs)
            except KeyboardInterrupt:
                raise Interrupted(f"interrupted; {self._kept(outputs)}") from None
        return outputs

    def discard(self) -> None:
        """Delete the chunks this runner loaded or saved (call once the output is written)."""
        if self._store is not None:
            self._store.remove(self._written)
        self._written.clear()

    # ------------------------------------------------------------------ internals

    def _load(self, chunks, outputs, copies) -> None:
        if self._store is None:
            return
        found = [key for key in copies if self._store.has(key)]
        if found and not self.resume:
            print(f"note: {len(found)} finished chunks of this sweep in {self._store.directory} "
                  "are recomputed; --resume would reuse them", file=sys.stderr)
            return
        for key in found:
            loaded = self._store.load(key)
            if loaded is not None:
                self._written.add(key)
                for j in copies[key]:
                    outputs[j] = loaded

    def _kept(self, outputs) -> str:
        n_done = sum(o is not None for o in outputs)
        if self._store is None:
            return f"{n_done} of {len(outputs)} chunks had finished (no chunk directory: not kept)"
        return (f"{n_done} of {len(outputs)} chunks finished and kept in {self._store.directory}; "
                "rerun the same command with --resume to continue")

    def _run_ray(self, ray, chunks, todo, record, outputs) -> None:
        task = ray.remote(_ray_call).options(num_cpus=1, max_retries=int(self.retries),
                                             retry_exceptions=False)
        limit = self.in_flight or max(4, 2 * int(ray.cluster_resources().get("CPU", 1)))
        queue, pending = list(reversed(todo)), {}
        try:
            while queue or pending:
                while queue and len(pending) < limit:
                    i = queue.pop()
                    pending[task.remote(chunks[i].fn, ray_payload(chunks[i].args))] = i
                (ref,), _ = ray.wait(list(pending), num_returns=1)
                i = pending.pop(ref)
                try:
                    result, seconds, fingerprint, node = ray.get(ref)
                except ray.exceptions.RayTaskError as exc:  # the chunk itself raised
                    if not isinstance(exc.cause, BaseException):
                        raise
                    raise exc.cause from None
                except ray.exceptions.RayError as exc:
                    raise JobError(
                        f"Ray lost chunk {i + 1} of {len(chunks)} after {self.retries} retries "
                        f"({type(exc).__name__}: {first_line(exc)[:160]}); {self._kept(outputs)}"
                    ) from None
                if fingerprint != code_fingerprint():
                    raise JobError(
                        f"the Ray worker on node {node} runs other solver/softarm_gym code "
                        f"(fingerprint {fingerprint}, this process {code_fingerprint()}): install "
                        "the same softarm-gym version on every node")
                record(i, result, seconds)
        finally:
            cancel_unfinished(ray, pending, force=True)


# ----------------------------------------------------------------------------- Ray connection


def cancel_unfinished(ray, refs, *, force: bool) -> None:
    """``ray.cancel`` the tasks of ``refs`` whose results are not ready yet, and only those.

    Cancelling a task that has just finished races, in Ray's driver, with the task's
    completion: the driver can abort with "Check failed: it != submissible_tasks_.end() Tried
    to complete task that was not pending" (exit status 1, no Python traceback). Cancelling
    every task after they had all stopped aborted it twice in two runs of 150 cancels
    (after 10 and 30); cancelling the unfinished ones only, in none.
    """
    refs = list(refs)
    if not refs:
        return
    _, unfinished = ray.wait(refs, num_returns=len(refs), timeout=0)
    for ref in unfinished:
        ray.cancel(ref, force=force)


@contextlib.contextmanager
def ray_session(address: str | None):
    """The ``ray`` module, connected for the ``with`` block; stdout silenced meanwhile.

    Connects to ``address`` (see :class:`Runner`) unless this process already has a Ray
    session, which is then used and left open; a session opened here is shut down at the end.
    Ray's driver prints its notices (a worker died, ...) on stdout, which holds the commands'
    ``--json`` output; what matters reaches the caller as an exception.

    Raises:
        JobError: Ray is not installed, ``address`` is malformed or unreachable (checked
            with a TCP probe first, where Ray alone retries for minutes), or the cluster runs
            another Ray or Python version (one line each).
    """
    with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet):
        ray, connected = _ray_connect(address)
        try:
            yield ray
        finally:
            if connected:
                ray.shutdown()


def _ray_connect(address):
    """``(ray, connected)``: the Ray module, initialised; ``connected`` if this call did it."""
    try:
        import ray
    except ImportError:
        raise JobError("backend 'ray' needs Ray: pip install 'softarm-gym[ray]'") from None
    if ray.is_initialized():
        return ray, False
    if address is not None:
        _check_reachable(address)
    options = dict(log_to_driver=False, logging_level=logging.ERROR)
    try:
        if address is None:
            ray.init(include_dashboard=False, **options)
        else:
            ray.init(address=address, **options)
    except RuntimeError as exc:
        if "version mismatch" in str(exc).lower():
            raise JobError(_mismatch(exc, address)) from None
        raise JobError(f"cannot start Ray: {first_line(exc)}") from None
    except ConnectionError as exc:
        raise JobError(f"cannot connect to a Ray cluster at {address!r}: {first_line(exc)}") from None
    return ray, True


def first_line(exc) -> str:
    """The first line of an exception's message (its type name if it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _mismatch(exc, address) -> str:
    found = re.findall(r"Ray: (\S+)\s+Python: (\S+)", str(exc))
    if len(found) == 2:
        (ray_c, py_c), (ray_m, py_m) = found
        return (f"Ray version mismatch: the cluster at {address!r} runs Ray {ray_c} on Python {py_c}, "
                f"this process Ray {ray_m} on Python {py_m}; install the same versions on every node")
    return "Ray version mismatch: " + " ".join(str(exc).split())


def _check_reachable(address: str) -> None:
    """Fail fast with one line if nothing listens at ``address`` (Ray itself retries for minutes)."""
    target = address
    if address == "auto":
        try:
            from ray._private.services import canonicalize_bootstrap_address_or_die
        except ImportError:  # a Ray without this helper: let ray.init resolve "auto" itself
            return
        try:
            target = canonicalize_bootstrap_address_or_die("auto")
        except ConnectionError:
            raise JobError("--address auto: no running Ray cluster found on this machine "
                           "(start one with `ray start --head`)") from None
    host, sep, port = target.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise JobError(f"Ray address {address!r} is not 'auto', HOST:PORT or ray://HOST:PORT")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise JobError(f"cannot reach a Ray cluster at {address!r}: {reason}") from None


# ----------------------------------------------------------------------------- output files


@contextlib.contextmanager
def atomic_path(path):
    """A temporary path beside ``path`` (same suffix) that replaces ``path`` on success.

    Readers never see a partial file: the content appears under ``path`` only by an atomic
    rename once the ``with`` block has finished; on an exception the temporary file goes.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


def write_atomic(path, text: str) -> None:
    """Write ``text`` to ``path`` through :func:`atomic_path`."""
    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
