"""Runs of one job under numba's thread counts: the tests that check work done side by side
(:class:`solver.stepper.CopyPool`) gives, bit for bit, what one thread gives."""

import threading

import numba
import pytest

needs_two_threads = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2,
                                       reason="one numba thread on this machine: nothing runs side by side")


def by_thread_count(job, spied, name, prepare=lambda: None, counts=(1, 2)):
    """``job(prepare())`` under each numba thread count of ``counts``, with ``spied.name`` (a
    function of a class or module) wrapped to record the threads it runs on during ``job``;
    both restored after. Returns [(result, number of threads that ran ``spied.name``)], one
    per count."""
    threads = set()
    original = getattr(spied, name)
    own = name in vars(spied)  # else inherited: restored by removing the spy

    def spy(*args, **kwargs):
        threads.add(threading.get_ident())
        return original(*args, **kwargs)

    setattr(spied, name, spy)
    out = []
    before = numba.get_num_threads()
    try:
        for count in counts:
            numba.set_num_threads(count)
            ready = prepare()
            threads.clear()
            out.append((job(ready), len(threads)))
    finally:
        numba.set_num_threads(before)
        if own:
            setattr(spied, name, original)
        else:
            delattr(spied, name)
    return out
