"""Strict JSON and all-or-nothing writes (softarm_gym.files)."""

import _thread
import json
import signal

import numpy as np
import pytest

from softarm_gym.files import atomic_write, json_text, signals_deferred, write_json


def test_json_text_is_strict_and_plain():
    text = json_text({"tip": np.array([0.1, np.nan]), "residual": float("inf"), "n": np.int64(3),
                      "ok": np.bool_(True), "nested": [(1.5, -np.inf)]})
    assert json.loads(text) == {"tip": [0.1, None], "residual": None, "n": 3, "ok": True,
                                "nested": [[1.5, None]]}
    assert "NaN" not in text and "Infinity" not in text
    with pytest.raises(TypeError):
        json_text({"object": object()})


def test_atomic_write_leaves_the_old_file_on_error(tmp_path):
    path = tmp_path / "out.json"
    write_json(path, {"a": 1})
    with pytest.raises(RuntimeError), atomic_write(path) as fh:
        fh.write('{"a": ')
        raise RuntimeError("interrupted mid-write")
    assert json.loads(path.read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]  # no temporary file left behind
    with pytest.raises(TypeError):
        write_json(path, {"x": object()})
    assert json.loads(path.read_text()) == {"a": 1}


def _pass_bytecode_boundaries() -> list[int]:
    """Run Python code for a moment: a simulated signal's handler runs at such boundaries."""
    return [i * i for i in range(10_000)]


def test_a_held_interrupt_is_delivered_after_the_block_even_when_the_os_signal_is_blocked():
    """Ray cancels a task gently with a *simulated* SIGINT while its worker blocks the real one:
    the held interrupt must still raise KeyboardInterrupt when the block ends, not sit pending."""
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    finished_block = False
    try:
        with pytest.raises(KeyboardInterrupt):
            with signals_deferred(signal.SIGINT, signal.SIGTERM):
                _thread.interrupt_main(signal.SIGINT)
                _pass_bytecode_boundaries()
                finished_block = True
        assert signal.SIGINT not in signal.sigpending()  # nothing left for later
    finally:
        signal.sigtimedwait({signal.SIGINT}, 0)  # a left-over OS signal must fail this test, not stop pytest
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    assert finished_block  # the block was not cut short
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_signals_deferred_delivers_each_held_signal_to_the_restored_handler_once():
    received = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: received.append(signum))
    try:
        with signals_deferred(signal.SIGTERM):
            signal.raise_signal(signal.SIGTERM)
            signal.raise_signal(signal.SIGTERM)
            _pass_bytecode_boundaries()
            assert received == []
        assert received == [signal.SIGTERM]
        with signals_deferred(signal.SIGTERM):  # nothing arrived: nothing delivered
            pass
        assert received == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, previous)
