"""Gymnasium environments of multi-section pneumatic soft arms (registered by ``import softarm_gym``).

* :class:`ReachEnv` — ``SoftArm/OctArmReach-v0``, ``SoftArm/CTReach-v0``.
* :class:`WrapEnv` — ``SoftArm/OctArmWrap-v0``, ``SoftArm/CTWrap-v0``.
* :class:`ObstacleReachEnv` — ``SoftArm/OctArmObstacleReach-v0``, ``SoftArm/CTObstacleReach-v0``.
* :class:`TrackEnv` — ``SoftArm/OctArmTrack-v0``, ``SoftArm/CTTrack-v0``.
* :class:`GraspEnv` — ``SoftArm/OctArmGrasp-v1`` (and ``-v0``).

:func:`run_demo_episode` runs a reach episode with a simple model-based controller and saves
an animation. All share :class:`SoftArmEnv` (arm, warm-started quasi-static stepping, sensing, estimator,
observation assembly, rendering); see ``docs/environments.md``.
"""

from softarm_gym.envs.base import ACTION_MODES, OBSERVATION_FORMATS, SoftArmEnv
from softarm_gym.envs.demo import run_demo_episode
from softarm_gym.envs.grasp import GraspEnv
from softarm_gym.envs.obstacle import ObstacleReachEnv
from softarm_gym.envs.randomization import ArmRandomization, PosteriorRandomization, coerce_randomization
from softarm_gym.envs.reach import ReachEnv
from softarm_gym.envs.track import TrackEnv
from softarm_gym.envs.wrap import WrapEnv, arm_half_thickness, wrap_angle

__all__ = ["SoftArmEnv", "ReachEnv", "ObstacleReachEnv", "TrackEnv", "WrapEnv", "GraspEnv",
           "ArmRandomization", "PosteriorRandomization", "coerce_randomization", "wrap_angle",
           "arm_half_thickness", "run_demo_episode", "ACTION_MODES",
           "OBSERVATION_FORMATS"]
