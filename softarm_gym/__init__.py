"""softarm-gym: Gymnasium environments for multi-section pneumatic soft arms.

Importing the package registers the environments (``gym.make("SoftArm/OctArmReach-v0")``);
the classes live in :mod:`softarm_gym.envs`. Default kwargs below are the only difference
between the OctArm and CT variants.
"""

from gymnasium.envs.registration import register

__version__ = "0.1.0"

register(
    id="SoftArm/OctArmReach-v0",
    entry_point="softarm_gym.envs:ReachEnv",
    vector_entry_point="softarm_gym.vector:BatchedReachVectorEnv",
    max_episode_steps=100,
    kwargs={"design": "octarm_v", "base_angle_deg": 90.0},
)

register(
    id="SoftArm/CTReach-v0",
    entry_point="softarm_gym.envs:ReachEnv",
    vector_entry_point="softarm_gym.vector:BatchedReachVectorEnv",
    max_episode_steps=100,
    kwargs={"design": "ct", "base_angle_deg": 90.0},
)

register(
    id="SoftArm/OctArmWrap-v0",
    entry_point="softarm_gym.envs:WrapEnv",
    max_episode_steps=200,
    kwargs={"design": "octarm_v", "base_angle_deg": 0.0, "object_radius": (0.09, 0.11)},
)

register(
    id="SoftArm/CTWrap-v0",
    entry_point="softarm_gym.envs:WrapEnv",
    max_episode_steps=200,
    # The CT arm turns by at most ~200 deg at 70 psi (docs/environments.md): larger objects,
    # a half-turn placement and a 90 deg success threshold.
    kwargs={"design": "ct", "base_angle_deg": 90.0, "object_radius": (0.15, 0.20),
            "placement_wrap_deg": 180.0, "success_wrap_deg": 90.0},
)
