"""The shipped custom-design example loads, solves, drives an env and the CLI."""

import json

import gymnasium as gym
import numpy as np

import softarm_gym  # noqa: F401
import solver
from softarm_gym.cli import main
from softarm_gym.controllers import JacobianController

EXAMPLE = solver.designs.example_file()


def test_example_design_loads_and_round_trips():
    arm = solver.designs.load(EXAMPLE)
    assert arm.name == "two_section_pneumatic"
    assert arm.input_names(planar=True) == ("s1_I", "s1_II+III", "s2_I", "s2_II+III")
    assert arm.length == 0.55 and arm.max_pressure == 0.7e6
    assert solver.designs.from_json(arm.to_json()) == arm


def test_example_design_runs_in_a_registered_env():
    arm = solver.designs.load(EXAMPLE)
    env = gym.make("SoftArm/OctArmReach-v0", design=arm)
    assert env.action_space.shape == (4,)
    controller = JacobianController(env)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    for _ in range(30):
        obs, _, _, _, info = env.step(controller.act(obs))
    assert info["converged"] and info["is_success"]


def test_example_design_through_softarm_solve(capsys):
    assert main(["solve", "--design-file", str(EXAMPLE), "--pressures-psi", "50,0,50,0",
                 "--base-angle", "90", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    arm = solver.designs.load(EXAMPLE)
    eq = solver.solve(arm, np.array([50, 0, 50, 0]) * solver.PSI, solver.Scene(base_angle_deg=90))
    assert out["design"] == "two_section_pneumatic" and out["converged"] and out["stable"]
    np.testing.assert_allclose(out["tip"], eq.tip, rtol=0, atol=1e-12)
