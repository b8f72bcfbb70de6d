"""The one place that sets numba flags for every kernel in :mod:`solver`.

Kernels are compiled with ``cache=True`` so that a fresh process (a test run, a CI job,
an environment worker) loads machine code from ``__pycache__`` instead of recompiling.
``fastmath`` stays off: the kernels rely on NaN/inf propagating so that a diverging
solve is detected and reported rather than silently returning garbage.
"""

from __future__ import annotations

import numba

_FLAGS = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}


def njit(*args, **overrides):
    """``numba.njit`` with the project's flags (``cache``, ``nogil``, numpy error model).

    Usable bare (``@njit``) or with keyword overrides (``@njit(parallel=True)``).
    """
    flags = {**_FLAGS, **overrides}
    if args and callable(args[0]):
        return numba.njit(**flags)(args[0])
    return numba.njit(*args, **flags)


prange = numba.prange
