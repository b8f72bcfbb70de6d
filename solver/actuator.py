"""Extensor air-muscle model (thesis §2.2): pressure ↔ axial stretch ↔ tube force.

A neo-Hookean rubber tube (Young's modulus E, radii Ri < Ro) inside a braid of initial
wind angle α extends when pressurised. Virtual work (Eqs. 2.1–2.9) gives the pressure
that holds the tube at axial stretch λ:

    p(λ) = (E·At / (3·A)) · Q(λ) / (λ³ · D(λ)),   At = π(Ro² − Ri²),  A = πRi²,
    D(λ) = (λ²c² − 1)² (3λ²c² − 1),               c = cos α,

with Q the polynomial of Appendix A.1. Eq. (2.10) *as printed* is the same expression with
the opposite overall sign (it would give p < 0 for λ > 1); we use the Appendix A.1 sign,
which equals p = dU/dV (tested in ``tests/solver/test_actuator.py``).

The physical branch is λ ∈ [1, λmax), λmax = 1/(√3·cos α): the braid angle reaches
54.7° there and p → ∞. On that branch p(λ) is strictly increasing, so the inverse is found
by safeguarded Newton inside the bracket. Each tube then carries the equivalent axial
force ``F = E·At·(λ − 1)`` (Eq. 2.11).
"""

from __future__ import annotations

import math

import numpy as np

from solver.jit import njit

PSI = 6894.757293168361
"""One pound per square inch in pascals."""


@njit
def tube_pressure(lam, youngs_modulus, area_ratio, cos_alpha):
    """Pressure (Pa) holding a tube at axial stretch ``lam`` (Appendix A.1 form of Eq. 2.10).

    ``area_ratio`` is At/A = (Ro² − Ri²)/Ri².
    """
    return pressure_and_slope(lam, youngs_modulus, area_ratio, cos_alpha)[0]


@njit
def pressure_and_slope(lam, youngs_modulus, area_ratio, cos_alpha):
    """(p, dp/dλ) at ``lam``: the pressure of :func:`tube_pressure` and its exact derivative."""
    c2 = cos_alpha * cos_alpha
    c4 = c2 * c2
    c6 = c4 * c2
    # Q(λ) = a0 + a1 λ² + a2 λ⁴ + a3 λ⁶ + a4 λ⁸ (Appendix A.1)
    a0 = 1.0 - 2.0 * c2 + c4
    a1 = -2.0 * c6 + 4.0 * c4 - 2.0 * c2
    a2 = 2.0 * c2 - 1.0
    a3 = 2.0 * c2 - 4.0 * c4
    a4 = 2.0 * c6 - c4
    l2 = lam * lam
    l4 = l2 * l2
    l6 = l4 * l2
    l8 = l4 * l4
    q = a0 + a1 * l2 + a2 * l4 + a3 * l6 + a4 * l8
    dq = lam * (2.0 * a1 + 4.0 * a2 * l2 + 6.0 * a3 * l4 + 8.0 * a4 * l6)
    x = l2 * c2
    d = (x - 1.0) * (x - 1.0) * (3.0 * x - 1.0)
    dd = (2.0 * (x - 1.0) * (3.0 * x - 1.0) + 3.0 * (x - 1.0) * (x - 1.0)) * 2.0 * lam * c2
    k = youngs_modulus * area_ratio / 3.0
    den = l2 * lam * d
    dden = 3.0 * l2 * d + l2 * lam * dd
    return k * q / den, k * (dq * den - q * dden) / (den * den)


@njit
def tube_stretch(pressure, youngs_modulus, area_ratio, cos_alpha):
    """Axial stretch λ ∈ [1, λmax) at ``pressure`` (Pa ≥ 0): inverse of :func:`tube_pressure`.

    Safeguarded Newton on the bracket [1, λmax) with the exact slope: a Newton step that
    leaves the current bracket is replaced by bisection, so the iteration cannot escape the
    physical branch. Returns NaN for a negative or non-finite pressure (the wrapper turns
    that into an error).
    """
    if not (pressure >= 0.0) or not math.isfinite(pressure):
        return math.nan
    if pressure == 0.0:
        return 1.0
    lo = 1.0
    hi = 1.0 / (math.sqrt(3.0) * cos_alpha)
    # Start from the linearisation at λ = 1 (p(1) = 0): two or three Newton steps from there
    # instead of five or six from the middle of the bracket.
    lam = 1.0 + pressure / pressure_and_slope(1.0, youngs_modulus, area_ratio, cos_alpha)[1]
    if not (lo < lam < hi):
        lam = 0.5 * (lo + hi)
    for _ in range(200):
        p, df = pressure_and_slope(lam, youngs_modulus, area_ratio, cos_alpha)
        f = p - pressure
        if f > 0.0:
            hi = lam
        else:
            lo = lam
        step = lam - f / df if df > 0.0 else 0.5 * (lo + hi)
        # Converged when the Newton correction itself is at round-off — tested before the
        # bracket check, because a converged step lands on the bracket end just set and
        # would otherwise be replaced by bisection, away from the root, again and again.
        if abs(step - lam) <= 1e-15 * lam:
            return step
        if not (lo < step < hi):
            step = 0.5 * (lo + hi)
        if hi - lo <= 4e-16 * hi:
            return step
        lam = step
    return lam


@njit
def _stretch_array(pressures, youngs_modulus, area_ratio, cos_alpha, out):
    """Vectorised :func:`tube_stretch`: writes λ for every pressure into ``out``."""
    for i in range(pressures.shape[0]):
        out[i] = tube_stretch(pressures[i], youngs_modulus, area_ratio, cos_alpha)


def pressure_from_stretch(stretch, youngs_modulus, inner_radius, outer_radius, wind_angle_deg):
    """Pressure (Pa) that holds an extensor at axial ``stretch`` (Appendix A.1 / Eq. 2.10).

    Args:
        stretch: λ, scalar or array, on the physical branch [1, λmax).
        youngs_modulus: E of the tube rubber (Pa).
        inner_radius, outer_radius: Ri < Ro of the tube (m).
        wind_angle_deg: initial braid wind angle α (degrees, 54.74 < α < 90).

    Returns:
        Pressure in Pa, same shape as ``stretch``.
    """
    lam = np.asarray(stretch, dtype=float)
    ratio, c = _geometry(youngs_modulus, inner_radius, outer_radius, wind_angle_deg)
    lam_max = max_stretch(wind_angle_deg)
    if np.any(~np.isfinite(lam)) or np.any(lam < 1.0) or np.any(lam >= lam_max):
        raise ValueError(f"stretch must lie on the physical branch [1, {lam_max:.6f}); got {stretch!r}")
    out = np.vectorize(lambda x: tube_pressure(x, youngs_modulus, ratio, c))(lam)
    return out if out.ndim else float(out)


def stretch_from_pressure(pressure, youngs_modulus, inner_radius, outer_radius, wind_angle_deg,
                          max_pressure=None):
    """Axial stretch λ of an extensor at ``pressure`` (Pa): the inverse of Eq. (2.10).

    Args:
        pressure: gauge pressure in Pa, scalar or array, ≥ 0.
        youngs_modulus, inner_radius, outer_radius, wind_angle_deg: as in
            :func:`pressure_from_stretch`.
        max_pressure: optional rated maximum (Pa); larger pressures are an error.

    Returns:
        λ ∈ [1, λmax), same shape as ``pressure``.

    Raises:
        ValueError: for a negative, non-finite or over-rated pressure.
    """
    p = np.atleast_1d(np.asarray(pressure, dtype=float))
    if np.any(~np.isfinite(p)):
        raise ValueError(f"pressure must be finite; got {pressure!r}")
    if np.any(p < 0.0):
        raise ValueError(f"pressure must be >= 0 Pa (gauge); got minimum {p.min():.6g} Pa")
    if max_pressure is not None and np.any(p > max_pressure):
        raise ValueError(
            f"pressure {p.max():.6g} Pa exceeds the rated maximum {max_pressure:.6g} Pa")
    ratio, c = _geometry(youngs_modulus, inner_radius, outer_radius, wind_angle_deg)
    out = np.empty_like(p)
    _stretch_array(p.ravel(), float(youngs_modulus), ratio, c, out.ravel())
    out = out.reshape(np.shape(pressure))
    return out if out.ndim else float(out)


def max_stretch(wind_angle_deg):
    """λmax = 1/(√3·cos α): the stretch at which the braid locks at 54.74° (p → ∞)."""
    return 1.0 / (math.sqrt(3.0) * math.cos(math.radians(wind_angle_deg)))


def _geometry(youngs_modulus, inner_radius, outer_radius, wind_angle_deg):
    if not (youngs_modulus > 0 and 0 < inner_radius < outer_radius):
        raise ValueError(
            f"need E > 0 and 0 < Ri < Ro; got E={youngs_modulus}, Ri={inner_radius}, Ro={outer_radius}")
    if not (math.degrees(math.acos(1 / math.sqrt(3))) < wind_angle_deg < 90.0):
        raise ValueError(f"wind angle must lie in (54.74°, 90°) for an extensor; got {wind_angle_deg}°")
    ratio = (outer_radius**2 - inner_radius**2) / inner_radius**2
    return ratio, math.cos(math.radians(wind_angle_deg))
