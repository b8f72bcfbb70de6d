"""Difficulty levels: every level is a valid env configuration, and the table says what ran."""

import gymnasium as gym
import pytest

from softarm_gym.benchmarks.difficulty import LEVELS, format_table, main, run


def test_every_level_makes_a_valid_env_and_includes_the_default():
    for env_id, (knob, levels) in LEVELS.items():
        assert [name for name, kw in levels if not kw] == ["default"], env_id
        for _, kwargs in levels:
            assert set(kwargs) <= {knob}
            env = gym.make(env_id, **kwargs)
            env.reset(seed=0)
            ranges = {"object_radius": "object_radius_range", "object_mass_kg": "object_mass_range",
                      "n_obstacles": "n_obstacles_range"}
            set_to = getattr(env.unwrapped, ranges.get(knob, knob))
            if kwargs:
                want = kwargs[knob]
                if knob in ranges:
                    want = tuple(want) if isinstance(want, tuple) else (want, want)  # a count: n..n
                    assert tuple(set_to) == want
                else:
                    assert set_to == want
            env.close()


def test_run_reports_success_per_level(capsys):
    result = run(episodes=1, ids=["SoftArm/CTReach-v0"], progress=False)
    levels = result["SoftArm/CTReach-v0"]["levels"]
    assert [lv["level"] for lv in levels] == ["easy", "default", "hard", "expert"]
    assert all(0.0 <= lv["success_rate"] <= 1.0 and lv["episodes"] == 1 for lv in levels)
    assert "| `SoftArm/CTReach-v0` | `success_tolerance` | expert | 0.005 |" in format_table(result)
    with pytest.raises(ValueError, match="no difficulty levels"):
        run(episodes=1, ids=["SoftArm/Nope-v0"])
    assert main(["--episodes", "0"]) == 2 and "episodes" in capsys.readouterr().err
