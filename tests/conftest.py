"""Settings shared by every test."""

import os
import signal

import numba
import pytest

# render_mode="human" opens a pygame window; the dummy video driver makes that headless.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

# Several tests interrupt a child process with SIGINT (Ctrl-C) and check what it saved. A
# shell without job control starts background jobs with SIGINT ignored, and an ignored signal
# stays ignored across exec, so a suite started as `make test &` would hand its children a
# deaf ear. Restoring Python's handler here makes the children's disposition the default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _numba_threads_left_as_found(request):
    """A test that changes numba's thread count must put it back: the tests a worker runs next
    (which ones depends on how pytest-xdist shares them out) would otherwise run on one thread,
    and a threaded kernel's test would fail or, worse, pass without running threaded."""
    before = numba.get_num_threads()
    yield
    after = numba.get_num_threads()
    if after != before:
        numba.set_num_threads(before)
        pytest.fail(f"{request.node.nodeid} left numba on {after} thread(s), found on {before}")
