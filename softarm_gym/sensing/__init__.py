"""Sensors and shape estimators (thesis chapter 4).

Synthesise what cable encoders, inclinometers and a base load cell would report for a
solved equilibrium, then turn those readings into a backbone shape::

    from softarm_gym.sensing import SensorNoise, synthesize, make_estimator
    readings = synthesize(eq, arm, SensorNoise.thesis(), rng)
    shape = make_estimator("cable_encoder", arm, scene=scene).estimate(readings, pressures)
"""

from softarm_gym.sensing.estimators import (
    ESTIMATORS,
    Estimator,
    ShapeEstimate,
    make_estimator,
    shape_from_equilibrium,
)
from softarm_gym.sensing.sensors import SensorNoise, SensorReadings, synthesize

__all__ = ["ESTIMATORS", "Estimator", "ShapeEstimate", "make_estimator", "shape_from_equilibrium",
           "SensorNoise", "SensorReadings", "synthesize"]
