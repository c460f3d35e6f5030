r"""The parsing helpers every importer shares, public in this one place.

Reading delimited text
    :func:`read_numeric_table` reads a table of numbers (blank lines and ``#``
    comments skipped), all columns or only those asked for; :func:`table_width`,
    :func:`split_cells`, :func:`data_line_numbers` name the input lines.
Checking what a log holds
    :func:`check_counts` (raw integer counts), :func:`check_time_column` (rows
    in time order), :func:`nominal_rate`, :func:`positive`, :func:`require_file`,
    :func:`show` and :func:`as_float` for messages and options.  Every
    :class:`~graph_calib.errors.InputError` raised here names the file and the
    input line of the first fault, and the column where one is at fault: columns
    are counted from 0, as ``--columns`` counts them.
Building the experiment
    Rates become increments over the interval each sample closes
    (:func:`intervals`); a log without temperature gets the one channel
    :data:`ASSUMED_TEMPERATURE_NAME` (:func:`constant_temperature`);
    :func:`normal_gravity` gives gravity from the latitude when the local value is
    not known; :func:`build_experiment` assembles the experiment and validates it
    with :func:`graph_calib.io.validate_experiment`, naming the input line of a rule
    broken at a sample.
"""

from __future__ import annotations

import csv as _csv
import math
import numbers
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError
from graph_calib.io import validate_experiment
from graph_calib.records.experiment import Experiment


def show(x):
    """``repr`` of a value for messages, numpy scalars shown as plain Python numbers."""
    if isinstance(x, np.generic):
        x = x.item()
    return repr(x)


def require_file(path):
    path = Path(path)
    if not path.exists():
        raise InputError("file not found", path=path)
    if not path.is_file():
        raise InputError("not a file", path=path)
    return path


def _strip_comment(line):
    return line.split("#", 1)[0].strip()


#: The column separators a text log may use, by the name ``--delimiter`` takes (None: any whitespace).
DELIMITERS = {"comma": ",", "semicolon": ";", "tab": "\t", "space": " ", "whitespace": None}


def split_cells(line, delimiter):
    """Cells of one line: a one-character delimiter with ``"`` quoting (as numpy reads it), or whitespace."""
    if delimiter is None:
        cells = line.split()
    else:
        cells = next(_csv.reader([line], delimiter=delimiter, quotechar='"'), [""])
    return [cell.strip().strip('"') for cell in cells]


def data_rows(path, skip_lines):
    """``(line number, text)`` of every data row (1-based; blank and comment lines and the header skipped)."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for no, line in enumerate(fh, start=1):
                text = _strip_comment(line)
                if no > skip_lines and text:
                    yield no, text
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path=path) from None


def data_line_numbers(path, skip_lines):
    """1-based line number of every data row (comment and blank lines skipped); error path only."""
    return np.asarray([no for no, _ in data_rows(path, skip_lines)], dtype=np.int64)


def table_width(path, *, delimiter=None, skip_lines=0):
    """Number of columns of the first data row of a delimited text file.

    Raises
    ------
    InputError
        Missing file or no data lines.
    """
    path = require_file(path)
    for _, text in data_rows(path, skip_lines):
        return len(split_cells(text, delimiter))
    raise InputError("no data lines", path=path)


def _column(j, names):
    """``"column 3 (gz)"``: columns are counted from 0 everywhere (as ``--columns`` counts them)."""
    name = (names or {}).get(j)
    return f"column {j} ({name})" if name else f"column {j}"


def _scan(path, *, delimiter, skip_lines, n_columns, usecols, names, numbers):
    """Check every data row's width (and, if ``numbers``, its used cells) and raise at the first fault."""
    expected = n_columns
    for no, text in data_rows(path, skip_lines):
        if not numbers and delimiter is not None and '"' not in text:
            width = text.count(delimiter) + 1  # the common case, without splitting the line
            if width == expected:
                continue
        cells = split_cells(text, delimiter)
        if expected is None:
            expected = len(cells)
        if len(cells) != expected:
            raise InputError(f"{len(cells)} columns, expected {expected}", path=path, dataset=f"line {no}")
        if numbers:
            for j in (range(len(cells)) if usecols is None else usecols):
                try:
                    float(cells[j])
                except ValueError:
                    raise InputError(f"non-numeric cell {show(cells[j])} in {_column(j, names)}", path=path,
                                     dataset=f"line {no}") from None


def read_numeric_table(path, *, delimiter=None, skip_lines=0, n_columns=None, usecols=None, column_names=None):
    """Read a delimited text file of numbers.

    Blank lines and ``#`` comments are skipped.  Every data row must have the
    same number of columns; only the columns read (``usecols``) must hold numbers.

    Parameters
    ----------
    path : str or Path
    delimiter : str or None
        One-character column separator (``"`` quotes a cell); None for any whitespace.
    skip_lines : int
        Header lines to skip before the data.
    n_columns : int or None
        Required number of columns (None: any, but the same on every line).
    usecols : sequence of int or None
        Columns to read, counted from 0, in the order wanted; the others may
        hold anything (text included).  None: all, and all must be numbers.
    column_names : dict or None
        ``{column: name}`` to name a column in messages (``"column 3 (gz)"``).

    Returns
    -------
    ndarray, shape (R, C)
        float64; C is ``len(usecols)`` when given.

    Raises
    ------
    InputError
        Missing file, no data, a wrong column count, a non-numeric cell or a
        non-finite value in a column read, naming the file, the line and the
        column (counted from 0).
    """
    path = require_file(path)
    scan = {"delimiter": delimiter, "skip_lines": skip_lines, "n_columns": n_columns,
            "usecols": None if usecols is None else list(usecols), "names": column_names}
    try:
        data = np.loadtxt(path, delimiter=delimiter, skiprows=skip_lines, comments="#", ndmin=2,
                          dtype=np.float64, encoding="utf-8-sig", quotechar='"', usecols=scan["usecols"])
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path=path) from None
    except ValueError:
        _scan(path, numbers=True, **scan)
        raise InputError("cannot be read as a table of numbers", path=path) from None
    if data.size == 0:
        raise InputError("no data lines", path=path)
    if usecols is not None:
        _scan(path, numbers=False, **scan)  # numpy does not check the width of rows wider than the columns read
    elif n_columns is not None and data.shape[1] != n_columns:
        line = data_line_numbers(path, skip_lines)[0]
        raise InputError(f"{data.shape[1]} columns, expected {n_columns}", path=path, dataset=f"line {line}")
    bad = ~np.isfinite(data)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        col = int(np.flatnonzero(bad[row])[0])
        line = data_line_numbers(path, skip_lines)[row]
        j = col if usecols is None else list(usecols)[col]
        raise InputError(f"non-finite value {show(data[row, col])} in {_column(j, column_names)}", path=path,
                         dataset=f"line {line}")
    return data


def check_counts(counts, *, path, skip_lines, lo, hi, what):
    """Refuse values that cannot be raw integer counts in [lo, hi]; return the count of saturated rows."""
    bad = (counts != np.round(counts)) | (counts < lo) | (counts > hi)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        line = data_line_numbers(path, skip_lines)[row]
        raise InputError(f"value {show(counts[row][bad[row]][0])} is not a {what} count (an integer in [{lo}, {hi}])",
                         path=path, dataset=f"line {line}")
    return int(((counts <= lo) | (counts >= hi)).any(axis=1).sum())


def check_time_column(t, *, path, skip_lines, unit="s"):
    """Refuse a time column that does not strictly increase, naming the line; ``t`` in the file's ``unit``."""
    bad = ~(np.diff(t) > 0)
    if bad.any():
        row = int(np.flatnonzero(bad)[0]) + 1
        line = data_line_numbers(path, skip_lines)[row]
        raise InputError(f"time {show(t[row])} {unit} is not after the previous row's {show(t[row - 1])} {unit}: "
                         "rows must be in time order", path=path, dataset=f"line {line}")


def nominal_rate(t):
    """``1 / median(diff(t))`` rounded to 6 significant digits, Hz."""
    return float(f"{1.0 / float(np.median(np.diff(t))):.6g}")


def as_float(x):
    """``float(x)`` for a real number; anything else unchanged (the validator refuses it by name)."""
    return float(x) if isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_)) else x


def positive(value, name):
    if not isinstance(as_float(value), float) or not value > 0 or not math.isfinite(value):
        raise InputError(f"must be a positive number, got {show(value)}", dataset=name)
    return float(value)




#: Name of the temperature channel of a log that recorded no temperature.
ASSUMED_TEMPERATURE_NAME = "assumed_constant"


#: WGS-84 normal gravity (Somigliana's closed formula): equatorial gravity, m/s^2, the
#: constant k = (b g_p) / (a g_e) - 1, and the first eccentricity squared (NIMA TR8350.2).
WGS84_GRAVITY_EQUATOR_MPS2 = 9.7803253359
WGS84_SOMIGLIANA_K = 0.00193185265241
WGS84_E2 = 0.00669437999013


def normal_gravity(latitude_rad):
    """WGS-84 normal gravity on the ellipsoid (at sea level), m/s^2.

    Somigliana's formula ``g = g_e (1 + k sin^2 phi) / sqrt(1 - e^2 sin^2 phi)``:
    9.7803 m/s^2 at the equator, 9.8322 at the poles.  It ignores altitude
    (about -3.1e-6 m/s^2 per metre) and local anomalies (up to a few 1e-4 m/s^2).

    Parameters
    ----------
    latitude_rad : float
        Geodetic latitude, rad.

    Returns
    -------
    float
    """
    s2 = math.sin(latitude_rad) ** 2
    return WGS84_GRAVITY_EQUATOR_MPS2 * (1.0 + WGS84_SOMIGLIANA_K * s2) / math.sqrt(1.0 - WGS84_E2 * s2)


def intervals(t, rate_hz, segment=None):
    """Interval each sample closes, s: ``diff(t)``, and the nominal period at the first sample of each segment."""
    dt = np.empty_like(t)
    dt[0] = 1.0 / rate_hz
    dt[1:] = np.diff(t)
    if segment is not None:
        dt[1:][np.diff(segment) != 0] = 1.0 / rate_hz
    return dt


def build_experiment(*, t, dtheta, dv, temperature, names, temperature_map, rate_hz, latitude_rad, gravity_mps2,
           imu_id, description, source, skip_lines, segment=None):
    """Assemble and validate; a rule broken at a sample names the input line too."""
    exp = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=temperature, temperature_names=tuple(names),
        temperature_map=np.asarray(temperature_map, dtype=np.int64), rate_hz=as_float(rate_hz),
        latitude_rad=as_float(latitude_rad), gravity_mps2=as_float(gravity_mps2), imu_id=imu_id,
        description=description, table=None, source=str(source), segment=segment,
    )
    try:
        validate_experiment(exp, path=source)
    except InputError as exc:
        if exc.index is None or skip_lines is None:
            raise
        line = data_line_numbers(source, skip_lines)[exc.index]
        err = InputError(f"{exc} (input line {line})")
        err.path, err.dataset, err.index = exc.path, exc.dataset, exc.index
        raise err from None
    return exp


def constant_temperature(n, temperature_degC):
    if not isinstance(as_float(temperature_degC), float) or not math.isfinite(temperature_degC):
        raise InputError(f"assumed temperature must be a finite number of degC, got {show(temperature_degC)}",
                         dataset="temperature_degC")
    return np.full((n, 1), float(temperature_degC)), (ASSUMED_TEMPERATURE_NAME,)


__all__ = ["read_numeric_table", "table_width", "split_cells", "data_rows", "data_line_numbers", "require_file", "show",
           "as_float", "positive", "check_counts", "check_time_column", "nominal_rate", "intervals",
           "constant_temperature", "build_experiment", "normal_gravity", "ASSUMED_TEMPERATURE_NAME", "DELIMITERS"]
