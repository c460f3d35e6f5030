"""Results into stitched curves: every element of a result as a subrange point, then :func:`stitch`.

The method is described in :mod:`graph_calib.stitching`.
"""

from __future__ import annotations

import numpy as np

from graph_calib.sensors import params
from graph_calib.sensors.effects import REGISTRY
from graph_calib.stitching.fits import fit_element
from graph_calib.stitching.pieces import Stitched, SubrangePoint, family, is_stitched, sensor_of


def _cov_block(result, names):
    """Covariance of ``names`` from a result (its full matrix, else its sigmas)."""
    if result.covariance is not None and result.covariance_names is not None:
        idx = {n: i for i, n in enumerate(result.covariance_names)}
        if all(n in idx for n in names):
            ii = [idx[n] for n in names]
            return np.asarray(result.covariance, dtype=float)[np.ix_(ii, ii)]
    return np.diag([float(result.sigmas[n]) ** 2 for n in names])


def result_points(result, *, name=None, sensor_ranges=None, values=None):
    """Every stitched element of one result as a :class:`SubrangePoint`, ``{flat element: point}``.

    Parameters
    ----------
    result : graph_calib.records.experiment.Result
    name : str, optional
        Label of the points (default: the result's source).
    sensor_ranges : array_like (6, 2), optional
        Temperature range of each sensor (default: the result's range for all).  With them, an element of
        a temperature-dependent parameter that the result holds without its temperature coefficients (a
        calibration at constant temperature) is placed at the middle of its own sensor's range, where its
        value was measured, not at the result's ``T_ref`` (the mean of all six sensors, which a sensor's
        self-heating puts tenths of a degree away).
    values : dict, optional
        Values to use instead of ``result.values`` (e.g. with a truth's curvature remainder added).
        Coefficients are taken in order (value, ``_tc``, ``_tc2``) up to the first one absent; the
        covariance comes from the result (zero without sigmas: a truth).
    """
    values = result.values if values is None else values
    rg = (np.tile(np.asarray(result.temperature_range_degC, dtype=float), (6, 1)) if sensor_ranges is None
          else np.asarray(sensor_ranges, dtype=float).reshape(6, 2))
    out = {}
    for flat in values:
        try:
            parameter, el = params.split_element_name(flat)
        except KeyError:
            continue
        if not is_stitched(parameter):
            continue
        coef_names = [flat]
        for _, cn in sorted(family(parameter)[1].items()):
            cn = cn if el is None else f"{cn}.{el}"
            if cn not in values:
                break
            coef_names.append(cn)
        coef = np.array([float(values[n]) for n in coef_names])
        cov = _cov_block(result, coef_names) if result.sigmas is not None else np.zeros((coef.size, coef.size))
        s = sensor_of(flat)
        t_range = tuple(float(v) for v in (rg[s] if s is not None else rg.mean(axis=0)))
        t_at = float(result.t_ref_degC)
        if coef.size == 1 and family(parameter)[1] and s is not None and sensor_ranges is not None:
            # a value without its temperature coefficients (a constant-temperature step) is the element at its
            # own sensor's temperature, which sits away from the experiment's T_ref (the mean of all six)
            t_at = 0.5 * (t_range[0] + t_range[1])
        out[flat] = SubrangePoint(name or result.source, t_at, coef, cov, t_range)
    return out


def stitch(results, *, names=None, sensor_ranges=None, solver=None):
    """Stitch per-subrange results of one IMU into a model of every IMU parameter over temperature.

    Parameters
    ----------
    results : sequence of graph_calib.records.experiment.Result
        One per subrange (same solver), each with sigmas and preferably its covariance.
    names : sequence of str, optional
        Experiment names (default: the results' sources).
    sensor_ranges : sequence of array_like (6, 2), optional
        Per result, the lowest and highest temperature of each sensor (:data:`SENSORS`),
        degC.  Default: the result's ``temperature_range_degC`` for every sensor.
    solver : str, optional
        Label (default: the first result's solver).

    Returns
    -------
    Stitched
    """
    results = list(results)
    if not results:
        raise ValueError("nothing to stitch: no results")
    names = list(names) if names is not None else [r.source for r in results]
    if len(set(names)) != len(names):
        raise ValueError(f"experiment names must be unique, got {names}")
    ranges = []
    for i, r in enumerate(results):
        if sensor_ranges is not None and sensor_ranges[i] is not None:
            ranges.append(np.asarray(sensor_ranges[i], dtype=float).reshape(6, 2))
        else:
            ranges.append(None)
    points = {}
    for r, nm, rg in zip(results, names, ranges):
        if r.sigmas is None:
            raise ValueError(f"{nm}: a result without sigmas (truth?) cannot be stitched")
        for flat, pt in result_points(r, name=nm, sensor_ranges=rg).items():
            points.setdefault(flat, []).append(pt)
    curves = {}
    order = {n: i for i, n in enumerate(p.name for p in REGISTRY)}
    for flat in sorted(points, key=lambda f: (order[params.split_element_name(f)[0]], f)):
        curves[flat] = fit_element(flat, points[flat])
    ordered = [nm for _, nm in sorted(zip([r.t_ref_degC for r in results], names))]
    return Stitched(solver=solver or results[0].solver, subranges=tuple(ordered), curves=curves)


__all__ = ["result_points", "stitch"]
