"""Convert models saved with pickled sidecars to the safe format — for files you trust.

    python -m baselines.convert runs/sac_OctArmReach-v1_s0/best_model.zip [...] [--remove-pickle]

Models saved before the safe format keep their observation statistics in
``FILE_vecnormalize.pkl`` and lack the policy description in ``FILE.json``, so
:func:`baselines.config.load_policy` refuses them. This loads each one the old way (SB3's
``ALGO.load`` and ``VecNormalize.load``, which unpickle and can therefore run code: only
convert files you made yourself), writes ``FILE_vecnormalize.json`` and adds ``policy``,
``policy_kwargs`` and ``normalized`` to ``FILE.json``, then checks that the safe loader
gives the same deterministic actions as the trusted model on observations from
``--check-episodes`` episodes of random actions. ``--remove-pickle`` deletes the ``.pkl``
after a successful check.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from baselines.config import (
    ALGOS,
    legacy_normalization_path,
    load_policy,
    make_env,
    policy_metadata,
    save_normalization,
    sidecar_paths,
)
from softarm_gym.files import write_json

__all__ = ["convert", "main"]


def convert(model_path: Path | str, *, check_episodes: int = 3, remove_pickle: bool = False) -> dict:
    """Convert one trusted model (module docstring).

    Returns:
        ``{"model", "normalization" (path or None), "observations_checked",
        "max_action_difference"}``.

    Raises:
        ValueError: missing files, or the safe loader does not reproduce the model's actions.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    model_path = Path(model_path)
    meta_path, norm_path = sidecar_paths(model_path)
    pickled = legacy_normalization_path(model_path)
    if not (model_path.is_file() and meta_path.is_file()):
        raise ValueError(f"{model_path} needs to exist with its metadata {meta_path.name}")
    meta = json.loads(meta_path.read_text())
    if meta.get("algo") not in ALGOS:
        raise ValueError(f"{meta_path.name} names unknown algo {meta.get('algo')!r}")
    trusted = ALGOS[meta["algo"]].load(model_path, device="cpu")
    vecnorm = None
    if pickled.is_file():
        venv = DummyVecEnv([lambda: make_env(meta["env_id"], meta.get("env_kwargs", {}))])
        vecnorm = VecNormalize.load(str(pickled), venv)
        vecnorm.training, vecnorm.norm_reward = False, False
        save_normalization(vecnorm, norm_path)
    write_json(meta_path, {**meta, **policy_metadata(trusted), "normalized": vecnorm is not None})

    policy, _, safe_norm = load_policy(model_path)
    env = make_env(meta["env_id"], meta.get("env_kwargs", {}))
    worst, count = 0.0, 0
    for episode in range(check_episodes):
        obs, _ = env.reset(seed=episode)
        env.action_space.seed(episode)
        done = False
        while not done:
            a = trusted.predict(vecnorm.normalize_obs(obs) if vecnorm else obs, deterministic=True)[0]
            b = policy.predict(safe_norm.normalize_obs(obs) if safe_norm else obs, deterministic=True)[0]
            worst, count = max(worst, float(np.max(np.abs(a - b)))), count + 1
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            done = terminated or truncated
    env.close()
    if worst > 1e-6:
        raise ValueError(f"{model_path.name}: the safely loaded policy differs from the trusted one by "
                         f"{worst:.3g} in its actions; not converted")
    if remove_pickle and pickled.is_file():
        pickled.unlink()
    return {"model": str(model_path), "normalization": str(norm_path) if vecnorm else None,
            "observations_checked": count, "max_action_difference": worst}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.convert", description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+", metavar="FILE.zip", help="models you trust")
    parser.add_argument("--check-episodes", type=int, default=3,
                        help="episodes whose observations the check compares actions on")
    parser.add_argument("--remove-pickle", action="store_true",
                        help="delete FILE_vecnormalize.pkl afterwards")
    args = parser.parse_args(argv)
    for model in args.models:
        try:
            result = convert(model, check_episodes=args.check_episodes, remove_pickle=args.remove_pickle)
        except ValueError as exc:
            print(f"baselines.convert: error: {exc}", file=sys.stderr)
            return 2
        print(f"{result['model']}: converted; actions identical on {result['observations_checked']} "
              f"observations (max difference {result['max_action_difference']:.1g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
