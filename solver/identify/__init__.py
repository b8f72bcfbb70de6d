"""Calibrate a design to a real arm: its parameters fitted to measured shapes, with uncertainty.

A lab that builds an arm meets the gap between its design numbers and the arm first; the
thesis names the main cause itself (§2.4: "the model is very sensitive to wind angle, which
varies within each actuator and from actuator to actuator"). This package fits a design's
parameters to measurements of the arm::

    import solver
    from solver.identify import Measurements, TipPositions, fit

    meas = Measurements(pressures, base_angle_deg, payload_kg,
                        observations=(TipPositions(tips, sigma=0.005),))
    result = fit(solver.designs.octarm_v(), meas, "wind_angle:s1,wind_angle:s2,E")
    print(result.summary())
    result.fitted_design                  # a validated ArmDesign (to_json() for a design file)
    result.posterior().sample(rng)        # a design drawn from the fitted distribution

* :mod:`solver.identify.parameters` — the parameters, named as the design names them
  (wind angle per tube group, E, G, stiffness and mass scales per section, tube offsets,
  endplate masses, an unknown payload), with their bounds.
* :mod:`solver.identify.measurements` — configurations, observations (tips, backbone
  markers; sensor readings come from ``softarm_gym.identify``) and the model's predictions.
* :mod:`solver.identify.fitting` — robust least squares, covariance, identifiability, the χ²
  misspecification test, the held-out error, and the posterior for domain randomisation.

Planar measurements only (the thesis's experiments are planar).
"""

from solver.identify.fitting import FORMAT, LOSSES, FitResult, Posterior, fit, identifiable
from solver.identify.measurements import (
           BackbonePoints,
           Measurements,
           Observation,
           Shapes,
           TipPositions,
           predict,
)
from solver.identify.parameters import KINDS, Parameter, apply_parameters, parse_parameters

__all__ = ["fit", "FitResult", "Posterior", "identifiable", "LOSSES", "FORMAT", "Measurements", "Observation",
           "TipPositions", "BackbonePoints", "Shapes", "predict", "Parameter", "KINDS", "parse_parameters",
           "apply_parameters"]
