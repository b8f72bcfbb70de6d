"""The snap relaxation's minimiser (solver.kernels.relax.minimise) against scipy's L-BFGS-B,
an independent minimiser, on the energy of a real snap."""

import numpy as np
import pytest
import scipy.optimize

import solver
from solver import PSI, designs
from solver.kernels import relax as relax_kernels


@pytest.fixture(scope="module")
def snap_relaxations():
    """The minimiser's inputs (start, scales, energy arguments) of every relaxation in a step
    of OctArm V curled round a disc at its base and switched to channels I of sections 1 and 2,
    on which the arm snaps off the disc."""
    captured = []
    minimise = relax_kernels.minimise

    def spy(y, scale, args, max_iter, gtol):
        captured.append((y.copy(), scale.copy(), args, max_iter, gtol))
        return minimise(y, scale, args, max_iter, gtol)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(relax_kernels, "minimise", spy)
        arm = designs.octarm_v()
        disc = solver.Disc(center=(-0.1596, -0.0616), radius=0.1493, stiffness=9.8e4)
        start = np.array([1, 1, 0, 1, 1, 0]) * 100 * PSI
        scene = solver.Scene(obstacles=(disc,))
        eq = solver.solve(arm, start, scene, warm_start=solver.solve(arm, start, solver.Scene()))
        eq = solver.solve(arm, np.array([1, 0, 1, 0, 0, 0]) * 100 * PSI, scene, warm_start=eq)
    assert eq.converged and eq.snapped and captured, "the step no longer snaps: choose another"
    return captured


def test_the_minimiser_lands_where_scipys_lbfgsb_does(snap_relaxations):
    for y0, scale, args, max_iter, gtol in snap_relaxations:
        grad = np.empty_like(y0)

        def energy(y, scale=scale, args=args, grad=grad):
            value = relax_kernels.energy_and_gradient(y * scale, *args, grad)
            return value, grad * scale

        ours = y0.copy()
        value, iterations, _ = relax_kernels.minimise(ours, scale, args, max_iter, gtol)
        theirs = scipy.optimize.minimize(energy, y0, jac=True, method="L-BFGS-B",
                                         options={"maxiter": max_iter, "gtol": gtol, "ftol": 0.0})
        assert 0 < iterations < max_iter
        # The same basin's floor: energies equal to rounding, the unknowns (angles in rad,
        # strains) to well below what the Newton polish corrects, and a vanishing gradient.
        assert value == pytest.approx(energy(ours)[0], rel=1e-15)
        assert value <= theirs.fun + 1e-12 * abs(theirs.fun)
        np.testing.assert_allclose(ours * scale, theirs.x * scale, rtol=0, atol=1e-6)
        assert np.abs(energy(ours)[1]).max() < 1e-6
        assert energy(y0)[0] - value > 1e3 * (abs(value) * 1e-12)  # it did go downhill
