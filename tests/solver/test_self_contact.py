"""Self-contact (``Scene(self_contact=k)``): a curled arm presses on itself instead of passing
through, by a law whose pairs carry no net force or moment."""

import math

import numpy as np
import pytest

import solver
from softarm_gym.benchmarks.stress import moment_balance_error
from solver.problem import context, pack

ARM = solver.designs.octarm_v()
# The outer tubes' ring stiffness: the penalty the wrap env gives contact (N/m²).
RING = min(t.material.ring_stiffness for t in ARM.tubes)
# Channel I of every section at the rated 100 psi: the arm curls past a full turn.
CURL = np.where(np.arange(ARM.n_inputs(True)) % 2 == 0, ARM.max_pressure, 0.0)
WRAPPED = solver.Disc(center=(-0.16, -0.062), radius=0.119 + 0.0302, stiffness=2e4)


def far_gap(eq, arm=ARM):
    """The smallest surface gap (m; negative: overlap) between backbone samples farther apart
    along the arc than the self-contact exclusion, from the recorded shape alone."""
    half = np.array(arm.half_thickness())
    section = np.minimum(np.searchsorted(np.asarray(eq.section_ends), np.arange(eq.s.size)),
                         half.size - 1)
    h = half[section]
    gap = np.hypot(*(eq.positions[:, None] - eq.positions[None, :]).transpose(2, 0, 1)) \
        - h[:, None] - h[None, :]
    far = np.abs(eq.s[:, None] - eq.s[None, :]) > solver.scene.SELF_CONTACT_EXCLUSION * 2 * half.max()
    return float(gap[far].min())


def _ramp(scene, steps=10):
    eq = solver.solve(ARM, np.zeros(ARM.n_inputs(True)), scene)
    for fraction in np.linspace(1.0 / steps, 1.0, steps):
        eq = solver.solve(ARM, fraction * CURL, scene, warm_start=eq)
        assert eq.converged and eq.stable, fraction
    return eq


@pytest.mark.parametrize("obstacles", [(), (WRAPPED,)], ids=["free", "wrapping_a_disc"])
def test_curled_arm_does_not_pass_through_itself(obstacles):
    """All channels I at 100 psi: without self-contact the arm's middle sinks 35 mm into its
    base; with it the overlap is the penalty's give, within the wrap env's 5 mm tolerance,
    whether ramped there or solved cold (the same equilibrium). The overlap is measured on
    the recorded shape, not read off the solver's penetration."""
    through = solver.solve(ARM, CURL, solver.Scene(obstacles=obstacles))
    assert through.converged and far_gap(through) < -0.02
    scene = solver.Scene(obstacles=obstacles, self_contact=RING)
    ramped = _ramp(scene)
    cold = solver.solve(ARM, CURL, scene)
    assert cold.converged and cold.stable
    np.testing.assert_allclose(cold.tip, ramped.tip, atol=1e-8)
    for eq in (ramped, cold):
        assert eq.in_contact
        assert -0.005 < far_gap(eq) < 0.0


def test_self_contact_pairs_carry_no_net_force_or_moment():
    """Contact between parts of the arm is internal: the base reaction is the dead loads'
    (exactly, not to a quadrature), and the base moment balances the external loads by the
    independent global check of ``softarm stress``."""
    settings = solver.Settings()
    for payload in (0.0, 0.2):
        scene = solver.Scene(payload_kg=payload, self_contact=RING)
        eq = solver.solve(ARM, CURL, scene)
        assert eq.converged and eq.in_contact
        dead = context(ARM, pack(ARM, "full", settings), solver.Scene(payload_kg=payload), 2,
                       settings).base_force
        np.testing.assert_allclose(eq.base_force, dead, atol=1e-9 * np.abs(dead).max())
        assert moment_balance_error(ARM, solver.Scene(payload_kg=payload), eq) < 1e-5
        # The recorded load per length integrates to zero as well.
        np.testing.assert_allclose(np.trapezoid(eq.contact_force, eq.s, axis=0), 0.0, atol=1e-9)
        assert np.abs(eq.contact_force).max() > 10.0  # ... while it is far from zero locally


def test_stiffer_penalties_converge_to_hard_contact():
    """Stiffer penalties approach hard contact: the overlap shrinks (as k^-½ or so here: the
    arm's middle presses on its base, whose end makes the patch widen as it sinks) and the
    shape settles — each tenfold stiffening moves the tip less than the one before."""
    pens, tips = [], []
    for k in (RING, 10 * RING, 100 * RING):
        eq = solver.solve(ARM, CURL, solver.Scene(self_contact=k))
        assert eq.converged and eq.stable
        pens.append(eq.penetration.max())
        tips.append(eq.tip)
    assert pens[0] > 2 * pens[1] > 4 * pens[2] > 0
    assert np.linalg.norm(tips[2] - tips[1]) < 0.5 * np.linalg.norm(tips[1] - tips[0])


def test_rigid_self_contact_meets_the_gap_tolerance():
    """``self_contact=math.inf``: penalty continuation until the deepest overlap is below
    ``Settings.gap_tol`` (0.1 mm), the state the stiff penalties were converging to."""
    eq = solver.solve(ARM, CURL, solver.Scene(self_contact=math.inf))
    assert eq.converged and eq.stable
    assert 0.0 < eq.penetration.max() <= solver.Settings().gap_tol
    assert far_gap(eq) > -solver.Settings().gap_tol - 1e-6
    stiff = solver.solve(ARM, CURL, solver.Scene(self_contact=100 * RING))
    np.testing.assert_allclose(eq.tip, stiff.tip, atol=5e-3)


def test_self_contact_far_apart_changes_nothing():
    """Where no part comes near another the contact-free equilibrium is returned as it is."""
    p = 0.4 * CURL
    plain = solver.solve(ARM, p, solver.Scene())
    with_self = solver.solve(ARM, p, solver.Scene(self_contact=RING))
    assert with_self.converged and not with_self.in_contact
    np.testing.assert_array_equal(with_self.positions, plain.positions)
    np.testing.assert_array_equal(with_self.contact_force, 0.0)


@pytest.mark.parametrize("value", [0.0, -1.0, -math.inf, math.nan, True, "tube"])
def test_scene_rejects_bad_self_contact(value):
    with pytest.raises(ValueError, match="self_contact"):
        solver.Scene(self_contact=value)


def test_self_contact_is_planar_and_needs_a_rod_model():
    scene = solver.Scene(self_contact=RING)
    with pytest.raises(ValueError, match="planar solves only"):
        solver.solve(ARM, np.zeros(ARM.n_inputs(False)), scene, planar=False)
    with pytest.raises(ValueError, match="constant-curvature"):
        solver.solve(ARM, CURL, scene, model="constant_curvature")


# Self-contact scenes of OctArm V for the resolution test: the curled middle pressing on the
# arm's base end (the scene of issue 35, and others with other pressures, base angles,
# stiffnesses and a payload), and a curl round a disc.
_P = solver.PSI
RESOLUTION_SCENES = {
    "middle_on_base_end": (dict(base_angle_deg=13.44218070001563), 1.0,
                           np.array([90.96475894367777, 0, 90.79741275582431, 0, 89.03072383657893, 0])),
    "full_curl": (dict(), 1.0, np.array([100, 0, 100, 0, 100, 0])),
    "full_curl_payload": (dict(payload_kg=0.2), 1.0, np.array([100, 0, 100, 0, 100, 0])),
    "stiff_tubes": (dict(), 10.0, np.array([100, 0, 100, 0, 100, 0])),
    "tilted_mixed": (dict(base_angle_deg=30.0), 3.0, np.array([95, 0, 100, 0, 85, 0])),
    "round_a_disc": (dict(obstacles=(WRAPPED,)), 1.0, np.array([100, 0, 100, 0, 100, 0])),
}


@pytest.mark.parametrize("name", list(RESOLUTION_SCENES))
def test_self_contact_tip_error_at_default_resolution(name):
    """Where parts of the arm touch, the law is sampled between the RK4 nodes and its geometry
    carries the kinks of the loads (docs/design.md §9, "Resolution"): at the default 16 RK4
    steps per section the tip is within 2e-4·L of a 64-step solve (which is within 2e-5·L of
    a 128-step one on the first scene), and 32 steps are closer still. Before, the curled
    middle pressing on the base end was seen by one or two nodes and the tip was 4e-3·L off."""
    kw, stiffness, psi = RESOLUTION_SCENES[name]
    scene = solver.Scene(self_contact=stiffness * RING, **kw)
    tips = {}
    for steps in (16, 32, 64):
        eq = solver.solve(ARM, psi * _P, scene, settings=solver.Settings(steps_per_section=steps))
        assert eq.converged and eq.stable and eq.in_contact, steps
        tips[steps] = eq.tip
    error = {n: np.linalg.norm(tips[n] - tips[64]) / ARM.length for n in (16, 32)}
    assert error[16] <= 2e-4
    assert error[32] < error[16]
    if name == "middle_on_base_end":
        finer = solver.solve(ARM, psi * _P, scene, settings=solver.Settings(steps_per_section=128))
        assert np.linalg.norm(finer.tip - tips[64]) <= 2e-5 * ARM.length


EXACT = solver.Settings(shortcuts=False)


def _may_touch(eq, arm=ARM):
    """:func:`solver.kernels.self_contact.may_touch` of ``eq``'s shooting nodes, with its tip
    segment's end (the tip) and without."""
    from solver.kernels.self_contact import may_touch
    from solver.paths.shooting import shooting_grid
    from solver.problem import contact_layout, rest_strains
    layout, segs, sec_start = contact_layout(arm, pack(arm, "full", EXACT), eq.scene)
    grid = shooting_grid(arm, eq.scene, layout, segs, sec_start)
    rest = np.vstack(rest_strains(arm, eq.channel_pressures, layout))
    nodes = eq.shooting_nodes
    assert nodes.shape == (6 * (len(segs) - 1) + 3,)
    return (may_touch(nodes, grid, rest, *eq.tip), may_touch(nodes, grid, rest, math.nan, math.nan))


def test_may_touch_never_misses_a_close_pair_and_clears_an_open_arm():
    """The bound that skips self-contact's work is conservative — every state whose far parts
    overlap or come within a centimetre (brute force over the recorded backbone,
    ``far_gap``) is flagged, with the tip known or not — and tight enough to clear an arm
    bent well open, which its segments' midpoint circles alone never did (a pair just beyond
    the exclusion is bounded by its end nodes). States: channel I ramped to the full curl
    (the arm snaps onto itself) and backed off until it springs open, at two mountings."""
    close = cleared = 0
    for angle in (13.44, -30.0):
        scene = solver.Scene(base_angle_deg=angle, self_contact=RING)
        eq = None
        for fraction in np.concatenate([np.linspace(0.0, 1.0, 11), np.linspace(0.98, 0.5, 25)]):
            # (the general path, whose nodes lie on the contact layout)
            eq = solver.solve(ARM, fraction * CURL, scene, warm_start=eq, settings=EXACT)
            assert eq.converged
            with_tip, without = _may_touch(eq)
            assert with_tip <= without  # knowing the tip only tightens it
            gap = far_gap(eq)
            if gap < 0.01:
                assert with_tip, (angle, fraction, gap)
                close += 1
            elif gap > 0.1:
                assert not with_tip and without, (angle, fraction, gap)
                cleared += 1
    assert close >= 10 and cleared >= 10  # both kinds met
