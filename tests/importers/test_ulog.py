"""``graph-calib import ulog``: PX4 ULog files written by the test writer (shown faithful here) read back."""

from __future__ import annotations

import io as _io
import re

import numpy as np
import pytest

from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.importers.ulog import import_ulog

pyulog = pytest.importorskip("pyulog")
from ulog_writer import SENSOR_ACCEL, SENSOR_COMBINED, SENSOR_GYRO, write_ulog  # noqa: E402

N, RATE = 400, 250.0
KW = {"latitude_rad": 0.83, "gravity_mps2": 9.81}


def _signals(seed=0):
    rng = np.random.default_rng(seed)
    stamps = 5_000_000 + np.round(np.arange(N) * 1e6 / RATE).astype(np.int64)
    omega = (rng.normal(0.0, 0.3, (N, 3))).astype(np.float32)
    f = (np.array([0.1, -0.2, -9.8]) + rng.normal(0.0, 0.05, (N, 3))).astype(np.float32)
    temp = np.linspace(30.0, 31.0, N).astype(np.float32)
    return stamps, omega, f, temp


def _topics(stamps, omega, f, temp, *, instances=(0,)):
    out = []
    for i in instances:
        common = {"timestamp": stamps + 300, "timestamp_sample": stamps, "device_id": 2490378 + i, "error_count": 0}
        out.append(("sensor_gyro", i, SENSOR_GYRO, {**common, "x": omega[:, 0], "y": omega[:, 1], "z": omega[:, 2],
                                                   "temperature": temp}))
        out.append(("sensor_accel", i, SENSOR_ACCEL, {**common, "x": f[:, 0], "y": f[:, 1], "z": f[:, 2],
                                                     "temperature": temp + 2.0}))
    return out


def test_the_writer_is_faithful(tmp_path):
    """pyulog reads back what was written, and its own writer re-writes it to the same bytes."""
    stamps, omega, f, temp = _signals()
    path = write_ulog(tmp_path / "a.ulg", _topics(stamps, omega, f, temp), start_us=int(stamps[0]))
    ulog = pyulog.ULog(str(path))
    gyro = ulog.get_dataset("sensor_gyro").data
    np.testing.assert_array_equal(gyro["timestamp_sample"], stamps)
    np.testing.assert_array_equal(gyro["y"], omega[:, 1])
    buf = _io.BytesIO()
    ulog.write_ulog(buf)
    assert buf.getvalue() == path.read_bytes()


def test_gyro_and_accel_with_their_temperatures(tmp_path):
    stamps, omega, f, temp = _signals()
    path = write_ulog(tmp_path / "a.ulg", _topics(stamps, omega, f, temp))
    exp = import_ulog(path, **KW)
    assert exp.n_samples == N and exp.rate_hz == RATE
    np.testing.assert_allclose(exp.dtheta, omega * (1.0 / RATE), rtol=1e-6)
    np.testing.assert_allclose(exp.dv, f * (1.0 / RATE), rtol=1e-6)
    assert exp.temperature_names == ("gyro", "accel") and list(exp.temperature_map) == [0, 0, 0, 1, 1, 1]
    np.testing.assert_allclose(exp.temperature[:, 1] - exp.temperature[:, 0], 2.0, atol=1e-5)


def test_a_missing_instance_names_the_ones_the_log_has(tmp_path):
    path = write_ulog(tmp_path / "a.ulg", _topics(*_signals(), instances=(0, 1)))
    assert import_ulog(path, instance=1, **KW).n_samples == N
    with pytest.raises(InputError, match=re.escape("--instance: no sensor_gyro instance 2; the log has instance(s) "
                                                   "0 (device_id 2490378), 1 (device_id 2490379)")):
        import_ulog(path, instance=2, **KW)


def test_sensor_combined_needs_an_assumed_temperature(tmp_path):
    stamps, omega, f, _ = _signals()
    rows = {"timestamp": stamps, "gyro_integral_dt": 4000, "accelerometer_timestamp_relative": 0,
            "accelerometer_integral_dt": 4000, **{f"gyro_rad[{i}]": omega[:, i] for i in range(3)},
            **{f"accelerometer_m_s2[{i}]": f[:, i] for i in range(3)}}
    path = write_ulog(tmp_path / "c.ulg", [("sensor_combined", 0, SENSOR_COMBINED, rows)])
    with pytest.raises(InputError, match=re.escape("--temperature: sensor_combined holds no temperature")):
        import_ulog(path, **KW)
    exp = import_ulog(path, temperature_degC=25.0, **KW)
    np.testing.assert_allclose(exp.dv, f / RATE, rtol=1e-6)


def test_not_a_ulog_is_refused(tmp_path):
    path = tmp_path / "x.ulg"
    path.write_bytes(b"not a log at all")
    with pytest.raises(InputError, match="cannot be read as a PX4 ULog"):
        import_ulog(path, **KW)


def test_cli_import_ulog(tmp_path, capsys):
    path = write_ulog(tmp_path / "a.ulg", _topics(*_signals()))
    assert main(["import", "ulog", str(path), "--latitude-deg", "47.4", "--out", str(tmp_path / "x.h5")]) == 0
    assert "400 samples" in capsys.readouterr().out
