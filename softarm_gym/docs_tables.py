"""The generated parts of the README and the documentation: what the registry and the
benchmark JSON say, written out so that the prose around them cannot drift from them.

``python -m softarm_gym.docs_tables`` rewrites them; ``--check`` exits 1 and names each file
that differs from what would be written (the test suite runs it). Two kinds of output:

* whole pages, one per environment family (``docs/envs/<family>.md``): the env card rendered
  from the env class's docstring, and each registered id's spaces, defaults and reward
  threshold read from the registry and the env it builds;
* marked sections of hand-written pages (README.md, ``docs/*.md``): everything between
  ``<!-- generated: NAME -->`` and ``<!-- end generated: NAME -->`` is :data:`SECTIONS`'s
  NAME, from the registry or from ``docs/bench/*.json`` and ``baselines/results/eval``.
"""

from __future__ import annotations

import argparse
import functools
import inspect
import json
import re
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

from softarm_gym.benchmarks.envs import CONTACT_TARGETS
from softarm_gym.benchmarks.side_by_side import PLANNER_SPEEDUP_TARGET
from softarm_gym.benchmarks.vector_bench import BATCHED_CONTACT_TARGET
from softarm_gym.registry import env_ids, is_deprecated, latest, make_unwrapped

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "docs" / "bench"
EVAL = ROOT / "baselines" / "results" / "eval"

FAMILIES = {
    "reach": ("Reach", "ReachEnv"),
    "track": ("Track", "TrackEnv"),
    "obstacle_reach": ("Obstacle reach", "ObstacleReachEnv"),
    "wrap": ("Wrap", "WrapEnv"),
    "grasp": ("Grasp", "GraspEnv"),
}
"""Page name → (title, env class in :mod:`softarm_gym.envs`)."""

ARMS = {"octarm_v": "OctArm V", "octarm_vi": "OctArm VI", "ct": "CT"}

PICTURES = {
    "wrap": (("environments/wrap_v2_sequence.png", "CEMPlanner on OctArmWrap-v2 and CTWrap-v2",
              "The planner on the recommended wrap ids, from the start to the first success and the "
              "last step (`python -m softarm_gym.benchmarks.planner --ids "
              "SoftArm/OctArmWrap-v2,SoftArm/CTWrap-v2 --picture docs/environments/wrap_v2_sequence.png`)"),),
    "obstacle_reach": (("environments/obstacle_reach_v1_sequence.png",
                        "CEMPlanner on OctArmObstacleReach-v1 and CTObstacleReach-v1, seed 11",
                        "The planner on the recommended obstacle-reach ids, seed 11, from the start to "
                        "the first success and the last step: on OctArm V the one-step search stalls "
                        "behind a disc and a ramp round it reaches the target "
                        "(`python -m softarm_gym.benchmarks.planner --ids "
                        "SoftArm/OctArmObstacleReach-v1,SoftArm/CTObstacleReach-v1 --first-seed 11 "
                        "--picture docs/environments/obstacle_reach_v1_sequence.png`)"),),
}
"""Page name → pictures under ``docs/`` shown below the success rules: (path, alt text, caption)."""

LEARNED = ("sac", "ppo", "td3", "sac_her")
REFERENCE = ("jacobian", "curl", "planner")

_MARK = re.compile(r"(<!-- generated: (?P<name>[a-z_]+) -->\n)(?P<body>.*?)"
                   r"(<!-- end generated: (?P=name) -->)", re.DOTALL)


# ------------------------------------------------------------------------------ the registry

def family_of(env_id: str) -> str:
    """The page (:data:`FAMILIES` key) of ``env_id``."""
    cls = gym.spec(env_id).entry_point.split(":")[1]
    return next(name for name, (_, c) in FAMILIES.items() if c == cls)


def _actions(env) -> str:
    n = env.action_space.shape[0]
    if env.action_mode == "delta":
        return f"{n} pressures, steps of ≤ {env.delta_scale:.0%} p_max"
    return f"{n} pressures, absolute"


def _success(env) -> str:
    if hasattr(env, "success_lift"):
        return f"object held ≥ {1000 * env.success_lift:.0f} mm above its forks"
    if hasattr(env, "success_wrap_deg"):
        return f"wrap ≥ {env.success_wrap_deg:g}°"
    return f"tip within {1000 * env.success_tolerance:.0f} mm"


@functools.cache
def _facts(env_id: str) -> dict:
    """What the tables say of ``env_id``, read from its registry entry and the env it builds."""
    env = make_unwrapped(env_id)
    try:
        spec = gym.spec(env_id)
        return {"id": env_id, "task": FAMILIES[family_of(env_id)][0],
                "arm": ARMS.get(env.arm.name, env.arm.name),
                "dims": "2D" if env.planar else "3D", "actions": _actions(env), "success": _success(env),
                "action_space": f"Box(-1, 1, ({env.action_space.shape[0]},))",
                "observation_space": f"Box({env.observation_space.shape[0]},)",
                "steps": spec.max_episode_steps,
                "threshold": "—" if spec.reward_threshold is None else f"{spec.reward_threshold:g}",
                "kwargs": ", ".join(f"`{k}={v!r}`" for k, v in spec.kwargs.items()),
                "vector": "batched" if spec.vector_entry_point else "—"}
    finally:
        env.close()


def ids_table() -> str:
    """The registered ids to use (the latest version of each), one line each."""
    rows = ["| id | task | arm | | actions | success |", "|---|---|---|---|---|---|"]
    for env_id in env_ids(include_deprecated=False):
        f = _facts(env_id)
        rows.append(f"| `{env_id}` | {f['task']} | {f['arm']} | {f['dims']} | {f['actions']} | "
                    f"{f['success']} |")
    old = [i for i in env_ids() if is_deprecated(i)]
    rows.append("")
    rows.append(f"Older versions stay registered so that earlier results reproduce: "
                f"{', '.join(f'`{i}` (use `{latest(i)}`)' for i in old)}; "
                "`gym.make` says they are out of date.")
    return "\n".join(rows)


def _card(cls) -> str:
    """The env card of ``cls`` (its docstring) as Markdown: reST literals and roles become
    code spans, the card's ``##`` headings become ``###`` under the page's sections."""
    doc = inspect.getdoc(cls)
    doc = re.sub(r":[a-z]+:`~?([^`]+)`", lambda m: f"`{m.group(1).split('.')[-1]}`", doc)
    doc = doc.replace("``", "`")
    return re.sub(r"^## ", "### ", doc, flags=re.MULTILINE)


def family_page(family: str) -> str:
    """``docs/envs/<family>.md``: the ids of the family with their spaces and defaults, then
    the env card."""
    import softarm_gym.envs as envs

    title, cls_name = FAMILIES[family]
    cls = getattr(envs, cls_name)
    ids = [i for i in env_ids() if family_of(i) == family]
    lines = [f"# {title}: `{cls_name}`", "",
             "<!-- Generated by `python -m softarm_gym.docs_tables` from the registry and the env class; "
             "do not edit. -->", "",
             f"{inspect.getdoc(cls).splitlines()[0]}", "",
             "## Registered ids", "",
             "| id | arm | | action space | observation (flat) | steps | reward threshold | vector env |",
             "|---|---|---|---|---|---|---|---|"]
    facts = [_facts(i) for i in ids]
    for f in facts:
        name = f"`{f['id']}`" + (f" (out of date: use `{latest(f['id'])}`)" if is_deprecated(f["id"]) else "")
        lines.append(f"| {name} | {f['arm']} | {f['dims']} | `{f['action_space']}`, {f['actions']} | "
                     f"`{f['observation_space']}` | {f['steps']} | {f['threshold']} | {f['vector']} |")
    lines += ["", "Success: " + "; ".join(f"`{f['id']}` {f['success']}" for f in facts) + ".", ""]
    for path, alt, caption in PICTURES.get(family, ()):
        lines += [f"![{alt}](../{path})", "", f"*{caption}.*", ""]
    lines += ["Registered keyword arguments (what each id sets; everything else is the class default "
              "below):", ""]
    lines += [f"* `{f['id']}`: {f['kwargs']}" for f in facts]
    lines += ["", "Each reward threshold is floor(0.9 × the mean return of the reference controller over 20 "
              "seeded episodes) (`python -m softarm_gym.benchmarks.reference`; "
              "[measured returns](../environments.md#reward-thresholds)).", "",
              "## Env card", "", _card(cls), ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- the benchmarks

def _json(name: str) -> dict:
    return json.loads((BENCH / name).read_text())


def _eval_cells() -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(EVAL.glob("*__main.json"))]


def _agent_kind(cell: dict) -> str:
    return cell["agent_name"].split("_")[0] if not cell["agent_name"].startswith("sac_her") else "sac_her"


def baseline_rows() -> list[dict]:
    """Per (task, arm, dims), from the main evaluation cells: the best learned agent with
    continuous actions and the best with discrete ones (the pressure box's corners), each by
    mean success over its seeds, and every reference controller's best (planner, scripted
    curl, Jacobian) — each as (mean success, seeds, agent name, env id) or None."""
    groups: dict = {}
    for cell in _eval_cells():
        facts = _facts(cell["env_id"])
        key = (facts["task"], facts["arm"], facts["dims"])
        name = re.sub(r"_s\d+$", "", cell["agent_name"])  # one agent, its seeds together
        groups.setdefault(key, {}).setdefault((_agent_kind(cell), name, cell["env_id"]), []).append(
            cell["success_rate"])
    rows = []
    order = [title for title, _ in FAMILIES.values()]
    for (task, arm, dims), agents in sorted(groups.items(), key=lambda g: (order.index(g[0][0]), g[0][1:])):
        scored = [(kind, "corners" in name, (float(np.mean(v)), len(v), name, env_id))
                  for (kind, name, env_id), v in agents.items()]
        learned = {corners: max((r for kind, c, r in scored if kind in LEARNED and c == corners),
                                default=None) for corners in (False, True)}
        rows.append({"task": task, "arm": arm, "dims": dims, "continuous": learned[False],
                     "discrete": learned[True],
                     "reference": {ref: max((r for kind, _, r in scored if kind == ref), default=None)
                                   for ref in REFERENCE}})
    return rows


def _version(env_id: str) -> str:
    return env_id.rsplit("-", 1)[-1]


def _agent(best) -> str:
    mean, seeds, name, env_id = best
    algo = name.split("_")[0].upper() if not name.startswith("sac_her") else "SAC+HER"
    variant = " (corner actions)" if "corners" in name else (" (delta actions)" if "_delta" in name else "")
    detail = (f"{seeds} seeds, " if seeds > 1 else "") + _version(env_id)
    return f"{algo}{variant} {mean:.0%} ({detail})"


def _baseline_cell(row: dict) -> str:
    """One arm's results: learned continuous and discrete, then each reference controller."""
    parts = [f"{label} {_agent(row[key])}" for key, label in (("continuous", "learned"),
                                                               ("discrete", "learned discrete"))
             if row[key] is not None]
    parts += [f"{ref} {mean:.0%} ({_version(env_id)})"
              for ref, found in row["reference"].items() if found is not None
              for mean, _, _, env_id in (found,)]
    return f"{row['arm']}: " + ", ".join(parts or ["—"])


def headline_table() -> str:
    """The README's results: speed against peers, accuracy against oracles, baseline success."""
    solver = _json("solver.json")
    default = next(s for s in solver["settings"]
                   if s["steps_per_section"] == solver["default_steps_per_section"])
    scipy = min(solver["scipy"], key=lambda s: s["tol"])  # the speed-ups are against the most accurate run
    envs = _json("envs.json")
    v1 = next(c for c in envs["cases"] if c["env_id"] == "SoftArm/OctArmReach-v1"
              and c["observation"] == "true" and c["planar"] and not c["self_contact"])
    batched = max(envs["batched_vector"], key=lambda r: r["env_steps_per_s"])
    rows = ["| result | figure | source |", "|---|---|---|",
            f"| warm quasi-static step, OctArm V / CT ({solver['scenes']} scenes) | "
            f"{solver['speedup_vs_scipy_warm']:.0f}× faster than scipy `solve_bvp` at tol {scipy['tol']:g} "
            f"({default['median_warm_us']:.0f} µs against {1000 * scipy['median_seconds']:.1f} ms) | "
            "[benchmarks](docs/benchmarks.md#solver-speed-against-accuracy) |",
            f"| cold solve from rest | {solver['speedup_vs_scipy_cold']:.0f}× faster than scipy "
            "`solve_bvp` | "
            "[benchmarks](docs/benchmarks.md#solver-speed-against-accuracy) |",
            f"| accuracy at the default grid | max tip error {default['max_tip_error_over_L']:.1e}·L, median "
            f"{default['median_tip_error_over_L']:.1e}·L against a 1024-step reference (itself within "
            "1e-8·L of an independent `solve_bvp` formulation) | "
            "[oracles](docs/benchmarks.md#accuracy-against-oracles-that-do-not-trust-our-code) |",
            f"| `OctArmReach-v1` env steps | {v1['single_steps_per_s'] / 1000:.0f}k steps/s on one core; "
            f"batched env {batched['env_steps_per_s'] / 1000:.0f}k env-steps/s at {batched['num_envs']} "
            "arms | "
            "[benchmarks](docs/benchmarks.md#environments) |"]
    rows += contact_headline_rows()
    by_task: dict = {}
    for row in baseline_rows():
        by_task.setdefault((row["task"], row["dims"]), []).append(_baseline_cell(row))
    for (task, dims), cells in by_task.items():
        rows.append(f"| {task} {dims}: success rate | {'; '.join(cells)} | [baselines](docs/baselines.md) |")
    rows += ["", f"Measured on: {solver['measured']['machine']}. Speeds are ratios measured side by side in "
             "one run; wall-clock figures carry over to another machine only as ratios."]
    return "\n".join(rows)


def thresholds_table() -> str:
    """Reference returns and the reward thresholds set from them (``docs/bench/reference_returns.json``)."""
    data = _json("reference_returns.json")
    rows = ["| ID | reference | mean return ± std (20 episodes) | reference success | `reward_threshold` |",
            "|---|---|---|---|---|"]
    for env_id, row in data["ids"].items():
        threshold = "none" if row["threshold"] is None else f"{row['threshold']:g}"
        rows.append(f"| `{env_id}` | `{row['controller']}` | {row['mean']:.1f} ± {row['std']:.1f} | "
                    f"{row['success_rate']:.0%} | {threshold} |")
    rows += ["", f"`{data['command']}`, {data['date']}. Rule: {data['rule']}."]
    for run in data.get("added", ()):
        rows += ["", f"Rows of {', '.join(f'`{i}`' for i in run['ids'])}: `{run['command']}`, {run['date']}."]
    return "\n".join(rows)


def solver_table() -> str:
    """Speed against accuracy per RK4 grid (``docs/bench/solver.json``, as ``softarm bench`` prints it)."""
    from softarm_gym.benchmarks.solver_bench import format_table

    solver = _json("solver.json")
    m = solver["measured"]
    return f"{format_table(solver)}\n\n`{m['command']}` on a {m['machine']}."


def friction_table() -> str:
    """Coulomb friction's time against error on the capstan and slip-threshold paths
    (``docs/bench/friction.json``, as ``softarm bench --friction`` prints it)."""
    from softarm_gym.benchmarks.friction_bench import format_table

    friction = _json("friction.json")
    m = friction["measured"]
    text = (f"{format_table(friction)}\n\n`{m['command']}`, {m['date']}, {m['repeat']} timings per "
            f"increment, load average {m['load_before'][0]:.1f} before and {m['load_after'][0]:.1f} after.")
    own = friction.get("self_slip_measured")
    if own:  # the self-contact row measured on its own, after the run above
        text += (f" Self-contact rows: `{own['command']}`, {own['date']}, {own['repeat']} timings per "
                 f"increment, load average {own['load_before'][0]:.1f} before and "
                 f"{own['load_after'][0]:.1f} after.")
    return text


def friction_spatial_table() -> str:
    """Coulomb friction's time against error on the 3D oracles' paths, the oblique stylus and
    the capstan round a tilted drum (``docs/bench/friction_3d.json``, as ``softarm bench
    --friction --3d`` prints it)."""
    from softarm_gym.benchmarks.friction_bench import format_table_3d

    friction = _json("friction_3d.json")
    m = friction["measured"]
    text = (f"{format_table_3d(friction)}\n\n`{m['command']}`, {m['date']}, one timing per "
            f"increment, load average {m['load_before'][0]:.1f} before and {m['load_after'][0]:.1f} after.")
    for own in friction.get("rows_measured_alone", []):  # rows added after the run above
        text += (f" {own['rows']}: `{own['command']}`, {own['date']}, load average "
                 f"{own['load_before'][0]:.1f} before and {own['load_after'][0]:.1f} after.")
    return text


def env_table() -> str:
    """Single and vector env steps/s per (id, observation) (``docs/bench/envs.json``)."""
    envs = _json("envs.json")
    rows = ["| environment | observation | single env (steps/s) | 2 async workers (steps/s) |",
            "|---|---|---|---|"]
    for c in envs["cases"]:
        label = c["env_id"] + ("" if c["planar"] else ", 3D")
        label += ", self-contact" if c["self_contact"] else ""
        rows.append(f"| `{label}` | {c['observation']} | {c['single_steps_per_s']:,.0f} | "
                    f"{c['vector_steps_per_s']:,.0f} |")
    rows += ["", "| batched vector env (`true` obs., delta actions) | env-steps/s | on one thread | "
             "converged |", "|---|---|---|---|"]
    for r in envs["batched_vector"]:
        rows.append(f"| {r['num_envs']} arms | {r['env_steps_per_s']:,.0f} | "
                    f"{r['one_thread_env_steps_per_s']:,.0f} | {r['converged_fraction']:.2%} |")
    m = envs["measured"]
    rows += ["", f"`{m['command']}` on a {m['machine']}."]
    return "\n".join(rows)


def _verdict(value: float, target: float, at_most: bool = True) -> str:
    return "met" if (value <= target if at_most else value >= target) else "not met"


def contact_headline_rows() -> list[str]:
    """The README's contact rows: contact steps against a free step before and after the lean
    contact step, the recommended versions' steps now, the batched contact envs against
    batched reach, the planner's decisions (``docs/bench/contact_side_by_side.json``,
    ``planner_side_by_side.json`` and the contact keys of ``envs.json``)."""
    sbs = _json("contact_side_by_side.json")
    ratios = {r["name"]: r for r in sbs["ratios"]["rows"]}
    cells = [f"{name} {ratios[name]['before']:.1f}× → {ratios[name]['after']:.1f}×"
             for name in CONTACT_TARGETS if name in ratios]
    envs = _json("envs.json")
    later = [r for r in envs["contact_ratios"]["rows"] if r["name"] in CONTACT_TARGETS
             and r["name"] not in ratios]  # cases the bench gained after that comparison
    batched = envs["batched_contact"]
    reach = batched["rows"][0]
    shares = [f"{r['name']} {r['env_steps_per_s'] / 1000:.0f}k ({r['ratio_to_reach']:.0%})"
              for r in batched["rows"][1:]]
    wrap = _json("planner_side_by_side.json")["planner"]["ids"]["SoftArm/OctArmWrap-v1"]
    return [f"| contact env steps, × a free `OctArmReach-v1` step (3D wrap: × a 3D reach step), "
            f"before → after the lean contact step | {'; '.join(cells)} | "
            "[benchmarks](docs/benchmarks.md#contact) |",
            "| recommended contact versions (self-contact on), × a free `OctArmReach-v1` step "
            "(`softarm bench --env --contact`) | "
            + "; ".join(f"{r['name']} {r['times_unit']:.1f}× (target ≤ {CONTACT_TARGETS[r['name']]:g}×)"
                        for r in later) + " | [benchmarks](docs/benchmarks.md#contact) |",
            f"| batched contact envs, {batched['num_envs']} arms (share of batched reach's "
            f"{reach['env_steps_per_s'] / 1000:.0f}k arm-steps/s) | {'; '.join(shares)} | "
            "[benchmarks](docs/benchmarks.md#contact) |",
            f"| `CEMPlanner` decision on `OctArmWrap-v1`, same samples | "
            f"{1e3 * wrap['before']['median_decision_s']:.0f} ms → "
            f"{1e3 * wrap['after']['median_decision_s']:.0f} ms ({wrap['speedup']:.1f}× faster); success "
            f"{wrap['before']['success_rate']:.0%} → {wrap['after']['success_rate']:.0%} | "
            "[benchmarks](docs/benchmarks.md#contact) |"]


def contact_table() -> str:
    """Contact speed against the issue's targets: single-env ratios before and after, batched
    contact envs, planner decisions (``docs/bench/contact_side_by_side.json``,
    ``planner_side_by_side.json``, ``envs.json``)."""
    sbs = _json("contact_side_by_side.json")
    planners = _json("planner_side_by_side.json")  # the planner against the same tree before
    envs = _json("envs.json")
    bench = {r["name"]: r for r in envs["contact_ratios"]["rows"]}
    rows = ["| single env, random actions | unit step | × unit, before | × unit, after | "
            "× unit, `softarm bench --env` | target | |", "|---|---|---|---|---|---|---|"]
    compared = {r["name"]: r for r in sbs["ratios"]["rows"][1:]}
    # The side-by-side's rows, then the bench's later ones (no tree before to compare).
    # (friction's cases have their own table: their cost against their frictionless twins)
    later = [n for n in bench if n not in compared and n != "free reach" and "friction" not in n]
    for name in [*compared, *later]:
        r = compared.get(name, bench[name])
        target = CONTACT_TARGETS.get(name)
        kwargs = "".join(f", {k}={v}" for k, v in r["kwargs"].items())
        now = bench[name]["times_unit"]  # this tree's figure: the one a target is judged on
        before, after = (f"{r['before']:.1f}", f"{r['after']:.1f}") if name in compared else ("—", "—")
        rows.append(f"| {name} (`{r['env_id']}`{kwargs}) | {r['unit']} | {before} | {after} | "
                    f"{now:.1f} | " + (f"≤ {target:g} | {_verdict(now, target)} |" if target else "— | |"))
    batched = envs["batched_contact"]
    rows += ["", f"| batched env, {batched['num_envs']} arms, random actions | arm-steps/s (median of "
             f"{batched['repeats']}) | share of batched reach | converged | target | |",
             "|---|---|---|---|---|---|"]
    for r in batched["rows"]:
        unit = r is batched["rows"][0]  # batched reach, the unit
        target = "—" if unit else f"≥ {BATCHED_CONTACT_TARGET:.0%}"
        verdict = "" if unit else _verdict(r["ratio_to_reach"], BATCHED_CONTACT_TARGET, at_most=False)
        kwargs = "".join(f", {k}={v}" for k, v in r["kwargs"].items())
        rows.append(f"| {r['name']} (`{r['env_id']}`{kwargs}) | {r['env_steps_per_s']:,.0f} | "
                    f"{r['ratio_to_reach']:.0%} | {r['converged_fraction']:.2%} | {target} | {verdict} |")
    for key, threads in (("planner", "numba's default threads"), ("planner_one_thread", "one numba thread")):
        planner = planners[key]
        kwargs = ", ".join(f"{k}={v}" for k, v in planner["kwargs"].items())
        seeds = f"seeds {planner['seeds'][0]}–{planner['seeds'][-1]}"
        rows += ["", f"| `CEMPlanner`, {threads} ({kwargs}, {seeds}) | decision before (ms) | after (ms) | "
                 "speed-up | success before → after | same per seed | target | |",
                 "|---|---|---|---|---|---|---|---|"]
        for env_id, e in planner["ids"].items():
            target = PLANNER_SPEEDUP_TARGET if env_id == "SoftArm/OctArmWrap-v1" else None
            rows.append(f"| `{env_id}` | {1e3 * e['before']['median_decision_s']:.0f} | "
                        f"{1e3 * e['after']['median_decision_s']:.0f} | {e['speedup']:.1f}× | "
                        f"{e['before']['success_rate']:.0%} → {e['after']['success_rate']:.0%} | "
                        f"{'yes' if e['same_success'] else 'no'} | "
                        + (f"≥ {target:g}× | {_verdict(e['speedup'], target, at_most=False)} |" if target
                           else "— | |"))
    m = envs["contact_measured"]
    rows += ["", f"Single-env rows: before {sbs['before']}; after {sbs['after']}."]
    rows.append(f"Planner rows: before {planners['before']}; after {planners['after']}.")
    for key in ("ratios", "planner", "planner_one_thread"):
        part = sbs[key] if key == "ratios" else planners[key]
        rows.append(f"`{part['command']}`, {part['date']}, {part['rounds']} alternating rounds, load average "
                    f"{part['load_before'][0]:.1f} before and {part['load_after'][0]:.1f} after.")
    after = "not read" if m["load_after"] is None else f"{m['load_after'][0]:.1f}"
    rows.append(f"`{m['command']}`, {m['date']}, load average {m['load_before'][0]:.1f} before and "
                f"{after} after.")
    return "\n".join(rows)


def first_episode_table() -> str:
    """First episode in a fresh process, cached kernels against an empty cache
    (``docs/bench/first_episode.json``)."""
    result = _json("first_episode.json")
    rows = ["| environment | first episode, cached kernels (s) | steady episode (s) | "
            "first episode, empty cache (s) |", "|---|---|---|---|"]
    for env_id, row in result["rows"].items():
        warm = row["warm"]
        steady = warm["steps"] / warm["steady_steps_per_s"]
        cold = f"{row['cold']['first_seconds']:.1f}" if "cold" in row else "—"
        rows.append(f"| `{env_id}` | {warm['first_seconds']:.2f} | {steady:.3f} | {cold} |")
    return "\n".join(rows)


def fresh_machine_table() -> str:
    """``make demo`` and ``make test`` on a fresh clone (``docs/bench/fresh_machine.json``)."""
    data = _json("fresh_machine.json")
    rows = ["| step | wall time (s) | load average before | what it does |", "|---|---|---|---|"]
    for step in data["steps"]:
        load = "—" if step["load_before"] is None else f"{step['load_before']:.1f}"  # not read
        rows.append(f"| `{step['command']}` | {step['seconds']:.0f} | {load} | {step['what']} |")
    first = data["first_episode"]
    rows += ["", f"First episode after `make demo`, in a fresh process: `{first['env_id']}`, "
             f"{first['steps']} steps in {first['first_seconds']:.2f} s (imports "
             f"{first['import_seconds']:.1f} s before it), against "
             f"{first['steady_steps_per_s']:,.0f} steps/s once running.",
             "", f"Measured on {data['machine']}, {data['date']}: {data['how']}."]
    return "\n".join(rows)


SECTIONS = {"ids_table": ids_table, "headline_table": headline_table, "solver_table": solver_table,
            "friction_table": friction_table, "friction_spatial_table": friction_spatial_table,
            "thresholds_table": thresholds_table,
            "env_table": env_table, "contact_table": contact_table,
            "first_episode_table": first_episode_table,
            "fresh_machine_table": fresh_machine_table}
"""Marked-section name → the function whose Markdown fills it."""


# ------------------------------------------------------------------------------- the files

def fill(text: str, cache: dict) -> str:
    """``text`` with every marked section rewritten from :data:`SECTIONS` (``cache`` keeps each
    section's Markdown between calls). An unknown section name is a ``ValueError``."""
    def body(match):
        name = match.group("name")
        if name not in SECTIONS:
            raise ValueError(f"unknown generated section {name!r}; known: {', '.join(SECTIONS)}")
        if name not in cache:
            cache[name] = SECTIONS[name]()
        return f"{match.group(1)}{cache[name]}\n{match.group(4)}"

    return _MARK.sub(body, text)


def expected() -> dict[Path, str]:
    """Every generated file and every file with marked sections, as they should read."""
    out = {ROOT / "docs" / "envs" / f"{family}.md": family_page(family) for family in FAMILIES}
    cache: dict = {}
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = path.read_text(encoding="utf-8")
        if _MARK.search(text):
            out[path] = fill(text, cache)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m softarm_gym.docs_tables",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if a file differs from what would be written")
    args = parser.parse_args(argv)
    stale = []
    for path, text in expected().items():
        current = path.read_text(encoding="utf-8") if path.exists() else None
        if current == text:
            continue
        stale.append(path.relative_to(ROOT))
        if not args.check:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
    if args.check and stale:
        print(f"out of date (run python -m softarm_gym.docs_tables): {', '.join(map(str, stale))}",
              file=sys.stderr)
        return 1
    print(f"{'checked' if args.check else 'wrote'} the generated docs"
          + (f"; rewrote {', '.join(map(str, stale))}" if stale and not args.check else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
