"""bench_estimators: the medians it reports (no timing assertions: machines are noisy)."""

import pytest

from softarm_gym.sensing import ESTIMATORS
from softarm_gym.sensing.bench import bench_estimators


def test_bench_reports_every_estimator():
    planar = bench_estimators(steps=2)
    assert set(ESTIMATORS) | {"synthesize"} <= set(planar)
    assert all(planar[k] > 0 for k in (*ESTIMATORS, "synthesize"))
    assert planar["planar"] and planar["steps"] == 2 and planar["design"] == "octarm_vi"
    spatial = bench_estimators(steps=1, planar=False)
    assert spatial["inclinometer"] > 0 and spatial["load_cell"] > 0 and not spatial["planar"]


@pytest.mark.parametrize("steps", [0, 1.5, True])
def test_bench_rejects_bad_steps(steps):
    with pytest.raises(ValueError, match="steps"):
        bench_estimators(steps=steps)
