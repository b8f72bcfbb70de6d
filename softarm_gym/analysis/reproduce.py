"""The thesis's workspace and dexterity studies, rerun with this solver.

* :func:`table_2_2`: mean tip height over the OctArm V 7⁶ workspace at base 0/45/90°,
  constant curvature versus full model (Table 2.2), under both bending-stiffness readings.
* :func:`ct_vs_octarm`: §5.3.1, the two-section OctArm versus the continuous-tube arm,
  hanging, 7⁴ grid 0–70 psi (Fig. 5.4), with and without endplates on the OctArm.
* :func:`dexterity_comparison`: §5.3.2, dexterity maps of both arms (Fig. 5.5) and the
  dexterous area versus σ_min threshold (Fig. 5.6).

Each study runs all its sweeps through one :class:`~softarm_gym.jobs.Runner` (one progress
bar, the chosen backend, chunks kept on disk for ``--resume``).

The thesis's own numbers are kept here, beside the functions that reproduce them.
"""

from __future__ import annotations

import numpy as np

import solver
from softarm_gym.analysis.manipulability import DEFAULT_DEXTERITY_CHUNK, DexterityMap, dexterity_plan
from softarm_gym.analysis.workspace import Workspace, workspace_plan
from softarm_gym.jobs import Runner

__all__ = ["THESIS_TABLE_2_2", "THESIS_5_3_1", "ENDPLATE_MASS", "EI_READINGS", "table_2_2",
           "closest_reading", "ct_vs_octarm", "dexterity_comparison", "dexterous_area_curves"]

THESIS_TABLE_2_2 = {0.0: (-0.485, -0.733), 45.0: (-0.343, -0.694), 90.0: (0.0, -0.445)}
"""Table 2.2: base angle (deg) → mean tip y (m), (constant curvature, full order)."""

THESIS_5_3_1 = {"octarm_2s": {"highest_tip": (0.31, -0.02), "area_pi_L2": 0.5},
                "ct": {"highest_tip": (0.37, 0.11), "area_pi_L2": 0.6}}
"""§5.3.1: highest workspace point (±x, y) (m) and workspace area (πL²) of each arm."""

ENDPLATE_MASS = 0.1
"""Per-endplate mass (kg) of the §5.3.1 OctArm when endplates are included. The thesis gives
none; 0.1 kg is a machined aluminium ring with fittings and clamps (Fig. 1.9(c)), about an
eighth of the 0.78 kg six-tube first section. Results are reported with 0 kg as well."""

EI_READINGS = ("eq2.32", "tubes")


def table_2_2(levels: int = 7, angles=(0.0, 45.0, 90.0), readings=EI_READINGS,
              runner: Runner | None = None, chunk_size: int | None = None) -> list[dict]:
    """Mean tip height over the OctArm V workspace, constant curvature versus full model.

    Args:
        levels: pressure levels per channel (7 → the thesis's 117,649 points).
        angles: base angles (deg).
        readings: ``ei`` readings of :func:`solver.designs.octarm_v`.
        runner: runs the sweeps (default: local, in memory, no progress bar).
        chunk_size: grid rows per chunk (default by planar/spatial, see
            :func:`~softarm_gym.analysis.sweep.default_chunk_size`).

    Returns:
        One row per (reading, angle): ``ei``, ``base_angle_deg``, ``cc_mean_y``,
        ``full_mean_y``, ``difference`` (cc − full), ``thesis_cc``, ``thesis_full``,
        ``thesis_difference`` (None where the thesis has no entry), ``n``, ``n_failed``,
        ``seconds_full``, ``seconds_cc``.
    """
    cases = [(ei, float(angle)) for ei in readings for angle in angles]
    plans = []
    for ei, angle in cases:
        arm, scene = solver.designs.octarm_v(ei=ei), solver.Scene(base_angle_deg=angle)
        plans += [workspace_plan(arm, scene, levels=levels, chunk_size=chunk_size),
                  workspace_plan(arm, scene, levels=levels, model="constant_curvature",
                                 chunk_size=chunk_size)]
    spaces = (runner or Runner()).run_plans(plans, desc="table 2.2 sweeps")
    rows = []
    for k, (ei, angle) in enumerate(cases):
        full, cc = spaces[2 * k], spaces[2 * k + 1]
        thesis = THESIS_TABLE_2_2.get(angle)
        rows.append({
            "ei": ei, "base_angle_deg": angle,
            "cc_mean_y": float(cc.mean_tip[1]), "full_mean_y": float(full.mean_tip[1]),
            "difference": float(cc.mean_tip[1] - full.mean_tip[1]),
            "thesis_cc": thesis[0] if thesis else None,
            "thesis_full": thesis[1] if thesis else None,
            "thesis_difference": round(thesis[0] - thesis[1], 3) if thesis else None,
            "n": full.n, "n_failed": full.n_failed + cc.n_failed,
            "seconds_full": full.seconds, "seconds_cc": cc.seconds,
        })
    return rows


def closest_reading(rows: list[dict]) -> dict:
    """RMS difference from the thesis (m) per ``ei`` reading, over its cc and full entries."""
    out = {}
    for ei in dict.fromkeys(r["ei"] for r in rows):
        err = [v for r in rows if r["ei"] == ei and r["thesis_cc"] is not None
               for v in (r["cc_mean_y"] - r["thesis_cc"], r["full_mean_y"] - r["thesis_full"])]
        out[ei] = float(np.sqrt(np.mean(np.square(err)))) if err else None
    return out


def ct_vs_octarm(levels: int = 7, max_psi: float = 70.0, endplate_masses=(0.0, ENDPLATE_MASS),
                 runner: Runner | None = None, chunk_size: int | None = None) -> dict[str, Workspace]:
    """§5.3.1: hanging workspaces of the two-section OctArm and the CT arm.

    Returns:
        ``{label: Workspace}``: ``"octarm_2s (endplates m kg)"`` per mass, then ``"ct"``.
    """
    scene = solver.Scene(base_angle_deg=0.0)
    arms = _section_5_3_arms(endplate_masses)
    plans = [workspace_plan(arm, scene, levels=levels, max_pressure=max_psi * solver.PSI,
                            chunk_size=chunk_size) for arm in arms.values()]
    return dict(zip(arms, (runner or Runner()).run_plans(plans, desc="fig 5.4 sweeps")))


def dexterity_comparison(levels: int = 7, max_psi: float = 70.0,
                         endplate_masses=(0.0, ENDPLATE_MASS), runner: Runner | None = None,
                         chunk_size: int = DEFAULT_DEXTERITY_CHUNK) -> dict[str, DexterityMap]:
    """§5.3.2: hanging dexterity maps of the two-section OctArm (per endplate mass) and the CT
    arm (Fig. 5.5), labelled as in :func:`ct_vs_octarm`."""
    scene = solver.Scene(base_angle_deg=0.0)
    arms = _section_5_3_arms(endplate_masses)
    plans = [dexterity_plan(arm, scene, levels=levels, max_pressure=max_psi * solver.PSI,
                            chunk_size=chunk_size) for arm in arms.values()]
    return dict(zip(arms, (runner or Runner()).run_plans(plans, desc="fig 5.5 dexterity")))


def _section_5_3_arms(endplate_masses) -> dict:
    arms = {f"octarm_2s (endplates {mass:g} kg)":
            solver.designs.octarm_two_section(endplate_mass=float(mass)) for mass in endplate_masses}
    arms["ct"] = solver.designs.ct()
    return arms


def dexterous_area_curves(maps: dict[str, DexterityMap], n_thresholds: int = 41) -> dict:
    """Fig. 5.6 data: dexterous area versus σ_min threshold on a common threshold axis.

    Returns:
        ``{label: (thresholds (m/Pa), areas (m²), L (m))}``; thresholds run from 0 to the
        largest σ_min of any map.
    """
    top = max(float(np.nanmax(m.measure("sigma_min"))) for m in maps.values())
    thresholds = np.linspace(0.0, top, n_thresholds)
    return {label: (thresholds, m.dexterous_area(thresholds), m.length)
            for label, m in maps.items()}

