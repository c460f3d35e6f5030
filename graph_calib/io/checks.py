"""Small checks shared by the readers of :mod:`graph_calib.io`: number kinds, first failing index, message text."""

from __future__ import annotations

import numbers

import numpy as np


def _show(x):
    """``repr`` of a value for messages, numpy scalars shown as plain Python numbers."""
    if isinstance(x, np.generic):
        x = x.item()
    return repr(x)


def _is_real(x):
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def _is_int(x):
    return isinstance(x, numbers.Integral) and not isinstance(x, (bool, np.bool_))


def _first(mask):
    """Index of the first True of a boolean array along its first axis."""
    mask = np.asarray(mask)
    if mask.ndim > 1:
        mask = mask.reshape(mask.shape[0], -1).any(axis=1)
    return int(np.flatnonzero(mask)[0])
