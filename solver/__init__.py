"""softarm solver: quasi-static Cosserat rods for multi-section pneumatic soft arms.

Pure numerics: numpy, scipy and numba only (never gymnasium), usable on its own::

    import solver
    arm = solver.designs.octarm_v()
    scene = solver.Scene(base_angle_deg=90.0, payload_kg=0.25)
    eq = solver.solve(arm, [30 * solver.PSI, 0, 0, 0, 0, 0], scene)
    eq.tip, eq.converged, eq.stable
"""

from solver import actuator, designs, rod
from solver.actuator import PSI, pressure_from_stretch, stretch_from_pressure
from solver.batch_spatial import SpatialBatchStepper
from solver.paths.lean_contact import refusal_names
from solver.problem import rest_strains
from solver.results import BatchState, Equilibrium
from solver.scene import Cylinder, Disc, Scene, Sphere
from solver.settings import MODELS, Settings, SolverError
from solver.solve import channel_pressures, solve, solve_batch, step_batch
from solver.stepper import BatchReport, BatchStepper, Stepper, StepReport, ThreadPolicy

__all__ = [
    "actuator", "designs", "rod", "PSI", "pressure_from_stretch", "stretch_from_pressure",
    "Scene", "Disc", "Cylinder", "Sphere", "MODELS", "Equilibrium", "Settings", "SolverError",
    "rest_strains", "solve",
    "solve_batch", "step_batch", "BatchState", "channel_pressures", "Stepper", "StepReport", "ThreadPolicy",
    "BatchStepper", "BatchReport", "SpatialBatchStepper", "refusal_names",
]
