"""Per-episode randomisation of the simulated arm's parameters (domain randomisation).

The environment draws a perturbed copy of the nominal design at every reset; the shape
estimators keep the nominal design, so the randomisation is a model error they do not know.

Two kinds, chosen by the ``randomization`` argument of the environments
(:func:`coerce_randomization`):

* :class:`ArmRandomization` — uniform ranges around the nominal design
  (``{"wind_angle_deg": 2, "youngs_modulus_rel": 0.1}``): guesses;
* :class:`PosteriorRandomization` — arms drawn from what a calibration found
  (``"fit.json"``, the fit file of ``softarm fit --output``, or ``{"fit": "fit.json",
  "widen": 2}``): the fitted parameters' multivariate normal, correlations kept, clipped to
  their physical bounds (docs/identification.md).
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np

import solver
from solver.designs import ArmDesign

__all__ = ["ArmRandomization", "PosteriorRandomization", "coerce_randomization"]

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


@dataclass(frozen=True)
class PosteriorRandomization:
    """Arms drawn from a fit's posterior, one per episode (:meth:`solver.identify.Posterior.sample`).

    Every fitted parameter is drawn at once from N(mean, widen²·covariance) (the correlations
    the data left between them kept), clipped to its physical bounds, and set in the design
    the fit started from; parameters the fit did not identify keep that design's values.

    Attributes:
        posterior: the fitted parameters' distribution.
        widen: standard-deviation factor (1: as fitted; larger trains for a wider spread of
            arms than the data support; 0: always the fitted arm).
        source: the fit file it was read from ("" if built in Python).
    """

    posterior: solver.identify.Posterior
    widen: float = 1.0
    source: str = ""

    def __post_init__(self):
        from solver.identify import Posterior  # scipy.stats and optimize: only for fitted arms

        if not isinstance(self.posterior, Posterior):
            raise ValueError(f"PosteriorRandomization.posterior must be a solver.identify.Posterior; "
                             f"got {type(self.posterior).__name__}")
        v = self.widen
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                or not math.isfinite(v) or v < 0:
            raise ValueError(f"PosteriorRandomization.widen must be a finite number >= 0; got {v!r}")
        object.__setattr__(self, "widen", float(v))

    @classmethod
    def load(cls, path, widen: float = 1.0) -> PosteriorRandomization:
        """The posterior of the fit file at ``path`` (``softarm fit --output``).

        Raises:
            ValueError: the file cannot be read or is not a fit file (one line).
        """
        from solver.identify import Posterior

        try:
            posterior = Posterior.load(path)
        except OSError as exc:
            raise ValueError(f"randomization: cannot read fit file {str(path)!r}: {exc.strerror}") from None
        return cls(posterior, widen, str(path))

    @property
    def active(self) -> bool:
        """True when the draws vary (a posterior with parameters, widened by more than 0)."""
        return self.widen > 0 and len(self.posterior.parameters) > 0

    def check(self, arm: ArmDesign) -> None:
        """Raise ``ValueError`` unless ``arm`` is the design the fit started from or its fitted
        design (the arms drawn are variants of those)."""
        post = self.posterior
        if arm != post.design and arm != post.mean_design:
            raise ValueError(f"randomization {self.source or 'posterior'} was fitted to design "
                             f"{post.design.name!r}; the environment's design is {arm.name!r}, neither that "
                             "design nor its fitted one")

    def sample(self, arm: ArmDesign, rng: np.random.Generator) -> ArmDesign:
        """A design drawn from the posterior (``arm`` is checked by :meth:`check`, not read).

        Args:
            arm: the environment's nominal design.
            rng: the environment's generator (the only source of randomness).
        """
        if not self.active:
            return self.posterior.mean_design
        return self.posterior.sample(rng, self.widen)


def coerce_randomization(value) -> ArmRandomization | PosteriorRandomization:
    """The randomisation an environment's ``randomization`` argument asks for.

    ``None`` (none), a mapping of :class:`ArmRandomization` fields, a fit file's path (str or
    ``os.PathLike``), ``{"fit": path, "widen": w}``, or an instance of either class.
    """
    if isinstance(value, (ArmRandomization, PosteriorRandomization)):
        return value
    if isinstance(value, (str, os.PathLike)):
        return PosteriorRandomization.load(value)
    if isinstance(value, dict) and "fit" in value:
        unknown = sorted(set(value) - {"fit", "widen"})
        if unknown:
            raise ValueError(f"randomization {{'fit': ...}} takes 'fit' and 'widen'; got {unknown}")
        return PosteriorRandomization.load(value["fit"], value.get("widen", 1.0))
    if value is None or isinstance(value, dict):
        return ArmRandomization.coerce(value)
    raise ValueError("randomization must be None, a dict with wind_angle_deg / youngs_modulus_rel, a fit "
                     f"file (path or {{'fit': path, 'widen': w}}), or an ArmRandomization; got {value!r}")
