"""Hyperparameters, environment construction and model sidecars shared by train and evaluate.

Hyperparameters live in ``baselines/hyperparams/<algo>.yml`` keyed by environment id, as in
rl-baselines3-zoo, but as plain YAML (``policy_kwargs`` is a mapping, not a Python string, so
nothing is ``eval``-ed). Keys other than the ones below go to the SB3 algorithm constructor:

* ``policy`` (str), ``n_timesteps`` (int): the policy class name and the training budget;
* ``n_envs`` (int, default 1): parallel copies of the environment (``DummyVecEnv``);
* ``normalize`` (bool or mapping of ``VecNormalize`` arguments, default false);
* ``env_kwargs`` (mapping, default empty): keyword arguments of ``gym.make``;
* ``noise_type`` / ``noise_std`` (off-policy only): ``"normal"`` action noise of that std.

A trained model ``FILE.zip`` is accompanied by ``FILE.json`` (env id, algorithm, env_kwargs,
seed, training summary) and, when observations were normalised, ``FILE_vecnormalize.pkl``;
:func:`load_policy` reads all three so an evaluation needs only the zip's path.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import yaml
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.noise import NormalActionNoise

import softarm_gym  # noqa: F401  (registers the SoftArm/* environments)

__all__ = ["ALGOS", "HYPERPARAMS_DIR", "load_hyperparams", "split_hyperparams", "make_env",
           "sidecar_paths", "load_policy", "action_noise"]

ALGOS = {"ppo": PPO, "sac": SAC, "td3": TD3}
"""Algorithm names accepted by ``--algo``."""
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
_SPECIAL_KEYS = ("policy", "n_timesteps", "n_envs", "normalize", "env_kwargs", "noise_type", "noise_std")


def load_hyperparams(algo: str, env_id: str, directory: Path | str = HYPERPARAMS_DIR) -> dict:
    """The hyperparameters of ``algo`` on ``env_id`` from ``<directory>/<algo>.yml``.

    Args:
        algo: one of :data:`ALGOS`.
        env_id: a registered environment id, a top-level key of the YAML file.
        directory: folder of the YAML files.

    Returns:
        A fresh dict (safe to modify) with at least ``policy`` and ``n_timesteps``.

    Raises:
        ValueError: unknown algorithm, missing file, env id not in the file, or a malformed entry.
    """
    if algo not in ALGOS:
        raise ValueError(f"unknown algo {algo!r}; choose one of {', '.join(ALGOS)}")
    path = Path(directory) / f"{algo}.yml"
    if not path.is_file():
        raise ValueError(f"no hyperparameter file {path}")
    table = yaml.safe_load(path.read_text()) or {}
    if env_id not in table:
        raise ValueError(f"{path.name} has no entry for {env_id!r}; it has: {', '.join(table) or 'none'}")
    params = copy.deepcopy(table[env_id])
    if not isinstance(params, dict) or "policy" not in params or "n_timesteps" not in params:
        raise ValueError(f"{path.name}[{env_id!r}] must be a mapping with 'policy' and 'n_timesteps'")
    if not isinstance(params.get("env_kwargs", {}), dict):
        raise ValueError(f"{path.name}[{env_id!r}].env_kwargs must be a mapping")
    return params


def split_hyperparams(params: dict) -> tuple[dict, dict]:
    """Split a hyperparameter dict into (the zoo-style special keys, SB3 constructor kwargs)."""
    special = {k: params[k] for k in _SPECIAL_KEYS if k in params}
    algo_kwargs = {k: v for k, v in params.items() if k not in _SPECIAL_KEYS}
    return special, algo_kwargs


def action_noise(special: dict, n_actions: int):
    """The SB3 action-noise object described by ``noise_type``/``noise_std`` (None without them)."""
    kind = special.get("noise_type")
    if kind is None:
        return None
    if kind != "normal":
        raise ValueError(f"noise_type must be 'normal'; got {kind!r}")
    std = float(special.get("noise_std", 0.1))
    return NormalActionNoise(mean=np.zeros(n_actions), sigma=std * np.ones(n_actions))


def make_env(env_id: str, env_kwargs: dict | None = None, **overrides) -> gym.Env:
    """``gym.make(env_id, **env_kwargs, **overrides)``; overrides win (e.g. ``observation=...``)."""
    kwargs = dict(env_kwargs or {})
    kwargs.update(overrides)
    return gym.make(env_id, **kwargs)


def sidecar_paths(model_path: Path | str) -> tuple[Path, Path]:
    """(metadata JSON, VecNormalize pickle) paths that belong to ``model_path`` (``.zip``)."""
    model_path = Path(model_path)
    stem = model_path.with_suffix("")
    return stem.with_suffix(".json"), stem.parent / f"{stem.name}_vecnormalize.pkl"


def load_policy(model_path: Path | str):
    """Load a trained model with its metadata and observation-normalisation statistics.

    Args:
        model_path: a ``.zip`` written by :mod:`baselines.train`.

    Returns:
        (model, metadata dict, ``VecNormalize`` or None). The VecNormalize is loaded around a
        throw-away env and set to evaluation mode; use its ``normalize_obs``.

    Raises:
        ValueError: the file or its metadata is missing or names an unknown algorithm.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    model_path = Path(model_path)
    if model_path.suffix != ".zip" or not model_path.is_file():
        raise ValueError(f"--model must be an existing .zip saved by baselines.train; "
                         f"got {str(model_path)!r}")
    meta_path, norm_path = sidecar_paths(model_path)
    if not meta_path.is_file():
        raise ValueError(f"{model_path.name} has no metadata file {meta_path.name} next to it")
    meta = json.loads(meta_path.read_text())
    algo = meta.get("algo")
    if algo not in ALGOS:
        raise ValueError(f"{meta_path.name} names unknown algo {algo!r}")
    model = ALGOS[algo].load(model_path, device="cpu")
    vecnorm = None
    if norm_path.is_file():
        env_id, env_kwargs = meta["env_id"], meta.get("env_kwargs", {})
        venv = DummyVecEnv([lambda: make_env(env_id, env_kwargs)])
        vecnorm = VecNormalize.load(str(norm_path), venv)
        vecnorm.training = False
        vecnorm.norm_reward = False
    return model, meta, vecnorm
