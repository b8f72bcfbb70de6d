"""Dexterity template (thesis §3.1): wrap angles, section lengths and tube thickness.

Every section must be able to wrap an object: the distal section through 360°, the last
two together around a bigger one, and so on (Eq. 3.2, ``Θ_i = 360°/(N − i + 1)``). With the
section's rest curvature at the template pressure, ``|u*_i| = M_i,max / EI_i``, the
reference length that gives that wrap is ``L_i = Θ_i / |u*_i|`` (Eq. 3.3).

``|u*_i|`` comes from the tube geometry through :func:`solver.rest_strains` (docs/design.md §1–4:
moments from geometry, not the printed factors of Eq. 2.64), with the section's two lifting
channels (II and III) at the template pressure and channel I at 0; by the symmetry of the
tube ring, channel I alone gives the same magnitude.

All extensors share one tube (outer radius Ro, thickness t). For a fixed Ro, ``L_i`` grows
monotonically with t (a thicker wall stretches less and is stiffer), so one length
constraint fixes t by a 1-D bracketed root search: the total length for Eq. (3.9), or the
distal section length for the fixed-gripping-radius case.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

import solver
from solver.designs import FluidDesign

__all__ = [
    "TUBE_COUNTS", "InfeasibleDesign", "Template", "wrap_angles", "build_arm", "lifting_pressures",
    "lifting_channels",
    "section_curvatures", "section_lengths", "template",
]

TUBE_COUNTS = (3, 6, 9, 12)
"""Tubes per section the optimisation allows (Eq. 3.12)."""

_THIN = 1e-4
"""Thinnest and thickest wall tried, as fractions of Ro: t ∈ [_THIN·Ro, (1 − _THIN)·Ro]."""


class InfeasibleDesign(ValueError):
    """No wall thickness meets the length constraint (the arm is too short for the template)."""


@dataclass(frozen=True)
class Template:
    """A design that meets the dexterity template.

    Attributes:
        tubes: tubes per section, base to tip.
        outer_radius: tube outer radius Ro (m).
        thickness: tube wall thickness t (m).
        section_lengths: (N,) reference section lengths L_i (m).
        curvatures: (N,) |u*_i| at the template pressure (rad/m).
        wrap_angles: (N,) Θ_i (rad).
    """

    tubes: tuple[int, ...]
    outer_radius: float
    thickness: float
    section_lengths: np.ndarray
    curvatures: np.ndarray
    wrap_angles: np.ndarray

    @property
    def length(self) -> float:
        """Total reference length (m)."""
        return float(self.section_lengths.sum())

    @property
    def internal_volume(self) -> float:
        """Fluid volume of all tubes, Σ N_i·π·Ri²·L_i (m³)."""
        ri = self.outer_radius - self.thickness
        return float(math.pi * ri**2 * np.dot(self.tubes, self.section_lengths))


def wrap_angles(n_sections: int) -> np.ndarray:
    """Θ_i = 360°/(N − i + 1), i = 1..N (Eq. 3.2).

    Returns:
        (N,) wrap angles in rad, base to tip.
    """
    if isinstance(n_sections, bool) or int(n_sections) != n_sections or n_sections < 1:
        raise ValueError(f"number of sections must be an integer >= 1; got {n_sections!r}")
    n = int(n_sections)
    return np.radians([360.0 / (n - i) for i in range(n)])


def _check_tubes(tubes) -> tuple[int, ...]:
    counts = tuple(tubes)
    if not counts or any(isinstance(c, bool) or c not in TUBE_COUNTS for c in counts):
        raise ValueError(f"tube counts must be a non-empty sequence drawn from {TUBE_COUNTS}; "
                         f"got {tubes!r}")
    return tuple(int(c) for c in counts)


def build_arm(params: FluidDesign, tubes, section_lengths, thickness: float,
              outer_radius: float) -> solver.designs.ArmDesign:
    """The Table 3.1 arm (pneumatic or hydraulic ``params``) with the given layout.

    Args:
        params: material and pressures (``solver.designs.PNEUMATIC``/``HYDRAULIC`` or a
            ``dataclasses.replace`` of them, e.g. another Young's modulus).
        tubes: (N,) tubes per section.
        section_lengths: (N,) reference lengths (m).
        thickness: tube wall thickness t (m).
        outer_radius: tube outer radius Ro (m).
    """
    name = "hydraulic" if params.fluid_density > 0 else "pneumatic"
    return solver.designs.fluid_arm(name, params, _check_tubes(tubes), tuple(section_lengths),
                                     thickness, outer_radius)


def lifting_pressures(arm: solver.designs.ArmDesign, pressure: float) -> np.ndarray:
    """Planar inputs with every section's II + III channel at ``pressure``, channel I at 0.

    Channel I sits on +d1 (on top of a horizontal arm) and bends the arm clockwise, so
    II + III, below the axis, curl it upwards (docs/design.md §1–4).

    Returns:
        (n_inputs,) pressures (Pa) in the order of ``arm.input_names(planar=True)``.

    Raises:
        ValueError: the design has no ``s<k>_II+III`` planar channels (not an OctArm layout).
    """
    names = arm.input_names(planar=True)
    lifting = np.array([re.fullmatch(r"s\d+_II\+III", n) is not None for n in names], dtype=bool)
    if not lifting.any():
        raise ValueError(f"design {arm.name!r} has no OctArm 's<k>_II+III' planar channels to lift "
                         f"with; its inputs are {names}")
    return np.where(lifting, float(pressure), 0.0)


def lifting_channels(arm: solver.designs.ArmDesign, pressure: float) -> np.ndarray:
    """:func:`lifting_pressures` expanded to the spatial channels.

    Returns:
        (n_channels,) pressures (Pa).
    """
    channels = np.zeros(arm.n_channels)
    for value, (_, idx) in zip(lifting_pressures(arm, pressure), arm.planar_channels):
        channels[list(idx)] = value
    return channels


def section_curvatures(params: FluidDesign, tubes, thickness: float, outer_radius: float,
                       pressure: float) -> np.ndarray:
    """|u*_i| = M_i/EI_i of every section with its lifting channels at ``pressure``.

    Returns:
        (N,) rest curvatures (rad/m).
    """
    counts = _check_tubes(tubes)
    arm = build_arm(params, counts, (1.0,) * len(counts), thickness, outer_radius)
    _, u2, _ = solver.rest_strains(arm, lifting_channels(arm, pressure))
    return np.abs(u2)


def section_lengths(params: FluidDesign, tubes, thickness: float, outer_radius: float,
                    pressure: float | None = None) -> np.ndarray:
    """L_i = Θ_i / |u*_i| (Eq. 3.3) at ``pressure`` (default: ``params.max_pressure``).

    Returns:
        (N,) reference section lengths (m).
    """
    p = params.max_pressure if pressure is None else pressure
    curvature = section_curvatures(params, tubes, thickness, outer_radius, p)
    return wrap_angles(len(curvature)) / curvature


def template(params: FluidDesign, tubes, outer_radius: float, *, total_length: float | None = None,
             distal_length: float | None = None, pressure: float | None = None) -> Template:
    """The wall thickness (and so the section lengths) that meets one length constraint.

    Exactly one of ``total_length`` (Eq. 3.9, ΣL_i = L) and ``distal_length`` (fixed
    gripping radius, L_N given) must be set.

    Args:
        params: Table 3.1 parameters.
        tubes: (N,) tubes per section.
        outer_radius: tube outer radius Ro (m).
        total_length: required ΣL_i (m).
        distal_length: required L_N (m).
        pressure: template pressure (Pa); default ``params.max_pressure`` (Eq. 3.3).

    Raises:
        InfeasibleDesign: even the thinnest wall gives a longer arm than required.
        ValueError: bad arguments.
    """
    counts = _check_tubes(tubes)
    if (total_length is None) == (distal_length is None):
        raise ValueError("give exactly one of total_length and distal_length")
    target = total_length if total_length is not None else distal_length
    if not (isinstance(target, (int, float)) and math.isfinite(target) and target > 0):
        raise ValueError(f"required length must be a finite number > 0 m; got {target!r}")
    if not (math.isfinite(outer_radius) and outer_radius > 0):
        raise ValueError(f"outer radius must be a finite number > 0 m; got {outer_radius!r}")
    p = params.max_pressure if pressure is None else float(pressure)
    if not 0 < p <= params.max_pressure:
        raise ValueError(f"template pressure {p} Pa must lie in (0, {params.max_pressure}] Pa")

    def measure(t: float) -> float:
        lengths = section_lengths(params, counts, t, outer_radius, p)
        return float(lengths.sum() if total_length is not None else lengths[-1]) - target

    t_lo, t_hi = _THIN * outer_radius, (1.0 - _THIN) * outer_radius
    shortest = measure(t_lo)
    if shortest > 0:
        raise InfeasibleDesign(
            f"tubes {'-'.join(map(str, counts))} with Ro = {outer_radius * 1e3:.2f} mm cannot meet "
            f"the template in {target:.4g} m: even the thinnest wall needs "
            f"{shortest + target:.4g} m")
    t = brentq(measure, t_lo, t_hi, xtol=1e-12 * outer_radius, rtol=1e-12)
    curvature = section_curvatures(params, counts, t, outer_radius, p)
    theta = wrap_angles(len(counts))
    return Template(tubes=counts, outer_radius=float(outer_radius), thickness=float(t),
                    section_lengths=theta / curvature, curvatures=curvature, wrap_angles=theta)
