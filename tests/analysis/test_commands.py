"""``softarm workspace`` and ``softarm dexterity``: JSON contract, plots, progress on stderr."""

import json

import pytest

from softarm_gym.cli import main


def _json(capsys, argv):
    assert main(argv) == 0
    out, err = capsys.readouterr()
    return json.loads(out), err


def test_workspace_json_contract_and_progress_on_stderr(capsys, tmp_path):
    plot = tmp_path / "ws.png"
    data, err = _json(capsys, ["workspace", "--design", "octarm_v", "--base-angle", "90",
                               "--levels", "2", "--max-psi", "50", "--json", "--plot", str(plot)])
    assert {"n", "mean_tip", "area_m2", "highest_tip", "seconds"} <= set(data)
    assert data["n"] == 2**6 and data["max_psi"] == 50.0 and len(data["mean_tip"]) == 2
    assert "sweep" in err  # the tqdm bar went to stderr, leaving stdout parseable
    assert plot.stat().st_size > 0


def test_workspace_reproduction_of_fig_5_4(capsys):
    data, _ = _json(capsys, ["workspace", "--reproduce", "fig-5.4", "--levels", "2", "--json",
                             "--quiet"])
    assert set(data["workspaces"]) == {"octarm_2s (endplates 0 kg)",
                                       "octarm_2s (endplates 0.1 kg)", "ct"}
    spaces = data["workspaces"]
    # Endplates only add weight: they lower the OctArm's highest point.
    assert spaces["octarm_2s (endplates 0.1 kg)"]["highest_tip"][1] < \
        spaces["octarm_2s (endplates 0 kg)"]["highest_tip"][1]


def test_table_2_2_signs_follow_the_thesis(capsys):
    data, _ = _json(capsys, ["workspace", "--reproduce", "table-2.2", "--levels", "2", "--json",
                             "--quiet"])
    rows = data["rows"]
    assert len(rows) == 6 and set(data["rms_vs_thesis"]) == {"eq2.32", "tubes"}
    for ei in ("eq2.32", "tubes"):
        mine = sorted((r for r in rows if r["ei"] == ei), key=lambda r: r["base_angle_deg"])
        # Gravity lowers the mean tip, the more so the more horizontal the base.
        assert all(r["difference"] > 0 for r in mine)
        assert mine[0]["difference"] < mine[1]["difference"] < mine[2]["difference"]
        assert mine[0]["full_mean_y"] < mine[1]["full_mean_y"] < mine[2]["full_mean_y"]


def test_dexterity_json_and_plots(capsys, tmp_path):
    maps, areas = tmp_path / "maps.png", tmp_path / "areas.png"
    data, err = _json(capsys, ["dexterity", "--design", "ct", "--levels", "2", "--json",
                               "--thresholds", "5", "--plot", str(maps), "--area-plot", str(areas)])
    ct = data["maps"]["ct"]
    assert ct["n"] == 16 and ct["n_valid"] == 16
    assert ct["dexterous_fraction"][0] == 1.0 and len(ct["dexterous_fraction"]) == 5
    assert ct["median_sigma_min"] <= ct["median_sigma_max"]
    assert "dexterity" in err
    assert maps.stat().st_size > 0 and areas.stat().st_size > 0


@pytest.mark.parametrize("argv, message", [
    (["workspace", "--levels", "1"], "levels must be an integer >= 2"),
    (["workspace", "--design", "ct", "--max-psi", "100"], "exceeds design"),
    (["workspace", "--backend", "local", "--address", "auto"], "--address needs --backend ray"),
    (["workspace", "--reproduce", "table-2.2", "--ei", "tubes"], "fixes the designs"),
    (["dexterity", "--thresholds", "1"], "--thresholds must be >= 2"),
    (["dexterity", "--rel-step", "0.5", "--levels", "2"], "rel_step"),
])
def test_bad_input_exits_2_with_one_line(capsys, argv, message):
    assert main(argv + ["--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
