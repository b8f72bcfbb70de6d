"""Wrappers for the soft-arm environments.

:class:`GoalAPI` forwards a goal env's ``compute_reward`` through the wrappers ``gym.make``
adds (every ``SoftArm/*`` id is registered with it, outermost), so that SB3's ``check_env`` and
``HerReplayBuffer`` find it on the env ``gym.make`` returns: Gymnasium's wrappers forward no
attribute a Gymnasium env does not define, and SB3 looks for ``compute_reward`` on
``env.unwrapped`` but calls it on the env itself.

:class:`CornerActions` turns the continuous pressure box into its corners: every channel
either vented or at p_max. The wrap task's optimum can lie there: on ``OctArmWrap-v1`` seeds
0–3, ``CEMPlanner`` holds one corner from the first step (channel I or II+III of every section
at p_max, by the side of the disc), while on the straight path from all vented to that corner
the wrap snaps from under 50° to over 300° between 80 % and 90 % of p_max: a cliff that a
continuous policy's gradient does not show. A categorical policy over the corners sees each
of them directly.
"""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = ["CornerActions", "GoalAPI", "MAX_CORNER_INPUTS", "GOAL_API_SPEC"]

MAX_CORNER_INPUTS = 12
"""The most action dimensions :class:`CornerActions` takes (4,096 corners)."""


class GoalAPI(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """The wrapped env, with the goal env's ``compute_reward`` reachable from outside.

    ``compute_reward`` is the unwrapped env's (``observation_format="goal"``); like the
    env's own, the attribute does not exist for the other formats, which are not goal envs
    (``hasattr`` is False), so libraries that test for it see the right kind of env.
    """

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)

    @property
    def compute_reward(self):
        """``compute_reward(achieved_goal, desired_goal, info)`` of the unwrapped goal env."""
        return self.env.unwrapped.compute_reward


GOAL_API_SPEC = gym.envs.registration.WrapperSpec(name="GoalAPI", entry_point="softarm_gym.wrappers:GoalAPI",
                                                  kwargs={})
"""The registry's entry for :class:`GoalAPI` (``EnvSpec.additional_wrappers``)."""


class CornerActions(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """A ``Discrete(2**n)`` action space over the corners of the env's ``Box(-1, 1, (n,))``.

    Action ``k`` is the corner whose component ``c`` is +1 where bit ``n - 1 - c`` of ``k`` is
    set and −1 where it is clear (``k`` written in binary with channel 0 first, the order of
    ``itertools.product((-1, 1), repeat=n)``). With the envs' absolute actions a corner is a
    bang-bang pressure command (each channel vented or at p_max); with delta actions it moves
    every channel by ± ``delta_scale``.

    Args:
        env: an env with a ``Box(-1, 1, (n,))`` action space, ``n`` ≤ :data:`MAX_CORNER_INPUTS`.

    Raises:
        ValueError: another action space, or too many dimensions.
    """

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        box = env.action_space
        if not isinstance(box, spaces.Box) or len(box.shape) != 1 \
                or not (np.all(box.low == -1.0) and np.all(box.high == 1.0)):
            raise ValueError(f"CornerActions needs a Box(-1, 1, (n,)) action space; got {box}")
        n = box.shape[0]
        if n > MAX_CORNER_INPUTS:
            raise ValueError(f"CornerActions takes at most {MAX_CORNER_INPUTS} action dimensions "
                             f"({2 ** MAX_CORNER_INPUTS} corners); got {n}")
        self.corners = np.array(list(itertools.product((-1.0, 1.0), repeat=n)), dtype=box.dtype)
        """(2**n, n) the corner of each discrete action."""
        self.action_space = spaces.Discrete(len(self.corners))

    def action(self, action) -> np.ndarray:
        """The corner of discrete action ``action`` (an int in [0, 2**n))."""
        k = np.asarray(action)
        if k.shape not in ((), (1,)) or not np.issubdtype(k.dtype, np.integer) \
                or not 0 <= int(k.reshape(())) < len(self.corners):
            raise ValueError(f"action must be an integer in [0, {len(self.corners)}); got {action!r}")
        return self.corners[int(k.reshape(()))]
