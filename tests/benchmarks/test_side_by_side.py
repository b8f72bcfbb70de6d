"""The side-by-side contact benchmark: its jobs measure what they say, in the tree they are sent to,
and its tables read the result (the figures themselves live in docs/bench)."""

from pathlib import Path

import pytest

from softarm_gym.benchmarks import side_by_side
from softarm_gym.benchmarks.envs import CONTACT_RATIO_CASES, CONTACT_TARGETS, RATIO_UNITS, contact_ratios

ROOT = Path(__file__).resolve().parents[2]
CASES = [["free reach", "SoftArm/OctArmReach-v1", {}],
         ["3D reach", "SoftArm/OctArmReach-v1", {"planar": False}],
         ["3D wrap", "SoftArm/OctArmWrap3D-v0", {}]]


def test_ratio_job_divides_each_case_by_its_unit_step():
    result = side_by_side.time_ratio_cases(CASES, n_steps=3, seed=0, units={"3D wrap": "3D reach"})
    rates, ratios = result["steps_per_s"], result["times_unit"]
    assert ratios["free reach"] == 1.0
    assert ratios["3D reach"] == rates["free reach"] / rates["3D reach"]
    assert ratios["3D wrap"] == rates["3D reach"] / rates["3D wrap"]
    assert result["module"].startswith(str(ROOT))


def test_planner_job_reports_every_searched_decision_and_the_success():
    result = side_by_side.run_worker({"kind": "planner", "env_id": "SoftArm/OctArmObstacleReach-v0",
                                      "seeds": [0], "planner_kwargs": {"samples": 4, "elites": 2,
                                                                       "iterations": 1}})
    (episode,) = result["episodes"]
    assert episode["seed"] == 0 and isinstance(episode["success"], bool)
    assert 0 < len(episode["decision_seconds"]) <= episode["decisions"] <= 100
    with pytest.raises(ValueError, match="unknown job kind 'nope'"):
        side_by_side.run_worker({"kind": "nope"})


def test_a_job_runs_in_the_tree_it_is_sent_to():
    result = side_by_side.in_tree(ROOT, {"kind": "ratios", "cases": CASES[:1], "n_steps": 2, "seed": 0,
                                          "units": {}}, numba_threads=1)
    assert result["module"] == str(ROOT / "softarm_gym" / "__init__.py")
    assert result["times_unit"] == {"free reach": 1.0}


def test_the_other_tree_must_be_a_checkout(tmp_path, capsys):
    with pytest.raises(ValueError, match="not a softarm-gym checkout"):
        side_by_side.run(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        side_by_side.main(["--before", str(tmp_path)])
    assert exit_.value.code == 2 and "not a softarm-gym checkout" in capsys.readouterr().err


def test_env_bench_units_and_targets_name_its_cases():
    names = [name for name, _, _ in CONTACT_RATIO_CASES]
    assert set(RATIO_UNITS) | set(RATIO_UNITS.values()) | set(CONTACT_TARGETS) <= set(names)
    with pytest.raises(ValueError, match="unit case.s. 3D reach missing"):
        contact_ratios(1, rounds=1, cases=(("free reach", "SoftArm/OctArmReach-v1", {}),
                                           ("3D wrap", "SoftArm/OctArmWrap3D-v0", {})))


def test_selected_cases_come_after_their_units(tmp_path, capsys):
    cases = side_by_side.select_cases(["3D wrap v1", "wrap"])
    assert [c[0] for c in cases] == ["free reach", "3D reach", "3D wrap v1", "wrap"]
    with pytest.raises(SystemExit) as exit_:
        side_by_side.main(["--before", str(ROOT), "--cases", "3D wrap,warp"])
    assert exit_.value.code == 2 and "no case named 'warp'" in capsys.readouterr().err
