"""``ArmDesign.scaled``: the fast perturbed design of domain randomisation.

The scaled design must equal a validated rebuild, its kernel arrays the arrays packed afresh,
and its loading stage (the nominal's loaded state followed to loads/f, docs/design.md §7) the
cold ramp of a freshly built equal design.
"""

from dataclasses import replace

import numpy as np
import pytest

import solver
from solver.inputs import request
from solver.paths.planar import loaded_base_moment
from solver.problem import build_pack, pack
from solver.settings import DEFAULT_SETTINGS

FIELDS = ("secf", "tubes_f", "c_j", "mass_per_length", "endplate", "tubes_i", "sec_steps",
          "spatial_of_planar")


def _rebuilt(arm, f, d):
    """The same design through dataclasses.replace (validated, packed from scratch)."""
    mats = {}
    for t in arm.tubes:
        m = t.material
        mats.setdefault(id(m), replace(m, youngs_modulus=m.youngs_modulus * f,
                                       shear_modulus=m.shear_modulus * f,
                                       wind_angle_deg=m.wind_angle_deg + d))
    return replace(arm, sections=tuple(replace(s, EA=s.EA * f, GA=s.GA * f, EI=s.EI * f, GJ=s.GJ * f)
                                       for s in arm.sections),
                   tubes=tuple(replace(t, material=mats[id(t.material)]) for t in arm.tubes))


@pytest.mark.parametrize("design", ["octarm_v", "octarm_vi", "ct"])
@pytest.mark.parametrize("f, d", [(1.1, 2.0), (0.9, -2.0), (0.5, 0.0), (1.0, 0.7)])
def test_scaled_design_equals_a_validated_rebuild_and_packs_alike(design, f, d):
    arm = solver.designs.get(design)
    scaled, rebuilt = arm.scaled(f, d), _rebuilt(arm, f, d)
    assert scaled == rebuilt
    for model in ("full", "unshearable"):
        a, b = pack(scaled, model, DEFAULT_SETTINGS), build_pack(rebuilt, model, DEFAULT_SETTINGS)
        for name in FIELDS:
            np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-14, atol=0)
        assert a.moment_scale == pytest.approx(b.moment_scale, rel=1e-14)
        assert (a.key, a.n_rows, a.section_ends) == (b.key, b.n_rows, b.section_ends)


@pytest.mark.parametrize("design, base_angle", [("octarm_v", 90.0), ("octarm_v", 45.0), ("octarm_v", 0.0),
                                                ("ct", 90.0), ("octarm_vi", 135.0)])
@pytest.mark.parametrize("f", [0.9, 0.97, 1.1])
def test_loading_stage_and_solves_match_a_fresh_design(design, base_angle, f):
    arm = solver.designs.get(design)
    scene = solver.Scene(base_angle_deg=base_angle, payload_kg=0.1)
    scaled, rebuilt = arm.scaled(f, 1.0), _rebuilt(arm, f, 1.0)
    loaded = []
    for a in (scaled, rebuilt):
        loaded.append(loaded_base_moment(request(a, np.zeros(a.n_inputs(True)), scene, "full", True,
                                                 None, DEFAULT_SETTINGS)))
    assert loaded[0].converged and loaded[0].resolved and not loaded[0].snapped
    scale = abs(loaded[1].m0) + 1e-3
    assert loaded[0].m0 == pytest.approx(loaded[1].m0, abs=1e-7 * scale)
    rng = np.random.default_rng(3)
    for p in rng.uniform(0, arm.max_pressure, (3, arm.n_inputs())):
        e1, e2 = solver.solve(scaled, p, scene), solver.solve(rebuilt, p, scene)
        assert e1.converged and e2.converged
        np.testing.assert_allclose(e1.tip, e2.tip, atol=1e-7 * arm.length)


@pytest.mark.parametrize("args, match", [
    ((0.0, 0.0), "modulus_factor"), ((float("nan"), 0.0), "modulus_factor"), ((True, 0.0), "modulus_factor"),
    ((1.0, float("inf")), "wind_angle_delta_deg"), ((1.0, 40.0), "α ="), ((1e20, 0.0), "E ="),
])
def test_scaled_rejects_bad_arguments(args, match):
    with pytest.raises(ValueError, match=match):
        solver.designs.octarm_v().scaled(*args)
