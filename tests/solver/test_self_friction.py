"""Coulomb friction in self-contact (``Scene(self_contact=k, self_friction=μ)``,
docs/design.md §9.1): the obstacles' return mapping at every point of the self-contact law,
anchored to the partner's material point.

Oracles that do not trust the friction code:
- action and reaction: the pairs carry no net force or moment, so the base reaction is the
  dead loads' and the global moment balance of ``softarm stress`` holds, as without friction;
- dissipation never negative, and never decreasing, along a load–unload–reload path;
- μ → 0 tends to the frictionless state, linearly;
- the mirrored scene gives the mirrored answer;
- stick then slip: a tangential tip load on a curl pressed on itself is held by friction
  while it is small (the tip barely moves) and slides the contact past μ × the contact's
  normal force (the samples on the cone).
"""

import math

import numpy as np
import pytest

import solver
from softarm_gym.benchmarks.stress import moment_balance_error
from solver import layout as L
from solver.problem import context, pack

ARM = solver.designs.octarm_v()
RING = min(t.material.ring_stiffness for t in ARM.tubes)
# Channel I of every section at the rated 100 psi: the arm curls past a full turn.
CURL = np.where(np.arange(ARM.n_inputs(True)) % 2 == 0, ARM.max_pressure, 0.0)


def _scene(mu, **kw):
    return solver.Scene(self_contact=RING, self_friction=mu, **kw)


def _ramp(scene, pressures=CURL, steps=8, eq=None):
    """Warm solves from the unactuated arm (or ``eq``) to ``pressures`` in ``steps``."""
    if eq is None:
        eq = solver.solve(ARM, np.zeros(ARM.n_inputs(True)), scene)
    start = eq.pressures if eq.pressures.size else np.zeros(ARM.n_inputs(True))
    path = []
    for fraction in np.linspace(1.0 / steps, 1.0, steps):
        eq = solver.solve(ARM, start + fraction * (pressures - start), scene, warm_start=eq)
        assert eq.converged and eq.stable, fraction
        path.append(eq)
    return path


@pytest.fixture(scope="module")
def curled():
    """The curl ramped in with μ = 0.5 and without friction."""
    return {mu: _ramp(_scene(mu))[-1] for mu in (0.0, 0.5)}


@pytest.mark.parametrize("value", [-0.1, math.nan, math.inf, "0.5", True])
def test_scene_rejects_a_bad_self_friction(value):
    with pytest.raises(ValueError, match="Scene.self_friction"):
        _scene(value)


def test_self_friction_needs_self_contact():
    with pytest.raises(ValueError, match="Scene.self_friction.*self-contact"):
        solver.Scene(self_friction=0.5)
    assert solver.Scene(self_friction=0.0).self_friction == 0.0
    assert _scene(0.5).without_contact == solver.Scene()


def test_friction_acts_and_its_pairs_carry_no_net_force_or_moment(curled):
    """Self-contact friction is internal: the base reaction is still the dead loads'
    exactly and the independent moment balance about the base holds — which it would not if
    the pair's forces acted on the backbones alone (a couple of the arm's thickness × the
    friction) or a reaction were missing."""
    eq = curled[0.5]
    fs = eq.self_friction_samples
    assert fs.ndim == 4 and fs.shape[2:] == (solver.kernels.self_contact.SUBPOINTS, L.N_FS)
    impulses = np.hypot(fs[..., L.FS_F], fs[..., L.FS_F + 1])
    assert impulses.sum() > 0.05  # N: friction acts ...
    assert np.abs(eq.tip - curled[0.0].tip).max() > 1e-4  # ... and changes the answer (m)
    settings = solver.Settings()
    dead = context(ARM, pack(ARM, "full", settings), solver.Scene(), 2, settings).base_force
    np.testing.assert_allclose(eq.base_force, dead, atol=1e-9 * np.abs(dead).max())
    assert moment_balance_error(ARM, solver.Scene(), eq) < 1e-5
    np.testing.assert_allclose(np.trapezoid(eq.contact_force, eq.s, axis=0), 0.0, atol=1e-9)


def test_dissipation_is_never_negative_along_a_path():
    """Load, unload half way, reload: the dissipated energy never decreases, every sample's
    work is ≥ 0, and unloading a curl held by friction dissipates (it slides back)."""
    scene = _scene(0.5)
    path = _ramp(scene, steps=6)
    path += _ramp(scene, 0.5 * CURL, steps=4, eq=path[-1])
    path += _ramp(scene, CURL, steps=4, eq=path[-1])
    dissipated = np.array([eq.dissipated for eq in path])
    assert np.all(dissipated >= 0.0)
    assert np.all(np.diff(dissipated) >= 0.0)
    assert dissipated[-1] > dissipated[5] > 0.0
    for eq in path:  # (a state clear of contact, from the contact-free shortcut, has none)
        fs = eq.self_friction_samples
        assert fs.size == 0 or np.all(fs[..., L.FS_WORK] >= 0.0)
        assert fs.size == 0 or np.all(fs[..., L.FS_SLIP] >= 0.0)


def test_small_friction_tends_to_the_frictionless_state(curled):
    """μ → 0: the state tends to the frictionless one, linearly in μ."""
    free = curled[0.0]
    gaps = []
    for mu in (1e-2, 1e-3):
        eq = _ramp(_scene(mu))[-1]
        gaps.append(np.abs(eq.positions - free.positions).max())
    assert gaps[0] < 2e-3 * ARM.length
    assert 5.0 < gaps[0] / gaps[1] < 20.0


def _moment_curl(sign):
    """The unactuated arm mounted 10° off the vertical, curled onto itself by a tip moment
    ramped to 4 N m (its mirror image in the vertical plane: ``sign`` −1)."""
    zero = np.zeros(ARM.n_inputs(True))
    eq = solver.solve(ARM, zero, _scene(0.5, base_angle_deg=10.0 * sign))
    for fraction in np.linspace(0.125, 1.0, 8):
        scene = _scene(0.5, base_angle_deg=10.0 * sign, tip_moment=4.0 * fraction * sign)
        eq = solver.solve(ARM, zero, scene, warm_start=eq)
        assert eq.converged and eq.stable
    return eq


def test_mirrored_scene_gives_the_mirrored_answer():
    """The arm curled onto itself by a tip moment, and its mirror image (mounting angle and
    moment of the other sign: the planar channels are not mirror images of each other): the
    mirrored state to 1e-9·L, the mirrored friction impulses, the same dissipation."""
    ref = _moment_curl(1.0)
    eq = _moment_curl(-1.0)
    assert ref.in_contact and ref.dissipated > 0.0
    np.testing.assert_allclose(eq.positions[:, 0], -ref.positions[:, 0], atol=1e-9 * ARM.length)
    np.testing.assert_allclose(eq.positions[:, 1], ref.positions[:, 1], atol=1e-9 * ARM.length)
    a, b = eq.self_friction_samples, ref.self_friction_samples
    # An impulse is the tangential spring's k·w (~200 N/m a sample) times a slip, which
    # the solves fix to their tolerance: 1e-9·L of position is ~2e-7 N of impulse.
    np.testing.assert_allclose(a[..., L.FS_F], -b[..., L.FS_F], atol=2e-7)
    np.testing.assert_allclose(a[..., L.FS_F + 1], b[..., L.FS_F + 1], atol=2e-7)
    assert np.abs(b[..., L.FS_F:L.FS_F + 2]).max() > 0.01
    assert eq.dissipated == pytest.approx(ref.dissipated, rel=1e-6, abs=1e-12)


def test_steppers_carry_the_tangential_state_on_the_lean_path():
    """A Stepper walking the curl up, half down and up again in a self-friction scene: its
    lean contact path takes the steps where parts touch, the dissipation never decreases,
    the pairs still carry no net force or moment; and a BatchStepper's copy steps bit for
    bit as the Stepper (one kernel for both)."""
    scene = _scene(0.5)
    walk = [f * CURL for f in np.linspace(0.0, 1.0, 13)]
    walk += [f * CURL for f in np.linspace(0.9, 0.5, 5)] + [f * CURL for f in np.linspace(0.6, 1.0, 5)]
    stepper = solver.Stepper(ARM, scene)
    batch = solver.BatchStepper(ARM, scene, 2)
    stepper.reset(walk[0])
    batch.reset(np.array([walk[0]] * 2))
    paths, dissipated = [], []
    for p in walk[1:]:
        report = stepper.step(p)
        batch_report = batch.step(np.array([p, p]))
        assert report.converged and batch_report.converged.all()
        paths.append(stepper.last_path)
        eq = stepper.equilibrium
        dissipated.append(eq.dissipated)
        for k in range(2):
            np.testing.assert_array_equal(batch.equilibrium(k).positions, eq.positions)
            assert batch.equilibrium(k).dissipated == eq.dissipated
    assert "lean contact" in paths
    assert np.all(np.diff(dissipated) >= 0.0) and dissipated[-1] > 0.0
    assert eq.self_friction_samples.shape[0] > 0
    assert moment_balance_error(ARM, solver.Scene(), eq) < 1e-5
