"""An SB3 ``VecEnv`` over the batched vector envs: PPO, SAC, TD3 step N arms in one solver call.

Example::

    from stable_baselines3 import SAC
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize
    from softarm_gym.sb3 import BatchedVecEnv

    venv = VecNormalize(VecMonitor(BatchedVecEnv("SoftArm/OctArmReach-v1", 16)),
                        norm_reward=False)
    venv.seed(0)
    SAC("MlpPolicy", venv, train_freq=1, gradient_steps=4).learn(100_000)

:class:`BatchedVecEnv` puts Stable-Baselines3's ``VecEnv`` API on a batched vector env
(:mod:`softarm_gym.vector`: reach, track, obstacle reach, planar wrap) run with ``SAME_STEP``
autoreset:

* ``step`` returns ``(obs, rewards, dones, infos)`` with ``dones = terminated | truncated``;
  a finished copy is already reset: its ``obs`` row is the next episode's first
  observation, its info (that of the finishing step) holds ``terminal_observation`` and its
  reset info goes to ``reset_infos``; every info has ``TimeLimit.truncated`` (truncated
  and not terminated), as ``DummyVecEnv`` gives them;
* ``infos`` is a list of one dict per copy with the single env's keys and types (floats,
  bools, ints, and arrays for the tip, target and pressures);
* ``reset()`` returns the observations only; ``seed(s)`` seeds copy i with s + i at the
  next ``reset()`` (without it, a reset continues each copy's random stream);
  ``set_options(options)`` passes the same options to every copy's next reset (where the
  env takes options: not reach), different options per copy are refused;
* ``get_attr``, ``set_attr`` and ``env_method`` act on the configuration every copy shares
  (one single env of the ID that is never stepped: its spaces, weights,
  ``p_max``, ...); per-copy state is in the infos. ``set_attr`` sets all copies or none, and
  ``env_method`` refuses ``reset``, ``step``, ``render`` and ``close``, which would act on
  that template instead of the arms.

Copy i seeded s is, step for step and bit for bit, ``DummyVecEnv`` over ``gym.make(env_id)``
seeded s + i (observations, rewards, dones, infos, ``terminal_observation``), so a policy
trained on either runs on the other; ``tests/test_sb3.py`` holds it to that. The batched
env's limits apply (true observations, one payload and no randomisation, planar contact;
see :mod:`softarm_gym.vector`): other settings raise its ``ValueError``; use ``DummyVecEnv``.
Wrap it in ``VecMonitor`` for episode statistics and in ``VecNormalize`` as any ``VecEnv``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as exc:  # pragma: no cover - the baselines extra is missing
    raise ImportError("softarm_gym.sb3 needs stable-baselines3: pip install 'softarm-gym[baselines]' "
                      f"({exc})") from None

__all__ = ["BatchedVecEnv"]

_TEMPLATE_ONLY = ("reset", "step", "render", "close")
"""Methods ``env_method`` refuses: on the shared template they would not act on the arms."""


def _per_copy(infos: dict, n: int) -> list[dict]:
    """Vector infos (arrays with ``_key`` masks, all True) as n single-env info dicts."""
    out = [{} for _ in range(n)]
    for key, value in infos.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        if isinstance(value, dict):
            parts = _per_copy(value, n)
        elif value.ndim == 1:
            parts = value.tolist()  # Python bools, ints and floats, as the single env gives them
        else:
            parts = list(value)
        for info, part in zip(out, parts):
            info[key] = part
    return out


class BatchedVecEnv(VecEnv):
    """``num_envs`` arms of a reach env id as one SB3 ``VecEnv`` (module docstring).

    Args:
        env_id: a registered id with a batched vector entry point (the reach, track, obstacle
            reach and planar wrap IDs).
        num_envs: number of arms.
        **env_kwargs: ``gym.make`` kwargs of the id (``action_mode``, ``max_episode_steps``,
            reward weights, ...).

    Raises:
        ValueError: an id without a batched env, or settings the batched env cannot simulate.
    """

    def __init__(self, env_id: str, num_envs: int, **env_kwargs):
        spec = gym.spec(env_id)
        if spec.vector_entry_point is None:
            raise ValueError(f"{env_id} has no batched vector env; wrap single envs in SB3's DummyVecEnv")
        self.batched = gym.make_vec(
            env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
            autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs)
        self.spec = spec
        super().__init__(num_envs, self.batched.single_observation_space, self.batched.single_action_space)
        self._actions: np.ndarray | None = None

    def reset(self):
        options = self._options[0]
        if any(o != options for o in self._options):
            raise ValueError(f"the batched env resets every copy with the same options; got "
                             f"{self._options!r}")
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        obs, infos = self.batched.reset(seed=seeds, options=options or None)
        self.reset_infos = _per_copy(infos, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("call step_async(actions) before step_wait()")
        obs, rewards, terminated, truncated, infos = self.batched.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        step_infos = _per_copy(infos, self.num_envs)
        timeouts = (truncated & ~terminated).tolist()
        ended = np.flatnonzero(dones)
        if ended.size:
            finished = _per_copy(infos["final_info"], self.num_envs)
            for i in ended:
                self.reset_infos[i] = step_infos[i]
                step_infos[i] = finished[i]
        for info, timeout in zip(step_infos, timeouts):
            info["TimeLimit.truncated"] = timeout
        for i in ended:
            step_infos[i]["terminal_observation"] = infos["final_obs"][i]
        return obs, rewards.astype(np.float32), dones, step_infos

    def close(self) -> None:
        self.batched.close()

    # ------------------------------------------------------------------ attributes

    def _all(self, indices) -> list[int]:
        return list(self._get_indices(indices))

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        """The shared template's ``attr_name``, once per index (AttributeError if it has none)."""
        value = getattr(self.batched.template, attr_name)
        return [value for _ in self._all(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        """Set ``attr_name`` of the shared template, which every copy reads (all copies only)."""
        if sorted(self._all(indices)) != list(range(self.num_envs)):
            raise ValueError(f"the {self.num_envs} arms share one configuration: set_attr({attr_name!r}) "
                             "applies to all of them or none (indices=None)")
        setattr(self.batched.template, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        """Call the shared template's ``method_name`` once per index (e.g. ``compute_reward``)."""
        if method_name in _TEMPLATE_ONLY:
            raise ValueError(f"env_method({method_name!r}) would act on the shared template, not the arms; "
                             f"use the VecEnv's own {method_name}()")
        method = getattr(self.batched.template, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._all(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices=None) -> list[bool]:
        """False for every copy: the arms are rows of one batched env, not wrapped envs."""
        return [False for _ in self._all(indices)]
