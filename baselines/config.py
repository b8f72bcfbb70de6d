"""Hyperparameters, environment construction and model sidecars shared by train and evaluate.

Hyperparameters live in ``baselines/hyperparams/<algo>.yml`` keyed by environment id, as in
rl-baselines3-zoo, but as plain YAML (``policy_kwargs`` is a mapping, not a Python string, so
nothing is ``eval``-ed). Keys other than the ones below go to the SB3 algorithm constructor:

* ``policy`` (str), ``n_timesteps`` (int): the policy class name and the training budget;
* ``n_envs`` (int, default 1): parallel copies of the environment (``DummyVecEnv``);
* ``normalize`` (bool or mapping of ``VecNormalize`` arguments, default false);
* ``env_kwargs`` (mapping, default empty): keyword arguments of ``gym.make``, and
  ``action_wrapper``, a name from :data:`ACTION_WRAPPERS` (``"corners"``: discrete bang-bang
  actions, :class:`softarm_gym.wrappers.CornerActions`) put round the env wherever it is made;
* ``noise_type`` / ``noise_std`` (off-policy only): ``"normal"`` action noise of that std, or
  ``"ornstein-uhlenbeck"``, temporally correlated noise of that σ (SB3's defaults θ = 0.15,
  dt = 0.01; rl-zoo3's names for both);
* ``replay_buffer_class`` (off-policy only): a name from :data:`REPLAY_BUFFERS`
  (``HerReplayBuffer``, with ``replay_buffer_kwargs`` a mapping), as rl-zoo3 writes it.

``sac_her`` is SAC with its own file, ``hyperparams/sac_her.yml``: hindsight experience
replay on the goal format (``env_kwargs: {observation_format: goal}``). Files under
``hyperparams/batched/`` have the same layout for training on the batched env
(``python -m baselines.train --batched``: ``n_envs`` arms in one
:class:`softarm_gym.sb3.BatchedVecEnv`).

A trained model ``FILE.zip`` is accompanied by ``FILE.json`` (env id, algorithm, env_kwargs,
policy class and ``policy_kwargs``, seed, training summary) and, when observations were
normalised, ``FILE_vecnormalize.json`` (the statistics as plain numbers); :func:`load_policy`
reads all three so an evaluation needs only the zip's path.

Loading is safe by default: nothing in these files can run code. An SB3 zip also holds
cloudpickled Python objects (its ``data`` entry), and SB3's ``load`` and ``VecNormalize.load``
unpickle them — a crafted file then runs whatever it likes. :func:`load_policy` instead

* reads only the ``policy.pth`` entry of the zip, with ``torch.load(weights_only=True)``
  (tensors only), into a policy rebuilt from the metadata: an SB3 policy alias of the
  algorithm and JSON ``policy_kwargs`` from a short list of known keys;
* reads the normalisation statistics from JSON;
* accepts from the metadata only registered ``SoftArm/*`` environment ids (Gymnasium
  imports the module of an id of the form ``module:Env``).

``trust_pickle=True`` (``--trust-pickle``) loads the old way, for files you made yourself:
``ALGO.load`` on the zip and a ``FILE_vecnormalize.pkl``. ``python -m baselines.convert``
turns such a trusted model into the safe format.
"""

from __future__ import annotations

import copy
import inspect
import io
import json
import math
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import yaml
from gymnasium import spaces
from stable_baselines3 import PPO, SAC, TD3, HerReplayBuffer
from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

import softarm_gym  # noqa: F401  (registers the SoftArm/* environments)
from softarm_gym.files import write_json
from softarm_gym.wrappers import CornerActions

__all__ = ["ACTION_NOISES", "ACTION_WRAPPERS", "ALGOS", "HYPERPARAMS_DIR", "REPLAY_BUFFERS",
           "load_hyperparams", "split_hyperparams", "make_env",
           "check_env_id", "check_model_env", "is_grasp", "is_wrap", "registered_equivalent", "sidecar_paths",
           "legacy_normalization_path",
           "policy_metadata",
           "save_normalization", "load_normalization", "restore_normalization", "read_metadata",
           "load_policy", "action_noise", "observation_sizes"]

ALGOS = {"ppo": PPO, "sac": SAC, "td3": TD3, "sac_her": SAC}
"""Algorithm names accepted by ``--algo`` (``sac_her``: SAC with the settings of ``sac_her.yml``)."""
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
REPLAY_BUFFERS = {"HerReplayBuffer": HerReplayBuffer}
"""Replay buffers a ``replay_buffer_class`` entry may name."""
ACTION_NOISES = {"normal": NormalActionNoise, "ornstein-uhlenbeck": OrnsteinUhlenbeckActionNoise}
"""Action noises a ``noise_type`` entry may name (rl-zoo3's names)."""
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
    """Split a hyperparameter dict into (the zoo-style special keys, SB3 constructor kwargs);
    a ``replay_buffer_class`` name becomes the class (:data:`REPLAY_BUFFERS`)."""
    special = {k: params[k] for k in _SPECIAL_KEYS if k in params}
    algo_kwargs = {k: v for k, v in params.items() if k not in _SPECIAL_KEYS}
    if "replay_buffer_class" in algo_kwargs:
        name = algo_kwargs["replay_buffer_class"]
        if name not in REPLAY_BUFFERS:
            raise ValueError(f"replay_buffer_class must be one of {', '.join(REPLAY_BUFFERS)}; got {name!r}")
        algo_kwargs["replay_buffer_class"] = REPLAY_BUFFERS[name]
    return special, algo_kwargs


def action_noise(special: dict, action_space: spaces.Space):
    """The SB3 action-noise object described by ``noise_type``/``noise_std`` (None without them).

    Raises:
        ValueError: an unknown ``noise_type``, or noise asked for a discrete action space.
    """
    kind = special.get("noise_type")
    if kind is None:
        return None
    if kind not in ACTION_NOISES:
        raise ValueError(f"noise_type must be one of {', '.join(map(repr, ACTION_NOISES))}; got {kind!r}")
    if not isinstance(action_space, spaces.Box):
        raise ValueError(f"noise_type needs a continuous (Box) action space; got {action_space}")
    n_actions = action_space.shape[0]
    std = float(special.get("noise_std", 0.1))
    return ACTION_NOISES[kind](mean=np.zeros(n_actions), sigma=std * np.ones(n_actions))


def check_env_id(env_id) -> str:
    """``env_id`` if it is a registered ``SoftArm/*`` id, else ValueError.

    Gymnasium imports the module named in an id of the form ``module:Env`` (code from the
    working directory), so ids from files are restricted to this project's registry entries.
    """
    if not (isinstance(env_id, str) and env_id.startswith("SoftArm/") and env_id in gym.registry):
        known = ", ".join(sorted(k for k in gym.registry if k.startswith("SoftArm/")))
        raise ValueError(f"environment id must be a registered SoftArm/* id ({known}); got {env_id!r}")
    return env_id


def is_wrap(env_id: str) -> bool:
    """Whether ``env_id`` is a wrap task (:class:`softarm_gym.envs.WrapEnv`, or the grasp built
    on it, :class:`softarm_gym.envs.GraspEnv`): success is not a distance to a target, so
    monitors and evaluations record ``wrap_angle_deg``."""
    return gym.spec(check_env_id(env_id)).entry_point in ("softarm_gym.envs:WrapEnv",
                                                          "softarm_gym.envs:GraspEnv")


def is_grasp(env_id: str) -> bool:
    """Whether ``env_id`` is the grasp task (:class:`softarm_gym.envs.GraspEnv`)."""
    return gym.spec(check_env_id(env_id)).entry_point == "softarm_gym.envs:GraspEnv"


ACTION_WRAPPERS = {"corners": CornerActions}
"""Names an ``env_kwargs["action_wrapper"]`` may take, and the wrapper each puts round the env."""


def make_env(env_id: str, env_kwargs: dict | None = None, **overrides) -> gym.Env:
    """``gym.make(env_id, **env_kwargs, **overrides)``; overrides win (e.g. ``observation=...``);
    an ``action_wrapper`` entry is not passed on but names the wrapper put round the env
    (:data:`ACTION_WRAPPERS`).

    Raises:
        ValueError: ``env_id`` is not a registered ``SoftArm/*`` id (:func:`check_env_id`), or
            an unknown ``action_wrapper``.
    """
    kwargs = dict(env_kwargs or {})
    kwargs.update(overrides)
    wrapper = kwargs.pop("action_wrapper", None)
    if wrapper is not None and wrapper not in ACTION_WRAPPERS:
        raise ValueError(f"unknown action_wrapper {wrapper!r}; choose one of {', '.join(ACTION_WRAPPERS)}")
    env = gym.make(check_env_id(env_id), **kwargs)
    return env if wrapper is None else ACTION_WRAPPERS[wrapper](env)


def registered_equivalent(env_id: str, env_kwargs: dict | None = None) -> tuple[str, dict]:
    """The newest registered version of ``env_id``'s family whose defaults include
    ``env_kwargs``, with the kwargs left over: ``("SoftArm/OctArmReach-v1", {})`` for
    ``("SoftArm/OctArmReach-v0", {"action_mode": "delta", "delta_scale": 0.1})``.

    The two are the same environment (same entry point, time limit and effective kwargs), so a
    policy trained on one runs unchanged on ``gym.make`` of the other; ``(env_id, env_kwargs)``
    itself when no other version matches.
    """
    spec = gym.spec(check_env_id(env_id))
    effective = {**spec.kwargs, **(env_kwargs or {})}
    best = (spec.version or 0, env_id, dict(env_kwargs or {}))
    for other in gym.registry.values():
        if (other.namespace, other.name) != (spec.namespace, spec.name) or other.id == env_id:
            continue
        if (other.entry_point, other.max_episode_steps) != (spec.entry_point, spec.max_episode_steps):
            continue
        if not all(k in effective and effective[k] == v for k, v in other.kwargs.items()):
            continue
        left = {k: v for k, v in effective.items() if k not in other.kwargs}
        if (other.version or 0) > best[0]:
            best = (other.version or 0, other.id, left)
    return best[1], best[2]


def _describe_env(env: gym.Env) -> dict:
    """What a policy depends on in ``env``: the action semantics (mode and step size), the
    action and observation spaces, and the action wrapper, as comparable, printable values."""
    base = env.unwrapped
    mode = getattr(base, "action_mode", None)
    semantics = f"{mode} actions" + (f" (delta_scale {base.delta_scale:g})" if mode == "delta" else "")
    wrapper = type(env).__name__ if isinstance(env, tuple(ACTION_WRAPPERS.values())) else "no action wrapper"
    return {"action semantics": semantics, "action space": _space_text(env.action_space),
            "observation space": _space_text(env.observation_space), "wrapper": wrapper}


def _space_text(space) -> str:
    if isinstance(space, spaces.Dict):
        return "Dict(" + ", ".join(f"{k}: {_space_text(v)}" for k, v in space.spaces.items()) + ")"
    if isinstance(space, spaces.Discrete):
        return f"Discrete({space.n})"
    return f"{type(space).__name__}{tuple(space.shape)}"


def check_model_env(meta: dict, env: gym.Env, env_id: str, force: bool = False) -> list[str]:
    """Compare the env a model was trained on (its metadata) with ``env``, the env asked for.

    A policy acts on what its actions mean and reads what its observations hold: a delta-action
    policy on an absolute-action env, or a 39-value policy on a 61-value observation, gives
    numbers without meaning (or an error deep in numpy). So a different action semantics,
    action or observation space, or action wrapper is refused in one line naming both envs.

    Args:
        meta: the model's metadata (``env_id``, ``env_kwargs``).
        env: the env the model is about to act in (``make_env`` of ``env_id``).
        env_id: the id ``env`` was made from (for the message).
        force: report the differences instead of refusing them.

    Returns:
        The differences (empty when the envs agree), each ``"what: model's vs env's"``.

    Raises:
        ValueError: the envs differ and ``force`` is False.
    """
    trained = make_env(meta["env_id"], meta.get("env_kwargs", {}))
    try:
        ours, theirs = _describe_env(trained), _describe_env(env)
    finally:
        trained.close()
    differences = [f"{what}: {ours[what]} vs {theirs[what]}" for what in ours if ours[what] != theirs[what]]
    if differences and not force:
        raise ValueError(f"the model was trained on {meta['env_id']} and {env_id} differs: "
                         f"{'; '.join(differences)} (model vs env); pass --force to evaluate anyway")
    return differences


def sidecar_paths(model_path: Path | str) -> tuple[Path, Path]:
    """(metadata JSON, normalisation-statistics JSON) paths that belong to ``model_path`` (``.zip``)."""
    model_path = Path(model_path)
    stem = model_path.with_suffix("")
    return stem.with_suffix(".json"), stem.parent / f"{stem.name}_vecnormalize.json"


def legacy_normalization_path(model_path: Path | str) -> Path:
    """The ``FILE_vecnormalize.pkl`` (a pickled ``VecNormalize``) of models saved before the JSON format."""
    stem = Path(model_path).with_suffix("")
    return stem.parent / f"{stem.name}_vecnormalize.pkl"


# ----------------------------------------------------------------- what the metadata may say

_POLICY_KWARGS = {
    "net_arch": "list of layer sizes, or a mapping of such lists (pi, qf, vf)",
    "log_std_init": "a number", "use_sde": "a bool", "n_critics": "an integer in 1..16",
    "share_features_extractor": "a bool", "ortho_init": "a bool", "squash_output": "a bool",
    "use_expln": "a bool", "clip_mean": "a number", "full_std": "a bool", "normalize_images": "a bool",
}
"""policy_kwargs a metadata file may set: plain data only (no classes, no callables)."""
_MAX_LAYER, _MAX_LAYERS = 4096, 16
_MAX_METADATA_BYTES = 1_000_000
_MAX_WEIGHTS_BYTES = 256 * 2**20


def _layers(value, where: str) -> list[int]:
    if not isinstance(value, list) or len(value) > _MAX_LAYERS or any(
            isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= _MAX_LAYER for n in value):
        raise ValueError(f"{where} must be a list of at most {_MAX_LAYERS} layer sizes in "
                         f"1..{_MAX_LAYER}; got {value!r:.80}")
    return value


def _policy_kwargs(kwargs, where: str) -> dict:
    """Check metadata ``policy_kwargs`` against :data:`_POLICY_KWARGS` (types and sizes)."""
    if not isinstance(kwargs, dict):
        raise ValueError(f"{where} policy_kwargs must be a mapping; got {kwargs!r:.80}")
    for key, value in kwargs.items():
        if key not in _POLICY_KWARGS:
            raise ValueError(f"{where} policy_kwargs has {key!r}, which a metadata file may not set "
                             f"(allowed: {', '.join(_POLICY_KWARGS)})")
        kind = _POLICY_KWARGS[key]
        if key == "net_arch":
            if isinstance(value, dict):
                for name, layers in value.items():
                    if name not in ("pi", "qf", "vf"):
                        raise ValueError(f"{where} net_arch has unknown head {name!r} (pi, qf, vf)")
                    _layers(layers, f"{where} net_arch[{name!r}]")
            else:
                _layers(value, f"{where} net_arch")
        elif kind == "a bool" and not isinstance(value, bool) \
                or kind.startswith("an integer") and (isinstance(value, bool) or not isinstance(value, int)
                                                      or not 1 <= value <= 16) \
                or kind == "a number" and (isinstance(value, bool) or not isinstance(value, (int, float))
                                           or not math.isfinite(value)):
            raise ValueError(f"{where} policy_kwargs[{key!r}] must be {kind}; got {value!r:.80}")
    return kwargs


def policy_metadata(model) -> dict:
    """``{"policy": alias, "policy_kwargs": ...}`` that rebuild ``model``'s policy (see
    :func:`load_policy`); ``policy_kwargs`` as the policy constructor receives them."""
    algo = next(name for name, cls in ALGOS.items() if isinstance(model, cls))
    aliases = ALGOS[algo].policy_aliases
    alias = next((name for name, cls in aliases.items() if type(model.policy) is cls), None)
    if alias is None:
        raise ValueError(f"the {algo} policy {type(model.policy).__name__} is not one of the SB3 aliases "
                         f"{', '.join(ALGOS[algo].policy_aliases)}")
    kwargs = copy.deepcopy(dict(model.policy_kwargs))
    if "use_sde" in inspect.signature(type(model.policy)).parameters:  # PPO passes it separately
        kwargs.setdefault("use_sde", bool(getattr(model, "use_sde", False)))
    return {"policy": alias, "policy_kwargs": kwargs}


def read_metadata(meta_path: Path | str) -> dict:
    """A model's metadata JSON, checked: known ``algo``, registered ``SoftArm/*`` ``env_id``,
    ``env_kwargs`` a mapping, ``policy`` an SB3 alias of the algorithm, safe ``policy_kwargs``.

    Raises:
        ValueError: missing, unreadable, oversized or malformed metadata (one line).
    """
    meta_path = Path(meta_path)
    try:
        with open(meta_path, "rb") as fh:
            raw = fh.read(_MAX_METADATA_BYTES + 1)
    except OSError as exc:
        raise ValueError(f"cannot read metadata file {meta_path.name}: {exc.strerror}") from None
    if len(raw) > _MAX_METADATA_BYTES:
        raise ValueError(f"{meta_path.name} is larger than {_MAX_METADATA_BYTES:,} bytes")
    try:
        meta = json.loads(raw)
    except (ValueError, RecursionError) as exc:
        raise ValueError(f"{meta_path.name} is not valid JSON: {str(exc):.120}") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{meta_path.name} must hold a JSON object")
    algo = meta.get("algo")
    if not (isinstance(algo, str) and algo in ALGOS):
        raise ValueError(f"{meta_path.name} names unknown algo {algo!r:.60}; expected one of "
                         f"{', '.join(ALGOS)}")
    try:
        check_env_id(meta.get("env_id"))
    except ValueError as exc:
        raise ValueError(f"{meta_path.name}: {exc}") from None
    if not isinstance(meta.get("env_kwargs", {}), dict):
        raise ValueError(f"{meta_path.name}: env_kwargs must be a mapping")
    policy = meta.get("policy")
    if not (isinstance(policy, str) and policy in ALGOS[algo].policy_aliases):
        raise ValueError(f"{meta_path.name}: policy must be one of {', '.join(ALGOS[algo].policy_aliases)} "
                         f"(an SB3 alias of {algo}); got {policy!r:.60}. Models saved before this check "
                         "can be converted with python -m baselines.convert")
    _policy_kwargs(meta.get("policy_kwargs", {}), meta_path.name)
    return meta


# ----------------------------------------------------------------- normalisation statistics

def observation_sizes(space) -> int | dict[str, int]:
    """The size of a flat observation space, or of each part of a ``Dict`` one (as
    ``VecNormalize`` keeps statistics: one running mean per ``Dict`` key)."""
    if isinstance(space, spaces.Dict):
        return {key: int(np.prod(sub.shape)) for key, sub in space.spaces.items()}
    return int(np.prod(space.shape))


def save_normalization(vecnorm, path: Path | str) -> None:
    """Write a ``VecNormalize``'s settings and running statistics to ``path`` as JSON, atomically
    (``obs_rms`` holds one set of statistics per key for ``Dict`` observations)."""

    def stats(rms):
        return {"mean": np.asarray(rms.mean, dtype=float).ravel().tolist(),
                "var": np.asarray(rms.var, dtype=float).ravel().tolist(), "count": float(rms.count)}

    obs_rms = vecnorm.obs_rms
    write_json(path, {"format": "vecnormalize-1", "norm_obs": bool(vecnorm.norm_obs),
                      "norm_reward": bool(vecnorm.norm_reward), "clip_obs": float(vecnorm.clip_obs),
                      "clip_reward": float(vecnorm.clip_reward), "gamma": float(vecnorm.gamma),
                      "epsilon": float(vecnorm.epsilon),
                      "obs_rms": {k: stats(v) for k, v in obs_rms.items()} if isinstance(obs_rms, dict)
                      else stats(obs_rms),
                      "ret_rms": stats(vecnorm.ret_rms)}, indent=1)


def _stats(rms, size: int, where: str, name: str) -> dict:
    """One mean/var/count entry of a statistics file, checked against ``size``."""
    try:
        mean, var = (np.asarray(rms[k], dtype=float) for k in ("mean", "var"))
        count = float(rms["count"])
    except (TypeError, KeyError, ValueError):
        raise ValueError(f"{where}: {name} must hold mean, var (lists of numbers) and count") from None
    if mean.shape != (size,) or var.shape != (size,) or not (
            np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)
            and math.isfinite(count) and count > 0):
        raise ValueError(f"{where}: {name} must have {size} finite means, {size} finite variances "
                         f">= 0 and a count > 0")
    return {"mean": mean, "var": var, "count": count}


def load_normalization(path: Path | str, obs_size: int | dict[str, int]) -> dict:
    """The statistics written by :func:`save_normalization`, checked (sizes, finite, var >= 0).

    Args:
        path: the JSON file.
        obs_size: the flat observation size they must match, or the size per key of a
            ``Dict`` observation (:func:`observation_sizes`).

    Raises:
        ValueError: unreadable or inconsistent statistics (one line).
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = json.loads(fh.read(_MAX_METADATA_BYTES + 1))
    except OSError as exc:
        raise ValueError(f"cannot read {path.name}: {exc.strerror}") from None
    except (ValueError, RecursionError) as exc:
        raise ValueError(f"{path.name} is not valid JSON: {str(exc):.120}") from None
    if not isinstance(data, dict) or data.get("format") != "vecnormalize-1":
        raise ValueError(f"{path.name} is not a vecnormalize-1 statistics file")
    for key in ("norm_obs", "norm_reward"):
        if not isinstance(data.get(key), bool):
            raise ValueError(f"{path.name}: {key} must be true or false")
    for key in ("clip_obs", "clip_reward", "epsilon", "gamma"):
        v = data.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
            raise ValueError(f"{path.name}: {key} must be a finite number > 0; got {v!r:.40}")
    data["ret_rms"] = _stats(data.get("ret_rms"), 1, path.name, "ret_rms")
    obs_rms = data.get("obs_rms")
    if isinstance(obs_size, dict):
        if not isinstance(obs_rms, dict) or set(obs_rms) != set(obs_size):
            raise ValueError(f"{path.name}: obs_rms must hold statistics for the observation keys "
                             f"{', '.join(obs_size)}")
        data["obs_rms"] = {k: _stats(obs_rms[k], n, path.name, f"obs_rms[{k!r}]")
                           for k, n in obs_size.items()}
    elif isinstance(obs_rms, dict) and "mean" not in obs_rms:
        raise ValueError(f"{path.name}: obs_rms holds statistics per observation key ({', '.join(obs_rms)}), "
                         "but the observation is flat")
    else:
        data["obs_rms"] = _stats(obs_rms, obs_size, path.name, "obs_rms")
    return data


def restore_normalization(vecnorm, stats: dict) -> None:
    """Put :func:`load_normalization` statistics into a ``VecNormalize`` (settings and running stats)."""
    for key in ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon"):
        setattr(vecnorm, key, stats[key])
    pairs = [(vecnorm.ret_rms, stats["ret_rms"])]
    if isinstance(vecnorm.obs_rms, dict):
        pairs += [(vecnorm.obs_rms[k], stats["obs_rms"][k]) for k in vecnorm.obs_rms]
    else:
        pairs.append((vecnorm.obs_rms, stats["obs_rms"]))
    for rms, saved in pairs:
        rms.mean = saved["mean"].reshape(np.shape(rms.mean)).copy()
        rms.var = saved["var"].reshape(np.shape(rms.var)).copy()
        rms.count = saved["count"]


# ----------------------------------------------------------------- loading a trained policy

def _weights(model_path: Path) -> dict:
    """The ``policy.pth`` state dict of an SB3 zip, loaded with ``torch.load(weights_only=True)``."""
    import torch

    try:
        with zipfile.ZipFile(model_path) as archive:
            info = archive.getinfo("policy.pth")
            if info.file_size > _MAX_WEIGHTS_BYTES:
                raise ValueError(f"{model_path.name}: policy.pth is {info.file_size:,} bytes; at most "
                                 f"{_MAX_WEIGHTS_BYTES:,} are read")
            raw = archive.read(info)
    except zipfile.BadZipFile:
        raise ValueError(f"{model_path.name} is not a zip file") from None
    except KeyError:
        raise ValueError(f"{model_path.name} has no policy.pth (not a model saved by SB3)") from None
    try:
        state = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as exc:  # weights_only refuses anything but tensors and plain containers
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"{model_path.name}: policy.pth is not plain weights (refused by "
                         f"torch.load(weights_only=True): {first:.160})") from None
    if not isinstance(state, dict):
        raise ValueError(f"{model_path.name}: policy.pth must hold a state dict")
    return state


def _rebuilt_policy(meta: dict, model_path: Path, observation_space, action_space):
    """The metadata's policy class with its kwargs, and the zip's weights loaded into it."""
    cls = ALGOS[meta["algo"]].policy_aliases[meta["policy"]]
    try:
        policy = cls(observation_space, action_space, lambda _: 0.0, **meta.get("policy_kwargs", {}))
    except (TypeError, ValueError, AssertionError) as exc:
        raise ValueError(f"{model_path.name}: cannot build {meta['policy']} from its metadata: "
                         f"{str(exc):.160}") from None
    try:
        policy.load_state_dict(_weights(model_path), strict=True)
    except RuntimeError as exc:  # missing/unexpected keys, wrong shapes
        raise ValueError(f"{model_path.name}: the weights do not fit the policy its metadata describes "
                         f"({str(exc).splitlines()[0]:.160})") from None
    policy.set_training_mode(False)
    return policy


def load_policy(model_path: Path | str, *, trust_pickle: bool = False):
    """Load a trained policy with its metadata and observation-normalisation statistics.

    Args:
        model_path: a ``.zip`` written by :mod:`baselines.train` (or converted by
            :mod:`baselines.convert`), with ``FILE.json`` and, if observations were normalised,
            ``FILE_vecnormalize.json`` next to it.
        trust_pickle: load the old way (module docstring): ``ALGO.load`` unpickles the zip's
            Python objects and ``FILE_vecnormalize.pkl`` is unpickled if there is no JSON —
            either can run arbitrary code, so only for files you made yourself.

    Returns:
        (policy, metadata dict, ``VecNormalize`` or None). ``policy.predict(obs,
        deterministic=True)`` acts; the VecNormalize wraps a throw-away env, is in evaluation
        mode, and its ``normalize_obs`` prepares observations.

    Raises:
        ValueError: a missing, malformed or unsafe file, named on one line.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    model_path = Path(model_path)
    if model_path.suffix != ".zip" or not model_path.is_file():
        raise ValueError(f"--model must be an existing .zip saved by baselines.train; "
                         f"got {str(model_path)!r}")
    meta_path, norm_path = sidecar_paths(model_path)
    if not meta_path.is_file():
        raise ValueError(f"{model_path.name} has no metadata file {meta_path.name} next to it")
    meta = read_metadata(meta_path)
    pickled = legacy_normalization_path(model_path)
    if not norm_path.is_file() and pickled.is_file() and not trust_pickle:
        raise ValueError(f"{model_path.name}: its normalisation statistics are the pickle {pickled.name}, "
                         "which can run code when loaded; if you made it, convert the model with "
                         "python -m baselines.convert (or pass --trust-pickle)")
    if not norm_path.is_file() and not pickled.is_file() and meta.get("normalized"):
        raise ValueError(f"{model_path.name} was trained on normalised observations but "
                         f"{norm_path.name} is missing")
    venv = DummyVecEnv([lambda: make_env(meta["env_id"], meta.get("env_kwargs", {}))])
    try:
        if trust_pickle:
            policy = ALGOS[meta["algo"]].load(model_path, device="cpu")
        else:
            policy = _rebuilt_policy(meta, model_path, venv.observation_space, venv.action_space)
        if norm_path.is_file():
            vecnorm = VecNormalize(venv, training=False)
            sizes = observation_sizes(venv.observation_space)
            restore_normalization(vecnorm, load_normalization(norm_path, sizes))
        elif pickled.is_file():
            vecnorm = VecNormalize.load(str(pickled), venv)
        else:
            venv.close()
            return policy, meta, None
    except BaseException:
        venv.close()
        raise
    vecnorm.training = False
    vecnorm.norm_reward = False
    return policy, meta, vecnorm
