r"""PX4 ULog files (:func:`import_ulog`): ``sensor_gyro`` and ``sensor_accel`` with their temperatures, via ``pyulog``.

PX4 logs each IMU's raw (uncalibrated, board-rotated) output per instance:
``sensor_gyro`` (``x``, ``y``, ``z`` in rad/s) and ``sensor_accel`` (m/s^2), each
with ``timestamp_sample`` (us) and the sensor's ``temperature`` (degC).  One
instance (``--instance``, default 0) is imported: the gyro's samples are the
record's samples, the accelerometer is interpolated linearly to their stamps, and
the two temperatures become two channels (``gyro``, ``accel``; the
``temperature_map`` sends each triad to its own).  Without ``sensor_gyro`` and
``sensor_accel`` the log's ``sensor_combined`` is read (rates and forces after PX4's
own calibration and filtering, no temperature: an assumed one is then required).
Rates are read as averaged over the sample interval unless ``rates="instantaneous"``
(:mod:`graph_calib.importers.rosbag` explains the two); jitter and missing samples are
handled as for bags (:func:`graph_calib.importers.timing.message_times`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError
from graph_calib.importers.common import (
    ASSUMED_TEMPERATURE_NAME,
    build_experiment,
    constant_temperature,
    intervals,
    normal_gravity,
    positive,
    require_file,
)
from graph_calib.importers.registry import ImportFormat, Option
from graph_calib.importers.timing import RATE_MEANINGS, increments, message_times

_TOPICS = ("sensor_gyro", "sensor_accel", "sensor_combined")


def _load(path):
    from pyulog import ULog

    try:
        return ULog(str(path), message_name_filter_list=list(_TOPICS))
    except Exception as exc:  # pyulog's own errors for a file that is not a ULog
        raise InputError(f"cannot be read as a PX4 ULog ({type(exc).__name__}: {exc})", path=path) from None


def _instances(ulog, name):
    return {d.multi_id: d for d in ulog.data_list if d.name == name}


def _stamps(d):
    return np.asarray(d.data.get("timestamp_sample", d.data["timestamp"]), dtype=np.int64)


def _xyz(d, prefix=""):
    if prefix:
        return np.column_stack([d.data[f"{prefix}[{i}]"] for i in range(3)]).astype(float)
    return np.column_stack([d.data[a] for a in "xyz"]).astype(float)


def _read_pair(ulog, instance, path):
    gyros, accels = _instances(ulog, "sensor_gyro"), _instances(ulog, "sensor_accel")
    if not gyros or not accels:
        return None
    for what, found in (("sensor_gyro", gyros), ("sensor_accel", accels)):
        if instance not in found:
            listed = ", ".join(f"{k} (device_id {int(d.data['device_id'][0]) if 'device_id' in d.data else '?'})"
                               for k, d in sorted(found.items()))
            raise InputError(f"no {what} instance {instance}; the log has instance(s) {listed}", path=path,
                             dataset="--instance")
    g, a = gyros[instance], accels[instance]
    tg, ta = _stamps(g), _stamps(a)
    order_g, order_a = np.argsort(tg, kind="stable"), np.argsort(ta, kind="stable")
    tg, ta = tg[order_g], ta[order_a]
    omega, temp_g = _xyz(g)[order_g], np.asarray(g.data["temperature"], float)[order_g]
    f_a, temp_a = _xyz(a)[order_a], np.asarray(a.data["temperature"], float)[order_a]
    f = np.column_stack([np.interp(tg, ta, f_a[:, i]) for i in range(3)])
    temp = np.column_stack([temp_g, np.interp(tg, ta, temp_a)])
    text = (f"sensor_gyro and sensor_accel instance {instance} ({tg.size} and {ta.size} samples; the accelerometer "
            "interpolated to the gyro's stamps)")
    return tg, omega, f, temp, ("gyro", "accel"), text


def _read_combined(ulog, path):
    found = _instances(ulog, "sensor_combined")
    if not found:
        raise InputError("no sensor_gyro/sensor_accel pair and no sensor_combined: nothing to import (log the "
                         "sensor topics, e.g. SDLOG_PROFILE with 'sensor comparison' or 'high rate')", path=path)
    d = found[min(found)]
    t = np.asarray(d.data["timestamp"], dtype=np.int64)
    return (t, _xyz(d, "gyro_rad"), _xyz(d, "accelerometer_m_s2"), None, None,
            f"sensor_combined ({t.size} samples; PX4's calibrated and filtered output, no temperature)")


def import_ulog(path, *, latitude_rad, instance=0, gravity_mps2=None, temperature_degC=None, rates="averaged",
                rate_hz=None, imu_id="", description=None):
    """Import one IMU instance of a PX4 ULog (module docstring).

    Parameters
    ----------
    path : str or Path
    latitude_rad : float
    instance : int
        Multi-instance number of ``sensor_gyro``/``sensor_accel``.
    gravity_mps2 : float or None
        None: WGS-84 normal gravity at the latitude.
    temperature_degC : float or None
        Assumed temperature, for ``sensor_combined`` (which has none).
    rates : {"averaged", "instantaneous"}
    rate_hz : float or None
    imu_id, description : str

    Returns
    -------
    Experiment
    """
    path = require_file(path)
    if rates not in RATE_MEANINGS:
        raise InputError(f"must be one of {', '.join(RATE_MEANINGS)}, got {rates!r}", dataset="rates")
    ulog = _load(path)
    got = _read_pair(ulog, instance, path) or _read_combined(ulog, path)
    stamps_us, omega, f, temp, names, text = got
    if stamps_us.size < 2:
        raise InputError(f"{stamps_us.size} sample(s); a record needs more", path=path)
    same = np.flatnonzero(np.diff(stamps_us) == 0)
    if same.size:
        raise InputError(f"samples {int(same[0])} and {int(same[0]) + 1} have the same stamp "
                         f"{stamps_us[same[0]]} us", path=path)
    t = (stamps_us - stamps_us[0]) * 1e-6
    t, rate_hz, segment, timing = message_times(t, None if rate_hz is None else positive(rate_hz, "rate_hz"),
                                                source=path.name)
    dt = intervals(t, rate_hz, segment)
    if temp is None:
        if temperature_degC is None:
            raise InputError("sensor_combined holds no temperature: give an assumed constant temperature "
                             "(--temperature DEGC)", path=path, dataset="--temperature")
        temp, names = constant_temperature(t.shape[0], temperature_degC)
        temp_text = f"channel '{ASSUMED_TEMPERATURE_NAME}' holds an assumed {float(temperature_degC):g} degC"
        temperature_map = np.zeros(6)
    else:
        if temperature_degC is not None:
            raise InputError("the log records the sensors' temperatures: an assumed temperature would be ignored",
                             dataset="--temperature")
        temp_text = "temperatures of the gyro and the accelerometer as channels gyro and accel"
        temperature_map = np.array([0, 0, 0, 1, 1, 1])
    if gravity_mps2 is None:
        gravity_mps2 = normal_gravity(latitude_rad)
        temp_text += (f"; gravity {gravity_mps2:.5f} m/s^2 is WGS-84 normal gravity at latitude "
                      f"{math.degrees(latitude_rad):.4f} deg, at sea level")
    if description is None:
        description = (f"Imported from the PX4 ULog {path.name}: {text}, rates read as {rates} over the sample "
                       f"interval; {temp_text}" + (f"; {timing}" if timing else "") + ".")
    return build_experiment(t=t, dtheta=increments(omega, dt, segment, rates), dv=increments(f, dt, segment, rates),
                            temperature=temp, names=names, temperature_map=temperature_map, rate_hz=rate_hz,
                            latitude_rad=latitude_rad, gravity_mps2=gravity_mps2, imu_id=imu_id,
                            description=description, source=path, skip_lines=None, segment=segment)


def _read(inputs, options):
    """``graph-calib import ulog FILE.ulg``: :func:`import_ulog` with the options given."""
    if options.get("latitude_rad") is None:
        raise InputError("required for format ulog: the bench latitude in degrees (the Earth rate needs it)",
                         dataset="--latitude-deg")
    keys = ("latitude_rad", "instance", "gravity_mps2", "temperature_degC", "rates", "rate_hz", "imu_id",
            "description")
    return import_ulog(Path(inputs[0]), **{k: options[k] for k in keys if k in options})


FORMAT = ImportFormat(
    name="ulog", inputs=("FILE.ulg",),
    summary="a PX4 ULog: sensor_gyro and sensor_accel of one instance with their temperatures (or sensor_combined)",
    example="graph-calib import ulog flight.ulg --latitude-deg 47.4 --out px4.h5",
    read=_read,
    notes=lambda experiment, options: [p.strip() for p in experiment.description.rstrip(".").split("; ")
                                       if "jitter" in p or "missing" in p or "rates read" in p],
    options=(
        Option("--instance", "the IMU instance of sensor_gyro/sensor_accel (default 0)",
               {"type": int, "metavar": "N"}),
        Option("--rates", "a message's rate is the mean over the interval its stamp closes (averaged, the default) "
               "or a sample at the stamp (instantaneous: trapezoid increments)", {"choices": RATE_MEANINGS}),
        Option("--rate-hz", "nominal sample rate, Hz (default: 1 / median spacing of the stamps)",
               {"type": float, "metavar": "HZ"}),
    ),
)


__all__ = ["FORMAT", "import_ulog"]
