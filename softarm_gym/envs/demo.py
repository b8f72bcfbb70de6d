"""A reach episode with a simple model-based controller, saved as an animation (``make demo``).

The controller sees only what a policy sees — the estimated tip and the goal in the
observation — and the nominal design: each step it takes a finite-difference Jacobian of
the nominal model's tip with respect to the channel pressures (payload assumed 0) and moves
the pressures by a damped least-squares step towards the target.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

import solver

__all__ = ["JacobianReachController", "run_demo_episode"]


class JacobianReachController:
    """Damped least-squares reaching on the nominal model (no knowledge of payload or randomisation).

    Args:
        arm: the nominal design.
        base_angle_deg: mounting of the arm (deg).
        gravity: gravitational acceleration the model assumes (m/s²).
        gain: fraction of the least-squares step taken per call.
        damping: Levenberg damping λ (m); limits steps near singular configurations.
        max_step: largest pressure change per call, as a fraction of p_max.
    """

    def __init__(self, arm: solver.designs.ArmDesign, base_angle_deg: float, gravity: float = 9.81,
                 gain: float = 0.7, damping: float = 0.02, max_step: float = 0.15):
        if not (0 < gain <= 1 and damping >= 0 and 0 < max_step <= 1):
            raise ValueError(f"need 0 < gain <= 1, damping >= 0, 0 < max_step <= 1; got {gain}, "
                             f"{damping}, {max_step}")
        self.arm = arm
        self.scene = solver.Scene(base_angle_deg=base_angle_deg, gravity=gravity)
        self.gain, self.damping, self.max_step = gain, damping, max_step
        self._model = None

    def reset(self) -> None:
        """Forget the model state (new episode)."""
        self._model = None

    def _tip(self, fraction: np.ndarray) -> tuple[np.ndarray, solver.Equilibrium]:
        eq = solver.solve(self.arm, fraction * self.arm.max_pressure, self.scene, warm_start=self._model,
                          record=False)
        return eq.tip, eq

    def act(self, fraction: np.ndarray, error: np.ndarray) -> np.ndarray:
        """Next pressures (fractions of p_max) from the current ones and the tip error (target − tip, m)."""
        tip, self._model = self._tip(fraction)
        n = fraction.shape[0]
        jac = np.empty((2, n))
        h = 0.02
        for k in range(n):
            step = h if fraction[k] + h <= 1.0 else -h
            probe = fraction.copy()
            probe[k] += step
            jac[:, k] = (solver.solve(self.arm, probe * self.arm.max_pressure, self.scene,
                                      warm_start=self._model, record=False).tip - tip) / step
        delta = jac.T @ np.linalg.solve(jac @ jac.T + self.damping**2 * np.eye(2), error)
        delta *= self.gain
        largest = np.abs(delta).max()
        if largest > self.max_step:
            delta *= self.max_step / largest
        return np.clip(fraction + delta, 0.0, 1.0)


def run_demo_episode(out: str | Path = "reach_demo.gif", env_id: str = "SoftArm/OctArmReach-v0",
                     steps: int = 30, seed: int = 0, fps: int = 8, **env_kwargs) -> dict:
    """Run one reach episode with :class:`JacobianReachController` and save it as a GIF or PNG strip.

    Args:
        out: ``.gif`` (every frame) or ``.png`` (a strip of up to 6 frames).
        env_id: a registered reach environment.
        steps: episode length.
        seed: reset seed.
        fps: GIF frame rate.
        **env_kwargs: passed to ``gym.make`` (e.g. ``observation="cable_encoder"``).

    Returns:
        ``{"out", "distances" (m, per step), "estimation_errors" (m), "success", "final_distance"}``.
    """
    from PIL import Image

    out = Path(out)
    if out.suffix.lower() not in (".gif", ".png"):
        raise ValueError(f"out must end in .gif or .png; got {str(out)!r}")
    if "Reach" not in env_id:
        raise ValueError(f"the demo controller reaches targets; {env_id!r} is not a reach environment")
    env = gym.make(env_id, render_mode="rgb_array", max_episode_steps=steps, **env_kwargs)
    base = env.unwrapped
    controller = JacobianReachController(base.arm, base.base_angle_deg, base.gravity)
    obs, info = env.reset(seed=seed)
    goal = base._slices["goal"]
    fraction = (obs[base._slices["pressures"]].astype(float) + 1.0) / 2.0
    frames = [env.render()]
    distances, errors = [info["distance"]], [info["estimation_error"]]
    for _ in range(steps):
        fraction = controller.act(fraction, obs[goal][2:].astype(float))
        obs, _, terminated, truncated, info = env.step(2.0 * fraction - 1.0)
        fraction = (obs[base._slices["pressures"]].astype(float) + 1.0) / 2.0
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
    return {"out": str(out), "distances": distances, "estimation_errors": errors,
            "success": bool(info["is_success"]), "final_distance": float(distances[-1])}
