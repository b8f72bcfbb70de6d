"""A reach episode with a simple model-based controller, saved as an animation (``make demo``).

The controller (:class:`softarm_gym.controllers.JacobianController`, also the baselines'
classical comparison) sees only what a policy sees and the nominal design: box-constrained
damped least squares on the nominal model's Jacobian, payload assumed 0.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

__all__ = ["run_demo_episode"]


def run_demo_episode(out: str | Path = "reach_demo.gif", env_id: str = "SoftArm/OctArmReach-v1",
                     steps: int = 30, seed: int = 0, fps: int = 8, **env_kwargs) -> dict:
    """Run one reach episode with the Jacobian controller and save it as a GIF or PNG strip.

    The controller is :class:`~softarm_gym.controllers.JacobianController`.

    Args:
        out: ``.gif`` (every frame) or ``.png`` (a strip of up to 6 frames).
        env_id: a registered reach environment.
        steps: episode length.
        seed: reset seed.
        fps: GIF frame rate.
        **env_kwargs: passed to ``gym.make`` (e.g. ``observation="cable_encoder"``).

    Returns:
        ``{"out", "frames", "distances" (m, per step), "estimation_errors" (m), "success",
        "final_distance"}``.
    """
    from PIL import Image

    out = Path(out)
    if out.suffix.lower() not in (".gif", ".png"):
        raise ValueError(f"out must end in .gif or .png; got {str(out)!r}")
    if "Reach" not in env_id:
        raise ValueError(f"the demo controller reaches targets; {env_id!r} is not a reach environment")
    env = gym.make(env_id, render_mode="rgb_array", max_episode_steps=steps, **env_kwargs)
    # Imported here: the controllers build on the envs package (its reward rules).
    from softarm_gym.controllers import JacobianController

    controller = JacobianController(env)
    obs, info = env.reset(seed=seed)
    frames = [env.render()]
    distances, errors = [info["distance"]], [info["estimation_error"]]
    for _ in range(steps):
        obs, _, terminated, truncated, info = env.step(controller.act(obs))
        frames.append(env.render())
        distances.append(info["distance"])
        errors.append(info["estimation_error"])
        if terminated or truncated:
            break
    env.close()
    images = [Image.fromarray(f) for f in frames]
    if out.suffix.lower() == ".gif":
        images[0].save(out, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    else:
        picks = np.unique(np.linspace(0, len(frames) - 1, min(6, len(frames))).astype(int))
        Image.fromarray(np.concatenate([frames[i] for i in picks], axis=1)).save(out)
    return {"out": str(out), "frames": len(frames), "distances": distances,
            "estimation_errors": errors,
            "success": bool(info["is_success"]), "final_distance": float(distances[-1])}
