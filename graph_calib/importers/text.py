r"""Reading delimited text logs and checking what they hold, for every importer.

:func:`read_numeric_table` reads a table of numbers (blank lines and ``#``
comments skipped); the helpers here check raw counts, time columns and numeric
options, and name the file and the input line of the first fault in the
:class:`~graph_calib.errors.InputError` they raise.
"""

from __future__ import annotations

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
    cells = line.split(delimiter) if delimiter is not None else line.split()
    return [cell.strip().strip('"') for cell in cells]


def _data_line_numbers(path, skip_lines):
    """1-based line number of every data row (comment and blank lines skipped); error path only."""
    numbers = []
    with open(path, encoding="utf-8") as fh:
        for no, line in enumerate(fh, start=1):
            if no > skip_lines and _strip_comment(line):
                numbers.append(no)
    return np.asarray(numbers, dtype=np.int64)


def _diagnose(path, *, delimiter, skip_lines, n_columns):
    """Find the first line that does not parse and raise an InputError naming it."""
    expected = n_columns
    with open(path, encoding="utf-8") as fh:
        for no, line in enumerate(fh, start=1):
            text = _strip_comment(line)
            if no <= skip_lines or not text:
                continue
            cells = _split(text, delimiter)
            if expected is None:
                expected = len(cells)
            if len(cells) != expected:
                raise InputError(f"{len(cells)} columns, expected {expected}", path=path, dataset=f"line {no}")
            for j, cell in enumerate(cells):
                try:
                    float(cell)
                except ValueError:
                    raise InputError(f"non-numeric cell {_show(cell)} in column {j + 1}", path=path,
                                     dataset=f"line {no}") from None
    raise InputError("cannot be read as a table of numbers", path=path)


def read_numeric_table(path, *, delimiter=None, skip_lines=0, n_columns=None):
    """Read a delimited text file of numbers.

    Blank lines and ``#`` comments are skipped.

    Parameters
    ----------
    path : str or Path
    delimiter : str or None
        Column separator; None for any whitespace.
    skip_lines : int
        Header lines to skip before the data.
    n_columns : int or None
        Required number of columns (None: any, but the same on every line).

    Returns
    -------
    ndarray, shape (R, C)
        float64.

    Raises
    ------
    InputError
        Missing file, no data, a wrong column count, a non-numeric cell or a
        non-finite value, naming the file and the line.
    """
    path = _require_file(path)
    try:
        data = np.loadtxt(path, delimiter=delimiter, skiprows=skip_lines, comments="#", ndmin=2,
                          dtype=np.float64, encoding="utf-8", quotechar='"')
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path=path) from None
    except ValueError:
        _diagnose(path, delimiter=delimiter, skip_lines=skip_lines, n_columns=n_columns)
        raise  # pragma: no cover  (_diagnose always raises)
    if data.size == 0:
        raise InputError("no data lines", path=path)
    if n_columns is not None and data.shape[1] != n_columns:
        line = _data_line_numbers(path, skip_lines)[0]
        raise InputError(f"{data.shape[1]} columns, expected {n_columns}", path=path, dataset=f"line {line}")
    bad = ~np.isfinite(data)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        col = int(np.flatnonzero(bad[row])[0])
        line = _data_line_numbers(path, skip_lines)[row]
        raise InputError(f"non-finite value {_show(data[row, col])} in column {col + 1}", path=path, dataset=f"line {line}")
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


def _check_time_column(t, *, path, skip_lines):
    bad = ~(np.diff(t) > 0)
    if bad.any():
        row = int(np.flatnonzero(bad)[0]) + 1
        line = _data_line_numbers(path, skip_lines)[row]
        raise InputError(f"time {_show(t[row])} s is not after the previous one {_show(t[row - 1])} s", path=path,
                         dataset=f"line {line}")


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


__all__ = ["read_numeric_table"]
