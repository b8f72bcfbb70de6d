"""Per-episode randomisation of the simulated arm's parameters (domain randomisation).

The environment draws a perturbed copy of the nominal design at every reset; the shape
estimators keep the nominal design, so the randomisation is a model error they do not know.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from solver.designs import ArmDesign

__all__ = ["ArmRandomization"]

_BRAID_LOCK_DEG = math.degrees(math.acos(1.0 / math.sqrt(3.0)))


@dataclass(frozen=True)
class ArmRandomization:
    """Uniform perturbations of the simulated arm, drawn once per episode.

    One wind angle and one modulus factor are drawn per episode and applied to every tube
    and section (a batch of tubes from one production run), so a planar arm stays planar.

    Attributes:
        wind_angle_deg: half-width of the braid-angle perturbation (deg):
            α ~ U(α0 − w, α0 + w) for every tube. The result must stay inside the extensor
            range (54.74°, 90°).
        youngs_modulus_rel: relative half-width of the rubber-modulus perturbation:
            E ~ E0·U(1 − r, 1 + r). The tube moduli E, G and the section stiffnesses
            EA, GA, EI, GJ all scale by the same factor. Must lie in [0, 1).
    """

    wind_angle_deg: float = 0.0
    youngs_modulus_rel: float = 0.0

    def __post_init__(self):
        for name in ("wind_angle_deg", "youngs_modulus_rel"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v) or v < 0:
                raise ValueError(f"ArmRandomization.{name} must be a finite number >= 0; got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.youngs_modulus_rel >= 1.0:
            raise ValueError("ArmRandomization.youngs_modulus_rel must be < 1 (E must stay > 0); "
                             f"got {self.youngs_modulus_rel}")

    @classmethod
    def coerce(cls, value) -> ArmRandomization:
        """``None`` (no randomisation), a mapping of the fields, or an instance."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            valid = [f.name for f in dataclasses.fields(cls)]
            unknown = [repr(k) for k in value if k not in valid]
            if unknown:
                raise ValueError(f"randomization has unknown field(s) {', '.join(unknown)}; valid fields: "
                                 f"{', '.join(valid)}")
            return cls(**value)
        raise ValueError("randomization must be None, a dict with wind_angle_deg / "
                         f"youngs_modulus_rel, or an ArmRandomization; got {value!r}")

    @property
    def active(self) -> bool:
        """True when any perturbation has a non-zero width."""
        return self.wind_angle_deg > 0 or self.youngs_modulus_rel > 0

    def check(self, arm: ArmDesign) -> None:
        """Raise ``ValueError`` if the widths can push a tube of ``arm`` out of its valid range."""
        for tube in arm.tubes:
            alpha = tube.material.wind_angle_deg
            if alpha - self.wind_angle_deg <= _BRAID_LOCK_DEG or alpha + self.wind_angle_deg >= 90.0:
                raise ValueError(
                    f"randomization wind_angle_deg ±{self.wind_angle_deg} takes the braid angle "
                    f"{alpha}° of design {arm.name!r} outside ({_BRAID_LOCK_DEG:.2f}°, 90°)")

    def sample(self, arm: ArmDesign, rng: np.random.Generator) -> ArmDesign:
        """A perturbed copy of ``arm`` (``arm`` itself when nothing is randomised).

        Args:
            arm: the nominal design.
            rng: the environment's generator (the only source of randomness).

        Returns:
            The simulated design for one episode.
        """
        if not self.active:
            return arm
        d_alpha = rng.uniform(-self.wind_angle_deg, self.wind_angle_deg)
        factor = 1.0 + rng.uniform(-self.youngs_modulus_rel, self.youngs_modulus_rel)
        # check() bounded the widths, so the scaled design is valid; scaling derives its
        # kernel arrays from the nominal's instead of validating and packing a new design.
        return arm.scaled(factor, d_alpha)
