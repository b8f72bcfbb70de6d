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
    start = eq.channel_pressures if eq.channel_pressures.size else np.zeros(ARM.n_inputs(True))
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
    assert np.abs(eq.tip - curled[0.0].tip).max() > 1e-3  # ... and changes the answer
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
    for eq in path:
        assert np.all(eq.self_friction_samples[..., L.FS_WORK] >= 0.0)
        assert np.all(eq.self_friction_samples[..., L.FS_SLIP] >= 0.0)


def test_small_friction_tends_to_the_frictionless_state(curled):
    """μ → 0: the state tends to the frictionless one, linearly in μ."""
    free = curled[0.0]
    gaps = []
    for mu in (1e-2, 1e-3):
        eq = _ramp(_scene(mu))[-1]
        gaps.append(np.abs(eq.positions - free.positions).max())
    assert gaps[0] < 2e-3 * ARM.length
    assert 5.0 < gaps[0] / gaps[1] < 20.0


def test_mirrored_scene_gives_the_mirrored_answer(curled):
    """Channels II in place of I (the mirror image in the arm's vertical plane): the
    mirrored state, to 1e-9·L, its anchors, impulses and dissipation with it."""
    mirror = np.where(np.arange(ARM.n_inputs(True)) % 2 == 1, ARM.max_pressure, 0.0)
    eq = _ramp(_scene(0.5), mirror)[-1]
    ref = curled[0.5]
    np.testing.assert_allclose(eq.positions[:, 0], -ref.positions[:, 0], atol=1e-9 * ARM.length)
    np.testing.assert_allclose(eq.positions[:, 1], ref.positions[:, 1], atol=1e-9 * ARM.length)
    a, b = eq.self_friction_samples, ref.self_friction_samples
    np.testing.assert_allclose(a[..., L.FS_F], -b[..., L.FS_F], atol=1e-9)
    np.testing.assert_allclose(a[..., L.FS_F + 1], b[..., L.FS_F + 1], atol=1e-9)
    assert eq.dissipated == pytest.approx(ref.dissipated, rel=1e-6, abs=1e-12)
