"""The planner benchmark's command line: env kwargs reach gym.make and the record."""

import pytest

from softarm_gym.benchmarks.planner import main, run


def test_env_kwargs_reach_the_env_and_the_recorded_command():
    result = run(["SoftArm/CTWrap-v1"], episodes=1, progress=False,
                 env_kwargs={"self_contact": True})
    assert result["env_kwargs"] == {"self_contact": True}
    assert "--env-kwargs '{\"self_contact\": true}'" in result["command"]
    row = result["ids"]["SoftArm/CTWrap-v1"]
    assert 0.0 <= row["success_rate"] <= 1.0 and row["median_wrap_deg"] >= 0.0


@pytest.mark.parametrize("value, match", [("{", "not JSON"), ("[1]", "JSON object")])
def test_bad_env_kwargs_are_named(value, match, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--ids", "SoftArm/CTWrap-v1", "--episodes", "1", "--env-kwargs", value])
    assert exit_info.value.code == 2 and match in capsys.readouterr().err


def test_picture_is_a_filmstrip_of_the_episode_and_steps_to_success_are_recorded(tmp_path):
    from matplotlib.image import imread

    path = tmp_path / "strip.png"
    assert main(["--ids", "SoftArm/CTWrap-v2", "--picture", str(path)]) == 0
    image = imread(path)
    assert image.shape[1] > 3 * image.shape[0]  # one row of frames
    row = run(["SoftArm/CTWrap-v2"], episodes=1, progress=False)["ids"]["SoftArm/CTWrap-v2"]
    # Rate-limited (10 % of p_max per step), the wrap takes a ramp of steps, not one.
    assert row["success_rate"] == 1.0 and row["median_steps_to_success"] >= 5
    assert row["episodes"][0]["first_success_step"] == row["median_steps_to_success"]


def test_picture_needs_ids(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--picture", "x.png"])
    assert exit_info.value.code == 2 and "--picture needs --ids" in capsys.readouterr().err
