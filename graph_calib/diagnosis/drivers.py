"""What could drive a missing effect: the generic drivers and their keyframe means.

A *driver* is a per-sample series built from the raw signals (time, temperature,
the angular rate, its sign and size, angular acceleration, specific force and its
square) placed as a bias on one sensor axis.  :func:`driver_series` builds the
series and the driver columns the score tests use; :func:`keyframe_context` the
keyframe means the descriptive regressions and the report's figures use.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Sensor axes a generic driver is placed on (as a bias), in order.
SENSOR_AXES = ("gyro.x", "gyro.y", "gyro.z", "accel.x", "accel.y", "accel.z")

#: Driver groups: name -> one-line meaning (the features, per sample, from the raw signals).
DRIVER_GROUPS = {
    "time": "cubic B-splines over the record (slow change of a bias in time, any shape)",
    "temperature": "dT^3 of the sensor (curvature beyond the dT^2 of the candidates)",
    "rate_sign": "sign of the angular rate about x, y, z (0 below the dead band)",
    "rate_size": "|angular rate| about x, y, z (gyro: the other two axes; |w_i| on gyro i is gyro.scale_asym)",
    "angular_acceleration": "angular acceleration (gyro: about x, y, z; accelerometer i: about axis i only, "
                            "the others are the lever arm and accel.size_effect)",
    "specific_force_sq": "square of the specific force (accelerometer i: along the other two axes; f_i^2 "
                         "is accel.nonlinearity)",
}

#: Signatures the descriptive regressions relate the residuals to (keyframe means; ``keyframe_context``).
REGRESSION_DRIVERS = ("time", "temperature", "temperature_rate", "rate", "rate_size", "rate_sign",
                      "angular_acceleration", "specific_force", "specific_force_sq")

#: Dead band of the rate sign, rad/s (2 deg/s: above the bias of a consumer gyro).
RATE_SIGN_DEADBAND = np.deg2rad(2.0)

#: Number of cubic B-spline functions of the ``time`` driver.
TIME_SEGMENTS = 12


@dataclass(frozen=True)
class Driver:
    """One generic driver column: a bias on ``axis`` that follows ``series`` (per sample).

    Attributes
    ----------
    group : str
        A key of :data:`DRIVER_GROUPS`.
    axis : str
        One of :data:`SENSOR_AXES`.
    label : str
        The feature, e.g. ``"f_x^2"``, ``"B-spline 3"``.
    series : int
        Column of the driver series matrix (:func:`driver_series`).
    """

    group: str
    axis: str
    label: str
    series: int


def time_basis(t, n):
    """Cubic B-spline basis on uniform knots over the record, shape (N, n), rows summing to one.

    Any slow change in time (a drift, a sinusoid of up to about ``(n - 3) / 2``
    cycles per record) lies nearly in its span; the constant is the bias itself.
    """
    k = 3
    n = max(int(n), k + 1)
    u = (np.asarray(t, dtype=float) - t[0]) / max(float(t[-1] - t[0]), 1e-12)
    inner = np.linspace(0.0, 1.0, n - k + 1)
    knots = np.concatenate([np.zeros(k), inner, np.ones(k)])
    from scipy.interpolate import BSpline       # loaded when used

    return BSpline.design_matrix(np.clip(u, 0.0, 1.0), knots, k).toarray()


def _series(model, *, n_segments, deadband):
    """The distinct per-sample driver series of ``model``'s experiment, one at a time.

    Yields ``(key, series)`` with ``series`` of shape (N,) (SI units; ``dT`` in degC); the keys are
    ``("time", s)``, ``("dT3", i)``, ``("sign", j)``, ``("abs", j)``, ``("dw", j)``, ``("f2", j)``.
    """
    e = model.experiment
    w = model.record.w_raw
    f = model.record.f_raw
    dw = model.record.dw_raw
    dT = np.column_stack([model.record.dTg, model.record.dTa])          # (N, 6) per sensor
    for s, col in enumerate(time_basis(e.t, n_segments).T):
        yield ("time", s), col
    for i in range(6):
        yield ("dT3", i), dT[:, i] ** 3
    for j in range(3):
        yield ("sign", j), np.sign(w[:, j]) * (np.abs(w[:, j]) > deadband)
        yield ("abs", j), np.abs(w[:, j])
        yield ("dw", j), dw[:, j]
        yield ("f2", j), f[:, j] ** 2


def _drivers(names, n_segments):
    """The driver columns, given the column ``names[key]`` of each distinct series."""
    xyz = "xyz"
    drivers = []
    for i, ax in enumerate(SENSOR_AXES):
        gyro = i < 3
        own = i % 3
        for s in range(n_segments):
            drivers.append(Driver("time", ax, f"B-spline {s + 1}", names[("time", s)]))
        drivers.append(Driver("temperature", ax, "dT^3", names[("dT3", i)]))
        for j in range(3):
            drivers.append(Driver("rate_sign", ax, f"sign(w_{xyz[j]})", names[("sign", j)]))
        for j in range(3):
            if not (gyro and j == own):
                drivers.append(Driver("rate_size", ax, f"|w_{xyz[j]}|", names[("abs", j)]))
        for j in range(3):
            if gyro or j == own:
                drivers.append(Driver("angular_acceleration", ax, f"dw_{xyz[j]}/dt", names[("dw", j)]))
        for j in range(3):
            if gyro or j != own:
                drivers.append(Driver("specific_force_sq", ax, f"f_{xyz[j]}^2", names[("f2", j)]))
    return drivers


def driver_series(model, *, n_segments=TIME_SEGMENTS, deadband=RATE_SIGN_DEADBAND):
    """Per-sample driver series of ``model``'s experiment and the driver columns built from them.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    n_segments : int
        Cubic B-spline functions of the ``time`` driver.
    deadband : float
        Dead band of the rate sign, rad/s.

    Returns
    -------
    Phi : ndarray, shape (N, D)
        One column per distinct series (SI units; ``dT`` in degC).
    drivers : list of Driver
    """
    names, cols = {}, []
    for key, v in _series(model, n_segments=n_segments, deadband=deadband):
        names[key] = len(cols)
        cols.append(np.asarray(v, dtype=float))
    return np.column_stack(cols), _drivers(names, n_segments)


@dataclass(frozen=True)
class DriverSums:
    """Sums of every driver series up to each boundary a factor's interval can start or end at.

    The intervals of the factors (keyframes ``[k0[k], k0[k+1])``, encoder readings
    ``[k0[key], reading_sample + 1)``) all start and end at a few boundaries; the sums
    up to those boundaries give every factor's driver means without a cumulative sum over
    the samples.  They depend on the record only, so one serves every round of a loop.

    Shapes: ``B`` boundaries, ``D`` distinct series.

    Attributes
    ----------
    drivers : list of Driver
        The driver columns (as :func:`driver_series`).
    bounds : ndarray of int64, shape (B,)
        Sample indices, ascending, from 0.
    sums : ndarray, shape (B, D)
        Sum of each series over the samples ``[0, bounds[i])``.
    """

    drivers: list
    bounds: np.ndarray
    sums: np.ndarray

    @classmethod
    def of(cls, model, *, n_segments=TIME_SEGMENTS, deadband=RATE_SIGN_DEADBAND):
        """The sums of ``model``'s record at its keyframe boundaries and encoder readings."""
        rec = model.record
        n = int(rec.k0[-1])
        bounds = np.unique(np.concatenate([[0], rec.k0, np.asarray(rec.reading_sample) + 1])).astype(np.int64)
        bounds = bounds[bounds <= n]
        inner = bounds[(bounds > 0) & (bounds < n)]
        starts = np.concatenate([[0], inner])
        names, cols = {}, []
        for key, v in _series(model, n_segments=n_segments, deadband=deadband):
            names[key] = len(cols)
            v = np.asarray(v, dtype=float)[:n]
            # sums over [bounds[i], bounds[i+1]), accumulated: the sum up to each boundary
            cols.append(np.concatenate([[0.0], np.cumsum(np.add.reduceat(v, starts))]))
        return cls(drivers=_drivers(names, n_segments), bounds=bounds, sums=np.column_stack(cols))

    def _at(self, samples):
        """Row of :attr:`sums` of each sample index in ``samples`` (each must be a boundary)."""
        samples = np.asarray(samples, dtype=np.int64)
        i = np.minimum(np.searchsorted(self.bounds, samples), self.bounds.size - 1)
        if np.any(self.bounds[i] != samples):
            raise ValueError("an interval does not start or end at a boundary of the driver sums")
        return i

    def means(self, lo, hi):
        """Mean of every series over the samples ``[lo, hi)`` of each interval, shape (F, D).

        ``lo`` and ``hi`` (F,) must be boundaries (:attr:`bounds`).
        """
        lo = np.asarray(lo, dtype=np.int64)
        hi = np.asarray(hi, dtype=np.int64)
        cnt = np.maximum(hi - lo, 1)[:, None]
        return (self.sums[self._at(hi)] - self.sums[self._at(lo)]) / cnt


def cumulative_sums(Phi):
    """Cumulative sums with a leading zero row, for :func:`interval_means`."""
    Phi = np.asarray(Phi, dtype=float).reshape(Phi.shape[0], -1)
    return np.vstack([np.zeros((1, Phi.shape[1])), np.cumsum(Phi, axis=0)])


def interval_means(cs, lo, hi):
    """Mean over samples ``[lo, hi)`` of every column, from the cumulative sums ``cs``."""
    cnt = np.maximum(hi - lo, 1)[:, None]
    return (cs[hi] - cs[lo]) / cnt


def keyframe_context(model):
    """Keyframe means of the drivers, for regressions and figures: ``{name: (K, ...)}``.

    The names are :data:`REGRESSION_DRIVERS`.
    """
    k0 = model.record.k0
    lo, hi = k0[:-1], k0[1:]
    adjacent = bool(np.all(hi > lo))      # every keyframe holds samples: one sum per keyframe, in order

    def mean(a):
        a = np.asarray(a, dtype=float)
        if adjacent:
            sums = np.add.reduceat(a[: hi[-1]], lo, axis=0)
            return sums / (hi - lo).reshape((-1,) + (1,) * (a.ndim - 1))
        return interval_means(cumulative_sums(a), lo, hi).reshape((lo.size,) + a.shape[1:])

    t = model.experiment.t
    dT = np.column_stack([model.record.dTg, model.record.dTa])
    dTdt = np.column_stack([model.record.dTdtg, model.record.dTdta])
    w = model.record.w_raw
    return {
        "time": mean(t - t[0]),
        "temperature": mean(dT),
        "temperature_rate": mean(dTdt),
        "rate": mean(w),
        "rate_size": mean(np.abs(w)),
        "rate_sign": mean(np.sign(w) * (np.abs(w) > RATE_SIGN_DEADBAND)),
        "angular_acceleration": mean(model.record.dw_raw),
        "specific_force": mean(model.record.f_raw),
        "specific_force_sq": mean(model.record.f_raw**2),
    }
