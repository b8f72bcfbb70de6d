"""The CSV format of measured shapes, synthetic data, and sensor readings as an observation."""

import math

import numpy as np
import pytest

import solver
from softarm_gym.identify import SensorObservation, make_synthetic, read_csv, sensor_sigma, write_csv
from softarm_gym.identify.sensors import readings_vector, sensor_labels
from softarm_gym.sensing import SensorNoise, synthesize
from solver.identify import BackbonePoints, TipPositions, predict

ARM = solver.designs.octarm_v()
HEADER = ("base_angle_deg,payload_kg,s1_I_psi,s1_II+III_psi,s2_I_psi,s2_II+III_psi,s3_I_psi,s3_II+III_psi,"
          "tip_x_m,tip_y_m")


def test_synthetic_data_round_trip_through_the_csv_file(tmp_path):
    meas, labels, _ = make_synthetic(ARM, {"wind_angle": 77.0}, pressures_psi=(40,),
                                     base_angles_deg=(0.0, 90.0), payload_kg=0.1, seed=1)
    assert [o.name for o in meas.observations] == ["tip", "points", "sensors"]
    assert meas.n == 128 and meas.holdout.sum() == round(0.2 * 128)
    path = tmp_path / "shapes.csv"
    write_csv(path, ARM, meas, labels, comments=["made by a test"])
    back, back_labels = read_csv(path, ARM)
    assert back_labels == labels
    np.testing.assert_array_equal(back.holdout, meas.holdout)
    np.testing.assert_allclose(back.pressures, meas.pressures, rtol=1e-15)
    np.testing.assert_array_equal(back.payload_kg, 0.1)
    for a, b in zip(meas.observations, back.observations):
        assert type(a) is type(b)
        np.testing.assert_allclose(b.measured, a.measured, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(b.sigma, a.sigma)
    assert back.observations[1].s == (0.25, 0.53)


def test_synthetic_readings_are_the_sensor_models_rounded_to_table_4_3():
    truth = {"wind_angle": 77.0, "E": 2.2e6}
    meas, _, true_arm = make_synthetic(ARM, truth, pressures_psi=(60,), base_angles_deg=(90.0,),
                                       tip_sigma=0.0, point_sigma=0.0, holdout=0.0, seed=0)
    (obs,) = meas.observations
    noise = SensorNoise.thesis()
    shapes = predict(true_arm, meas, backbone=True)
    exact = []
    for k in range(meas.n):
        r = synthesize(shapes.equilibrium(k), true_arm)
        exact.append(readings_vector(r.encoder_lengths, r.inclinometers, r.base_wrench,
                                     float(shapes.equilibrium(k).angles[0])))
    exact = np.array(exact)
    res = np.concatenate([np.full(6, noise.encoder_resolution), np.full(3, math.radians(2.5)),
                          [noise.force_resolution, noise.axial_force_resolution, noise.moment_resolution]])
    assert np.all(np.abs(obs.measured - exact) <= res / 2 * (1 + 1e-9))
    np.testing.assert_allclose(obs.sigma[0], res / math.sqrt(12.0))
    # The load cell reads n(0) = −m·g·ŷ (global equilibrium), along a horizontal base's d1 = ŷ.
    np.testing.assert_allclose(exact[:, 9], -true_arm.mass * 9.81, rtol=1e-9)
    np.testing.assert_allclose(exact[:, 10], 0.0, atol=1e-9)


def test_sensor_prediction_picks_the_inclinometer_turn_nearest_the_reading():
    meas, _, true_arm = make_synthetic(ARM, {"wind_angle": 77.0}, pressures_psi=(90,),
                                       base_angles_deg=(90.0,), tip_sigma=0.0, point_sigma=0.0, holdout=0.0,
                                       seed=0)
    obs = meas.observations[0]
    shifted = obs.measured.copy()
    shifted[:, 6:9] += 2 * math.pi  # a sensor that reports θ + 2π
    moved = SensorObservation(shifted, obs.sigma, n_sections=3)
    shapes = predict(true_arm, meas, backbone=True)
    turned = moved.predict(shapes, true_arm)[:, 6:9] - obs.predict(shapes, true_arm)[:, 6:9]
    np.testing.assert_allclose(turned, 2 * math.pi)


def test_sensor_sigma():
    assert sensor_labels(2) == ("enc_s1_plus", "enc_s1_minus", "enc_s2_plus", "enc_s2_minus", "incl_s1",
                                "incl_s2", "load_shear", "load_axial", "load_moment")
    sigma = sensor_sigma(SensorNoise.thesis(gaussian_std=1.0), 1)
    np.testing.assert_allclose(sigma[0], 0.03 * math.sqrt(1 + 1 / 12))
    with pytest.raises(ValueError, match="zero standard deviation"):
        sensor_sigma(SensorNoise.off(), 3)


def _write(tmp_path, text):
    path = tmp_path / "data.csv"
    path.write_text(text)
    return path


ROW = "90,0,30,0,0,0,0,0,0.8,-0.2"


@pytest.mark.parametrize("text, match", [
    ("", "no header row"),
    ("# only a comment\n", "no header row"),
    (HEADER + "\n", "a header but no data rows"),
    (HEADER + "\n90,0,30,0,0,0,0,0,0.8\n", "line 2: 9 fields; the header has 10"),
    (HEADER + "\n90,0,thirty,0,0,0,0,0,0.8,-0.2\n", "line 2, column 's1_I_psi': 'thirty' is not a number"),
    (HEADER + "\n90,0,nan,0,0,0,0,0,0.8,-0.2\n", "'nan' is not a finite number"),
    (HEADER + "\n,0,30,0,0,0,0,0,0.8,-0.2\n", "column 'base_angle_deg' is empty; it is required"),
    (HEADER + ",colour\n" + ROW + ",red\n", "unknown column(s) 'colour'"),
    (HEADER.replace("s3_II+III_psi", "s3_II_psi") + "\n" + ROW + "\n", "unknown column(s) 's3_II_psi'"),
    (HEADER.replace(",s3_II+III_psi", "") + "\n90,0,30,0,0,0,0,0.8,-0.2\n",
     "missing column(s) s3_II+III_psi"),
    (HEADER + ",x@0.25_m\n" + ROW + ",0.2\n", "needs both x@0.25_m and y@0.25_m"),
    (HEADER + ",x@-1_m,y@-1_m\n" + ROW + ",0,0\n", "arc length >= 0"),
    (HEADER.replace(",tip_y_m", "") + "\n90,0,30,0,0,0,0,0,0.8\n", "tip_x_m and tip_y_m come together"),
    (HEADER + ",split\n" + ROW + ",test\n", "'test' is not fit or holdout"),
    (HEADER + ",tip_x_m\n" + ROW + ",1\n", "column 'tip_x_m' appears twice"),
    (HEADER + "\n90,0,30,0,0,0,0,0,,\n", "nothing measured"),
    (HEADER + '\n90,0,30,0,0,0,0,0,"0.8,-0.2\n', "malformed CSV"),
    (HEADER + "\n90,0,130,0,0,0,0,0,0.8,-0.2\n", "pressure for channel 's1_I'"),
])
def test_malformed_data_files_are_one_line_errors(tmp_path, text, match):
    path = _write(tmp_path, text)
    with pytest.raises(ValueError) as exc:
        meas, _ = read_csv(path, ARM)
        meas.check(ARM)
    assert match in str(exc.value) and "\n" not in str(exc.value)


def test_comments_blank_lines_and_partial_rows_are_read(tmp_path):
    path = _write(tmp_path, "# a comment\n\n" + HEADER + ",x@0.53_m,y@0.53_m\n" + ROW + ",,\n"
                  "0,0.2,0,30,0,0,0,0,,,0.1,-0.5\n")
    meas, labels = read_csv(path, ARM, payload_kg=0.5)
    assert labels == ["", ""] and meas.holdout is None
    tip, points = meas.observations
    assert isinstance(tip, TipPositions) and isinstance(points, BackbonePoints)
    np.testing.assert_array_equal(np.isfinite(tip.measured), [[True, True], [False, False]])
    np.testing.assert_array_equal(meas.payload_kg, [0.0, 0.2])
    assert meas.n_values == 4
