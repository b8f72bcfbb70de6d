"""Python threads over a batch's copies (:class:`CopyPool`): the project's kernels release
the GIL (:mod:`solver.jit`), so jobs that each touch only their own copies' rows share the
cores without numba's parallel loops — and without their compile, a parallel kernel being
compiled apart from its serial twin with the whole call graph it links."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba

__all__ = ["CopyPool"]


class CopyPool:
    """Jobs over a batch's copies on ``numba.get_num_threads()`` Python threads: the
    general path's solves (and the spatial steppers') run in kernels that release the GIL,
    so copies solved side by side share the cores. Each job must touch only its own copy's
    data; :meth:`map` returns the results in order, as the serial loop would. The pool is
    made on first use (and again if numba's thread count changed); a pickled copy has none;
    ``with CopyPool() as pool:`` lets its threads go at the block's end (a pool for one call).
    """

    def __init__(self):
        self._pool = None
        self._workers = 0

    def map(self, job, items) -> list:
        """``[job(item) for item in items]``, on the threads where there are two items and
        two threads or more."""
        items = list(items)
        workers = numba.get_num_threads()
        if len(items) < 2 or workers < 2:
            return [job(item) for item in items]
        if self._pool is None or self._workers != workers:
            self.close()
            self._pool, self._workers = ThreadPoolExecutor(workers), workers
        return list(self._pool.map(job, items))

    def close(self) -> None:
        """Let the pool's threads go (a later :meth:`map` makes a new pool)."""
        if self._pool is not None:
            self._pool.shutdown()
        self._pool, self._workers = None, 0

    def __enter__(self) -> CopyPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __getstate__(self):
        return {"_pool": None, "_workers": 0}
