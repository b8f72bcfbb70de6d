"""The one place that sets numba flags for every kernel in :mod:`solver` (and its users).

Kernels are compiled with ``cache=True`` so that a fresh process (a test run, a CI job,
an environment worker) loads machine code from ``__pycache__`` instead of recompiling.
``fastmath`` stays off: the kernels rely on NaN/inf propagating so that a diverging
solve is detected and reported rather than silently returning garbage.

The on-disk cache heals itself:

* an entry that cannot be read (a truncated or corrupt ``.nbi``/``.nbc`` file, say from a
  full disk or a killed process) is deleted with a :class:`CacheWarning` and the kernel
  recompiled, instead of every later process failing with ``UnpicklingError``;
* where numba finds no writable cache directory (a read-only install without a writable
  HOME, which numba reports as "cannot cache function ...: no locator available"), the
  cache moves to :func:`fallback_cache_dir` (``$TMPDIR/softarm-numba-<uid>``), as if
  ``NUMBA_CACHE_DIR`` had been set, with a :class:`CacheWarning` the first time. Set
  ``NUMBA_CACHE_DIR`` yourself to choose the place.

:func:`clear_cache` (``softarm warmup --clear``) deletes the compiled files of every kernel
made with :func:`njit`.

A kernel missing from the cache compiles on its first call (seconds, once): the first such
compile in a process prints one line on stderr saying so, and where the result is cached
(:func:`announce_compiles` turns that off).

A kernel called from another kernel is compiled for the plain types of its arguments, not their
literal values: numba otherwise compiles a callee once per constant a caller passes (``record=True``
here, a variable flag there, ``0`` for a start index: four copies of the contact integrator). A
callee that only types with the value itself (an index into a heterogeneous tuple) is still
compiled for it (:func:`_typed_without_literals`).

Every kernel compiled on its own (one called from Python, or from other kernels without
``inline="always"``) links the machine code of everything it calls and optimises that whole
call graph again: each one-line wrapper round the 3-D contact residual pass took 5–7 s to
compile, and a four-line loop round the 3-D row kernel 20 s. So a kernel with a single caller,
or a thin wrapper, is inlined into its callers (``@njit(inline="always")``), and a wrapper that
only allocates scratch arrays for Python is a plain Python function; compiling is most of
``softarm warmup`` and of a fresh ``make test``. A kernel that Python calls (the paths, or the
tests, which call kernels directly) is compiled on its own whatever its flag, so it is not
inlined: that would compile it twice. :func:`record_compiles` (``softarm warmup --profile``)
measures what each compile costs.
"""

from __future__ import annotations

import contextlib
import functools
import glob
import os
import stat
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numba
from numba.core import config, errors, event, types
from numba.core.caching import FunctionCache

__all__ = ["njit", "prange", "CacheWarning", "clear_cache", "fallback_cache_dir", "announce_compiles",
           "record_compiles"]

_FLAGS = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}
_KERNELS: list = []
"""Every dispatcher made by :func:`njit` with caching on (for :func:`clear_cache`)."""


_ANNOUNCE = {"enabled": True, "done": False}
"""Whether the first compile of a process prints its line, and whether it has."""


def announce_compiles(enabled: bool = True) -> None:
    """Print (the default) or not the one line on stderr with which a process's first
    compile of a kernel missing from the cache says that it compiles, and where it caches."""
    _ANNOUNCE["enabled"] = bool(enabled)


def _announce_compile(cache_path: str) -> None:
    if _ANNOUNCE["enabled"] and not _ANNOUNCE["done"]:
        _ANNOUNCE["done"] = True
        print(f"softarm: compiling numba kernels on first use (once; cached in {cache_path}; "
              "`softarm warmup` compiles them all up front)", file=sys.stderr, flush=True)


class _CompileListener(event.Listener):
    """Numba's compile events as (kernel, seconds, exclusive seconds) rows: a kernel's time
    includes the kernels it compiles in turn, its exclusive time does not."""

    def __init__(self, rows: list):
        self.rows = rows
        self.open: list = []  # [name, start, seconds of nested compiles] per compile under way

    def on_start(self, ev):
        fn = ev.data["dispatcher"].py_func
        self.open.append([f"{fn.__module__}.{fn.__qualname__}", time.perf_counter(), 0.0])

    def on_end(self, ev):
        name, start, nested = self.open.pop()
        seconds = time.perf_counter() - start
        if self.open:
            self.open[-1][2] += seconds
        self.rows.append({"kernel": name, "seconds": seconds, "exclusive_seconds": seconds - nested})


@contextlib.contextmanager
def record_compiles():
    """Record every numba compile in this process while the context is open (``softarm warmup
    --profile``): yields a list that fills with one dict per compile, ``kernel`` (module and
    name; numba's own overloads too), ``seconds`` and ``exclusive_seconds`` (less the kernels
    it compiled in turn, which have rows of their own). Loads from the cache are not compiles."""
    rows: list = []
    with event.install_listener("numba:compile", _CompileListener(rows)):
        yield rows


class CacheWarning(UserWarning):
    """The numba cache was repaired or moved; results are unaffected."""


def _sources_stamp(folder: Path) -> tuple:
    """(latest modification time, total size, count) of the modules in ``folder`` and its
    subpackages (``kernels/``) whose code kernels compile in: every module that defines
    kernels (``@njit``) and ``layout.py``, whose constants they freeze."""
    files = sorted(p for p in folder.rglob("*.py")
                   if p.name == "layout.py" or "@njit" in p.read_text(encoding="utf-8"))
    stats = [p.stat() for p in files]
    return (max((s.st_mtime_ns for s in stats), default=0), sum(s.st_size for s in stats),
            len(stats))


@functools.cache
def _solver_stamp() -> tuple:
    """:func:`_sources_stamp` of this package, worked out at the first kernel (once a process)."""
    return _sources_stamp(Path(__file__).parent)


class _HealingCache(FunctionCache):
    """numba's per-function cache, except that an unreadable entry is deleted and recompiled,
    and that an entry is stale when any solver module kernels compile in has changed.

    numba stamps an entry with its own module's file alone. The kernels inline the rod
    equations of :mod:`solver.rod` (and constants of :mod:`solver.layout`, helpers of other
    kernel modules, in :mod:`solver.kernels` or not) into their machine code, so after an
    edit there an entry stamped with an unchanged module of its own would still load, and
    run the old equations. Each entry's stamp is therefore its module's and the solver's
    kernel modules' together: an edit of any of them recompiles every kernel (``softarm
    warmup``).
    """

    def __init__(self, py_func):
        super().__init__(py_func)
        self._cache_file._source_stamp = (self._cache_file._source_stamp, _solver_stamp())

    def load_overload(self, sig, target_context):
        try:
            loaded = super().load_overload(sig, target_context)
        except Exception as exc:  # UnpicklingError, EOFError, ...: whatever a damaged file raises
            self._discard(f"could not be read ({type(exc).__name__}: {exc})")
            loaded = None  # numba compiles it, then saves a fresh entry
        if loaded is None:
            _announce_compile(self.cache_path)
        return loaded

    def save_overload(self, sig, data):
        try:
            super().save_overload(sig, data)
        except Exception as exc:  # a damaged index met while saving, a full disk, ...
            self._discard(f"could not be written ({type(exc).__name__}: {exc})")

    def files(self) -> list[Path]:
        """This kernel's index and data files."""
        base = glob.escape(os.path.join(self.cache_path, self._impl.filename_base))
        return [Path(p) for p in glob.glob(base + ".nbi") + glob.glob(base + ".*.nbc")]

    def _discard(self, why: str) -> None:
        for path in self.files():
            path.unlink(missing_ok=True)
        warnings.warn(f"numba cache of {self._py_func.__qualname__} in {self.cache_path} {why}; "
                      "removed it, the kernel is compiled afresh", CacheWarning, stacklevel=4)


def fallback_cache_dir() -> Path:
    """A private cache directory for when numba finds no writable one.

    ``$TMPDIR/softarm-numba-<uid>``, created with mode 0700, so that later processes reuse
    it. If that path exists but is not a directory owned by this user and closed to others
    (cache files are unpickled, so a directory others can write would let them run code
    here), a fresh ``mkdtemp`` directory is used instead.
    """
    uid = os.getuid() if hasattr(os, "getuid") else None
    path = Path(tempfile.gettempdir()) / f"softarm-numba-{uid if uid is not None else 'user'}"
    try:
        path.mkdir(mode=0o700, exist_ok=True)
        st = path.lstat()
        private = stat.S_ISDIR(st.st_mode) and not st.st_mode & 0o022 \
            and (uid is None or st.st_uid == uid)
    except OSError:
        private = False
    return path if private else Path(tempfile.mkdtemp(prefix="softarm-numba-"))


def _cache_for(dispatcher) -> _HealingCache:
    try:
        return _HealingCache(dispatcher.py_func)
    except RuntimeError as exc:  # "cannot cache function ...: no locator available for file ..."
        if config.CACHE_DIR:
            raise
        existing = {p for p in Path(tempfile.gettempdir()).glob("softarm-numba-*")}
        config.CACHE_DIR = str(fallback_cache_dir())
        if Path(config.CACHE_DIR) not in existing:  # say it once, not in every later process
            warnings.warn(f"numba found no writable cache directory ({exc}); caching in "
                          f"{config.CACHE_DIR} instead (set NUMBA_CACHE_DIR to choose)",
                          CacheWarning, stacklevel=4)
        return _HealingCache(dispatcher.py_func)


def _typed_without_literals(dispatcher) -> None:
    """Make calls from other kernels compile ``dispatcher`` for their arguments' plain types.

    Branch pruning on a literal flag saves a predictable branch at run time, but each literal
    combination costs a full compile of the callee and of everything it inlines; the floating
    point operations are the same either way, so results do not change. Where the plain types
    do not type (a literal index into a heterogeneous tuple), the literal call is compiled as
    numba would have.
    """
    get_call_template = dispatcher.get_call_template

    def plain_call_template(args, kws):
        plain = tuple(types.unliteral(a) for a in args)
        if plain == tuple(args) and not kws:
            return get_call_template(args, kws)
        try:
            return get_call_template(plain, {k: types.unliteral(v) for k, v in kws.items()})
        except errors.TypingError:
            return get_call_template(args, kws)

    dispatcher.get_call_template = plain_call_template


def _compile(fn, flags):
    cache = flags.pop("cache")
    dispatcher = numba.njit(**flags)(fn)
    _typed_without_literals(dispatcher)
    if cache:
        dispatcher._cache = _cache_for(dispatcher)  # what ``enable_caching`` sets, healing
        _KERNELS.append(dispatcher)
    return dispatcher


def njit(*args, **overrides):
    """``numba.njit`` with the project's flags (``cache``, ``nogil``, numpy error model).

    Usable bare (``@njit``) or with keyword overrides (``@njit(parallel=True)``).
    """
    flags = {**_FLAGS, **overrides}
    if args and callable(args[0]):
        return _compile(args[0], flags)
    if args:
        raise TypeError("njit takes keyword flags only (signatures are inferred)")
    return lambda fn: _compile(fn, dict(flags))


def clear_cache() -> list[Path]:
    """Delete every compiled file (``*.nbi``, ``*.nbc``) in the cache directories of the kernels
    made so far by :func:`njit`; returns the deleted paths. Import the kernels' modules first."""
    folders = {Path(k._cache.cache_path) for k in _KERNELS}
    removed = []
    for folder in sorted(folders):
        for path in sorted([*folder.glob("*.nbi"), *folder.glob("*.nbc")]):
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


prange = numba.prange
