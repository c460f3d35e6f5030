"""Importers of measured logs and the ``graph-calib import`` command."""

import math
import re

import numpy as np
import pytest

from graph_calib import constants as c
from graph_calib import importers
from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.io import read_experiment, write_experiment

XSENS_ROWS = 51175
MPU_FILES = {  # file -> data rows
    "example_data_calibration.csv": 10245,
    "example_data_tinit_calc.csv": 44930,
    "imu_90_x_rot.csv": 9987,
    "imu_static_test.csv": 9986,
}


def _specific_force(exp):
    return np.linalg.norm(exp.dv, axis=1) / exp.dt


# ---------------------------------------------------------------------------
# measured data
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def xsens(real_data):
    folder = real_data / "imu_tk_xsens"
    return importers.import_xsens(folder / "xsens_acc.mat", folder / "xsens_gyro.mat"), folder


def test_xsens_import(xsens):
    exp, folder = xsens
    assert exp.n_samples == XSENS_ROWS
    assert exp.rate_hz == 100.0
    assert exp.t[0] == pytest.approx(0.02984, abs=1e-9) and exp.t[-1] == pytest.approx(511.718, abs=1e-9)
    assert exp.t[-1] - exp.t[0] == pytest.approx(511.68816, abs=1e-9)
    assert 1.0 / np.median(np.diff(exp.t)) == pytest.approx(100.0, rel=1e-6)
    # nominal scales: mean |f| over the session within 3 % of g (measured 2.4 % low: the scales are nominal)
    assert np.mean(_specific_force(exp)) == pytest.approx(exp.gravity_mps2, rel=0.03)
    assert exp.table is None
    assert exp.temperature_names == ("assumed_constant",) and np.all(exp.temperature == 20.0)
    assert exp.latitude_rad == pytest.approx(math.radians(45.41)) and exp.gravity_mps2 == 9.81744
    assert "Copyright (c) 2014, Alberto Pretto" in exp.description
    assert exp.segment is None and exp.n_segments == 1  # one session: one segment


def test_xsens_conversion_is_counts_over_nominal_scale(xsens):
    exp, folder = xsens
    acc = np.loadtxt(folder / "xsens_acc.mat")
    gyro = np.loadtxt(folder / "xsens_gyro.mat")
    dt = np.diff(acc[:, 0])
    np.testing.assert_allclose(exp.dv[1:] / dt[:, None], (acc[1:, 1:] - 32768.0) / 415.0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(exp.dtheta[1:] / dt[:, None], (gyro[1:, 1:] - 32768.0) / 4770.0, rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose(exp.dv[0], (acc[0, 1:] - 32768.0) / 415.0 / 100.0, rtol=1e-12)


@pytest.mark.parametrize("name, rows", MPU_FILES.items())
def test_mpu6050_import(real_data, name, rows):
    exp = importers.import_mpu6050(real_data / "mpu6050_uncuyo" / name)
    assert exp.n_samples == rows
    assert exp.rate_hz == 100.0
    assert np.array_equal(exp.t, np.arange(rows) / 100.0)
    assert exp.t[-1] - exp.t[0] + 1.0 / exp.rate_hz == pytest.approx(rows / 100.0)
    # nominal scales and a large z bias: within 10 % of g (measured 2 % to 9 % low)
    assert np.mean(_specific_force(exp)) == pytest.approx(exp.gravity_mps2, rel=0.10)
    assert exp.latitude_rad == pytest.approx(math.radians(-32.89))
    assert "MIT licence" in exp.description
    # only the calibration session's fast turns reach the gyros' int16 limits (tests below)
    assert (exp.segment is None) == (name != "example_data_calibration.csv")


def test_mpu6050_import_cuts_the_record_after_each_saturated_run(real_data):
    """18 samples at the int16 limits in three runs (x at +-250.1 deg/s twice, z once): a boundary on the first
    sample after each, every piece with a rest of its own; ``cut_saturated=False`` keeps the record whole."""
    path = real_data / "mpu6050_uncuyo" / "example_data_calibration.csv"
    exp = importers.import_mpu6050(path)
    assert exp.segment_bounds() == [(0, 3912), (3912, 6672), (6672, 8772), (8772, 10245)]
    assert "The gyros are saturated in 18 samples (3 episodes, first samples 3910, 6662, 8766): the record is cut after " \
        "3 of them" in exp.description
    whole = importers.import_mpu6050(path, cut_saturated=False)
    assert whole.segment is None and "saturated in 18" not in whole.description
    np.testing.assert_array_equal(whole.dtheta, exp.dtheta)


def test_mpu6050_calibration_session_duration_and_gravity(real_data):
    exp = importers.import_mpu6050(real_data / "mpu6050_uncuyo" / "example_data_calibration.csv")
    assert exp.t[-1] + 1.0 / exp.rate_hz == pytest.approx(102.45)
    assert np.mean(_specific_force(exp)) == pytest.approx(exp.gravity_mps2, rel=0.05)  # measured 3.9 % low
    assert "Initialization time = 36.5" in exp.description
    assert "18 samples touch the int16 limits" in exp.description


def test_mpu6050_authors_calibration_brings_static_poses_to_g(real_data):
    """The authors' own calibration of this session, applied to what the importer made, gives |f| = g.

    Their model is ``a = T K (raw + b)`` on raw counts with g = 9.80665 (README); it only fits if
    the importer kept the rows, the column order and the count scale exactly.
    """
    folder = real_data / "mpu6050_uncuyo"
    exp = importers.import_mpu6050(folder / "example_data_calibration.csv")
    raw = exp.dv / exp.dt[:, None] / c.G0 * 16384.0
    np.testing.assert_allclose(raw, np.round(raw), atol=1e-6)
    p = np.loadtxt(folder / "reference_params_acc.csv")
    m, k, b = p[:3], p[3:6], p[6:]
    T = np.array([[1.0, -m[0], m[1]], [0.0, 1.0, -m[2]], [0.0, 0.0, 1.0]])
    f_cal = (raw + b) @ (T @ np.diag(k)).T
    starts, ends = np.loadtxt(folder / "reference_static_intervals.csv", delimiter=",").astype(int)
    mags = np.array([np.linalg.norm(f_cal[s:e].mean(axis=0)) for s, e in zip(starts, ends)])
    np.testing.assert_allclose(mags, 9.80665, rtol=2e-3)
    raw_mags = np.array([np.linalg.norm((exp.dv / exp.dt[:, None])[s:e].mean(axis=0)) for s, e in zip(starts, ends)])
    assert np.ptp(raw_mags) > 1.0  # before calibration the poses disagree by more than 1 m/s^2


def test_imported_experiment_round_trips(real_data, tmp_path):
    exp = importers.import_mpu6050(real_data / "mpu6050_uncuyo" / "imu_90_x_rot.csv")
    path = tmp_path / "rot.h5"
    write_experiment(exp, path)
    back = read_experiment(path)
    assert np.array_equal(back.dtheta, exp.dtheta) and np.array_equal(back.dv, exp.dv)
    assert back.description == exp.description


# ---------------------------------------------------------------------------
# xsens and mpu6050 errors, on small generated files
# ---------------------------------------------------------------------------


def _xsens_pair(tmp_path, n=20, *, gyro_t_shift=None, acc_lines=None):
    t = 0.03 + np.arange(n) * 0.01
    acc = np.column_stack([t, np.full(n, 32768.0), np.full(n, 32768.0), np.full(n, 32768.0 + 4070.0)])
    gyro = np.column_stack([t, np.full((n, 3), 32768.0)])
    if gyro_t_shift is not None:
        gyro[gyro_t_shift, 0] += 0.001
    a, g = tmp_path / "acc.mat", tmp_path / "gyro.mat"
    np.savetxt(a, acc, fmt="%.7e")
    np.savetxt(g, gyro, fmt="%.7e")
    if acc_lines is not None:
        lines = a.read_text().splitlines()
        for i, text in acc_lines.items():
            lines[i] = text
        a.write_text("\n".join(lines) + "\n")
    return a, g


def test_xsens_small_file_is_imported(tmp_path):
    a, g = _xsens_pair(tmp_path)
    exp = importers.import_xsens(a, g)
    assert exp.n_samples == 20
    np.testing.assert_allclose(exp.dv[:, 2] * 100.0, 4070.0 / 415.0)


def test_xsens_mismatched_time_stamps_are_refused(tmp_path):
    a, g = _xsens_pair(tmp_path, gyro_t_shift=7)
    with pytest.raises(InputError, match=re.escape(f"{g}: line 8: time stamp")) as info:
        importers.import_xsens(a, g)
    assert "must hold the same time stamps" in str(info.value)


def test_xsens_different_lengths_are_refused(tmp_path):
    a, g = _xsens_pair(tmp_path)
    g.write_text("\n".join(g.read_text().splitlines()[:-1]) + "\n")
    with pytest.raises(InputError, match=re.escape(f"{g}: 19 data lines, but {a} has 20")):
        importers.import_xsens(a, g)


def test_xsens_non_numeric_cell_names_the_line(tmp_path):
    a, g = _xsens_pair(tmp_path, acc_lines={4: "0.07 32768 abc 32768"})
    with pytest.raises(InputError, match=re.escape(f"{a}: line 5: non-numeric cell 'abc' in column 2 (y)")):
        importers.import_xsens(a, g)


def test_xsens_wrong_column_count_names_the_line(tmp_path):
    a, g = _xsens_pair(tmp_path, acc_lines={2: "0.05 32768 32768"})
    with pytest.raises(InputError, match=re.escape(f"{a}: line 3: 3 columns, expected 4")):
        importers.import_xsens(a, g)


def test_xsens_values_that_are_not_counts_are_refused(tmp_path):
    a, g = _xsens_pair(tmp_path, acc_lines={9: "0.12 0.5 0.1 9.81"})
    with pytest.raises(InputError, match=re.escape(f"{a}: line 10: value 0.5 is not a 16-bit unsigned count")):
        importers.import_xsens(a, g)


def test_missing_input_file(tmp_path):
    with pytest.raises(InputError, match=re.escape(f"{tmp_path / 'no.mat'}: file not found")):
        importers.import_xsens(tmp_path / "no.mat", tmp_path / "no2.mat")


def _mpu_file(tmp_path, *, header=None, rows=None, n=50):
    header = header or ["Fs,100", "Logging Type,1", "Initialization time,-1", "Waiting time,-1", "ax,ay,az,gx,gy,gz"]
    data = rows or [f"{i % 3},-4,16384,{i % 5},2,-3" for i in range(n)]
    path = tmp_path / "mpu.csv"
    path.write_text("\n".join(header + data) + "\n")
    return path


def test_mpu6050_small_file(tmp_path):
    exp = importers.import_mpu6050(_mpu_file(tmp_path), gravity_mps2=9.80665)
    np.testing.assert_allclose(exp.dv[:, 2], 9.80665 / 100.0, rtol=1e-15)
    np.testing.assert_allclose(exp.dtheta[:, 1], 2.0 / 131.0 * c.DEG_TO_RAD / 100.0, rtol=1e-15)


@pytest.mark.parametrize("header, line, pattern", [
    (["Fs,abc", "Logging Type,1", "Initialization time,-1", "Waiting time,-1", "ax,ay,az,gx,gy,gz"], 1,
     "expected 'Fs,<sample rate in Hz>'"),
    (["Fs,100", "Logging Type", "Initialization time,-1", "Waiting time,-1", "ax,ay,az,gx,gy,gz"], 2,
     "expected a 'key,value' header line"),
    (["Fs,100", "Logging Type,1", "Initialization time,-1", "Waiting time,-1", "gx,gy,gz,ax,ay,az"], 5,
     "expected the column line 'ax,ay,az,gx,gy,gz'"),
])
def test_mpu6050_bad_header(tmp_path, header, line, pattern):
    path = _mpu_file(tmp_path, header=header)
    with pytest.raises(InputError, match=re.escape(f"{path}: line {line}: ") + pattern):
        importers.import_mpu6050(path)


def test_mpu6050_value_out_of_int16_range(tmp_path):
    rows = [f"0,0,16384,0,0,{40000 if i == 3 else 0}" for i in range(10)]
    path = _mpu_file(tmp_path, rows=rows)
    with pytest.raises(InputError, match=re.escape(f"{path}: line 9: value 40000.0 is not a int16 count")):
        importers.import_mpu6050(path)


# ---------------------------------------------------------------------------
# generic csv
# ---------------------------------------------------------------------------


def _csv(tmp_path, *, n=200, rate=200.0, gyro="rad/s", accel="m/s^2", header=None, name="log.csv", t0=5.0,
         delimiter=","):
    """A log turning at 30 deg/s about y, z up; columns t, gx, gy, gz, ax, ay, az, temp."""
    t = t0 + np.arange(n) / rate
    w = np.array([0.0, math.radians(30.0), 0.0])
    f = np.array([0.0, 0.0, 9.8])
    g_cols = {"rad/s": w, "deg/s": np.degrees(w), "rad": w / rate, "deg": np.degrees(w) / rate}[gyro]
    a_cols = {"m/s^2": f, "g": f / c.G0, "m/s": f / rate}[accel]
    data = np.column_stack([t, np.tile(g_cols, (n, 1)), np.tile(a_cols, (n, 1)), np.linspace(20, 21, n)])
    path = tmp_path / name
    np.savetxt(path, data, delimiter=delimiter, fmt="%.17g", header=header or "", comments="")
    if header is None:
        path.write_text(path.read_text().lstrip("\n"))
    return path


COLS = {"t": 0, "gx": 1, "gy": 2, "gz": 3, "ax": 4, "ay": 5, "az": 6, "temp": 7}


@pytest.mark.parametrize("gyro, accel", [("rad/s", "m/s^2"), ("deg/s", "g"), ("rad", "m/s"), ("deg", "m/s^2")])
def test_csv_units_give_the_same_increments(tmp_path, gyro, accel):
    path = _csv(tmp_path, gyro=gyro, accel=accel)
    exp = importers.import_csv(path, columns=COLS, latitude_rad=0.8, gravity_mps2=9.8, gyro_units=gyro,
                               accel_units=accel)
    assert exp.rate_hz == 200.0
    np.testing.assert_allclose(exp.dtheta, np.tile([0.0, math.radians(30.0) / 200.0, 0.0], (200, 1)),
                               rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(exp.dv[:, 2], 9.8 / 200.0, rtol=1e-12)
    assert exp.temperature_names == ("temp",)
    np.testing.assert_allclose(exp.temperature[[0, -1], 0], [20.0, 21.0])


def test_csv_rates_read_as_increments_are_caught(tmp_path):
    path = _csv(tmp_path, gyro="deg/s", n=200)
    # 30 deg/s read as increments in degrees is 30 deg per 5 ms: 104.7 rad/s, beyond the 35 rad/s limit
    with pytest.raises(InputError, match=r"/imu/dtheta \[sample 0\]: \|dtheta\| / dt = 104.72 rad/s.*\(input line 1\)"):
        importers.import_csv(path, columns=COLS, latitude_rad=0.8, gravity_mps2=9.8, gyro_units="deg")


def test_csv_counts_scale_and_offset(tmp_path):
    n = 100
    omega_counts = np.array([0.0, 0.0, 10.0]) * 131.0 + 500.0  # 10 deg/s, offset 500
    f_counts = np.array([0.0, 16384.0, 0.0]) + 20.0  # 1 g along y, offset 20
    data = np.column_stack([np.tile(f_counts, (n, 1)), np.tile(omega_counts, (n, 1))])
    path = tmp_path / "counts.csv"
    np.savetxt(path, data, delimiter=";", fmt="%d", header="ax;ay;az;gx;gy;gz", comments="")
    exp = importers.import_csv(
        path, columns={"ax": "ax", "ay": "ay", "az": "az", "gx": "gx", "gy": "gy", "gz": "gz"},
        latitude_rad=0.0, gravity_mps2=9.78, rate_hz=50.0, gyro_units="deg/s", gyro_counts_per_unit=131.0,
        gyro_offset_counts=500.0, accel_units="g", accel_counts_per_unit=16384.0, accel_offset_counts=20.0,
        temperature_degC=23.0, delimiter=";", header_lines=1)
    np.testing.assert_allclose(exp.t, np.arange(n) / 50.0)
    np.testing.assert_allclose(exp.dtheta[:, 2], math.radians(10.0) / 50.0, rtol=1e-12)  # dt = diff(t)
    np.testing.assert_allclose(exp.dv[:, 1], c.G0 / 50.0, rtol=1e-12)
    assert exp.temperature_names == ("assumed_constant",) and np.all(exp.temperature == 23.0)
    assert "counts (131 per deg/s, offset 500)" in exp.description


def test_csv_time_in_ms_and_named_temperatures(tmp_path):
    path = _csv(tmp_path, rate=100.0, t0=1000.0)
    data = np.loadtxt(path, delimiter=",")
    data[:, 0] *= 1000.0
    data = np.column_stack([data, data[:, 7] + 1.0])
    np.savetxt(path, data, delimiter=",", fmt="%.17g")
    exp = importers.import_csv(path, columns={**{k: v for k, v in COLS.items() if k != "temp"},
                                              "temp:gyro": 7, "temp:accel": 8},
                               latitude_rad=0.8, gravity_mps2=9.8, time_units="ms",
                               temperature_map=[0, 0, 0, 1, 1, 1])
    assert exp.rate_hz == 100.0 and exp.t[0] == pytest.approx(1000.0)
    assert exp.temperature_names == ("gyro", "accel")
    np.testing.assert_allclose(exp.sensor_temperatures()[0], [20, 20, 20, 21, 21, 21])


def test_csv_errors(tmp_path):
    path = _csv(tmp_path)
    kw = dict(latitude_rad=0.8, gravity_mps2=9.8)
    with pytest.raises(InputError, match="columns: unknown column name 'wx'"):
        importers.import_csv(path, columns={**COLS, "wx": 9}, **kw)
    with pytest.raises(InputError, match="columns: no column given for az"):
        importers.import_csv(path, columns={k: v for k, v in COLS.items() if k != "az"}, **kw)
    with pytest.raises(InputError, match=re.escape(f"{path}: columns: column 9 of temp is beyond the 8 columns")):
        importers.import_csv(path, columns={**COLS, "temp": 9}, **kw)
    with pytest.raises(InputError, match=re.escape(f"{path}: --rate-hz: no time column: give the sample rate (--rate-hz HZ)")):
        importers.import_csv(path, columns={k: v for k, v in COLS.items() if k != "t"}, **kw)
    with pytest.raises(InputError, match="--temperature: no temperature column"):
        importers.import_csv(path, columns={k: v for k, v in COLS.items() if k != "temp"}, **kw)
    with pytest.raises(InputError, match="gyro_units: unknown gyro units 'rpm'"):
        importers.import_csv(path, columns=COLS, gyro_units="rpm", **kw)
    lines = path.read_text().splitlines()
    lines[10] = lines[10].replace(",", ";", 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=re.escape(f"{path}: line 11: 7 columns, expected 8")):
        importers.import_csv(path, columns=COLS, **kw)


def test_csv_time_not_increasing_names_the_line(tmp_path):
    path = _csv(tmp_path)
    lines = path.read_text().splitlines()
    lines[6], lines[7] = lines[7], lines[6]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=re.escape(
            f"{path}: line 8: time 5.03 s is not after the previous row's 5.035 s: rows must be in time order")):
        importers.import_csv(path, columns=COLS, latitude_rad=0.8, gravity_mps2=9.8)


def test_csv_repeated_time_in_its_own_units_names_the_line(tmp_path):
    path = _csv(tmp_path, rate=100.0)
    data = np.loadtxt(path, delimiter=",")
    data[:, 0] = np.round(data[:, 0] * 1000.0)
    data[20, 0] = data[19, 0]
    np.savetxt(path, data, delimiter=",", fmt="%.17g")
    with pytest.raises(InputError, match=re.escape(
            f"{path}: line 21: time 5190.0 ms is not after the previous row's 5190.0 ms")):
        importers.import_csv(path, columns=COLS, latitude_rad=0.8, gravity_mps2=9.8, time_units="ms")


# ---------------------------------------------------------------------------
# csv: what new users met
# ---------------------------------------------------------------------------

KW = {"latitude_rad": 0.8, "gravity_mps2": 9.8}


def _text_csv(tmp_path, rows, name="text.csv"):
    path = tmp_path / name
    path.write_text("\n".join(rows) + "\n")
    return path


def _rows(n=100, *, first="x_a", t=lambda k: f"{k / 100.0!r}", seg=None):
    """Rows ``first, t, gx, gy, gz, ax, ay, az, temp[, seg]``: static, z up; column 0 holds text."""
    return [f"{first},{t(k)},0,0,0.01,0,0,9.8,21" + ("" if seg is None else f",{seg(k)}") for k in range(n)]


COLS_TEXT = {"t": 1, "gx": 2, "gy": 3, "gz": 4, "ax": 5, "ay": 6, "az": 7, "temp": 8}


def test_csv_unmapped_columns_may_hold_anything(tmp_path):
    rows = _rows()
    rows[5] = rows[5].replace("x_a", '"free, text"', 1)  # a quoted cell holding the delimiter is one cell
    rows[6] = rows[6].replace("x_a", "", 1)
    exp = importers.import_csv(_text_csv(tmp_path, rows), columns=COLS_TEXT, **KW)
    assert exp.n_samples == 100 and exp.rate_hz == 100.0
    np.testing.assert_allclose(exp.dv[:, 2], 9.8 / 100.0)


def test_csv_mapped_column_must_be_numeric_and_columns_count_from_0(tmp_path):
    path = _text_csv(tmp_path, _rows())
    with pytest.raises(InputError, match=re.escape(f"{path}: line 1: non-numeric cell 'x_a' in column 0 (t)")):
        importers.import_csv(path, columns={**COLS_TEXT, "t": 0}, **KW)


def test_csv_non_finite_value_names_the_column_from_0(tmp_path):
    rows = _rows()
    rows[9] = rows[9].replace(",0.01,", ",nan,")
    path = _text_csv(tmp_path, rows)
    with pytest.raises(InputError, match=re.escape(f"{path}: line 10: non-finite value nan in column 4 (gz)")):
        importers.import_csv(path, columns=COLS_TEXT, **KW)


def test_csv_rows_of_another_width_are_refused_even_in_unmapped_columns(tmp_path):
    rows = _rows()
    rows[30] = rows[30] + ",5"  # e.g. a decimal comma, which would shift the columns after it
    path = _text_csv(tmp_path, rows)
    with pytest.raises(InputError, match=re.escape(f"{path}: line 31: 10 columns, expected 9")):
        importers.import_csv(path, columns=COLS_TEXT, **KW)


def test_csv_sample_index_time_with_rate(tmp_path):
    path = _text_csv(tmp_path, _rows(t=lambda k: str(k + 7)))
    exp = importers.import_csv(path, columns=COLS_TEXT, time_units="samples", rate_hz=204.8, **KW)
    np.testing.assert_allclose(exp.t, (np.arange(100) + 7) / 204.8, rtol=1e-15)
    assert exp.rate_hz == 204.8
    np.testing.assert_allclose(exp.dtheta[:, 2], 0.01 / 204.8, rtol=1e-12)
    assert "time column in samples (t = index / 204.8 Hz)" in exp.description


def test_csv_sample_index_time_needs_the_rate(tmp_path):
    path = _text_csv(tmp_path, _rows(t=str))
    with pytest.raises(InputError, match=re.escape(
            f"{path}: --rate-hz: the time column counts samples: give the sample rate (--rate-hz HZ), t = index / "
            "rate_hz")):
        importers.import_csv(path, columns=COLS_TEXT, time_units="samples", **KW)


def test_csv_sample_index_must_be_an_integer(tmp_path):
    rows = _rows(t=str)
    rows[3] = rows[3].replace(",3,", ",3.5,", 1)
    path = _text_csv(tmp_path, rows)
    with pytest.raises(InputError, match=re.escape(f"{path}: line 4: sample index 3.5 is not an integer")):
        importers.import_csv(path, columns=COLS_TEXT, time_units="samples", rate_hz=100.0, **KW)


@pytest.mark.parametrize("rate_hz", [None, 204.8])
def test_csv_sample_index_read_as_seconds_is_refused(tmp_path, rate_hz):
    path = _text_csv(tmp_path, _rows(t=str))
    with pytest.raises(InputError, match=re.escape(
            f"{path}: time_units: the time column holds whole numbers one apart, a 1 Hz record if they are "
            "seconds: if they count samples give time units 'samples' (--time-units samples)")):
        importers.import_csv(path, columns=COLS_TEXT, rate_hz=rate_hz, **KW)


def test_csv_whole_seconds_are_accepted_with_a_rate_of_1_hz(tmp_path):
    rows = [r.replace(",0.01,", ",0.0001,") for r in _rows(t=str)]
    exp = importers.import_csv(_text_csv(tmp_path, rows), columns=COLS_TEXT, rate_hz=1.0, **KW)
    assert exp.rate_hz == 1.0 and exp.t[-1] == 99.0


def test_csv_time_units_without_a_time_column_are_refused(tmp_path):
    path = _text_csv(tmp_path, _rows())
    with pytest.raises(InputError, match=re.escape(
            "time_units: 'ms' given, but no time column (t=COLUMN): samples are then k / rate_hz apart")):
        importers.import_csv(path, columns={k: v for k, v in COLS_TEXT.items() if k != "t"}, time_units="ms",
                             rate_hz=100.0, **KW)


def test_csv_delimiter_must_be_one_character(tmp_path):
    path = _text_csv(tmp_path, _rows())
    with pytest.raises(InputError, match=re.escape("delimiter: must be one character other than")):
        importers.import_csv(path, columns=COLS_TEXT, delimiter=";;", **KW)


def test_normal_gravity_is_wgs84_somigliana():
    assert importers.normal_gravity(0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert importers.normal_gravity(math.pi / 2) == pytest.approx(9.8321849379, abs=1e-9)
    assert importers.normal_gravity(math.radians(-32.89)) == pytest.approx(9.79557, abs=1e-5)  # docs: Mendoza
    # 45 deg: 9.8061978 with the WGS-84 constants (GRS80's, often quoted, give 9.8061992)
    assert importers.normal_gravity(math.radians(45.0)) == pytest.approx(9.8061978, abs=1e-7)


def test_csv_gravity_from_latitude_says_so(tmp_path):
    path = _text_csv(tmp_path, _rows())
    exp = importers.import_csv(path, columns=COLS_TEXT, latitude_rad=math.radians(48.0))
    assert exp.gravity_mps2 == importers.normal_gravity(math.radians(48.0))
    assert exp.description.endswith("Gravity 9.80891 m/s^2 is WGS-84 normal gravity (Somigliana) at latitude "
                                    "48.0000 deg, at sea level: no local value was given.")
    given = importers.import_csv(path, columns=COLS_TEXT, latitude_rad=math.radians(48.0), description="bench 3")
    assert given.description.startswith("bench 3 Gravity 9.80891")


def test_csv_gravity_from_latitude_needs_a_latitude(tmp_path):
    path = _text_csv(tmp_path, _rows())
    with pytest.raises(InputError, match=re.escape(
            "latitude_rad: normal gravity needs a latitude in [-pi/2, pi/2] rad, got 48.0")):
        importers.import_csv(path, columns=COLS_TEXT, latitude_rad=48.0)


# ---------------------------------------------------------------------------
# csv: segments
# ---------------------------------------------------------------------------


def test_csv_segment_column(tmp_path):
    """Three pieces, the second and third after long gaps; rates become increments over one period at a cut."""
    def cut(k):
        return 0 if k < 40 else (1 if k < 70 else 5)
    rows = _rows(t=lambda k: repr(k / 100.0 + 10.0 * cut(k)), seg=cut)
    path = _text_csv(tmp_path, rows)
    exp = importers.import_csv(path, columns={**COLS_TEXT, "segment": 9}, **KW)
    assert exp.segment.dtype == np.int32 and np.array_equal(exp.segment, np.repeat([0, 1, 5], [40, 30, 30]))
    assert exp.n_segments == 3 and exp.segment_bounds() == [(0, 40), (40, 70), (70, 100)]
    np.testing.assert_allclose(exp.dtheta[:, 2], 0.01 / 100.0, rtol=1e-9)  # also at samples 40 and 70
    assert "3 segment(s) from the segment column" in exp.description
    out = tmp_path / "seg.h5"
    write_experiment(exp, out)
    assert np.array_equal(read_experiment(out).segment, exp.segment)
    # the same gaps without the segment column: refused at the first one, naming the sample and the line
    with pytest.raises(InputError, match=re.escape(f"{path}: t [sample 40]: gap of 10.01 s (1001 nominal "
                                                   "periods) before sample 40 (at ")) as info:
        importers.import_csv(path, columns=COLS_TEXT, **KW)
    assert "samples are missing" in str(info.value) and "segment=COLUMN" in str(info.value)
    assert str(info.value).endswith("(input line 41)")


def test_csv_segment_labels_that_are_not_integers_become_one_segment_per_run(tmp_path):
    path = _text_csv(tmp_path, _rows(seg=lambda k: 0 if k < 50 else 0.5))
    exp = importers.import_csv(path, columns={**COLS_TEXT, "segment": 9}, **KW)
    assert np.array_equal(exp.segment, np.repeat([0, 1], [50, 50]))


def test_csv_decreasing_segment_labels_are_runs_in_order_of_appearance(tmp_path):
    path = _text_csv(tmp_path, ["# a comment line"] + _rows(seg=lambda k: 1 if k < 50 else 0))
    exp = importers.import_csv(path, columns={**COLS_TEXT, "segment": 9}, **KW)
    assert np.array_equal(exp.segment, np.repeat([0, 1], [50, 50]))


# ---------------------------------------------------------------------------
# the command
# ---------------------------------------------------------------------------


def test_cli_import_mpu6050(real_data, tmp_path, capsys):
    out = tmp_path / "calib.h5"
    rc = main(["import", "mpu6050", str(real_data / "mpu6050_uncuyo" / "example_data_calibration.csv"),
               "--out", str(out), "--latitude-deg", "-32.9", "--temperature", "22.5"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "10245 samples in 4 segments, 102.45 s at 100 Hz" in text and "mean |f| = 9.41" in text
    assert "note: The gyros are saturated in 18 samples (3 episodes" in text and f"wrote {out}" in text
    exp = read_experiment(out)
    assert exp.n_samples == 10245 and exp.latitude_rad == pytest.approx(math.radians(-32.9))
    assert np.all(exp.temperature == 22.5)
    assert exp.n_segments == 4 and "saturated in 18 samples" in exp.description


def test_cli_import_keep_saturated_and_a_declared_gyro_range(real_data, tmp_path, capsys):
    path = str(real_data / "mpu6050_uncuyo" / "example_data_calibration.csv")
    assert main(["import", "mpu6050", path, "--out", str(tmp_path / "whole.h5"), "--keep-saturated"]) == 0
    text = capsys.readouterr().out
    assert "10245 samples, 102.45 s" in text
    # kept whole, the flat tops are still pointed out, with the option that cuts after them
    assert ("note: the gyros sit at their largest output (x at +250.13 and -250.14 deg/s, z at -250.14 deg/s) in 18 "
            "samples (3 episodes), as a saturated gyro does: --gyro-range-dps") in text
    assert read_experiment(tmp_path / "whole.h5").segment is None
    # a declared range replaces the counts' limits: at 200 deg/s one more fast turn reaches it
    assert main(["import", "mpu6050", path, "--out", str(tmp_path / "r200.h5"), "--gyro-range-dps", "200"]) == 0
    assert "saturated in 82 samples (4 episodes" in capsys.readouterr().out
    assert read_experiment(tmp_path / "r200.h5").n_segments == 4


@pytest.mark.parametrize("value", ["0", "-250", "nan"])
def test_cli_import_refuses_a_gyro_range_that_is_not_positive(real_data, tmp_path, capsys, value):
    path = str(real_data / "mpu6050_uncuyo" / "imu_90_x_rot.csv")
    assert main(["import", "mpu6050", path, "--out", str(tmp_path / "x.h5"), f"--gyro-range-dps={value}"]) == 2
    assert "--gyro-range-dps: must be a positive number of deg/s" in capsys.readouterr().err
    assert not (tmp_path / "x.h5").exists()


def test_cli_import_xsens(real_data, tmp_path, capsys):
    out = tmp_path / "xsens.h5"
    folder = real_data / "imu_tk_xsens"
    rc = main(["import", "xsens", str(folder / "xsens_acc.mat"), str(folder / "xsens_gyro.mat"), "--out", str(out)])
    assert rc == 0
    assert "51175 samples" in capsys.readouterr().out
    assert read_experiment(out).n_samples == XSENS_ROWS


def test_cli_import_csv(tmp_path, capsys):
    path = _csv(tmp_path, gyro="deg/s")
    out = tmp_path / "csv.h5"
    rc = main(["import", "csv", str(path), "--out", str(out), "--columns", "t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6,temp=7",
               "--gyro-units", "deg/s", "--latitude-deg", "48.1", "--gravity", "9.8078"])
    assert rc == 0, capsys.readouterr().err
    exp = read_experiment(out)
    np.testing.assert_allclose(exp.dtheta[:, 1], math.radians(30.0) / 200.0, rtol=1e-12)


def test_cli_import_csv_gravity_from_latitude_prints_a_note(tmp_path, capsys):
    path = _text_csv(tmp_path, _rows(t=str, seg=lambda k: k // 50))
    out = tmp_path / "csv.h5"
    rc = main(["import", "csv", str(path), "--out", str(out), "--columns",
               "t=1,gx=2,gy=3,gz=4,ax=5,ay=6,az=7,temp=8,segment=9", "--time-units", "samples",
               "--rate-hz", "204.8", "--latitude-deg", "48"])
    assert rc == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "100 samples in 2 segments" in text
    assert ("note: gravity 9.80891 m/s^2 is WGS-84 normal gravity (Somigliana) at 48 deg latitude, at sea level; "
            "give --gravity for the local value") in text
    exp = read_experiment(out)
    assert exp.rate_hz == 204.8 and exp.n_segments == 2
    assert exp.gravity_mps2 == pytest.approx(9.80891, abs=1e-5) and "normal gravity" in exp.description


def test_cli_missing_input_file_exits_2(tmp_path, capsys):
    missing = tmp_path / "nope.csv"
    rc = main(["import", "mpu6050", str(missing), "--out", str(tmp_path / "x.h5")])
    assert rc == 2
    err = capsys.readouterr().err
    assert err == f"graph-calib import: error: {missing}: file not found\n"
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize("args, pattern", [
    (["xsens", "a.mat"], "INPUT: format xsens takes ACC_FILE GYRO_FILE, got 1 input"),
    (["mpu6050", "a.csv", "--offset", "3"], "--offset: does not apply to format mpu6050"),
    (["csv", "a.csv", "--latitude-deg", "10", "--gravity", "9.8"], "a.csv: file not found"),
    (["csv", "a.csv", "--columns", "t=0,gx", "--latitude-deg", "10", "--gravity", "9.8"],
     "--columns: expected KEY=COLUMN items"),
    (["mpu6050", "a.csv", "--latitude-deg", "123"], r"--latitude-deg: latitude must be within \[-90, 90\]"),
    (["csv", "a.csv", "--columns", "t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6", "--gravity", "9.8"],
     re.escape("--latitude-deg: required for format csv: the bench latitude in degrees (the Earth rate needs it; "
               "without --gravity, gravity is the normal gravity at that latitude)")),
])
def test_cli_bad_options_exit_2(tmp_path, capsys, monkeypatch, args, pattern):
    """Each option's fault with its message; the input ``a.csv`` exists but where the missing file is the fault
    (a missing input is named before what the format asks of its options)."""
    monkeypatch.chdir(tmp_path)
    if "file not found" not in pattern:
        (tmp_path / "a.csv").write_text("1,2,3,4,5,6,7\n")
    rc = main(["import", *args, "--out", str(tmp_path / "x.h5")])
    assert rc == 2
    err = capsys.readouterr().err
    assert re.search(pattern, err), err
    assert err.count("\n") == 1
