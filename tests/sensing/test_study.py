"""The chapter-4 study and the ``softarm estimators`` command (one pressure level, to stay fast)."""

import json

import pytest

from softarm_gym.cli import main
from softarm_gym.sensing.study import configurations, run_study


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
