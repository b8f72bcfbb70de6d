"""Parameters of a fit: names, groups, bounds, and what setting one does to a design."""

import json
import math

import numpy as np
import pytest

import solver
from solver.identify import KINDS, apply_parameters, parse_parameters

ARM = solver.designs.octarm_v()


def _set(arm, name, value):
    params = parse_parameters(arm, name)
    return apply_parameters(arm, params, [value])


def test_groups_pick_the_tubes_the_design_names():
    by_name = {p.name: p for p in parse_parameters(
        ARM, "wind_angle:s1_I,wind_angle:s1_II+III,wind_angle:s2,wind_angle:tube10,offset:s3_III")}
    assert by_name["wind_angle:s1_I"].tubes == (0, 1)  # six tubes in section 1: two per channel
    assert by_name["wind_angle:s1_II+III"].tubes == (2, 3, 4, 5)
    assert by_name["wind_angle:s2"].tubes == (6, 7, 8)
    assert by_name["wind_angle:tube10"].tubes == (10,)
    assert by_name["offset:s3_III"].tubes == (11,)
    assert by_name["offset:s3_III"].nominal == pytest.approx(ARM.tubes[11].radius)
    ct = solver.designs.ct()
    (p,) = parse_parameters(ct, "wind_angle:s2")
    assert p.tubes == (0, 1, 2)  # only the inner tubes run into section 2


def test_every_kind_parses_with_its_unit_and_a_nominal_inside_its_bounds():
    names = ["wind_angle", "offset:s1_I", "E", "G", "EA_scale:s1", "GA_scale:s2", "EI_scale", "GJ_scale:s3",
             "mass_scale", "endplate_mass:s1", "payload"]
    params = parse_parameters(ARM, names)
    assert {p.kind for p in params} == set(KINDS)
    units = {p.name: p.unit for p in params}
    assert (units["wind_angle"], units["E"], units["EI_scale"], units["payload"]) == ("deg", "Pa", "-", "kg")
    for p in params:
        assert p.lower <= p.nominal <= p.upper and p.scale > 0
    assert apply_parameters(ARM, params, [p.nominal for p in params]) == ARM


def test_setting_values_changes_exactly_the_named_fields():
    e = _set(ARM, "E", 2.5e6)
    f = 2.5e6 / 2.0e6
    for a, b in zip(ARM.sections, e.sections):
        assert (b.EA, b.EI) == pytest.approx((a.EA * f, a.EI * f))
        assert (b.GA, b.GJ, b.mass_per_length) == (a.GA, a.GJ, a.mass_per_length)
    assert all(t.material.youngs_modulus == 2.5e6 and t.material.shear_modulus == 0.4e6 for t in e.tubes)
    g = _set(ARM, "G", 0.5e6)
    assert [s.GA for s in g.sections] == pytest.approx([s.GA * 1.25 for s in ARM.sections])
    assert [s.EI for s in g.sections] == [s.EI for s in ARM.sections]
    w = _set(ARM, "wind_angle:s1_I", 76.0)
    assert [t.material.wind_angle_deg for t in w.tubes] == [76.0, 76.0] + [78.0] * 10
    ei = apply_parameters(ARM, parse_parameters(ARM, "E,EI_scale:s2"), [2.2e6, 0.9])
    assert ei.sections[1].EI == pytest.approx(ARM.sections[1].EI * 1.1 * 0.9)
    assert ei.sections[0].EI == pytest.approx(ARM.sections[0].EI * 1.1)
    m = _set(ARM, "mass_scale:s3", 1.5)
    assert m.sections[2].mass_per_length == pytest.approx(1.5 * ARM.sections[2].mass_per_length)
    assert m.sections[0].mass_per_length == ARM.sections[0].mass_per_length
    pay = _set(ARM, "payload", 0.2)
    assert [s.endplate_mass for s in pay.sections] == [0.0, 0.0, 0.2]


def test_payload_parameter_is_the_scene_payload():
    """An unknown payload lives in the design as the last endplate: the same load at the tip."""
    p = np.array([40, 0, 0, 60, 20, 0]) * solver.PSI
    with_payload = solver.solve(ARM, p, solver.Scene(base_angle_deg=90, payload_kg=0.3))
    as_endplate = solver.solve(_set(ARM, "payload", 0.3), p, solver.Scene(base_angle_deg=90))
    np.testing.assert_allclose(as_endplate.tip, with_payload.tip, rtol=0, atol=1e-12)


def test_fitted_design_round_trips_through_a_design_file(tmp_path):
    params = parse_parameters(ARM, "wind_angle:s2,E,EI_scale:s1,offset:s1_I")
    arm = apply_parameters(ARM, params, [77.1, 2.3e6, 1.07, 0.03])
    path = tmp_path / "fitted.json"
    path.write_text(arm.to_json())
    loaded = solver.designs.load(path)
    assert loaded == arm
    assert json.loads(path.read_text())["tubes"][0]["radius"] == 0.03


@pytest.mark.parametrize("names, match", [
    ("wind_angel", "unknown parameter 'wind_angel'"),
    ("E:s1", "E takes no group"),
    ("wind_angle:s9", "has sections s1..s3"),
    ("wind_angle:s1_IV", "unknown group 's1_IV'"),
    ("EI_scale:s1_I", "unknown group 's1_I'; name a section"),
    ("endplate_mass", "needs a section"),
    ("E,E", "named twice"),
    ("wind_angle,wind_angle:s1", "both set wind_angle of tube 0"),
    ("payload,endplate_mass:s3", "both set endplate_mass of section 3"),
    ("EI_scale,EI_scale:s2", "both set EI_scale of section 2"),
    ("", "non-empty names"),
    ("E,,G", "non-empty names"),
])
def test_bad_parameter_names_are_one_line_errors(names, match):
    with pytest.raises(ValueError, match=match) as exc:
        parse_parameters(ARM, names)
    assert "\n" not in str(exc.value)


def test_groups_whose_tubes_differ_must_be_split():
    arm = _set(ARM, "wind_angle:s1_I", 76.0)
    with pytest.raises(ValueError, match="wind angles of its tubes differ"):
        parse_parameters(arm, "wind_angle:s1")
    assert parse_parameters(arm, "wind_angle:s1_I")[0].nominal == 76.0


def test_values_outside_bounds_are_refused():
    params = parse_parameters(ARM, "wind_angle,E")
    lock = math.degrees(math.acos(1 / math.sqrt(3)))
    assert params[0].lower == pytest.approx(lock + 0.5)
    with pytest.raises(ValueError, match="'wind_angle' = 54.0 lies outside"):
        apply_parameters(ARM, params, [54.0, 2e6])
    with pytest.raises(ValueError, match="'E' = nan"):
        apply_parameters(ARM, params, [78.0, float("nan")])
    with pytest.raises(ValueError, match="2 parameters need as many values"):
        apply_parameters(ARM, params, [78.0])
