r"""The compensation table: every temperature-dependent element on a temperature grid, and the constants.

What an INS loads.  On one grid ``T_0 < T_1 < ... < T_{G-1}`` (degC, usually a
regular step), each temperature-dependent element ``p`` holds its values
``p_k`` and one-sigma band ``sigma_k`` at ``T_k``; each constant element one
value and one sigma.  Values are SI, the units of ``docs/model.md`` (rad/s, 1,
rad, m/s^2).

The interpolation the table assumes (:func:`interpolate`)
    Each element at **its own sensor's temperature** ``T`` (the record's
    ``temperature_map`` channel of the sensor the element belongs to:
    :func:`graph_calib.stitching.sensor_of`), **linear between grid points**:
    with ``T_j <= T <= T_{j+1}`` and ``w = (T - T_j) / (T_{j+1} - T_j)``,
    ``p(T) = (1 - w) p_j + w p_{j+1}``; **outside the grid the end value is held**
    (``T < T_0`` gives ``p_0``, ``T > T_{G-1}`` gives ``p_{G-1}``).  At a grid
    temperature this is the grid value itself, exactly.  The sigma band is
    interpolated the same way (an approximation of the band between grid points).

Applying it
    The element values at each sample's temperatures make one calibration vector
    per sample, inverted through the one sensor model
    (:meth:`graph_calib.compensation.elements.ElementCompensation.correct`).

The document (:meth:`CompensationTable.to_dict`) has ``format``
:data:`TABLE_FORMAT` and ``version`` :data:`TABLE_VERSION`; a newer version is
refused.  Its layout is in ``docs/compensation.md``; the file formats (JSON,
CSV, C header) are :mod:`graph_calib.compensation.formats`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graph_calib.compensation.elements import (
    BENCH_PARAMETERS, BENCH_REASON, ElementCompensation, element_order, sensor_name, table_element, unit_of,
)
from graph_calib.errors import InputError
from graph_calib.stitching import sensor_of

#: ``format`` of a compensation table.
TABLE_FORMAT = "imu-compensation-table"
#: ``version`` of the table this code writes; it reads this one and older.
TABLE_VERSION = 1
#: The interpolation rule, in words, as every table states it.
INTERPOLATION = ("linear between grid points, each element at its own sensor's temperature "
                 "(the record's temperature_map); outside the grid the end value is held")


def interpolate(grid, values, T):
    """The table's interpolation: linear between grid points, end values held outside.

    Parameters
    ----------
    grid : ndarray, shape (G,)
        Strictly increasing temperatures, degC (G >= 1).
    values : ndarray, shape (G,)
    T : array_like
        Temperatures, degC.

    Returns
    -------
    ndarray, shape of ``T``
        ``(1 - w) values[j] + w values[j+1]`` with ``grid[j] <= T <= grid[j+1]``,
        ``w = (T - grid[j]) / (grid[j+1] - grid[j])``; the grid value itself at a grid
        temperature.

    >>> float(interpolate(np.array([0.0, 10.0]), np.array([1.0, 3.0]), 2.5))
    1.5
    >>> interpolate(np.array([0.0, 10.0]), np.array([1.0, 3.0]), [-5.0, 10.0, 99.0]).tolist()
    [1.0, 3.0, 3.0]
    """
    grid = np.asarray(grid, dtype=float)
    values = np.asarray(values, dtype=float)
    T = np.asarray(T, dtype=float)
    if grid.size == 1:
        return np.full(T.shape, values[0])
    Tc = np.clip(T, grid[0], grid[-1])
    j = np.clip(np.searchsorted(grid, Tc, side="right") - 1, 0, grid.size - 2)
    w = (Tc - grid[j]) / (grid[j + 1] - grid[j])
    return (1.0 - w) * values[j] + w * values[j + 1]


@dataclass(frozen=True)
class TableCurve:
    """One temperature-dependent element of a table: values and one-sigma band on the table's grid (SI)."""

    values: np.ndarray
    sigmas: np.ndarray
    calibrated_range_degC: tuple = (float("nan"), float("nan"))
    interpolation_error: dict = field(default_factory=dict)

    @property
    def t_span(self):
        """:attr:`calibrated_range_degC`, under the name :func:`graph_calib.evaluation.validation.validate` reads (the
        stitched curves' ``t_span``): a window counts as inside where its sensor temperature lies in it (none
        does when the table states no range)."""
        return self.calibrated_range_degC


@dataclass(frozen=True, eq=False)
class CompensationTable(ElementCompensation):
    """A compensation table (module docstring): grid, temperature-dependent elements, constants.

    Attributes
    ----------
    grid_degC : ndarray, shape (G,)
        Strictly increasing temperatures, degC.
    curves : dict
        ``{flat element: TableCurve}``: values and sigmas on the grid.
    constants : dict
        ``{flat element: (value, sigma)}``.
    info : dict
        Provenance and checks, JSON-ready: ``imu_id``, ``solver``, ``stitch_model``,
        ``source`` (the campaign), ``subranges``, ``calibrated_range_degC``, ...

    Examples
    --------
    >>> tab = CompensationTable(np.array([20.0, 30.0]),
    ...                         {"gyro.bias.x": TableCurve(np.array([1e-7, 3e-7]), np.array([1e-9, 1e-9]))},
    ...                         {"gyro.misalignment.xy": (2e-5, 1e-6)})
    >>> vals = tab.element_values([[25.0, 0, 0, 0, 0, 0]])
    >>> float(vals["gyro.bias.x"][0]), float(vals["gyro.misalignment.xy"][0])
    (2e-07, 2e-05)
    """

    grid_degC: np.ndarray
    curves: dict
    constants: dict
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        grid = np.array(self.grid_degC, dtype=float)
        if grid.ndim != 1 or grid.size < 1 or not np.all(np.isfinite(grid)) or np.any(np.diff(grid) <= 0):
            raise ValueError("grid_degC must be a non-empty, finite, strictly increasing 1-D array")
        grid.setflags(write=False)
        object.__setattr__(self, "grid_degC", grid)
        curves = {}
        for name in element_order(list(self.curves)):
            c = self.curves[name]
            v = np.array(c.values, dtype=float)
            s = np.array(c.sigmas, dtype=float)
            if v.shape != grid.shape or s.shape != grid.shape:
                raise ValueError(f"{name}: values and sigmas must have the grid's shape {grid.shape}")
            for a in (v, s):
                a.setflags(write=False)
            curves[name] = TableCurve(v, s, tuple(float(t) for t in c.calibrated_range_degC),
                                      dict(c.interpolation_error))
        object.__setattr__(self, "curves", curves)
        object.__setattr__(self, "constants", {n: (float(self.constants[n][0]), float(self.constants[n][1]))
                                               for n in element_order(list(self.constants))})
        bad = [n for n in list(curves) + list(self.constants) if not table_element(n)]
        if bad:
            raise ValueError(f"not elements of a compensation: {bad}")
        no_sensor = [n for n in curves if sensor_of(n) is None]
        if no_sensor:
            raise ValueError(f"temperature-dependent elements need a sensor: {no_sensor}")

    # -- ElementCompensation -----------------------------------------------------------

    def curve_elements(self):
        return list(self.curves)

    def curve_values(self, element, T):
        c = self.curves[element]
        return interpolate(self.grid_degC, c.values, T), interpolate(self.grid_degC, c.sigmas, T)

    def valid_range(self, element):
        return float(self.grid_degC[0]), float(self.grid_degC[-1])

    def describe(self):
        i = self.info
        what = f"{i.get('solver', '?')} {i.get('stitch_model', '?')}"
        return (f"corrected with the compensation table of {i.get('imu_id') or 'an unnamed IMU'} ({what}, "
                f"{self.grid_degC[0]:g}..{self.grid_degC[-1]:g} degC, from {i.get('source') or '?'})")

    # -- what graph_calib.evaluation.validation.validate reads ----------------------------------------

    def evaluate(self, T_sensors, model=None):
        """Every element at the sensor temperatures of each row, ``{flat element: (N,)}``, SI: the table as
        :func:`graph_calib.evaluation.validation.validate` evaluates a calibration.

        The values :meth:`element_values` gives, which are those :meth:`correct` (``graph-calib apply``)
        uses: each element interpolated (:func:`interpolate`) at its own sensor's temperature of the row,
        end values held outside the grid; constants as they are.

        Parameters
        ----------
        T_sensors : array_like, shape (N, 6)
            Temperatures of gyro x, y, z and accel x, y, z, degC (a validation window's means).
        model : str, optional
            The stitched model; a table holds one (``info["stitch_model"]``), and asking for
            another is a ``ValueError`` rather than a silent substitute.
        """
        self._check_model(model)
        return self.element_values(T_sensors)

    def element_sigmas(self, T_sensors, model=None):
        """One sigma of every element at the sensor temperatures of each row, ``{flat element: (N,)}``
        (the bands interpolated as the values are; ``model`` as in :meth:`evaluate`)."""
        self._check_model(model)
        return super().element_sigmas(T_sensors)

    def _check_model(self, model):
        held = self.info.get("stitch_model")
        if model is not None and held is not None and model != held:
            raise ValueError(f"this table holds the {held} stitched model, not {model!r} "
                             "(export the campaign again with --model)")

    # -- the document ------------------------------------------------------------------

    def to_dict(self):
        """JSON-ready document (``docs/compensation.md``): format, version, grid, elements, constants, info."""
        doc = {"format": TABLE_FORMAT, "version": TABLE_VERSION}
        doc.update({k: v for k, v in self.info.items() if k not in ("format", "version")})
        doc["interpolation"] = INTERPOLATION
        doc["grid_degC"] = self.grid_degC.tolist()
        doc["elements"] = {
            n: {"unit": unit_of(n), "sensor": sensor_name(n), "values": c.values.tolist(), "sigmas": c.sigmas.tolist(),
                "calibrated_range_degC": list(c.calibrated_range_degC),
                "interpolation_error": c.interpolation_error}
            for n, c in self.curves.items()}
        doc["constants"] = {n: {"unit": unit_of(n), "sensor": sensor_name(n), "value": v, "sigma": s}
                            for n, (v, s) in self.constants.items()}
        doc["not_in_table"] = {p: BENCH_REASON for p in BENCH_PARAMETERS}
        return doc

    @classmethod
    def from_dict(cls, doc, *, path=None):
        """The table of a :meth:`to_dict` document.

        Raises
        ------
        graph_calib.errors.InputError
            Naming ``path`` and the key: not a table, a newer version, an unknown
            element, a unit or sensor other than graph-calib's, values not on the grid,
            a non-finite number.
        """
        def bad(message, key=None):
            return InputError(message, path=path, dataset=key)

        if not isinstance(doc, dict):
            raise bad(f"a compensation table is a JSON object, got {type(doc).__name__}")
        check_header(doc.get("format"), doc.get("version"), path=path)
        grid = _numbers(doc.get("grid_degC"), "grid_degC", path)
        if grid.ndim != 1 or grid.size < 1 or np.any(np.diff(grid) <= 0):
            raise bad("must be a non-empty list of strictly increasing temperatures", "grid_degC")
        curves, constants = {}, {}
        for key, section in (("elements", doc.get("elements", {})), ("constants", doc.get("constants", {}))):
            if not isinstance(section, dict):
                raise bad("must be an object {element: {...}}", key)
            for name, entry in section.items():
                where = f"{key}.{name}"
                check_element(name, entry.get("unit") if isinstance(entry, dict) else None,
                              entry.get("sensor") if isinstance(entry, dict) else None, where=where, path=path)
                if key == "elements":
                    v = _numbers(entry.get("values"), f"{where}.values", path)
                    s = _numbers(entry.get("sigmas"), f"{where}.sigmas", path)
                    for a, k in ((v, "values"), (s, "sigmas")):
                        if a.shape != grid.shape:
                            raise bad(f"{a.size} numbers for a grid of {grid.size}", f"{where}.{k}")
                    if sensor_of(name) is None:
                        raise bad("an element without a sensor cannot depend on temperature", where)
                    rng = entry.get("calibrated_range_degC") or [float("nan")] * 2
                    curves[name] = TableCurve(v, s, tuple(rng), entry.get("interpolation_error") or {})
                else:
                    v = _numbers(entry.get("value"), f"{where}.value", path)
                    s = _numbers(entry.get("sigma"), f"{where}.sigma", path)
                    if v.ndim or s.ndim:
                        raise bad("value and sigma must be numbers", where)
                    constants[name] = (float(v), float(s))
        both = sorted(set(curves) & set(constants))
        if both:
            raise bad(f"{', '.join(both)} both temperature-dependent and constant", "constants")
        if not curves and not constants:
            raise bad("no elements and no constants", "elements")
        keep = ("format", "version", "interpolation", "grid_degC", "elements", "constants", "not_in_table",
                "written_by")
        return cls(grid, curves, constants, info={k: v for k, v in doc.items() if k not in keep})


def check_header(fmt, version, *, path=None):
    """Refuse what is not a compensation table of a version this graph-calib reads (:class:`InputError`)."""
    if fmt != TABLE_FORMAT:
        raise InputError(f"format is {fmt!r}, expected {TABLE_FORMAT!r}", path=path, dataset="format")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise InputError(f"version {version!r} is not a table version (a positive integer)", path=path,
                         dataset="version")
    if version > TABLE_VERSION:
        raise InputError(f"version {version} is newer than this graph-calib reads (up to {TABLE_VERSION}); read it "
                         "with the graph-calib that wrote it, or a newer one", path=path, dataset="version")


def check_element(name, unit, sensor, *, where, path=None):
    """Refuse an element graph-calib does not know, or whose unit or sensor differs from graph-calib's."""
    if not table_element(name):
        raise InputError(f"{name!r} is not an element of a compensation (a sensor-model parameter, not a "
                         "temperature coefficient)", path=path, dataset=where)
    if unit != unit_of(name):
        raise InputError(f"unit {unit!r}, graph-calib's is {unit_of(name)!r}", path=path, dataset=where)
    if sensor != sensor_name(name):
        raise InputError(f"sensor {sensor!r}, graph-calib evaluates {name} at {sensor_name(name)!r}", path=path,
                         dataset=where)


def _numbers(value, key, path):
    """``value`` as a finite float array (a number or a list of numbers), else :class:`InputError`."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) or (
        isinstance(value, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    a = np.asarray(value, dtype=float) if ok else None
    if a is None or not np.all(np.isfinite(a)):
        raise InputError("must be a finite number or a list of finite numbers", path=path, dataset=key)
    return a


__all__ = ["TABLE_FORMAT", "TABLE_VERSION", "INTERPOLATION", "interpolate", "TableCurve", "CompensationTable",
           "check_header", "check_element"]
