"""Strict JSON and all-or-nothing writes (softarm_gym.files)."""

import json

import numpy as np
import pytest

from softarm_gym.files import atomic_write, json_text, write_json


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
