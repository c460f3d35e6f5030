"""Small checks shared by the readers of :mod:`graph_calib.io`: number kinds, first failing index, message text."""

from __future__ import annotations

import numbers
import re
import sys

import numpy as np


def _show(x):
    """``repr`` of a value for messages, numpy scalars shown as plain Python numbers, on one line.

    numpy wraps the ``repr`` of a long array over several lines; a message is one line (cli.md).
    """
    if isinstance(x, np.generic):
        x = x.item()
    return re.sub(r"\s*\n\s*", " ", repr(x))


def _is_real(x):
    """A real number that a float can hold: an integer beyond the float range (JSON and TOML allow any
    number of digits) is not, so that ``math.isfinite`` never overflows on it."""
    return (isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))
            and not (isinstance(x, numbers.Integral) and abs(x) > sys.float_info.max))


def _is_int(x):
    return isinstance(x, numbers.Integral) and not isinstance(x, (bool, np.bool_))


def _first(mask):
    """Index of the first True of a boolean array along its first axis."""
    mask = np.asarray(mask)
    if mask.ndim > 1:
        mask = mask.reshape(mask.shape[0], -1).any(axis=1)
    return int(np.flatnonzero(mask)[0])


def version_problem(version, known):
    """What is wrong with a file's ``version`` for a reader that knows version ``known`` (None when nothing): a
    version stored as text or as a fraction is not a version number (``'1'`` is not 1)."""
    if not _is_int(version):
        return f"must be the integer {known}, got {type(version).__name__} {_show(version)}"
    if version != known:
        return f"version {_show(version)} is not supported (this reader knows version {known})"
    return None
