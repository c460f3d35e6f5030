r"""Reading delimited text logs and checking what they hold, for every importer.

:func:`read_numeric_table` reads a table of numbers (blank lines and ``#``
comments skipped), all columns or only those asked for; the helpers here check
raw counts, time columns and numeric options, and name the file and the input
line of the first fault in the :class:`~graph_calib.errors.InputError` they
raise, and the column where one is at fault: columns are counted from 0, as
``--columns`` counts them.
"""

from __future__ import annotations

import csv as _csv
import math
import numbers
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError


def _show(x):
    """``repr`` of a value for messages, numpy scalars shown as plain Python numbers."""
    if isinstance(x, np.generic):
        x = x.item()
    return repr(x)


def _require_file(path):
    path = Path(path)
    if not path.exists():
        raise InputError("file not found", path=path)
    if not path.is_file():
        raise InputError("not a file", path=path)
    return path


def _strip_comment(line):
    return line.split("#", 1)[0].strip()


def _split(line, delimiter):
    """Cells of one line: a one-character delimiter with ``"`` quoting (as numpy reads it), or whitespace."""
    if delimiter is None:
        cells = line.split()
    else:
        cells = next(_csv.reader([line], delimiter=delimiter, quotechar='"'), [""])
    return [cell.strip().strip('"') for cell in cells]


def _data_rows(path, skip_lines):
    """``(line number, text)`` of every data row (1-based; blank and comment lines and the header skipped)."""
    try:
        with open(path, encoding="utf-8") as fh:
            for no, line in enumerate(fh, start=1):
                text = _strip_comment(line)
                if no > skip_lines and text:
                    yield no, text
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path=path) from None


def _data_line_numbers(path, skip_lines):
    """1-based line number of every data row (comment and blank lines skipped); error path only."""
    return np.asarray([no for no, _ in _data_rows(path, skip_lines)], dtype=np.int64)


def table_width(path, *, delimiter=None, skip_lines=0):
    """Number of columns of the first data row of a delimited text file.

    Raises
    ------
    InputError
        Missing file or no data lines.
    """
    path = _require_file(path)
    for _, text in _data_rows(path, skip_lines):
        return len(_split(text, delimiter))
    raise InputError("no data lines", path=path)


def _column(j, names):
    """``"column 3 (gz)"``: columns are counted from 0 everywhere (as ``--columns`` counts them)."""
    name = (names or {}).get(j)
    return f"column {j} ({name})" if name else f"column {j}"


def _scan(path, *, delimiter, skip_lines, n_columns, usecols, names, numbers):
    """Check every data row's width (and, if ``numbers``, its used cells) and raise at the first fault."""
    expected = n_columns
    for no, text in _data_rows(path, skip_lines):
        if not numbers and delimiter is not None and '"' not in text:
            width = text.count(delimiter) + 1  # the common case, without splitting the line
            if width == expected:
                continue
        cells = _split(text, delimiter)
        if expected is None:
            expected = len(cells)
        if len(cells) != expected:
            raise InputError(f"{len(cells)} columns, expected {expected}", path=path, dataset=f"line {no}")
        if numbers:
            for j in (range(len(cells)) if usecols is None else usecols):
                try:
                    float(cells[j])
                except ValueError:
                    raise InputError(f"non-numeric cell {_show(cells[j])} in {_column(j, names)}", path=path,
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
    path = _require_file(path)
    scan = {"delimiter": delimiter, "skip_lines": skip_lines, "n_columns": n_columns,
            "usecols": None if usecols is None else list(usecols), "names": column_names}
    try:
        data = np.loadtxt(path, delimiter=delimiter, skiprows=skip_lines, comments="#", ndmin=2,
                          dtype=np.float64, encoding="utf-8", quotechar='"', usecols=scan["usecols"])
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
        line = _data_line_numbers(path, skip_lines)[0]
        raise InputError(f"{data.shape[1]} columns, expected {n_columns}", path=path, dataset=f"line {line}")
    bad = ~np.isfinite(data)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        col = int(np.flatnonzero(bad[row])[0])
        line = _data_line_numbers(path, skip_lines)[row]
        j = col if usecols is None else list(usecols)[col]
        raise InputError(f"non-finite value {_show(data[row, col])} in {_column(j, column_names)}", path=path,
                         dataset=f"line {line}")
    return data


def _check_counts(counts, *, path, skip_lines, lo, hi, what):
    """Refuse values that cannot be raw integer counts in [lo, hi]; return the count of saturated rows."""
    bad = (counts != np.round(counts)) | (counts < lo) | (counts > hi)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        line = _data_line_numbers(path, skip_lines)[row]
        raise InputError(f"value {_show(counts[row][bad[row]][0])} is not a {what} count (an integer in [{lo}, {hi}])",
                         path=path, dataset=f"line {line}")
    return int(((counts <= lo) | (counts >= hi)).any(axis=1).sum())


def _check_time_column(t, *, path, skip_lines, unit="s"):
    """Refuse a time column that does not strictly increase, naming the line; ``t`` in the file's ``unit``."""
    bad = ~(np.diff(t) > 0)
    if bad.any():
        row = int(np.flatnonzero(bad)[0]) + 1
        line = _data_line_numbers(path, skip_lines)[row]
        raise InputError(f"time {_show(t[row])} {unit} is not after the previous row's {_show(t[row - 1])} {unit}: "
                         "rows must be in time order", path=path, dataset=f"line {line}")


def _nominal_rate(t):
    """``1 / median(diff(t))`` rounded to 6 significant digits, Hz."""
    return float(f"{1.0 / float(np.median(np.diff(t))):.6g}")


def _num(x):
    """``float(x)`` for a real number; anything else unchanged (the validator refuses it by name)."""
    return float(x) if isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_)) else x


def _positive(value, name):
    if not isinstance(_num(value), float) or not value > 0 or not math.isfinite(value):
        raise InputError(f"must be a positive number, got {_show(value)}", dataset=name)
    return float(value)


__all__ = ["read_numeric_table", "table_width"]
