r"""Converters from bench and third-party logs into :class:`~graph_calib.records.experiment.Experiment`.

Each importer reads raw sensor output (counts, rates or increments, in the
units the log uses), converts it to SI with *nominal* (datasheet) scales — the
calibration estimates the actual ones — and returns a validated experiment,
ready for :func:`graph_calib.io.write_experiment`:

* :func:`import_xsens` — the Xsens MTi sample data of IMU-TK (two text files of
  raw ADC counts);
* :func:`import_mpu6050` — the MPU-6050 logs of UNCuyo's ImuCalibration (CSV of
  int16 counts with a small header);
* :func:`import_csv` — any delimited text log, described by a column mapping and
  units (only the mapped columns are read; a ``segment`` column gives
  ``/imu/segment``; gravity defaults to :func:`normal_gravity` at the latitude).

A sample holding a rate (``omega``, ``f``) becomes an increment over the
interval it closes, ``dtheta[k] = omega[k] * (t[k] - t[k-1])`` with
``t[0] - t[-1] := 1 / rate_hz`` (``data-format.md``).  Logs without temperature
get one channel ``"assumed_constant"`` holding the assumed temperature, and the
description says so.  Defaults and their provenance are in
``docs/data-format.md``.

Modules
-------
:mod:`~graph_calib.importers.registry`
    The formats by name: each format module defines ``FORMAT`` (its inputs, its
    own options, an example, its ``read``); ``graph-calib import`` is built from it.
:mod:`~graph_calib.importers.common`
    The parsing helpers every importer shares, public: reading delimited text
    (:func:`read_numeric_table`), the checks of counts, time columns and options
    naming the file and the line, rates to increments, the assumed temperature
    channel, WGS-84 normal gravity (:func:`normal_gravity`), assembling and
    validating the experiment (``build_experiment``).
:mod:`~graph_calib.importers.timing`
    Groups restarting their clock, jittered stamps (shared by the importers).
:mod:`~graph_calib.importers.xsens`
    :func:`import_xsens` and the nominal constants of the IMU-TK data.
:mod:`~graph_calib.importers.mpu6050`
    :func:`import_mpu6050`, :func:`mpu6050_reference_calibration` and the
    nominal constants of the UNCuyo data.
:mod:`~graph_calib.importers.csv`
    :func:`import_csv` and its units; a header naming its columns in a common way is
    read without ``--columns`` (:mod:`~graph_calib.importers.csv_header`).
:mod:`~graph_calib.importers.rosbag`
    :func:`import_rosbag`: ``sensor_msgs/Imu`` (and ``sensor_msgs/Temperature``) of a
    ROS 2 bag (sqlite3 or MCAP) or a ROS 1 bag, with the ``rosbags`` library.
:mod:`~graph_calib.importers.ulog`
    :func:`import_ulog`: a PX4 ULog's ``sensor_gyro``/``sensor_accel`` (or
    ``sensor_combined``) with their temperatures, with ``pyulog``.

Errors in the input (missing file, wrong column count, non-numeric cell,
rows out of time order, mismatched time stamps, values that cannot be raw
counts) raise :class:`~graph_calib.errors.InputError` naming the file and the
line, and the column where one is at fault, counted from 0 as ``--columns``
counts.
"""

from graph_calib.importers.common import ASSUMED_TEMPERATURE_NAME, normal_gravity, read_numeric_table
from graph_calib.importers.csv import (
    ACCEL_UNITS,
    CSV_SENSOR_COLUMNS,
    GYRO_UNITS,
    TIME_UNITS,
    import_csv,
)
from graph_calib.importers.mpu6050 import (
    MPU6050_ACCEL_COUNTS_PER_G,
    MPU6050_COLUMNS,
    MPU6050_GRAVITY_MPS2,
    MPU6050_GYRO_COUNTS_PER_DPS,
    MPU6050_LATITUDE_RAD,
    MPU6050_NOTICE,
    import_mpu6050,
    mpu6050_reference_calibration,
)
from graph_calib.importers.rosbag import import_rosbag
from graph_calib.importers.ulog import import_ulog
from graph_calib.importers.xsens import (
    XSENS_ACCEL_COUNTS_PER_MPS2,
    XSENS_GRAVITY_MPS2,
    XSENS_GYRO_COUNTS_PER_RADS,
    XSENS_LATITUDE_RAD,
    XSENS_NOTICE,
    XSENS_OFFSET_COUNTS,
    XSENS_RATE_HZ,
    import_xsens,
)

__all__ = [
    "import_xsens", "import_mpu6050", "import_csv", "import_rosbag", "import_ulog", "mpu6050_reference_calibration", "read_numeric_table",
    "normal_gravity",
    "ASSUMED_TEMPERATURE_NAME", "GYRO_UNITS", "ACCEL_UNITS", "TIME_UNITS", "CSV_SENSOR_COLUMNS",
    "XSENS_LATITUDE_RAD", "XSENS_GRAVITY_MPS2", "XSENS_ACCEL_COUNTS_PER_MPS2", "XSENS_GYRO_COUNTS_PER_RADS",
    "XSENS_OFFSET_COUNTS", "XSENS_RATE_HZ", "XSENS_NOTICE", "MPU6050_LATITUDE_RAD", "MPU6050_GRAVITY_MPS2",
    "MPU6050_ACCEL_COUNTS_PER_G", "MPU6050_GYRO_COUNTS_PER_DPS", "MPU6050_COLUMNS", "MPU6050_NOTICE",
]
