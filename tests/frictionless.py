"""Hashes of frictionless contact results: solves (planar, rigid, self-contact, spatial), the
stepper's and the batched stepper's steps, and episodes of the contact environments.

Friction (docs/design.md §9) adds arrays and branches that a scene without it skips, so that
μ = 0 gives the results of the code before friction bit for bit. ``frictionless_hashes.json``
holds these hashes as that code computed them (the commit in its ``"base"`` entry);
``tests/solver/test_friction.py`` checks that today's code computes the same. A change meant
to alter frictionless contact results writes the file again, after checking the μ = 0 case
against its parent commit the same way::

    python -m tests.frictionless --write      # from the repository root

Each case builds its scenes without naming friction (so that the code before it runs it).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

HASHES = Path(__file__).with_name("frictionless_hashes.json")


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes())
    return h.hexdigest()[:24]


def _eq_arrays(eq) -> tuple:
    return (eq.tip, eq.positions, eq.internal_force, eq.internal_moment, eq.contact_force,
            eq.penetration, eq.base_force, [eq.iterations, eq.converged, eq.stable])


def _solves():
    import solver
    from solver import PSI, designs
    arm = designs.octarm_v()
    ring = arm.tubes[0].material.ring_stiffness
    p = np.array([60, 0, 60, 0, 60, 0]) * PSI
    out = {}
    scenes = {
        "wrap": solver.Scene(base_angle_deg=0, obstacles=(solver.Disc((-0.20, -0.55), 0.12, 2e4),)),
        "two discs": solver.Scene(base_angle_deg=90.0, obstacles=(
            solver.Disc((0.2, -0.45), 0.07, 1e6), solver.Disc((0.45, -0.75), 0.05, ring))),
        "self": solver.Scene(base_angle_deg=13.44, self_contact=ring,
                             obstacles=(solver.Disc((0.1, -0.3), 0.04, ring),)),
        "rigid": solver.Scene(base_angle_deg=0, obstacles=(
            solver.Disc((-0.20, -0.55), 0.12, float("inf")),)),
    }
    for name, scene in scenes.items():
        eq = solver.solve(arm, p, scene)
        warm = solver.solve(arm, 0.6 * p, scene, warm_start=eq)
        out[f"solve {name}"] = _digest(*_eq_arrays(eq), *_eq_arrays(warm))
    spatial = solver.Scene(base_angle_deg=0, obstacles=(
        solver.Cylinder((0.17, -0.5, 0.0), (0.0, 0.0, 1.0), 0.12, ring),))
    p3 = np.zeros(arm.n_channels)
    p3[::3] = 40 * PSI
    eq = solver.solve(arm, p3, spatial, planar=False)
    out["solve spatial"] = _digest(*_eq_arrays(eq), eq.orientations)
    return out


def _steppers():
    import solver
    from solver import designs
    from tests.solver.test_lean_contact import curl_walk
    arm = designs.octarm_v()
    ring = arm.tubes[0].material.ring_stiffness
    scene = solver.Scene(base_angle_deg=0.0, obstacles=(solver.Disc((0.16, -0.55), 0.13, ring),))
    stepper = solver.Stepper(arm, scene)
    walk = curl_walk(arm, 30, seed=7)
    stepper.reset(walk[0])
    rows = []
    for p in walk[1:]:
        report = stepper.step(p)
        rows.append([*stepper.tip, report.iterations, report.converged])
    out = {"stepper": _digest(rows, *_eq_arrays(stepper.equilibrium))}
    n = 3
    batch = solver.BatchStepper(arm, scene, n)
    walks = [curl_walk(arm, 20, seed=10 + k) for k in range(n)]
    batch.reset(np.array([w[0] for w in walks]))
    rows = []
    for t in range(1, 20):
        report = batch.step(np.array([w[t] for w in walks]))
        rows.append(np.concatenate([batch.tips.ravel(), report.iterations, report.converged]))
    out["batch stepper"] = _digest(rows, *_eq_arrays(batch.equilibrium(1)))
    return out


def _envs():
    import gymnasium as gym

    import softarm_gym  # noqa: F401  (registers the ids)
    out = {}
    for env_id, steps in (("SoftArm/OctArmWrap-v1", 12), ("SoftArm/OctArmWrap-v2", 12),
                          ("SoftArm/OctArmObstacleReach-v0", 12),
                          ("SoftArm/OctArmObstacleReach-v1", 12),
                          ("SoftArm/OctArmGrasp-v0", 6), ("SoftArm/OctArmWrap3D-v0", 3)):
        env = gym.make(env_id)
        obs, _ = env.reset(seed=3)
        env.action_space.seed(3)
        rows = [obs]
        for _ in range(steps):
            obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            rows.append(np.append(obs, [reward, terminated, truncated]))
        env.close()
        out[f"env {env_id}"] = _digest(*rows)
    return out


def compute() -> dict:
    """Every case's hash, by name."""
    return {**_solves(), **_steppers(), **_envs()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"write {HASHES.name}")
    parser.add_argument("--base", default="", help="the commit whose code computed them")
    args = parser.parse_args(argv)
    hashes = compute()
    if args.write:
        HASHES.write_text(json.dumps({"base": args.base, "hashes": hashes}, indent=1) + "\n")
    json.dump(hashes, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
