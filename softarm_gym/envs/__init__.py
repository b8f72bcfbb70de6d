"""Gymnasium environments of multi-section pneumatic soft arms (registered by ``import softarm_gym``).

* :class:`ReachEnv` — ``SoftArm/OctArmReach-v0``, ``SoftArm/CTReach-v0``.

All share :class:`SoftArmEnv` (arm, warm-started quasi-static stepping, sensing, estimator,
observation assembly, rendering); see ``docs/environments.md``.
"""

from softarm_gym.envs.base import ACTION_MODES, OBSERVATION_FORMATS, SoftArmEnv
from softarm_gym.envs.randomization import ArmRandomization
from softarm_gym.envs.reach import ReachEnv

__all__ = ["SoftArmEnv", "ReachEnv", "ArmRandomization", "ACTION_MODES", "OBSERVATION_FORMATS"]
