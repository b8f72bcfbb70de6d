"""The thesis's dexterity template (§3.1, Fig. 3.2) seen through the wrap environment.

A three-section pneumatic arm designed by Eqs. (3.2)–(3.3) (distal section 360°, middle
180°, proximal 120° at p_max; gravity off, as the template neglects loads): its distal section
alone wraps a small object, and a larger one needs the middle section too.
"""

import math

import numpy as np
import pytest

import solver
from softarm_gym.design_tools import build_arm, fluid_params, template
from softarm_gym.envs import WrapEnv, arm_half_thickness


@pytest.fixture(scope="module")
def template_arm():
    params = fluid_params("pneumatic")
    tpl = template(params, (6, 6, 3), 0.015, total_length=1.0)
    return tpl, build_arm(params, tpl.tubes, tpl.section_lengths, tpl.thickness, tpl.outer_radius)


def _wrap(arm, section_start, contact_radius, sections):
    """Hang the arm straight, put the disc beside it at ``section_start``, curl ``sections``."""
    env = WrapEnv(arm, gravity=0.0, base_angle_deg=0.0, initial_pressure_fraction=0.0,
                  max_solver_failures=1000)
    # Channel I of a hanging arm curls it towards -x: the disc sits on that side, 2 mm away.
    obj = (-(contact_radius + 0.002), -section_start, contact_radius - arm_half_thickness(arm))
    env.reset(seed=0, options={"object": obj})
    action = -np.ones(env.n_inputs)
    action[[2 * k for k in sections]] = 1.0
    for frac in np.linspace(0.025, 1.0, 40):
        _, _, _, _, info = env.step(-1.0 + frac * (action + 1.0))
    return info["wrap_angle_deg"]


def test_distal_section_alone_wraps_a_small_object_and_a_large_one_needs_more(template_arm):
    tpl, arm = template_arm
    starts = np.concatenate([[0.0], np.cumsum(tpl.section_lengths)])
    channels = np.zeros(arm.n_channels)
    channels[[0, 3, 6]] = arm.max_pressure
    _, u2, v3 = solver.rest_strains(arm, channels)
    # Small object: the distal section's own curl at p_max (radius v3/|u*|, Eq. 3.3).
    small = v3[2] / abs(u2[2])
    assert _wrap(arm, starts[2], small, sections=(2,)) >= 340.0
    # Large object: one the middle and distal sections together close around (L2 + L3 = 2πρ).
    large = (v3[1] * tpl.section_lengths[1] + v3[2] * tpl.section_lengths[2]) / (2 * math.pi)
    distal_only = _wrap(arm, starts[1], large, sections=(2,))
    both = _wrap(arm, starts[1], large, sections=(1, 2))
    assert distal_only < 180.0
    assert both > distal_only + 60.0
