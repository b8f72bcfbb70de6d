"""Imitation of the sampling planner (or a scripted controller): demonstrations, behaviour
cloning and DAgger.

Usage::

    python -m baselines.imitate collect --env SoftArm/OctArmWrap-v2 --episodes 40 --seed 0 \\
        --out runs/demos/planner_OctArmWrap-v2_s0.npz
    python -m baselines.imitate collect --env SoftArm/OctArmGrasp-v1 --expert curl --episodes 100 \\
        --out runs/demos/curl_OctArmGrasp-v1_s0.npz
    python -m baselines.imitate bc --demos runs/demos/planner_OctArmWrap-v2_s0.npz \\
        --out runs/bc_OctArmWrap-v2_s0
    python -m baselines.imitate dagger --demos runs/demos/planner_OctArmWrap-v2_s0.npz \\
        --rounds 2 --episodes 10 --seed 1000 --out runs/dagger_OctArmWrap-v2_s0
    python -m baselines.evaluate --model runs/bc_OctArmWrap-v2_s0/final_model.zip --episodes 50 --seed 100000
    python -m baselines.train --env SoftArm/OctArmWrap-v2 --algo ppo --batched \\
        --hyperparams-dir baselines/hyperparams/batched_gsde \\
        --init-policy runs/bc_OctArmWrap-v2_s0/final_model.zip

A cloned policy's run folder is laid out as a training run's (``final_model.zip`` with its
sidecars, ``summary.json``, whose steps and times are the expert's environment steps and the
collection and fitting time), so ``python -m baselines.results collect/evaluate/report`` treat
it as one.

The expert (:data:`EXPERTS`) is :class:`softarm_gym.controllers.CEMPlanner` with its defaults,
made afresh at every episode start and seeded with the episode's seed (as ``baselines.evaluate
--controller planner`` runs it), or the scripted :class:`softarm_gym.controllers.CurlController`
(``--expert curl``: where the planner is too slow to demonstrate — a grasp decision takes it
minutes — the curl is a teacher at the cost of a step). A demonstration records, at every
step, the observation the policy sees (the env's raw flat observation) and the action the
expert sent (the env's action space: delta actions on the recommended ids). The files are
``.npz`` arrays (``allow_pickle=False``) with a ``.json`` sidecar (env id, expert, seeds, the
expert's success, wall time).

Behaviour cloning (:func:`behaviour_clone`) fits the policy of a PPO model built with the
hyperparameters PPO itself trains with (default ``baselines/hyperparams/batched_gsde/ppo.yml``),
so the result is an ordinary PPO model: ``baselines.evaluate`` loads it, and
``baselines.train --init-policy`` starts a PPO fine-tune from it. The loss is the negative
log-likelihood of the planner's actions under the policy's action distribution minus a small
entropy bonus (as the ``imitation`` library's BC; ``policy.evaluate_actions``). Observations
are normalised with the demonstrations' mean and variance, saved as the model's
``_vecnormalize.json``, as PPO's ``VecNormalize`` statistics are.

Why not ``imitation`` (HumanCompatibleAI) itself: its release 1.0.1 pins
``stable-baselines3~=2.2.1`` and ``gymnasium~=0.29``; installing it would downgrade this
project's stable-baselines3 2.9 and gymnasium 1.x (``pip install --dry-run imitation``).

DAgger (:func:`dagger`): the learner acts, the planner labels every state the learner visits
with the action it would send there (its nominal model follows the observed pressures, so it
replans from the learner's state), the labelled states join the data and the policy is cloned
again on all of it. Round ``k`` rolls out the policy of round ``k - 1`` deterministically, on
episode seeds ``seed + k * episodes ...``.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
from tqdm import tqdm

from baselines.config import (
    HYPERPARAMS_DIR,
    check_env_id,
    load_hyperparams,
    load_policy,
    make_env,
    split_hyperparams,
)
from baselines.train import project_path, save_checkpoint
from softarm_gym.commands.common import add_numba_threads_argument, add_quiet_argument, apply_numba_threads
from softarm_gym.controllers import CEMPlanner, CurlController
from softarm_gym.files import write_json

__all__ = ["DEMO_FIELDS", "EXPERTS", "collect", "save_demonstrations", "load_demonstrations",
           "behaviour_clone", "dagger", "main"]

DEMO_FIELDS = ("observations", "actions", "episodes")
"""Per-step arrays of a demonstration file: (T, obs) float32 observations, (T, n) float32
actions, (T,) int64 index of the episode each step belongs to."""
EXPERTS = {"planner": CEMPlanner, "curl": CurlController}
"""What :func:`collect` can take demonstrations from: name -> controller class (``act(obs)``),
one made afresh at every episode start (the planner seeded with the episode's seed)."""
DEFAULT_HYPERPARAMS_DIR = HYPERPARAMS_DIR / "batched_gsde"
"""The PPO settings a cloned policy takes its architecture from (the gSDE remedy's)."""


def _expert_rollouts(env, episode_seeds, act, progress: bool, label: str, expert: str = "planner") -> dict:
    """Run one episode per seed; ``act(obs, expert_action)`` is the action sent. Returns the
    visited observations with the expert's (:data:`EXPERTS`) action at each, and per-episode
    outcomes."""
    observations, actions, episodes = [], [], []
    success, wrap = [], []
    for k, seed in enumerate(tqdm(episode_seeds, disable=not progress, file=sys.stderr, unit="episode",
                                  desc=label)):
        obs, info = env.reset(seed=int(seed))
        teacher = CEMPlanner(env, seed=int(seed)) if expert == "planner" else EXPERTS[expert](env)
        done = False
        while not done:
            label_action = teacher.act(obs)
            observations.append(np.asarray(obs, dtype=np.float32))
            actions.append(label_action)
            episodes.append(k)
            obs, _, terminated, truncated, info = env.step(act(obs, label_action))
            done = terminated or truncated
        success.append(bool(info["is_success"]))
        wrap.append(float(info.get("wrap_angle_deg", np.nan)))
    return {"observations": np.array(observations, dtype=np.float32),
            "actions": np.array(actions, dtype=np.float32), "episodes": np.array(episodes, dtype=np.int64),
            "episode_seeds": np.asarray(episode_seeds, dtype=np.int64), "success": np.array(success),
            "final_wrap_deg": np.array(wrap)}


def collect(env_id: str, episodes: int, seed: int = 0, env_kwargs: dict | None = None,
            progress: bool = False, expert: str = "planner") -> dict:
    """Demonstrations of ``expert`` (a name in :data:`EXPERTS`): ``episodes`` whole episodes,
    episode ``i`` reset with ``seed + i``.

    Returns:
        The :data:`DEMO_FIELDS` arrays plus ``episode_seeds``, ``success`` (the expert's, at
        the last step) and ``final_wrap_deg`` (NaN off wrap), one per episode, and
        ``meta`` (env id and kwargs, expert, wall time in s).
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1; got {episodes}")
    if expert not in EXPERTS:
        raise ValueError(f"unknown expert {expert!r}; choose one of {', '.join(EXPERTS)}")
    env = make_env(check_env_id(env_id), env_kwargs)
    start, cpu = time.perf_counter(), time.process_time()
    try:
        demos = _expert_rollouts(env, range(seed, seed + episodes), lambda obs, label: label, progress,
                                 expert, expert)
    finally:
        env.close()
    demos["meta"] = {"env_id": env_id, "env_kwargs": dict(env_kwargs or {}),
                     "expert": EXPERTS[expert].__name__, "first_seed": seed, "episodes": episodes,
                     "wall_time_s": time.perf_counter() - start, "cpu_time_s": time.process_time() - cpu,
                     "expert_success_rate": float(np.mean(demos["success"]))}
    return demos


def save_demonstrations(demos: dict, path: Path | str) -> Path:
    """Write ``demos`` (:func:`collect`) to ``path`` (``.npz``) and its ``meta`` to ``.json`` next to it."""
    path = Path(path)
    if path.suffix != ".npz":
        raise ValueError(f"a demonstration file must end in .npz; got {str(path)!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **{k: v for k, v in demos.items() if k != "meta"})
    write_json(path.with_suffix(".json"), demos["meta"])
    return path


def load_demonstrations(paths) -> dict:
    """Load and concatenate demonstration files (one env id and expert among them).

    Returns:
        The :data:`DEMO_FIELDS` arrays (episode indices renumbered across files) and ``meta``
        with ``env_id``, ``env_kwargs``, ``expert``, ``files`` and the number of ``episodes``.

    Raises:
        ValueError: a missing or malformed file, or files of different envs or experts.
    """
    parts, metas = [], []
    for path in map(Path, paths):
        if not path.is_file() or not path.with_suffix(".json").is_file():
            raise ValueError(f"{path} is not a demonstration file (an .npz with its .json; "
                             "python -m baselines.imitate collect writes them)")
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in DEMO_FIELDS if k not in data]
            if missing:
                raise ValueError(f"{path.name} lacks {', '.join(missing)}")
            parts.append({k: data[k] for k in DEMO_FIELDS})
        metas.append(json.loads(path.with_suffix(".json").read_text()))
    if not parts:
        raise ValueError("no demonstration files given")
    keys = {(m["env_id"], json.dumps(m.get("env_kwargs", {}), sort_keys=True)) for m in metas}
    if len(keys) > 1:
        raise ValueError(f"the demonstrations come from different envs: {sorted(keys)}")
    experts = {m.get("expert", CEMPlanner.__name__) for m in metas}
    if len(experts) > 1:
        raise ValueError(f"the demonstrations come from different experts: {sorted(experts)}")
    offset, episodes = 0, []
    for part in parts:
        episodes.append(part["episodes"] + offset)
        offset += int(part["episodes"].max()) + 1 if part["episodes"].size else 0
    return {"observations": np.concatenate([p["observations"] for p in parts]),
            "actions": np.concatenate([p["actions"] for p in parts]),
            "episodes": np.concatenate(episodes),
            "meta": {"env_id": metas[0]["env_id"], "env_kwargs": metas[0].get("env_kwargs", {}),
                     "expert": experts.pop(),
                     "files": [str(p) for p in paths], "episodes": offset,
                     "wall_time_s": sum(m.get("wall_time_s", 0.0) for m in metas),
                     "cpu_time_s": sum(m.get("cpu_time_s", 0.0) for m in metas)}}


def _carrier(env_id: str, env_kwargs: dict, hyperparams_dir: Path | str, seed: int):
    """A PPO model with the YAML's policy settings on one env (only its policy is trained here),
    in a ``VecNormalize`` whose observation statistics :func:`_fit` sets; and the YAML entry."""
    params = load_hyperparams("ppo", env_id, hyperparams_dir)
    special, algo_kwargs = split_hyperparams(copy.deepcopy(params))
    if dict(special.get("env_kwargs", {})) != dict(env_kwargs):
        raise ValueError(f"the demonstrations were recorded with env_kwargs {env_kwargs}, the PPO entry "
                         f"of {hyperparams_dir} trains with {special.get('env_kwargs', {})}")
    venv = VecNormalize(DummyVecEnv([lambda: make_env(env_id, env_kwargs)]), training=False,
                        **(special["normalize"] if isinstance(special.get("normalize"), dict) else {}))
    # One env: a rollout buffer of one batch (the carrier never collects rollouts).
    algo_kwargs["n_steps"] = algo_kwargs["batch_size"] = int(algo_kwargs.get("batch_size", 64))
    model = PPO(special["policy"], venv, seed=seed, device="cpu", verbose=0, **algo_kwargs)
    return model, params


def _fit(model, observations: np.ndarray, actions: np.ndarray, *, epochs: int, batch_size: int,
         learning_rate: float, ent_weight: float, seed: int, progress: bool) -> list[float]:
    """Set the observation statistics from ``observations`` and fit the policy to ``actions``
    by maximum likelihood (module docstring). Returns the mean loss of each epoch."""
    vecnorm = model.get_vec_normalize_env()
    vecnorm.obs_rms.mean = observations.mean(axis=0).astype(np.float64)
    vecnorm.obs_rms.var = observations.var(axis=0).astype(np.float64)
    vecnorm.obs_rms.count = float(len(observations))
    obs = torch.as_tensor(vecnorm.normalize_obs(observations), dtype=torch.float32)
    act = torch.as_tensor(actions, dtype=torch.float32)
    policy = model.policy
    policy.set_training_mode(True)
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    generator = torch.Generator().manual_seed(seed)
    losses = []
    for _ in tqdm(range(epochs), disable=not progress, file=sys.stderr, unit="epoch", desc="clone"):
        order = torch.randperm(len(obs), generator=generator)
        total = 0.0
        for start in range(0, len(obs), batch_size):
            idx = order[start:start + batch_size]
            _, log_prob, entropy = policy.evaluate_actions(obs[idx], act[idx])
            loss = -log_prob.mean() - ent_weight * (entropy.mean() if entropy is not None else 0.0)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(idx)
        losses.append(total / len(obs))
    policy.set_training_mode(False)
    return losses


def _clone(demos: dict, model_path: Path, *, hyperparams_dir: Path | str = DEFAULT_HYPERPARAMS_DIR,
           epochs: int = 50, batch_size: int = 256, learning_rate: float = 1e-3, ent_weight: float = 1e-3,
           seed: int = 0, progress: bool = False, extra: dict) -> dict:
    """Fit a policy to ``demos`` and save it as ``model_path`` with its sidecars; its metadata."""
    for name, value in (("epochs", epochs), ("batch_size", batch_size)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {value!r}")
    if not learning_rate > 0 or not ent_weight >= 0:
        raise ValueError(f"learning_rate must be > 0 and ent_weight >= 0; got {learning_rate}, {ent_weight}")
    meta = demos["meta"]
    torch.manual_seed(seed)
    model, params = _carrier(meta["env_id"], meta["env_kwargs"], hyperparams_dir, seed)
    start, cpu = time.perf_counter(), time.process_time()
    losses = _fit(model, demos["observations"], demos["actions"], epochs=epochs, batch_size=batch_size,
                  learning_rate=learning_rate, ent_weight=ent_weight, seed=seed, progress=progress)
    info = {"env_id": meta["env_id"], "algo": "ppo", "seed": seed, "env_kwargs": meta["env_kwargs"],
            "hyperparams": params, "batched": False,
            "imitation": {"method": "bc", "expert": meta["expert"], "demonstrations": meta["files"],
                          "episodes": meta["episodes"], "samples": int(len(demos["actions"])),
                          "epochs": epochs, "batch_size": batch_size, "learning_rate": learning_rate,
                          "ent_weight": ent_weight, "loss_per_epoch": losses,
                          "fit_wall_time_s": time.perf_counter() - start,
                          "fit_cpu_time_s": time.process_time() - cpu, **extra}}
    if Path(hyperparams_dir).resolve() != HYPERPARAMS_DIR:
        info["hyperparams_file"] = project_path(Path(hyperparams_dir) / "ppo.yml")
    model_path.parent.mkdir(parents=True, exist_ok=True)
    try:
        save_checkpoint(model, model_path, info)
    finally:
        model.get_env().close()
    return info


def _finish(run_dir: Path, info: dict, demos: dict) -> Path:
    """Write the run's ``summary.json`` (as :mod:`baselines.train` does, so ``baselines.results``
    collects and evaluates the run): the expert's environment steps and time count as training."""
    imitation = info["imitation"]
    write_json(run_dir / "summary.json", {
        **info, "kind": "final", "timesteps": imitation["samples"], "timesteps_done": imitation["samples"],
        "wall_time_s": demos["meta"]["wall_time_s"] + imitation.get("labels_wall_time_s", 0.0)
        + imitation["fit_wall_time_s"],
        "cpu_time_s": demos["meta"]["cpu_time_s"] + imitation.get("labels_cpu_time_s", 0.0)
        + imitation["fit_cpu_time_s"],
        "time_limit_min": None, "threads": torch.get_num_threads()})
    return run_dir / "final_model.zip"


def _check_run_dir(run_dir: Path) -> Path:
    run_dir = Path(run_dir)
    if (run_dir / "summary.json").is_file():
        raise ValueError(f"{run_dir} already holds a run; choose another --out")
    return run_dir


def behaviour_clone(demos: dict, run_dir: Path | str, *,
                    hyperparams_dir: Path | str = DEFAULT_HYPERPARAMS_DIR, epochs: int = 50,
                    batch_size: int = 256, learning_rate: float = 1e-3, ent_weight: float = 1e-3,
                    seed: int = 0, progress: bool = False) -> Path:
    """Clone the planner's actions into a PPO policy, saved as ``run_dir/final_model.zip``
    (with the ``.json`` metadata and ``_vecnormalize.json`` sidecars that ``baselines.evaluate``
    reads) and ``run_dir/summary.json`` (the run's record, as :mod:`baselines.train` writes).

    Args:
        demos: :func:`load_demonstrations` output.
        run_dir: the run folder (must not hold a run).
        hyperparams_dir: folder whose ``ppo.yml`` entry for the demos' env gives the policy
            (class, ``policy_kwargs``, ``use_sde``) and the normalisation settings.
        epochs, batch_size, learning_rate: Adam on the negative log-likelihood.
        ent_weight: weight of the entropy bonus.
        seed: seeds the policy's initial weights and the batch order.
        progress: tqdm bar on stderr.

    Returns:
        The model file.
    """
    run_dir = _check_run_dir(run_dir)
    info = _clone(demos, run_dir / "final_model.zip", hyperparams_dir=hyperparams_dir, epochs=epochs,
                  batch_size=batch_size, learning_rate=learning_rate, ent_weight=ent_weight, seed=seed,
                  progress=progress, extra={})
    return _finish(run_dir, info, demos)


def _learner(policy, vecnorm):
    """``act(obs, expert)`` of DAgger's rollouts: the learner's deterministic action (the
    expert's is only recorded)."""
    return lambda obs, expert: policy.predict(vecnorm.normalize_obs(obs), deterministic=True)[0]


def dagger(demos: dict, run_dir: Path | str, *, rounds: int = 2, episodes: int = 10, seed: int = 1000,
           progress: bool = False, **bc_kwargs) -> Path:
    """DAgger from ``demos`` (module docstring): clone, then ``rounds`` times roll the policy
    out on ``episodes`` new episodes, label its states with the planner and clone again.

    In ``run_dir``: ``round0_model.zip`` (plain BC), the labelled states of round k
    (``round<k>_labels.npz``), the policies of the rounds between, and ``final_model.zip`` (the
    last round's) with ``summary.json``. ``bc_kwargs``: the fitting arguments of
    :func:`behaviour_clone` (``hyperparams_dir``, ``epochs``, ...; ``seed`` the policy's).

    Returns:
        The final model file.
    """
    if rounds < 1 or episodes < 1:
        raise ValueError(f"rounds and episodes must be >= 1; got {rounds}, {episodes}")
    if demos["meta"]["expert"] != CEMPlanner.__name__:
        # A scripted controller keeps state over its episode (its side, its ramp): it cannot
        # label a state the learner reached.
        raise ValueError(f"DAgger labels with the planner; these demonstrations are "
                         f"{demos['meta']['expert']}'s (clone them with bc)")
    run_dir = _check_run_dir(run_dir)
    first = demos
    current = run_dir / "round0_model.zip"
    _clone(demos, current, progress=progress, extra={}, **bc_kwargs)
    history, wall, cpu_spent = [], 0.0, 0.0
    for k in range(1, rounds + 1):
        policy, _, vecnorm = load_policy(current)
        env = make_env(demos["meta"]["env_id"], demos["meta"]["env_kwargs"])
        seeds = range(seed + (k - 1) * episodes, seed + k * episodes)
        start, cpu = time.perf_counter(), time.process_time()
        try:
            labelled = _expert_rollouts(env, seeds, _learner(policy, vecnorm), progress, f"DAgger round {k}")
        finally:
            env.close()
            vecnorm.venv.close()
        wall, cpu_spent = wall + time.perf_counter() - start, cpu_spent + time.process_time() - cpu
        history.append({"round": k, "policy": current.name, "episode_seeds": [seeds.start, seeds.stop - 1],
                        "learner_success_rate": float(np.mean(labelled["success"])),
                        "learner_median_wrap_deg": float(np.median(labelled["final_wrap_deg"])),
                        "label_wall_time_s": time.perf_counter() - start})
        labelled["meta"] = {**first["meta"], "expert": CEMPlanner.__name__, "labels_for": current.name,
                            "wall_time_s": time.perf_counter() - start,
                            "cpu_time_s": time.process_time() - cpu,
                            "expert_success_rate": None, **history[-1]}
        saved = save_demonstrations(labelled, run_dir / f"round{k}_labels.npz")
        meta = demos["meta"]
        demos = {"observations": np.concatenate([demos["observations"], labelled["observations"]]),
                 "actions": np.concatenate([demos["actions"], labelled["actions"]]),
                 "episodes": np.concatenate([demos["episodes"], labelled["episodes"] + meta["episodes"]]),
                 "meta": {**meta, "files": [*meta["files"], str(saved)],
                          "episodes": meta["episodes"] + len(seeds)}}
        current = run_dir / ("final_model.zip" if k == rounds else f"round{k}_model.zip")
        info = _clone(demos, current, progress=progress,
                      extra={"method": "dagger", "rounds": history, "labels_wall_time_s": wall,
                             "labels_cpu_time_s": cpu_spent}, **bc_kwargs)
    return _finish(run_dir, info, first)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.imitate", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    col = sub.add_parser("collect", help="record demonstrations")
    col.add_argument("--env", default="SoftArm/OctArmWrap-v2")
    col.add_argument("--episodes", type=int, default=40)
    col.add_argument("--seed", type=int, default=0, help="episode i is reset with seed + i")
    col.add_argument("--env-kwargs", default=None, help="extra gym.make kwargs as a JSON object")
    col.add_argument("--out", required=True, help="the demonstration file (.npz)")
    col.add_argument("--expert", choices=sorted(EXPERTS), default="planner",
                     help="who demonstrates: the sampling planner or the scripted curl (default %(default)s)")
    for name, help_text in (("bc", "behaviour cloning"), ("dagger", "DAgger with the planner as the expert")):
        p = sub.add_parser(name, help=help_text)
        p.add_argument("--demos", nargs="+", required=True, help="demonstration files (.npz)")
        p.add_argument("--out", required=True, metavar="RUN_DIR",
                       help="the run folder: final_model.zip (with sidecars) and summary.json")
        p.add_argument("--hyperparams-dir", default=str(DEFAULT_HYPERPARAMS_DIR),
                       help="folder of the ppo.yml giving the policy (default %(default)s)")
        p.add_argument("--epochs", type=int, default=50)
        p.add_argument("--batch-size", type=int, default=256)
        p.add_argument("--learning-rate", type=float, default=1e-3)
        p.add_argument("--ent-weight", type=float, default=1e-3)
        p.add_argument("--seed", type=int, default=0 if name == "bc" else 1000,
                       help="bc: the policy's seed; dagger: first episode seed of the learner's rollouts")
        if name == "dagger":
            p.add_argument("--rounds", type=int, default=2)
            p.add_argument("--episodes", type=int, default=10, help="learner episodes per round")
    for p in sub.choices.values():
        add_numba_threads_argument(p)
        p.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1)")
        add_quiet_argument(p)
    args = parser.parse_args(argv)
    try:
        apply_numba_threads(args.numba_threads)
        torch.set_num_threads(args.threads)
        if args.command == "collect":
            env_kwargs = json.loads(args.env_kwargs) if args.env_kwargs else None
            if env_kwargs is not None and not isinstance(env_kwargs, dict):
                raise ValueError("--env-kwargs must be a JSON object")
            demos = collect(args.env, args.episodes, args.seed, env_kwargs, progress=not args.quiet,
                            expert=args.expert)
            path = save_demonstrations(demos, args.out)
            m = demos["meta"]
            print(f"{path}: {len(demos['actions'])} steps of {m['episodes']} episodes, {m['expert']} success "
                  f"{100 * m['expert_success_rate']:.0f} %, {m['wall_time_s']:.0f} s")
            return 0
        demos = load_demonstrations(args.demos)
        kwargs = dict(hyperparams_dir=args.hyperparams_dir, epochs=args.epochs, batch_size=args.batch_size,
                      learning_rate=args.learning_rate, ent_weight=args.ent_weight, progress=not args.quiet)
        if args.command == "bc":
            path = behaviour_clone(demos, args.out, seed=args.seed, **kwargs)
        else:
            path = dagger(demos, args.out, rounds=args.rounds, episodes=args.episodes, seed=args.seed,
                          **kwargs)
    except (ValueError, json.JSONDecodeError) as exc:
        print(f"baselines.imitate: error: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
