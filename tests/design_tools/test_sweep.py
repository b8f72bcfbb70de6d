"""Exhaustive layout search: configurations, constraint cases, best layout, JSON."""

import math

import numpy as np
import pytest

import solver
from softarm_gym import design_tools as dt

P = solver.designs.PNEUMATIC


def test_configurations_are_exhaustive_or_tapered():
    every = dt.configurations(3)
    assert len(every) == 64 and len(set(every)) == 64
    tapered = dt.configurations(3, tapered=True)
    assert len(tapered) == math.comb(3 + 3, 3)
    assert all(a >= b for c in tapered for a, b in zip(c, c[1:]))
    assert set(tapered) <= set(every)


def _diameter(tubes, ro):
    return 2.0 * (ro / math.sin(math.pi / tubes) + ro)


def test_outer_radius_of_each_constraint_case():
    assert dt.outer_radius(P, "tube-ratio", (12, 3), 2.0) == pytest.approx(0.09)  # 2Ro = βL
    ro = dt.outer_radius(P, "base-ratio", (6, 3), 0.8)
    assert _diameter(6, ro) == pytest.approx(0.09 * 0.8)  # the base section of a tapered arm
    ro = dt.outer_radius(P, "base-ratio", (3, 12, 3), 0.8)
    assert _diameter(12, ro) == pytest.approx(0.09 * 0.8)  # never a bulge wider than that
    ro = dt.outer_radius(P, "diameter", (3, 9, 3), 2.5)
    assert _diameter(9, ro) == pytest.approx(0.09)  # widest section, whatever the length
    assert dt.outer_radius(P, "gripping-radius", (3, 3), 0.3) == P.outer_radius
    with pytest.raises(ValueError, match="constraint"):
        dt.outer_radius(P, "aspect", (3,), 1.0)


def test_ratio_cases_scale_geometrically():
    """With Ro ∝ L the template is scale-free: same t/Ro and L_i/L at every length."""
    a = dt.evaluate(P, "tube-ratio", (12, 6), 0.5)
    b = dt.evaluate(P, "tube-ratio", (12, 6), 1.0)
    assert a.thickness_m / a.outer_radius_m == pytest.approx(b.thickness_m / b.outer_radius_m, rel=1e-8)
    np.testing.assert_allclose(np.array(a.section_lengths_m) / 0.5, np.array(b.section_lengths_m) / 1.0,
                               rtol=1e-8)


def test_sweep_picks_the_largest_load_and_reports_it():
    s = dt.sweep("pneumatic", "tube-ratio", 2, sizes=(0.5, 1.0), progress=False)
    assert len(s.candidates) == 2 and all(len(row) == 16 for row in s.candidates)
    for i, row in enumerate(s.candidates):
        feasible = [c for c in row if c.feasible]
        assert s.best_at(i).load_n == max(c.load_n for c in feasible)
    data = s.to_dict()
    assert set(data["best"]) >= {"tubes", "length_m", "load_n"}
    assert data["best"]["load_n"] == max(c.load_n for c in s.best_per_size)
    assert len(data["sweep"]) == 32
    # Chunks of 5 evaluations (and their trip through JSON) give the same sweep.
    again = dt.sweep("pneumatic", "tube-ratio", 2, sizes=(0.5, 1.0), progress=False, chunk_size=5)
    assert again.to_dict() == data


def test_infeasible_layouts_are_reported_not_raised():
    c = dt.evaluate(P, "diameter", (12, 12, 12), 0.05)
    assert not c.feasible and "thinnest wall" in c.reason and math.isnan(c.load_n)
    assert c.to_dict()["load_n"] is None


def test_gripping_radius_sweeps_the_distal_length():
    c = dt.evaluate(P, "gripping-radius", (6, 3), 0.3)
    assert c.section_lengths_m[-1] == pytest.approx(0.3, rel=1e-9)
    assert c.length_m > 0.3


def test_stiffer_tubes_lift_more():
    """§3.4.5: at a fixed p_max a stiffer tube needs a thinner wall and lifts more."""
    soft = dt.sweep("hydraulic", "base-ratio", 2, sizes=(1.0,), youngs_modulus=12e6, progress=False).best
    stiff = dt.sweep("hydraulic", "base-ratio", 2, sizes=(1.0,), youngs_modulus=48e6, progress=False).best
    assert stiff.thickness_m < soft.thickness_m
    assert stiff.load_n > soft.load_n


@pytest.mark.parametrize("kwargs, match", [
    ({"fluid": "oil"}, "fluid"),
    ({"constraint": "aspect"}, "constraint"),
    ({"n_sections": 0}, "sections"),
    ({"sizes": (0.5, -1.0)}, "sizes"),
    ({"youngs_modulus": -1.0}, "Young"),
    ({"template_pressure": "min"}, "template_pressure"),
])
def test_sweep_rejects_bad_input(kwargs, match):
    args = {"fluid": "pneumatic", "constraint": "tube-ratio", "n_sections": 1, "sizes": (0.5,),
            "progress": False, **kwargs}
    with pytest.raises(ValueError, match=match):
        dt.sweep(**args)


def test_capacity_rises_then_falls_with_length_at_a_fixed_tube_ratio():
    """§3.4.2: actuation grows like L³ and the load's lever like L, self-weight like L⁴."""
    loads = [dt.evaluate(P, "tube-ratio", (12, 12, 6), length).load_n
             for length in (0.25, 0.5, 0.75, 1.0, 1.5, 2.0)]
    assert np.all(np.diff(loads[:4]) > 0)
    assert loads[5] < loads[4] < loads[3]
