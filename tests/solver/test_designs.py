"""Designs: numbers traced to the thesis, validation, JSON round trip."""

import dataclasses
import math

import numpy as np
import pytest

import solver
from solver import PSI, designs


def test_octarm_v_stiffness_both_readings():
    ei = [s.EI for s in designs.octarm_v().sections]
    assert ei == pytest.approx([0.6961, 0.3481, 0.3481], abs=5e-5)
    tubes = [s.EI for s in designs.octarm_v(ei="tubes").sections]
    assert tubes == pytest.approx([1.9099, 0.4155, 0.4155], abs=5e-5)


def test_ring_radius_and_channel_layout():
    arm = designs.octarm_v()
    sec1 = [t for t in arm.tubes if t.first_section == 0]
    sec2 = [t for t in arm.tubes if t.first_section == 1]
    assert len(sec1) == 6 and len(sec2) == 3
    assert sec1[0].radius == pytest.approx(0.028, abs=1e-6)
    assert sec2[0].radius == pytest.approx(0.01617, abs=1e-5)
    ch_i = sorted(t.angle_deg for t in sec1 if t.channel == 0)
    assert ch_i == pytest.approx([30.0, 330.0])
    assert arm.input_names() == ("s1_I", "s1_II+III", "s2_I", "s2_II+III", "s3_I", "s3_II+III")


def test_rest_strain_fact():
    """docs/design.md §1–4: 100 psi in channel I of section 1 → u* = −11.48 rad/m, v3* = 1.0798."""
    arm = designs.octarm_v()
    p = np.zeros(9)
    p[0] = 100 * PSI
    u1, u2, v3 = solver.rest_strains(arm, p)
    assert u2[0] == pytest.approx(-11.48, abs=5e-3)
    assert v3[0] == pytest.approx(1.0798, abs=5e-5)
    assert abs(u1[0]) < 1e-12 and u2[1] == 0 and v3[1] == 1


def test_equal_pressure_everywhere_is_pure_stretch():
    arm = designs.octarm_v()
    u1, u2, v3 = solver.rest_strains(arm, np.full(9, 50 * PSI))
    np.testing.assert_allclose(u1, 0, atol=1e-12)
    np.testing.assert_allclose(u2, 0, atol=1e-12)
    np.testing.assert_allclose(v3, 1.108714, atol=1e-6)


def test_octarm_vi_reproduces_table_4_2():
    arm = designs.octarm_vi()
    mat = arm.tubes[0].material
    n = [s.n_tubes for s in arm.sections]
    assert n == [6, 6, 3]
    for sec, ntub in zip(arm.sections, n):
        # The derived tube must reproduce Table 4.2 (not just copy it).
        assert ntub * mat.youngs_modulus * mat.area == pytest.approx(sec.EA, rel=1e-9)
        ei = ntub * mat.youngs_modulus * (mat.second_moment + mat.area * mat.outer_radius**2 / 2)
        assert ei == pytest.approx(sec.EI, rel=1e-3)
        assert sec.GA == pytest.approx(sec.EA / 3)
    assert [s.length for s in arm.sections] == [0.280, 0.265, 0.325]
    assert arm.extra["cable_radius"] == 42.9e-3


def test_ct_layout_matches_table_5_1():
    """Moment per unit E·At·Δλ·Ro of single tubes equals Table 5.1's coefficients."""
    arm = designs.ct()
    ro = arm.tubes[0].material.outer_radius
    inner = [t for t in arm.tubes if t.last_section == 1]
    outer = [t for t in arm.tubes if t.last_section == 0]
    assert len(inner) == 3 and len(outer) == 3
    assert inner[0].radius / ro == pytest.approx(2 / math.sqrt(3))
    assert outer[0].radius / ro == pytest.approx(4 / math.sqrt(3))  # Table 5.1: 4·√3/3
    # Inner tube at 120°: lever arm along d1 is −Ro/√3 = −(√3/3)·Ro (Table 5.1 coefficient).
    assert inner[1].offset[0] / ro == pytest.approx(-math.sqrt(3) / 3)
    assert inner[1].offset[1] / ro == pytest.approx(1.0)
    mat = arm.tubes[0].material
    assert arm.sections[0].EI == pytest.approx(
        mat.youngs_modulus * (6 * mat.second_moment + 2.5 * mat.area * ro**2))


def test_ct_inner_tubes_bend_both_sections():
    arm = designs.ct()
    u1, u2, v3 = solver.rest_strains(arm, np.array([50 * PSI, 0, 0, 0, 0, 0]))
    assert u2[0] < 0 and u2[1] < 0
    u1, u2, v3 = solver.rest_strains(arm, np.array([0, 0, 0, 50 * PSI, 0, 0]))
    assert u2[0] > 0 and u2[1] == 0 and v3[1] == 1


@pytest.mark.parametrize("name", designs.DESIGN_NAMES)
def test_json_round_trip(name, tmp_path):
    arm = designs.get(name)
    path = tmp_path / "arm.json"
    path.write_text(arm.to_json())
    back = designs.load(path)
    assert back == arm
    p = np.full(arm.n_inputs(), 0.3 * arm.max_pressure)
    scene = solver.Scene(base_angle_deg=60)
    np.testing.assert_array_equal(solver.solve(back, p, scene).tip, solver.solve(arm, p, scene).tip)


@pytest.mark.parametrize("text, match", [
    ("{not json", "not valid JSON"),
    ("[1, 2]", "JSON object"),
    ('{"name": "x"}', "missing fields: sections"),
    ('{"name": "x", "sections": [], "colour": 1}', "unknown fields: 'colour'"),
    ('{"name": "x", "sections": []}', "no sections"),
    ('{"name": "x", "sections": [{"length": -1, "EA": 1, "GA": 1, "EI": 1, "GJ": 1}]}', "length"),
])
def test_malformed_design_json(text, match):
    with pytest.raises(ValueError, match=match):
        designs.from_json(text)


def test_invalid_designs():
    with pytest.raises(ValueError, match="inner radius"):
        designs.TubeMaterial(2e6, 4e5, 1500, 0.02, 0.01, 78)
    with pytest.raises(ValueError, match="outside every channel"):
        arm = designs.octarm_v()
        designs.ArmDesign(name="bad", sections=arm.sections,
                          tubes=arm.tubes[:-1] + (designs.Tube(99, 0, 0.01, 0, 0, arm.tubes[0].material),),
                          channels=arm.channels, planar_channels=arm.planar_channels,
                          max_pressure=arm.max_pressure)
    with pytest.raises(ValueError, match="only 3 sections"):
        arm = designs.octarm_v()
        designs.ArmDesign(name="bad", sections=arm.sections,
                          tubes=(designs.Tube(0, 0, 0.01, 0, 5, arm.tubes[0].material),),
                          channels=("a",), max_pressure=1.0)
    with pytest.raises(ValueError, match="unknown design"):
        designs.get("octarm_ix")
    with pytest.raises(ValueError, match="unknown ei"):
        designs.octarm_v(ei="guess")
    with pytest.raises(ValueError, match="multiple of 3"):
        designs.pneumatic((4, 3), (0.5, 0.5), 0.003)


def test_builders_table_3_1():
    arm = designs.hydraulic((12, 9, 6), (0.3, 0.3, 0.4), 0.002)
    mat = arm.tubes[0].material
    assert mat.youngs_modulus == 12e6 and mat.outer_radius == 15e-3
    sec = arm.sections[0]
    water = 1000 * 12 * mat.bore_area
    assert sec.mass_per_length == pytest.approx(1500 * 12 * mat.area + water)
    assert arm.max_pressure == 7e6


def test_json_after_a_solve_and_bad_design_files():
    """The solver caches arrays on the design; serialising must not see them."""
    arm = designs.octarm_v()
    solver.solve(arm, np.zeros(6), solver.Scene(base_angle_deg=90))
    assert designs.from_json(arm.to_json()) == arm
    data = arm.to_json().replace('"wind_angle_deg": 78.0', '"wind_angel_deg": 78.0', 1)
    with pytest.raises(ValueError, match=r"tubes\[0\]: Tube.material has unknown fields: 'wind_angel_deg'"):
        designs.from_json(data)
    import json

    raw = json.loads(arm.to_json())
    raw["tubes"][0]["material"] = 5
    with pytest.raises(ValueError, match="Tube.material must be a mapping of TubeMaterial fields"):
        designs.from_json(json.dumps(raw))
    raw = json.loads(arm.to_json())
    raw["max_pressure"] = float("inf")
    with pytest.raises(ValueError, match="max_pressure must be a finite number"):
        designs.from_json(json.dumps(raw))


def test_python_api_gets_the_same_checks_as_design_files():
    sec = designs.octarm_v().sections[0]
    with pytest.raises(ValueError, match=r"Section.length must be a finite number > 0 and <= 100 m; got Tru"):
        dataclasses.replace(sec, length=True)
    with pytest.raises(ValueError, match="Section.n_tubes must be an integer"):
        dataclasses.replace(sec, n_tubes=6.0)
    with pytest.raises(ValueError, match=r"at most 32 are supported \(solver.designs.MAX_SECTIONS\)"):
        designs.ArmDesign(name="long", sections=(sec,) * (designs.MAX_SECTIONS + 1))
    with pytest.raises(ValueError, match="ArmDesign.name must be a string"):
        designs.ArmDesign(name=("octarm",), sections=(sec,))
    # numpy scalars are numbers: stored as plain floats and ints, so the JSON stays plain.
    arm = designs.ArmDesign(name="np", sections=(dataclasses.replace(sec, EI=np.float32(0.5),
                                                                     n_tubes=np.int64(3)),))
    assert type(arm.sections[0].EI) is float and type(arm.sections[0].n_tubes) is int
    assert designs.from_json(arm.to_json()) == arm
