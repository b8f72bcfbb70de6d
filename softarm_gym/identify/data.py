"""Measured shapes as a CSV file, and synthetic ones made by the solver.

The format (one configuration per row; a header row names the columns, in any order; lines
starting with ``#`` are comments; an empty cell is a quantity not measured there):

=============================  ====  ===================================================
column                         unit  meaning
=============================  ====  ===================================================
``base_angle_deg``             deg   base angle (required; 0 hangs, 90 horizontal)
``payload_kg``                 kg    known tip payload (optional; default ``--payload-kg``)
``<input>_psi``                psi   one per planar input of the design, e.g.
                                     ``s1_I_psi``, ``s1_II+III_psi`` (required)
``tip_x_m``, ``tip_y_m``       m     measured tip position
``x@<s>_m``, ``y@<s>_m``       m     a backbone marker at reference arc length ``<s>`` m
                                     from the base (an endplate, a tape mark)
``enc_s<k>_plus_m``, …         m     cable encoders: ``enc_s<k>_plus_m`` / ``_minus_m``
                                     (cable at +R·d1 / −R·d1, base to the end of section k)
``incl_s<k>_deg``              deg   inclinometer at the end of section k (θ of d3 from +x)
``load_shear_n``,              N,    base load cell in its own frame: force along the
``load_axial_n``,              N,    base's d1 and d3, moment
``load_moment_nm``             N m
``split``                      –     ``fit`` or ``holdout`` (optional: which configurations
                                     the fit leaves out to measure its error on unseen data)
``label``                      –     free text (optional), e.g. the on/off code ``101100``
=============================  ====  ===================================================

Positions are in the solver's frame (base at the origin, x horizontal, y up). A file must
measure something: a tip, a marker or a sensor reading in at least one row.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import re

import numpy as np

import solver
from softarm_gym.identify.sensors import SensorObservation, readings_vector, sensor_labels, sensor_sigma
from softarm_gym.sensing import SensorNoise, synthesize
from solver.identify import (
    BackbonePoints,
    Measurements,
    TipPositions,
    apply_parameters,
    parse_parameters,
    predict,
)

__all__ = ["read_csv", "write_csv", "make_synthetic", "on_off_configurations", "MAX_CSV_BYTES",
           "PERTURBED_ARM"]

MAX_CSV_BYTES = 100_000_000
"""Largest data file read (a million configurations of every column is well below it)."""

PERTURBED_ARM = {"wind_angle:s1": 76.5, "wind_angle:s2": 77.8, "wind_angle:s3": 79.0, "E": 2.2e6,
                 "G": 0.45e6, "EI_scale:s1": 1.10, "EI_scale:s2": 0.95, "EI_scale:s3": 1.05,
                 "mass_scale": 1.08}
"""The "real" OctArm V of the worked example and the Fig. 2.6-style study: braid angles a degree
or so off 78° (§2.4), rubber 10 % stiffer, the sections' bending stiffness ±10 % (bonding of
the bundle), 8 % more mass (fittings, cables). Nine parameters."""

_MARKER = re.compile(r"([xy])@([0-9.eE+-]+)_m")


def _sensor_columns(n_sections: int) -> list[tuple[str, float]]:
    """(CSV column, factor from the file's unit to the observation's) per sensor label."""
    cols = []
    for label in sensor_labels(n_sections):
        if label.startswith("enc_"):
            cols.append((f"{label}_m", 1.0))
        elif label.startswith("incl_"):
            cols.append((f"{label}_deg", math.pi / 180.0))
        else:
            cols.append((f"{label}_nm" if label == "load_moment" else f"{label}_n", 1.0))
    return cols


def _number(text: str, where: str, required: bool) -> float:
    text = text.strip()
    if not text:
        if required:
            raise ValueError(f"{where} is empty; it is required")
        return math.nan
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{where}: {text[:40]!r} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{where}: {text[:40]!r} is not a finite number")
    return v


def read_csv(path, design: solver.designs.ArmDesign, *, tip_sigma: float = 0.005,
             point_sigma: float = 0.005, sensor_noise: SensorNoise | None = None,
             payload_kg: float = 0.0) -> tuple[Measurements, list[str]]:
    """Read a data file (module docstring) for ``design``.

    Args:
        path: the CSV file.
        design: the design the pressures drive (its planar inputs name the pressure columns).
        tip_sigma, point_sigma: standard deviation of the tip and marker positions (m).
        sensor_noise: the sensors' resolutions and noise (default Table 4.3), which give the
            readings' standard deviations (:func:`softarm_gym.identify.sensors.sensor_sigma`).
        payload_kg: payload of every configuration when the file has no ``payload_kg`` column.

    Returns:
        ``(measurements, labels)``: the :class:`solver.identify.Measurements` and each row's
        ``label`` ("" without that column).

    Raises:
        OSError: the file cannot be read.
        ValueError: (one line, naming the line and column) anything wrong with its content.
    """
    noise = SensorNoise.thesis() if sensor_noise is None else sensor_noise
    with open(path, "rb") as fh:
        raw = fh.read(MAX_CSV_BYTES + 1)
    if len(raw) > MAX_CSV_BYTES:
        raise ValueError(f"{path}: larger than {MAX_CSV_BYTES:,} bytes")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    lines = [(k + 1, line) for k, line in enumerate(text.splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{path}: no header row (and no data)")
    try:
        rows = list(csv.reader(io.StringIO("\n".join(line for _, line in lines)), strict=True))
    except csv.Error as exc:
        raise ValueError(f"{path}: malformed CSV: {exc}") from None
    header = [h.strip() for h in rows[0]]
    body = rows[1:]
    if not body:
        raise ValueError(f"{path}: a header but no data rows")
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        raise ValueError(f"{path}: column {repeated[0]!r} appears twice")
    ns = len(design.sections)
    inputs = design.input_names(True)
    pressure_cols = [f"{name}_psi" for name in inputs]
    sensor_cols = _sensor_columns(ns)
    known = {"base_angle_deg", "payload_kg", "tip_x_m", "tip_y_m", "split", "label", *pressure_cols,
             *(c for c, _ in sensor_cols)}
    markers: dict[float, dict[str, str]] = {}
    unknown = []
    for h in header:
        m = _MARKER.fullmatch(h)
        if m is not None:
            try:
                s = float(m.group(2))
            except ValueError:
                s = math.nan
            if not (math.isfinite(s) and s >= 0):
                raise ValueError(f"{path}: marker column {h!r} needs an arc length >= 0 in metres")
            markers.setdefault(s, {})[m.group(1)] = h
        elif h not in known:
            unknown.append(h)
    if unknown:
        raise ValueError(f"{path}: unknown column(s) {', '.join(map(repr, unknown[:5]))}; design "
                         f"{design.name!r} takes base_angle_deg, payload_kg, {', '.join(pressure_cols)}, "
                         "tip_x_m, tip_y_m, x@<s>_m, y@<s>_m, enc_s<k>_plus_m/_minus_m, incl_s<k>_deg, "
                         "load_shear_n, load_axial_n, load_moment_nm, split, label (docs/identification.md)")
    missing = [c for c in ("base_angle_deg", *pressure_cols) if c not in header]
    if missing:
        raise ValueError(f"{path}: missing column(s) {', '.join(missing)} (design {design.name!r} has the "
                         f"planar inputs {', '.join(inputs)})")
    for s, pair in markers.items():
        if set(pair) != {"x", "y"}:
            raise ValueError(f"{path}: marker at s = {s:g} m needs both x@{s:g}_m and y@{s:g}_m columns")
    if ("tip_x_m" in header) != ("tip_y_m" in header):
        raise ValueError(f"{path}: tip_x_m and tip_y_m come together")
    col = {h: i for i, h in enumerate(header)}
    n = len(body)
    values = {h: np.full(n, np.nan) for h in header if h not in ("split", "label")}
    split = np.zeros(n, dtype=bool)
    labels = [""] * n
    required = {"base_angle_deg", *pressure_cols}
    for r, row in enumerate(body):
        line = lines[r + 1][0]
        if len(row) != len(header):
            raise ValueError(f"{path} line {line}: {len(row)} fields; the header has {len(header)}")
        for h, arr in values.items():
            arr[r] = _number(row[col[h]], f"{path} line {line}, column {h!r}", h in required)
        if "split" in col:
            word = row[col["split"]].strip()
            if word not in ("fit", "holdout"):
                raise ValueError(f"{path} line {line}, column 'split': {word[:40]!r} is not fit or holdout")
            split[r] = word == "holdout"
        if "label" in col:
            labels[r] = row[col["label"]].strip()
    observations = []
    if "tip_x_m" in header:
        observations.append(TipPositions(np.column_stack([values["tip_x_m"], values["tip_y_m"]]), tip_sigma))
    if markers:
        s_sorted = sorted(markers)
        pts = np.column_stack([values[markers[s][c]] for s in s_sorted for c in ("x", "y")])
        observations.append(BackbonePoints(pts, point_sigma, s=tuple(s_sorted)))
    present = [c for c, _ in sensor_cols if c in header]
    if present:
        readings = np.column_stack([values[c] * f if c in values else np.full(n, np.nan)
                                    for c, f in sensor_cols])
        observations.append(SensorObservation(readings, sensor_sigma(noise, ns), n_sections=ns))
    observations = [o for o in observations if np.isfinite(o.measured).any()]
    if not observations:
        raise ValueError(f"{path}: nothing measured (no tip, marker or sensor value in any row)")
    payload = values["payload_kg"] if "payload_kg" in values else payload_kg
    meas = Measurements(np.column_stack([values[c] for c in pressure_cols]) * solver.PSI,
                        values["base_angle_deg"], payload, tuple(observations),
                        holdout=split if "split" in col else None)
    return meas, labels


def write_csv(path, design: solver.designs.ArmDesign, measurements: Measurements, labels=None,
              comments=()) -> None:
    """Write ``measurements`` (of ``design``) in the format :func:`read_csv` reads."""
    ns = len(design.sections)
    columns: dict[str, np.ndarray] = {"base_angle_deg": measurements.base_angle_deg,
                                      "payload_kg": measurements.payload_kg}
    for k, name in enumerate(design.input_names(True)):
        columns[f"{name}_psi"] = measurements.pressures[:, k] / solver.PSI
    for o in measurements.observations:
        if isinstance(o, TipPositions):
            columns["tip_x_m"], columns["tip_y_m"] = o.measured[:, 0], o.measured[:, 1]
        elif isinstance(o, BackbonePoints):
            for j, s in enumerate(o.s):
                columns[f"x@{s:g}_m"], columns[f"y@{s:g}_m"] = o.measured[:, 2 * j], o.measured[:, 2 * j + 1]
        elif isinstance(o, SensorObservation):
            for j, (c, f) in enumerate(_sensor_columns(ns)):
                columns[c] = o.measured[:, j] / f
        else:
            raise ValueError(f"observation {o.name!r} has no CSV columns")
    out = io.StringIO()
    for line in comments:
        out.write(f"# {line}\n")
    writer = csv.writer(out, lineterminator="\n")
    extra = ["split"] if measurements.holdout is not None else []
    extra += ["label"] if labels is not None else []
    writer.writerow([*columns, *extra])
    for r in range(measurements.n):
        row = ["" if not math.isfinite(v[r]) else repr(float(v[r])) for v in columns.values()]
        if measurements.holdout is not None:
            row.append("holdout" if measurements.holdout[r] else "fit")
        if labels is not None:
            row.append(labels[r])
        writer.writerow(row)
    from softarm_gym.files import atomic_write

    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(out.getvalue())


def on_off_configurations(design: solver.designs.ArmDesign, pressures_psi, base_angles_deg):
    """The thesis's experiment (§2.4): every on/off combination of the planar inputs at every
    pressure level, for every base angle.

    Returns:
        ``(pressures (n, n_inputs) Pa, base angles (n,) deg, labels)``; labels are
        ``"<code>@<psi>psi/<angle>deg"`` with the on/off code in input order.
    """
    n_inputs = design.n_inputs(True)
    if n_inputs > 10:
        raise ValueError(f"design {design.name!r} has {n_inputs} planar inputs: 2**{n_inputs} on/off "
                         "combinations per level is too many")
    codes = list(itertools.product((0, 1), repeat=n_inputs))
    rows, angles, labels = [], [], []
    for angle in base_angles_deg:
        for level in pressures_psi:
            for code in codes:
                rows.append(np.array(code, dtype=float) * level * solver.PSI)
                angles.append(angle)
                labels.append(f"{''.join(map(str, code))}@{level:g}psi/{angle:g}deg")
    return np.array(rows), np.array(angles, dtype=float), labels


def make_synthetic(design: solver.designs.ArmDesign, truth: dict, *,
                   pressures_psi=(30, 40, 50, 60, 70, 80, 90), base_angles_deg=(0.0, 90.0),
                   payload_kg: float = 0.0, tip_sigma: float = 0.005, point_sigma: float = 0.005,
                   markers="section_ends", sensor_noise: SensorNoise | None = None, model: str = "full",
                   holdout: float = 0.2, seed: int = 0):
    """Synthetic "measured" data of an arm whose true parameters are ``truth``.

    The true arm (``design`` with ``truth`` applied) is solved at the on/off configurations
    (:func:`on_off_configurations`); tips and markers get Gaussian camera noise, the sensors
    their own noise model (quantised to Table 4.3 resolution by default).

    Args:
        design: the nominal design. truth: ``{parameter name: true value}``.
        pressures_psi, base_angles_deg, payload_kg: the experiment.
        tip_sigma, point_sigma: camera noise (m); 0 leaves that observation out.
        markers: reference arc lengths of the markers (m), or ``"section_ends"`` (every
            endplate but the tip's).
        sensor_noise: the sensors' noise (default Table 4.3); None readings with
            ``SensorNoise.off()``'s zero σ are left out.
        model: the solver model that makes the data.
        holdout: fraction of configurations marked ``holdout`` (chosen with ``seed``).
        seed: seeds every random draw.

    Returns:
        ``(measurements, labels, true_design)``.
    """
    noise = SensorNoise.thesis() if sensor_noise is None else sensor_noise
    params = parse_parameters(design, list(truth))
    true_arm = apply_parameters(design, params, [float(v) for v in truth.values()])
    pressures, angles, labels = on_off_configurations(design, pressures_psi, base_angles_deg)
    n, ns = len(labels), len(design.sections)
    if markers == "section_ends":
        markers = tuple(float(np.sum([s.length for s in design.sections[:k + 1]])) for k in range(ns - 1))
    rng = np.random.default_rng(seed)
    base = Measurements(pressures, angles, payload_kg, (TipPositions(np.zeros((n, 2)), 1.0),))
    base.check(design)
    shapes = predict(true_arm, base, model=model, backbone=True)
    if not shapes.converged.all():
        bad = np.flatnonzero(~shapes.converged)
        raise ValueError(f"the true arm has no converged equilibrium at {bad.size} configurations "
                         f"(first: {labels[bad[0]]})")
    observations = []
    if tip_sigma > 0:
        observations.append(TipPositions(shapes.tips + rng.normal(0.0, tip_sigma, (n, 2)), tip_sigma))
    if point_sigma > 0 and len(markers):
        pts = shapes.points(np.asarray(markers, dtype=float)).reshape(n, -1)
        observations.append(BackbonePoints(pts + rng.normal(0.0, point_sigma, pts.shape), point_sigma,
                                           s=tuple(markers)))
    if not noise.is_off:
        eqs = [shapes.equilibrium(k) for k in range(n)]
        readings = []
        for eq in eqs:
            r = synthesize(eq, true_arm, noise, rng)
            readings.append(readings_vector(r.encoder_lengths, r.inclinometers, r.base_wrench,
                                            float(eq.angles[0])))
        readings = np.array(readings)
        observations.append(SensorObservation(readings, sensor_sigma(noise, ns), n_sections=ns))
    mask = np.zeros(n, dtype=bool)
    mask[rng.permutation(n)[:int(round(holdout * n))]] = True
    meas = Measurements(pressures, angles, payload_kg, tuple(observations), holdout=mask)
    return meas, labels, true_arm
