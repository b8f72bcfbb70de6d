"""``softarm bench --contact-profile``: the per-case figures it reports."""

import pytest

from softarm_gym.benchmarks import contact_profile


def test_profile_case_splits_steps_by_path_and_reports_the_resets_share():
    # 120 steps of 100-step episodes (after 24 of warm-up): one reset inside the timed run.
    case = contact_profile.profile_case("SoftArm/OctArmReach-v1", {}, 120)
    assert case["steps"] == 120 and sum(case["paths"].values()) == 120
    assert 0.0 < case["reset_share"] < 1.0
    assert abs(sum(case["profile_share"].values()) - 1.0) < 1e-9
    table = contact_profile.format_table({"cases": {"free reach": {**case, "ratio_to_free_step": 1.0}}})
    assert f"{100 * case['reset_share']:.0f} %" in table.splitlines()[2]


def test_batched_profile_accounts_for_every_arm_step_and_its_time():
    """The batched wrap profile: every timed arm-step is a lean, lean contact or general one,
    the parts' seconds add up to the run's, and a general step says why the lean kernel
    refused it (copy by copy and on the batch's threads alike)."""
    for per_copy in (True, False):
        r = contact_profile.profile_batched(n=3, curl_steps=12, steps=3, per_copy=per_copy)
        counted = sum(part["steps"] for part in r["paths"].values())
        assert counted == 3 * 3
        assert r["paths"].get("general", {"steps": 0})["steps"] == len(r["general"])
        assert r["lean_s"] + r["general_s"] + r["other_s"] == pytest.approx(r["seconds"])
        assert min(r["lean_s"], r["general_s"], r["other_s"]) >= 0.0
        for step in r["general"]:
            assert step["lean_refusal"] != "none"
        if per_copy:
            lean_s = sum(part["lean_kernel_s"] for part in r["paths"].values())
            assert 0.0 < lean_s <= r["lean_s"]
