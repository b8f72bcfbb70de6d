"""Runs of one job under numba's thread counts: the tests that check work done side by side
(:class:`solver.threads.CopyPool`) gives, bit for bit, what one thread gives."""

import threading

import numba
import pytest

needs_two_threads = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2,
                                       reason="one numba thread on this machine: nothing runs side by side")


def by_thread_count(job, spied, name, prepare=lambda: None, counts=(1, 2)):
    """``job(prepare())`` under each numba thread count of ``counts``, with ``spied.name`` (a
    function of a class or module) wrapped to record the threads it runs on during ``job``;
    both restored after. Returns [(result, number of threads that ran ``spied.name``)], one
    per count.

    With two threads or more, the first calls from two threads other than the caller's wait
    for each other (a barrier, 60 s): work that a pool really runs side by side passes it, and
    the count of threads does not hang on how the OS schedules a short job (on a loaded
    machine one worker could finish every job before the other started). Work done one job
    after another breaks the barrier (``threading.BrokenBarrierError``)."""
    threads = set()
    caller = threading.get_ident()
    original = getattr(spied, name)
    own = name in vars(spied)  # else inherited: restored by removing the spy
    meeting = {"barrier": None, "met": set()}

    def spy(*args, **kwargs):
        me = threading.get_ident()
        threads.add(me)
        barrier, met = meeting["barrier"], meeting["met"]
        if barrier is not None and me != caller and me not in met and len(met) < barrier.parties:
            met.add(me)
            barrier.wait()
        return original(*args, **kwargs)

    setattr(spied, name, spy)
    out = []
    before = numba.get_num_threads()
    try:
        for count in counts:
            numba.set_num_threads(count)
            ready = prepare()
            threads.clear()
            meeting["met"] = set()
            meeting["barrier"] = threading.Barrier(2, timeout=60.0) if count >= 2 else None
            out.append((job(ready), len(threads)))
    finally:
        numba.set_num_threads(before)
        if own:
            setattr(spied, name, original)
        else:
            delattr(spied, name)
    return out
