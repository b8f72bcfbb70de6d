"""Coulomb friction in self-contact (``Scene(self_contact=k, self_friction=μ)``,
docs/design.md §9.1): the obstacles' return mapping at every point of the self-contact law,
anchored to the partner's material point.

Oracles that do not trust the friction code:
- action and reaction: the pairs carry no net force or moment, so the base reaction is the
  dead loads' and the global moment balance of ``softarm stress`` holds, as without friction;
- dissipation never negative, and never decreasing, along a load–unload–reload path;
- μ → 0 tends to the frictionless state, linearly;
- the mirrored scene gives the mirrored answer;
- slip threshold, flat on flat: a hairpin's upper layer lying on its lower one, pulled along
  them, sticks while the pull is small (the tip moves < 0.1 × the frictionless tip) and
  slides at F = μN past 1.2 μN, F and N the contact's resultant on the upper layer from
  its statics (the cut's internal force, the tip load, its weight), split along the
  layers; μ = 0 slides at once and reads F ≈ 0 (the split's resolution).
"""

import math

import numpy as np
import pytest

import solver
from softarm_gym.benchmarks.friction_bench import (
    fold_hairpin,
    hairpin_forces,
    hairpin_pressures,
    hairpin_scene,
)
from softarm_gym.benchmarks.stress import moment_balance_error
from solver import layout as L
from solver.kernels.self_contact import backbone_crosses
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


def _hairpin_pulls(steps):
    """The hairpin (``friction_bench.hairpin``) laid on itself with μ = 0.5 and without
    friction at ``steps`` RK4 steps per section, then pulled along its layers from 0.1 to
    2 μN₀ (N₀ the normal force at no pull, μ = 0.5 for both): per μ, (pull, friction,
    normal, spread, tip x) of the laid state and every pull."""
    settings = solver.Settings(steps_per_section=steps)
    out = {}
    for mu in (0.5, 0.0):
        arm, path = fold_hairpin(mu, settings)
        for eq in path:
            assert eq.converged and eq.stable and not eq.snapped
        eq = path[-1]
        _, n0, _ = hairpin_forces(eq, 0.0)
        rows = [(0.0, *hairpin_forces(eq, 0.0), eq.tip[0])]
        for pull in np.linspace(0.1, 2.0, 20) * 0.5 * n0:
            eq = solver.solve(arm, hairpin_pressures(), hairpin_scene(mu, pull), warm_start=eq,
                              settings=settings)
            assert eq.converged and eq.stable and not eq.snapped, (mu, pull)
            rows.append((pull, *hairpin_forces(eq, pull), eq.tip[0]))
        out[mu] = np.array(rows)
    return out


# The finer grid checks the tolerance's resolution (24 s: run after make test, with the long oracles).
@pytest.mark.parametrize("steps", [16, pytest.param(32, marks=pytest.mark.long_oracle)])
def test_a_fold_laid_on_itself_slips_at_mu_times_the_normal_force(steps):
    """Flat on flat: a hairpin's heavy upper layer lies on its stiff lower layer, pulled
    along them at its tip (default settings, 16 and 32 RK4 steps a section). From the
    statics of the upper layer (the internal force where it leaves the fold, less the tip
    force and its weight) the contact's resultant, split along the layers, is friction F and
    normal force N: F ≤ μN all along; while the pull is below 0.8 μN the upper layer sticks
    (the tip moves less than a tenth of the frictionless layer's, which slides at once, held
    by the fold alone, and friction takes over 90 % of each added pull); past 1.2 μN it
    slides, F = μN. The tolerance is the resolution of the split: the touching samples'
    tangents spread by ``spread`` (2.4e-3–2.8e-3 rad at 16 steps, 5.2e-3–5.7e-3 at 32: the
    layers bend under the load), so F/μN is defined to spread/μ; frictionless, the split
    reads |F| ≤ 1e-3 N."""
    pulls = _hairpin_pulls(steps)
    rows, free = pulls[0.5], pulls[0.0]
    pull, friction, normal, spread, tip = rows.T
    mu = 0.5
    assert np.all(normal > 0.8) and np.all(spread < 1e-2)
    ratio = friction / (mu * normal)
    assert np.all(ratio <= 1.0 + spread / mu)
    sticking = pull[1:] < 0.8 * mu * normal[1:]
    moved, moved_free = np.abs(np.diff(tip)), np.abs(np.diff(free[:, 4]))
    assert sticking.sum() >= 6
    assert np.all(moved[sticking] < 0.1 * moved_free[sticking])
    took = np.diff(friction) / np.diff(pull)
    assert np.all(took[sticking] > 0.9)
    sliding = pull > 1.2 * mu * normal
    assert sliding.sum() >= 8
    assert np.all(np.abs(ratio[sliding] - 1.0) < spread[sliding] / mu)
    assert np.all(moved[sliding[1:]] > 0.3 * moved_free[sliding[1:]])
    # frictionless: nothing holds the layer along the contact
    assert np.all(np.abs(free[:, 1]) < 1e-3 * free[:, 2])


def test_a_snap_does_not_land_the_hairpin_through_itself():
    """Issue #38: with a small Newton budget (``max_iter=6``) the hairpin's path stalls at
    the tenth pull (1.0 μN₀), takes the stall for a fold and snaps; the snap's stiffening
    stages dropped the upper layer through the lower one (converged, stable, ``snapped``, no
    contact left, the tip 17 cm below the clamp's line). A landing whose backbone crosses
    itself is refused now: every pull reported converged keeps the layers touching and its
    backbone uncrossed, and the pull that stalls is reported unconverged."""
    mu = 0.5
    settings = solver.Settings(max_iter=6)
    arm, path = fold_hairpin(mu, settings)
    eq = path[-1]
    assert eq.converged and eq.stable and not eq.snapped
    _, n0, _ = hairpin_forces(eq, 0.0)
    done = 0
    for pull in np.linspace(0.1, 2.0, 20) * mu * n0:
        eq = solver.solve(arm, hairpin_pressures(), hairpin_scene(mu, pull), warm_start=eq,
                          settings=settings)
        if not eq.converged:
            break
        done += 1
        upper = np.arange(eq.section_ends[1] + 1, eq.s.size)
        assert (eq.penetration[upper] > 0).any(), pull / (mu * n0)
        assert not backbone_crosses(np.ascontiguousarray(eq.positions[:, :2]), eq.s)
        assert eq.tip[1] > 0.0  # the upper layer lies above the lower one's line (y = 0)
    assert done >= 9  # the pulls up to where the path stalls (0.99 μN₀)
