"""Design tools (thesis chapter 3): load capacity, dexterity template, optimal layouts.

* :func:`load_capacity` — the heaviest tip load a horizontal arm lifts to y = 0 at the
  test pressure (§3, Fig. 3.1).
* :func:`template` — section lengths from the wrap angles (Eqs. 3.2–3.3) and the wall
  thickness from a length constraint (Eq. 3.9).
* :func:`sweep` — exhaustive search over tubes per section for the four constraint cases
  (§3.4, Appendix B), pneumatic or hydraulic (Table 3.1).

See ``docs/design_tools.md`` for the choices made where the thesis is ambiguous, and the
reproduction of Figs. 3.4–3.7.
"""

from softarm_gym.design_tools.capacity import CapacityError, LoadCapacity, load_capacity
from softarm_gym.design_tools.sweep import (
    CONSTRAINTS,
    DEFAULT_SIZES,
    FLUIDS,
    TEMPLATE_PRESSURES,
    Candidate,
    Sweep,
    configurations,
    evaluate,
    fluid_params,
    outer_radius,
    sweep,
)
from softarm_gym.design_tools.template import (
    TUBE_COUNTS,
    InfeasibleDesign,
    Template,
    build_arm,
    lifting_channels,
    lifting_pressures,
    section_curvatures,
    section_lengths,
    template,
    wrap_angles,
)

__all__ = [
    "CapacityError", "LoadCapacity", "load_capacity", "CONSTRAINTS", "DEFAULT_SIZES", "FLUIDS",
    "TEMPLATE_PRESSURES", "Candidate", "Sweep", "configurations", "evaluate", "fluid_params",
    "outer_radius", "sweep", "TUBE_COUNTS", "InfeasibleDesign", "Template", "build_arm",
    "lifting_channels", "lifting_pressures", "section_curvatures", "section_lengths", "template",
    "wrap_angles",
]
