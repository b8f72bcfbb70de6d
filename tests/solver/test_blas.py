"""The solver's dense algebra runs on one BLAS thread (solver.blas; docs/design.md §8)."""

import importlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import solver
from solver import PSI, designs
from solver.blas import single_blas_thread
from solver.kernels import relax as relax_kernels

solve_module = importlib.import_module("solver.paths.dispatch")  # where solve() picks its path


def _blas_threads() -> set[int]:
    return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}


@pytest.fixture
def two_blas_threads():
    """BLAS at two threads around the test, as on this 2-core machine by default."""
    with threadpool_limits(limits=2, user_api="blas"):
        yield _blas_threads()


def test_the_block_limits_blas_to_one_thread_and_restores_the_limit(two_blas_threads):
    with single_blas_thread():
        assert _blas_threads() == {1}
    assert _blas_threads() == two_blas_threads


def test_a_contact_step_and_its_snap_relaxation_run_on_one_blas_thread(monkeypatch, two_blas_threads):
    """OctArm V curled round a disc at its base, switched to channels I of sections 1 and 2:
    the arm snaps, and the snap's landing is found by relaxation (L-BFGS, which calls no BLAS
    itself: it runs inside the contact solve's block)."""
    seen = {"contact": [], "relax": []}
    contact, minimise = solve_module.solve_contact, relax_kernels.minimise

    def contact_spy(*args, **kwargs):
        seen["contact"].append(_blas_threads())
        return contact(*args, **kwargs)

    def minimise_spy(*args, **kwargs):
        seen["relax"].append(_blas_threads())
        return minimise(*args, **kwargs)

    monkeypatch.setattr(solve_module, "solve_contact", contact_spy)
    monkeypatch.setattr(relax_kernels, "minimise", minimise_spy)
    arm = designs.octarm_v()
    disc = solver.Disc(center=(-0.1596, -0.0616), radius=0.1493, stiffness=9.8e4)
    start = np.array([1, 1, 0, 1, 1, 0]) * 100 * PSI
    free = solver.solve(arm, start, solver.Scene())
    scene = solver.Scene(obstacles=(disc,))
    eq = solver.solve(arm, start, scene, warm_start=free)
    eq = solver.solve(arm, np.array([1, 0, 1, 0, 0, 0]) * 100 * PSI, scene, warm_start=eq)
    assert eq.converged
    assert seen["contact"] and seen["relax"], "the step no longer snaps: choose another"
    assert all(threads == {1} for threads in seen["contact"] + seen["relax"])
    assert _blas_threads() == two_blas_threads


def test_scipys_blas_is_limited_even_when_loaded_after_the_first_block():
    """numpy's and scipy's OpenBLAS are two libraries, and scipy's loads with scipy.linalg or
    scipy.optimize (the snap relaxation's L-BFGS): a first block before that must still know
    it. In a fresh process, where nothing has loaded scipy's yet."""
    code = textwrap.dedent("""
        from threadpoolctl import threadpool_info, threadpool_limits
        from solver.blas import single_blas_thread
        with threadpool_limits(limits=2, user_api="blas"):
            with single_blas_thread():
                pass
            import scipy.optimize  # noqa: F401
            with single_blas_thread():
                inside = [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]
        print(len(inside), sorted(set(inside)))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    count, threads = out.split(" ", 1)
    assert int(count) >= 2, "numpy's and scipy's BLAS are no longer two libraries: rethink the test"
    assert threads.strip() == "[1]"
