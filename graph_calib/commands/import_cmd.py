"""``graph-calib import FORMAT INPUT... --out FILE.h5``: convert a log into an experiment file.

Formats: ``xsens`` (two inputs: the accelerometer file, then the gyro file, of
IMU-TK's sample data), ``mpu6050`` (one CSV of UNCuyo's ImuCalibration), ``csv``
(any delimited log, described by ``--columns`` and the units options).
Latitude is given in degrees here, at the edge, and stored in radians.  For a
csv log the latitude is required; without ``--gravity`` the gravity is the
WGS-84 normal gravity at that latitude at sea level, and a note says so.
Columns are counted from 0, in ``--columns`` and in every message.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from graph_calib import constants as c
from graph_calib import importers
from graph_calib.errors import InputError
from graph_calib.io import write_experiment

FORMATS = ("xsens", "mpu6050", "csv")
_N_INPUTS = {"xsens": 2, "mpu6050": 1, "csv": 1}
_INPUT_NAMES = {"xsens": "ACC_FILE GYRO_FILE", "mpu6050": "CSV_FILE", "csv": "CSV_FILE"}
# options that only some formats take (the rest are common)
_FORMAT_OPTIONS = {
    "offset": ("xsens",),
    "accel_offset": ("csv",), "gyro_offset": ("csv",),
    "rate_hz": ("xsens", "csv"),
    "columns": ("csv",), "gyro_units": ("csv",), "accel_units": ("csv",), "time_units": ("csv",),
    "delimiter": ("csv",), "header_lines": ("csv",), "temperature_map": ("csv",),
}
_DELIMITERS = {"comma": ",", "semicolon": ";", "tab": "\t", "space": " ", "whitespace": None}


def add_arguments(parser):
    """Options of ``graph-calib import``."""
    parser.add_argument("format", choices=FORMATS, metavar="FORMAT", help=f"one of {', '.join(FORMATS)}")
    parser.add_argument("inputs", nargs="+", metavar="INPUT",
                        help="xsens: ACC_FILE GYRO_FILE; mpu6050 and csv: one CSV file")
    parser.add_argument("--out", required=True, metavar="FILE.h5", help="experiment file to write (atomically)")
    site = parser.add_argument_group("bench")
    site.add_argument("--latitude-deg", type=float, metavar="DEG",
                      help="bench latitude, degrees (default: xsens Padova 45.41, mpu6050 Mendoza -32.89; "
                           "required for csv: the Earth rate needs it)")
    site.add_argument("--gravity", type=float, metavar="MPS2",
                      help="local gravity, m/s^2 (default: xsens 9.81744, mpu6050 9.7933; csv: WGS-84 normal "
                           "gravity at --latitude-deg, at sea level)")
    site.add_argument("--temperature", type=float, metavar="DEGC",
                      help="assumed constant temperature, degC, for logs without one (default 20 for xsens "
                           "and mpu6050)")
    site.add_argument("--imu-id", help="IMU model and serial number")
    site.add_argument("--description", help="free text (default: provenance and conversion)")
    conv = parser.add_argument_group("conversion")
    conv.add_argument("--accel-scale", type=float, metavar="COUNTS",
                      help="nominal accelerometer scale, counts per unit: xsens per m/s^2 (415), mpu6050 per g "
                           "(16384), csv per --accel-units (default: the column is not counts)")
    conv.add_argument("--gyro-scale", type=float, metavar="COUNTS",
                      help="nominal gyro scale, counts per unit: xsens per rad/s (4770), mpu6050 per deg/s (131), "
                           "csv per --gyro-units (default: the column is not counts)")
    conv.add_argument("--offset", type=float, metavar="COUNTS", help="xsens: zero of both triads, counts (32768)")
    conv.add_argument("--accel-offset", type=float, metavar="COUNTS", help="csv: zero of the accelerometer counts (0)")
    conv.add_argument("--gyro-offset", type=float, metavar="COUNTS", help="csv: zero of the gyro counts (0)")
    conv.add_argument("--rate-hz", type=float, metavar="HZ",
                      help="nominal sample rate (xsens: 100; csv: required without a time column, else "
                           "1 / median spacing)")
    csv = parser.add_argument_group("csv layout")
    csv.add_argument("--columns", metavar="MAP",
                     help="e.g. t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6,temp=7: column indices counted from 0 (as in "
                          "every message) or header names; several temperatures as temp:NAME=COL; segment=COL "
                          "for a column of integer segment numbers (pieces of a record cut together, "
                          "non-decreasing). Columns not mapped are ignored, whatever they hold")
    csv.add_argument("--gyro-units", choices=tuple(importers.GYRO_UNITS),
                     help="rad/s, deg/s (rates) or rad, deg (increments); default rad/s")
    csv.add_argument("--accel-units", choices=tuple(importers.ACCEL_UNITS),
                     help="m/s^2, g (specific force) or m/s (increments); default m/s^2")
    csv.add_argument("--time-units", choices=tuple(importers.TIME_UNITS),
                     help="units of the time column; default s. samples: a sample index, t = index / --rate-hz "
                          "(then required)")
    csv.add_argument("--delimiter", metavar="SEP",
                     help=f"column separator: a character or one of {', '.join(_DELIMITERS)}; default comma")
    csv.add_argument("--header-lines", type=int, metavar="N", help="lines before the data; default 0")
    csv.add_argument("--temperature-map", metavar="I,I,I,I,I,I",
                     help="temperature channel of gyro x, y, z and accel x, y, z; default 0,0,0,0,0,0")


def parse_columns(text):
    """``"t=0,gx=1,temp:case=7,ax=Acc X"`` -> ``{"t": 0, "gx": 1, "temp:case": 7, "ax": "Acc X"}``."""
    out = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise InputError(f"expected KEY=COLUMN items separated by commas, got {item.strip()!r}",
                             dataset="--columns")
        if key in out:
            raise InputError(f"{key} given twice", dataset="--columns")
        # an index is ASCII digits: "²" and "--5" pass str.isdigit but not int() (a header name then)
        out[key] = int(value) if re.fullmatch(r"-?[0-9]+", value) else value
    return out


def _parse_map(text):
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 6:
        raise InputError(f"expected six comma-separated integers, got {text!r}", dataset="--temperature-map")
    return np.asarray(values, dtype=np.int64)


def _latitude(args, default):
    if args.latitude_deg is None:
        return default
    if not math.isfinite(args.latitude_deg) or abs(args.latitude_deg) > 90.0:
        raise InputError(f"latitude must be within [-90, 90] degrees, got {args.latitude_deg!r}",
                         dataset="--latitude-deg")
    return args.latitude_deg * c.DEG_TO_RAD


def _given(args, name, default):
    value = getattr(args, name)
    return default if value is None else value


def _import(args):
    fmt = args.format
    for name, formats in _FORMAT_OPTIONS.items():
        if getattr(args, name) is not None and fmt not in formats:
            option = "--" + name.replace("_", "-")
            raise InputError(f"does not apply to format {fmt} (only {', '.join(formats)})", dataset=option)
    if len(args.inputs) != _N_INPUTS[fmt]:
        raise InputError(f"format {fmt} takes {_INPUT_NAMES[fmt]}, got {len(args.inputs)} input(s)",
                         dataset="INPUT")
    inputs = [Path(p) for p in args.inputs]
    common = {}
    if args.imu_id is not None:
        common["imu_id"] = args.imu_id
    if args.description is not None:
        common["description"] = args.description
    if fmt == "xsens":
        return importers.import_xsens(
            inputs[0], inputs[1], latitude_rad=_latitude(args, importers.XSENS_LATITUDE_RAD),
            gravity_mps2=_given(args, "gravity", importers.XSENS_GRAVITY_MPS2),
            temperature_degC=_given(args, "temperature", 20.0),
            accel_scale_counts_per_mps2=_given(args, "accel_scale", importers.XSENS_ACCEL_COUNTS_PER_MPS2),
            gyro_scale_counts_per_rads=_given(args, "gyro_scale", importers.XSENS_GYRO_COUNTS_PER_RADS),
            offset_counts=_given(args, "offset", importers.XSENS_OFFSET_COUNTS),
            rate_hz=_given(args, "rate_hz", importers.XSENS_RATE_HZ), **common)
    if fmt == "mpu6050":
        return importers.import_mpu6050(
            inputs[0], latitude_rad=_latitude(args, importers.MPU6050_LATITUDE_RAD),
            gravity_mps2=_given(args, "gravity", importers.MPU6050_GRAVITY_MPS2),
            temperature_degC=_given(args, "temperature", 20.0),
            accel_counts_per_g=_given(args, "accel_scale", importers.MPU6050_ACCEL_COUNTS_PER_G),
            gyro_counts_per_dps=_given(args, "gyro_scale", importers.MPU6050_GYRO_COUNTS_PER_DPS), **common)
    # csv
    if args.columns is None:
        raise InputError("required for format csv (e.g. t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6,temp=7)",
                         dataset="--columns")
    if args.latitude_deg is None:
        raise InputError("required for format csv: the bench latitude in degrees (the Earth rate needs it; "
                         "without --gravity, gravity is the normal gravity at that latitude)",
                         dataset="--latitude-deg")
    delimiter = _given(args, "delimiter", ",")
    delimiter = _DELIMITERS.get(delimiter, delimiter)
    if delimiter == " ":
        delimiter = None
    return importers.import_csv(
        inputs[0], columns=parse_columns(args.columns), latitude_rad=_latitude(args, None),
        gravity_mps2=args.gravity, rate_hz=args.rate_hz, time_units=args.time_units,
        gyro_units=_given(args, "gyro_units", "rad/s"), accel_units=_given(args, "accel_units", "m/s^2"),
        gyro_counts_per_unit=args.gyro_scale, gyro_offset_counts=_given(args, "gyro_offset", 0.0),
        accel_counts_per_unit=args.accel_scale, accel_offset_counts=_given(args, "accel_offset", 0.0),
        temperature_degC=args.temperature,
        temperature_map=None if args.temperature_map is None else _parse_map(args.temperature_map),
        delimiter=delimiter, header_lines=_given(args, "header_lines", 0), **common)


def summary(experiment):
    """Short human summary lines of an imported experiment."""
    e = experiment
    dt = e.dt
    f = np.linalg.norm(e.dv, axis=1) / dt
    w = np.linalg.norm(e.dtheta, axis=1) / dt
    temp = e.temperature
    segments = f" in {e.n_segments} segments" if e.n_segments > 1 else ""
    return [
        f"{e.n_samples} samples{segments}, {e.t[-1] - e.t[0] + 1.0 / e.rate_hz:.2f} s at {e.rate_hz:g} Hz",
        f"mean |f| = {f.mean():.4f} m/s^2 ({f.mean() / e.gravity_mps2:.4f} x local gravity {e.gravity_mps2:g}), "
        f"largest |omega| = {w.max() * c.RAD_TO_DEG:.1f} deg/s",
        f"temperature: {temp.shape[1]} channel(s) ({', '.join(e.temperature_names)}), "
        f"{temp.min():.2f} to {temp.max():.2f} degC",
        f"latitude {e.latitude_rad * c.RAD_TO_DEG:.4f} deg, no turntable reference",
    ]


def run(args):
    """Import, write, print a summary; InputError on bad input (exit 2)."""
    experiment = _import(args)
    out = Path(args.out)
    write_experiment(experiment, out)
    print(f"graph-calib import {args.format}: " + ", ".join(str(p) for p in args.inputs))
    for line in summary(experiment):
        print("  " + line)
    if args.format == "csv" and args.gravity is None:
        print(f"note: gravity {experiment.gravity_mps2:.5f} m/s^2 is WGS-84 normal gravity (Somigliana) at "
              f"{args.latitude_deg:g} deg latitude, at sea level; give --gravity for the local value (it falls "
              "by about 3.1e-6 m/s^2 per metre of altitude)")
    print(f"wrote {out}")
    return 0
