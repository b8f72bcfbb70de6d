"""The deepest penetration between samples (``Equilibrium.peak_penetration``), against the
sampled depth of fine-resolution solves, which converges to it; and the rigid continuation's
stopping rule on it (docs/design.md §9, "Penetration")."""

import math

import numpy as np
import pytest

import solver
from solver import PSI, designs

ARM = designs.octarm_v()
ROD = designs.rod(length=1.0, EI=1.0, EA=1e3, GA=1e3, GJ=0.7)
PUSHED = dict(base_angle_deg=90, gravity=0.0, tip_force=(0.0, -3.0, 0.5))
SMALL_DISC = solver.Disc((0.07, -0.70), 0.05, 2e4)  # a patch of about an RK4 step
FINE = solver.Settings(steps_per_section=512)
DEFAULT = solver.Settings()


def _solve(arm, scene, planar, settings=DEFAULT):
    if arm is ARM:
        p = np.array([0, 0, 0, 0, 0, 100]) * PSI
        if not planar:
            p = solver.channel_pressures(arm, p)
    else:
        p = np.zeros(arm.n_inputs(planar))
    eq = solver.solve(arm, p, scene, planar=planar, settings=settings)
    assert eq.converged and eq.in_contact
    return eq


def _sampled_vertex(eq):
    """The vertex of the parabola through ``eq``'s deepest sample and its two neighbours
    (equally spaced, all inside the obstacle): the depth's maximum from the samples alone.

    Even 512 steps do not put a sample on the deepest point: near it the depth along the
    backbone is a parabola of curvature c of the order of the surface's 1/R, so samples ds
    apart can fall up to c·ds²/8 below its vertex. From the 512-step samples' second
    differences c = 5.5 1/m on the sphere (R = 0.2 m) and 5.8 1/m on the cylinder
    (R = 0.15 m) at ds = 1.95 mm, a bound of 2.6 and 2.8 µm (the samples fall 1.6 and 2.4 µm
    short); 19.5 1/m on the small disc (R = 0.05 m) at 0.59 mm, 0.8 µm. The parabola's own
    error is of order ds³: nanometres."""
    depth = eq.penetration
    k = int(np.argmax(depth))
    a, b, c = depth[k - 1:k + 2]
    assert a > 0 and c > 0
    assert np.diff(eq.s)[k - 1] == pytest.approx(np.diff(eq.s)[k], rel=1e-12)
    return b - (c - a) ** 2 / (8 * (a + c - 2 * b))


@pytest.mark.parametrize("arm, scene, planar", [
    (ARM, solver.Scene(obstacles=(SMALL_DISC,)), True),
    (ARM, solver.Scene(obstacles=(SMALL_DISC,)), False),
    (ROD, solver.Scene(**PUSHED, obstacles=(solver.Sphere((0.7, -0.3, 0.12), 0.2, 2e3),)), False),
    (ROD, solver.Scene(**PUSHED, obstacles=(
        solver.Cylinder((0.6, -0.3, 0.0), (1.0, 0.3, 1.0), 0.15, 2e3),)), False),
], ids=["disc", "disc_in_3d", "sphere", "cylinder"])
def test_peak_between_samples_matches_a_fine_solve(arm, scene, planar):
    """At the default resolution the samples miss the deepest point by 0.07–2 mm (a contact
    patch about a step long, or narrower than the steps on a sphere); the peak of the curves
    between them is the fine solve's (512 RK4 steps per section: its peak within 1 µm of the
    vertex of the parabola through its deepest samples, :func:`_sampled_vertex`) to the
    default grid's own error (the state moves by a few µm)."""
    coarse = _solve(arm, scene, planar)
    fine = _solve(arm, scene, planar, FINE)
    truth = _sampled_vertex(fine)
    assert fine.penetration.max() <= truth
    assert fine.peak_penetration == pytest.approx(truth, abs=1e-6)
    assert coarse.penetration.max() < truth - 5e-5  # the samples alone miss it
    assert coarse.peak_penetration == pytest.approx(truth, abs=1e-5)
    assert coarse.peak_penetration >= coarse.penetration.max()


def test_peak_with_self_contact():
    """The curled arm pressed on itself: the peak is at least every sample's depth and is the
    fine solve's sampled depth to the default grid's error."""
    curl = np.where(np.arange(ARM.n_inputs(True)) % 2 == 0, ARM.max_pressure, 0.0)
    ring = min(t.material.ring_stiffness for t in ARM.tubes)
    scene = solver.Scene(self_contact=ring)
    coarse = solver.solve(ARM, curl, scene)
    fine = solver.solve(ARM, curl, scene, settings=solver.Settings(steps_per_section=64))
    assert coarse.converged and fine.converged and coarse.in_contact
    assert coarse.peak_penetration >= coarse.penetration.max() > 0
    assert coarse.peak_penetration == pytest.approx(fine.penetration.max(), abs=1e-5)


def test_no_contact_and_unrecorded():
    free = solver.solve(ARM, np.zeros(6), solver.Scene())
    assert free.peak_penetration == 0.0
    far = solver.solve(ARM, np.zeros(6), solver.Scene(obstacles=(solver.Disc((5, 5), 0.1),)))
    assert far.peak_penetration == 0.0
    blind = solver.solve(ARM, np.array([0, 0, 0, 0, 0, 100]) * PSI,
                         solver.Scene(obstacles=(SMALL_DISC,)), record=False)
    assert math.isnan(blind.peak_penetration)


def test_rigid_continuation_stops_on_the_true_peak():
    """A rigid disc met by a patch narrower than the steps: at a gap tolerance of 35 µm the
    sampled depth (33 µm) would stop the continuation a stage early, with the true peak at
    37 µm. It goes on until the peak is within the tolerance — checked on a fine solve of
    the same penalty, whose samples resolve the patch.

    The stage it stops at (k = 1.2e8 N/m²) presses a patch of about 2 mm (depth 9 µm on the
    disc of radius 5 cm) with steps of 3.7 mm (the contact grid's, half the decay length):
    whether a sample falls inside it is up to the grid — here none does, and
    ``in_contact``, which reads the samples, is False — so the contact is asserted on the
    peak."""
    tol = 3.5e-5
    scene = solver.Scene(obstacles=(solver.Disc((0.07, -0.70), 0.05, math.inf),))
    eq = solver.solve(ARM, np.array([0, 0, 0, 0, 0, 100]) * PSI, scene,
                      settings=solver.Settings(gap_tol=tol))
    assert eq.converged and 0 < eq.peak_penetration <= tol
    same = solver.Scene(obstacles=(solver.Disc((0.07, -0.70), 0.05, eq.penalty_stiffness),))
    assert _solve(ARM, same, True, FINE).penetration.max() <= tol
    softer = solver.Scene(obstacles=(
        solver.Disc((0.07, -0.70), 0.05, eq.penalty_stiffness / 10),))
    stage = _solve(ARM, softer, True)
    assert stage.penetration.max() <= tol < stage.peak_penetration  # where the samples stopped
