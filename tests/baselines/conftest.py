"""Shared fixtures of the baseline tests: tiny hyperparameters and one tiny trained model."""

from pathlib import Path

import pytest
import yaml

from baselines.train import train

TINY = {
    "sac": {"policy": "MlpPolicy", "n_timesteps": 200, "env_kwargs": {"action_mode": "delta"},
            "normalize": {"norm_obs": True, "norm_reward": False}, "learning_starts": 50,
            "batch_size": 16, "buffer_size": 1000, "policy_kwargs": {"net_arch": [8]}},
    "td3": {"policy": "MlpPolicy", "n_timesteps": 200, "env_kwargs": {"action_mode": "delta"},
            "noise_type": "normal", "noise_std": 0.1, "learning_starts": 50, "batch_size": 16,
            "buffer_size": 1000, "policy_kwargs": {"net_arch": [8]}},
    "ppo": {"policy": "MlpPolicy", "n_timesteps": 256, "n_envs": 2,
            "normalize": {"norm_obs": True, "norm_reward": True}, "n_steps": 64, "batch_size": 32,
            "n_epochs": 1, "policy_kwargs": {"net_arch": [8]}},
}
"""A few hundred steps with 8-unit networks: exercises every code path in seconds."""


def tiny_hyperparams(directory: Path, env_ids=("SoftArm/OctArmReach-v0",), **entries) -> Path:
    """``directory`` holding ``<algo>.yml`` with the :data:`TINY` entry (or ``entries[algo]``) per env."""
    directory.mkdir(parents=True, exist_ok=True)
    for algo, entry in {**TINY, **entries}.items():
        (directory / f"{algo}.yml").write_text(yaml.safe_dump({env_id: entry for env_id in env_ids}))
    return directory


@pytest.fixture(scope="session")
def tiny_sac_run(tmp_path_factory):
    """Run folder of a 200-step SAC training on OctArm reach (evaluation and checkpoints on)."""
    return train("SoftArm/OctArmReach-v0", "sac", seed=3, log_dir=tmp_path_factory.mktemp("runs"),
                 hyperparams=TINY["sac"], eval_freq=100, eval_episodes=1, checkpoint_freq=100,
                 progress=False)
