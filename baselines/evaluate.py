"""Evaluate a trained policy or a model-based controller, optionally with an estimator in the loop.

Usage::

    python -m baselines.evaluate --model baselines/trained/sac_OctArmReach-v1.zip --episodes 100 --json
    python -m baselines.evaluate --model FILE.zip --observation cable_encoder --sensor-noise thesis \\
        --payload-kg 0,0.5 --json
    python -m baselines.evaluate --controller jacobian --env SoftArm/OctArmReach-v1 --json
    python -m baselines.evaluate --controller planner --env SoftArm/OctArmWrap-v1 --episodes 20 --json

Models load safely (:func:`baselines.config.load_policy`): only the weights of the zip, read
with ``torch.load(weights_only=True)``, into a policy rebuilt from the JSON metadata, and JSON
normalisation statistics — a crafted model file cannot run code. ``--trust-pickle`` loads
the zip with SB3's ``ALGO.load`` and a legacy ``_vecnormalize.pkl`` instead: both unpickle
Python objects, which can run arbitrary code, so use it only for files you made yourself
(or convert those once with ``python -m baselines.convert``).

The policy is rolled out deterministically for whole episodes (``max_episode_steps``);
episode ``i`` is reset with seed ``seed + i``, so every policy and estimator sees the same
targets (or discs). Only the observation changes with ``--observation``: the success, the final
error and the reward always use the true arm. Reported (JSON keys):

* ``success_rate`` — fraction of episodes that succeed at the *last* step (``info["is_success"]``:
  reach, the true tip within the env's ``success_tolerance`` of the target; wrap, a wrap angle
  of at least ``success_wrap_deg`` with penetration within tolerance);
* reach and track: ``median_final_error_m``, ``p95_final_error_m``, ``mean_final_error_m`` —
  final |tip − target|; track also ``median_tracking_rms_m``, ``median_tracking_max_m`` — the
  median over episodes of each episode's RMS and largest tracking error (true tip, every step;
  ``info["tracking_rms_m"]``, ``info["tracking_max_m"]``); obstacle reach also
  ``contact_rate`` — fraction of episodes whose arm touched a disc at any step
  (``info["in_contact"]``); wrap: ``median_wrap_angle_deg``, ``p5_wrap_angle_deg``,
  ``mean_wrap_angle_deg`` — the final wrap angle (deg; :func:`softarm_gym.envs.wrap.wrap_angle`);
* ``reached_rate`` — fraction that succeeded at any step;
  ``median_steps_to_success``, ``p95_steps_to_success`` — first successful step, over
  those episodes (null if none);
* ``mean_estimation_error_m`` — mean |estimated − true tip| over all steps;
* ``mean_return``, ``solver_failures`` (unconverged steps in total), ``wall_time_s``.

Controllers (``--controller``): ``jacobian`` (:class:`~softarm_gym.controllers.JacobianController`,
reach), ``planner`` (:class:`~softarm_gym.controllers.CEMPlanner` with its defaults, seeded
with the episode's seed in every episode, as ``softarm_gym.benchmarks.planner`` runs it) and
``curl`` (:class:`~softarm_gym.controllers.CurlController`, the scripted wrap and grasp).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from baselines.config import check_model_env, load_policy, make_env
from softarm_gym.commands.common import (
    add_numba_threads_argument,
    add_output_argument,
    add_quiet_argument,
    apply_numba_threads,
)
from softarm_gym.controllers import CEMPlanner, CurlController, JacobianController
from softarm_gym.files import json_text, write_json
from softarm_gym.sensing import ESTIMATORS

__all__ = ["evaluate", "rollouts", "summarize", "main", "CONTROLLERS"]

CONTROLLERS = ("jacobian", "planner", "curl")


def rollouts(env, act, reset, episodes: int, seed: int = 0, progress: bool = False) -> dict[str, np.ndarray]:
    """Run ``episodes`` whole episodes and record per-episode outcomes.

    Args:
        env: a reach, track or wrap environment (``gym.make``, with its time limit).
        act: observation → action.
        reset: called with no arguments before each episode (forget controller state).
        episodes: number of episodes (>= 1).
        seed: episode ``i`` is reset with ``seed + i``.
        progress: tqdm bar on stderr.

    Returns:
        Arrays of length ``episodes``: ``final_error`` (m; NaN on wrap, which has no target),
        ``final_wrap_deg`` (deg; NaN but on wrap), ``tracking_rms`` and ``tracking_max`` (m, the
        episode's RMS and largest tracking error; NaN but on track), ``contact`` (1.0 if the arm
        touched a disc at any step, else 0.0; NaN on envs without obstacles), ``success`` (bool),
        ``steps_to_success`` (first successful step, −1 if never), ``estimation_error`` (m, mean over steps),
        ``episode_return``, ``solver_failures`` (unconverged steps).
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1; got {episodes}")
    final_error = np.full(episodes, np.nan)
    final_wrap = np.full(episodes, np.nan)
    tracking_rms = np.full(episodes, np.nan)
    tracking_max = np.full(episodes, np.nan)
    contact = np.full(episodes, np.nan)
    success = np.zeros(episodes, dtype=bool)
    steps_to_success = np.full(episodes, -1)
    estimation_error = np.empty(episodes)
    episode_return = np.empty(episodes)
    failures = np.zeros(episodes, dtype=int)
    for i in tqdm(range(episodes), disable=not progress, file=sys.stderr, unit="episode"):
        obs, info = env.reset(seed=seed + i)
        reset()
        total, est, steps = 0.0, 0.0, 0
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(act(obs))
            steps += 1
            total += float(reward)
            est += info["estimation_error"]
            failures[i] += not info["converged"]
            if "in_contact" in info:
                contact[i] = max(0.0 if np.isnan(contact[i]) else contact[i], float(info["in_contact"]))
            if info["is_success"] and steps_to_success[i] < 0:
                steps_to_success[i] = steps
            done = terminated or truncated
        final_error[i] = info.get("distance", np.nan)
        final_wrap[i] = info.get("wrap_angle_deg", np.nan)
        tracking_rms[i] = info.get("tracking_rms_m", np.nan)
        tracking_max[i] = info.get("tracking_max_m", np.nan)
        success[i] = info["is_success"]
        estimation_error[i] = est / steps
        episode_return[i] = total
    return {"final_error": final_error, "final_wrap_deg": final_wrap, "tracking_rms": tracking_rms,
            "tracking_max": tracking_max, "contact": contact, "success": success,
            "steps_to_success": steps_to_success, "estimation_error": estimation_error,
            "episode_return": episode_return, "solver_failures": failures}


def summarize(record: dict[str, np.ndarray]) -> dict:
    """The scalar metrics of :func:`rollouts` output (module docstring): the final-error keys
    for a task with a target, the wrap-angle keys for wrap (``final_wrap_deg`` not NaN), and the
    tracking-error keys on track and ``contact_rate`` on obstacle reach (their records not NaN)."""
    reached = record["steps_to_success"][record["steps_to_success"] >= 0]
    n = int(record["success"].size)
    wrap = record.get("final_wrap_deg")
    if wrap is not None and not np.any(np.isnan(wrap)):
        measures = {"median_wrap_angle_deg": float(np.median(wrap)),
                    "p5_wrap_angle_deg": float(np.percentile(wrap, 5)),
                    "mean_wrap_angle_deg": float(np.mean(wrap))}
    else:
        err = record["final_error"]
        measures = {"median_final_error_m": float(np.median(err)),
                    "p95_final_error_m": float(np.percentile(err, 95)),
                    "mean_final_error_m": float(np.mean(err))}
    rms, largest = record.get("tracking_rms"), record.get("tracking_max")
    if rms is not None and largest is not None and not np.any(np.isnan(rms)):  # track
        measures.update(median_tracking_rms_m=float(np.median(rms)),
                        median_tracking_max_m=float(np.median(largest)))
    contact = record.get("contact")
    if contact is not None and not np.any(np.isnan(contact)):  # obstacle reach
        measures["contact_rate"] = float(np.mean(contact))
    return {
        "episodes": n,
        "success_rate": float(np.mean(record["success"])),
        **measures,
        "reached_rate": float(reached.size / n),
        "median_steps_to_success": float(np.median(reached)) if reached.size else None,
        "p95_steps_to_success": float(np.percentile(reached, 95)) if reached.size else None,
        "mean_estimation_error_m": float(np.mean(record["estimation_error"])),
        "mean_return": float(np.mean(record["episode_return"])),
        "solver_failures": int(np.sum(record["solver_failures"])),
    }


def _payload(text: str | None):
    if text is None:
        return None
    parts = [p for p in text.split(",") if p.strip()]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"--payload-kg must be a number or LOW,HIGH (kg); got {text!r}") from None
    if len(values) == 1:
        return values[0]
    if len(values) == 2:
        return tuple(values)
    raise ValueError(f"--payload-kg must be a number or LOW,HIGH (kg); got {text!r}")


def evaluate(*, model: str | Path | None = None, controller: str | None = None, env_id: str | None = None,
             observation: str = "true", sensor_noise: str = "off", payload_kg=None,
             env_kwargs: dict | None = None, episodes: int = 100, seed: int = 0,
             progress: bool = False, trust_pickle: bool = False, force: bool = False) -> dict:
    """Evaluate a saved model or a controller; returns the :func:`summarize` metrics plus the setup.

    Args:
        model: a ``.zip`` written by :mod:`baselines.train` (with its ``.json`` sidecar).
        controller: instead of ``model``, one of :data:`CONTROLLERS`.
        env_id: environment id; default the model's training env (required for a controller).
        observation: shape estimator of the observations, one of ``ESTIMATORS``.
        sensor_noise: ``"off"`` or ``"thesis"``.
        payload_kg: tip payload (kg) or (low, high) drawn per episode; default the env's.
        env_kwargs: extra ``gym.make`` kwargs, applied over the model's training kwargs.
        episodes: episodes to run.
        seed: episode ``i`` uses seed ``seed + i``.
        progress: tqdm bar on stderr.
        trust_pickle: load ``model`` with SB3's pickle-based loader (module docstring).
        force: evaluate ``model`` even on an env whose action semantics, spaces or action
            wrapper differ from its training env's (:func:`baselines.config.check_model_env`);
            the differences are then listed in the result's ``model_env_differences``.

    Raises:
        ValueError: bad or conflicting arguments, or an unreadable or unsafe model.
    """
    if (model is None) == (controller is None):
        raise ValueError("give exactly one of --model and --controller")
    if observation not in ESTIMATORS:
        raise ValueError(f"unknown observation {observation!r}; choose one of {', '.join(ESTIMATORS)}")
    if sensor_noise not in ("off", "thesis"):
        raise ValueError(f"sensor_noise must be 'off' or 'thesis'; got {sensor_noise!r}")
    kwargs = {}
    if model is not None:
        policy, meta, vecnorm = load_policy(model, trust_pickle=trust_pickle)
        env_id = env_id or meta["env_id"]
        kwargs.update(meta.get("env_kwargs", {}))
        agent = f"{meta['algo']}:{Path(model).name}"
    else:
        if controller not in CONTROLLERS:
            raise ValueError(f"unknown controller {controller!r}; choose one of {', '.join(CONTROLLERS)}")
        if env_id is None:
            raise ValueError("--env is required with --controller")
        agent = controller
    kwargs.update(env_kwargs or {})
    kwargs.update(observation=observation, sensor_noise=sensor_noise)
    if payload_kg is not None:
        kwargs["payload_kg"] = payload_kg
    env = make_env(env_id, kwargs)
    differences = []
    if model is not None:
        try:
            differences = check_model_env(meta, env, env_id, force=force)
        except ValueError:
            env.close()
            raise

        def act(obs):
            if vecnorm is not None:
                obs = vecnorm.normalize_obs(obs)
            return policy.predict(obs, deterministic=True)[0]

        def reset():
            return None
    elif controller in ("jacobian", "curl"):
        ctrl = JacobianController(env) if controller == "jacobian" else CurlController(env)
        act, reset = ctrl.act, ctrl.reset
    else:
        act, reset = _seeded_planner(env, seed)
    start = time.perf_counter()
    record = rollouts(env, act, reset, episodes, seed, progress)
    wall = time.perf_counter() - start
    env.close()
    base = env.unwrapped
    criterion = ({"success_wrap_deg": float(base.success_wrap_deg)} if hasattr(base, "success_wrap_deg")
                 else {"success_tolerance_m": float(base.success_tolerance)})
    return {"agent": agent, "env_id": env_id, "observation": observation, "sensor_noise": sensor_noise,
            "payload_kg": list(base.payload_range), "seed": seed, **criterion,
            **summarize(record), "wall_time_s": wall,
            **({"model_env_differences": differences} if differences else {})}


def _seeded_planner(env, seed: int):
    """(act, reset) of a :class:`CEMPlanner` made afresh at every episode start, the one of
    episode i seeded with ``seed + i`` (the seed of the episode's reset)."""
    episode_seed = itertools.count(seed)
    planner = []

    def reset():
        planner[:] = [CEMPlanner(env, seed=next(episode_seed))]

    return (lambda obs: planner[0].act(obs)), reset


def _text(result: dict) -> str:
    steps = result["median_steps_to_success"]
    if "median_wrap_angle_deg" in result:
        criterion = f"wrap ≥ {result['success_wrap_deg']:.0f}°"
        measure = (f"  final wrap angle median {result['median_wrap_angle_deg']:.0f}°, 5th percentile "
                   f"{result['p5_wrap_angle_deg']:.0f}°\n")
    else:
        criterion = f"tolerance {1000 * result['success_tolerance_m']:.0f} mm"
        measure = (f"  final error median {1000 * result['median_final_error_m']:.1f} mm, 95th percentile "
                   f"{1000 * result['p95_final_error_m']:.1f} mm\n")
    return (f"{result['agent']} on {result['env_id']} (obs={result['observation']}, noise="
            f"{result['sensor_noise']}, payload={result['payload_kg']} kg), {result['episodes']} episodes:\n"
            f"  success rate {100 * result['success_rate']:.1f} % ({criterion})\n"
            + measure +
            f"  steps to success median {steps if steps is not None else '-'}\n"
            f"  mean estimation error {1000 * result['mean_estimation_error_m']:.1f} mm")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.evaluate", description=__doc__.splitlines()[0])
    who = parser.add_mutually_exclusive_group(required=True)
    who.add_argument("--model", help="a .zip saved by baselines.train")
    who.add_argument("--controller", choices=CONTROLLERS, help="a model-based controller instead")
    parser.add_argument("--env", default=None, help="environment id (default: the model's)")
    parser.add_argument("--observation", default="true", choices=ESTIMATORS)
    parser.add_argument("--sensor-noise", default="off", choices=("off", "thesis"))
    parser.add_argument("--payload-kg", default=None, help="payload (kg) or LOW,HIGH drawn per episode")
    parser.add_argument("--env-kwargs", default=None, help="extra gym.make kwargs as a JSON object")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    add_output_argument(parser, old=("--out",))
    add_quiet_argument(parser)
    add_numba_threads_argument(parser)
    parser.add_argument("--force", action="store_true",
                        help="evaluate a model on an env whose actions or observations differ from its "
                             "training env's (refused otherwise)")
    parser.add_argument("--trust-pickle", action="store_true",
                        help="load the model with SB3's pickle-based loader; pickles can run arbitrary "
                             "code, so only for files you made yourself")
    args = parser.parse_args(argv)
    try:
        apply_numba_threads(args.numba_threads)
        env_kwargs = json.loads(args.env_kwargs) if args.env_kwargs else None
        if env_kwargs is not None and not isinstance(env_kwargs, dict):
            raise ValueError("--env-kwargs must be a JSON object")
        result = evaluate(model=args.model, controller=args.controller, env_id=args.env,
                          observation=args.observation, sensor_noise=args.sensor_noise,
                          payload_kg=_payload(args.payload_kg), env_kwargs=env_kwargs,
                          episodes=args.episodes, seed=args.seed, progress=not args.quiet,
                          trust_pickle=args.trust_pickle, force=args.force)
    except (ValueError, json.JSONDecodeError) as exc:
        print(f"baselines.evaluate: error: {exc}", file=sys.stderr)
        return 2
    if args.output:
        Path(args.output).parent.mkdir(parents=True, exist_ok=True)
        write_json(args.output, result)
    print(json_text(result) if args.json else _text(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
