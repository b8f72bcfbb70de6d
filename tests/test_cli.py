"""Bad input at every ``softarm`` subcommand: exit status 2 and a ``softarm X: error: ...`` line.

The subcommands and their options are read from the parser itself, so a command added to
``COMMANDS`` is covered by the generic tests without editing this file.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softarm_gym.cli import COMMANDS, build_parser, emit, main


def _subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return action.choices


SUBPARSERS = _subparsers()


def _commands_with(option):
    return [name for name, sub in SUBPARSERS.items() if option in sub._option_string_actions]


def _fails_cleanly(capsys, argv, match=None):
    """Run ``softarm argv``; assert exit 2, the error on the last stderr line, no traceback."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: usage line(s), then the error line
        code = exc.code
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2, (argv, out, err)
    assert lines and lines[-1].startswith(f"softarm {argv[0]}: error: "), err
    assert "Traceback" not in err
    if match:
        assert match in lines[-1], lines[-1]
    return lines


def test_every_command_is_covered():
    assert set(SUBPARSERS) == set(COMMANDS)


@pytest.mark.parametrize("command", COMMANDS)
def test_unknown_option(capsys, command):
    with pytest.raises(SystemExit) as exc:
        main([command, "--no-such-option"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "unrecognized arguments: --no-such-option" in err.strip().splitlines()[-1]


@pytest.mark.parametrize("command", _commands_with("--design-file"))
def test_nonexistent_design_file(capsys, tmp_path, command):
    missing = tmp_path / "missing.json"
    lines = _fails_cleanly(capsys, [command, "--design-file", str(missing)], "cannot read design file")
    assert len(lines) == 1


MALFORMED = {
    "truncated": ('{"name": "x", "sections": [', "not valid JSON"),
    "not_an_object": ("[1, 2]", "must hold a JSON object"),
    "unknown_field": ('{"name": "x", "sections": [], "colour": "red"}', "unknown fields"),
    "negative_length": ('{"name": "x", "sections": [{"length": -1, "EA": 1, "GA": 1, "EI": 1, "GJ": 1}]}',
                        "length must be a finite number > 0"),
    "section_not_object": ('{"name": "x", "sections": ["abc"]}', "must be a mapping"),
}


@pytest.mark.parametrize("command", _commands_with("--design-file"))
@pytest.mark.parametrize("case", MALFORMED)
def test_malformed_design_file(capsys, tmp_path, command, case):
    text, match = MALFORMED[case]
    path = tmp_path / "design.json"
    path.write_text(text)
    lines = _fails_cleanly(capsys, [command, "--design-file", str(path)], match)
    assert len(lines) == 1


def test_design_file_with_a_non_object_material(capsys, tmp_path):
    path = tmp_path / "design.json"
    path.write_text('{"name": "x", "sections": [{"length": 0.3, "EA": 1000, "GA": 300, "EI": 0.5, '
                    '"GJ": 0.3}], "tubes": [{"channel": 0, "angle_deg": 0, "radius": 0.02, '
                    '"first_section": 0, "last_section": 0, "material": 5}], "channels": ["I"], '
                    '"planar_channels": [["I", [0]]], "max_pressure": 600000}')
    _fails_cleanly(capsys, ["solve", "--design-file", str(path), "--pressures-psi", "1"], "material")


@pytest.mark.parametrize("command", _commands_with("--design"))
def test_unknown_design(capsys, command):
    _fails_cleanly(capsys, [command, "--design", "octarm_ix"], "invalid choice: 'octarm_ix'")


@pytest.mark.parametrize("command", _commands_with("--model"))
def test_unknown_model(capsys, command):
    _fails_cleanly(capsys, [command, "--model", "pcc"], "invalid choice: 'pcc'")


@pytest.mark.parametrize("command", _commands_with("--pressures-psi"))
@pytest.mark.parametrize("text", ["a,b", "30,,0", "1e400x"])
def test_pressures_that_are_not_numbers(capsys, command, text):
    _fails_cleanly(capsys, [command, "--pressures-psi", text], "comma-separated numbers")


@pytest.mark.parametrize("text, match", [
    ("30,0", "expects 6 pressures"),
    ("-5,0,0,0,0,0", "negative"),
    ("nan,0,0,0,0,0", "not finite"),
    ("inf,0,0,0,0,0", "not finite"),
    ("0,0,0,0,0,101", "rated maximum"),
])
def test_solve_bad_pressures(capsys, text, match):
    lines = _fails_cleanly(capsys, ["solve", f"--pressures-psi={text}"], match)
    assert len(lines) == 1
    assert "Pa" not in lines[-1].replace("psi", "")  # in the unit the user typed


def test_pressure_errors_quote_the_psi_the_user_typed(capsys):
    lines = _fails_cleanly(capsys, ["solve", "--pressures-psi", "30,0,30"], "expects 6 pressures")
    assert lines[-1].endswith("got 3 (30,0,30 psi)")
    lines = _fails_cleanly(capsys, ["solve", "--pressures-psi", "300,0,30,0,0,0"], "rated maximum 100 psi")
    assert "'s1_I' (300 psi)" in lines[-1]
    _fails_cleanly(capsys, ["solve", "--design", "ct", "--pressures-psi", "0,71,0,0"], "rated maximum 70 psi")


def test_one_vocabulary_and_the_old_spellings_still_work(capsys, tmp_path):
    out = tmp_path / "solve.json"
    argv = ["solve", "--pressures-psi", "30,0,30,0,0,0"]
    assert main([*argv, "--payload-kg", "0.2", "--output", str(out)]) == 0
    tip = capsys.readouterr().out
    assert main([*argv, "--payload", "0.2"]) == 0
    assert capsys.readouterr().out == tip and '"converged": true' in out.read_text()
    for command in ("solve", "workspace", "dexterity", "estimators"):
        text = _help(command)
        assert "--payload-kg" in text and "--payload " not in text.replace("--payload-kg", ""), command
    for command in ("workspace", "dexterity", "design", "stress", "estimators"):
        text = _help(command)
        assert "--quiet" in text and "--no-progress" not in text and "--json-out" not in text, command
        assert "--output" in text and "--numba-threads" in text and "--json" in text, command
    assert "--numba-threads" in _help("bench") and "--numba-threads" in _help("fit")
    assert all(option in _help("bench") for option in ("--output", "--quiet", "--json", "--friction"))


def test_bench_output_into_a_missing_directory_fails_before_measuring(capsys, tmp_path):
    _fails_cleanly(capsys, ["bench", "--friction", "--output", str(tmp_path / "no" / "f.json")],
                   "does not exist")


def test_bench_3d_rows_are_an_option_of_the_friction_bench(capsys):
    assert "--3d" in _help("bench")
    _fails_cleanly(capsys, ["bench", "--3d"], "--3d only applies to --friction")


def _help(command):
    from softarm_gym.cli import build_parser

    parser = build_parser()
    return parser._subparsers._group_actions[0].choices[command].format_help()


@pytest.mark.parametrize("value", ["0", "99"])
def test_numba_threads_out_of_range_is_one_line(capsys, value):
    _fails_cleanly(capsys, ["workspace", "--levels", "2", "--quiet", "--numba-threads", value],
                   "--numba-threads must be between 1 and")


@pytest.mark.parametrize("option, value, match", [
    ("--base-angle", "nan", "base_angle_deg"), ("--payload", "-1", "payload_kg"),
    ("--gravity", "inf", "gravity"), ("--pressures-psi", "1,2", "9 pressures"),
])
def test_solve_bad_scene_and_spatial_count(capsys, option, value, match):
    _fails_cleanly(capsys, ["solve", "--spatial", f"{option}={value}"], match)


def test_long_wrong_pressure_list_is_still_one_line(capsys):
    lines = _fails_cleanly(capsys, ["solve", "--spatial", "--pressures-psi=1,2,3,4,5,6,7,8"], "9 pressures")
    assert len(lines) == 1


@pytest.mark.parametrize("command", _commands_with("--levels"))
def test_too_few_levels(capsys, command):
    _fails_cleanly(capsys, [command, "--levels", "1", "--quiet"], "levels")


@pytest.mark.parametrize("argv, match", [
    (["design", "--sections", "0"], "--sections must be integers >= 1"),
    (["design", "--sections", "1000"], "--sections must be at most 8 (MAX_SECTIONS"),
    (["design", "--sections", "3,1e400"], "--sections must be at most 8"),
    (["design", "--lengths=-1", "--no-progress"], "lengths"),
    (["estimators", "--pressures-psi=-5", "--no-progress"], "pressure levels"),
    (["stress", "--classes", "bogus"], "unknown stress class bogus"),
    (["stress", "--n-random", "-1"], "--n-random must be >= 0"),
    (["demo", "--observation", "bogus"], "unknown observation 'bogus'"),
])
def test_command_specific_bad_values(capsys, argv, match):
    _fails_cleanly(capsys, argv, match)


def test_demo_out_dir_that_is_a_file(capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    _fails_cleanly(capsys, ["demo", "--out-dir", str(blocker)], "out-dir")


def test_console_script_prints_one_line_and_no_traceback(tmp_path):
    script = Path(sys.executable).with_name("softarm")
    argv = [str(script)] if script.exists() else [sys.executable, "-m", "softarm_gym.cli"]
    missing = tmp_path / "missing.json"
    proc = subprocess.run([*argv, "solve", "--design-file", str(missing)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"softarm solve: error: cannot read design file '{missing}': No such file or directory"]
    assert proc.stdout == ""


@pytest.mark.parametrize("command", _commands_with("--pressures-psi"))
def test_negative_value_after_a_space_reaches_the_command(capsys, command):
    """``--pressures-psi -5,...`` must not be argparse's "expected one argument"."""
    lines = _fails_cleanly(capsys, [command, "--pressures-psi", "-5,0,0,0,0,0"])
    assert "expected one argument" not in lines[-1]


def test_solve_negative_pressure_after_a_space(capsys):
    lines = _fails_cleanly(capsys, ["solve", "--pressures-psi", "-5,0,0,0,0,0"], "'s1_I' is negative")
    assert len(lines) == 1


def test_negative_plain_numbers_still_parse(capsys):
    assert main(["solve", "--base-angle", "-30", "--pressures-psi", "5,0,0,0,0,0", "--json"]) == 0
    assert '"converged": true' in capsys.readouterr().out


@pytest.mark.parametrize("extra", [[], ["--shape"]])
def test_closed_stdout_pipe_ends_silently(extra):
    """``softarm solve --json | head -1``: no BrokenPipeError traceback, SIGPIPE-like status."""
    script = Path(sys.executable).with_name("softarm")
    argv = [str(script)] if script.exists() else [sys.executable, "-m", "softarm_gym.cli"]
    proc = subprocess.Popen([*argv, "solve", "--json", *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before the first byte is written
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert err == ""


def test_json_output_is_strict_json(capsys):
    """Standard parsers reject NaN/Infinity: a non-finite number is written as null."""
    emit({"tip": np.array([np.nan, 0.5]), "residual": np.float64(np.inf)}, True, "")
    out = capsys.readouterr().out
    assert json.loads(out, parse_constant=lambda c: pytest.fail(f"{c} in JSON output")) == {
        "tip": [None, 0.5], "residual": None}


@pytest.mark.parametrize("argv", [["--gravity", "1000", "--payload", "100", "--base-angle", "90"],
                                  ["--gravity", "1000", "--payload", "50", "--base-angle", "90"]])
def test_solve_beyond_the_solver_is_unconverged_not_a_traceback(capsys, argv):
    """Issue #19: 50-100 kg at g = 1000 raised LinAlgError out of solve(). Now: strict JSON
    saying converged false, a finite tip, exit status 1."""
    assert main(["solve", "--json", *argv]) == 1
    out = json.loads(capsys.readouterr().out,
                     parse_constant=lambda c: pytest.fail(f"{c} in JSON output"))
    assert out["converged"] is False and all(np.isfinite(out["tip"]))
