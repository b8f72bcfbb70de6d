"""``softarm stress``: a tiny seeded run of the study, its helpers, and its bad input."""

import dataclasses
import json
import math

import numpy as np
import pytest

import solver
from softarm_gym.benchmarks import stress
from softarm_gym.benchmarks.envs import env_ids
from softarm_gym.cli import main
from softarm_gym.sensing import ESTIMATORS
from tests.timings import without_timings

FIELDS = {"n", "converged_fraction", "flagged_unconverged_fraction", "nan_count", "exceptions",
          "worst_residual", "worst_iterations", "time_ms", "failures", "diagnosis"}


@pytest.fixture(scope="module")
def smoke():
    return stress.run(seed=3, n_random=40, n_per_class=2, env_steps=24, n_diagnose=2)


def test_report_has_every_class_both_columns_and_the_env_part(smoke):
    assert set(smoke["classes"]) == set(stress.CLASSES)
    for name, entry in [("random", smoke["random"]), *smoke["classes"].items()]:
        assert FIELDS <= set(entry) and FIELDS <= set(entry["without_fallback"])
        assert entry["n"] > 0 and set(entry["time_ms"]) == {"p50", "p90", "p99", "max"}
        # the target: no NaN/inf anywhere, no exception (failures say how to reproduce)
        assert entry["nan_count"] == 0 and entry["exceptions"] == 0, (name, entry["failures"])
        assert math.isclose(entry["converged_fraction"] + entry["flagged_unconverged_fraction"], 1.0)
    # a wrap_press trial is an 8-step warm-started ramp: every step is counted
    assert smoke["classes"]["wrap_press"]["n"] == 2 * 8
    env = smoke["env"]
    # one case per registered ID and observation mode, at least one step each
    cases = len(env_ids()) * len(ESTIMATORS)
    assert env["cases"] == cases and env["steps"] == cases * -(-24 // cases)
    assert env["exceptions"] == env["nan_observations"] == env["nan_rewards"] == 0
    assert smoke["targets"]["zero_nan"]
    json.dumps(smoke)  # the CLI prints it as JSON


def test_fallbacks_lift_the_converged_fraction(smoke):
    random = smoke["random"]
    assert random["converged_fraction"] > random["without_fallback"]["converged_fraction"]


def test_same_seed_same_scenes_and_outcomes(smoke):
    again = stress.run(seed=3, n_random=40, n_per_class=0, env_steps=0)
    for key in ("n", "converged_fraction", "worst_iterations", "worst_residual", "failures"):
        assert again["random"][key] == smoke["random"][key]
    other = stress.random_trials(5, np.random.default_rng(4))
    first = stress.random_trials(5, np.random.default_rng(3))
    assert not all(np.array_equal(a.pressures, b.pressures) for a, b in zip(first, other))


def test_chunking_does_not_change_the_report(smoke):
    """Chunks of 7 trials (each diagnosing its own first failures; the merge keeps the first
    two overall) give the report of the default 250-trial chunks, timings apart."""
    small = stress.run(seed=3, n_random=40, n_per_class=2, env_steps=24, n_diagnose=2, chunk_size=7)
    assert without_timings(small) == without_timings(smoke)


def test_chunked_records_merge_into_the_serial_ones():
    """With one Newton iteration most solves fail: each chunk diagnoses its own first three
    failures, and the merge keeps the first three overall, as a serial run does."""
    from dataclasses import asdict

    trials = stress.random_trials(8, np.random.default_rng(5))
    settings = solver.Settings.without_fallback(max_iter=1)
    serial = asdict(stress.run_trials(trials, settings, n_diagnose=3))
    chunks = [stress.trials_chunk(tuple(trials[a:a + 3]), settings, 3) for a in range(0, 8, 3)]
    merged = asdict(stress.merge_records(chunks, 3))
    assert len(serial["failures"]) > 3 and len(serial["diagnoses"]) == 3
    for key in serial:
        if key != "seconds":
            assert merged[key] == serial[key], key


def test_scaled_stiffness_keeps_the_actuation_and_scaled_length_the_arm():
    arm = solver.designs.octarm_v()
    soft = stress.scaled(arm, stiffness=0.1)
    long = stress.scaled(arm, length=4.0)
    p = np.linspace(0.0, 1.0, arm.n_channels) * arm.max_pressure  # every section bent and stretched
    # p(λ) ∝ E: the re-rated pressures reach the same rest strains (curvature and stretch)
    np.testing.assert_allclose(solver.rest_strains(soft, 0.1 * p), solver.rest_strains(arm, p), rtol=1e-9)
    assert math.isclose(soft.sections[0].EI, 0.1 * arm.sections[0].EI)
    assert math.isclose(long.length, 4.0 * arm.length) and long.mass == pytest.approx(4.0 * arm.mass)


def test_near_lockup_rating_reaches_the_requested_stretch():
    arm = stress.near_lockup(solver.designs.octarm_v(), fraction=0.999)
    m = arm.tubes[0].material
    lam = solver.stretch_from_pressure(arm.max_pressure, m.youngs_modulus, m.inner_radius,
                                       m.outer_radius, m.wind_angle_deg)
    assert lam == pytest.approx(0.999 * m.max_stretch, rel=1e-9)


def test_wrap_press_ramps_into_the_disc():
    (trial,) = stress.class_trials("wrap_press", 1, np.random.default_rng(0))
    assert trial.pressures.shape[0] == 8 and np.all(trial.pressures[0] == 0.0)
    assert trial.pressures[-1].max() == trial.arm.max_pressure and len(trial.scene.obstacles) == 1


def test_failed_solves_are_described_and_diagnosed():
    """One plain Newton iteration cannot curl a horizontal OctArm V at full pressure: the solve
    is flagged, described for reproduction, and the retries with the fallbacks on fix it."""
    arm = solver.designs.octarm_v()
    pressures = np.array([[100, 0, 100, 0, 100, 0]]) * solver.PSI
    trial = stress.Trial(arm, pressures, solver.Scene(base_angle_deg=90.0, payload_kg=0.2))
    rec = stress.run_trials([trial], solver.Settings.without_fallback(max_iter=1), n_diagnose=1)
    summary = stress.summarize(rec)
    assert summary["converged_fraction"] == 0.0 and summary["flagged_unconverged_fraction"] == 1.0
    failure = summary["failures"][0]
    assert failure["pressures_psi"] == [100, 0, 100, 0, 100, 0] and failure["base_angle_deg"] == 90.0
    assert summary["diagnosis"]["retried"] == 1 and summary["diagnosis"]["fixed_by_none"] == 0
    assert summary["diagnosis"]["fixed_by_finer_continuation"] == 1


def test_moment_balance_check_is_independent_of_the_solver():
    """A converged result balances to quadrature accuracy; a shifted base moment does not."""
    from dataclasses import replace

    arm = solver.designs.octarm_v(endplate_mass=0.05)
    scene = solver.Scene(base_angle_deg=90.0, payload_kg=0.2)
    eq = solver.solve(arm, np.array([30, 0, 0, 40, 10, 0]) * solver.PSI, scene)
    assert eq.converged and stress.moment_balance_error(arm, scene, eq) < 1e-6
    load_moment = (arm.mass + 0.2) * 9.81 * arm.length
    shifted = replace(eq, internal_moment=eq.internal_moment + 0.01 * load_moment)
    assert stress.moment_balance_error(arm, scene, shifted) == pytest.approx(0.01, rel=1e-3)
    arcs = solver.solve(arm, eq.pressures, scene, model="constant_curvature")
    assert math.isnan(stress.moment_balance_error(arm, scene, arcs))  # that model ignores loads


@pytest.mark.parametrize("kwargs, match", [
    (dict(classes=("bogus",)), "unknown stress class"), (dict(n_random=-1), "n_random"),
    (dict(n_per_class=1.5), "n_per_class"),
])
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        stress.run(env_steps=0, **kwargs)
    with pytest.raises(ValueError, match="unknown observation"):
        stress.run_env_steps(1, observations=("sonar",))
    with pytest.raises(ValueError, match="Trial.pressures"):
        stress.Trial(solver.designs.octarm_v(), np.zeros(5), solver.Scene())


def test_cli_json(capsys):
    assert main(["stress", "--n-random", "6", "--n-per-class", "1", "--classes", "all_max,tiny_arm",
                 "--env-steps", "0", "--no-progress", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data["classes"]) == {"all_max", "tiny_arm"} and data["random"]["n"] == 6
    assert "env" not in data and data["targets"]["zero_nan"]


@pytest.mark.parametrize("argv, match", [
    (["--classes", "all_max,bogus"], "unknown stress class bogus"),
    (["--classes", ","], "unknown stress class"),
    (["--env-steps", "-5"], "--env-steps must be >= 0"),
    (["--diagnose", "-1"], "--diagnose must be >= 0"),
])
def test_cli_bad_input(capsys, argv, match):
    assert main(["stress", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("softarm stress: error: ") and match in err[0]


def test_a_flagged_infinite_residual_is_not_a_leak():
    """An unconverged result with no finite state reports residual=inf on purpose; a converged
    one with an infinite residual, or any NaN in the state, is a leak."""
    arm = solver.designs.get("octarm_v")
    eq = solver.solve(arm, np.zeros(arm.n_inputs(True)))
    assert stress.finite_result(eq)
    assert stress.finite_result(dataclasses.replace(eq, converged=False, residual=math.inf))
    assert not stress.finite_result(dataclasses.replace(eq, residual=math.inf))
    positions = eq.positions.copy()
    positions[3, 0] = math.nan
    assert not stress.finite_result(dataclasses.replace(eq, converged=False, positions=positions))
