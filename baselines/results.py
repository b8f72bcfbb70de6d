"""Collect training runs, run the evaluation grid, and regenerate ``baselines/RESULTS.md``.

    python -m baselines.results collect  --runs runs            # runs/* → baselines/results/training
    python -m baselines.results evaluate --runs runs --workers 2  # → baselines/results/eval/*.json
    python -m baselines.results ship     --runs runs            # best policy per env → baselines/trained
    python -m baselines.results report                          # RESULTS.md + plots from saved files

``report`` reads only the small files under ``baselines/results/`` (summaries, learning-curve
CSVs, evaluation JSONs), so the document and its plots can be regenerated without the
(gitignored) run folders. The evaluation grid, for every trained policy (its
``best_model.zip``) and the Jacobian controller on each reach environment:

* ``main`` — true observations, no sensor noise, no payload, :data:`MAIN_EPISODES` episodes;
* estimator-in-the-loop — every estimator × :data:`CONDITIONS` (``clean``: no noise, no
  payload; ``noisy``: the thesis's Table 4.3 sensor resolutions; ``noisy+payload``: the same
  plus a tip payload drawn per episode from :data:`PAYLOAD_RANGE_KG`, unknown to the agent and
  to the ``model`` estimator), :data:`GRID_EPISODES` episodes each; not for agents trained on
  the goal format (``sac_her``), which see the true tip as ``achieved_goal``: the goal format
  refuses estimators.

Episode ``i`` of every cell is reset with seed ``i``, so all agents face the same targets.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from baselines.config import ALGOS, registered_equivalent, sidecar_paths
from baselines.evaluate import evaluate
from softarm_gym.files import write_json
from softarm_gym.sensing import ESTIMATORS

__all__ = ["collect", "evaluation_jobs", "run_evaluation_job", "run_evaluations", "ship", "report",
           "training_observation", "DEFINITIONS", "main"]

PACKAGE_DIR = Path(__file__).resolve().parent
RESULTS_DIR = PACKAGE_DIR / "results"
TRAINED_DIR = PACKAGE_DIR / "trained"
ENV_IDS = ("SoftArm/OctArmReach-v0", "SoftArm/CTReach-v0")
MAIN_EPISODES = 100
GRID_EPISODES = 20
PAYLOAD_RANGE_KG = (0.0, 0.25)
CONDITIONS = {"clean": ("off", None), "noisy": ("thesis", None),
              "noisy+payload": ("thesis", PAYLOAD_RANGE_KG)}
"""Condition name → (sensor noise, payload range or None for the env's default of 0)."""
TARGETS = (("SoftArm/OctArmReach-v0", "sac", 0.90), ("SoftArm/OctArmReach-v0", "jacobian", 0.99))
"""(env, agent name prefix, success rate) targets of the issue, checked in the report."""
DEFINITIONS = ("Success = final true tip within the env's tolerance "
               "(2 cm) after the 100-step episode; errors are final |true tip − target|; steps to "
               "success = first step within tolerance, over the episodes that got there. "
               "Policies are each run's `best_model.zip` (best periodic evaluation return during "
               "training), acting deterministically; episode i of every evaluation uses seed i.")
"""What the report's numbers mean (part of its introduction)."""


def _runs(runs_dir: Path) -> list[Path]:
    return sorted(p.parent for p in Path(runs_dir).glob("*/summary.json"))


def collect(runs_dir: Path | str, results_dir: Path | str = RESULTS_DIR) -> list[str]:
    """Copy each finished run's summary and learning curves into ``results_dir/training/<run>/``.

    Writes ``summary.json``, ``monitor.csv`` (training episodes of all env copies, sorted by
    wall time, with a ``timesteps`` column) and ``evaluations.csv`` (periodic evaluations:
    timesteps, success rate, mean return, episodes per evaluation). Returns the run names.
    """
    names = []
    for run in _runs(Path(runs_dir)):
        out = Path(results_dir) / "training" / run.name
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy(run / "summary.json", out / "summary.json")
        frames = [pd.read_csv(f, skiprows=1) for f in sorted(run.glob("*monitor.csv"))]
        if frames:
            episodes = pd.concat(frames).sort_values("t").reset_index(drop=True)
            episodes["timesteps"] = episodes["l"].cumsum()
            episodes.to_csv(out / "monitor.csv", index=False, float_format="%.6g")
        if (run / "evaluations.npz").is_file():
            data = np.load(run / "evaluations.npz")
            table = pd.DataFrame({"timesteps": data["timesteps"],
                                  "success_rate": data["successes"].mean(axis=1),
                                  "mean_return": data["results"].mean(axis=1),
                                  "episodes": data["results"].shape[1]})
            table.to_csv(out / "evaluations.csv", index=False, float_format="%.6g")
        names.append(run.name)
    return names


def evaluation_jobs(runs_dir: Path | str, results_dir: Path | str = RESULTS_DIR, *, grid: bool = True,
                    env_ids=ENV_IDS, episodes: int | None = None) -> list[tuple[Path, dict]]:
    """(output JSON path, :func:`baselines.evaluate.evaluate` kwargs) of every grid cell not yet done.

    Args:
        runs_dir: folder of run folders; each one with a ``best_model.zip`` is an agent.
        results_dir: the cells go to ``results_dir/eval/<agent>__<cell>.json``.
        grid: the estimator-in-the-loop cells too, not only ``main`` (never for agents
            trained on the goal format, whose observation has no estimator blocks to swap).
        env_ids: environments the Jacobian controller is evaluated on, as a reference.
        episodes: episodes of every cell (default :data:`MAIN_EPISODES` for ``main``,
            :data:`GRID_EPISODES` for the others).
    """
    agents = [(run.name, {"model": run / "best_model.zip"}, _goal_format(run))
              for run in _runs(Path(runs_dir)) if (run / "best_model.zip").is_file()]
    agents += [(f"jacobian_{env_id.split('/')[-1]}", {"controller": "jacobian", "env_id": env_id}, False)
               for env_id in env_ids]
    jobs = []
    out_dir = Path(results_dir) / "eval"
    for name, who, goal_format in agents:
        cells = [("main", {"episodes": episodes or MAIN_EPISODES})]
        for observation in ESTIMATORS if grid and not goal_format else ():
            for condition, (noise, payload) in CONDITIONS.items():
                cells.append((f"{observation}__{condition}",
                              {"episodes": episodes or GRID_EPISODES, "observation": observation,
                               "sensor_noise": noise, "payload_kg": payload}))
        for cell, kwargs in cells:
            path = out_dir / f"{name}__{cell}.json"
            if not path.is_file():
                jobs.append((path, {**who, **kwargs, "seed": 0}))
    return jobs


def _goal_format(run: Path) -> bool:
    """Whether the run trained on ``observation_format="goal"`` (its best model's metadata)."""
    meta = json.loads(sidecar_paths(run / "best_model.zip")[0].read_text())
    return meta.get("env_kwargs", {}).get("observation_format") == "goal"


def run_evaluation_job(job: tuple[Path, dict]) -> str:
    """Evaluate one cell of :func:`evaluation_jobs` (one torch thread) and write its JSON; its name."""
    import torch

    torch.set_num_threads(1)
    path, kwargs = job
    result = evaluate(**kwargs)
    result["cell"] = path.stem.split("__", 1)[1]
    result["agent_name"] = path.stem.split("__", 1)[0]
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, result)
    return path.name


def run_evaluations(runs_dir: Path | str, results_dir: Path | str = RESULTS_DIR, workers: int = 1,
                    only: str | None = None) -> int:
    """Run the missing grid cells (optionally only agents whose name contains ``only``)."""
    from tqdm import tqdm

    jobs = [j for j in evaluation_jobs(runs_dir, results_dir) if only is None or only in j[0].name]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for _ in tqdm(pool.map(run_evaluation_job, jobs), total=len(jobs), file=sys.stderr, unit="cell"):
            pass
    return len(jobs)


def _load_evaluations(results_dir: Path) -> pd.DataFrame:
    rows = [json.loads(p.read_text()) for p in sorted((results_dir / "eval").glob("*.json"))]
    return pd.DataFrame(rows)


def ship(runs_dir: Path | str, results_dir: Path | str = RESULTS_DIR,
         trained_dir: Path | str = TRAINED_DIR) -> list[Path]:
    """Copy the best trained policy per environment (highest main success rate, then lowest
    median error) with its sidecars into ``trained_dir`` as ``<algo>_<env>.zip``."""
    table = _load_evaluations(Path(results_dir))
    main_rows = table[(table["cell"] == "main") & ~table["agent_name"].str.startswith("jacobian")]
    shipped = []
    for _, rows in main_rows.groupby("env_id"):
        best = rows.sort_values(["success_rate", "median_final_error_m"], ascending=[False, True]).iloc[0]
        src = Path(runs_dir) / best["agent_name"] / "best_model.zip"
        algo = best["agent"].split(":")[0]
        meta = json.loads(sidecar_paths(src)[0].read_text())
        ship_id, ship_kwargs = registered_equivalent(meta["env_id"], meta.get("env_kwargs", {}))
        dst = Path(trained_dir) / f"{algo}_{ship_id.split('/')[-1]}.zip"
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(src, dst)
        for a, b in zip(sidecar_paths(src), sidecar_paths(dst)):
            if a.is_file():
                shutil.copy(a, b)
        write_json(sidecar_paths(dst)[0], shipped_metadata(meta, best["agent_name"], ship_id, ship_kwargs))
        shipped.append(dst)
    return shipped


def shipped_metadata(meta: dict, selected_from: str, env_id: str, env_kwargs: dict) -> dict:
    """A run's metadata for its shipped copy: ``env_id``/``env_kwargs`` become the registered
    equivalent (:func:`baselines.config.registered_equivalent`), so the model runs on
    ``gym.make(env_id)``; what it was trained on stays in ``trained_on``."""
    out = dict(meta, selected_from=selected_from, env_id=env_id, env_kwargs=env_kwargs)
    if env_id != meta["env_id"]:
        out["trained_on"] = {"env_id": meta["env_id"], "env_kwargs": meta.get("env_kwargs", {})}
    return out


def _mm(x) -> str:
    return "–" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{1000 * x:.1f}"


def _steps(x) -> str:
    return "–" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.0f}"


def _episodes(counts) -> str:
    """``"20 episodes"``, ``"1 episode"``, or ``"2–20 episodes"`` when the counts differ."""
    counts = sorted({int(v) for v in counts if not pd.isna(v)})
    if len(counts) > 1:
        return f"{counts[0]}–{counts[-1]} episodes"
    return f"{counts[0]} episode{'s' if counts[0] != 1 else ''}"


def training_observation(summary: dict) -> str:
    """The shape estimator a run was trained with (its ``env_kwargs``; the env default is ``true``)."""
    return summary.get("env_kwargs", {}).get("observation", "true")


def _env_ids(runs: list[dict], table: pd.DataFrame | None = None) -> list[str]:
    """The environments of the runs (and of the evaluations in ``table``), :data:`ENV_IDS` first."""
    used = {r["env_id"] for r in runs} | (set(table["env_id"]) if table is not None and len(table) else set())
    return [e for e in ENV_IDS if e in used] + sorted(used - set(ENV_IDS))


def _learning_curves(results_dir: Path, runs: list[dict], path: Path) -> None:
    from softarm_gym.plotting import figure, save

    env_ids = _env_ids(runs)
    fig, axes = figure(1, len(env_ids), figsize=(5.5 * len(env_ids), 3.8), squeeze=False)
    for ax, env_id in zip(axes[0], env_ids):
        for summary in runs:
            if summary["env_id"] != env_id:
                continue
            folder = results_dir / "training" / summary["run"]
            observation = training_observation(summary)
            label = f"{summary['algo']} seed {summary['seed']}" + \
                ("" if observation == "true" else f", {observation} obs.")
            if (folder / "monitor.csv").is_file():
                episodes = pd.read_csv(folder / "monitor.csv")
                window = max(1, min(50, len(episodes) // 5))
                rolling = episodes["is_success"].astype(float).rolling(window, min_periods=window).mean()
                line, = ax.plot(episodes["timesteps"], 100 * rolling, lw=1, alpha=0.8,
                                label=f"{label} (training episodes, {window}-ep. mean)")
                color = line.get_color()
            else:
                color = None
            if (folder / "evaluations.csv").is_file():
                evals = pd.read_csv(folder / "evaluations.csv")
                ax.plot(evals["timesteps"], 100 * evals["success_rate"], "o--", ms=3, color=color,
                        label=f"{label} (deterministic eval)")
        ax.set_title(env_id)
        ax.set_xscale("log")
        ax.set_xlabel("environment steps (log scale)")
        ax.set_ylabel("final-step success rate (%)")
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    save(fig, path)


def report(results_dir: Path | str = RESULTS_DIR, out: Path | str = PACKAGE_DIR / "RESULTS.md", *,
           title: str = "Baseline results", intro: list[str] | None = None) -> str:
    """Write ``out`` (and ``results_dir/learning_curves.png``) from the saved results; return the text.

    Args:
        results_dir: what :func:`collect` and the evaluations wrote.
        out: the Markdown file.
        title: its heading.
        intro: Markdown lines after the heading (default: how the shipped baselines were made;
            other callers say how their runs were made, and include :data:`DEFINITIONS`).
    """
    results_dir = Path(results_dir)
    runs = []
    for f in sorted((results_dir / "training").glob("*/summary.json")):
        summary = json.loads(f.read_text())
        summary["run"] = f.parent.name
        runs.append(summary)
    table = _load_evaluations(results_dir)
    if runs:
        _learning_curves(results_dir, runs, results_dir / "learning_curves.png")
    lines = [f"# {title}", ""]
    lines += intro if intro is not None else [
             "Regenerated by `python -m baselines.results report` from the files under "
             "`baselines/results/`; every number below was measured on the project's 2-core machine "
             "(the CPU time of each run is given next to its wall time: the first runs shared the "
             "machine with other jobs). " + DEFINITIONS, "",
             "Agents: SAC (and TD3/PPO where listed) with the settings of `baselines/hyperparams/<algo>.yml` "
             "(delta pressure actions of at most 10 % of p_max per step, VecNormalize on observations, "
             "128×128 MLPs, one torch thread). The SAC seeds are trained for a fixed "
             "150,000 steps each (`--timesteps 150000`), so they differ only by seed; PPO and TD3 "
             "had a wall-clock budget (`--time-limit-min`, the budget column), so the steps they "
             "got depend on how busy the machine was. `jacobian_*` is "
             "`softarm_gym.controllers.JacobianController` on the registered env (absolute actions): "
             "box-constrained damped least squares on the nominal model's finite-difference "
             "Jacobian, fed the same observation vector (estimated tip, commanded pressures, goal); "
             "it assumes no payload and never sees the true tip. `sac_her_*` is SAC with hindsight "
             "experience replay (`baselines/hyperparams/sac_her.yml`: the same SAC settings, "
             "`observation_format=\"goal\"`, 4 relabelled goals per transition from later in the "
             "episode, `copy_info_dict` keeps the infos its `compute_reward` needs); it sees the true "
             "tip as `achieved_goal`, so it is evaluated on true observations only (no estimator grid). "
             "Algorithms without a row here are configured in "
             "`baselines/hyperparams/` and smoke-tested, but were not trained (machine time).", "",
             "Produced with: `python -m baselines.train --env ID --algo sac --seed S --timesteps 150000` "
             "per run (runs in `runs/`, two at a time), then `python -m baselines.results collect`, "
             "`python -m baselines.results evaluate --workers W`, `python -m baselines.results ship` "
             "(best policy per env → `baselines/trained/`) and `python -m baselines.results report`. "
             "SAC+HER: `python -m baselines.train --env SoftArm/OctArmReach-v0 --algo sac_her --seed 0` "
             "(the YAML's 100,000 steps), collected and evaluated the same way "
             "(`evaluate --only sac_her`).", ""]
    by_run = {r["run"]: r for r in runs}
    if len(table):  # the observation mode each agent was trained on (the controller: true)
        table["trained_on"] = [training_observation(by_run[name]) if name in by_run else "true"
                               for name in table["agent_name"]]

    def kind(name: str) -> str:  # the algorithm of a run (sac_her is not sac), else the name's prefix
        return by_run[name]["algo"] if name in by_run else name.split("_")[0]

    main = table[table["cell"] == "main"] if len(table) else table
    lines += ["## Reach with true observations", "",
              f"{_episodes(main['episodes'])} each, no sensor noise, no payload." if len(main)
              else "No agent has been evaluated yet.", "",
              "| env | agent | budget (min) | train steps | train wall (min) | train CPU (min) | success "
              "| median err (mm) | p95 err (mm) | median steps to success |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for env_id in _env_ids(runs, table):
        rows = main[main["env_id"] == env_id] if len(main) else main
        if not len(rows):
            continue
        for _, row in rows.sort_values("agent_name").iterrows():
            run = by_run.get(row["agent_name"])
            steps = f"{run['timesteps_done']:,}" if run else "–"
            wall = f"{run['wall_time_s'] / 60:.1f}" if run else "–"
            cpu = f"{run['cpu_time_s'] / 60:.1f}" if run and "cpu_time_s" in run else "–"
            budget = f"{run['time_limit_min']:g}" if run and run.get("time_limit_min") else "–"
            lines.append(f"| {env_id} | {row['agent_name']} | {budget} | {steps} | {wall} | {cpu} | "
                         f"{100 * row['success_rate']:.0f} % | {_mm(row['median_final_error_m'])} | "
                         f"{_mm(row['p95_final_error_m'])} | {_steps(row['median_steps_to_success'])} |")
        for algo in ALGOS:
            for observation in ESTIMATORS:
                learned = rows[(rows["agent_name"].map(kind) == algo)
                               & (rows["trained_on"] == observation)]
                if len(learned) < 2:
                    continue
                rates = 100 * learned["success_rate"]
                which = algo if observation == "true" else f"{algo} on {observation} observations"
                lines.append(f"| {env_id} | **{which} mean ± std over {len(learned)} seeds** | | | | | "
                             f"**{rates.mean():.0f} ± {rates.std():.0f} %** | "
                             f"{_mm(learned['median_final_error_m'].mean())} | "
                             f"{_mm(learned['p95_final_error_m'].mean())} | |")
    lines += ["", "Targets of the issue, as measured:", ""]
    for env_id, agent, goal in TARGETS:  # the targets are for policies trained on true observations
        rows = main[(main["env_id"] == env_id) & (main["agent_name"].map(kind) == agent)
                    & (main["trained_on"] == "true")] if len(main) else main
        if len(rows):
            best = rows["success_rate"].max()
            lines.append(f"* {agent} on {env_id}: best {100 * best:.0f} % against the target "
                         f"{100 * goal:.0f} % — {'met' if best >= goal else 'NOT met'} "
                         f"({len(rows)} run{'s' if len(rows) > 1 else ''} of {_episodes(rows['episodes'])}).")
    curves = [pd.read_csv(f) for f in sorted((results_dir / "training").glob("*/evaluations.csv"))]
    per_eval = _episodes(pd.concat([c["episodes"] for c in curves if "episodes" in c])) \
        if any("episodes" in c for c in curves) else None
    picture = Path(os.path.relpath(results_dir.resolve() / "learning_curves.png", Path(out).resolve().parent))
    lines += ["", "Learning curves (final-step success of training episodes, rolling mean; dots: the "
              "periodic deterministic evaluations" + (f", {per_eval}" if per_eval else "") + "):",
              "", f"![learning curves]({picture.as_posix()})", ""]
    grid = table[table["cell"] != "main"] if len(table) else table
    lines += _estimator_section(grid, _env_ids(runs, table))
    text = "\n".join(lines) + "\n"
    Path(out).write_text(text)
    return text


def _estimator_section(grid: pd.DataFrame, env_ids: list[str]) -> list[str]:
    """The estimator-in-the-loop tables (nothing if no grid cell was evaluated)."""
    if not len(grid):
        return []
    lines = ["## Estimator in the loop", "",
              f"{_episodes(grid['episodes'])} per cell; cells give success rate / median final error (mm). "
              "`clean`: perfect sensors, no payload; `noisy`: Table 4.3 sensor resolutions "
              "(encoder 3 cm, inclinometer 2.5°, load cell); `noisy+payload`: the same plus a tip "
              f"payload drawn per episode uniformly in {PAYLOAD_RANGE_KG[0]}–{PAYLOAD_RANGE_KG[1]} kg, "
              "unknown to the agents and to the estimators. The last column is the mean estimation "
              "error of the tip (mm) for that estimator and condition, averaged over agents.", ""]
    for env_id in env_ids:
        rows = grid[grid["env_id"] == env_id]
        if not len(rows):
            continue
        agents = sorted(rows["agent_name"].unique())
        lines += [f"### {env_id}", "", "| estimator | condition | " + " | ".join(agents) +
                  " | tip est. err (mm) |", "|---|---|" + "---|" * (len(agents) + 1)]
        for observation in ESTIMATORS:
            for condition in CONDITIONS:
                cell = rows[rows["cell"] == f"{observation}__{condition}"]
                if not len(cell):
                    continue
                values = []
                for agent in agents:
                    hit = cell[cell["agent_name"] == agent]
                    values.append("–" if not len(hit) else
                                  f"{100 * hit['success_rate'].iloc[0]:.0f} % / "
                                  f"{_mm(hit['median_final_error_m'].iloc[0])}")
                lines.append(f"| {observation} | {condition} | " + " | ".join(values) +
                             f" | {_mm(cell['mean_estimation_error_m'].mean())} |")
        lines.append("")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.results", description=__doc__.splitlines()[0])
    parser.add_argument("step", choices=("collect", "evaluate", "ship", "report"))
    parser.add_argument("--runs", default="runs", help="folder of the training runs (default %(default)s)")
    parser.add_argument("--results", default=str(RESULTS_DIR))
    parser.add_argument("--workers", type=int, default=1, help="parallel evaluation processes")
    parser.add_argument("--only", default=None, help="evaluate only agents whose name contains this")
    args = parser.parse_args(argv)
    if args.step == "collect":
        print("\n".join(collect(args.runs, args.results)))
    elif args.step == "evaluate":
        print(f"{run_evaluations(args.runs, args.results, args.workers, args.only)} cells evaluated")
    elif args.step == "ship":
        print("\n".join(str(p) for p in ship(args.runs, args.results)))
    else:
        report(args.results)
        print(PACKAGE_DIR / "RESULTS.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
