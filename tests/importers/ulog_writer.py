"""A minimal PX4 ULog writer for the tests, written from the ULog file format's documentation.

A file is the 16-byte header (``ULog`` magic, version 1, start time in us), the
flag-bits message ``B``, one format message ``F`` per topic (``name:type field;...``),
then the data section: one subscription ``A`` per (topic, instance) and one data
message ``D`` per sample, in time order.  Every message is ``uint16 size, uint8 type,
payload``, little-endian.  Faithfulness is shown in the tests: pyulog reads the file
back to the values written, and pyulog's own writer re-writes what it read to the same
bytes.
"""

from __future__ import annotations

import struct

import numpy as np

MAGIC = b"ULog\x01\x12\x35"
_TYPES = {"uint64_t": "<u8", "int64_t": "<i8", "uint32_t": "<u4", "int32_t": "<i4", "float": "<f4",
          "double": "<f8", "uint8_t": "u1", "int8_t": "i1", "uint16_t": "<u2", "bool": "u1"}


def _msg(kind, payload):
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def _dtype(fields):
    out = []
    for ftype, name in fields:
        if "[" in ftype:
            base, n = ftype[:-1].split("[")
            out += [(f"{name}[{i}]", _TYPES[base]) for i in range(int(n))]
        else:
            out.append((name, _TYPES[ftype]))
    return np.dtype(out)


def write_ulog(path, topics, *, start_us=0):
    """Write ``topics``: a list of ``(name, multi_id, fields, rows)``.

    ``fields`` is ``[(type, name), ...]`` with ``timestamp`` (uint64_t, us) first; ``rows`` a dict of arrays by field
    name (array fields as ``name[i]``).  Topics of one name share their format.
    """
    out = bytearray(MAGIC + bytes([1]) + struct.pack("<Q", start_us))
    out += _msg("B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    formats = {}
    for name, _, fields, _ in topics:
        if name not in formats:
            formats[name] = fields
            out += _msg("F", (name + ":" + "".join(f"{t} {n};" for t, n in fields)).encode())
    items = []
    for msg_id, (name, multi_id, fields, rows) in enumerate(topics):
        out += _msg("A", struct.pack("<BH", multi_id, msg_id) + name.encode())
        dt = _dtype(fields)
        rec = np.zeros(len(rows["timestamp"]), dtype=dt)
        for key in dt.names:
            rec[key] = rows[key]
        for k in range(rec.shape[0]):
            items.append((int(rows["timestamp"][k]), msg_id, _msg("D", struct.pack("<H", msg_id) + rec[k].tobytes())))
    items.sort(key=lambda x: (x[0], x[1]))
    for _, _, buf in items:
        out += buf
    with open(path, "wb") as fh:
        fh.write(bytes(out))
    return path


SENSOR_GYRO = [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("uint32_t", "device_id"),
               ("float", "x"), ("float", "y"), ("float", "z"), ("float", "temperature"), ("uint32_t", "error_count")]
SENSOR_ACCEL = SENSOR_GYRO
SENSOR_COMBINED = [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"), ("uint32_t", "gyro_integral_dt"),
                   ("int32_t", "accelerometer_timestamp_relative"), ("float[3]", "accelerometer_m_s2"),
                   ("uint32_t", "accelerometer_integral_dt")]
