"""One BLAS thread for the solver's dense algebra (this package only).

The solver's dense problems are small: the contact Newton's coupled columns (tens of
unknowns). A second BLAS thread does not speed them up, and where the cores are busy —
vectorised envs, a training beside the envs, several sweeps — OpenBLAS's threads wait on
each other at every call: a wrap step that snaps took ten times longer on a loaded 2-core
machine (docs/design.md §8). Parallel work is across arms (``BatchStepper``, processes),
never inside one solve.
"""

from __future__ import annotations

from threadpoolctl import ThreadpoolController

__all__ = ["single_blas_thread"]

_controller: ThreadpoolController | None = None


def single_blas_thread():
    """A context manager limiting every loaded BLAS/LAPACK library to one thread for the block
    (the previous limits come back at its end; about 20 µs, so for solves of milliseconds).

    The libraries are looked up once, at the first call, with scipy's loaded for it: numpy's
    and scipy's OpenBLAS are two libraries, and scipy's (which numba's ``np.linalg`` and the
    snap relaxation's L-BFGS call) is loaded only when ``scipy.linalg`` or ``scipy.optimize``
    first is — a lookup before that left it out, on two threads in every later block.
    """
    global _controller
    if _controller is None:
        import scipy.linalg  # noqa: F401  (loads scipy's OpenBLAS before the lookup)

        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")
