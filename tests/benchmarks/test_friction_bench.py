"""``softarm bench --friction``: the rows it reports, on a tiny case (no timing assertions)."""

import math

import numpy as np

from softarm_gym.benchmarks import friction_bench


def test_friction_bench_reports_finite_errors_and_times_against_the_closed_forms():
    result = friction_bench.run(cases=((90.0, 1.0),), configs=((friction_bench.K_DRUM, 16),), steps=(16,),
                                hairpin_steps=(16,), repeat=1)
    (row,) = result["capstan"]
    assert row["capstan"] == math.exp(math.pi / 2)  # e^{μθ}, μ = 1, θ = 90°
    assert row["slipped"] and row["converged_fraction"] == 1.0
    assert row["relative_error"] == abs(row["ratio"] / row["capstan"] - 1.0) < 0.01
    (slip,) = result["slip"]
    assert slip["converged_fraction"] == 1.0 and slip["relative_error"] < 0.01
    (self_slip,) = result["self_slip"]
    assert self_slip["converged_fraction"] == 1.0
    assert 0 < self_slip["relative_error"] < self_slip["spread"] / self_slip["mu"] < 0.01
    for r in (row, slip, self_slip):
        assert r["increments"] > 0
        for key in ("relative_error", "median_solve_ms", "path_seconds"):
            assert np.isfinite(r[key]) and r[key] > 0, key
    table = friction_bench.format_table(result).splitlines()
    assert table[2].startswith("| 90° | 1 | 1e+05 | 16 |") and table[-1].startswith("| 0.5 | 16 |")
    assert any(line.startswith("| self-contact slip") for line in table)


def test_the_3d_friction_bench_reports_the_oblique_slip_threshold():
    """The 3D rows' slip case at the default 16 RK4 steps (the capstan rows take minutes each:
    their physics is ``tests/solver/test_friction_3d.py``'s long oracle)."""
    ticks = []
    result = friction_bench.run_3d(cases=(), steps=(16,), tick=lambda: ticks.append(1))
    assert len(ticks) == friction_bench.solves_3d(cases=(), steps=(16,)) == 22
    (row,) = result["slip_3d"]
    assert row["converged_fraction"] == 1.0 and row["increments"] == 21
    # Within 1 % of μN while it slides (measured 6.1e-3 at 16 steps: the normal penalty is
    # summed by RK4, the friction samples by the trapezoid, on a patch a step long).
    assert row["relative_error"] < 1e-2
    assert row["max_friction_over_mu_normal"] < 1.01
    assert row["worst_cos_to_sliding"] < -0.99  # friction opposes the sliding
    assert result["capstan_3d"] == []
    table = friction_bench.format_table_3d(result).splitlines()
    assert table[-1].startswith("| 0.5 | 16 |") and table[0].startswith("| 3D capstan θ |")
