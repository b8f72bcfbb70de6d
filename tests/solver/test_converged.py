"""``converged=True`` never lies: the residual tolerance and the RK4 grid are checked against
the result itself (docs/design.md §11)."""

from dataclasses import replace

import numpy as np
import pytest

import solver
from solver import PSI, designs
from solver._model import pack

ARM = designs.octarm_v()
FINE = solver.Settings(steps_per_section=512)


def _stiffened(arm, factors):
    """``arm`` with each section's EI and GJ multiplied by ``factors``."""
    return replace(arm, sections=tuple(replace(s, EI=s.EI * f, GJ=s.GJ * f)
                                       for s, f in zip(arm.sections, factors)))


def test_moment_scale_is_the_sections_in_series():
    arm = _stiffened(ARM, (1e11 / ARM.sections[0].EI, 1.0, 1.0))
    packed = pack(arm, "full", solver.Settings())
    assert packed.moment_scale == pytest.approx(1.0 / sum(s.length / s.EI for s in arm.sections))
    assert packed.moment_scale < min(s.EI / s.length for s in arm.sections)


@pytest.mark.parametrize("ei", [1e10, 1e11])
def test_a_stiff_section_hides_no_residual(ei):
    """Issue #19: section 1 at EI = 1e10–1e11 N m² once converged 39–313 mm off, its residual
    (1.38 N m) under a tolerance scaled by EI_max/L; solve_batch agreed with it."""
    arm = _stiffened(ARM, (ei / ARM.sections[0].EI, 1.0, 1.0))
    p = np.array([30, 0, 30, 0, 30, 0]) * PSI
    scene = solver.Scene(base_angle_deg=90)
    eq = solver.solve(arm, p, scene)
    fine = solver.solve(arm, p, scene, settings=FINE, record=False)
    assert eq.converged and fine.converged
    assert eq.residual < 1e-9
    np.testing.assert_allclose(eq.tip, [0.502, -0.475], atol=1e-3)
    assert np.linalg.norm(eq.tip - fine.tip) < 1e-6 * arm.length
    tips, ok = solver.solve_batch(arm, p[None], scene)
    assert ok[0] and tips[0].tolist() == eq.tip.tolist()


def test_a_grid_too_coarse_for_the_load_is_refined():
    """Issue #19: 100 N m at OctArm V's tip turns the default grid 5 rad a step (8e-3·L off);
    the solve refines to 128 steps where needed and returns the settings' samples."""
    scene = solver.Scene(tip_moment=100.0)
    eq = solver.solve(ARM, np.zeros(6), scene)
    fine = solver.solve(ARM, np.zeros(6), scene, settings=FINE, record=False)
    assert eq.converged and fine.converged
    assert np.linalg.norm(eq.tip - fine.tip) < 1e-6 * ARM.length
    assert eq.s.size == 3 * 17 and eq.section_ends == (16, 33, 50)
    np.testing.assert_allclose(eq.positions[-1], eq.tip)
    tips, ok = solver.solve_batch(ARM, np.zeros((2, 6)), scene)
    assert ok.all() and tips[0].tolist() == eq.tip.tolist()
    # Without room to refine, the same solve says it did not converge.
    pinned = solver.solve(ARM, np.zeros(6), scene, settings=solver.Settings(max_refinement=1))
    assert not pinned.converged and pinned.residual < 1e-9


def test_a_load_beyond_the_finest_grid_is_unconverged():
    """1,000 N m curls OctArm V's last section through 137 turns: 0.84 rad a step even at
    64× the default grid."""
    scene = solver.Scene(tip_moment=1000.0)
    eq = solver.solve(ARM, np.zeros(6), scene)
    assert not eq.converged and np.all(np.isfinite(eq.positions))
    with pytest.raises(solver.SolverError):
        solver.solve(ARM, np.zeros(6), scene, strict=True)
    assert not solver.solve_batch(ARM, np.zeros((1, 6)), scene)[1][0]


def test_steppers_refine_as_solve_does():
    """A lean step the default grid cannot resolve is taken by the general path (refined):
    the same equilibrium as a warm solve, and the batch copy the same bits."""
    scene = solver.Scene(base_angle_deg=90, tip_moment=60.0)
    stepper = solver.Stepper(ARM, scene)
    batch = solver.BatchStepper(ARM, scene, n=1)
    p = np.array([[0, 0, 0, 0, 0, 0], [40, 0, 0, 60, 0, 30]]) * PSI
    assert stepper.lean and stepper.reset(p[0]).converged
    batch.reset(p[:1])
    warm = stepper.equilibrium
    report = stepper.step(p[1])
    eq = solver.solve(ARM, p[1], scene, warm_start=warm)
    assert report.converged and eq.converged
    np.testing.assert_allclose(stepper.tip, eq.tip, atol=1e-9)
    assert batch.step(p[1:]) == tuple(np.array([v]) for v in report)
    np.testing.assert_array_equal(batch.records[0], stepper.record)
