"""Sensors synthesised from a solved equilibrium (thesis chapter 4, Table 4.3).

Three kinds of sensor, as in Figs. 4.1–4.3:

* **Cable encoders.** A cable is fixed to every endplate at distance R from the backbone
  and circumferential angle φ from d1 (towards d2); encoder k of section i measures the
  cable from the base to the end of section i. In the plane there are two cables, at
  φ = 0 (+R·d1, the channel-I side) and φ = π (−R·d1); in space three, at φ = 0°, 120°,
  240° (OctArm VI's nine encoders). The cable point is r_c = r + R(cos φ d1 + sin φ d2), so
  with r' = R_b v and d_j' = R_b (u × e_j) its length is the exact integral

      l = ∫ |v + u × ρ| ds,   ρ = R (cos φ, sin φ, 0)   (body frame)

  which in the plane, with ρ = ±R e1, is l± = ∫ √((v3 ∓ R u)² + v1²) ds. Without shear
  (v1 = 0) this is Eq. (4.24) with κ = θ' and τ = 0, and with constant strains
  l± = L0·v3 ∓ R·Δθ (Eq. 4.28). The integral is evaluated from the equilibrium's recorded
  strains by composite Simpson quadrature on the solver's RK4 nodes (error ∝ h⁴).
* **Inclinometers** at the base and at each section end. Planar: θ of d3 from +x (rad).
  Spatial: a two-axis tilt sensor, (asin(d3·ŷ), asin(d1·ŷ)) — the elevation of the axis
  and of d1 above the horizontal (rad); heading about gravity is not observable.
* **IMUs** (spatial only) at the base and at each section end: an accelerometer and a
  magnetometer, which report the world's up direction ŷ and magnetic north (taken as +x)
  in the sensor's body frame [d1 d2 d3]: a = Rᵀŷ, b = Rᵀx̂ (six numbers per sensor). The
  pair fixes the whole orientation (:func:`imu_frames`, the TRIAD construction), heading
  included, which a tilt sensor cannot see; gravity and north are never parallel, so there
  is no gimbal lock. The thesis has no IMU: the noise (per component, in radians of the
  unit vectors) is an assumption, set in :meth:`SensorNoise.thesis` to the class of the
  Table 4.3 inclinometer (2.5°) for both.
* **A 6-axis load cell** at the base: the wrench (n(0), m(0)) the arm applies to its mount,
  i.e. the internal force and moment at s = 0, reported in the world frame. Planar
  (n_x, n_y, m_z); spatial (n_x, n_y, n_z, m_x, m_y, m_z). Its noise acts in the sensor's
  own frame (the base directors): shear along d1, d2; axial along d3.

Noise (:class:`SensorNoise`): optional additive Gaussian noise, then quantisation to the
sensor's resolution (round to the nearest count). Defaults from Table 4.3 (encoder 3 cm,
inclinometer 2.5°, load cell 1/200 N shear, 1/100 N axial, 1/800 N m); the base inclinometer
is the USD-T2 of §4.3 (Δθ0 = 8.7e-4 rad = 0.05°), which the load-cell study assumes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

import solver
from softarm_gym.sensing.kernels import planar_cable_integrand, section_integrals

__all__ = ["SensorNoise", "SensorReadings", "synthesize", "cable_angles", "cable_radius", "imu_frames"]

DEFAULT_CABLE_RADIUS = 42.9e-3
"""Table 4.2 cable radius R (m), used when a design carries no ``extra["cable_radius"]``."""


@dataclass(frozen=True)
class SensorNoise:
    """Resolution and Gaussian noise of every sensor (0 switches a term off).

    Attributes:
        encoder_resolution: cable-encoder count (m).
        inclinometer_resolution_deg: section-end inclinometer resolution (deg).
        base_inclinometer_resolution_deg: base inclinometer resolution (deg); ``None`` means
            the same as ``inclinometer_resolution_deg``.
        force_resolution: load-cell shear-force resolution, along d1 and d2 (N).
        axial_force_resolution: load-cell axial-force resolution, along d3 (N).
        moment_resolution: load-cell moment resolution (N m).
        imu_tilt_resolution_deg: IMU accelerometer resolution, per component of the measured
            up direction, as an angle (deg); spatial only.
        imu_heading_resolution_deg: IMU magnetometer resolution, per component of the
            measured north direction, as an angle (deg); spatial only.
        gaussian_std: standard deviation of additive Gaussian noise, in units of each
            sensor's resolution (dimensionless), added before quantisation.
        quantize: round each reading to its resolution. With ``quantize=False`` the
            resolutions only scale the Gaussian noise.
    """

    encoder_resolution: float = 0.0
    inclinometer_resolution_deg: float = 0.0
    base_inclinometer_resolution_deg: float | None = None
    force_resolution: float = 0.0
    axial_force_resolution: float = 0.0
    moment_resolution: float = 0.0
    gaussian_std: float = 0.0
    quantize: bool = True
    imu_tilt_resolution_deg: float = 0.0
    imu_heading_resolution_deg: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "quantize":
                if not isinstance(v, (bool, np.bool_)):
                    raise ValueError(f"SensorNoise.quantize must be a bool; got {v!r}")
                continue
            if v is None and f.name == "base_inclinometer_resolution_deg":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v) or v < 0:
                raise ValueError(f"SensorNoise.{f.name} must be a finite number >= 0; got {v!r}")
            object.__setattr__(self, f.name, float(v))

    @classmethod
    def off(cls) -> SensorNoise:
        """Perfect sensors."""
        return cls()

    @classmethod
    def thesis(cls, **overrides) -> SensorNoise:
        """Table 4.3 resolutions (and the §4.3 USD-T2 base inclinometer), quantised; the
        IMUs (no thesis figure) at the inclinometer's 2.5°."""
        values = dict(encoder_resolution=0.03, inclinometer_resolution_deg=2.5,
                      base_inclinometer_resolution_deg=math.degrees(8.7e-4),
                      force_resolution=1.0 / 200.0, axial_force_resolution=1.0 / 100.0,
                      moment_resolution=1.0 / 800.0, imu_tilt_resolution_deg=2.5,
                      imu_heading_resolution_deg=2.5)
        values.update(overrides)
        return cls(**values)

    @property
    def is_off(self) -> bool:
        """True when every reading is exact."""
        resolutions = (self.encoder_resolution, self.inclinometer_resolution_deg,
                       self.base_inclinometer_deg, self.force_resolution,
                       self.axial_force_resolution, self.moment_resolution,
                       self.imu_tilt_resolution_deg, self.imu_heading_resolution_deg)
        return not any(resolutions) or (not self.quantize and self.gaussian_std == 0.0)

    @property
    def base_inclinometer_deg(self) -> float:
        """Resolution of the base inclinometer (deg)."""
        if self.base_inclinometer_resolution_deg is None:
            return self.inclinometer_resolution_deg
        return self.base_inclinometer_resolution_deg

    def apply(self, values: np.ndarray, resolution, rng) -> np.ndarray:
        """Noisy, quantised copy of ``values`` given per-element ``resolution`` (same units)."""
        res = np.broadcast_to(np.asarray(resolution, dtype=float), np.shape(values))
        out = np.array(values, dtype=float)
        if self.gaussian_std > 0 and np.any(res > 0):
            if rng is None:
                raise ValueError("SensorNoise with gaussian_std > 0 needs an rng "
                                 "(numpy.random.Generator)")
            out += rng.normal(0.0, 1.0, out.shape) * self.gaussian_std * res
        if self.quantize:
            counted = res > 0
            out = np.where(counted, np.round(out / np.where(counted, res, 1.0)) * res, out)
        return out


@dataclass(frozen=True)
class SensorReadings:
    """What the sensors report for one equilibrium.

    Attributes:
        encoder_lengths: (n_sections, n_cables) cable lengths from the base to the end of
            section i (m); planar 2 cables (+R·d1, −R·d1), spatial 3 (φ = 0°, 120°, 240°).
        inclinometers: planar (n_sections + 1,) θ at the base and each section end (rad);
            spatial (n_sections + 1, 2) tilt (asin(d3·ŷ), asin(d1·ŷ)) (rad).
        base_wrench: planar (3,) (n_x, n_y, m_z); spatial (6,) (n, m) at the base, world
            frame (N, N m).
        planar: which mode the readings are for.
        imu: spatial (n_sections + 1, 6): per IMU (base, then each section end) the up
            direction and north in its body frame, (a, b) = (Rᵀŷ, Rᵀx̂) (unit vectors up to
            noise; :func:`imu_frames` turns them into orientations); planar, or readings
            made without IMUs: (0, 6).
    """

    encoder_lengths: np.ndarray
    inclinometers: np.ndarray
    base_wrench: np.ndarray
    planar: bool = True
    imu: np.ndarray | None = None

    def __post_init__(self):
        enc = np.array(self.encoder_lengths, dtype=float)
        inc = np.array(self.inclinometers, dtype=float)
        wrench = np.array(self.base_wrench, dtype=float)
        n_cables, n_wrench = (2, 3) if self.planar else (3, 6)
        if enc.ndim != 2 or enc.shape[1] != n_cables:
            raise ValueError(f"encoder_lengths must have shape (n_sections, {n_cables}); got {enc.shape}")
        want_inc = (enc.shape[0] + 1,) if self.planar else (enc.shape[0] + 1, 2)
        if inc.shape != want_inc:
            raise ValueError(f"inclinometers must have shape {want_inc}; got {inc.shape}")
        if wrench.shape != (n_wrench,):
            raise ValueError(f"base_wrench must have shape ({n_wrench},); got {wrench.shape}")
        imu = np.zeros((0, 6)) if self.imu is None else np.array(self.imu, dtype=float)
        if imu.size and (self.planar or imu.shape != (enc.shape[0] + 1, 6)):
            raise ValueError(f"imu must have shape ({enc.shape[0] + 1}, 6) for spatial readings (none "
                             f"for planar ones); got {imu.shape}")
        imu = imu.reshape(-1, 6)
        for name, arr in (("encoder_lengths", enc), ("inclinometers", inc), ("base_wrench", wrench),
                          ("imu", imu)):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"SensorReadings.{name} contains non-finite values")
            arr.setflags(write=False)
        object.__setattr__(self, "encoder_lengths", enc)
        object.__setattr__(self, "inclinometers", inc)
        object.__setattr__(self, "base_wrench", wrench)
        object.__setattr__(self, "imu", imu)

    def as_vector(self) -> np.ndarray:
        """All readings as one flat float array: encoders, inclinometers, base wrench, IMUs."""
        return np.concatenate([self.encoder_lengths.ravel(), self.inclinometers.ravel(),
                               self.base_wrench, self.imu.ravel()])


def imu_frames(imu: np.ndarray) -> np.ndarray:
    """Orientations [d1 d2 d3] (world frame, columns) from IMU readings (TRIAD).

    Args:
        imu: (k, 6) per sensor the up direction a = Rᵀŷ and north b = Rᵀx̂ in the body frame
            (noisy: not exactly unit or orthogonal).

    Returns:
        (k, 3, 3) proper rotations R: up is matched exactly (the accelerometer fixes the
        tilt), north as closely as orthogonality allows (it fixes the heading).

    Raises:
        ValueError: a reading whose up and north directions are (nearly) parallel.
    """
    imu = np.asarray(imu, dtype=float).reshape(-1, 6)
    up = imu[:, :3] / np.linalg.norm(imu[:, :3], axis=1, keepdims=True)
    north = imu[:, 3:] - np.sum(imu[:, 3:] * up, axis=1, keepdims=True) * up
    size = np.linalg.norm(north, axis=1, keepdims=True)
    if not np.all(size > 1e-6):
        raise ValueError("IMU reading with parallel up and north directions: no heading")
    north /= size
    # Body triad (up, north, up × north) ↦ world triad (ŷ, x̂, ŷ × x̂ = −ẑ): R = W·Bᵀ.
    body = np.stack([up, north, np.cross(up, north)], axis=2)  # columns B1 B2 B3
    world = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # columns W1 W2 W3
    return world @ np.transpose(body, (0, 2, 1))


def cable_radius(arm: solver.designs.ArmDesign) -> float:
    """Encoder cable radius R of a design (m): ``arm.extra["cable_radius"]`` or Table 4.2."""
    return float(arm.extra.get("cable_radius", DEFAULT_CABLE_RADIUS))


def cable_angles(planar: bool) -> np.ndarray:
    """Circumferential cable angles φ from d1 towards d2 (rad): (0, π) planar, 0/120/240° spatial."""
    return np.array([0.0, math.pi]) if planar else np.radians([0.0, 120.0, 240.0])


def _cable_lengths(eq: solver.Equilibrium, radius: float) -> np.ndarray:
    """Cumulative cable lengths (n_sections, n_cables): ∫|v + u × ρ| ds by sections."""
    ends = np.asarray(eq.section_ends, dtype=np.int64)
    if eq.planar:
        integrand = np.empty((eq.s.size, 2))
        planar_cable_integrand(eq.shear_stretch, eq.curvature, radius, integrand)
    else:
        phi = cable_angles(False)
        rho = radius * np.column_stack([np.cos(phi), np.sin(phi), np.zeros(3)])  # (3 cables, 3)
        cross = np.cross(eq.curvature[:, None, :], rho[None, :, :])  # (N, cables, 3)
        integrand = np.linalg.norm(eq.shear_stretch[:, None, :] + cross, axis=2)
    lengths = np.empty((ends.size, integrand.shape[1]))
    section_integrals(eq.s, integrand, ends, lengths)
    return lengths


def exact_readings(eq: solver.Equilibrium, arm: solver.designs.ArmDesign):
    """Noise-free (encoder lengths, inclinometers, base wrench) of a recorded equilibrium."""
    if not isinstance(eq, solver.Equilibrium):
        raise ValueError(f"eq must be a solver.Equilibrium; got {type(eq).__name__}")
    if eq.s.size == 0:
        raise ValueError("the equilibrium was solved with record=False; sensors need the "
                         "backbone samples (solve with record=True)")
    if len(eq.section_ends) != len(arm.sections):
        raise ValueError(f"the equilibrium has {len(eq.section_ends)} sections but design "
                         f"{arm.name!r} has {len(arm.sections)}")
    lengths = _cable_lengths(eq, cable_radius(arm))
    idx = [0, *eq.section_ends]
    if eq.planar:
        incl = eq.angles[idx]
        wrench = np.array([eq.internal_force[0, 0], eq.internal_force[0, 1], eq.internal_moment[0]])
    else:
        frames = eq.orientations[idx]
        incl = np.arcsin(np.clip(np.column_stack([frames[:, 1, 2], frames[:, 1, 0]]), -1.0, 1.0))
        wrench = np.concatenate([eq.internal_force[0], eq.internal_moment[0]])
    return lengths, incl, wrench


_PERFECT = SensorNoise()


def synthesize(eq: solver.Equilibrium, arm: solver.designs.ArmDesign,
               noise: SensorNoise | None = None, rng: np.random.Generator | None = None
               ) -> SensorReadings:
    """Sensor readings of an equilibrium, with noise.

    Args:
        eq: a recorded equilibrium (``solve(..., record=True)``) of ``arm``, planar or spatial.
        arm: the design that was solved (gives the cable radius and section count).
        noise: resolutions and Gaussian noise (default: perfect sensors).
        rng: random generator; needed only when ``noise.gaussian_std > 0``.

    Returns:
        The :class:`SensorReadings`.
    """
    noise = _PERFECT if noise is None else noise
    if not isinstance(noise, SensorNoise):
        raise ValueError(f"noise must be a SensorNoise; got {type(noise).__name__}")
    if rng is not None and not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    lengths, incl, wrench = exact_readings(eq, arm)
    imu = None
    if not eq.planar:
        frames = eq.orientations[[0, *eq.section_ends]]
        imu = np.concatenate([frames[:, 1, :], frames[:, 0, :]], axis=1)  # (Rᵀŷ, Rᵀx̂)
    if noise.is_off:
        return SensorReadings(lengths, incl, wrench, planar=eq.planar, imu=imu)
    if imu is not None:
        tilt = math.radians(noise.imu_tilt_resolution_deg)
        heading = math.radians(noise.imu_heading_resolution_deg)
        imu = noise.apply(imu, np.tile(np.repeat([tilt, heading], 3), (imu.shape[0], 1)), rng)
    # The load cell reads in its own frame (the base directors): shear along d1 (d2), axial d3.
    if eq.planar:
        th = eq.angles[0]
        frame = np.array([[-math.sin(th), math.cos(th)], [math.cos(th), math.sin(th)]]).T  # [d1 d3]
        body = np.append(frame.T @ wrench[:2], wrench[2])
        wrench_res = [noise.force_resolution, noise.axial_force_resolution, noise.moment_resolution]
    else:
        frame = eq.orientations[0]
        body = np.concatenate([frame.T @ wrench[:3], frame.T @ wrench[3:]])
        wrench_res = [noise.force_resolution, noise.force_resolution, noise.axial_force_resolution] \
            + [noise.moment_resolution] * 3
    inc_res = np.full(incl.shape, math.radians(noise.inclinometer_resolution_deg))
    inc_res[0] = math.radians(noise.base_inclinometer_deg)
    flat = noise.apply(np.concatenate([lengths.ravel(), incl.ravel(), body]),
                       np.concatenate([np.full(lengths.size, noise.encoder_resolution), inc_res.ravel(),
                                       wrench_res]), rng)
    n_len, n_inc = lengths.size, incl.size
    body = flat[n_len + n_inc:]
    dim = frame.shape[0]
    wrench = np.concatenate([frame @ body[:dim], body[dim:] if eq.planar else frame @ body[dim:]])
    return SensorReadings(flat[:n_len].reshape(lengths.shape), flat[n_len:n_len + n_inc].reshape(incl.shape),
                          wrench, planar=eq.planar, imu=imu)
