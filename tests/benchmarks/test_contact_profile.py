"""``softarm bench --contact-profile``: the per-case figures it reports."""

from softarm_gym.benchmarks import contact_profile


def test_profile_case_splits_steps_by_path_and_reports_the_resets_share():
    # 120 steps of 100-step episodes (after 24 of warm-up): one reset inside the timed run.
    case = contact_profile.profile_case("SoftArm/OctArmReach-v1", {}, 120)
    assert case["steps"] == 120 and sum(case["paths"].values()) == 120
    assert 0.0 < case["reset_share"] < 1.0
    assert abs(sum(case["profile_share"].values()) - 1.0) < 1e-9
    table = contact_profile.format_table({"cases": {"free reach": {**case, "ratio_to_free_step": 1.0}}})
    assert f"{100 * case['reset_share']:.0f} %" in table.splitlines()[2]
