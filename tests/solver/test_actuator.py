"""Actuator model (thesis §2.2) against docs/design.md §1–4 facts and a first-principles p = dU/dV."""

import math

import numpy as np
import pytest

from solver import PSI, actuator, pressure_from_stretch, stretch_from_pressure
from tests.solver import naive

OCTARM_V = dict(youngs_modulus=2e6, inner_radius=9.3e-3, outer_radius=14e-3, wind_angle_deg=78.0)
AT = math.pi * (14e-3**2 - 9.3e-3**2)


@pytest.mark.parametrize("psi, lam, force", [(50, 1.108714, 74.803), (100, 1.239502, 164.794)])
def test_design_facts(psi, lam, force):
    got = stretch_from_pressure(psi * PSI, **OCTARM_V)
    assert got == pytest.approx(lam, abs=5e-7)
    assert 2e6 * AT * (got - 1) == pytest.approx(force, abs=5e-4)


def test_pressure_at_stretch_1_2():
    assert pressure_from_stretch(1.2, **OCTARM_V) / PSI == pytest.approx(85.6319, abs=5e-5)


def test_max_stretch_78deg():
    assert actuator.max_stretch(78.0) == pytest.approx(2.7769, abs=5e-5)


def test_equals_energy_derivative_and_printed_sign_is_wrong():
    """Appendix A.1 form = dU/dV (Eqs. 2.1–2.6); Eq. (2.10) as printed is its negative."""
    for lam in (1.05, 1.2, 1.6, 2.3):
        ours = pressure_from_stretch(lam, **OCTARM_V)
        energy = naive.pressure_energy(lam, 2e6, 9.3e-3, 14e-3, 78.0)
        printed = naive.pressure_eq210_printed(lam, 2e6, 9.3e-3, 14e-3, 78.0)
        assert ours == pytest.approx(energy, rel=1e-6)
        assert printed == pytest.approx(-ours, rel=1e-12)
        assert ours > 0


def test_round_trip_vectorised():
    p = np.linspace(0, 400 * PSI, 257)
    lam = stretch_from_pressure(p, **OCTARM_V)
    assert lam.shape == p.shape
    back = pressure_from_stretch(lam, **OCTARM_V)
    np.testing.assert_allclose(back, p, rtol=1e-9, atol=1e-9)
    assert np.all(np.diff(lam) > 0)


def test_independent_inversion():
    for psi in (1, 30, 90):
        assert stretch_from_pressure(psi * PSI, **OCTARM_V) == pytest.approx(
            naive.stretch_bisect(psi * PSI, 2e6, 9.3e-3, 14e-3, 78.0), abs=1e-9)


def test_extension_grows_with_wind_angle():
    """Fig. 2.4 trend: a larger wind angle extends more at the same pressure."""
    lams = [stretch_from_pressure(60 * PSI, 2e6, 9.3e-3, 14e-3, a) for a in (65, 71, 76, 78, 80)]
    assert np.all(np.diff(lams) > 0)


def test_near_lock_up_stays_on_branch():
    lam = stretch_from_pressure(1e9, **OCTARM_V)
    assert 1 < lam < actuator.max_stretch(78.0)


@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf])
def test_bad_pressure(bad):
    with pytest.raises(ValueError, match="pressure"):
        stretch_from_pressure(bad, **OCTARM_V)


def test_over_rated_pressure():
    with pytest.raises(ValueError, match="rated maximum"):
        stretch_from_pressure(120 * PSI, **OCTARM_V, max_pressure=100 * PSI)


def test_bad_stretch_and_geometry():
    with pytest.raises(ValueError, match="physical branch"):
        pressure_from_stretch(0.9, **OCTARM_V)
    with pytest.raises(ValueError, match="Ri < Ro"):
        stretch_from_pressure(1.0, 2e6, 0.02, 0.01, 78.0)
    with pytest.raises(ValueError, match="wind angle"):
        stretch_from_pressure(1.0, 2e6, 0.01, 0.02, 50.0)


@pytest.mark.parametrize("alpha", [60.0, 70.0, 80.0])
def test_pressure_slope_is_the_derivative(alpha):
    """The exact dp/dλ that drives the inversion agrees with a central difference."""
    from solver.actuator import pressure_and_slope, tube_pressure

    c = math.cos(math.radians(alpha))
    lam_max = 1.0 / (math.sqrt(3.0) * c)
    for lam in np.linspace(1.0, lam_max, 12)[:-1]:
        p, slope = pressure_and_slope(lam, 1.2e6, 2.5, c)
        h = 1e-6 * lam
        fd = (tube_pressure(lam + h, 1.2e6, 2.5, c) - tube_pressure(lam - h, 1.2e6, 2.5, c)) / (2 * h)
        assert p == tube_pressure(lam, 1.2e6, 2.5, c)
        assert slope == pytest.approx(fd, rel=1e-6)


def _mixed_materials():
    """OctArm V with one of channel 0's two tubes of a stiffer material: equal pressure, a
    different stretch."""
    import dataclasses

    from solver import designs

    arm = designs.octarm_v()
    tubes = list(arm.tubes)
    stiff = dataclasses.replace(tubes[1].material, youngs_modulus=3e6)
    tubes[1] = dataclasses.replace(tubes[1], material=stiff)
    return dataclasses.replace(arm, tubes=tuple(tubes))


@pytest.mark.parametrize("design", ["octarm_v", "ct", "octarm_vi", "mixed"])
def test_cached_rest_strains_equal_fresh_ones_bit_for_bit(design):
    """The stepper's λ(p) cache solves each tube only when its pressure changed, and once for
    tubes of one material at one pressure: the rest strains are those of a fresh solve of
    every tube, bit for bit, as pressures repeat across channels and from call to call."""
    from solver import designs, rod
    from solver.problem import pack
    from solver.settings import Settings

    arm = _mixed_materials() if design == "mixed" else designs.get(design)
    packed = pack(arm, "full", Settings())
    ns, n_tubes = len(arm.sections), packed.tubes_i.shape[0]
    p_seen, stretch = np.full(n_tubes, np.nan), np.empty(n_tubes)
    cached, fresh = np.empty((3, ns)), np.empty((3, ns))
    rng = np.random.default_rng(4)
    levels = rng.uniform(0.0, arm.max_pressure, 3)  # few values: channels often share one
    p = rng.choice(levels, arm.n_channels)
    for _ in range(30):
        changed = rng.uniform(size=arm.n_channels) < 0.5
        p = np.where(changed, rng.choice(np.append(levels, 0.0), arm.n_channels), p)
        rod.rest_strains_cached(p, packed.tubes_i, packed.tubes_f, packed.secf, p_seen, stretch, cached)
        rod.rest_strains_into(p, packed.tubes_i, packed.tubes_f, packed.secf, fresh)
        np.testing.assert_array_equal(cached, fresh)
