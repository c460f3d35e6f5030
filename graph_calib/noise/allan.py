r"""Overlapping Allan deviation of a rate from its increments, pooled over several rests.

A gyro (accelerometer) records angle (velocity) increments ``d_k`` over sample intervals of length
``tau_0``; their running sum is the phase ``theta_k``.  With ``tau = m tau_0`` the overlapping Allan
variance of the rate ``d / tau_0`` is (IEEE Std 952, annex C; the estimator ``oadev`` of allantools)

.. math::

    \sigma^2(\tau) = \frac{1}{2 \tau^2 (N - 2m)} \sum_{k=0}^{N-2m-1}
                     (\theta_{k+2m} - 2\theta_{k+m} + \theta_k)^2 ,

``N + 1`` phase points.  Over several rests (never across the motion between them) the sums of
squares and the term counts are pooled per ``m``; a rest contributes to every ``m`` it is long
enough for.  The confidence of each ``sigma(tau)``, as a relative one-sigma, is
``1 / sqrt(2 (T / tau - 1))`` with ``T`` the pooled rest time (about ``T / tau`` independent
averages; engineering-facts.md), the usual approximation for the overlapping estimator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Longest averaging time used, as a fraction of a rest: beyond it a rest has too few averages.
MAX_TAU_FRACTION = 0.25
#: Averaging times per factor of 10 (log-spaced, whole multiples of the sample period).
POINTS_PER_DECADE = 8


@dataclass(frozen=True)
class AllanDeviation:
    """Allan deviation of each channel of a triad over the rests.

    Attributes
    ----------
    tau : ndarray, shape (T,)
        Averaging times, s.
    adev : ndarray, shape (T, C)
        Overlapping Allan deviation of each channel, in the rate's unit (rad/s or m/s^2).
    n_terms : ndarray of int, shape (T,)
        Second differences pooled at each ``tau``.
    rel_sigma : ndarray, shape (T,)
        Relative one-sigma confidence of each ``adev`` value.
    rest_s : float
        Pooled rest time, s.
    """

    tau: np.ndarray
    adev: np.ndarray
    n_terms: np.ndarray
    rel_sigma: np.ndarray
    rest_s: float


def averaging_factors(n_max, *, points_per_decade=POINTS_PER_DECADE):
    """Whole multiples ``m`` of the sample period, log-spaced from 1 to ``n_max``, unique and increasing."""
    if n_max < 1:
        return np.zeros(0, dtype=np.int64)
    k = int(np.floor(np.log10(n_max) * points_per_decade)) + 1
    return np.unique(np.round(10.0 ** (np.arange(k) / points_per_decade)).astype(np.int64))


def overlapping_allan(increments, intervals, *, tau0, m=None):
    """Overlapping Allan deviation of a triad's rate over the given rests.

    Parameters
    ----------
    increments : ndarray, shape (N, C)
        Angle (rad) or velocity (m/s) increments of a record.
    intervals : array_like of int, shape (P, 2)
        Rests as ``(start, stop)`` sample indices, stop exclusive.
    tau0 : float
        Sample period, s.
    m : array_like of int, optional
        Averaging factors; default :func:`averaging_factors` up to :data:`MAX_TAU_FRACTION` of the
        longest rest.

    Returns
    -------
    AllanDeviation
    """
    d = np.asarray(increments, dtype=float)
    d = d.reshape(d.shape[0], -1)
    iv = np.asarray(intervals, dtype=np.int64).reshape(-1, 2)
    lengths = iv[:, 1] - iv[:, 0]
    if m is None:
        m = averaging_factors(int(MAX_TAU_FRACTION * lengths.max()) if lengths.size else 0)
    m = np.asarray(m, dtype=np.int64)
    ss = np.zeros((m.size, d.shape[1]))
    cnt = np.zeros(m.size, dtype=np.int64)
    for a, b in iv:
        x = d[a:b]
        theta = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x - x.mean(axis=0), axis=0)])
        n = theta.shape[0] - 1
        buf = np.empty_like(theta)       # the second differences formed in place: no temporaries per m
        for j, mm in enumerate(m):
            if n - 2 * mm < 1:
                break
            dd = buf[:n + 1 - 2 * mm]
            np.multiply(theta[mm:n + 1 - mm], -2.0, out=dd)
            dd += theta[2 * mm:]
            dd += theta[:n + 1 - 2 * mm]
            ss[j] += np.einsum("ij,ij->j", dd, dd)
            cnt[j] += dd.shape[0]
    ok = cnt > 0
    m, ss, cnt = m[ok], ss[ok], cnt[ok]
    tau = m * float(tau0)
    adev = np.sqrt(ss / (2.0 * tau[:, None] ** 2 * cnt[:, None]))
    rest_s = float(lengths.sum()) * float(tau0)
    rel = 1.0 / np.sqrt(2.0 * np.maximum(rest_s / tau - 1.0, 1.0))
    return AllanDeviation(tau=tau, adev=adev, n_terms=cnt, rel_sigma=rel, rest_s=rest_s)


__all__ = ["AllanDeviation", "overlapping_allan", "averaging_factors", "MAX_TAU_FRACTION", "POINTS_PER_DECADE"]
