"""The batched stepper with contact (:class:`solver.BatchStepper` of a scene with obstacles or
self-contact): every copy, with obstacles of its own, steps bit for bit as a single
:class:`solver.Stepper` in that copy's scene — on the lean planar path, the lean contact
path and the general one, on one thread and on numba's threads."""

from dataclasses import replace

import numpy as np
import pytest

import solver
from solver import designs
from solver.kernels import stepping
from tests.solver.test_lean_contact import K_TUBE, curl_walk
from tests.threads import by_thread_count, needs_two_threads


def _scenes(template, n, seed):
    rng = np.random.default_rng(seed)
    return [replace(template, obstacles=(solver.Disc(
        (0.12 + 0.08 * rng.uniform(), -0.5 - 0.1 * rng.uniform()), 0.11 + 0.02 * rng.uniform(),
        K_TUBE),)) for _ in range(n)]


@pytest.mark.parametrize("threaded", [False, True])
@pytest.mark.parametrize("self_contact", [None, K_TUBE])
def test_copies_step_as_single_steppers(threaded, self_contact):
    arm = designs.octarm_v()
    n = 5
    template = solver.Scene(base_angle_deg=0.0, self_contact=self_contact,
                            obstacles=(solver.Disc((0.16, -0.55), 0.13, K_TUBE),))
    scenes = _scenes(template, n, seed=1)
    batch = solver.BatchStepper(arm, template, n)
    # The policy picks threads for batches this small only when told to.
    batch.thread_policies["step"].choose = lambda rows: threaded
    walks = [curl_walk(arm, 36, seed=10 + k, drift=0.05 if self_contact else 0.03)
             for k in range(n)]
    batch.reset(np.array([w[0] for w in walks]), scenes=scenes)
    singles = [solver.Stepper(arm, scene) for scene in scenes]
    for stepper, walk in zip(singles, walks):
        stepper.reset(walk[0])
    # The walks, then a jump across the pressure range (the general path's snaps).
    jump = np.array([0.0, 1.0, 0.0, 1.0, 0.0, 1.0]) * arm.max_pressure
    for walk in walks:
        walk.append(jump)
    paths = set()
    for t in range(1, len(walks[0])):
        report = batch.step(np.array([w[t] for w in walks]))
        for k, stepper in enumerate(singles):
            single = stepper.step(walks[k][t])
            paths.add(stepper.last_path)
            assert (single.converged, single.iterations) == (report.converged[k], report.iterations[k])
            np.testing.assert_array_equal(batch.tips[k], stepper.tip)
            np.testing.assert_array_equal(batch.equilibrium(k).positions, stepper.equilibrium.positions)
            np.testing.assert_array_equal(batch.backbones()[k, :, :10], stepper.record[:, :10])
    assert paths == {"lean", "lean contact", "general"}


def test_adopt_fans_one_state_out_and_copies_keep_their_own_obstacles():
    arm = designs.octarm_v()
    template = solver.Scene(base_angle_deg=0.0, obstacles=(solver.Disc((0.16, -0.55), 0.13, K_TUBE),))
    walk = curl_walk(arm, 25, seed=3)
    stepper = solver.Stepper(arm, template)
    stepper.reset(walk[0])
    for p in walk[1:]:
        stepper.step(p)
    batch = solver.BatchStepper(arm, template, 4)
    batch.adopt(stepper.equilibrium)
    np.testing.assert_array_equal(batch.tips, np.repeat(stepper.tip[None], 4, axis=0))
    p = np.clip(walk[-1] + 0.05 * arm.max_pressure, 0, arm.max_pressure)
    batch.step(np.repeat(p[None], 4, axis=0))
    stepper.step(p)
    np.testing.assert_array_equal(batch.tips, np.repeat(stepper.tip[None], 4, axis=0))


def test_bad_copy_scenes_are_named():
    arm = designs.octarm_v()
    template = solver.Scene(base_angle_deg=0.0, obstacles=(solver.Disc((0.16, -0.55), 0.13, K_TUBE),))
    batch = solver.BatchStepper(arm, template, 2)
    p = np.zeros((2, 6))
    with pytest.raises(ValueError, match="stiffness"):
        batch.reset(p, scenes=[template, replace(template, obstacles=(solver.Disc((0.2, -0.5), 0.1, 1e6),))])
    with pytest.raises(ValueError, match="at most 1"):
        batch.reset(p, scenes=[template, replace(template, obstacles=template.obstacles * 2)])
    with pytest.raises(ValueError, match="only in its obstacles"):
        batch.reset(p, scenes=[template, replace(template, payload_kg=0.1)])
    with pytest.raises(ValueError, match="one scene per row"):
        batch.reset(p, scenes=[template])
    with pytest.raises(ValueError, match="rigid contact"):
        solver.BatchStepper(arm, replace(template, obstacles=(solver.Disc((0.2, -0.5), 0.1, np.inf),)), 2)
    with pytest.raises(ValueError, match="max_obstacles"):
        solver.BatchStepper(arm, template, 2, max_obstacles=0)


@needs_two_threads
def test_general_path_rows_run_side_by_side_bit_for_bit():
    """Copies that all snap in one step (the general path) are solved on the CopyPool's
    threads; the batch's states and reports are those of solving them one after another."""
    arm = designs.octarm_v()
    n = 4
    template = solver.Scene(base_angle_deg=0.0, obstacles=(solver.Disc((0.16, -0.55), 0.13, K_TUBE),))
    scenes = _scenes(template, n, seed=2)  # three of the four copies leave the lean paths
    jump = np.tile(np.array([0.0, 1.0, 0.0, 1.0, 0.0, 1.0]) * arm.max_pressure, (n, 1))

    def reset():
        batch = solver.BatchStepper(arm, template, n)
        batch.reset(np.zeros((n, 6)), scenes=scenes)
        return batch

    ((serial, one), serial_threads), ((threaded, two), pool_threads) = by_thread_count(
        lambda batch: (batch.step(jump), batch), solver.BatchStepper, "solve_copy", reset)
    assert serial_threads == 1 and pool_threads >= 2
    assert np.all(serial.converged)
    for field in ("converged", "stable", "snapped", "iterations", "residual"):
        np.testing.assert_array_equal(getattr(serial, field), getattr(threaded, field))
    for k in range(n):
        np.testing.assert_array_equal(one.equilibrium(k).positions, two.equilibrium(k).positions)
    np.testing.assert_array_equal(one.tips, two.tips)


@needs_two_threads
def test_lean_rows_run_side_by_side_bit_for_bit():
    """A threaded batch steps its copies in blocks on the CopyPool's threads, each block one
    call of the one-thread row kernel: the states and reports are those of one call over
    every copy."""
    arm = designs.octarm_v()
    n = 8
    template = solver.Scene(base_angle_deg=0.0, obstacles=(solver.Disc((0.16, -0.55), 0.13, K_TUBE),))
    rng = np.random.default_rng(4)  # discs on the side the walks curl to: most copies press on theirs
    scenes = [replace(template, obstacles=(solver.Disc(
        (-0.16 + 0.04 * rng.uniform(), -0.5 - 0.1 * rng.uniform()), 0.11 + 0.02 * rng.uniform(),
        K_TUBE),)) for _ in range(n)]
    walks = [curl_walk(arm, 12, seed=20 + k, drift=0.03) for k in range(n)]

    def reset():
        batch = solver.BatchStepper(arm, template, n)
        batch.thread_policies["step"].choose = lambda rows: True  # threads for a batch this small
        batch.reset(np.array([w[0] for w in walks]), scenes=scenes)
        return batch

    def walk(batch):
        reports, touching = [], 0
        for t in range(1, len(walks[0])):
            reports.append(batch.step(np.array([w[t] for w in walks])))
            touching += int(np.sum(batch.contact_measures()[:, 1] > 0))
        return (reports, touching), batch

    (((serial, touching), one), serial_threads), (((threaded, _), two), pool_threads) = \
        by_thread_count(walk, stepping, "contact_rows", reset)
    assert serial_threads == 1 and pool_threads >= 2
    assert touching >= 4 * n  # (copy-steps pressing on their discs: the lean contact step ran)
    for a, b in zip(serial, threaded):
        for field in ("converged", "stable", "snapped", "iterations", "residual"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    np.testing.assert_array_equal(one.tips, two.tips)
    np.testing.assert_array_equal(one.backbones(), two.backbones())
