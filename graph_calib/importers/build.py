r"""Building the imported :class:`~graph_calib.records.experiment.Experiment` and validating it.

Rates become increments over the interval each sample closes (:func:`_intervals`);
a log without temperature gets the one channel :data:`ASSUMED_TEMPERATURE_NAME`
(:func:`_constant_temperature`); :func:`normal_gravity` gives gravity from the
latitude when the local value is not known; :func:`_build` assembles the
experiment and validates it with :func:`graph_calib.io.validate_experiment`,
naming the input line of a rule broken at a sample.
"""

from __future__ import annotations

import math

import numpy as np

from graph_calib.errors import InputError
from graph_calib.records.experiment import Experiment
from graph_calib.importers.text import _data_line_numbers, _num, _show
from graph_calib.io import validate_experiment

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


def _intervals(t, rate_hz, segment=None):
    """Interval each sample closes, s: ``diff(t)``, and the nominal period at the first sample of each segment."""
    dt = np.empty_like(t)
    dt[0] = 1.0 / rate_hz
    dt[1:] = np.diff(t)
    if segment is not None:
        dt[1:][np.diff(segment) != 0] = 1.0 / rate_hz
    return dt


def _build(*, t, dtheta, dv, temperature, names, temperature_map, rate_hz, latitude_rad, gravity_mps2,
           imu_id, description, source, skip_lines, segment=None):
    """Assemble and validate; a rule broken at a sample names the input line too."""
    exp = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=temperature, temperature_names=tuple(names),
        temperature_map=np.asarray(temperature_map, dtype=np.int64), rate_hz=_num(rate_hz),
        latitude_rad=_num(latitude_rad), gravity_mps2=_num(gravity_mps2), imu_id=imu_id,
        description=description, table=None, source=str(source), segment=segment,
    )
    try:
        validate_experiment(exp, path=source)
    except InputError as exc:
        if exc.index is None:
            raise
        line = _data_line_numbers(source, skip_lines)[exc.index]
        err = InputError(f"{exc} (input line {line})")
        err.path, err.dataset, err.index = exc.path, exc.dataset, exc.index
        raise err from None
    return exp


def _constant_temperature(n, temperature_degC):
    if not isinstance(_num(temperature_degC), float) or not math.isfinite(temperature_degC):
        raise InputError(f"assumed temperature must be a finite number of degC, got {_show(temperature_degC)}",
                         dataset="temperature_degC")
    return np.full((n, 1), float(temperature_degC)), (ASSUMED_TEMPERATURE_NAME,)


__all__ = ["ASSUMED_TEMPERATURE_NAME", "normal_gravity"]
