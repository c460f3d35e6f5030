r"""The residual-series file (HDF5): :func:`write_residuals`, :func:`read_residuals`.

A solver's residual time series per factor kind, written by ``graph-calib
calibrate --residuals`` and by every campaign task; not part of the shared spec
(``docs/data-format.md`` gives the layout).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from graph_calib.errors import InputError
from graph_calib.io.atomic import atomic_path

#: ``format`` attribute of a residual-series file.
RESIDUALS_FORMAT = "imu-calibration-residuals"


def write_residuals(path, series, *, solver, source, kind="whitened residual"):
    """Write a solver's residual time series atomically (HDF5), for residual analysis elsewhere.

    Layout: root attributes ``format = "imu-calibration-residuals"``, ``version = 1``,
    ``solver``, ``source`` (the experiment file name) and ``quantity`` (``kind``:
    ``"whitened residual"`` for the factor graph, ``"normalised innovation"`` for the
    filter); one group per factor kind (``rotation``, ``gravity``, ``encoder``) with
    ``t`` (F,) float64, s, on the experiment's clock (keyframe start for gravity,
    keyframe end for rotation, reading time for encoder) and ``values`` (F, 3)
    float64, dimensionless (residual over its one-sigma noise, per axis).

    Parameters
    ----------
    path : str or Path
    series : dict
        ``{kind: (t (F,), values (F, 3))}``.
    solver, source, kind : str
    """
    path = Path(path)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = RESIDUALS_FORMAT
            f.attrs["version"] = 1
            f.attrs["solver"] = str(solver)
            f.attrs["source"] = str(source)
            f.attrs["quantity"] = str(kind)
            for name, (t, v) in series.items():
                t = np.asarray(t, dtype=np.float64)
                v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
                if t.shape != (v.shape[0],):
                    raise ValueError(f"{name}: {t.shape[0]} times for {v.shape[0]} residual rows")
                g = f.create_group(name)
                g.create_dataset("t", data=t)
                g.create_dataset("values", data=v)


def read_residuals(path):
    """``(attributes dict, {kind: (t, values)})`` of a file written by :func:`write_residuals`."""
    path = Path(path)
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != RESIDUALS_FORMAT:
            raise InputError(f"not a residual-series file (format {f.attrs.get('format')!r})", path=path)
        attrs = {k: (v.decode() if isinstance(v, bytes) else v.item() if hasattr(v, "item") else v)
                 for k, v in f.attrs.items()}
        return attrs, {name: (g["t"][()], g["values"][()]) for name, g in f.items()}
