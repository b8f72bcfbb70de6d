"""The chapter-4 study and the ``softarm estimators`` command (one pressure level, to stay fast)."""

import json

import numpy as np
import pytest

import solver
from softarm_gym.cli import main
from softarm_gym.sensing import SensorNoise, make_estimator, synthesize
from softarm_gym.sensing.study import SENSOR_GROUPS, configurations, run_study, sensitivity_bound


def test_configurations_cover_every_on_off_code():
    codes = configurations()
    assert len(codes) == 64 == len(set(codes))
    assert codes[0] == "000000" and codes[-1] == "111111"


@pytest.fixture(scope="module")
def cli_result(tmp_path_factory):
    out = tmp_path_factory.mktemp("estimators")
    paths = {k: out / f"{k}" for k in ("table.json", "fig.png", "payload.png")}
    code = main(["estimators", "--pressures-psi", "30", "--json-out", str(paths["table.json"]),
                 "--plot", str(paths["fig.png"]), "--payload-plot", str(paths["payload.png"]),
                 "--no-progress"])
    return code, paths


def test_cli_writes_table_and_plots(cli_result, capsys):
    code, paths = cli_result
    assert code == 0
    result = json.loads(paths["table.json"].read_text())
    assert result["pressures_psi"] == [30.0]
    for orient in ("horizontal", "vertical"):
        data = result["orientations"][orient]
        for key in ("perfect", "table4.3", "bound"):
            assert set(data[key]) == {"model", "constant_curvature", "cable_encoder", "inclinometer",
                                      "load_cell"}
        # Nominal model = simulated arm and no payload: model and load cell are exact.
        assert data["perfect"]["model"]["rms_over_L"][0] < 1e-9
        assert data["perfect"]["load_cell"]["rms_over_L"][0] < 1e-9
        # Constant curvature is the worst sensor-based estimator without noise.
        perfect = {k: v["rms_over_L"][0] for k, v in data["perfect"].items()}
        assert perfect["constant_curvature"] > max(perfect["cable_encoder"], perfect["inclinometer"])
        # The unknown 10 N payload: the model degrades, the load cell (perfect sensors) does not.
        pay = result["payload"][orient]["perfect"]
        assert pay["model"]["rms_over_L"][0] > 0.05
        assert pay["load_cell"]["rms_over_L"][0] < 1e-6
    for key in ("fig.png", "payload.png"):
        assert paths[key].stat().st_size > 10_000


@pytest.mark.parametrize("argv, message", [
    (["--pressures-psi", "30,x"], "comma-separated"),
    (["--pressures-psi", "200"], "pressure levels"),
    (["--pressures-psi", "30", "--payload", "-1"], "payload"),
    (["--pressures-psi", "30", "--base-inclinometer-deg", "-1"], "SensorNoise"),
])
def test_cli_bad_input_exits_2(argv, message, capsys):
    assert main(["estimators", "--no-progress", *argv]) == 2
    assert message in capsys.readouterr().err


def test_run_study_rejects_empty_levels():
    with pytest.raises(ValueError, match="pressure levels"):
        run_study(pressures_psi=[])


@pytest.mark.parametrize("name", ["load_cell", "inclinometer", "cable_encoder"])
def test_sensitivity_bound_matches_monte_carlo(name):
    """Independent small Gaussian errors of σ·resolution on every reading give an RMS tip
    error of σ·bound (linear error propagation): the bound's sensitivities are right."""
    arm = solver.designs.octarm_vi()
    scene = solver.Scene(base_angle_deg=90)
    p = np.array([40, 0, 0, 60, 20, 0]) * solver.PSI
    eq = solver.solve(arm, p, scene)
    est = make_estimator(name, arm, scene=scene)
    thesis = SensorNoise.thesis()
    readings = synthesize(eq, arm)
    bound = sensitivity_bound(est, readings, p, thesis)
    assert bound["total"] == pytest.approx(np.sqrt(sum(bound[g] ** 2 for g in SENSOR_GROUPS)))
    sigma = 0.01
    noise = SensorNoise(**{**thesis.__dict__, "gaussian_std": sigma, "quantize": False})
    rng = np.random.default_rng(3)
    clean = est.estimate(readings, p).tip
    errors = [est.estimate(synthesize(eq, arm, noise, rng), p).tip - clean for _ in range(600)]
    rms = np.sqrt(np.mean(np.sum(np.square(errors), axis=1)))
    assert rms == pytest.approx(sigma * bound["total"], rel=0.1)  # 600 samples: ~3 % statistical
