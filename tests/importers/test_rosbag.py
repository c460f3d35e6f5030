"""``graph-calib import rosbag``: bags written by the rosbags writer from a simulated record read back as that record."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from graph_calib import io
from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.importers.rosbag import import_rosbag

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402


def _messages(ts, exp, *, frame="imu_link", drop=(), t=None):
    """sensor_msgs Imu and Temperature messages of a record: rates = increments / interval, stamps = t."""
    T = ts.types
    ns = "sensor_msgs/msg/"
    Imu, Temp = T[ns + "Imu"], T[ns + "Temperature"]
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    ros1 = "seq" in Header.__dataclass_fields__
    omega = exp.dtheta / exp.dt[:, None]
    f = exp.dv / exp.dt[:, None]
    stamps = np.round((exp.t if t is None else t) * 1e9).astype(np.int64) + 1_700_000_000 * 10**9
    extra = {"seq": 0} if ros1 else {}
    for k in range(exp.n_samples):
        if k in drop:
            continue
        sec, nsec = divmod(int(stamps[k]), 10**9)
        head = Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame, **extra)
        imu = Imu(header=head, orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
                  angular_velocity=V3(x=omega[k, 0], y=omega[k, 1], z=omega[k, 2]),
                  angular_velocity_covariance=np.zeros(9),
                  linear_acceleration=V3(x=f[k, 0], y=f[k, 1], z=f[k, 2]),
                  linear_acceleration_covariance=np.zeros(9))
        temp = Temp(header=head, temperature=float(exp.temperature[k, 0]), variance=0.0)
        yield int(stamps[k]), imu, temp, ns


def write_bag(exp, path, *, storage="mcap", imu_topics=("/imu/data",), temperature=True, drop=(), t=None):
    """A ROS 2 bag (``storage`` mcap or sqlite3) or a ROS 1 bag (``storage="ros1"``) holding the record."""
    if storage == "ros1":
        ts = get_typestore(Stores.ROS1_NOETIC)
        w = Writer1(path)
        ser = ts.serialize_ros1
    else:
        ts = get_typestore(Stores.ROS2_HUMBLE)
        plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
        w = Writer(path, version=9, storage_plugin=plugin)
        ser = ts.serialize_cdr
    with w:
        ns = "sensor_msgs/msg/"
        imu_conns = [w.add_connection(t, ns + "Imu", typestore=ts) for t in imu_topics]
        tc = w.add_connection("/imu/temperature", ns + "Temperature", typestore=ts) if temperature else None
        for stamp, imu, temp, ns in _messages(ts, exp, drop=drop, t=t):
            for c in imu_conns:
                w.write(c, stamp, ser(imu, ns + "Imu"))
            if tc is not None:
                w.write(tc, stamp, ser(temp, ns + "Temperature"))
    return path


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    """A simulated hand-held record (consumer grade, no table, one temperature channel), 20 s."""
    from graph_calib.simulation import simulate, write_simulation
    out = tmp_path_factory.mktemp("sim")
    write_simulation(simulate("consumer-handheld", rng=np.random.default_rng(3)), out)
    return io.read_experiment(out / "handheld.h5")


def _short(exp, n=2000):
    keep = slice(0, n)
    return replace(exp, t=exp.t[keep], dtheta=exp.dtheta[keep], dv=exp.dv[keep], temperature=exp.temperature[keep])


KW = {"latitude_rad": 0.9721483933608416, "gravity_mps2": 9.8155}


@pytest.mark.parametrize("storage", ["mcap", "sqlite3", "ros1"])
def test_bag_reads_back_as_the_record(record, tmp_path, storage):
    exp = _short(record)
    path = write_bag(exp, tmp_path / ("bag.bag" if storage == "ros1" else "bag"), storage=storage)
    got = import_rosbag(path, **KW)
    assert got.n_samples == exp.n_samples and got.segment is None
    np.testing.assert_allclose(got.t, exp.t - exp.t[0], atol=1e-9)
    np.testing.assert_allclose(got.dtheta, exp.dtheta, rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(got.dv, exp.dv, rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(got.temperature, exp.temperature)
    assert "rates read as averaged" in got.description and "/imu/data" in got.description


def test_a_single_mcap_file_of_a_bag_folder_is_read(record, tmp_path):
    exp = _short(record, 300)
    path = write_bag(exp, tmp_path / "bag", storage="mcap")
    got = import_rosbag(next(path.glob("*.mcap")), **KW)
    np.testing.assert_allclose(got.dv, exp.dv, rtol=1e-6)


def test_two_imu_topics_are_refused_naming_both(record, tmp_path):
    path = write_bag(_short(record, 50), tmp_path / "bag", imu_topics=("/imu/a", "/imu/b"))
    with pytest.raises(InputError, match=re.escape("--imu-topic: 2 sensor_msgs/Imu topics: /imu/a, /imu/b; name one "
                                                   "with --imu-topic")):
        import_rosbag(path, **KW)
    assert import_rosbag(path, imu_topic="/imu/b", **KW).n_samples == 50


def test_a_bag_without_imu_messages_is_refused_naming_its_topics(record, tmp_path):
    path = write_bag(_short(record, 50), tmp_path / "bag", imu_topics=())
    with pytest.raises(InputError, match=re.escape("no sensor_msgs/Imu messages; the bag's topics: /imu/temperature "
                                                   "(sensor_msgs/msg/Temperature)")):
        import_rosbag(path, **KW)


def test_no_temperature_topic_names_the_options(record, tmp_path):
    path = write_bag(_short(record, 50), tmp_path / "bag", temperature=False)
    with pytest.raises(InputError, match=re.escape("--temperature: no sensor_msgs/Temperature topic: name one "
                                                   "(--temperature-topic) or give an assumed constant temperature "
                                                   "(--temperature DEGC)")):
        import_rosbag(path, **KW)
    assert import_rosbag(path, temperature_degC=21.0, **KW).temperature_names == ("assumed_constant",)


def test_dropped_messages_cut_segments_and_instantaneous_rates_are_trapezoids(record, tmp_path):
    exp = _short(record, 400)
    path = write_bag(exp, tmp_path / "bag", drop=range(200, 210))
    got = import_rosbag(path, **KW)
    assert got.n_samples == 390 and got.n_segments == 2 and "messages missing" in got.description
    inst = import_rosbag(path, rates="instantaneous", **KW)
    w = exp.dtheta / exp.dt[:, None]
    np.testing.assert_allclose(inst.dtheta[1:200], 0.5 * (w[:199] + w[1:200]) * exp.dt[1:200, None], rtol=1e-6)
    np.testing.assert_allclose(inst.dtheta[200], got.dtheta[200])  # a segment's first sample: its own rate


def test_jittered_stamps_with_no_message_missing_become_the_index(record, tmp_path):
    exp = _short(record, 600)
    # a wireless link delivering samples in bursts every 35 ms: stamps are arrival times, gaps of 3.5 periods
    k = np.arange(exp.n_samples)
    burst = np.ceil(np.round(exp.t / 0.035, 9)) * 0.035
    rank = k - np.searchsorted(burst, burst)          # position inside its burst
    arrival = burst + rank * 1e-4
    path = write_bag(exp, tmp_path / "bag", t=arrival)
    got = import_rosbag(path, rate_hz=100.0, **KW)
    assert got.segment is None and "no sample is missing" in got.description
    np.testing.assert_allclose(np.diff(got.t), 0.01, rtol=1e-9)


def test_cli_import_rosbag(record, tmp_path, capsys):
    path = write_bag(_short(record, 300), tmp_path / "bag", storage="sqlite3")
    out = tmp_path / "x.h5"
    assert main(["import", "rosbag", str(path), "--latitude-deg", "55.7", "--out", str(out)]) == 0
    assert io.read_experiment(out).n_samples == 300
    assert "rates read as averaged" in capsys.readouterr().out


def test_not_a_bag_is_refused(tmp_path):
    path = tmp_path / "x.bag"
    path.write_text("hello")
    with pytest.raises(InputError, match="cannot be read as a ROS 1 or ROS 2 bag"):
        import_rosbag(path, **KW)


@pytest.mark.slow
@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bag_calibrates_to_the_records_estimates_within_a_tenth_of_sigma(record, tmp_path, storage):
    """The whole record through a bag and `calibrate`: the factor graph's estimates within 0.1 sigma."""
    from graph_calib.calibrate import CalibrationOptions, calibrate

    path = write_bag(record, tmp_path / "bag", storage=storage)
    got = import_rosbag(path, **KW)
    a = calibrate(record, options=CalibrationOptions(), solvers=("factor-graph",)).results["factor-graph"]
    b = calibrate(got, options=CalibrationOptions(), solvers=("factor-graph",)).results["factor-graph"]
    worst = max(abs(a.values[k] - b.values[k]) / a.sigmas[k] for k in a.values if a.sigmas.get(k))
    assert worst < 0.1, worst
