r"""Any delimited text log, described by a column mapping and units (:func:`import_csv`).

Columns are counted from 0, in the mapping and in every message.  Only the
mapped columns are read (the others may hold anything, text included); every
row must still have the same number of columns.
"""

from __future__ import annotations

import math
import re

import numpy as np

from graph_calib import constants as c
from graph_calib.errors import InputError
from graph_calib.importers.common import (
    ASSUMED_TEMPERATURE_NAME,
    DELIMITERS,
    as_float,
    build_experiment,
    check_time_column,
    constant_temperature,
    data_line_numbers,
    data_rows,
    intervals,
    normal_gravity,
    positive,
    read_numeric_table,
    require_file,
    show,
    split_cells,
    table_width,
)
from graph_calib.importers.csv_header import detect_layout
from graph_calib.importers.registry import ImportFormat, Option
from graph_calib.importers.timing import label_segments, rebase_segments, regular_times, within_segment_order
from graph_calib.io import RATE_TOLERANCE

#: Units of :func:`import_csv`: name -> (factor to SI, True for a rate, False for an increment).
GYRO_UNITS = {"rad/s": (1.0, True), "deg/s": (c.DEG_TO_RAD, True), "rad": (1.0, False), "deg": (c.DEG_TO_RAD, False)}
ACCEL_UNITS = {"m/s^2": (1.0, True), "g": (c.G0, True), "m/s": (1.0, False)}
#: A time column read in its units that puts samples closer than this rate's period is taken as misread (MEMS
#: IMUs sample at up to a few kHz, 32 kHz at most), unless the rate is given.
MAX_RATE_HZ = 50_000.0
#: Units of the time column: name -> factor to s; ``"samples"`` (None) is a sample index, ``t = index / rate_hz``.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "samples": None}
CSV_SENSOR_COLUMNS = ("gx", "gy", "gz", "ax", "ay", "az")
_INT32 = np.iinfo(np.int32)
#: Integers from here on are not all exact as float64.
_EXACT_FLOAT_INTEGER = 2.0**53


def _refuse_skipped_counts(count, segment, *, path, header_lines):
    """A sample counter is the sample clock itself: a step other than one inside a segment is lost (or repeated)
    samples, never late stamps, so it is refused naming the line (the timing's jitter rule is for stamps)."""
    step = np.diff(count)
    bad = step != 1
    if segment is not None:
        bad &= np.diff(segment) == 0
    if not bad.any():
        return
    k = int(np.flatnonzero(bad)[0])
    line = data_line_numbers(path, header_lines)[k + 1]
    lost = f"{step[k] - 1:.0f} sample(s) lost" if step[k] > 1 else "a count repeated or going back"
    raise InputError(f"the sample counter steps from {count[k]:.0f} to {count[k + 1]:.0f} (input line {line}): {lost}. "
                     "Mark where each piece starts with a segment column (segment=COLUMN in --columns, e.g. a "
                     "counter that steps at each gap) and each piece is integrated on its own", path=path, dataset="t")


def _resolve_columns(columns, *, path, delimiter, header_lines):
    """Check a column mapping; return ({key: index from 0}, [temperature keys], {key: channel name}, header lines):
    names of header columns without ``header_lines`` read the first line as the header when it holds any of them."""
    if not isinstance(columns, dict) or not columns:
        raise InputError("columns must map names (t, gx, gy, gz, ax, ay, az, segment, temp or temp:NAME) to columns",
                         dataset="columns")
    known = ("t",) + CSV_SENSOR_COLUMNS + ("segment",)
    temp_keys, channel = [], {}
    for key in columns:
        if key == "temp" or key.startswith("temp:"):
            name = key.split(":", 1)[1] if ":" in key else "temp"
            if not name:
                raise InputError(f"empty channel name in {show(key)}", dataset="columns")
            temp_keys.append(key)
            channel[key] = name
        elif key not in known:
            raise InputError(f"unknown column name {show(key)}; known: {', '.join(known)}, temp, temp:NAME",
                             dataset="columns")
    missing = [k for k in CSV_SENSOR_COLUMNS if k not in columns]
    if missing:
        raise InputError(f"no column given for {', '.join(missing)}", dataset="columns")
    header = None
    index = {}
    for key, col in columns.items():
        if isinstance(col, str) and not col.isdigit():
            if header is None:
                try:
                    with open(path, encoding="utf-8-sig") as fh:
                        lines = [fh.readline() for _ in range(max(header_lines, 1))]
                except UnicodeDecodeError:
                    raise InputError("not a UTF-8 text file", path=path) from None
                header = split_cells(lines[-1].strip(), delimiter)
                if header_lines < 1:
                    named = [c for c in columns.values() if isinstance(c, str) and not c.isdigit()]
                    if not any(c in header for c in named):
                        raise InputError(f"column {key}={show(col)} names a header column, but no header line was "
                                         "given: give --header-lines N, N the line that names the columns",
                                         path=path, dataset="columns")
                    header_lines = 1            # the first line names columns: it is the header
            if col not in header:
                raise InputError(f"column {show(col)} not in the header line {header_lines} ({', '.join(header)})",
                                 path=path, dataset="columns")
            index[key] = header.index(col)
        else:
            try:
                idx = int(col)
            except (TypeError, ValueError):
                raise InputError(f"column of {key} must be an index or a header name, got {show(col)}",
                                 dataset="columns") from None
            if idx < 0 or isinstance(col, bool):
                raise InputError(f"column of {key} must be an index >= 0 (columns count from 0), got {show(col)}",
                                 dataset="columns")
            index[key] = idx
    seen = {}
    for key, idx in index.items():
        if idx in seen:
            raise InputError(f"column {idx} given for both {seen[idx]} and {key}", dataset="columns")
        seen[idx] = key
    return index, temp_keys, channel, header_lines


def _text_column(path, *, delimiter, skip_lines, j):
    """Column ``j`` of every data row as text (a label column: numbers or names)."""
    cells = [split_cells(text, delimiter)[j] for _, text in data_rows(path, skip_lines)]
    try:
        return np.asarray([float(c) for c in cells])
    except ValueError:
        return np.asarray(cells)


def _whole(values, *, what, path, skip_lines):
    """Refuse a column that must hold integers (fitting int32) at its first other value, naming the line."""
    bad = (values != np.round(values)) | (values < _INT32.min) | (values > _INT32.max)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        line = data_line_numbers(path, skip_lines)[row]
        raise InputError(f"{what} {show(values[row])} is not an integer (within int32)", path=path,
                         dataset=f"line {line}")


def _time_column(raw, *, time_units, rate_hz, path, skip_lines, segment=None, values=None):
    """Seconds from the time column in its units; refuses rows out of order and a sample index read as seconds.

    With a segment column, the order is checked inside each segment only (a group may restart its clock).
    ``values`` (N, k), the row's other numbers: a row that repeats the one before it is named as logged twice.
    """
    if time_units == "samples":
        _whole(raw, what="sample index", path=path, skip_lines=skip_lines)
    row = within_segment_order(raw, segment)
    if row is not None and values is not None and np.array_equal(values[row], values[row - 1]):
        lines = data_line_numbers(path, skip_lines)
        raise InputError(f"lines {lines[row - 1]} and {lines[row]} have the same time {show(raw[row])} {time_units}: "
                         "a row logged twice? remove one", path=path, dataset=f"line {lines[row]}")
    if row is not None:
        line = data_line_numbers(path, skip_lines)[row]
        remedy = ("rows must be in time order inside a segment" if segment is not None else
                  "rows must be in time order. If the rows are grouped (each group restarting its clock, e.g. one "
                  "group per face), map the group's label column as the segment (segment=COLUMN in --columns): each "
                  "group becomes a segment placed after the previous one; if the rows are only shuffled, --sort "
                  "sorts them by time")
        raise InputError(f"time {show(raw[row])} {time_units} is not after the previous row's {show(raw[row - 1])} "
                         f"{time_units}: {remedy}", path=path, dataset=f"line {line}")
    if time_units == "samples":
        return raw / rate_hz
    if (time_units == "s" and raw.shape[0] >= 2 and np.all(raw == np.round(raw))
            and np.median(np.diff(raw)) == 1.0
            and not (rate_hz is not None and abs(rate_hz - 1.0) <= RATE_TOLERANCE)):
        raise InputError(
            "the time column holds whole numbers one apart, a 1 Hz record if they are seconds: if they count "
            "samples give time units 'samples' (--time-units samples) and the sample rate (--rate-hz); if they "
            "are seconds, confirm with a rate of 1 Hz (--rate-hz 1)", path=path, dataset="time_units")
    seconds = raw * TIME_UNITS[time_units]
    if seconds.shape[0] >= 2:
        step = float(np.median(np.diff(seconds)))
        if step > 1.0:
            raise InputError(f"the time column advances by {show(step)} s per row read as {time_units} (a "
                             f"{show(1.0 / step)} Hz record): an IMU samples faster; if the column counts "
                             f"milliseconds or nanoseconds give --time-units ms or ns", path=path,
                             dataset="time_units")
        if 0.0 < step < 1.0 / MAX_RATE_HZ and rate_hz is None:
            raise InputError(f"the time column advances by {step:.4g} s per row read as {time_units} (a "
                             f"{1.0 / step:.4g} Hz record, {seconds[-1] - seconds[0]:.4g} s long): faster than "
                             f"an IMU samples; if the column counts coarser units give them (--time-units ms or s), "
                             f"or confirm the rate with --rate-hz", path=path, dataset="time_units")
    return seconds


def import_csv(path, *, columns, latitude_rad, gravity_mps2=None, rate_hz=None, time_units=None,
               gyro_units="rad/s", accel_units="m/s^2", gyro_counts_per_unit=None, gyro_offset_counts=0.0,
               accel_counts_per_unit=None, accel_offset_counts=0.0, temperature_degC=None,
               temperature_map=None, delimiter=",", header_lines=0, sort=False, imu_id="", description=None):
    """Import a delimited text log described by a column mapping and units.

    Parameters
    ----------
    path : str or Path
    columns : dict
        ``{key: column}`` with keys ``gx gy gz ax ay az`` (required), ``t``
        (optional), ``segment`` (optional) and ``temp`` or ``temp:NAME`` (one
        per temperature channel, degC, in the order given).  A column is an
        index counted from 0, or a name from the last header line.  Further
        columns of the file are ignored whatever they hold; every row must still
        have the same number of columns.
    latitude_rad : float
        Bench latitude, rad.
    gravity_mps2 : float or None
        Local gravity magnitude, m/s^2.  None: WGS-84 normal gravity at
        ``latitude_rad`` at sea level (:func:`normal_gravity`), and the
        description says so.
    rate_hz : float or None
        Nominal sample rate, Hz.  Required without a time column
        (``t[k] = k / rate_hz``) and with ``time_units="samples"``; otherwise it
        defaults to ``1 / median(diff(t))`` rounded to 6 significant digits.
    time_units : {'s', 'ms', 'us', 'ns', 'samples'} or None
        Units of the ``t`` column (default ``'s'``); ``'samples'``: a sample
        index, ``t = index / rate_hz``.  Refused without a ``t`` column.
    gyro_units : {'rad/s', 'deg/s', 'rad', 'deg'}
        Rates (multiplied by the sample interval) or increments.
    accel_units : {'m/s^2', 'g', 'm/s'}
        Specific force (multiplied by the sample interval) or velocity
        increments; ``g`` is standard gravity ``9.80665`` m/s^2.
    gyro_counts_per_unit, accel_counts_per_unit : float or None
        For raw counts: nominal scale, counts per ``gyro_units`` (``accel_units``);
        the value is ``(raw - offset) / counts_per_unit``.  None: the column
        already holds the unit.
    gyro_offset_counts, accel_offset_counts : float
        Zero of the counts.
    temperature_degC : float or None
        Assumed constant temperature when no ``temp`` column is given (then required).
    temperature_map : sequence of 6 int or None
        Channel of gyro x, y, z and accel x, y, z (default all 0).
    delimiter : str or None
        One-character column separator (``"`` quotes a cell); None for whitespace.
    header_lines : int
        Lines before the data; the last one may name the columns.
    sort : bool
        Sort the rows by time first (rows merged out of order); refused with a segment column.
    imu_id : str
    description : str or None
        Default: what was converted and how.

    Returns
    -------
    Experiment
        With ``segment`` (int32) when a ``segment`` column is mapped: integers that never
        decrease are kept, any other labels (text, or numbers out of order) become one segment per run of equal
        labels.  A segment whose clock restarts (rows grouped by a label, each group from time 0) is placed one
        nominal period after the previous one.  Jittered stamps whose spacing breaks the gap rule but that follow
        the sample index (no sample missing) become ``t0 + k / rate`` and the description says so
        (:func:`graph_calib.importers.timing.regular_times`).  Segments otherwise:
        the record's pieces, non-decreasing; a time gap is allowed only where
        the segment changes, and the first sample of each segment covers one
        nominal period.

    Raises
    ------
    InputError
        Bad options (naming the option), or a malformed file (naming the line
        and the column, counted from 0).
    """
    path = require_file(path)
    if gyro_units not in GYRO_UNITS:
        raise InputError(f"unknown gyro units {show(gyro_units)}; known: {', '.join(GYRO_UNITS)}", dataset="gyro_units")
    if accel_units not in ACCEL_UNITS:
        raise InputError(f"unknown accel units {show(accel_units)}; known: {', '.join(ACCEL_UNITS)}",
                         dataset="accel_units")
    if time_units is not None and time_units not in TIME_UNITS:
        raise InputError(f"unknown time units {show(time_units)}; known: {', '.join(TIME_UNITS)}", dataset="time_units")
    if not isinstance(header_lines, int) or header_lines < 0:
        raise InputError(f"must be a non-negative integer, got {show(header_lines)}", dataset="header_lines")
    if delimiter is not None and (not isinstance(delimiter, str) or len(delimiter) != 1 or delimiter in '"#'):
        raise InputError(f"must be one character other than '\"' and '#' (or None for whitespace), "
                         f"got {show(delimiter)}", dataset="delimiter")
    if rate_hz is not None:
        rate_hz = positive(rate_hz, "rate_hz")
    index, temp_keys, channel, header_lines = _resolve_columns(columns, path=path, delimiter=delimiter,
                                                               header_lines=header_lines)
    if "t" in index:
        time_units = "s" if time_units is None else time_units
        if time_units == "samples" and rate_hz is None:
            raise InputError("the time column counts samples: give the sample rate (--rate-hz HZ), t = index / "
                             "rate_hz", path=path, dataset="--rate-hz")
    elif time_units is not None:
        raise InputError(f"{show(time_units)} given, but no time column (t=COLUMN): samples are then "
                         "k / rate_hz apart", dataset="time_units")
    gravity_text = ""
    if gravity_mps2 is None:
        lat = as_float(latitude_rad)
        if not isinstance(lat, float) or not math.isfinite(lat) or abs(lat) > math.pi / 2:
            raise InputError(f"normal gravity needs a latitude in [-pi/2, pi/2] rad, got {show(latitude_rad)}",
                             dataset="latitude_rad")
        gravity_mps2 = normal_gravity(lat)
        gravity_text = (f"Gravity {gravity_mps2:.5f} m/s^2 is WGS-84 normal gravity (Somigliana) at latitude "
                        f"{math.degrees(lat):.4f} deg, at sea level: no local value was given.")

    n_cols = table_width(path, delimiter=delimiter, skip_lines=header_lines)
    too_far = {k: i for k, i in index.items() if i >= n_cols}
    if too_far:
        key, idx = next(iter(too_far.items()))
        raise InputError(f"column {idx} of {key} is beyond the {n_cols} columns of the file (columns count from 0)",
                         path=path, dataset="columns")
    label_col = index.get("segment")
    keys = [k for k in index if k != "segment"]
    table = read_numeric_table(path, delimiter=delimiter, skip_lines=header_lines,
                               usecols=[index[k] for k in keys], column_names={i: k for k, i in index.items()})
    col = {k: table[:, j] for j, k in enumerate(keys)}
    n = table.shape[0]
    stamp_note = ""
    if "t" in index and np.max(np.abs(col["t"])) >= _EXACT_FLOAT_INTEGER:
        # integer stamps beyond 2^53 (nanoseconds since 1970) are not exact as floats: read them as integers and
        # keep their exact differences from the first
        try:
            exact = np.loadtxt(path, delimiter=delimiter, skiprows=header_lines, comments="#", ndmin=1,
                               dtype=np.int64, encoding="utf-8-sig", quotechar='"', usecols=[index["t"]])
        except ValueError:
            exact = None
        if exact is not None and exact.shape == col["t"].shape:
            col["t"] = (exact - exact[0]).astype(np.float64)
            stamp_note = f"time from the first stamp {int(exact[0])} {time_units or 's'}"
    segment = None
    if label_col is not None:
        segment = label_segments(_text_column(path, delimiter=delimiter, skip_lines=header_lines, j=label_col))
    if sort:
        if segment is not None:
            raise InputError("rows are sorted by time only without a segment column (a segment's rows stay in "
                             "their order)", dataset="sort")
        if "t" not in index:
            raise InputError("sorting needs a time column (t=COLUMN)", dataset="sort")
        order = np.argsort(col["t"], kind="stable")
        col = {k: v[order] for k, v in col.items()}
        same = np.flatnonzero(np.diff(col["t"]) == 0)
        if same.size:
            lines = data_line_numbers(path, header_lines)
            a, b = sorted((int(lines[order[same[0]]]), int(lines[order[same[0] + 1]])))
            raise InputError(f"lines {a} and {b} have the same time {show(col['t'][same[0]])}"
                             f"{' ' + time_units if time_units else ''}: a row logged twice? sorting cannot order "
                             f"them; remove one", path=path, dataset=f"line {b}")
    timing_note = ""
    if "t" in index:
        others = np.column_stack([v for k, v in col.items() if k != "t"]) if len(col) > 1 else None
        t = _time_column(col["t"], time_units=time_units, rate_hz=rate_hz, path=path, skip_lines=header_lines,
                         segment=segment, values=others)
        given_rate = rate_hz is not None
        if rate_hz is None:
            if n < 2:
                raise InputError("one sample: give rate_hz", path=path, dataset="rate_hz")
            inside = np.diff(t) if segment is None else np.diff(t)[np.diff(segment) == 0]
            rate_hz = positive(float(f"{1.0 / float(np.median(inside)):.6g}"), "rate_hz")
        if segment is not None:
            t = rebase_segments(t, segment, rate_hz)
        if time_units == "samples":
            _refuse_skipped_counts(col["t"], segment, path=path, header_lines=header_lines)
        try:
            t, rate_hz, timing_note = regular_times(t, rate_hz, segment=segment, source=path.name,
                                                    given_rate=given_rate, path=path)
        except InputError as exc:
            line = data_line_numbers(path, header_lines)[exc.index]
            raise InputError(f"{exc} (input line {line})") from None
    else:
        if rate_hz is None:
            raise InputError("no time column: give the sample rate (--rate-hz HZ), or map a time column (t=COLUMN "
                             "in --columns)", path=path, dataset="--rate-hz")
        t = np.arange(n, dtype=np.float64) / rate_hz
    dt = intervals(t, rate_hz, segment)[:, None]

    def triad(keys, units_table, units, counts_per_unit, offset, label):
        raw = np.column_stack([col[k] for k in keys])
        if counts_per_unit is not None:
            raw = (raw - float(offset)) / positive(counts_per_unit, f"{label}_counts_per_unit")
        factor, is_rate = units_table[units]
        value = raw * factor
        return value * dt if is_rate else value

    dtheta = triad(("gx", "gy", "gz"), GYRO_UNITS, gyro_units, gyro_counts_per_unit, gyro_offset_counts, "gyro")
    dv = triad(("ax", "ay", "az"), ACCEL_UNITS, accel_units, accel_counts_per_unit, accel_offset_counts, "accel")

    if temp_keys:
        if temperature_degC is not None:
            raise InputError("temperature columns are given: an assumed temperature would be ignored",
                             dataset="temperature_degC")
        temperature = np.column_stack([col[k] for k in temp_keys])
        names = tuple(channel[k] for k in temp_keys)
        temp_text = f"temperature channels {', '.join(names)} from the log"
    else:
        if temperature_degC is None:
            raise InputError("no temperature column: map one (temp=COLUMN in --columns, or a header column named "
                             "temp or temperature) or give an assumed constant temperature (--temperature "
                             "DEGC)", path=path, dataset="--temperature")
        temperature, names = constant_temperature(n, temperature_degC)
        temp_text = (f"no temperature was recorded: channel '{ASSUMED_TEMPERATURE_NAME}' holds an assumed "
                     f"{float(temperature_degC):g} degC")
    if temperature_map is None:
        temperature_map = np.zeros(6, dtype=np.int64)
    else:
        tm = np.asarray(temperature_map)
        if tm.shape != (6,) or tm.dtype.kind not in "iu":
            raise InputError(f"must be six integer channel indices, got {show(temperature_map)}",
                             dataset="temperature_map")
        temperature_map = tm

    if description is None:
        def units_text(units, counts, offset):
            return f"counts ({counts:g} per {units}, offset {float(offset):g})" if counts is not None else units
        description = (
            f"Imported from {path.name}: gyro in {units_text(gyro_units, gyro_counts_per_unit, gyro_offset_counts)}, "
            f"accel in {units_text(accel_units, accel_counts_per_unit, accel_offset_counts)}, "
            + (f"time column in {time_units}" if "t" in index else f"t = k / {rate_hz:g} Hz")
            + (f" (t = index / {rate_hz:g} Hz)" if time_units == "samples" else "")
            + (f"; {1 + int(np.count_nonzero(np.diff(segment)))} segment(s) from the segment column"
               if segment is not None else "")
            + (f"; {timing_note}" if timing_note else "") + (f"; {stamp_note}" if stamp_note else "")
            + f"; {temp_text}."
        )
    if gravity_text:  # provenance of a computed constant: kept next to a description given too
        description = f"{description} {gravity_text}" if description else gravity_text
    return build_experiment(t=t, dtheta=dtheta, dv=dv, temperature=temperature, names=names,
                  temperature_map=temperature_map, rate_hz=rate_hz, latitude_rad=latitude_rad,
                  gravity_mps2=gravity_mps2, imu_id=imu_id, description=description, source=path,
                  skip_lines=header_lines, segment=segment)




# ---------------------------------------------------------------------------
# the command line's csv format
# ---------------------------------------------------------------------------


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


def _read(inputs, options):
    """``graph-calib import csv CSV_FILE``: :func:`import_csv` with the options given (a named header read)."""
    if options.get("latitude_rad") is None:
        raise InputError("required for format csv: the bench latitude in degrees (the Earth rate needs it; "
                         "without --gravity, gravity is the normal gravity at that latitude)",
                         dataset="--latitude-deg")
    delimiter = options.get("delimiter", ",")
    delimiter = DELIMITERS.get(delimiter, delimiter)
    if delimiter == " ":
        delimiter = None
    units, notes = {}, []
    header_lines = options.get("header_lines")
    if "columns" in options:
        columns = parse_columns(options["columns"])
    else:
        columns, units, notes, found_lines = detect_layout(inputs[0], delimiter=delimiter)
        if columns is None:
            raise InputError("required for format csv when the first line holds no column names (e.g. "
                             "t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6,temp=7)", dataset="--columns")
        header_lines = found_lines if header_lines is None else header_lines
    for kind, option in (("time", "time_units"), ("gyro", "gyro_units"), ("accel", "accel_units")):
        given, said = options.get(option), units.get(kind)
        if given is not None and said is not None and given != said:
            raise InputError(f"the header line says the {kind} column is in {said}, but {given} is given: give "
                             f"--{option.replace('_', '-')} only where the header says nothing (or leave it out)",
                             path=inputs[0], dataset=f"--{option.replace('_', '-')}")
    options["_notes"] = notes
    return import_csv(
        inputs[0], columns=columns, latitude_rad=options["latitude_rad"], gravity_mps2=options.get("gravity_mps2"),
        rate_hz=options.get("rate_hz"), time_units=options.get("time_units", units.get("time", units.get("time_guess"))),
        gyro_units=options.get("gyro_units", units.get("gyro", "rad/s")),
        accel_units=options.get("accel_units", units.get("accel", "m/s^2")),
        gyro_counts_per_unit=options.get("gyro_scale"), gyro_offset_counts=options.get("gyro_offset", 0.0),
        accel_counts_per_unit=options.get("accel_scale"), accel_offset_counts=options.get("accel_offset", 0.0),
        temperature_degC=options.get("temperature_degC"),
        temperature_map=None if "temperature_map" not in options else _parse_map(options["temperature_map"]),
        delimiter=delimiter, header_lines=0 if header_lines is None else header_lines,
        sort=bool(options.get("sort")), imu_id=options.get("imu_id", ""), description=options.get("description"))


def _notes(experiment, options):
    lines = list(options.get("_notes", ()))
    if options.get("gravity_mps2") is None:
        lines.append(f"gravity {experiment.gravity_mps2:.5f} m/s^2 is WGS-84 normal gravity (Somigliana) at "
                     f"{options['latitude_rad'] * c.RAD_TO_DEG:g} deg latitude, at sea level; give --gravity for the "
                     "local value (it falls by about 3.1e-6 m/s^2 per metre of altitude)")
    lines += [part.strip() for part in experiment.description.split(";") if "jitter" in part]
    return lines


FORMAT = ImportFormat(
    name="csv", inputs=("CSV_FILE",),
    summary="any delimited text log: a header naming its columns in a common way, or --columns",
    example="graph-calib import csv imu.csv --latitude-deg 48.1 --temperature 22 --out imu.h5",
    read=_read, notes=_notes,
    options=(
        Option("--columns", "e.g. t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6,temp=7: column indices counted from 0 (as in "
               "every message) or header names; several temperatures as temp:NAME=COL; segment=COL for a column "
               "that labels the record's pieces (numbers or names; each run of equal labels one segment, a "
               "segment whose clock restarts placed after the previous one). Columns not mapped are ignored. "
               "Default: read from a header line that names the columns (t/time/timestamp, gx/gyro_x/omega_x, "
               "ax/acc_x/alpha_x, temp; Kalibr's and EuRoC's layouts)", {"metavar": "MAP"}),
        Option("--gyro-units", "rad/s, deg/s (rates) or rad, deg (increments); default rad/s (or the header's)",
               {"choices": tuple(GYRO_UNITS)}),
        Option("--accel-units", "m/s^2, g (specific force) or m/s (increments); default m/s^2 (or the header's)",
               {"choices": tuple(ACCEL_UNITS)}),
        Option("--time-units", "units of the time column; default s (or the header's). samples: a sample index, "
               "t = index / --rate-hz (then required)", {"choices": tuple(TIME_UNITS)}),
        Option("--delimiter", f"column separator: a character or one of {', '.join(DELIMITERS)}; default comma",
               {"metavar": "SEP"}),
        Option("--header-lines", "lines before the data; default 0 (1 when the header names the columns)",
               {"type": int, "metavar": "N"}),
        Option("--temperature-map", "temperature channel of gyro x, y, z and accel x, y, z; default 0,0,0,0,0,0",
               {"metavar": "I,I,I,I,I,I"}),
        Option("--sort", "sort the rows by time first (a log merged out of order)", {"action": "store_const",
                                                                                       "const": True}),
        Option("--rate-hz", "nominal sample rate, Hz: required without a time column, else 1 / median spacing",
               {"type": float, "metavar": "HZ"}),
        Option("--accel-scale", "nominal accelerometer scale, counts per --accel-units (default: not counts)",
               {"type": float, "metavar": "COUNTS"}),
        Option("--gyro-scale", "nominal gyro scale, counts per --gyro-units (default: not counts)",
               {"type": float, "metavar": "COUNTS"}),
        Option("--accel-offset", "zero of the accelerometer counts (0)", {"type": float, "metavar": "COUNTS"}),
        Option("--gyro-offset", "zero of the gyro counts (0)", {"type": float, "metavar": "COUNTS"}),
    ),
)


__all__ = ["FORMAT", "import_csv", "parse_columns", "DELIMITERS", "GYRO_UNITS", "ACCEL_UNITS", "TIME_UNITS",
           "CSV_SENSOR_COLUMNS"]
