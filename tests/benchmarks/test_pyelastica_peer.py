"""PyElastica peer (softarm_gym.benchmarks.pyelastica_peer): equivalence checks at 20 elements.

PyElastica is first order in its element count; its leading error for a clamped rod is the
clamp convention (the first element keeps the base orientation, so the whole rod lags the
continuum by half an element's rotation, u(0)·dx/2). The arc test checks that this, and
nothing else, is what separates it from the closed form; the gravity test that the tip lands
near our converged solution. Two short settles: ~8 s with PyElastica's numba kernels cached
(they are cached in site-packages after the first run; a cold cache adds ~30-60 s of compiling).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import solver

pytest.importorskip("elastica", reason="PyElastica not installed (pip install 'softarm-gym[bench]')")
from softarm_gym.benchmarks import pyelastica_peer as peer  # noqa: E402

ARM = solver.designs.octarm_v()


def _rotation(angle: float) -> np.ndarray:
    return np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])


def test_unloaded_arc_differs_from_closed_form_only_by_the_clamp_offset():
    label, arm, p, scene, exact = peer.validation_cases()[0]
    result = peer.settle(arm, p, scene, n_elem=20, tol=1e-5)
    assert result.settled
    u_base = solver.rest_strains(arm, solver.channel_pressures(arm, p))[1][0]
    dx_base = arm.sections[0].length / peer.elements_per_section(arm, 20)[0]
    clamp_offset = _rotation(-u_base * dx_base / 2.0) @ exact
    error = np.linalg.norm(result.tip - exact)
    # The discretisation error is large at 20 elements (≈13 % of L here) ...
    assert error > 0.05 * arm.length
    # ... and the clamp offset accounts for it up to second-order terms (measured: 1 %).
    assert np.linalg.norm(result.tip - clamp_offset) < 0.05 * error


def test_settled_tip_near_our_solver_under_gravity_and_payload():
    p = np.array(peer.PRESSURE_PATTERNS_PSI["S"]) * solver.PSI
    scene = solver.Scene(base_angle_deg=45.0, payload_kg=0.1)
    result = peer.settle(ARM, p, scene, n_elem=20, tol=1e-5)
    ours = solver.solve(ARM, p, scene, settings=peer.REFERENCE).tip
    assert result.settled
    assert result.steps > 0 and result.seconds > 0 and result.final_velocity < 1e-5 / 0.05
    # First-order scheme at 20 elements: measured 0.32 % of L. A flipped rest-curvature sign
    # or a lost payload or endplate would move the tip by far more than 1 % of L.
    assert np.linalg.norm(result.tip - ours) < 0.01 * ARM.length


def test_max_time_reached_reports_not_settled():
    result = peer.settle(ARM, np.zeros(6), solver.Scene(base_angle_deg=90.0), n_elem=6, max_time=0.02)
    assert not result.settled
    assert result.simulated_time == pytest.approx(0.02, abs=2e-3)
    assert result.to_dict()["settled"] is False


@pytest.mark.parametrize("kwargs, match", [
    ({"pressures_pa": np.zeros(5)}, "expects 6 pressures in planar mode"),
    ({"pressures_pa": [-1.0, 0, 0, 0, 0, 0]}, "s1_I.*negative"),
    ({"pressures_pa": [np.nan, 0, 0, 0, 0, 0]}, "s1_I.*not finite"),
    ({"pressures_pa": [1e7, 0, 0, 0, 0, 0]}, "s1_I.*rated maximum"),
    ({"scene": solver.Scene(tip_moment=0.1)}, "tip moment"),
    ({"scene": "horizontal"}, "solver.Scene"),
    ({"n_elem": 5}, "n_elem must be an integer >= 6"),
    ({"n_elem": 30.0}, "n_elem must be an integer"),
    ({"tol": 0.0}, "tol must be"),
    ({"window": float("nan")}, "window must be"),
    ({"ramp_time": -1.0}, "ramp_time must be"),
    ({"dt": -1e-4}, "dt must be"),
    ({"damping": 0.0}, "damping must be"),
])
def test_bad_input_raises_value_error(kwargs, match):
    args = {"pressures_pa": np.zeros(6), "scene": solver.Scene(), "n_elem": 30, **kwargs}
    with pytest.raises(ValueError, match=match):
        peer.settle(ARM, args.pop("pressures_pa"), args.pop("scene"), **args)


def test_massless_design_is_rejected():
    rod = solver.designs.rod(length=1.0, EI=1.0, EA=1e4, GA=1e4, mass_per_length=0.0)
    with pytest.raises(ValueError, match="mass_per_length > 0"):
        peer.settle(rod, [], solver.Scene(gravity=0.0, tip_force=(0.0, -1.0)))


def test_peer_result_validates():
    with pytest.raises(ValueError, match="shape"):
        peer.PeerResult(tip=np.zeros(3), seconds=1.0, steps=1, settled=True, final_velocity=0.0,
                        simulated_time=1.0, n_elem=20, dt=1e-4)
    with pytest.raises(ValueError, match="seconds"):
        peer.PeerResult(tip=np.zeros(2), seconds=-1.0, steps=1, settled=True, final_velocity=0.0,
                        simulated_time=1.0, n_elem=20, dt=1e-4)


@pytest.mark.parametrize("n_elem", [6, 20, 60, 121])
def test_elements_follow_section_lengths_and_end_on_section_ends(n_elem):
    counts = peer.elements_per_section(ARM, n_elem)
    lengths = np.array([s.length for s in ARM.sections])
    assert counts.sum() == n_elem and np.all(counts >= 2)
    assert np.all(np.abs(counts - n_elem * lengths / lengths.sum()) <= 1.0)


def test_time_step_shrinks_with_element_size():
    steps = [peer.stable_time_step(ARM, n) for n in (20, 60, 120)]
    assert steps[0] > steps[1] > steps[2] > 0


def test_scene_sets():
    scenes = peer.peer_scenes()
    assert len(scenes) == 18 and len({label for label, *_ in scenes}) == 18
    assert {s.base_angle_deg for *_, s in scenes} == {0.0, 45.0, 90.0}
    assert {s.payload_kg for *_, s in scenes} == {0.0, 0.1}
    for _, design, p, scene in scenes:
        arm = solver.designs.get(design)
        assert p.shape == (arm.n_inputs(),) and np.all((p >= 0) & (p <= arm.max_pressure))
        assert scene.gravity > 0
    assert len(peer.peer_scenes(quick=True)) == 4


@pytest.mark.parametrize("psi, angle", [((100, 0, 0, 0, 0, 0), 90.0), ((0, 60, 30, 0, 60, 0), 30.0)])
def test_arc_tip_matches_our_unloaded_solve(psi, angle):
    p = np.array(psi, dtype=float) * solver.PSI
    ours = solver.solve(ARM, p, solver.Scene(base_angle_deg=angle, gravity=0.0)).tip
    np.testing.assert_allclose(peer.arc_tip(ARM, p, angle), ours, atol=1e-12)
