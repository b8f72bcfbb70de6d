"""The environment benchmark's reset rows and table (the figures themselves live in docs/bench)."""

from softarm_gym.benchmarks.envs import RESET_IDS, TARGETS, format_table, reset_times, target_for
from softarm_gym.cli import main


def test_reset_times_compare_plain_and_randomized_resets():
    row = reset_times(RESET_IDS[0], n_resets=5)
    assert row["env_id"] == RESET_IDS[0] and row["n_resets"] == 5
    assert row["plain_s"] > 0 and row["randomized_s"] > 0
    assert row["ratio"] == row["randomized_s"] / row["plain_s"]
    table = format_table({"cases": [], "n_envs": 2, "n_steps": 1, "resets": [row]})
    assert "randomized ms" in table and RESET_IDS[0] in table


def test_contact_tasks_are_held_to_the_wrap_target():
    for env_id in ("SoftArm/OctArmWrap-v0", "SoftArm/OctArmObstacleReach-v0", "SoftArm/CTObstacleReach-v0"):
        assert target_for(env_id, "true") == TARGETS["wrap"]
    assert target_for("SoftArm/OctArmReach-v0", "true") == TARGETS["reach_true"]


def test_env_bench_ids_are_checked(capsys):
    assert main(["bench", "--env", "--ids", "SoftArm/NoSuchTask-v0"]) == 2
    assert "unknown ID(s) SoftArm/NoSuchTask-v0" in capsys.readouterr().err
    assert main(["bench", "--ids", "SoftArm/CTReach-v0"]) == 2
    assert "--ids only applies to --env" in capsys.readouterr().err
