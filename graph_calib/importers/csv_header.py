r"""A CSV header that names its columns in a common way, read without ``--columns`` (:func:`detect_layout`).

Recognised names (case, spaces, ``#``, ``field.`` prefixes and units in brackets
ignored; the header is the first line that names both triads, or the last line before the first row of numbers,
so that the rows of a file with a text label column are data): time ``t``, ``time``, ``timestamp``, ``stamp``,
``%time``, ``header.stamp``;
gyro ``gx``, ``gyro_x``, ``gyr_x``, ``omega_x``, ``wx``, ``w_x``, ``angular_velocity.x``,
EuRoC's ``w_RS_S_x``; accelerometer ``ax``, ``acc_x``, ``accel_x``, ``a_x``, ``alpha_x``
(Kalibr's ``imu0.csv``), ``linear_acceleration.x``, EuRoC's ``a_RS_S_x``;
temperature ``temp``, ``temperature``, ``temp_c``, ``temperature_degc``, ``imu_temp``, ``temp_imu``; ``segment``.
A sample counter (``n_samples``, ``sample``, ``sample_index``, ``index``, ``counter``, ...; imucal's and many
loggers' exports) is the time column in samples when no time column is named: ``t = index / --rate-hz``, and a
counter that skips says where samples were lost.
Units in brackets set the units (``[ns]``, ``[rad s^-1]``, ``[deg/s]``, ``[m s^-2]``,
``[g]``); a time column of whole numbers above 1e12 without a unit is read as
nanoseconds (Kalibr's and ROS's stamps), and the note says so.
"""

from __future__ import annotations

import re

from graph_calib.errors import InputError
from graph_calib.importers.common import DELIMITERS, data_rows, require_file, split_cells

_AXES = "xyz"
_NAMES = {"t": ("t", "time", "timestamp", "stamp", "%time", "header.stamp", "time_s", "timestamp_s")}
for _i, _a in enumerate(_AXES):
    _NAMES[f"g{_a}"] = (f"g{_a}", f"gyro_{_a}", f"gyr_{_a}", f"gyro{_a}", f"omega_{_a}", f"w{_a}", f"w_{_a}",
                        f"angular_velocity.{_a}", f"w_rs_s_{_a}", f"gyroscope_{_a}")
    _NAMES[f"a{_a}"] = (f"a{_a}", f"acc_{_a}", f"accel_{_a}", f"acc{_a}", f"accel{_a}", f"a_{_a}", f"alpha_{_a}",
                        f"linear_acceleration.{_a}", f"a_rs_s_{_a}", f"accelerometer_{_a}")
_NAMES["temp"] = ("temp", "temperature", "temp_c", "temperature_degc", "temp_degc", "imu_temp", "temp_imu",
                  "imu_temperature", "temperature_imu")
_NAMES["segment"] = ("segment",)
_LOOKUP = {alias: key for key, aliases in _NAMES.items() for alias in aliases}
#: Names of a sample counter: the time column, in samples, of a header that names no time column.
SAMPLE_COUNTER_NAMES = ("n_samples", "sample", "samples", "sample_index", "sample_number", "sample_no", "sample_nr",
                        "index", "idx", "counter", "sample_counter", "packet_counter", "packetcounter")
_UNITS = {"ns": ("time", "ns"), "us": ("time", "us"), "ms": ("time", "ms"), "s": ("time", "s"),
          "rad s^-1": ("gyro", "rad/s"), "rad/s": ("gyro", "rad/s"), "deg/s": ("gyro", "deg/s"),
          "dps": ("gyro", "deg/s"), "m s^-2": ("accel", "m/s^2"), "m/s^2": ("accel", "m/s^2"),
          "m/s2": ("accel", "m/s^2"), "g": ("accel", "g")}
#: Whole-number stamps above this without a unit are nanoseconds (1e12 ns is 17 minutes; 1e12 s is 31,700 years).
NANOSECOND_STAMPS_ABOVE = 1e12


def _normal(cell):
    """``'#timestamp [ns]'`` -> ``('timestamp', 'ns')``; ``'field.angular_velocity.x'`` -> ``('angular_velocity.x', None)``."""
    text = cell.strip().lstrip("#").strip()
    unit = None
    m = re.search(r"[\[(]([^\])]*)[\])]\s*$", text)
    if m:
        unit = m.group(1).strip()
        text = text[:m.start()].strip()
    text = text.lower().replace(" ", "_")
    if text.startswith("field."):
        text = text[len("field."):]
    return text, unit


def detect_layout(path, *, delimiter):
    """The column mapping of a file whose first line names its columns.

    Returns
    -------
    columns : dict or None
        ``{key: index}`` for ``--columns``; None when the first line holds numbers (no header).
    units : dict
        ``{"time"|"gyro"|"accel": units}`` the header says (in brackets), and ``"time_guess"``: ``"ns"`` for a
        time column of whole numbers above :data:`NANOSECOND_STAMPS_ABOVE` that says nothing (``--time-units``
        overrides a guess; against what the header says it is refused).
    notes : list of str
        What was read, to print.
    header_lines : int
        Lines before the data: the header line and any comment lines above it (an exporter's ``# ...``).

    Raises
    ------
    InputError
        A header that names no gyro or accelerometer triad in a known way (naming what it found).
    """
    path = require_file(path)
    leading = []
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for _ in range(MAX_LEADING_LINES):
            line = fh.readline()
            if not line:
                break
            if _numeric(line.strip(), delimiter):
                break
            _refuse_decimal_comma(path, line.strip(), len(leading) + 1)
            leading.append(line.strip())
            if _names_both_triads(line.strip(), delimiter):
                break           # the header: the rows after it are data, a text label column in them or not
    if not leading:
        return None, {}, [], 0
    # the header is the last line before the data; what comes before it is an exporter's comment lines
    first = leading[-1]
    header_lines = len(leading)
    cells = split_cells(first, delimiter)
    columns, units = {}, {}
    for j, cell in enumerate(cells):
        name, unit = _normal(cell)
        key = _LOOKUP.get(name)
        if key is None or key in columns:
            continue
        columns[key] = j
        kind = {"t": "time"}.get(key, "gyro" if key[0] == "g" and len(key) == 2 else
                                 "accel" if key[0] == "a" and len(key) == 2 else None)
        if unit is not None and kind is not None and unit.lower() in _UNITS:
            ukind, uname = _UNITS[unit.lower()]
            if ukind == kind:
                units[kind] = uname
    if "t" not in columns:
        counter = next((j for j, cell in enumerate(cells) if _normal(cell)[0] in SAMPLE_COUNTER_NAMES), None)
        if counter is not None:
            columns["t"] = counter
            units["time"] = "samples"
    missing = [k for k in ("gx", "gy", "gz", "ax", "ay", "az") if k not in columns]
    if missing:
        other = next((name for name, d in DELIMITERS.items() if d not in (delimiter, None, " ") and len(cells) == 1
                      and len(split_cells(first, d)) > 1), None)
        if other is not None:
            raise InputError(f"the header line is one column ({first[:60]}) but splits at each {other}: give "
                             f"--delimiter {other}", path=path, dataset=f"line {header_lines}")
        raise InputError(f"the header line names its columns ({', '.join(cells)}) but none is a known name for "
                         f"{', '.join(missing)}: give --columns (e.g. t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6)",
                         path=path, dataset=f"line {header_lines}")
    notes = ["columns from the header line: " + ", ".join(f"{k}={cells[j].strip()}" for k, j in columns.items())]
    if units.get("time") == "samples":
        notes.append(f"{cells[columns['t']].strip()} read as a sample counter: t = index / --rate-hz")
    if header_lines > 1:
        notes.append(f"{header_lines - 1} line(s) above the header line read as comments")
    if "t" in columns and "time" not in units:
        for _, text in data_rows(path, header_lines):
            try:
                cell = split_cells(text, delimiter)[columns["t"]]
                stamp = float(cell)
            except (ValueError, IndexError):
                break
            if stamp >= NANOSECOND_STAMPS_ABOVE and stamp == round(stamp):
                units["time_guess"] = "ns"          # inferred, not said: --time-units overrides it
                notes.append(f"time column read as nanoseconds (whole numbers from {cell.strip()}); give "
                             "--time-units to read it in other units")
            break
    return columns, units, notes, header_lines


def _names_both_triads(line, delimiter):
    """Whether ``line`` names a gyro and an accelerometer column of each axis in a known way (a header line)."""
    keys = {_LOOKUP.get(_normal(cell)[0]) for cell in split_cells(line, delimiter)}
    return all(f"{t}{a}" in keys for t in "ga" for a in _AXES)


#: Lines read before the data at most when looking for the header line.
MAX_LEADING_LINES = 50


def _refuse_decimal_comma(path, line, number):
    """A data row whose numbers have a decimal comma (``0,49;-0,0057;...``, a European locale's export) is refused
    naming it: read as text it would be taken for a header of unknown names."""
    if "," not in line:
        return
    for name, d in DELIMITERS.items():
        if d == ",":
            continue
        cells = split_cells(line.replace(",", "."), d)
        try:
            [float(c) for c in cells]
        except ValueError:
            continue
        if len(cells) > 1:
            raise InputError(f"the numbers have a decimal comma ({line[:40]}): this importer reads decimal points; "
                             f"export with a decimal point, or convert the file (columns split at each {name}: "
                             f"--delimiter {name}, then every ',' a '.')", path=path, dataset=f"line {number}")


def _numeric(line, delimiter):
    """Whether ``line`` is a data row: every cell a number, split at ``delimiter`` or at another separator (a file
    split at another separator is then told so at its header line; an empty line is no data row)."""
    if not line:
        return False
    for d in dict.fromkeys((delimiter, *DELIMITERS.values())):
        try:
            [float(c) for c in split_cells(line, d)]
        except ValueError:
            continue
        return True
    return False


__all__ = ["detect_layout", "NANOSECOND_STAMPS_ABOVE", "SAMPLE_COUNTER_NAMES"]
