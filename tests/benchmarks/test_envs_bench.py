"""The environment benchmark's reset rows and table (the figures themselves live in docs/bench)."""

import numpy as np

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


def test_reach_is_also_timed_in_3d_and_with_self_contact():
    """The 3D rows: the reach IDs of SPATIAL_IDS with planar=False, held to the 3D targets, and
    the 3D ids (registered spatial) labelled 3D; the self-contact rows: the IDs of
    SELF_CONTACT_IDS with self_contact=True."""
    from softarm_gym.benchmarks.envs import SELF_CONTACT_IDS, SINGLE_REPEATS, SPATIAL_IDS, run

    assert SPATIAL_IDS[0] in SELF_CONTACT_IDS and "SoftArm/CTWrap-v1" in SELF_CONTACT_IDS
    result = run(n_steps=4, n_envs=2, observations=("true",),
                 ids=(SPATIAL_IDS[0], "SoftArm/CTWrap-v1", "SoftArm/CTWrap3D-v0"))
    rows = {(c["env_id"], c["planar"], c["self_contact"]): c for c in result["cases"]}
    for row in rows.values():
        assert len(row["single_runs_steps_per_s"]) == SINGLE_REPEATS
        assert row["single_steps_per_s"] == np.median(row["single_runs_steps_per_s"])
    assert set(rows) == {(SPATIAL_IDS[0], True, False), (SPATIAL_IDS[0], False, False),
                         ("SoftArm/CTWrap-v1", True, False), (SPATIAL_IDS[0], True, True),
                         ("SoftArm/CTWrap-v1", True, True), ("SoftArm/CTWrap3D-v0", False, False)}
    assert rows[(SPATIAL_IDS[0], False, False)]["target_steps_per_s"] == TARGETS["reach_true_3d"]
    assert target_for(SPATIAL_IDS[1], "cable_encoder", planar=False) == TARGETS["estimator"]
    table = format_table(result)
    assert f"{SPATIAL_IDS[0]} 3D" in table and "SoftArm/CTWrap-v1 self" in table
    assert "SoftArm/CTWrap3D-v0 3D" in table
