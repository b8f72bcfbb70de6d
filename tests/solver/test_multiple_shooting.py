"""Multiple shooting for dead-load solves: the path for arms whose single shooting is
ill-conditioned (L·√(N/EI) large), checked against scipy's collocation solver."""

import dataclasses
import importlib

import numpy as np
import pytest

import solver
from solver import PSI, designs
from solver._model import context, pack
from solver._paths_planar import solve_single
from solver._paths_shooting import solve_multiple
from tests.solver import naive

S = importlib.import_module("solver.solve")


def _long(arm, factor):
    return dataclasses.replace(arm, sections=tuple(
        dataclasses.replace(s, length=s.length * factor) for s in arm.sections))


def _channel(arm, planar_psi):
    p = np.zeros(arm.n_channels)
    for value, (_, idx) in zip(planar_psi, arm.planar_channels):
        p[list(idx)] = value * PSI
    return p


def test_multiple_equals_single_shooting_on_a_well_conditioned_arm():
    """Both integrate the same ODE with the same RK4 steps: the same equilibrium."""
    arm = designs.octarm_v()
    scene = solver.Scene(base_angle_deg=45, payload_kg=0.1)
    p = np.array([0, 60, 20, 0, 80, 10]) * PSI
    settings = solver.Settings()
    packed = pack(arm, "full", settings)
    p_inputs, p_channel = S._channel_pressures(arm, p, True, packed)
    single = solve_single(arm, packed, p_inputs, p_channel, scene, "full", None, settings)
    multiple = solve_multiple(arm, packed, p_inputs, p_channel, scene, "full", None, settings)
    assert single.converged and multiple.converged and multiple.stable
    np.testing.assert_allclose(multiple.positions, single.positions, atol=1e-9)
    np.testing.assert_allclose(multiple.internal_moment, single.internal_moment, atol=1e-8)


@pytest.mark.parametrize("factor, payload", [(4.0, 1.0), (5.5, 2.0)])
def test_long_heavy_arm_agrees_with_solve_bvp(factor, payload):
    """A 3.5-4.8 m OctArm VI with a payload, from a base 30° above horizontal: index
    (L·√(N/EI)) 100-190, where single shooting would amplify errors by e^100. Converges to
    scipy's collocation solution at fourth order in the RK4 step."""
    arm = _long(designs.octarm_vi(), factor)
    psi = [20, 0, 0, 30, 10, 0]
    scene = solver.Scene(base_angle_deg=120, payload_kg=payload)
    packed = pack(arm, "full", solver.Settings())
    assert context(arm, packed, scene, 2, solver.Settings()).shooting_index > 100
    errors = []
    for steps in (32, 64):
        # The grid pinned (no refinement), to see its order: the step-size check asks for
        # more steps here, so the result is flagged unconverged; Newton met its tolerance.
        settings = solver.Settings(steps_per_section=steps, max_refinement=1)
        eq = solver.solve(arm, np.array(psi) * PSI, scene, settings=settings)
        assert eq.residual <= settings.tol and eq.stable and eq.shooting_nodes.size
        if not errors:
            # Collocation needs a start near the hanging shape (from the straight rod it
            # refines without end): ours seeds it; the converged BVP solution is its own.
            tau = np.linspace(0.0, 1.0, 81)
            guess = np.zeros((6 * len(arm.sections), tau.size))
            state = np.column_stack([eq.positions, eq.angles, eq.internal_force,
                                     eq.internal_moment])
            start = 0
            for i, end in enumerate(eq.section_ends):
                local = (eq.s[start:end + 1] - eq.s[start]) / arm.sections[i].length
                for k in range(6):
                    guess[6 * i + k] = np.interp(tau, local, state[start:end + 1, k])
                start = end + 1
            tip, _, _ = naive.solve_bvp_planar(arm, _channel(arm, psi), scene, nodes=tau.size,
                                               guess=guess)
        errors.append(np.linalg.norm(eq.tip - tip))
    assert errors[1] < errors[0] / 8  # RK4: fourth order (16x), with room for the ends
    assert errors[1] < 1e-4 * arm.length
    # Warm steps continue from the shooting nodes.
    settings = solver.Settings(steps_per_section=64)
    warm = solver.solve(arm, np.array(psi) * 1.1 * PSI, scene, warm_start=eq, settings=settings)
    cold = solver.solve(arm, np.array(psi) * 1.1 * PSI, scene, settings=settings)
    assert warm.converged and warm.iterations < cold.iterations
    np.testing.assert_allclose(warm.tip, cold.tip, atol=1e-9)
