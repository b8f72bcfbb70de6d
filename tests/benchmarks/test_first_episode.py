"""``softarm warmup`` covers every registered env configuration; the first-episode benchmark."""

import json
import warnings

import gymnasium as gym
import numba
import numpy as np
import pytest

import softarm_gym  # noqa: F401
from softarm_gym.benchmarks.first_episode import format_table, measure, run
from softarm_gym.cli import main
from softarm_gym.commands import warmup
from softarm_gym.commands.warmup import (
    GROUPS,
    batch_kernels,
    cases,
    group_of,
    planar_snap_kernels,
    spatial_snap_kernels,
)
from softarm_gym.registry import is_deprecated, latest, make, make_unwrapped, recommended_ids
from softarm_gym.sensing import ESTIMATORS


def test_warmup_runs_every_registered_id_in_every_observation_mode():
    ids = {env_id for env_id in gym.registry if env_id.startswith("SoftArm/")}
    planar = {(env_id, kw["observation"]) for env_id, kw in cases() if kw.get("planar", True)}
    assert planar == {(env_id, obs) for env_id in ids for obs in ESTIMATORS}
    spatial = {(env_id, kw["observation"]) for env_id, kw in cases() if not kw.get("planar", True)}
    assert {env_id for env_id, _ in spatial} == {env_id for env_id in ids
                                                 if "Reach" in env_id and "Obstacle" not in env_id}
    for env_id, kwargs in cases():  # every case is a valid configuration
        make(env_id, quiet=True, **kwargs).close()


def test_every_warmup_case_belongs_to_a_group_and_every_env_group_has_cases():
    groups = {group_of(env_id, kw) for env_id, kw in cases()}
    assert groups == set(GROUPS) - {"solver", "batch", "batch_contact"}
    assert group_of("SoftArm/OctArmWrap3D-v0", {}) == "spatial_contact"
    assert group_of("SoftArm/OctArmWrap-v1", {}) == "contact"
    assert group_of("SoftArm/CTReach-v1", {"planar": False}) == "reach"


def test_warmup_builds_out_of_date_ids_without_a_deprecation_warning():
    assert is_deprecated("SoftArm/OctArmReach-v0")
    assert latest("SoftArm/OctArmReach-v0") == "SoftArm/OctArmReach-v1"
    assert is_deprecated("SoftArm/OctArmGrasp-v0")
    assert latest("SoftArm/OctArmGrasp-v0") == "SoftArm/OctArmGrasp-v1"
    assert not is_deprecated("SoftArm/OctArmGrasp-v1")
    assert "SoftArm/OctArmReach-v1" in recommended_ids() and "SoftArm/OctArmReach-v0" not in recommended_ids()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = make_unwrapped("SoftArm/OctArmReach-v0", observation="model")
        env.close()
        make("SoftArm/CTWrap-v0", quiet=True).close()
    assert env.action_mode == "absolute" and env.arm.name == "octarm_v"
    with pytest.warns(DeprecationWarning, match="out of date"):
        gym.make("SoftArm/CTWrap-v0").close()  # a user who types an old id is told


def test_warmup_rejects_unknown_groups_and_bad_job_counts(capsys, tmp_path):
    assert main(["warmup", "--only", "solver,nope"]) == 2
    assert "unknown group(s) nope" in capsys.readouterr().err
    assert main(["warmup", "--jobs", "0"]) == 2
    assert "--jobs must be at least 1" in capsys.readouterr().err
    assert main(["warmup", "--profile", str(tmp_path / "no" / "p.json")]) == 2  # before compiling
    assert "directory" in capsys.readouterr().err and not (tmp_path / "no").exists()


def test_warmup_profile_lists_each_groups_compiles(monkeypatch, tmp_path, capsys):
    """``--profile`` writes every group's seconds and compiles, the costliest first; here the
    group's work is one fresh kernel compiled in this process."""
    def fake_group(group):
        numba.njit(lambda x: x + 1.0)(1.0)
        return 0.5

    monkeypatch.setattr(warmup, "warm_group", fake_group)
    path = tmp_path / "profile.json"
    assert main(["warmup", "--only", "solver,batch", "--jobs", "1", "--quiet", "--profile", str(path)]) == 0
    assert "compile profile written to" in capsys.readouterr().out
    profile = json.loads(path.read_text())
    assert profile["command"] == f"softarm warmup --only solver,batch --jobs 1 --profile {path}"
    assert profile["jobs"] == 1 and set(profile["groups"]) == {"solver", "batch"}
    for group in profile["groups"].values():
        assert group["seconds"] == 0.5 and group["process"] == 0
        assert [c["kernel"].rsplit(".", 1)[-1] for c in group["compiles"]] == ["<lambda>"]
        assert group["compile_seconds"] == group["compiles"][0]["exclusive_seconds"] > 0.0


@pytest.mark.skipif(numba.get_num_threads() < 2,
                    reason="one numba thread: ThreadPolicy never runs the threaded kernels, "
                           "so there is no threaded timing to check")
def test_warmup_runs_bothbatch_kernels_both_ways():
    """The cold and the step rows kernels each ran, and were timed, serial and threaded: none
    is left to compile inside a user's first long batch."""
    batch = batch_kernels()
    for kind, policy in batch.thread_policies.items():
        assert np.isfinite(policy.per_row_s).all(), (kind, policy.per_row_s)


def test_warmup_takes_a_3d_contact_step_through_a_snap():
    """The spatial_contact group's ramp reaches the general 3D contact path's branch switch
    (a step that snaps), every step converged and stable: its kernels are compiled up front."""
    reports = spatial_snap_kernels()
    assert all(r.converged and r.stable for r in reports)
    assert any(r.snapped for r in reports)


def test_warmup_lands_a_planar_snap_by_the_fold_scan():
    """The solver group's cold solve snaps from a fold met clear of the disc and lands clear of
    it and of the arm: the general path's landing by the fold scan, whose clearance test runs
    from Python, so the warm-up compiles it only if the solve gets there (a landing in contact
    is the relaxation's instead)."""
    eq = planar_snap_kernels()
    assert eq.converged and eq.stable and eq.snapped
    assert not eq.in_contact


def test_measure_times_the_first_and_the_steady_episodes():
    row = measure("SoftArm/CTReach-v0", episodes=1)
    assert row["steps"] == 100
    assert row["first_seconds"] > 0 and row["import_seconds"] >= 0
    assert row["first_steps_per_s"] == pytest.approx(100 / row["first_seconds"])
    steady_episode = 100 / row["steady_steps_per_s"]
    assert row["first_overhead_seconds"] == pytest.approx(row["first_seconds"] - steady_episode)


def test_fresh_process_table():
    result = run(ids=["SoftArm/CTReach-v0"], episodes=1)
    row = result["rows"]["SoftArm/CTReach-v0"]
    assert row["ratio"] == pytest.approx(row["warm"]["first_steps_per_s"] / row["warm"]["steady_steps_per_s"])
    assert "SoftArm/CTReach-v0" in format_table(result)


def test_cold_needs_first_episode(capsys):
    assert main(["bench", "--cold"]) == 2
    assert "--cold only applies to --first-episode" in capsys.readouterr().err
