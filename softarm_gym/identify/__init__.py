"""Calibration of the model to a real arm, on the environments' side of the layering.

:mod:`solver.identify` fits a design's parameters to measured shapes; this package adds what
needs more than the solver:

* :mod:`~softarm_gym.identify.sensors` — sensor readings (cable encoders, inclinometers, the
  base load cell) as an observation of the fit, through the sensor models of
  :mod:`softarm_gym.sensing`;
* :mod:`~softarm_gym.identify.data` — the CSV format of measured shapes, and synthetic data
  made by the solver;
* :mod:`~softarm_gym.identify.plots` — the residual figure of ``softarm fit --plot``;
* :mod:`~softarm_gym.identify.studies` — the validation studies (the Fig. 2.6-style table,
  parameter error against noise, wind-angle sensitivity) and the fit benchmark.

A fit's posterior randomises the environments' arm: ``randomization="fit.json"``
(:class:`softarm_gym.envs.randomization.PosteriorRandomization`). See docs/identification.md.
"""

from softarm_gym.identify.data import (
           PERTURBED_ARM,
           make_synthetic,
           on_off_configurations,
           read_csv,
           write_csv,
)
from softarm_gym.identify.sensors import SensorObservation, sensor_sigma

__all__ = ["SensorObservation", "sensor_sigma", "read_csv", "write_csv", "make_synthetic",
           "on_off_configurations", "PERTURBED_ARM"]
