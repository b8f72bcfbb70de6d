"""``softarm fit``: make data, fit, inspect, and the bad input that must be one line and exit 2."""

import json

import gymnasium as gym
import numpy as np
import pytest

import softarm_gym  # noqa: F401  (registers the envs)
import solver
from softarm_gym.cli import main

HEADER = ("base_angle_deg,s1_I_psi,s1_II+III_psi,s2_I_psi,s2_II+III_psi,s3_I_psi,s3_II+III_psi,"
          "tip_x_m,tip_y_m\n")


def _fails_cleanly(capsys, argv, match):
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err and err[-1].startswith("softarm fit: error: "), err
    assert match in err[-1], err[-1]
    assert not any("Traceback" in line for line in err)
    return err[-1]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    path = tmp_path_factory.mktemp("fit") / "shapes.csv"
    assert main(["fit", "--make-synthetic", str(path), "--truth", "wind_angle=76.8,E=2.1e6",
                 "--pressures-psi", "40,80", "--base-angles", "90", "--no-sensors", "--seed", "2"]) == 0
    return path


def test_make_fit_inspect_and_use_the_results(data, tmp_path, capsys):
    capsys.readouterr()
    fit_file, design_file, plot = tmp_path / "fit.json", tmp_path / "fitted.json", tmp_path / "fit.png"
    assert main(["fit", "--design", "octarm_v", "--data", str(data), "--params", "wind_angle,E", "--json",
                 "--output", str(fit_file), "--save-design", str(design_file), "--plot", str(plot),
                 "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out == json.loads(fit_file.read_text())
    values = {p["name"]: p for p in out["parameters"]}
    for name, truth in (("wind_angle", 76.8), ("E", 2.1e6)):
        lo, hi = values[name]["ci95"]
        std = values[name]["std"]
        assert values[name]["identified"] and lo - 3 * std < truth < hi + 3 * std
    assert not out["chi_square"]["misspecified"]
    assert out["holdout"]["configurations"] == round(0.2 * 128)
    assert plot.stat().st_size > 50_000
    # The fitted design is a design file ...
    assert main(["solve", "--design-file", str(design_file), "--pressures-psi", "30,0,30,0,30,0",
                 "--base-angle", "90", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["converged"]
    fitted = solver.designs.load(design_file)
    assert fitted.tubes[0].material.wind_angle_deg == values["wind_angle"]["value"]
    # ... and the fit file randomises an environment's arm around it, deterministically per seed.
    env = gym.make("SoftArm/OctArmReach-v1", design=fitted, randomization=str(fit_file))
    arms = []
    for seed in (5, 5, 6):
        env.reset(seed=seed)
        arms.append(env.unwrapped.simulated_arm)
        env.step(env.action_space.sample())
    assert arms[0] == arms[1] and arms[0] != arms[2]
    assert abs(arms[2].tubes[0].material.wind_angle_deg - values["wind_angle"]["value"]) < 6 * values[
        "wind_angle"]["std"]


def test_text_output_names_what_was_fitted(data, capsys):
    capsys.readouterr()
    assert main(["fit", "--data", str(data), "--params", "wind_angle:s1,E", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "wind_angle:s1" in text and "95 % interval" in text and "chi-square" in text
    assert "held out (26 configurations), tip: mean error" in text


def test_unidentifiable_parameters_are_reported(data, capsys):
    capsys.readouterr()
    assert main(["fit", "--data", str(data), "--params", "E,G,GA_scale", "--quiet", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    named = [u["parameter"] for u in out["identifiability"]["unidentifiable"]]
    assert len(named) == 1 and named[0] in ("G", "GA_scale")
    held = next(p for p in out["parameters"] if p["name"] == named[0])
    assert not held["identified"] and held["std"] is None and held["value"] == held["nominal"]


@pytest.mark.parametrize("params, match", [
    ("wind_angel", "unknown parameter 'wind_angel'"),
    ("E,E", "named twice"),
    ("wind_angle:s7", "has sections s1..s3"),
])
def test_unknown_parameter_names(capsys, data, params, match):
    _fails_cleanly(capsys, ["fit", "--data", str(data), "--params", params, "--quiet"], match)


def test_too_few_measurements_for_the_parameters(capsys, tmp_path):
    path = tmp_path / "two.csv"
    path.write_text(HEADER + "90,40,0,0,0,0,0,0.7,-0.3\n90,0,40,0,0,0,0,0.7,-0.4\n")
    _fails_cleanly(capsys, ["fit", "--data", str(path), "--params", "wind_angle,E,G,EI_scale", "--holdout",
                            "0", "--quiet"],
                   "4 measured values in the fit set (2 configurations) cannot determine 4")


@pytest.mark.parametrize("text, match", [
    ("base_angle_deg;s1_I_psi\n90;40\n", "unknown column(s) 'base_angle_deg;s1_I_psi'"),
    (HEADER + "90,40,0,0,0,0,0,0.7\n", "line 2: 8 fields; the header has 9"),
    (HEADER + "90,40,0,0,0,0,0,0.7,oops\n", "line 2, column 'tip_y_m': 'oops' is not a number"),
    (HEADER, "a header but no data rows"),
    ("\x00\xff\xfe", "not UTF-8 text"),
])
def test_malformed_csv(capsys, tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_bytes(text.encode("latin-1"))
    _fails_cleanly(capsys, ["fit", "--data", str(path), "--quiet"], match)


@pytest.mark.parametrize("argv, match", [
    (["fit"], "--data FILE.csv is required"),
    (["fit", "--data", "/nonexistent/shapes.csv"], "cannot read data file '/nonexistent/shapes.csv'"),
    (["fit", "--make-synthetic", "x.csv", "--truth", "wind_angle"], "NAME=VALUE pairs"),
    (["fit", "--make-synthetic", "x.csv", "--truth", "wind_angle=abc"], "NAME=VALUE pairs"),
    (["fit", "--make-synthetic", "x.csv", "--design", "ct"], "--truth is needed for design 'ct'"),
    (["fit", "--make-synthetic", "/nonexistent/x.csv"], "--make-synthetic /nonexistent/x.csv: directory"),
    (["fit", "--tip-sigma-mm", "-1"], "--tip-sigma-mm must be a finite number >= 0"),
    (["fit", "--sensor-noise-std", "nan"], "--sensor-noise-std must be a finite number >= 0"),
    (["fit", "--reproduce", "fig-2.6", "--design", "ct"], "runs on OctArm V"),
    (["fit", "--reproduce", "noise", "--plot", "x.png"], "--plot applies to fits"),
    (["fit", "--plot", "fit.txt"], "unsupported image format 'txt'"),
    (["fit", "--base-angles", "a"], "--base-angles must be comma-separated numbers"),
])
def test_bad_options(capsys, argv, match):
    _fails_cleanly(capsys, argv, match)


def test_bad_option_values_with_data(capsys, data):
    argv = ["fit", "--data", str(data), "--quiet"]
    _fails_cleanly(capsys, [*argv, "--holdout", "1.5"], "holdout must be a fraction")
    _fails_cleanly(capsys, [*argv, "--tip-sigma-mm", "0"], "must be > 0")
    _fails_cleanly(capsys, [*argv, "--design", "ct"], "unknown column(s) 's1_I_psi'")


def test_randomization_from_a_fit_file_that_does_not_fit_the_env(tmp_path, data, capsys):
    fit_file = tmp_path / "fit.json"
    assert main(["fit", "--data", str(data), "--output", str(fit_file), "--quiet"]) == 0
    with pytest.raises(ValueError, match="fitted to design 'octarm_v'; the environment's design is 'ct'"):
        gym.make("SoftArm/CTReach-v1", randomization=str(fit_file))
    with pytest.raises(ValueError, match="cannot read fit file"):
        gym.make("SoftArm/OctArmReach-v1", randomization=str(tmp_path / "missing.json"))
    not_fit = tmp_path / "design.json"
    not_fit.write_text(solver.designs.octarm_v().to_json())
    with pytest.raises(ValueError, match="not a fit file"):
        gym.make("SoftArm/OctArmReach-v1", randomization=str(not_fit))
    with pytest.raises(ValueError, match="takes 'fit' and 'widen'"):
        gym.make("SoftArm/OctArmReach-v1", randomization={"fit": str(fit_file), "scale": 2})
    env = gym.make("SoftArm/OctArmReach-v1", randomization={"fit": str(fit_file), "widen": 0})
    env.reset(seed=0)
    assert env.unwrapped.simulated_arm == json_design(fit_file, "fitted_design")
    capsys.readouterr()


def json_design(path, key):
    return solver.designs.from_json(json.dumps(json.loads(path.read_text())[key]))


def test_the_base_design_is_accepted_too(tmp_path, data):
    fit_file = tmp_path / "fit.json"
    assert main(["fit", "--data", str(data), "--output", str(fit_file), "--quiet"]) == 0
    env = gym.make("SoftArm/OctArmReach-v1", randomization=str(fit_file))  # the default octarm_v
    env.reset(seed=1)
    sim = env.unwrapped.simulated_arm
    assert sim != solver.designs.octarm_v()
    assert np.isfinite(env.step(env.action_space.sample())[0]).all()
