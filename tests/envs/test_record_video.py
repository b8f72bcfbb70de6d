"""Gymnasium's RecordVideo works out of the box (MoviePy comes with the render and dev extras)."""

import gymnasium as gym
import imageio_ffmpeg
import numpy as np
from gymnasium.wrappers import RecordVideo

import softarm_gym  # noqa: F401


def test_record_video_writes_one_short_episode(tmp_path):
    steps = 6
    env = gym.make("SoftArm/CTReach-v0", render_mode="rgb_array", render_size=128, max_episode_steps=steps)
    folder = tmp_path / "videos"  # RecordVideo warns about a folder that already exists
    env = RecordVideo(env, str(folder), episode_trigger=lambda episode: episode == 0, disable_logger=True)
    env.reset(seed=0)
    truncated = False
    while not truncated:
        _, _, _, truncated, _ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    env.close()
    videos = sorted(folder.glob("*.mp4"))
    assert [v.name for v in videos] == ["rl-video-episode-0.mp4"]
    assert videos[0].stat().st_size > 0
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(videos[0]))
    assert frames == steps + 1  # the reset frame and one per step
