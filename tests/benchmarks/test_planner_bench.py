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
