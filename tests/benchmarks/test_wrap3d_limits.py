"""The 3D wrap's friction/gravity sweep: its recorded result, table, figure and CLI (the physics
itself is tested in tests/envs/test_wrap3d_friction.py)."""

import json
from pathlib import Path

import gymnasium as gym
import pytest

from softarm_gym.benchmarks.wrap3d_limits import (
    ENV_ID,
    FRICTIONS,
    GRAVITY_FRACTIONS,
    curl_wrap,
    format_table,
    main,
    run,
)

RECORD_PATH = Path(__file__).resolve().parents[2] / "docs" / "bench" / "wrap3d_limits.json"
RECORD = json.loads(RECORD_PATH.read_text())


def test_record_covers_both_sweeps_and_reproduces_a_case():
    assert RECORD["env_id"] == ENV_ID
    assert set(RECORD["friction"]) == {str(mu) for mu in FRICTIONS}
    registered = str(gym.spec(ENV_ID).kwargs["friction"])
    assert set(RECORD["gravity"]) == {registered, "0.0"}
    for sweep in RECORD["gravity"].values():
        assert set(sweep) == {str(f) for f in GRAVITY_FRACTIONS}
    # The full-gravity column is the friction sweep's own row.
    assert RECORD["gravity"][registered]["1.0"] == RECORD["friction"][registered]
    assert curl_wrap(1, RECORD["steps"]) == pytest.approx(RECORD["friction"][registered][1], abs=1e-6)


def test_table_counts_the_wraps_past_270():
    table = format_table(RECORD)
    rows = table.splitlines()[2:]
    assert len(rows) == len(FRICTIONS) + 2 * (len(GRAVITY_FRACTIONS) - 1)
    assert "| 0 | 0.375 g | 315, 305, 315, 287, 317, 322, 281, 298 | 310 | 8 of 8 |" in rows
    assert all(row.endswith("| 0 of 8 |") for row in rows[:len(FRICTIONS)])


def test_picture_and_cli(tmp_path, capsys):
    png = tmp_path / "limits.png"
    assert main(["--from-json", str(RECORD_PATH), "--picture", str(png)]) == 0
    assert png.stat().st_size > 10_000
    assert main(["--from-json", str(RECORD_PATH)]) == 0
    assert "| 0.7 | 1 g | 92, 76, 87, 87, 89, 83, 89, 86 | 87 | 0 of 8 |" in capsys.readouterr().out


def test_bad_seeds():
    with pytest.raises(ValueError, match="seeds"):
        run(0)
    with pytest.raises(SystemExit) as exit_info:
        main(["--seeds", "0"])
    assert exit_info.value.code == 2
