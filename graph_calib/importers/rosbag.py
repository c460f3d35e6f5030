r"""ROS bags (:func:`import_rosbag`): ``sensor_msgs/Imu`` and ``sensor_msgs/Temperature``, read with ``rosbags``.

A ROS 2 bag (its folder, or its single ``.db3`` or ``.mcap`` file) or a ROS 1
``.bag``; no ROS installation is needed.  ``sensor_msgs/Imu`` follows REP-103 and
REP-145: ``angular_velocity`` in rad/s, ``linear_acceleration`` in m/s^2 (specific
force), stamps in the header; its ``orientation`` is ignored.  The stamps are the
messages' header stamps (not the recording times).

Rates and increments
    The experiment holds increments over the interval each sample closes. With
    ``rates="averaged"`` (the default, and what the CSV importer assumes) a
    message's rate is the mean over the interval its stamp closes, ``dtheta[k] =
    omega[k] (t[k] - t[k-1])``: right for a sensor that integrates or low-pass
    filters over its output period (most MEMS parts with their digital filter at the
    output rate).  With ``rates="instantaneous"`` the rate is a sample at the stamp,
    and the increment is the trapezoid ``(omega[k-1] + omega[k]) / 2 (t[k] - t[k-1])``.

Time stamps
    Jittered stamps that follow the sample index become ``t0 + k / rate``; where
    messages are missing (gaps of more than three nominal periods that the index does
    not explain) the record is cut into segments there (``/imu/segment``), as a CSV
    log with a segment column.  Both are said in the description and on the terminal.

Temperature
    A ``sensor_msgs/Temperature`` topic (found when there is one, or named), linearly
    interpolated to the IMU stamps and held at its end values; without one an assumed
    constant temperature is required.

Reading a message
    ``rosbags`` iterates the messages; their fixed layout is decoded with numpy over
    all messages at once (checked against the library's own deserialisation of the
    first and last message), and falls back to that deserialisation message by
    message when the messages differ in length.
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
)
from graph_calib.importers.registry import ImportFormat, Option
from graph_calib.importers.timing import RATE_MEANINGS, increments, message_times

IMU_TYPES = ("sensor_msgs/msg/Imu", "sensor_msgs/Imu")
TEMPERATURE_TYPES = ("sensor_msgs/msg/Temperature", "sensor_msgs/Temperature")
# doubles of sensor_msgs/Imu after the header: orientation (4), its covariance (9), angular_velocity at 13,
# its covariance (9), linear_acceleration at 25
_OMEGA_AT, _F_AT, _N_DOUBLES = 13, 25, 37


def _open(path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # the library's own errors for a file that is not a bag
        raise InputError(f"cannot be read as a ROS 1 or ROS 2 bag ({type(exc).__name__}: {exc})", path=path) from None
    return reader


def _topics(reader):
    return ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections) or "none"


def _choose(reader, types, topic, what, option, path):
    """The one connection list of a topic of one of ``types`` (named, or the only one)."""
    found = {}
    for c in reader.connections:
        if c.msgtype in types:
            found.setdefault(c.topic, []).append(c)
    if topic is not None:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise InputError(f"no topic {topic} in the bag; its topics: {_topics(reader)}", path=path, dataset=option)
        if not any(c.msgtype in types for c in conns):
            raise InputError(f"topic {topic} holds {conns[0].msgtype}, not {types[0]}", path=path, dataset=option)
        return conns
    if len(found) > 1:
        raise InputError(f"{len(found)} {what} topics: {', '.join(sorted(found))}; name one with {option}",
                         path=path, dataset=option)
    return next(iter(found.values())) if found else None


def _raw_messages(reader, conns):
    return [raw for _, _, raw in reader.messages(connections=conns)]


def _decode_imu(reader, conns, raws):
    """``(stamps_ns int64, omega (N, 3), f (N, 3))``: numpy over the fixed layout, checked against rosbags."""
    msgtype = conns[0].msgtype
    n = len(raws)
    lengths = {len(r) for r in raws}
    first = reader.deserialize(raws[0], msgtype)
    if len(lengths) == 1:
        is2 = reader.is2
        buf = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(n, -1)
        if is2:  # CDR: 4 bytes of encapsulation, then stamp (int32 sec, uint32 nanosec), frame_id, doubles aligned
            little = raws[0][1] == 1
            end = "<" if little else ">"
            payload = buf[:, 4:]
            strlen = int(np.frombuffer(payload[0, 8:12].tobytes(), dtype=end + "u4")[0])
            at = (12 + strlen + 7) // 8 * 8
            sec = payload[:, 0:4].copy().view(end + "i4")[:, 0].astype(np.int64)
            nsec = payload[:, 4:8].copy().view(end + "u4")[:, 0].astype(np.int64)
        else:  # ROS 1: seq, stamp (uint32 sec, uint32 nsec), frame_id, doubles packed
            end = "<"
            payload = buf
            strlen = int(np.frombuffer(payload[0, 12:16].tobytes(), dtype="<u4")[0])
            at = 16 + strlen
            sec = payload[:, 4:8].copy().view("<u4")[:, 0].astype(np.int64)
            nsec = payload[:, 8:12].copy().view("<u4")[:, 0].astype(np.int64)
        if payload.shape[1] >= at + 8 * _N_DOUBLES:
            d = payload[:, at:at + 8 * _N_DOUBLES].copy().view(end + "f8")
            stamps = sec * 1_000_000_000 + nsec
            omega, f = d[:, _OMEGA_AT:_OMEGA_AT + 3], d[:, _F_AT:_F_AT + 3]
            last = reader.deserialize(raws[-1], msgtype)
            if all(_agrees(m, stamps[k], omega[k], f[k]) for k, m in ((0, first), (n - 1, last))):
                return stamps, np.ascontiguousarray(omega), np.ascontiguousarray(f)
    msgs = [reader.deserialize(r, msgtype) for r in raws]  # messages of different lengths: one by one
    stamps = np.array([m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs], dtype=np.int64)
    omega = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in msgs])
    f = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in msgs])
    return stamps, omega, f


def _stamp_ns(msg):
    s = msg.header.stamp
    return s.sec * 1_000_000_000 + (s.nanosec if hasattr(s, "nanosec") else s.nsec)


def _agrees(msg, stamp, omega, f):
    w, a = msg.angular_velocity, msg.linear_acceleration
    return (_stamp_ns(msg) == stamp and np.array_equal(omega, [w.x, w.y, w.z])
            and np.array_equal(f, [a.x, a.y, a.z]))


def _temperature(reader, conns, raws):
    msgtype = conns[0].msgtype
    msgs = [reader.deserialize(r, msgtype) for r in raws]
    stamps = np.array([_stamp_ns(m) for m in msgs], dtype=np.int64)
    values = np.array([m.temperature for m in msgs], dtype=float)
    order = np.argsort(stamps, kind="stable")
    return stamps[order], values[order]


def import_rosbag(path, *, latitude_rad, imu_topic=None, temperature_topic=None, gravity_mps2=None,
                  temperature_degC=None, rates="averaged", rate_hz=None, imu_id="", description=None):
    """Import the IMU messages of a ROS 1 or ROS 2 bag (module docstring).

    Parameters
    ----------
    path : str or Path
        A ROS 2 bag folder, its ``.db3`` or ``.mcap`` file, or a ROS 1 ``.bag``.
    latitude_rad : float
        Bench latitude, rad.
    imu_topic, temperature_topic : str or None
        Topics to read; None finds the only ``sensor_msgs/Imu`` (``Temperature``) topic.
    gravity_mps2 : float or None
        Local gravity, m/s^2; None: WGS-84 normal gravity at the latitude.
    temperature_degC : float or None
        Assumed constant temperature when the bag has no temperature topic (then required).
    rates : {"averaged", "instantaneous"}
        What a message's rate is (module docstring).
    rate_hz : float or None
        Nominal rate; None: ``1 / median`` spacing of the stamps.
    imu_id, description : str

    Returns
    -------
    Experiment

    Raises
    ------
    InputError
        Not a bag; no Imu topic (naming the topics the bag has); several Imu topics and no ``imu_topic``
        (naming them); duplicate stamps; no temperature and no assumed temperature.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("not found", path=path)
    if rates not in RATE_MEANINGS:
        raise InputError(f"must be one of {', '.join(RATE_MEANINGS)}, got {rates!r}", dataset="rates")
    reader = _open(path)
    try:
        imu = _choose(reader, IMU_TYPES, imu_topic, "sensor_msgs/Imu", "--imu-topic", path)
        if imu is None:
            raise InputError(f"no sensor_msgs/Imu messages; the bag's topics: {_topics(reader)}", path=path)
        topic = imu[0].topic
        raws = _raw_messages(reader, imu)
        if len(raws) < 2:
            raise InputError(f"topic {topic} holds {len(raws)} message(s); a record needs more", path=path)
        stamps, omega, f = _decode_imu(reader, imu, raws)
        temp_conns = _choose(reader, TEMPERATURE_TYPES, temperature_topic, "sensor_msgs/Temperature",
                             "--temperature-topic", path)
        temp = None if temp_conns is None else _temperature(reader, temp_conns, _raw_messages(reader, temp_conns))
    finally:
        reader.close()

    order = np.argsort(stamps, kind="stable")
    stamps, omega, f = stamps[order], omega[order], f[order]
    same = np.flatnonzero(np.diff(stamps) == 0)
    if same.size:
        k = int(same[0]) + 1
        raise InputError(f"messages {k - 1} and {k} (in stamp order) have the same header stamp "
                         f"{stamps[k] / 1e9:.9f} s", path=path, dataset=topic)
    t = t_stamp = (stamps - stamps[0]) * 1e-9
    if rate_hz is not None:
        rate_hz = positive(rate_hz, "rate_hz")
    t, rate_hz, segment, timing = message_times(t, rate_hz, source=topic)
    dt = intervals(t, rate_hz, segment)
    dtheta = increments(omega, dt, segment, rates)
    dv = increments(f, dt, segment, rates)

    if temp is not None:
        if temperature_degC is not None:
            raise InputError("the bag has a temperature topic: an assumed temperature would be ignored",
                             dataset="--temperature")
        t_temp = (temp[0] - stamps[0]) * 1e-9
        temperature = np.interp(t_stamp, t_temp, temp[1])[:, None]  # on the stamps' own clock
        names = (temp_conns[0].topic.strip("/").replace("/", "_") or "temperature",)
        temp_text = f"temperature from {temp_conns[0].topic} ({temp[1].size} messages), interpolated to the stamps"
    else:
        if temperature_degC is None:
            raise InputError("no sensor_msgs/Temperature topic: name one (--temperature-topic) or give an assumed "
                             "constant temperature (--temperature DEGC)", path=path, dataset="--temperature")
        temperature, names = constant_temperature(t.shape[0], temperature_degC)
        temp_text = (f"no temperature topic: channel '{ASSUMED_TEMPERATURE_NAME}' holds an assumed "
                     f"{float(temperature_degC):g} degC")
    if gravity_mps2 is None:
        gravity_mps2 = normal_gravity(latitude_rad)
        temp_text += (f"; gravity {gravity_mps2:.5f} m/s^2 is WGS-84 normal gravity at latitude "
                      f"{math.degrees(latitude_rad):.4f} deg, at sea level")
    if description is None:
        description = (f"Imported from the ROS bag {path.name}: {t.shape[0]} sensor_msgs/Imu messages of {topic} "
                       f"(header stamps, orientation ignored), rates read as {rates} over the sample interval; "
                       f"{temp_text}" + (f"; {timing}" if timing else "") + ".")
    return build_experiment(t=t, dtheta=dtheta, dv=dv, temperature=temperature, names=names,
                            temperature_map=np.zeros(6), rate_hz=rate_hz, latitude_rad=latitude_rad,
                            gravity_mps2=gravity_mps2, imu_id=imu_id, description=description, source=path,
                            skip_lines=None, segment=segment)


def _read(inputs, options):
    """``graph-calib import rosbag BAG``: :func:`import_rosbag` with the options given."""
    if options.get("latitude_rad") is None:
        raise InputError("required for format rosbag: the bench latitude in degrees (the Earth rate needs it)",
                         dataset="--latitude-deg")
    keys = ("latitude_rad", "imu_topic", "temperature_topic", "gravity_mps2", "temperature_degC", "rates", "rate_hz",
            "imu_id", "description")
    return import_rosbag(inputs[0], **{k: options[k] for k in keys if k in options})


def _notes(experiment, options):
    return [part.strip() for part in experiment.description.rstrip(".").split("; ")
            if "jitter" in part or "missing" in part or "rates read" in part]


FORMAT = ImportFormat(
    name="rosbag", inputs=("BAG",),
    summary="sensor_msgs/Imu (and sensor_msgs/Temperature) of a ROS 2 bag (folder or file; sqlite3 or MCAP) or a "
            "ROS 1 .bag",
    example="graph-calib import rosbag session_bag --latitude-deg 48.1 --out session.h5",
    read=_read, notes=_notes,
    options=(
        Option("--imu-topic", "the sensor_msgs/Imu topic (default: the only one in the bag)", {"metavar": "TOPIC"}),
        Option("--temperature-topic", "the sensor_msgs/Temperature topic (default: the only one, if any)",
               {"metavar": "TOPIC"}),
        Option("--rates", "a message's rate is the mean over the interval its stamp closes (averaged, the default) "
               "or a sample at the stamp (instantaneous: trapezoid increments)", {"choices": RATE_MEANINGS}),
        Option("--rate-hz", "nominal sample rate, Hz (default: 1 / median spacing of the stamps)",
               {"type": float, "metavar": "HZ"}),
    ),
)


__all__ = ["FORMAT", "import_rosbag", "IMU_TYPES", "TEMPERATURE_TYPES", "RATE_MEANINGS"]
