r"""Converters from bench and third-party logs into :class:`~graph_calib.experiment.Experiment`.

Each importer reads raw sensor output (counts, rates or increments, in the
units the log uses), converts it to SI with *nominal* (datasheet) scales — the
calibration estimates the actual ones — and returns a validated experiment,
ready for :func:`graph_calib.io.write_experiment`:

* :func:`import_xsens` — the Xsens MTi sample data of IMU-TK (two text files of
  raw ADC counts);
* :func:`import_mpu6050` — the MPU-6050 logs of UNCuyo's ImuCalibration (CSV of
  int16 counts with a small header);
* :func:`import_csv` — any delimited text log, described by a column mapping and
  units.

A sample holding a rate (``omega``, ``f``) becomes an increment over the
interval it closes, ``dtheta[k] = omega[k] * (t[k] - t[k-1])`` with
``t[0] - t[-1] := 1 / rate_hz`` (``data-format.md``).  Logs without temperature
get one channel ``"assumed_constant"`` holding the assumed temperature, and the
description says so.  Defaults and their provenance are in
``docs/data-format.md``.

Errors in the input (missing file, wrong column count, non-numeric cell,
mismatched time stamps, values that cannot be raw counts) raise
:class:`~graph_calib.errors.InputError` naming the file and the line.
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path

import numpy as np

from graph_calib import constants as c
from graph_calib.errors import InputError
from graph_calib.experiment import Experiment
from graph_calib.io import validate_experiment

#: Name of the temperature channel of a log that recorded no temperature.
ASSUMED_TEMPERATURE_NAME = "assumed_constant"

# IMU-TK sample data (Tedaldi, Pretto, Menegatti, ICRA 2014).
#: Assumed latitude of the IMU-TK recordings: Padova, Italy (45.41 deg N), where the
#: authors worked; the data do not say where they were taken.
XSENS_LATITUDE_RAD = math.radians(45.41)
#: Local gravity used by the IMU-TK authors for this data set, m/s^2.
XSENS_GRAVITY_MPS2 = 9.81744
XSENS_ACCEL_COUNTS_PER_MPS2 = 415.0
XSENS_GYRO_COUNTS_PER_RADS = 4770.0
XSENS_OFFSET_COUNTS = 32768.0
XSENS_RATE_HZ = 100.0
XSENS_NOTICE = ("IMU-TK sample data, BSD 2-clause licence: Copyright (c) 2014, Alberto Pretto. "
                "All rights reserved.")

# UNCuyo ImuCalibration sample data (MPU-6050).
#: Assumed latitude of the UNCuyo recordings: Mendoza, Argentina (32.89 deg S).
MPU6050_LATITUDE_RAD = math.radians(-32.89)
#: WGS-84 normal gravity at 32.89 deg S with the free-air correction for Mendoza's
#: altitude (746 m), m/s^2.
MPU6050_GRAVITY_MPS2 = 9.7933
MPU6050_ACCEL_COUNTS_PER_G = 16384.0
MPU6050_GYRO_COUNTS_PER_DPS = 131.0
MPU6050_COLUMNS = ("ax", "ay", "az", "gx", "gy", "gz")
MPU6050_NOTICE = "UNCuyo ImuCalibration sample data, MIT licence: Copyright (c) 2025 tomisuarez2."

#: Units of :func:`import_csv`: name -> (factor to SI, True for a rate, False for an increment).
GYRO_UNITS = {"rad/s": (1.0, True), "deg/s": (c.DEG_TO_RAD, True), "rad": (1.0, False), "deg": (c.DEG_TO_RAD, False)}
ACCEL_UNITS = {"m/s^2": (1.0, True), "g": (c.G0, True), "m/s": (1.0, False)}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
CSV_SENSOR_COLUMNS = ("gx", "gy", "gz", "ax", "ay", "az")



def _show(x):
    """``repr`` of a value for messages, numpy scalars shown as plain Python numbers."""
    if isinstance(x, np.generic):
        x = x.item()
    return repr(x)

# ---------------------------------------------------------------------------
# Reading delimited text
# ---------------------------------------------------------------------------


def _require_file(path):
    path = Path(path)
    if not path.exists():
        raise InputError("file not found", path=path)
    if not path.is_file():
        raise InputError("not a file", path=path)
    return path


def _strip_comment(line):
    return line.split("#", 1)[0].strip()


def _split(line, delimiter):
    cells = line.split(delimiter) if delimiter is not None else line.split()
    return [cell.strip().strip('"') for cell in cells]


def _data_line_numbers(path, skip_lines):
    """1-based line number of every data row (comment and blank lines skipped); error path only."""
    numbers = []
    with open(path, encoding="utf-8") as fh:
        for no, line in enumerate(fh, start=1):
            if no > skip_lines and _strip_comment(line):
                numbers.append(no)
    return np.asarray(numbers, dtype=np.int64)


def _diagnose(path, *, delimiter, skip_lines, n_columns):
    """Find the first line that does not parse and raise an InputError naming it."""
    expected = n_columns
    with open(path, encoding="utf-8") as fh:
        for no, line in enumerate(fh, start=1):
            text = _strip_comment(line)
            if no <= skip_lines or not text:
                continue
            cells = _split(text, delimiter)
            if expected is None:
                expected = len(cells)
            if len(cells) != expected:
                raise InputError(f"{len(cells)} columns, expected {expected}", path=path, dataset=f"line {no}")
            for j, cell in enumerate(cells):
                try:
                    float(cell)
                except ValueError:
                    raise InputError(f"non-numeric cell {_show(cell)} in column {j + 1}", path=path,
                                     dataset=f"line {no}") from None
    raise InputError("cannot be read as a table of numbers", path=path)


def read_numeric_table(path, *, delimiter=None, skip_lines=0, n_columns=None):
    """Read a delimited text file of numbers.

    Blank lines and ``#`` comments are skipped.

    Parameters
    ----------
    path : str or Path
    delimiter : str or None
        Column separator; None for any whitespace.
    skip_lines : int
        Header lines to skip before the data.
    n_columns : int or None
        Required number of columns (None: any, but the same on every line).

    Returns
    -------
    ndarray, shape (R, C)
        float64.

    Raises
    ------
    InputError
        Missing file, no data, a wrong column count, a non-numeric cell or a
        non-finite value, naming the file and the line.
    """
    path = _require_file(path)
    try:
        data = np.loadtxt(path, delimiter=delimiter, skiprows=skip_lines, comments="#", ndmin=2,
                          dtype=np.float64, encoding="utf-8", quotechar='"')
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path=path) from None
    except ValueError:
        _diagnose(path, delimiter=delimiter, skip_lines=skip_lines, n_columns=n_columns)
        raise  # pragma: no cover  (_diagnose always raises)
    if data.size == 0:
        raise InputError("no data lines", path=path)
    if n_columns is not None and data.shape[1] != n_columns:
        line = _data_line_numbers(path, skip_lines)[0]
        raise InputError(f"{data.shape[1]} columns, expected {n_columns}", path=path, dataset=f"line {line}")
    bad = ~np.isfinite(data)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        col = int(np.flatnonzero(bad[row])[0])
        line = _data_line_numbers(path, skip_lines)[row]
        raise InputError(f"non-finite value {_show(data[row, col])} in column {col + 1}", path=path, dataset=f"line {line}")
    return data


def _check_counts(counts, *, path, skip_lines, lo, hi, what):
    """Refuse values that cannot be raw integer counts in [lo, hi]; return the count of saturated rows."""
    bad = (counts != np.round(counts)) | (counts < lo) | (counts > hi)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        line = _data_line_numbers(path, skip_lines)[row]
        raise InputError(f"value {_show(counts[row][bad[row]][0])} is not a {what} count (an integer in [{lo}, {hi}])",
                         path=path, dataset=f"line {line}")
    return int(((counts <= lo) | (counts >= hi)).any(axis=1).sum())


def _check_time_column(t, *, path, skip_lines):
    bad = ~(np.diff(t) > 0)
    if bad.any():
        row = int(np.flatnonzero(bad)[0]) + 1
        line = _data_line_numbers(path, skip_lines)[row]
        raise InputError(f"time {_show(t[row])} s is not after the previous one {_show(t[row - 1])} s", path=path,
                         dataset=f"line {line}")


def _nominal_rate(t):
    """``1 / median(diff(t))`` rounded to 6 significant digits, Hz."""
    return float(f"{1.0 / float(np.median(np.diff(t))):.6g}")


# ---------------------------------------------------------------------------
# Building the experiment
# ---------------------------------------------------------------------------


def _intervals(t, rate_hz):
    dt = np.empty_like(t)
    dt[0] = 1.0 / rate_hz
    dt[1:] = np.diff(t)
    return dt


def _build(*, t, dtheta, dv, temperature, names, temperature_map, rate_hz, latitude_rad, gravity_mps2,
           imu_id, description, source, skip_lines):
    """Assemble and validate; a rule broken at a sample names the input line too."""
    exp = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=temperature, temperature_names=tuple(names),
        temperature_map=np.asarray(temperature_map, dtype=np.int64), rate_hz=_num(rate_hz),
        latitude_rad=_num(latitude_rad), gravity_mps2=_num(gravity_mps2), imu_id=imu_id,
        description=description, table=None, source=str(source),
    )
    try:
        validate_experiment(exp, path=source)
    except InputError as exc:
        if exc.index is None:
            raise
        line = _data_line_numbers(source, skip_lines)[exc.index]
        err = InputError(f"{exc} (input line {line})")
        err.path, err.dataset, err.index = exc.path, exc.dataset, exc.index
        raise err from None
    return exp


def _num(x):
    """``float(x)`` for a real number; anything else unchanged (the validator refuses it by name)."""
    return float(x) if isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_)) else x


def _constant_temperature(n, temperature_degC):
    if not isinstance(_num(temperature_degC), float) or not math.isfinite(temperature_degC):
        raise InputError(f"assumed temperature must be a finite number of degC, got {_show(temperature_degC)}",
                         dataset="temperature_degC")
    return np.full((n, 1), float(temperature_degC)), (ASSUMED_TEMPERATURE_NAME,)


def _positive(value, name):
    if not isinstance(_num(value), float) or not value > 0 or not math.isfinite(value):
        raise InputError(f"must be a positive number, got {_show(value)}", dataset=name)
    return float(value)


def import_xsens(acc_path, gyro_path, *, latitude_rad=XSENS_LATITUDE_RAD, gravity_mps2=XSENS_GRAVITY_MPS2,
                 temperature_degC=20.0, accel_scale_counts_per_mps2=XSENS_ACCEL_COUNTS_PER_MPS2,
                 gyro_scale_counts_per_rads=XSENS_GYRO_COUNTS_PER_RADS, offset_counts=XSENS_OFFSET_COUNTS,
                 rate_hz=XSENS_RATE_HZ, imu_id="Xsens MTi (IMU-TK sample data)", description=None):
    """Import the IMU-TK Xsens MTi sample data (``xsens_acc.mat``, ``xsens_gyro.mat``).

    Both files are whitespace-separated text (despite the ``.mat`` ending) with
    four columns: time, s, and x, y, z raw unsigned 16-bit ADC counts.  They
    must hold the same time stamps.  Counts become SI with the nominal scales,
    ``f = (counts - offset) / accel_scale`` and ``omega = (counts - offset) /
    gyro_scale``, then increments ``f * dt``, ``omega * dt``.

    Parameters
    ----------
    acc_path, gyro_path : str or Path
        Accelerometer and gyro files.
    latitude_rad : float
        Bench latitude, rad; default Padova (assumed, see the docs).
    gravity_mps2 : float
        Local gravity, m/s^2; default the IMU-TK authors' 9.81744.
    temperature_degC : float
        Assumed constant temperature (the data hold none), degC.
    accel_scale_counts_per_mps2, gyro_scale_counts_per_rads : float
        Nominal scales, counts per m/s^2 and counts per rad/s.
    offset_counts : float
        Nominal zero of both triads, counts.
    rate_hz : float
        Nominal sample rate, Hz.
    imu_id : str
    description : str or None
        Default: the provenance, the conversion and the licence notice.

    Returns
    -------
    Experiment
        N samples (51,175 for the IMU-TK files), no table, one temperature channel.

    Raises
    ------
    InputError
        Missing or malformed file (with line), different time stamps in the
        two files, values that are not 16-bit counts, converted data that break
        a rule of the experiment format.
    """
    acc_path, gyro_path = Path(acc_path), Path(gyro_path)
    sa = _positive(accel_scale_counts_per_mps2, "accel_scale_counts_per_mps2")
    sg = _positive(gyro_scale_counts_per_rads, "gyro_scale_counts_per_rads")
    rate_hz = _positive(rate_hz, "rate_hz")
    acc = read_numeric_table(acc_path, n_columns=4)
    gyro = read_numeric_table(gyro_path, n_columns=4)
    if acc.shape[0] != gyro.shape[0]:
        raise InputError(f"{gyro.shape[0]} data lines, but {acc_path} has {acc.shape[0]}; "
                         "the two files must hold the same time stamps", path=gyro_path)
    differ = acc[:, 0] != gyro[:, 0]
    if differ.any():
        row = int(np.flatnonzero(differ)[0])
        line = _data_line_numbers(gyro_path, 0)[row]
        raise InputError(f"time stamp {_show(gyro[row, 0])} s differs from {_show(acc[row, 0])} s in {acc_path}; "
                         "the two files must hold the same time stamps", path=gyro_path, dataset=f"line {line}")
    t = acc[:, 0]
    _check_time_column(t, path=acc_path, skip_lines=0)
    sat_a = _check_counts(acc[:, 1:], path=acc_path, skip_lines=0, lo=0, hi=65535, what="16-bit unsigned")
    sat_g = _check_counts(gyro[:, 1:], path=gyro_path, skip_lines=0, lo=0, hi=65535, what="16-bit unsigned")
    temperature, names = _constant_temperature(t.shape[0], temperature_degC)
    dt = _intervals(t, rate_hz)[:, None]
    f_b = (acc[:, 1:] - offset_counts) / sa
    omega_b = (gyro[:, 1:] - offset_counts) / sg
    if description is None:
        description = (
            f"Xsens MTi, hand-held multi-position session: IMU-TK sample data (Tedaldi, Pretto, Menegatti, "
            f"ICRA 2014), imported from {acc_path.name} and {gyro_path.name}. Raw counts converted with "
            f"nominal scales {sa:g} counts per m/s^2 and {sg:g} counts per rad/s, offset {offset_counts:g} "
            f"counts; samples at the 16-bit limits: accel {sat_a}, gyro {sat_g}. No temperature was recorded: "
            f"channel '{ASSUMED_TEMPERATURE_NAME}' holds an assumed {float(temperature_degC):g} degC. "
            f"Latitude {math.degrees(latitude_rad):.4f} deg and gravity {gravity_mps2:g} m/s^2 are assumed "
            f"(the importer's defaults are Padova, 45.41 deg, and the authors' 9.81744 m/s^2). {XSENS_NOTICE}"
        )
    return _build(t=t, dtheta=omega_b * dt, dv=f_b * dt, temperature=temperature, names=names,
                  temperature_map=np.zeros(6), rate_hz=rate_hz, latitude_rad=latitude_rad,
                  gravity_mps2=gravity_mps2, imu_id=imu_id, description=description, source=acc_path,
                  skip_lines=0)


def _read_mpu6050_header(path):
    """The four ``key,value`` header lines and the column line; returns (fs_hz, header dict)."""
    with open(path, encoding="utf-8") as fh:
        lines = [fh.readline() for _ in range(5)]
    header = {}
    for no, line in enumerate(lines[:4], start=1):
        cells = _split(line.strip(), ",")
        if len(cells) != 2 or not cells[0]:
            raise InputError(f"expected a 'key,value' header line, got {_show(line.strip())}", path=path,
                             dataset=f"line {no}")
        header[cells[0]] = cells[1]
    key, value = next(iter(header.items()))
    try:
        fs = float(value)
    except ValueError:
        fs = float("nan")
    if key != "Fs" or not (math.isfinite(fs) and fs > 0):
        raise InputError(f"expected 'Fs,<sample rate in Hz>', got {_show(lines[0].strip())}", path=path,
                         dataset="line 1")
    cols = tuple(_split(lines[4].strip().lower(), ","))
    if cols != MPU6050_COLUMNS:
        raise InputError(f"expected the column line {_show(','.join(MPU6050_COLUMNS))}, got {_show(lines[4].strip())}",
                         path=path, dataset="line 5")
    return fs, header


def import_mpu6050(csv_path, *, latitude_rad=MPU6050_LATITUDE_RAD, gravity_mps2=MPU6050_GRAVITY_MPS2,
                   temperature_degC=20.0, accel_counts_per_g=MPU6050_ACCEL_COUNTS_PER_G,
                   gyro_counts_per_dps=MPU6050_GYRO_COUNTS_PER_DPS,
                   imu_id="InvenSense MPU-6050 (UNCuyo ImuCalibration sample data)", description=None):
    """Import an MPU-6050 log of UNCuyo's ImuCalibration (CSV of raw int16 counts).

    Layout: four header lines (``Fs,100``, logging type, initialisation time,
    waiting time), the line ``ax,ay,az,gx,gy,gz``, then one line of int16 counts
    per sample.  There is no time column: ``t[k] = k / Fs``.  Counts become SI
    with the nominal scales, ``f = counts / accel_counts_per_g * G0`` (standard
    gravity, the datasheet's g) and ``omega = counts / gyro_counts_per_dps``
    in deg/s, converted to rad/s.

    Parameters
    ----------
    csv_path : str or Path
    latitude_rad : float
        Bench latitude, rad; default Mendoza (assumed, see the docs).
    gravity_mps2 : float
        Local gravity, m/s^2; default normal gravity at Mendoza.
    temperature_degC : float
        Assumed constant temperature (the log holds none), degC.
    accel_counts_per_g : float
        Nominal accelerometer scale, counts per standard g (``9.80665`` m/s^2).
    gyro_counts_per_dps : float
        Nominal gyro scale, counts per deg/s.
    imu_id : str
    description : str or None
        Default: provenance, header values, conversion, licence notice.

    Returns
    -------
    Experiment
        No table, one temperature channel.

    Raises
    ------
    InputError
        Missing file, a malformed header (with line), a wrong column count, a
        non-numeric cell, a value that is not an int16 count.
    """
    path = _require_file(csv_path)
    sa = _positive(accel_counts_per_g, "accel_counts_per_g")
    sg = _positive(gyro_counts_per_dps, "gyro_counts_per_dps")
    try:
        fs, header = _read_mpu6050_header(path)
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path=path) from None
    data = read_numeric_table(path, delimiter=",", skip_lines=5, n_columns=6)
    n_sat = _check_counts(data, path=path, skip_lines=5, lo=-32768, hi=32767, what="int16")
    n = data.shape[0]
    t = np.arange(n, dtype=np.float64) / fs
    f_b = data[:, :3] / sa * c.G0
    omega_b = data[:, 3:] / sg * c.DEG_TO_RAD
    temperature, names = _constant_temperature(n, temperature_degC)
    if description is None:
        head = "; ".join(f"{k} = {v}" for k, v in header.items())
        description = (
            f"InvenSense MPU-6050, hand-held session: UNCuyo ImuCalibration sample data, imported from "
            f"{path.name} (header: {head}). Raw int16 counts converted with nominal scales {sa:g} counts per g "
            f"(g = {c.G0} m/s^2) and {sg:g} counts per deg/s; t = k / Fs; {n_sat} samples touch the int16 "
            f"limits (saturated). No temperature was recorded: channel '{ASSUMED_TEMPERATURE_NAME}' holds an "
            f"assumed {float(temperature_degC):g} degC. Latitude {math.degrees(latitude_rad):.4f} deg and gravity "
            f"{gravity_mps2:g} m/s^2 are assumed (the importer's defaults are Mendoza, Argentina, -32.89 deg, "
            f"{MPU6050_GRAVITY_MPS2} m/s^2). {MPU6050_NOTICE}"
        )
    dt = 1.0 / fs
    return _build(t=t, dtheta=omega_b * dt, dv=f_b * dt, temperature=temperature, names=names,
                  temperature_map=np.zeros(6), rate_hz=fs, latitude_rad=latitude_rad,
                  gravity_mps2=gravity_mps2, imu_id=imu_id, description=description, source=path,
                  skip_lines=5)


def mpu6050_reference_calibration(params_path):
    """The UNCuyo authors' accelerometer calibration in this project's terms.

    Their ``reference_params_acc.csv`` holds ``m`` (3 misalignments), ``k`` (3
    scales, g per count) and ``b`` (3 biases, counts) of ``a = T K (raw + b)``,
    ``T = [[1, -m0, m1], [0, 1, -m2], [0, 0, 1]]``.  With the importer's nominal
    scale ``s = g0 / 16384`` (m/s^2 per count) the measured specific force is
    ``f_meas = s raw = A f - s b`` with ``A = s (T K)^-1``, so the model.md scale
    errors are ``diag(A) - 1`` and the biases ``-s b``.  Their misalignment
    convention differs from model.md's, so only scales and biases are returned.

    Parameters
    ----------
    params_path : str or pathlib.Path
        ``reference_params_acc.csv``.

    Returns
    -------
    dict
        ``{"accel.scale.x": ..., "accel.bias.x": ..., ...}``, SI.
    """
    p = read_numeric_table(params_path).ravel()
    if p.size != 9:
        raise InputError(f"{params_path}: expected 9 numbers (m, k, b), found {p.size}")
    m, k, b = p[:3], p[3:6], p[6:]
    s_nom = c.G0 / MPU6050_ACCEL_COUNTS_PER_G
    T = np.array([[1.0, -m[0], m[1]], [0.0, 1.0, -m[2]], [0.0, 0.0, 1.0]])
    A = s_nom * np.linalg.inv(T @ np.diag(k))
    out = {}
    for i, ax in enumerate("xyz"):
        out[f"accel.scale.{ax}"] = float(A[i, i] - 1.0)
        out[f"accel.bias.{ax}"] = float(-s_nom * b[i])
    return out


def _resolve_columns(columns, *, path, delimiter, header_lines):
    """Check a column mapping; return ({key: 0-based index}, [temperature keys], {key: channel name})."""
    if not isinstance(columns, dict) or not columns:
        raise InputError("columns must map names (t, gx, gy, gz, ax, ay, az, temp or temp:NAME) to columns",
                         dataset="columns")
    known = ("t",) + CSV_SENSOR_COLUMNS
    temp_keys, channel = [], {}
    for key in columns:
        if key == "temp" or key.startswith("temp:"):
            name = key.split(":", 1)[1] if ":" in key else "temp"
            if not name:
                raise InputError(f"empty channel name in {_show(key)}", dataset="columns")
            temp_keys.append(key)
            channel[key] = name
        elif key not in known:
            raise InputError(f"unknown column name {_show(key)}; known: {', '.join(known)}, temp, temp:NAME",
                             dataset="columns")
    missing = [k for k in CSV_SENSOR_COLUMNS if k not in columns]
    if missing:
        raise InputError(f"no column given for {', '.join(missing)}", dataset="columns")
    header = None
    index = {}
    for key, col in columns.items():
        if isinstance(col, str) and not col.isdigit():
            if header is None:
                if header_lines < 1:
                    raise InputError(f"column {key}={_show(col)} names a header column, but header_lines is 0",
                                     dataset="columns")
                with open(path, encoding="utf-8") as fh:
                    lines = [fh.readline() for _ in range(header_lines)]
                header = _split(lines[-1].strip(), delimiter)
            if col not in header:
                raise InputError(f"column {_show(col)} not in the header line {header_lines} ({', '.join(header)})",
                                 path=path, dataset="columns")
            index[key] = header.index(col)
        else:
            try:
                idx = int(col)
            except (TypeError, ValueError):
                raise InputError(f"column of {key} must be an index or a header name, got {_show(col)}",
                                 dataset="columns") from None
            if idx < 0 or isinstance(col, bool):
                raise InputError(f"column of {key} must be a 0-based index >= 0, got {_show(col)}", dataset="columns")
            index[key] = idx
    seen = {}
    for key, idx in index.items():
        if idx in seen:
            raise InputError(f"column {idx} given for both {seen[idx]} and {key}", dataset="columns")
        seen[idx] = key
    return index, temp_keys, channel


def import_csv(path, *, columns, latitude_rad, gravity_mps2, rate_hz=None, time_units="s",
               gyro_units="rad/s", accel_units="m/s^2", gyro_counts_per_unit=None, gyro_offset_counts=0.0,
               accel_counts_per_unit=None, accel_offset_counts=0.0, temperature_degC=None,
               temperature_map=None, delimiter=",", header_lines=0, imu_id="", description=None):
    """Import a delimited text log described by a column mapping and units.

    Parameters
    ----------
    path : str or Path
    columns : dict
        ``{key: column}`` with keys ``gx gy gz ax ay az`` (required), ``t``
        (optional) and ``temp`` or ``temp:NAME`` (one per temperature channel,
        degC, in the order given).  A column is a 0-based index, or a name from
        the last header line.  Further columns of the file are ignored.
    latitude_rad : float
        Bench latitude, rad.
    gravity_mps2 : float
        Local gravity magnitude, m/s^2.
    rate_hz : float or None
        Nominal sample rate, Hz.  Without a time column it is required and
        ``t[k] = k / rate_hz``; with one it defaults to ``1 / median(diff(t))``
        rounded to 6 significant digits.
    time_units : {'s', 'ms', 'us', 'ns'}
    gyro_units : {'rad/s', 'deg/s', 'rad', 'deg'}
        Rates (multiplied by the sample interval) or increments.
    accel_units : {'m/s^2', 'g', 'm/s'}
        Specific force (multiplied by the sample interval) or velocity
        increments; ``g`` is standard gravity ``9.80665`` m/s^2.
    gyro_counts_per_unit, accel_counts_per_unit : float or None
        For raw counts: nominal scale, counts per ``gyro_units`` (``accel_units``);
        the value is ``(raw - offset) / counts_per_unit``.  None: the column
        already holds the unit.
    gyro_offset_counts, accel_offset_counts : float
        Zero of the counts.
    temperature_degC : float or None
        Assumed constant temperature when no ``temp`` column is given (then required).
    temperature_map : sequence of 6 int or None
        Channel of gyro x, y, z and accel x, y, z (default all 0).
    delimiter : str or None
        Column separator; None for whitespace.
    header_lines : int
        Lines before the data; the last one may name the columns.
    imu_id : str
    description : str or None
        Default: what was converted and how.

    Returns
    -------
    Experiment

    Raises
    ------
    InputError
        Bad options (naming the option), or a malformed file (naming the line).
    """
    path = _require_file(path)
    if gyro_units not in GYRO_UNITS:
        raise InputError(f"unknown gyro units {_show(gyro_units)}; known: {', '.join(GYRO_UNITS)}", dataset="gyro_units")
    if accel_units not in ACCEL_UNITS:
        raise InputError(f"unknown accel units {_show(accel_units)}; known: {', '.join(ACCEL_UNITS)}",
                         dataset="accel_units")
    if time_units not in TIME_UNITS:
        raise InputError(f"unknown time units {_show(time_units)}; known: {', '.join(TIME_UNITS)}", dataset="time_units")
    if not isinstance(header_lines, int) or header_lines < 0:
        raise InputError(f"must be a non-negative integer, got {_show(header_lines)}", dataset="header_lines")
    index, temp_keys, channel = _resolve_columns(columns, path=path, delimiter=delimiter, header_lines=header_lines)
    data = read_numeric_table(path, delimiter=delimiter, skip_lines=header_lines)
    n, n_cols = data.shape
    too_far = {k: i for k, i in index.items() if i >= n_cols}
    if too_far:
        key, idx = next(iter(too_far.items()))
        raise InputError(f"column {idx} of {key} is beyond the {n_cols} columns of the file", path=path,
                         dataset="columns")

    if "t" in index:
        t = data[:, index["t"]] * TIME_UNITS[time_units]
        _check_time_column(t, path=path, skip_lines=header_lines)
        if rate_hz is None:
            if n < 2:
                raise InputError("one sample: give rate_hz", path=path, dataset="rate_hz")
            rate_hz = _nominal_rate(t)
        rate_hz = _positive(rate_hz, "rate_hz")
    else:
        if rate_hz is None:
            raise InputError("no time column: give the sample rate", dataset="rate_hz")
        rate_hz = _positive(rate_hz, "rate_hz")
        t = np.arange(n, dtype=np.float64) / rate_hz
    dt = _intervals(t, rate_hz)[:, None]

    def triad(keys, units_table, units, counts_per_unit, offset, label):
        raw = data[:, [index[k] for k in keys]]
        if counts_per_unit is not None:
            raw = (raw - float(offset)) / _positive(counts_per_unit, f"{label}_counts_per_unit")
        factor, is_rate = units_table[units]
        value = raw * factor
        return value * dt if is_rate else value

    dtheta = triad(("gx", "gy", "gz"), GYRO_UNITS, gyro_units, gyro_counts_per_unit, gyro_offset_counts, "gyro")
    dv = triad(("ax", "ay", "az"), ACCEL_UNITS, accel_units, accel_counts_per_unit, accel_offset_counts, "accel")

    if temp_keys:
        if temperature_degC is not None:
            raise InputError("temperature columns are given: an assumed temperature would be ignored",
                             dataset="temperature_degC")
        temperature = data[:, [index[k] for k in temp_keys]]
        names = tuple(channel[k] for k in temp_keys)
        temp_text = f"temperature channels {', '.join(names)} from the log"
    else:
        if temperature_degC is None:
            raise InputError("no temperature column: give one (temp=COLUMN) or an assumed constant temperature",
                             dataset="temperature_degC")
        temperature, names = _constant_temperature(n, temperature_degC)
        temp_text = (f"no temperature was recorded: channel '{ASSUMED_TEMPERATURE_NAME}' holds an assumed "
                     f"{float(temperature_degC):g} degC")
    if temperature_map is None:
        temperature_map = np.zeros(6, dtype=np.int64)
    else:
        tm = np.asarray(temperature_map)
        if tm.shape != (6,) or tm.dtype.kind not in "iu":
            raise InputError(f"must be six integer channel indices, got {_show(temperature_map)}",
                             dataset="temperature_map")
        temperature_map = tm

    if description is None:
        def units_text(units, counts, offset):
            return f"counts ({counts:g} per {units}, offset {float(offset):g})" if counts is not None else units
        description = (
            f"Imported from {path.name}: gyro in {units_text(gyro_units, gyro_counts_per_unit, gyro_offset_counts)}, "
            f"accel in {units_text(accel_units, accel_counts_per_unit, accel_offset_counts)}, "
            + (f"time column in {time_units}" if "t" in index else f"t = k / {rate_hz:g} Hz")
            + f"; {temp_text}."
        )
    return _build(t=t, dtheta=dtheta, dv=dv, temperature=temperature, names=names,
                  temperature_map=temperature_map, rate_hz=rate_hz, latitude_rad=latitude_rad,
                  gravity_mps2=gravity_mps2, imu_id=imu_id, description=description, source=path,
                  skip_lines=header_lines)
