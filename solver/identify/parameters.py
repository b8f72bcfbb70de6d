"""The design parameters a fit may adjust, named as the design names them.

A parameter is ``kind`` or ``kind:group``. Tube kinds act on a group of tubes, section kinds
on a group of sections; without a group a kind acts on all of them (one common value):

==================  =====  ======  =================================================  ==================
kind                unit   group   what it sets                                       bounds
==================  =====  ======  =================================================  ==================
``wind_angle``      deg    tubes   the braid angle α of the tubes' material           (55.24, 89.5)
``offset``          m      tubes   ``Tube.radius``: the tube axis's distance from     [r0/4, 4·r0]
                                   the backbone (its moment arm)
``E``               Pa     –       the tubes' Young's modulus; every section's EA     [E0/10, 10·E0]
                                   and EI scale with it
``G``               Pa     –       the tubes' shear modulus; GA and GJ scale with it  [G0/10, 10·G0]
``EA_scale`` …      –      sects   a factor on the sections' EA (also ``GA_scale``,   [0.1, 10]
                                   ``EI_scale``, ``GJ_scale``), on top of E and G
``mass_scale``      –      sects   a factor on the sections' ``mass_per_length``      [0, 10]
``endplate_mass``   kg     one     ``Section.endplate_mass`` of one section           [0, max(1, 10·m)]
``payload``         kg     –       an unknown mass at the tip, carried in every       [0, max(1, 10·m)]
                                   configuration: the last section's endplate mass
==================  =====  ======  =================================================  ==================

(m: the arm's mass; r0, E0, G0: the nominal values; 55.24° is half a degree above the braid's
locking angle 54.74°, where λmax → 1.) Groups of tubes: a spatial channel (``s1_I``), a
planar channel (``s1_II+III``: the tubes of channels II and III), a section (``s2``: the
tubes that span section 2; sections count from 1, as the channel names do) or one tube
(``tube0``: index into ``ArmDesign.tubes``, as the design file lists them). Groups of
sections: ``s1``, ``s2``, …

A parameter's value is the value of the design field for wind angles, offsets, moduli and
masses, and a factor (nominal 1) for the ``*_scale`` kinds. The tubes of one wind-angle or
offset group must share a nominal value, and ``E`` and ``G`` need one rubber for every tube;
two parameters may not set the same field of the same tube or section.

Each parameter has a *typical scale* (1° of wind angle, 10 % of a modulus, offset or
stiffness, 0.05·m of mass): the unit in which the fit moves it, takes finite differences
and judges identifiability (a direction the data do not pin to within ten typical scales is
not identified).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from solver.designs import ArmDesign

__all__ = ["Parameter", "KINDS", "parse_parameters", "apply_parameters", "BRAID_LOCK_DEG"]

BRAID_LOCK_DEG = math.degrees(math.acos(1.0 / math.sqrt(3.0)))
"""The braid's locking angle 54.74° (λmax = 1): the lower limit of every extensor's α."""

_TUBE_KINDS = ("wind_angle", "offset")
_SECTION_SCALES = {"EA_scale": "EA", "GA_scale": "GA", "EI_scale": "EI", "GJ_scale": "GJ",
                   "mass_scale": "mass_per_length"}
_GLOBAL_KINDS = ("E", "G", "payload")
KINDS = (*_TUBE_KINDS, "E", "G", *_SECTION_SCALES, "endplate_mass", "payload")
"""Every parameter kind, in the order of the module table."""

_UNITS = {"wind_angle": "deg", "offset": "m", "E": "Pa", "G": "Pa", "endplate_mass": "kg",
          "payload": "kg"}


@dataclass(frozen=True)
class Parameter:
    """One fitted quantity of a design.

    Attributes:
        name: ``kind`` or ``kind:group`` as the user named it.
        kind: one of :data:`KINDS`.
        unit: of its value (``"-"`` for a factor).
        nominal: its value in the design it was parsed against.
        lower, upper: physical bounds of its value.
        scale: its typical scale (same unit): the fit's unit of change.
        tubes: indices of the tubes it sets (tube kinds).
        sections: indices (0-based) of the sections it sets (section kinds, ``payload``).
    """

    name: str
    kind: str
    unit: str
    nominal: float
    lower: float
    upper: float
    scale: float
    tubes: tuple[int, ...] = ()
    sections: tuple[int, ...] = ()

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"Parameter.kind must be one of {', '.join(KINDS)}; got {self.kind!r}")
        for name in ("nominal", "lower", "upper", "scale"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v):
                raise ValueError(f"Parameter {self.name!r}: {name} must be a finite number; got {v!r}")
            object.__setattr__(self, name, float(v))
        if not (self.lower <= self.nominal <= self.upper and self.scale > 0):
            raise ValueError(f"Parameter {self.name!r}: need lower <= nominal <= upper and scale > 0; got "
                             f"{self.lower:g} <= {self.nominal:g} <= {self.upper:g}, scale {self.scale:g}")
        object.__setattr__(self, "tubes", tuple(int(i) for i in self.tubes))
        object.__setattr__(self, "sections", tuple(int(i) for i in self.sections))

    def to_dict(self) -> dict:
        """The fields as plain JSON values."""
        return {"name": self.name, "kind": self.kind, "unit": self.unit, "nominal": self.nominal,
                "lower": self.lower, "upper": self.upper, "scale": self.scale,
                "tubes": list(self.tubes), "sections": list(self.sections)}

    @classmethod
    def from_dict(cls, data: dict) -> Parameter:
        """Inverse of :meth:`to_dict` (validated)."""
        if not isinstance(data, dict):
            raise ValueError(f"a parameter must be a JSON object; got {type(data).__name__}")
        want = {"name", "kind", "unit", "nominal", "lower", "upper", "scale", "tubes", "sections"}
        if set(data) != want:
            raise ValueError(f"a parameter needs exactly the fields {', '.join(sorted(want))}; got "
                             f"{', '.join(sorted(map(str, data)))}")
        return cls(**data)


def _split_names(names) -> list[str]:
    if isinstance(names, str):
        names = names.split(",")
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"parameters must be names (a comma-separated string or a list of strings); "
                         f"got {names!r}")
    out = [n.strip() for n in names]
    if not out or any(not n for n in out):
        raise ValueError(f"parameters must be non-empty names ({', '.join(KINDS)}, optionally "
                         f"kind:group); got {names!r}")
    repeated = sorted({n for n in out if out.count(n) > 1})
    if repeated:
        raise ValueError(f"parameter {repeated[0]!r} is named twice")
    return out


def _section_index(design: ArmDesign, group: str, name: str) -> int | None:
    m = re.fullmatch(r"s(\d+)", group)
    if m is None:
        return None
    k = int(m.group(1))
    if not 1 <= k <= len(design.sections):
        raise ValueError(f"parameter {name!r}: design {design.name!r} has sections "
                         f"s1..s{len(design.sections)}; got {group!r}")
    return k - 1


def _tube_group(design: ArmDesign, group: str | None, name: str) -> tuple[int, ...]:
    """Indices of the tubes a tube-kind group names (module docstring)."""
    tubes = design.tubes
    if group is None:
        return tuple(range(len(tubes)))
    if group in design.channels:
        c = design.channels.index(group)
        return tuple(k for k, t in enumerate(tubes) if t.channel == c)
    planar = dict(design.planar_channels)
    if group in planar:
        return tuple(k for k, t in enumerate(tubes) if t.channel in planar[group])
    section = _section_index(design, group, name)
    if section is not None:
        found = tuple(k for k, t in enumerate(tubes) if t.first_section <= section <= t.last_section)
        if not found:
            raise ValueError(f"parameter {name!r}: no tube of design {design.name!r} spans section {group}")
        return found
    m = re.fullmatch(r"tube(\d+)", group)
    if m is not None and int(m.group(1)) < len(tubes):
        return (int(m.group(1)),)
    planar_names = [n for n, _ in design.planar_channels]
    raise ValueError(f"parameter {name!r}: unknown group {group!r}; name a channel "
                     f"({', '.join(design.channels)}), a planar channel ({', '.join(planar_names)}), a "
                     f"section (s1..s{len(design.sections)}) or a tube (tube0..tube{len(tubes) - 1})")


def _common(values, what: str, name: str) -> float:
    values = sorted(set(values))
    if values[-1] - values[0] > 1e-12 * max(abs(values[-1]), 1e-300):
        raise ValueError(f"parameter {name!r}: the {what} of its tubes differ ({values[0]:g} .. "
                         f"{values[-1]:g}); fit them in groups that share one value")
    return values[0]


def _mass_bound(design: ArmDesign) -> float:
    return max(1.0, 10.0 * design.mass)


def _mass_scale(design: ArmDesign) -> float:
    return max(0.01, 0.05 * design.mass)


def _parse_one(design: ArmDesign, name: str) -> Parameter:
    kind, _, group = name.partition(":")
    group = group or None
    if kind not in KINDS:
        raise ValueError(f"unknown parameter {name!r}; the kinds are {', '.join(KINDS)} (optionally "
                         "kind:group, see solver.identify.parameters)")
    if kind in _GLOBAL_KINDS and group is not None:
        raise ValueError(f"parameter {name!r}: {kind} takes no group")
    if kind in _TUBE_KINDS or kind in ("E", "G"):
        if not design.tubes:
            raise ValueError(f"parameter {name!r}: design {design.name!r} has no tubes")
    if kind in _TUBE_KINDS:
        tubes = _tube_group(design, group, name)
        if kind == "wind_angle":
            nominal = _common([design.tubes[k].material.wind_angle_deg for k in tubes], "wind angles", name)
            return Parameter(name, kind, "deg", nominal, BRAID_LOCK_DEG + 0.5, 89.5, 1.0, tubes=tubes)
        nominal = _common([design.tubes[k].radius for k in tubes], "offsets (Tube.radius)", name)
        if not nominal > 0:
            raise ValueError(f"parameter {name!r}: its tubes sit on the backbone (radius 0); an offset "
                             "fit needs a nominal radius > 0")
        return Parameter(name, kind, "m", nominal, nominal / 4.0, 4.0 * nominal, 0.1 * nominal, tubes=tubes)
    if kind in ("E", "G"):
        field = "youngs_modulus" if kind == "E" else "shear_modulus"
        what = "Young's moduli" if kind == "E" else "shear moduli"
        nominal = _common([getattr(t.material, field) for t in design.tubes], what, name)
        return Parameter(name, kind, "Pa", nominal, nominal / 10.0, 10.0 * nominal, 0.1 * nominal,
                         tubes=tuple(range(len(design.tubes))))
    if kind == "payload" or kind == "endplate_mass":
        if kind == "payload":
            section = len(design.sections) - 1
        elif group is None or _section_index(design, group, name) is None:
            raise ValueError(f"parameter {name!r}: endplate_mass needs a section, e.g. endplate_mass:s1")
        else:
            section = _section_index(design, group, name)
        nominal = design.sections[section].endplate_mass
        return Parameter(name, kind, "kg", nominal, 0.0, max(_mass_bound(design), nominal),
                         _mass_scale(design), sections=(section,))
    # a section scale
    if group is None:
        sections = tuple(range(len(design.sections)))
    else:
        section = _section_index(design, group, name)
        if section is None:
            raise ValueError(f"parameter {name!r}: unknown group {group!r}; name a section "
                             f"(s1..s{len(design.sections)})")
        sections = (section,)
    lower = 0.0 if kind == "mass_scale" else 0.1
    return Parameter(name, kind, "-", 1.0, lower, 10.0, 0.1, sections=sections)


def _family(p: Parameter) -> tuple[str, tuple[int, ...], str]:
    """(field family, members, member word): two parameters of one family may not share a member."""
    if p.kind in _TUBE_KINDS:
        return p.kind, p.tubes, "tube"
    if p.kind in ("E", "G"):
        return p.kind, (0,), "design"
    if p.kind in ("payload", "endplate_mass"):
        return "endplate_mass", p.sections, "section"
    return p.kind, p.sections, "section"


def parse_parameters(design: ArmDesign, names) -> tuple[Parameter, ...]:
    """The :class:`Parameter` s ``names`` ask for, checked against ``design``.

    Args:
        design: the design whose fields they name.
        names: a comma-separated string (``"wind_angle,E"``) or a list of names.

    Returns:
        One :class:`Parameter` per name, in order.

    Raises:
        ValueError: (one line) an unknown kind or group, a repeated name, two parameters
            that set the same field of one tube or section, a group whose tubes differ in
            nominal value.
    """
    if not isinstance(design, ArmDesign):
        raise ValueError(f"design must be a solver.designs.ArmDesign; got {type(design).__name__}")
    params = tuple(_parse_one(design, n) for n in _split_names(names))
    seen: dict[tuple[str, int], str] = {}
    for p in params:
        family, members, word = _family(p)
        for m in members:
            other = seen.setdefault((family, m), p.name)
            if other != p.name:
                where = f"{word} {m if word == 'tube' else m + 1}" if word != "design" else "the design"
                raise ValueError(f"parameters {other!r} and {p.name!r} both set {family} of {where}")
    return params


def apply_parameters(design: ArmDesign, parameters, values) -> ArmDesign:
    """``design`` with ``parameters`` set to ``values``, validated.

    Args:
        design: the design the parameters were parsed against.
        parameters: :class:`Parameter` s (from :func:`parse_parameters`).
        values: (n_parameters,) their values, in their units.

    Returns:
        The new design (a validated :class:`~solver.designs.ArmDesign`).

    Raises:
        ValueError: a value that is not finite or lies outside its parameter's bounds.
    """
    values = np.asarray(values, dtype=float).reshape(-1)
    if values.size != len(parameters):
        raise ValueError(f"{len(parameters)} parameters need as many values; got {values.size}")
    ns = len(design.sections)
    alpha = [t.material.wind_angle_deg for t in design.tubes]
    radius = [t.radius for t in design.tubes]
    e_factor = g_factor = 1.0
    factors = {f: np.ones(ns) for f in _SECTION_SCALES.values()}
    endplate = [s.endplate_mass for s in design.sections]
    for p, v in zip(parameters, values):
        if not (math.isfinite(v) and p.lower <= v <= p.upper):
            raise ValueError(f"parameter {p.name!r} = {float(v)!r} lies outside its bounds "
                             f"[{p.lower:g}, {p.upper:g}] {p.unit}")
        if p.kind == "wind_angle":
            for k in p.tubes:
                alpha[k] = v
        elif p.kind == "offset":
            for k in p.tubes:
                radius[k] = v
        elif p.kind == "E":
            e_factor = v / p.nominal
        elif p.kind == "G":
            g_factor = v / p.nominal
        elif p.kind in _SECTION_SCALES:
            factors[_SECTION_SCALES[p.kind]][list(p.sections)] *= v
        else:  # payload, endplate_mass
            endplate[p.sections[0]] = v
    sections = tuple(replace(
        s, EA=s.EA * e_factor * factors["EA"][i], GA=s.GA * g_factor * factors["GA"][i],
        EI=s.EI * e_factor * factors["EI"][i], GJ=s.GJ * g_factor * factors["GJ"][i],
        mass_per_length=s.mass_per_length * factors["mass_per_length"][i], endplate_mass=endplate[i])
        for i, s in enumerate(design.sections))
    materials: dict[tuple[int, float], object] = {}
    tubes = []
    for k, t in enumerate(design.tubes):
        m = t.material
        key = (id(m), alpha[k])
        if key not in materials:
            materials[key] = replace(m, youngs_modulus=m.youngs_modulus * e_factor,
                                     shear_modulus=m.shear_modulus * g_factor, wind_angle_deg=alpha[k])
        tubes.append(replace(t, radius=radius[k], material=materials[key]))
    return replace(design, sections=sections, tubes=tuple(tubes))
