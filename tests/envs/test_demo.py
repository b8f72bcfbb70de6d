"""The demo episode: the model-based controller reaches the target and the animation is written."""

import numpy as np
import pytest
from PIL import Image

from softarm_gym.envs import run_demo_episode


@pytest.mark.parametrize("suffix", [".gif", ".png"])
def test_demo_episode_reaches_and_writes_frames(tmp_path, suffix):
    out = tmp_path / f"demo{suffix}"
    result = run_demo_episode(out, steps=12, seed=1, render_size=96)
    assert out.exists()
    with Image.open(out) as img:
        assert img.size[1] == 96
        if suffix == ".gif":
            # PIL merges identical consecutive frames (the arm at rest on the target).
            assert 2 <= img.n_frames <= 13
    assert result["frames"] == 13
    d = np.array(result["distances"])
    assert d[0] > 0.3 and result["final_distance"] < 0.02 and result["success"]


def test_demo_rejects_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match=".gif or .png"):
        run_demo_episode(tmp_path / "demo.mp4")
    with pytest.raises(ValueError, match="reach"):
        run_demo_episode(tmp_path / "demo.gif", env_id="SoftArm/OctArmWrap-v0")
