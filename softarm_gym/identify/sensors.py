"""Sensor readings as an observation of :func:`solver.identify.fit`: the sensor models' side.

``solver`` does not know the sensors (they live in :mod:`softarm_gym.sensing`, and the
solver never imports this package), so the fit takes readings through the generic
:class:`solver.identify.Observation` interface, implemented here by
:class:`SensorObservation`: the model's reading of each configuration is
:func:`softarm_gym.sensing.synthesize` of its equilibrium, noise-free — the same sensor model
the environments observe through (:func:`softarm_gym.sensing.sensors.exact_readings`, the
readings :func:`~softarm_gym.sensing.synthesize` adds noise to).

Columns, planar (``k`` counts sections from 1):

* ``enc_s{k}_plus``, ``enc_s{k}_minus`` (m): the cable encoders at +R·d1 and −R·d1, from
  the base to the end of section k;
* ``incl_s{k}`` (rad): the inclinometer at the end of section k, θ of d3 from +x. The
  base inclinometer is left out: it reads the mount's angle, which the data fix;
* ``load_shear``, ``load_axial`` (N), ``load_moment`` (N m): the base load cell in its
  own frame, the force along the base's d1 and d3 and the moment (what a cell bolted to the
  mount reports; Table 4.3 gives its resolutions in that frame).

Noise: a reading quantised to resolution Δ (Table 4.3) is off by up to ±Δ/2, uniformly:
σ = Δ/√12; with Gaussian noise of g resolutions added before the rounding,
σ = Δ·√(g² + 1/12) (:func:`sensor_sigma`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from softarm_gym.sensing import SensorNoise
from softarm_gym.sensing.sensors import exact_readings
from solver.identify import Observation

__all__ = ["SensorObservation", "sensor_labels", "sensor_sigma", "readings_vector"]


def sensor_labels(n_sections: int) -> tuple[str, ...]:
    """The columns of a :class:`SensorObservation` of an arm with ``n_sections`` sections."""
    enc = tuple(f"enc_s{k}_{side}" for k in range(1, n_sections + 1) for side in ("plus", "minus"))
    incl = tuple(f"incl_s{k}" for k in range(1, n_sections + 1))
    return (*enc, *incl, "load_shear", "load_axial", "load_moment")


def _units(n_sections: int) -> tuple[str, ...]:
    return ("m",) * (2 * n_sections) + ("rad",) * n_sections + ("N", "N", "N m")


def sensor_sigma(noise: SensorNoise, n_sections: int) -> np.ndarray:
    """(k,) the standard deviation of each reading's error under ``noise`` (module docstring).

    Raises:
        ValueError: a reading whose σ is zero (perfect sensors carry no noise to weigh by).
    """
    per = math.sqrt(noise.gaussian_std**2 + (1.0 / 12.0 if noise.quantize else 0.0))
    res = np.concatenate([np.full(2 * n_sections, noise.encoder_resolution),
                          np.full(n_sections, math.radians(noise.inclinometer_resolution_deg)),
                          [noise.force_resolution, noise.axial_force_resolution, noise.moment_resolution]])
    sigma = res * per
    if not np.all(sigma > 0):
        zero = [lab for lab, s in zip(sensor_labels(n_sections), sigma) if not s > 0]
        raise ValueError(f"sensor noise gives readings {', '.join(zero)} a zero standard deviation; "
                         "weigh sensor readings by a noise model with resolutions (e.g. "
                         "SensorNoise.thesis())")
    return sigma


def readings_vector(encoder_lengths, inclinometers, base_wrench, base_theta: float) -> np.ndarray:
    """(k,) the columns of :class:`SensorObservation` from planar readings (the fields of
    :class:`~softarm_gym.sensing.SensorReadings`) of an arm whose base points at
    θ0 = ``base_theta`` (rad)."""
    c, s = math.cos(base_theta), math.sin(base_theta)
    nx, ny, m = base_wrench
    load = (-s * nx + c * ny, c * nx + s * ny, m)  # along d1 = (−sin θ0, cos θ0), d3 = (cos θ0, sin θ0)
    return np.concatenate([np.ravel(encoder_lengths), inclinometers[1:], load])


@dataclass(frozen=True)
class SensorObservation(Observation):
    """Measured planar sensor readings (module docstring): cable encoders, section-end
    inclinometers and the base load cell, NaN where a reading was not taken.

    Attributes:
        n_sections: sections of the arm (sets the columns).
    """

    n_sections: int = 3
    name = "sensors"
    needs_backbone = True
    needs_equilibria = True

    @property
    def labels(self):
        return sensor_labels(self.n_sections)

    @property
    def units(self):
        return _units(self.n_sections)

    def check(self, design):
        if len(design.sections) != self.n_sections:
            raise ValueError(f"sensor readings are for {self.n_sections} sections; design {design.name!r} "
                             f"has {len(design.sections)}")

    def predict(self, shapes, design):
        n = self.measured.shape[0]
        out = np.empty((n, len(self.labels)))
        for k in range(n):
            eq = shapes.equilibrium(k)
            out[k] = readings_vector(*exact_readings(eq, design), float(eq.angles[0]))
        # An inclinometer reads θ modulo 2π: the prediction nearest each measured angle.
        incl = slice(2 * self.n_sections, 3 * self.n_sections)
        turns = np.round(np.nan_to_num(self.measured[:, incl] - out[:, incl]) / (2 * math.pi))
        out[:, incl] += 2 * math.pi * turns
        return out
