"""Workspace and manipulability analysis of soft arms (thesis §2.4 and chapter 5).

``workspace`` sweeps a pressure grid and returns the tip cloud with its area, density,
highest point and mean; ``dexterity_map`` adds the Jacobian and the dexterity measures at
every grid point (``*_plan`` give their chunks, to run with :class:`softarm_gym.jobs.Runner`:
Ray, resume, one progress bar for several sweeps); ``reproduce`` holds the thesis
reproductions behind ``softarm workspace`` and ``softarm dexterity``.
"""

from softarm_gym.analysis.manipulability import (
    DEFAULT_REL_STEP,
    MEASURES,
    METHODS,
    Dexterity,
    DexterityMap,
    dexterity,
    dexterity_map,
    dexterity_plan,
    jacobian,
    step_study,
)
from softarm_gym.analysis.sweep import BACKENDS, PressureGrid, pressure_grid, sweep_tips, tips_plan
from softarm_gym.analysis.workspace import (
    DEFAULT_ALPHA_FRACTION,
    Workspace,
    alpha_complex,
    alpha_shape_area,
    occupancy_area,
    workspace,
    workspace_plan,
)

__all__ = [
    "DEFAULT_REL_STEP", "MEASURES", "METHODS", "Dexterity", "DexterityMap", "dexterity",
    "dexterity_map", "dexterity_plan", "jacobian", "step_study", "BACKENDS", "PressureGrid",
    "pressure_grid", "sweep_tips", "tips_plan", "DEFAULT_ALPHA_FRACTION", "Workspace",
    "alpha_complex", "alpha_shape_area", "occupancy_area", "workspace", "workspace_plan",
]
