"""The environment benchmark's reset rows and table (the figures themselves live in docs/bench)."""

from softarm_gym.benchmarks.envs import RESET_IDS, format_table, reset_times


def test_reset_times_compare_plain_and_randomized_resets():
    row = reset_times(RESET_IDS[0], n_resets=5)
    assert row["env_id"] == RESET_IDS[0] and row["n_resets"] == 5
    assert row["plain_s"] > 0 and row["randomized_s"] > 0
    assert row["ratio"] == row["randomized_s"] / row["plain_s"]
    table = format_table({"cases": [], "n_envs": 2, "n_steps": 1, "resets": [row]})
    assert "randomized ms" in table and RESET_IDS[0] in table
