"""``softarm design`` end to end: JSON contract, plot, bad input."""

import json

from softarm_gym.cli import main


def test_json_has_best_and_the_whole_sweep(capsys):
    assert main(["design", "--sections", "2", "--lengths", "0.5", "--json", "--no-progress"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data["best"]) == {"tubes", "length_m", "load_n"}
    assert len(data["best"]["tubes"]) == 2
    assert len(data["sweep"]) == 16
    assert data["best"]["load_n"] == max(c["load_n"] for c in data["sweep"] if c["load_n"] is not None)


def test_several_section_counts_and_a_plot(tmp_path, capsys):
    out = tmp_path / "fig.png"
    assert main(["design", "--sections", "1,2", "--lengths", "0.4,0.6", "--tapered",
                 "--plot", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "N=1" in text and "N=2" in text and "best:" in text
    assert out.stat().st_size > 0


def test_bad_input_is_one_line_and_exit_2(capsys):
    assert main(["design", "--sections", "two", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("softarm design: error:") and "\n" not in err
    assert main(["design", "--lengths", "0.5,-1", "--no-progress"]) == 2
