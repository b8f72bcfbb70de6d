"""Inputs for calling the planar kernels directly, as the solver packs them."""

import numpy as np

import solver
from solver.problem import context, pack


def planar_case(design: str, payload_kg: float, base_angle_deg: float):
    """(arm, scene, packed arrays, scene context) of a named design with default settings."""
    arm = getattr(solver.designs, design)()
    scene = solver.Scene(payload_kg=payload_kg, base_angle_deg=base_angle_deg)
    settings = solver.Settings()
    packed = pack(arm, "full", settings)
    return arm, scene, packed, context(arm, packed, scene, 2, settings)


def planar_grid(arm, scene, packed, ctx, channel_pressures) -> tuple:
    """(θ0, secf, steps, rest strains, loads): the leading arguments of
    ``solver.rod.integrate_planar`` at ``channel_pressures`` (Pa)."""
    rest = np.vstack(solver.rest_strains(arm, np.asarray(channel_pressures, dtype=float)))
    return scene.base_theta, packed.secf, packed.sec_steps, rest, ctx.loads
