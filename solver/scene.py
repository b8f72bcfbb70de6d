"""The loading and mounting of an arm: base angle, gravity, payload, tip force and moment."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Scene"]


@dataclass(frozen=True)
class Scene:
    """Everything outside the arm that sets its equilibrium (DESIGN §2 conventions).

    Frame: base at the origin, ``x`` horizontal, ``y`` vertical up, ``z`` out of plane;
    gravity acts along −y.

    Attributes:
        base_angle_deg: angle of the unactuated arm axis from the downward vertical,
            towards +x: 0 hangs down, 90 points along +x, 180 points up.
        payload_kg: point mass at the tip (kg).
        gravity: magnitude of gravitational acceleration (m/s²); 0 switches gravity off.
        tip_force: extra dead force at the tip, (Fx, Fy) or (Fx, Fy, Fz) in N.
        tip_moment: extra dead moment at the tip, Mz (N m) or (Mx, My, Mz).
    """

    base_angle_deg: float = 0.0
    payload_kg: float = 0.0
    gravity: float = 9.81
    tip_force: tuple = (0.0, 0.0)
    tip_moment: float | tuple = 0.0

    def __post_init__(self):
        for name in ("base_angle_deg", "payload_kg", "gravity"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v):
                raise ValueError(f"Scene.{name} must be a finite number; got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.payload_kg < 0:
            raise ValueError(f"Scene.payload_kg must be >= 0; got {self.payload_kg}")
        if self.gravity < 0:
            raise ValueError(f"Scene.gravity must be >= 0 (it always acts along -y); got {self.gravity}")
        force = np.asarray(self.tip_force, dtype=float).ravel()
        if force.size not in (2, 3) or not np.all(np.isfinite(force)):
            raise ValueError(f"Scene.tip_force must be 2 or 3 finite numbers (N); got {self.tip_force!r}")
        moment = np.asarray(self.tip_moment, dtype=float).ravel()
        if moment.size not in (1, 3) or not np.all(np.isfinite(moment)):
            raise ValueError(
                f"Scene.tip_moment must be 1 (Mz) or 3 finite numbers (N m); got {self.tip_moment!r}")
        object.__setattr__(self, "tip_force", tuple(float(f) for f in force))
        object.__setattr__(self, "tip_moment",
                           float(moment[0]) if moment.size == 1 else tuple(float(m) for m in moment))

    @property
    def base_theta(self) -> float:
        """Planar orientation θ0 of d3 at the base, from +x counter-clockwise (rad)."""
        return math.radians(self.base_angle_deg - 90.0)

    def tip_force_3d(self) -> np.ndarray:
        """Tip force as a 3-vector (N)."""
        f = np.zeros(3)
        f[: len(self.tip_force)] = self.tip_force
        return f

    def tip_moment_3d(self) -> np.ndarray:
        """Tip moment as a 3-vector (N m); a scalar is Mz."""
        if isinstance(self.tip_moment, float):
            return np.array([0.0, 0.0, self.tip_moment])
        return np.array(self.tip_moment, dtype=float)

    @property
    def is_planar(self) -> bool:
        """True when no load leaves the x–y plane."""
        m = self.tip_moment_3d()
        return self.tip_force_3d()[2] == 0.0 and m[0] == 0.0 and m[1] == 0.0

    @property
    def unloaded(self) -> bool:
        """True when no external load acts (closed-form arcs apply)."""
        return (self.payload_kg == 0.0 or self.gravity == 0.0) and not np.any(self.tip_force_3d()) \
            and not np.any(self.tip_moment_3d())
