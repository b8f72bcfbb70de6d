"""The general steps' side-by-side benchmark: a capture keeps the general (or other) steps of seeded
episodes, and a replay takes each again from its stepper, as the episode took it."""

import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from softarm_gym.benchmarks import general_steps, side_by_side
from softarm_gym.controllers import CurlController

ROOT = Path(__file__).resolve().parents[2]
# CTWrap3D-v0, seed 3: its 36th random step snaps and goes to the general path.
CASE = ("SoftArm/CTWrap3D-v0", 3, 36)


@pytest.fixture(scope="module")
def kept():
    env_id, seed, n_steps = CASE
    return general_steps.capture([env_id], [seed], n_steps)


def test_a_capture_keeps_the_general_steps_and_a_replay_takes_them_as_the_episode_did(kept):
    env_id, seed, n_steps = CASE
    assert [(k["id"], k["seed"]) for k in kept] == [(env_id, seed)] * len(kept) and kept
    env = gym.make(env_id)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    tips = {}
    for step in range(n_steps):
        env.step(env.action_space.sample())
        tips[step] = env.unwrapped.stepper.tip.copy()
    result = general_steps.replay(pickle.loads(pickle.dumps(kept)))
    assert result["module"].startswith(str(ROOT))
    for k, row in zip(kept, result["rows"]):
        assert row["path"] == "general" and row["iterations"] > 0
        np.testing.assert_array_equal(row["tip"], tips[k["step"]])


def test_a_replay_runs_in_the_tree_it_is_sent_to(kept, tmp_path):
    capture = tmp_path / "steps.pkl"
    capture.write_bytes(pickle.dumps(kept[:1]))
    result = side_by_side.in_tree(ROOT, {"capture": str(capture)}, None,
                                  script=Path(general_steps.__file__))
    assert result["module"].startswith(str(ROOT)) and len(result["rows"]) == 1


def test_the_other_tree_must_be_a_checkout(tmp_path, capsys):
    capture = tmp_path / "steps.pkl"
    capture.write_bytes(pickle.dumps([]))
    with pytest.raises(SystemExit):
        general_steps.main(["replay", str(capture), "--before", str(tmp_path)])
    assert "not a softarm-gym checkout" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        general_steps.main(["capture", "--ids", "SoftArm/CTWrap3D-v0", "--seeds", "x", "--out",
                            str(capture)])
    assert "--seeds 'x'" in capsys.readouterr().err


def test_a_capture_keeps_the_steps_of_the_path_it_is_given():
    env_id, seed, n_steps = CASE
    kept = general_steps.capture([env_id], [seed], 12, path="lean contact")
    assert kept and {row["path"] for row in general_steps.replay(kept)["rows"]} == {"lean contact"}


def test_a_whole_env_capture_replays_a_grasp_episode_step_by_step():
    # A grasp env's steps settle arm and object outside the stepper: the whole env is kept.
    env_id, seed, n_steps = "SoftArm/OctArmGrasp-v0", 0, 10
    kept = general_steps.capture([env_id], [seed], n_steps, whole_env=True, expert="curl")
    assert [k["step"] for k in kept] == list(range(n_steps))
    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    curl = CurlController(env)
    curl.reset()
    infos = []
    for _ in range(n_steps):
        obs, _, _, _, info = env.step(curl.act(obs))
        infos.append(info)
    rows = general_steps.replay(pickle.loads(pickle.dumps(kept)))["rows"]
    assert any(info["solver"]["iterations"] > 1 for info in infos)  # the curl closed on the object
    for info, row in zip(infos, rows):
        assert row["path"] == "env" and row["iterations"] == info["solver"]["iterations"]
        np.testing.assert_array_equal(row["tip"], [*info["tip_true"], *info["object_center"]])


def test_an_unknown_expert_is_refused():
    with pytest.raises(ValueError, match="unknown expert 'planner'"):
        general_steps.capture(["SoftArm/OctArmGrasp-v0"], [0], 1, expert="planner")
