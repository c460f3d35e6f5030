r"""The Xsens MTi sample data of IMU-TK: two text files of raw ADC counts (:func:`import_xsens`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError
from graph_calib.importers.registry import ImportFormat, Option
from graph_calib.importers.common import (
    ASSUMED_TEMPERATURE_NAME,
    build_experiment,
    check_counts,
    check_time_column,
    constant_temperature,
    data_line_numbers,
    intervals,
    positive,
    read_numeric_table,
    show,
)

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
    sa = positive(accel_scale_counts_per_mps2, "accel_scale_counts_per_mps2")
    sg = positive(gyro_scale_counts_per_rads, "gyro_scale_counts_per_rads")
    rate_hz = positive(rate_hz, "rate_hz")
    names = dict(enumerate(("t", "x", "y", "z")))
    acc = read_numeric_table(acc_path, n_columns=4, column_names=names)
    gyro = read_numeric_table(gyro_path, n_columns=4, column_names=names)
    if acc.shape[0] != gyro.shape[0]:
        raise InputError(f"{gyro.shape[0]} data lines, but {acc_path} has {acc.shape[0]}; "
                         "the two files must hold the same time stamps", path=gyro_path)
    differ = acc[:, 0] != gyro[:, 0]
    if differ.any():
        row = int(np.flatnonzero(differ)[0])
        line = data_line_numbers(gyro_path, 0)[row]
        raise InputError(f"time stamp {show(gyro[row, 0])} s differs from {show(acc[row, 0])} s in {acc_path}; "
                         "the two files must hold the same time stamps", path=gyro_path, dataset=f"line {line}")
    t = acc[:, 0]
    check_time_column(t, path=acc_path, skip_lines=0)
    sat_a = check_counts(acc[:, 1:], path=acc_path, skip_lines=0, lo=0, hi=65535, what="16-bit unsigned")
    sat_g = check_counts(gyro[:, 1:], path=gyro_path, skip_lines=0, lo=0, hi=65535, what="16-bit unsigned")
    temperature, names = constant_temperature(t.shape[0], temperature_degC)
    dt = intervals(t, rate_hz)[:, None]
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
    return build_experiment(t=t, dtheta=omega_b * dt, dv=f_b * dt, temperature=temperature, names=names,
                  temperature_map=np.zeros(6), rate_hz=rate_hz, latitude_rad=latitude_rad,
                  gravity_mps2=gravity_mps2, imu_id=imu_id, description=description, source=acc_path,
                  skip_lines=0)


def _read(inputs, options):
    """``graph-calib import xsens ACC_FILE GYRO_FILE``: :func:`import_xsens` with the options given."""
    keys = {"latitude_rad": "latitude_rad", "gravity_mps2": "gravity_mps2", "temperature_degC": "temperature_degC",
            "accel_scale": "accel_scale_counts_per_mps2", "gyro_scale": "gyro_scale_counts_per_rads",
            "offset": "offset_counts", "rate_hz": "rate_hz", "imu_id": "imu_id", "description": "description"}
    return import_xsens(inputs[0], inputs[1], **{k: options[o] for o, k in keys.items() if o in options})


FORMAT = ImportFormat(
    name="xsens", inputs=("ACC_FILE", "GYRO_FILE"),
    summary="the Xsens MTi sample data of IMU-TK (two text files of raw counts)",
    example="graph-calib import xsens xsens_acc.mat xsens_gyro.mat --out xsens.h5",
    read=_read,
    options=(
        Option("--accel-scale", "nominal accelerometer scale, counts per m/s^2 (415)",
               {"type": float, "metavar": "COUNTS"}),
        Option("--gyro-scale", "nominal gyro scale, counts per rad/s (4770)", {"type": float, "metavar": "COUNTS"}),
        Option("--offset", "zero of both triads, counts (32768)", {"type": float, "metavar": "COUNTS"}),
        Option("--rate-hz", "nominal sample rate, Hz (100)", {"type": float, "metavar": "HZ"}),
    ),
)

__all__ = [
    "FORMAT", "import_xsens", "XSENS_LATITUDE_RAD", "XSENS_GRAVITY_MPS2", "XSENS_ACCEL_COUNTS_PER_MPS2",
    "XSENS_GYRO_COUNTS_PER_RADS", "XSENS_OFFSET_COUNTS", "XSENS_RATE_HZ", "XSENS_NOTICE",
]
