"""Arm designs as frozen, validated parameter objects, each number traced to its source.

An :class:`ArmDesign` is a chain of :class:`Section` s (stiffness, mass, endplate) plus the
:class:`Tube` s that actuate it. A tube has an explicit angular position about d3 (measured
from +d1 towards +d2), a radial offset, the section range it spans and the spatial channel
it belongs to. Channels are named; ``planar_channels`` says which spatial channels a planar
channel drives together (planar operation pressurises II and III as one, §2.3.2.1).

Channel maps, in one place:

* OctArm (V, VI): spatial channels ``s{k}_I, s{k}_II, s{k}_III`` per section k, centred at
  0°, 120°, 240° from +d1. With 6 tubes a channel is the two adjacent tubes at ±30° of its
  centre line; with 3 tubes, one tube. Planar channels, in order:
  ``[s1_I, s1_II+III, s2_I, s2_II+III, s3_I, s3_II+III]``.
* CT (chapter 5, Table 5.1): six tubes at the base. The inner three (ring radius 2Ro/√3,
  at 0°/120°/240°) run base to tip; the outer three (radius 4Ro/√3, nestled in the gaps,
  at 60°/180°/300°) end at the section-1/2 junction. Spatial channels
  ``inner_I, inner_II, inner_III, outer_I, outer_II, outer_III``; the outer tube of channel
  k sits opposite the inner tube of channel k (outer_I at 180°). Planar channels, in order:
  ``[inner_I, inner_II+III, outer_I, outer_II+III]`` — inner_I bends the whole arm
  clockwise, outer_I bends section 1 counter-clockwise, and so on.

Bending stiffness, ``ei=`` (docs/design.md §1–4):

* ``"eq2.32"`` (default): ``EI = E·N_t·(I_tube + At·Ro²/2)`` as Eq. (2.32) and Table 4.2;
  for the CT base section Table 5.1's ``E·(6·I_tube + 5·At·Ro²/2)``.
* ``"tubes"``: parallel-axis sum over the actual tube positions, ``E·Σ(I_tube + At·y_k²)``
  (a bundle bonded along its length; an upper bound).

Validation. Every field is checked when a parameter object is built, whether in Python or
from a design file: numbers are real numbers (never ``bool``), finite and within the ranges
below (generous physical bounds that keep the solver's arithmetic far from overflow); counts
and indices are integers; names are strings. A design has at most :data:`MAX_SECTIONS`
sections and :data:`MAX_TUBES` tubes (and channels), and a design file at most
:data:`MAX_FILE_BYTES`; each limit is named in the error it raises. Every problem is a
one-line ``ValueError`` saying which field of which entry is wrong.

=========================================  ================================
field                                      accepted range
=========================================  ================================
lengths (section ``length``)               (0, 100] m
radii (tube ``radius`` ≥ 0, material)      (0, 10] m
``EA``, ``GA`` / ``EI``, ``GJ``            (0, 1e15] N / N m²
moduli                                     (0, 1e12] Pa
``density``                                (0, 1e5] kg/m³
``mass_per_length`` / ``endplate_mass``    [0, 1e6] kg/m / kg
``angle_deg``                              [-360, 360] deg
``max_pressure``                           [0, 1e12] Pa (> 0 with tubes)
names                                      1–100 characters; ``source`` up to 10,000
=========================================  ================================
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
from pathlib import Path

from solver.actuator import PSI, max_stretch
from solver.cache import DesignCache

__all__ = [
    "TubeMaterial", "Section", "Tube", "ArmDesign", "octarm_v", "octarm_vi", "ct",
    "octarm_two_section", "rod", "pneumatic", "hydraulic", "fluid_arm", "FluidDesign",
    "from_json", "load", "get", "example_file", "EXAMPLES_DIR",
    "DESIGN_NAMES", "MAX_SECTIONS", "MAX_TUBES", "MAX_FILE_BYTES",
]

MAX_SECTIONS = 32
"""Most sections a design may have (the thesis's arms have 2–3; each adds RK4 steps to every solve)."""
MAX_TUBES = 256
"""Most tubes, and most channels, a design may have."""
MAX_FILE_BYTES = 1_000_000
"""Largest design file :func:`load` reads (a design at both caps above is about 150 kB)."""
_MAX_NAME = 100
_MAX_SOURCE = 10_000
_MAX_LENGTH, _MAX_RADIUS = 100.0, 10.0  # m
_MAX_STIFFNESS = 1e15  # N (EA, GA) or N m² (EI, GJ)
_MAX_MODULUS = 1e12  # Pa
_MAX_PRESSURE = 1e12  # Pa (stress tests scale pressure with the moduli)
_MAX_DENSITY = 1e5  # kg/m³
_MAX_MASS = 1e6  # kg/m or kg


def _short(value) -> str:
    """``repr(value)`` cut to one short line (a bad field may hold megabytes or deep nesting)."""
    try:
        text = repr(value)
    except RecursionError:
        text = f"<deeply nested {type(value).__name__}>"
    return text if len(text) <= 60 else text[:57] + "..."


def _number(obj, name: str, low: float, high: float, unit: str, *, open_low: bool = False) -> None:
    """Check that field ``name`` is a real number (not a bool) in [low, high] (or (low, high]); store
    it as a float."""
    v = getattr(obj, name)
    x = math.nan
    if isinstance(v, numbers.Real) and not isinstance(v, bool):
        try:
            x = float(v)
        except OverflowError:  # an integer beyond float range
            x = math.inf
    if not (math.isfinite(x) and (x > low if open_low else x >= low) and x <= high):
        bound = f"> {low:g}" if open_low else f">= {low:g}"
        raise ValueError(f"{type(obj).__name__}.{name} must be a finite number {bound} and <= {high:g}"
                         f"{' ' + unit if unit else ''}; got {_short(v)}")
    object.__setattr__(obj, name, x)


def _integer(obj, name: str, low: int, high: int, limit: str = "") -> None:
    """Check that field ``name`` is an integer (not a bool, not a float) in [low, high]."""
    v = getattr(obj, name)
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or not low <= v <= high:
        raise ValueError(f"{type(obj).__name__}.{name} must be an integer in [{low}, {high}]"
                         f"{limit}; got {_short(v)}")
    object.__setattr__(obj, name, int(v))


def _unchecked(obj, **changes):
    """A copy of the frozen dataclass ``obj`` with ``changes``, not validated again: for
    changes the caller has checked (:meth:`ArmDesign.scaled`)."""
    new = object.__new__(type(obj))
    new.__dict__.update(obj.__dict__, **changes)
    return new


def _text(value, what: str, max_length: int, allow_empty: bool = False) -> str:
    if not isinstance(value, str) or len(value) > max_length or (not value and not allow_empty):
        size = f"at most {max_length}" if allow_empty else f"1 to {max_length}"
        raise ValueError(f"{what} must be a string of {size} characters; got {_short(value)}")
    return value


def _entries(value, what: str, limit: int, limit_name: str) -> tuple:
    """A list or tuple of at most ``limit`` entries, as a tuple."""
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"{what} must be a list; got {_short(value)}")
    if len(value) > limit:
        raise ValueError(f"{what} has {len(value)} entries; at most {limit} are supported "
                         f"(solver.designs.{limit_name})")
    return tuple(value)


def _build(cls, value, where: str):
    """``value`` if it already is a ``cls``, else ``cls(**value)`` with the problem named on one line."""
    if isinstance(value, cls):
        return value
    if not isinstance(value, dict):
        raise ValueError(f"{where} must be a mapping of {cls.__name__} fields (a JSON object); "
                         f"got {_short(value)}")
    init = [f for f in fields(cls) if f.init]
    unknown = sorted(map(repr, set(value) - {f.name for f in init}))
    if unknown:
        raise ValueError(f"{where} has unknown fields: {', '.join(unknown)} ({cls.__name__} has "
                         f"{', '.join(f.name for f in init)})")
    missing = [f.name for f in init if f.default is MISSING and f.default_factory is MISSING
               and f.name not in value]
    if missing:
        raise ValueError(f"{where} is missing fields: {', '.join(missing)}")
    try:
        return cls(**value)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


@dataclass(frozen=True)
class TubeMaterial:
    """An extensor actuator: neo-Hookean rubber tube in a braid (thesis §2.2).

    Attributes:
        youngs_modulus: E of the rubber (Pa).
        shear_modulus: G of the rubber (Pa).
        density: rubber density (kg/m³).
        inner_radius: Ri (m).
        outer_radius: Ro (m).
        wind_angle_deg: initial braid angle α (deg), in (54.74°, 90°).
    """

    youngs_modulus: float
    shear_modulus: float
    density: float
    inner_radius: float
    outer_radius: float
    wind_angle_deg: float

    def __post_init__(self):
        for name in ("youngs_modulus", "shear_modulus"):
            _number(self, name, 0.0, _MAX_MODULUS, "Pa", open_low=True)
        _number(self, "density", 0.0, _MAX_DENSITY, "kg/m³", open_low=True)
        for name in ("inner_radius", "outer_radius"):
            _number(self, name, 0.0, _MAX_RADIUS, "m", open_low=True)
        _number(self, "wind_angle_deg", 0.0, 90.0, "deg")
        if self.inner_radius >= self.outer_radius:
            raise ValueError(
                f"tube inner radius {self.inner_radius} m must be smaller than outer radius "
                f"{self.outer_radius} m")
        lock = math.degrees(math.acos(1.0 / math.sqrt(3.0)))
        if not (lock < self.wind_angle_deg < 90.0):
            raise ValueError(
                f"wind_angle_deg must lie in ({lock:.2f}, 90) for an extensor; got {self.wind_angle_deg}")

    @property
    def area(self) -> float:
        """Rubber cross-section At = π(Ro² − Ri²) (m²)."""
        return math.pi * (self.outer_radius**2 - self.inner_radius**2)

    @property
    def bore_area(self) -> float:
        """Internal (fluid) cross-section A = πRi² (m²)."""
        return math.pi * self.inner_radius**2

    @property
    def second_moment(self) -> float:
        """I_tube = π(Ro⁴ − Ri⁴)/4 about the tube's own axis (m⁴)."""
        return math.pi * (self.outer_radius**4 - self.inner_radius**4) / 4.0

    @property
    def max_stretch(self) -> float:
        """Braid lock-up stretch λmax = 1/(√3 cos α)."""
        return max_stretch(self.wind_angle_deg)

    @property
    def ring_stiffness(self) -> float:
        """Contact stiffness of the unpressurised tube squeezed across a diameter (N/m²):
        line load per unit length of tube per metre of diametral compression.

        A ring of mean radius R = (Ro + Ri)/2 and wall t = Ro − Ri under a diametral line
        load w per length compresses by δ = 0.1488·w·R³/D (Roark's Formulas for Stress and
        Strain, thin circular ring loaded by two opposed forces), with the plate bending
        stiffness D = E t³ / (12 (1 − ν²)) of the wall, ν = ½ for rubber. It is the
        penalty stiffness of contact through the tube (about 1e5 N/m² for OctArm V): a lower
        bound, since the pressure adds membrane stiffness, and a rough one, the wall being
        thick (t/R ≈ 0.4). See docs/design.md, "Contact stiffness".
        """
        t = self.outer_radius - self.inner_radius
        radius = 0.5 * (self.outer_radius + self.inner_radius)
        plate = self.youngs_modulus * t**3 / (12.0 * (1.0 - 0.25))
        return plate / (0.1488 * radius**3)


@dataclass(frozen=True)
class Section:
    """One arm section: a uniform Cosserat rod segment with an optional endplate at its end.

    Attributes:
        length: reference length L (m).
        EA, GA: axial and shear stiffness (N).
        EI: bending stiffness about d1 and d2 (N m²).
        GJ: torsional stiffness (N m²).
        mass_per_length: mass per reference length, rubber plus any fluid (kg/m).
        endplate_mass: lumped mass at the distal end of the section (kg).
        n_tubes: number of extensors in the cross-section (0 for a passive rod).
    """

    length: float
    EA: float
    GA: float
    EI: float
    GJ: float
    mass_per_length: float = 0.0
    endplate_mass: float = 0.0
    n_tubes: int = 0

    def __post_init__(self):
        _number(self, "length", 0.0, _MAX_LENGTH, "m", open_low=True)
        for name in ("EA", "GA"):
            _number(self, name, 0.0, _MAX_STIFFNESS, "N", open_low=True)
        for name in ("EI", "GJ"):
            _number(self, name, 0.0, _MAX_STIFFNESS, "N m²", open_low=True)
        _number(self, "mass_per_length", 0.0, _MAX_MASS, "kg/m")
        _number(self, "endplate_mass", 0.0, _MAX_MASS, "kg")
        _integer(self, "n_tubes", 0, MAX_TUBES, " (solver.designs.MAX_TUBES)")


@dataclass(frozen=True)
class Tube:
    """One extensor, placed in the cross-section and assigned to a channel.

    Attributes:
        channel: index into :attr:`ArmDesign.channels` (the spatial channel that feeds it).
        angle_deg: angular position about d3, from +d1 towards +d2 (deg).
        radius: distance of the tube axis from the backbone (m).
        first_section, last_section: the sections it spans (inclusive, 0-based).
        material: its actuator model.
    """

    channel: int
    angle_deg: float
    radius: float
    first_section: int
    last_section: int
    material: TubeMaterial

    def __post_init__(self):
        _integer(self, "channel", 0, MAX_TUBES - 1, " (solver.designs.MAX_TUBES channels)")
        _number(self, "angle_deg", -360.0, 360.0, "deg")
        _number(self, "radius", 0.0, _MAX_RADIUS, "m")
        for name in ("first_section", "last_section"):
            _integer(self, name, 0, MAX_SECTIONS - 1, " (solver.designs.MAX_SECTIONS sections)")
        if self.first_section > self.last_section:
            raise ValueError(
                f"tube spans sections {self.first_section}..{self.last_section}: need "
                "0 <= first_section <= last_section")
        object.__setattr__(self, "material", _build(TubeMaterial, self.material, "Tube.material"))

    @property
    def offset(self) -> tuple[float, float]:
        """Position in the cross-section, components along (d1, d2) (m)."""
        a = math.radians(self.angle_deg)
        return self.radius * math.cos(a), self.radius * math.sin(a)


@dataclass(frozen=True)
class ArmDesign:
    """A multi-section soft arm: sections, tubes, channels and the rated pressure.

    Attributes:
        name: short identifier (``"octarm_v"``).
        sections: base to tip.
        tubes: every extensor, with position, span and channel.
        channels: names of the spatial channels (one pressure each in spatial mode).
        planar_channels: ``(name, (spatial channel indices...))`` pairs; in planar mode one
            pressure per entry drives all its spatial channels.
        max_pressure: rated maximum channel pressure (Pa).
        source: where the numbers come from, and what was assumed.
    """

    name: str
    sections: tuple[Section, ...]
    tubes: tuple[Tube, ...] = ()
    channels: tuple[str, ...] = ()
    planar_channels: tuple[tuple[str, tuple[int, ...]], ...] = ()
    max_pressure: float = 0.0
    source: str = ""
    extra: dict = field(default_factory=dict, compare=False, hash=False)
    # What the solver derives from this (immutable) design, keyed by what it depends on.
    _solver_cache: DesignCache = field(default_factory=DesignCache, init=False, repr=False,
                                       compare=False, hash=False)

    def __post_init__(self):
        _text(self.name, "ArmDesign.name", _MAX_NAME)
        _text(self.source, "ArmDesign.source", _MAX_SOURCE, allow_empty=True)
        try:
            plain = isinstance(self.extra, dict) and bool(json.dumps(self.extra, allow_nan=False))
        except (TypeError, ValueError, RecursionError):
            plain = False
        if not plain:
            raise ValueError("ArmDesign.extra must be a mapping of plain JSON values (finite numbers, "
                             f"strings, lists, mappings); got {_short(self.extra)}")
        sections = _entries(self.sections, "ArmDesign.sections", MAX_SECTIONS, "MAX_SECTIONS")
        object.__setattr__(self, "sections", tuple(
            _build(Section, s, f"sections[{k}]") for k, s in enumerate(sections)))
        tubes = _entries(self.tubes, "ArmDesign.tubes", MAX_TUBES, "MAX_TUBES")
        object.__setattr__(self, "tubes", tuple(_build(Tube, t, f"tubes[{k}]") for k, t in enumerate(tubes)))
        channels = _entries(self.channels, "ArmDesign.channels", MAX_TUBES, "MAX_TUBES")
        object.__setattr__(self, "channels", tuple(
            _text(c, f"channels[{k}]", _MAX_NAME) for k, c in enumerate(channels)))
        planar = []
        for k, entry in enumerate(_entries(self.planar_channels, "ArmDesign.planar_channels", MAX_TUBES,
                                           "MAX_TUBES")):
            if not isinstance(entry, (list, tuple)) or len(entry) != 2:
                raise ValueError(f"planar_channels[{k}] must be a [name, [channel indices...]] pair; "
                                 f"got {_short(entry)}")
            name, idx = entry
            idx = _entries(idx, f"planar_channels[{k}] indices", MAX_TUBES, "MAX_TUBES")
            if any(isinstance(i, bool) or not isinstance(i, numbers.Integral) for i in idx):
                raise ValueError(f"planar_channels[{k}] indices must be integers; got {_short(idx)}")
            planar.append((_text(name, f"planar_channels[{k}] name", _MAX_NAME), tuple(int(i) for i in idx)))
        object.__setattr__(self, "planar_channels", tuple(planar))
        _number(self, "max_pressure", 0.0, _MAX_PRESSURE, "Pa")
        for what, names in (("channel", self.channels), ("planar channel", [n for n, _ in planar])):
            repeated = sorted({n for n in names if names.count(n) > 1})
            if repeated:
                raise ValueError(f"design {self.name!r}: {what} name {repeated[0]!r} is used twice")
        if not self.sections:
            raise ValueError(f"design {self.name!r} has no sections")
        n_sec, n_ch = len(self.sections), len(self.channels)
        for k, t in enumerate(self.tubes):
            if t.last_section >= n_sec:
                raise ValueError(
                    f"design {self.name!r}: tube {k} spans up to section {t.last_section}, "
                    f"but there are only {n_sec} sections")
            if not (0 <= t.channel < n_ch):
                raise ValueError(
                    f"design {self.name!r}: tube {k} belongs to channel {t.channel}, which is "
                    f"outside every channel (0..{n_ch - 1})")
        used = {t.channel for t in self.tubes}
        for c, name in enumerate(self.channels):
            if c not in used:
                raise ValueError(f"design {self.name!r}: channel {name!r} drives no tube")
        for name, idx in self.planar_channels:
            if not idx or any(not (0 <= i < n_ch) for i in idx):
                raise ValueError(f"design {self.name!r}: planar channel {name!r} maps to "
                                 f"{_short(list(idx))}; need one or more channel indices in 0..{n_ch - 1}")
        if self.tubes and not self.max_pressure > 0:
            raise ValueError(f"design {self.name!r}: max_pressure must be a finite number > 0 Pa; "
                             f"got {self.max_pressure!r}")

    @property
    def length(self) -> float:
        """Total reference length (m)."""
        return float(sum(s.length for s in self.sections))

    @property
    def n_channels(self) -> int:
        """Number of spatial channels."""
        return len(self.channels)

    def n_inputs(self, planar: bool = True) -> int:
        """Number of pressures :func:`solver.solve` expects in the given mode."""
        return len(self.planar_channels) if planar else len(self.channels)

    def input_names(self, planar: bool = True) -> tuple[str, ...]:
        """Names of the pressures :func:`solver.solve` expects, in order."""
        return tuple(n for n, _ in self.planar_channels) if planar else self.channels

    def half_thickness(self) -> tuple[float, ...]:
        """Each section's half-thickness (m): the largest ``tube.radius + Ro`` over the
        tubes that span it (0 where none does) — how far its surface stands off the backbone."""
        return tuple(max((t.radius + t.material.outer_radius for t in self.tubes
                          if t.first_section <= i <= t.last_section), default=0.0)
                     for i in range(len(self.sections)))

    @property
    def mass(self) -> float:
        """Total mass of rod and endplates (kg)."""
        return float(sum(s.mass_per_length * s.length + s.endplate_mass for s in self.sections))

    def scaled(self, modulus_factor: float = 1.0, wind_angle_delta_deg: float = 0.0) -> ArmDesign:
        """This design with stiffer or softer rubber and another braid angle, built fast.

        Every tube's rubber moduli E, G and every section's EA, GA, EI, GJ are multiplied by
        ``modulus_factor``; every tube's braid angle is shifted by ``wind_angle_delta_deg``
        (one production batch of tubes: the perturbation of domain randomisation). Only what
        the change can break is checked (the factor, the new angles and the moduli caps), and
        the solver derives the new design's kernel arrays from this design's (see
        :func:`solver.problem.pack`) instead of packing it afresh: a per-episode perturbed arm
        costs microseconds, not a validated rebuild.

        Args:
            modulus_factor: a finite number > 0.
            wind_angle_delta_deg: added to every tube's α (deg); the results must stay in the
                extensor range (54.74°, 90°).

        Returns:
            The new design (equal to one built by ``dataclasses.replace`` with the same values).

        Raises:
            ValueError: a bad factor or angle shift, or a result outside a field's range.
        """
        f, d = modulus_factor, wind_angle_delta_deg
        for name, v, positive in (("modulus_factor", f, True), ("wind_angle_delta_deg", d, False)):
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) \
                    or (positive and not v > 0):
                raise ValueError(f"ArmDesign.scaled: {name} must be a finite number"
                                 f"{' > 0' if positive else ''}; got {_short(v)}")
        f, d = float(f), float(d)
        lock = math.degrees(math.acos(1.0 / math.sqrt(3.0)))
        materials = {}
        for t in self.tubes:
            mat = t.material
            if id(mat) in materials:
                continue
            alpha, e, g = mat.wind_angle_deg + d, mat.youngs_modulus * f, mat.shear_modulus * f
            if not lock < alpha < 90.0 or max(e, g) > _MAX_MODULUS:
                raise ValueError(f"ArmDesign.scaled({f:g}, {d:g}) takes a tube of {self.name!r} to "
                                 f"α = {alpha:g}° (need ({lock:.2f}, 90)), E = {e:g} Pa, G = {g:g} Pa "
                                 f"(at most {_MAX_MODULUS:g})")
            materials[id(mat)] = _unchecked(mat, youngs_modulus=e, shear_modulus=g, wind_angle_deg=alpha)
        if max(max(s.EA, s.GA, s.EI, s.GJ) for s in self.sections) * f > _MAX_STIFFNESS:
            raise ValueError(f"ArmDesign.scaled({f:g}): a section stiffness of {self.name!r} exceeds "
                             f"{_MAX_STIFFNESS:g}")
        arm = _unchecked(
            self, sections=tuple(_unchecked(s, EA=s.EA * f, GA=s.GA * f, EI=s.EI * f, GJ=s.GJ * f)
                                 for s in self.sections),
            tubes=tuple(_unchecked(t, material=materials[id(t.material)]) for t in self.tubes),
            _solver_cache=DesignCache(scaled_from=(self, f)))
        return arm

    def to_json(self) -> str:
        """Serialise to JSON (round-trips through :func:`from_json`)."""
        data = {"name": self.name, "sections": [asdict(s) for s in self.sections],
                "tubes": [asdict(t) for t in self.tubes], "channels": list(self.channels),
                "planar_channels": [[n, list(idx)] for n, idx in self.planar_channels],
                "max_pressure": self.max_pressure, "source": self.source}
        return json.dumps(data, indent=2, allow_nan=False)


def from_json(text: str) -> ArmDesign:
    """Build a design from the JSON written by :meth:`ArmDesign.to_json`.

    Raises:
        ValueError: (one line) text over :data:`MAX_FILE_BYTES`, malformed or too deeply nested
            JSON, unknown or missing fields, or any invalid value such as ``NaN`` or ``Infinity``
            (module docstring).
    """
    if len(text) > MAX_FILE_BYTES:
        raise ValueError(f"design file has {len(text):,} characters; at most {MAX_FILE_BYTES:,} are "
                         "read (solver.designs.MAX_FILE_BYTES)")
    try:
        data = json.loads(text)  # NaN/Infinity parse to floats and fail the field's check, by name
    except json.JSONDecodeError as exc:
        raise ValueError(f"design file is not valid JSON: {exc}") from None
    except RecursionError:
        raise ValueError("design file is nested too deeply to be a design") from None
    except ValueError as exc:  # an integer of more digits than Python converts
        raise ValueError(f"design file has an unusable number: {str(exc).split(';')[0]}") from None
    if not isinstance(data, dict):
        raise ValueError("design file must hold a JSON object")
    return _build(ArmDesign, data, "design file")


EXAMPLES_DIR = Path(__file__).resolve().parent / "examples"
"""Example design files shipped with the package (``solver/examples/*.json``)."""


def example_file(name: str = "two_section_pneumatic") -> Path:
    """The path of a shipped example design, e.g. ``load(example_file())``.

    Raises:
        ValueError: no example of that name (the message lists the ones there are).
    """
    path = EXAMPLES_DIR / f"{name}.json"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in EXAMPLES_DIR.glob("*.json")))
        raise ValueError(f"no example design {name!r}; examples: {known}")
    return path


def load(path) -> ArmDesign:
    """Read a design JSON file of at most :data:`MAX_FILE_BYTES` (see :func:`from_json`).

    Raises:
        OSError: the file cannot be read.
        ValueError: anything wrong with its content, on one line.
    """
    with open(path, "rb") as fh:
        raw = fh.read(MAX_FILE_BYTES + 1)
    if len(raw) > MAX_FILE_BYTES:
        raise ValueError(f"design file is larger than {MAX_FILE_BYTES:,} bytes "
                         "(solver.designs.MAX_FILE_BYTES)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"design file is not UTF-8 text (byte {exc.start})") from None
    return from_json(text)


# --------------------------------------------------------------------------- builders

OCTARM_V_TUBE = TubeMaterial(
    youngs_modulus=2.0e6, shear_modulus=0.4e6, density=1500.0,
    inner_radius=9.3e-3, outer_radius=14.0e-3, wind_angle_deg=78.0)
"""OctArm V extensor, Table 2.1."""


def _ring_radius(material: TubeMaterial, n_tubes: int) -> float:
    """Circumradius δ = Ro / sin(π/N_t) of N_t touching tubes (Eq. 2.52)."""
    return material.outer_radius / math.sin(math.pi / n_tubes)


def _octarm_tubes(n_tubes: int, section: int, material: TubeMaterial) -> list[Tube]:
    """Tubes of one OctArm section: channel k centred at 120°·k from +d1."""
    delta = _ring_radius(material, n_tubes)
    per = n_tubes // 3
    tubes = []
    for k in range(3):
        centre = 120.0 * k
        for off in _spread(per, 360.0 / n_tubes):
            tubes.append(Tube(channel=3 * section + k, angle_deg=(centre + off) % 360.0,
                              radius=delta, first_section=section, last_section=section,
                              material=material))
    return tubes


def _spread(count: int, spacing: float) -> list[float]:
    """``count`` angles symmetric about 0 with ``spacing`` degrees between neighbours."""
    return [spacing * (i - (count - 1) / 2.0) for i in range(count)]


def _bending_stiffness(material: TubeMaterial, tubes: list[Tube], n_tubes: int, ei: str) -> float:
    """EI of a section by the named formula (module docstring)."""
    if ei == "eq2.32":
        return material.youngs_modulus * n_tubes * (
            material.second_moment + material.area * material.outer_radius**2 / 2.0)
    if ei == "tubes":
        return material.youngs_modulus * sum(
            material.second_moment + material.area * t.offset[0] ** 2 for t in tubes)
    raise ValueError(f"unknown ei formula {ei!r}; choose 'eq2.32' or 'tubes'")


def _tube_section(material: TubeMaterial, length: float, n_tubes: int, tubes, ei: str,
                  endplate_mass: float = 0.0, fluid_density: float = 0.0,
                  EI: float | None = None) -> Section:
    """Section stiffness from N_t identical tubes (Eqs. 2.31–2.33)."""
    area = n_tubes * material.area
    bending = _bending_stiffness(material, tubes, n_tubes, ei) if EI is None else EI
    return Section(
        length=length, EA=material.youngs_modulus * area, GA=material.shear_modulus * area,
        EI=bending, GJ=2.0 * bending * material.shear_modulus / material.youngs_modulus,
        mass_per_length=material.density * area + fluid_density * n_tubes * material.bore_area,
        endplate_mass=endplate_mass, n_tubes=n_tubes)


def _octarm(name, lengths, counts, material, max_pressure, ei, endplate_masses, source,
            fluid_density=0.0) -> ArmDesign:
    sections, tubes, channels, planar = [], [], [], []
    for i, (length, n) in enumerate(zip(lengths, counts)):
        if n % 3:
            raise ValueError(f"an OctArm section needs a multiple of 3 tubes; got {n}")
        sec_tubes = _octarm_tubes(n, i, material)
        tubes += sec_tubes
        sections.append(_tube_section(material, length, n, sec_tubes, ei,
                                      endplate_mass=endplate_masses[i], fluid_density=fluid_density))
        channels += [f"s{i + 1}_I", f"s{i + 1}_II", f"s{i + 1}_III"]
        planar += [(f"s{i + 1}_I", (3 * i,)), (f"s{i + 1}_II+III", (3 * i + 1, 3 * i + 2))]
    return ArmDesign(name=name, sections=tuple(sections), tubes=tuple(tubes),
                     channels=tuple(channels), planar_channels=tuple(planar),
                     max_pressure=max_pressure, source=source)


def octarm_v(ei: str = "eq2.32", endplate_mass: float = 0.0) -> ArmDesign:
    """OctArm V, Table 2.1: sections 25/28/30 cm with 6/3/3 tubes, rated 100 psi.

    Args:
        ei: bending-stiffness formula, ``"eq2.32"`` (default) or ``"tubes"``.
        endplate_mass: lumped mass at each section end (kg). Table 2.1 lists none and the
            chapter-2 model carries none, so the default is 0.
    """
    return _octarm(
        "octarm_v", (0.25, 0.28, 0.30), (6, 3, 3), OCTARM_V_TUBE, 100.0 * PSI, ei,
        (endplate_mass,) * 3,
        "Table 2.1 (L, N_t, Ro, Ri, rho, E, G, alpha); 100 psi rating from the §2.4 workspace "
        "range; GJ = 2·EI·G/E (thin-walled bundle, J = 2I) is an assumption (planar results "
        "do not depend on it).")


OCTARM_VI_YOUNGS = 1.2e6
"""OctArm VI rubber modulus: Table 3.1's pneumatic design, which §3.4.1 says is based on
OctArm VI (natural rubber)."""


def octarm_vi() -> ArmDesign:
    """OctArm VI, Table 4.2: measured EA, GA = EA/3, EI; 280/265/325 mm; 6-6-3 tubes; 90 psi.

    Table 4.2 gives stiffnesses, not tubes. With E = 1.2 MPa (Table 3.1 pneumatic design,
    "based on OctArm VI"), EA = 6·E·At and EI = 6·E·(I_tube + At·Ro²/2) give
    Ro = 12.38 mm, Ri = 6.25 mm; the 3-tube section then reproduces EA3 and EI3 exactly
    (half of sections 1–2), which checks the reading. α = 78° (Table 4.2), ρ = 1500 kg/m³
    (Table 3.1). Encoder cables run at R = 42.9 mm (Table 4.2); see ``extra``.
    """
    ea6, ei6 = 2584.0, 0.3225
    e = OCTARM_VI_YOUNGS
    at = ea6 / (6 * e)
    # 3Ro² + Ri² = 4·EI/(6·E·At) and Ro² − Ri² = At/π  ->  solve for Ro², Ri².
    s1 = 4.0 * ei6 / (6.0 * e * at)
    s2 = at / math.pi
    ro2 = (s1 + s2) / 4.0
    ri2 = ro2 - s2
    material = TubeMaterial(youngs_modulus=e, shear_modulus=e / 3.0, density=1500.0,
                            inner_radius=math.sqrt(ri2), outer_radius=math.sqrt(ro2),
                            wind_angle_deg=78.0)
    design = _octarm(
        "octarm_vi", (0.280, 0.265, 0.325), (6, 6, 3), material, 90.0 * PSI, "eq2.32",
        (0.0, 0.0, 0.0),
        "Table 4.2 (EA, GA = EA/3, EI, alpha, cable radius R, lengths); 6-6-3 tubes (§3.4.3); "
        "E = 1.2 MPa and rho = 1500 from Table 3.1; Ro, Ri derived from EA and EI; 90 psi "
        "rating from the §4.3 study range.")
    # Use Table 4.2's stiffnesses verbatim (the derived tube reproduces them to rounding).
    table = ((2584.0, 0.3225), (2584.0, 0.3225), (1292.0, 0.1613))
    sections = tuple(replace(s, EA=ea, GA=ea / 3.0, EI=ei_, GJ=2.0 * ei_ / 3.0)
                     for s, (ea, ei_) in zip(design.sections, table))
    return replace(design, sections=sections, extra={"cable_radius": 42.9e-3})


def ct(ei: str = "eq2.32", lengths: tuple[float, float] = (0.25, 0.28),
       max_pressure: float = 70.0 * PSI) -> ArmDesign:
    """Continuous-tube arm, chapter 5: two sections, no endplates, all manifolding at the base.

    Inner tubes (3, ring radius 2Ro/√3 — touching) span both sections; outer tubes (3, at
    4Ro/√3 in the gaps) end at the junction. These radii reproduce the moment coefficients of
    Table 5.1 (√3/3 and 1 for the inner ring, 4√3/3 for an outer tube on the axis).

    Numbers the thesis does not give, chosen here: the OctArm V tube (Table 2.1 — the CT
    prototype of Fig. 5.1 uses the same extensors) and section lengths 25/28 cm (the first
    two OctArm V sections, so that the §5.3.1 comparison arm is :func:`octarm_two_section`);
    70 psi rating (the §5.3.1 study range).
    """
    m = OCTARM_V_TUBE
    inner = 2.0 * m.outer_radius / math.sqrt(3.0)
    outer = 4.0 * m.outer_radius / math.sqrt(3.0)
    tubes = [Tube(channel=k, angle_deg=120.0 * k, radius=inner, first_section=0, last_section=1,
                  material=m) for k in range(3)]
    tubes += [Tube(channel=3 + k, angle_deg=(120.0 * k + 180.0) % 360.0, radius=outer,
                   first_section=0, last_section=0, material=m) for k in range(3)]
    if ei == "eq2.32":
        ei1 = m.youngs_modulus * (6 * m.second_moment + 2.5 * m.area * m.outer_radius**2)
    else:
        ei1 = None
    s1 = _tube_section(m, lengths[0], 6, tubes, ei, EI=ei1)
    s2 = _tube_section(m, lengths[1], 3, tubes[:3], ei)
    channels = ("inner_I", "inner_II", "inner_III", "outer_I", "outer_II", "outer_III")
    planar = (("inner_I", (0,)), ("inner_II+III", (1, 2)), ("outer_I", (3,)),
              ("outer_II+III", (4, 5)))
    return ArmDesign(
        name="ct", sections=(s1, s2), tubes=tuple(tubes), channels=channels,
        planar_channels=planar, max_pressure=max_pressure,
        source="Chapter 5, Table 5.1 (tube layout, I_1 = 6I + 5AtRo²/2, A_T); OctArm V tube "
               "(Table 2.1) and 25/28 cm sections assumed; 70 psi from §5.3.1.")


def octarm_two_section(endplate_mass: float = 0.0, ei: str = "eq2.32") -> ArmDesign:
    """The OctArm-type two-section arm of §5.3.1: OctArm V sections 1–2 (6 + 3 tubes)."""
    d = _octarm("octarm_2s", (0.25, 0.28), (6, 3), OCTARM_V_TUBE, 70.0 * PSI, ei,
                (endplate_mass, endplate_mass),
                "OctArm V sections 1-2 (Table 2.1) as the §5.3.1 comparison arm; 70 psi.")
    return d


def rod(length: float = 1.0, EI: float = 1.0, EA: float = 1e9, GA: float = 1e9,
        mass_per_length: float = 0.0, GJ: float | None = None) -> ArmDesign:
    """A passive uniform rod (no channels): for oracles and tests."""
    sec = Section(length=length, EA=EA, GA=GA, EI=EI, GJ=EI if GJ is None else GJ,
                  mass_per_length=mass_per_length)
    return ArmDesign(name="rod", sections=(sec,), source="user-defined passive rod")


@dataclass(frozen=True)
class FluidDesign:
    """Table 3.1 design parameters (pneumatic or hydraulic)."""

    youngs_modulus: float
    density: float
    wind_angle_deg: float
    outer_radius: float
    length: float
    test_pressure: float
    max_pressure: float
    beta: float
    fluid_density: float


PNEUMATIC = FluidDesign(1.2e6, 1500.0, 78.0, 15e-3, 1.0, 0.14e6, 0.7e6, 0.09, 0.0)
HYDRAULIC = FluidDesign(12e6, 1500.0, 78.0, 15e-3, 1.0, 1.4e6, 7.0e6, 0.09, 1000.0)


def fluid_arm(name, params: FluidDesign, tube_counts, lengths, thickness, outer_radius=None,
              ei="eq2.32") -> ArmDesign:
    """An OctArm-layout arm from any :class:`FluidDesign` record (Table 3.1 or a variant of it).

    Args:
        name: design name. params: material, wind angle, rating and fluid.
        tube_counts: tubes per section (multiples of 3). lengths: section lengths (m).
        thickness: tube wall thickness (m). outer_radius: Ro (m), default ``params``'.
        ei: bending-stiffness formula.
    """
    ro = params.outer_radius if outer_radius is None else outer_radius
    if not 0 < thickness < ro:
        raise ValueError(f"tube thickness {thickness} m must lie in (0, Ro={ro} m)")
    material = TubeMaterial(youngs_modulus=params.youngs_modulus,
                            shear_modulus=params.youngs_modulus / 3.0, density=params.density,
                            inner_radius=ro - thickness, outer_radius=ro,
                            wind_angle_deg=params.wind_angle_deg)
    return _octarm(name, lengths, tube_counts, material, params.max_pressure, ei,
                   (0.0,) * len(lengths),
                   f"Table 3.1 {name} design; G = E/3 (incompressible rubber); no endplates.",
                   fluid_density=params.fluid_density)


def pneumatic(tube_counts, lengths, thickness, outer_radius=None, ei="eq2.32") -> ArmDesign:
    """A Table 3.1 pneumatic arm (E 1.2 MPa, α 78°, 0.7 MPa rating) with the given layout."""
    return fluid_arm("pneumatic", PNEUMATIC, tube_counts, lengths, thickness, outer_radius, ei)


def hydraulic(tube_counts, lengths, thickness, outer_radius=None, ei="eq2.32") -> ArmDesign:
    """A Table 3.1 hydraulic arm (E 12 MPa, 7 MPa rating; tubes filled with water)."""
    return fluid_arm("hydraulic", HYDRAULIC, tube_counts, lengths, thickness, outer_radius, ei)


_NAMED = {"octarm_v": octarm_v, "octarm_vi": octarm_vi, "ct": ct,
          "octarm_2s": octarm_two_section}
DESIGN_NAMES = tuple(_NAMED)


def get(name: str, **kwargs) -> ArmDesign:
    """A named design (``octarm_v``, ``octarm_vi``, ``ct``, ``octarm_2s``)."""
    try:
        return _NAMED[name](**kwargs)
    except KeyError:
        raise ValueError(f"unknown design {name!r}; choose one of {', '.join(_NAMED)}") from None
