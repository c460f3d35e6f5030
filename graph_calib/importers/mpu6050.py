r"""The MPU-6050 logs of UNCuyo's ImuCalibration (:func:`import_mpu6050`) and the authors' calibration.

:func:`mpu6050_reference_calibration` turns the authors' accelerometer
calibration into this project's scale and bias terms, for comparison.
"""

from __future__ import annotations

import math

import numpy as np

from graph_calib import constants as c
from graph_calib.errors import InputError
from graph_calib.importers.registry import ImportFormat, Option
from graph_calib.records.saturation import cut_at_saturation
from graph_calib.importers.common import (
    ASSUMED_TEMPERATURE_NAME,
    build_experiment,
    check_counts,
    constant_temperature,
    positive,
    read_numeric_table,
    require_file,
    show,
    split_cells,
)

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


def _read_mpu6050_header(path):
    """The four ``key,value`` header lines and the column line; returns (fs_hz, header dict)."""
    with open(path, encoding="utf-8-sig") as fh:
        lines = [fh.readline() for _ in range(5)]
    header = {}
    for no, line in enumerate(lines[:4], start=1):
        cells = split_cells(line.strip(), ",")
        if len(cells) != 2 or not cells[0]:
            raise InputError(f"expected a 'key,value' header line, got {show(line.strip())}", path=path,
                             dataset=f"line {no}")
        header[cells[0]] = cells[1]
    key, value = next(iter(header.items()))
    try:
        fs = float(value)
    except ValueError:
        fs = float("nan")
    if key != "Fs" or not (math.isfinite(fs) and fs > 0):
        raise InputError(f"expected 'Fs,<sample rate in Hz>', got {show(lines[0].strip())}", path=path,
                         dataset="line 1")
    cols = tuple(split_cells(lines[4].strip().lower(), ","))
    if cols != MPU6050_COLUMNS:
        raise InputError(f"expected the column line {show(','.join(MPU6050_COLUMNS))}, got {show(lines[4].strip())}",
                         path=path, dataset="line 5")
    return fs, header


def import_mpu6050(csv_path, *, latitude_rad=MPU6050_LATITUDE_RAD, gravity_mps2=MPU6050_GRAVITY_MPS2,
                   temperature_degC=20.0, accel_counts_per_g=MPU6050_ACCEL_COUNTS_PER_G,
                   gyro_counts_per_dps=MPU6050_GYRO_COUNTS_PER_DPS,
                   imu_id="InvenSense MPU-6050 (UNCuyo ImuCalibration sample data)", description=None,
                   cut_saturated=True):
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
    cut_saturated : bool
        Cut the record after each run of samples at which a gyro count sits at the int16 limits
        (:func:`graph_calib.records.saturation.cut_at_saturation`; the sentence it adds to the description
        says where). False: keep the record whole, the angle the saturated turns lost included.

    Returns
    -------
    Experiment
        No table, one temperature channel; segments where the gyros saturated (``cut_saturated``).

    Raises
    ------
    InputError
        Missing file, a malformed header (with line), a wrong column count, a
        non-numeric cell, a value that is not an int16 count.
    """
    path = require_file(csv_path)
    sa = positive(accel_counts_per_g, "accel_counts_per_g")
    sg = positive(gyro_counts_per_dps, "gyro_counts_per_dps")
    try:
        fs, header = _read_mpu6050_header(path)
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path=path) from None
    data = read_numeric_table(path, delimiter=",", skip_lines=5, n_columns=6,
                              column_names=dict(enumerate(MPU6050_COLUMNS)))
    n_sat = check_counts(data, path=path, skip_lines=5, lo=-32768, hi=32767, what="int16")
    n = data.shape[0]
    t = np.arange(n, dtype=np.float64) / fs
    f_b = data[:, :3] / sa * c.G0
    omega_b = data[:, 3:] / sg * c.DEG_TO_RAD
    temperature, names = constant_temperature(n, temperature_degC)
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
    exp = build_experiment(t=t, dtheta=omega_b * dt, dv=f_b * dt, temperature=temperature, names=names,
                           temperature_map=np.zeros(6), rate_hz=fs, latitude_rad=latitude_rad,
                           gravity_mps2=gravity_mps2, imu_id=imu_id, description=description, source=path,
                           skip_lines=5)
    if not cut_saturated:
        return exp
    gyro = data[:, 3:]
    return cut_at_saturation(exp, np.any((gyro <= -32768) | (gyro >= 32767), axis=1)).experiment


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


def _read(inputs, options):
    """``graph-calib import mpu6050 CSV_FILE``: :func:`import_mpu6050` with the options given."""
    keys = {"latitude_rad": "latitude_rad", "gravity_mps2": "gravity_mps2", "temperature_degC": "temperature_degC",
            "accel_scale": "accel_counts_per_g", "gyro_scale": "gyro_counts_per_dps", "imu_id": "imu_id",
            "description": "description"}
    return import_mpu6050(inputs[0], **{k: options[o] for o, k in keys.items() if o in options},
                          cut_saturated=not options.get("keep_saturated", False))


FORMAT = ImportFormat(
    name="mpu6050", inputs=("CSV_FILE",),
    summary="an MPU-6050 log of UNCuyo's ImuCalibration (CSV of int16 counts)",
    example="graph-calib import mpu6050 mpu6050_static.csv --out mpu.h5",
    read=_read,
    options=(
        Option("--accel-scale", "nominal accelerometer scale, counts per g (16384)", {"type": float, "metavar": "COUNTS"}),
        Option("--gyro-scale", "nominal gyro scale, counts per deg/s (131)", {"type": float, "metavar": "COUNTS"}),
        Option("--keep-saturated", "do not cut the record after the runs of samples at which a gyro count sits at "
               "the int16 limits (by default each is followed by a segment boundary, so that no rotation factor "
               "spans the angle the saturated turn lost)", {"action": "store_true"}),
    ),
)

__all__ = [
    "FORMAT",
    "import_mpu6050", "mpu6050_reference_calibration", "MPU6050_LATITUDE_RAD", "MPU6050_GRAVITY_MPS2",
    "MPU6050_ACCEL_COUNTS_PER_G", "MPU6050_GYRO_COUNTS_PER_DPS", "MPU6050_COLUMNS", "MPU6050_NOTICE",
]
