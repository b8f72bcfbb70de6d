"""The batched env benchmark's rows (the figures themselves live in docs/bench)."""

import numba
import numpy as np
import pytest

from softarm_gym.benchmarks.vector_bench import format_table, run


def test_rows_report_the_median_of_alternating_runs_and_restore_the_thread_count():
    threads = numba.get_num_threads()
    rows = run(sizes=(4,), steps=3, repeats=2)
    assert numba.get_num_threads() == threads
    (row,) = rows
    assert row["num_envs"] == 4 and row["steps"] == 3 and row["threads"] == threads
    assert len(row["runs_env_steps_per_s"]) == len(row["runs_one_thread_env_steps_per_s"]) == 2
    assert row["env_steps_per_s"] == np.median(row["runs_env_steps_per_s"])
    assert row["one_thread_env_steps_per_s"] == np.median(row["runs_one_thread_env_steps_per_s"])
    assert row["env_steps_per_s"] == pytest.approx(4 * 3 / row["seconds"])
    assert 0.0 <= row["converged_fraction"] <= 1.0
    assert "| 4 arms |" in format_table(rows)


@pytest.mark.parametrize("repeats", [0, 1.5, True])
def test_repeats_must_be_a_positive_integer(repeats):
    with pytest.raises(ValueError, match="repeats must be an integer >= 1"):
        run(sizes=(4,), steps=1, repeats=repeats)
