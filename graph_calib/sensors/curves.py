r"""The one evaluation of a temperature curve: a polynomial in ``T - t0`` with its covariance.

Every consumer of a curve over temperature evaluates it here: a subrange's own model
(:class:`graph_calib.stitching.SubrangePoint`), a truth file's ``temperature_curves`` and a single result
applied over temperature (:mod:`graph_calib.evaluation.validation`), the joint calibration
(:class:`graph_calib.compensation.joint.JointCurve`), the campaign's truth checks and the report's
figures, and the export formats.  A curve is

.. math::

    p(T) = \sum_{j=0}^{d} c_j\,(T - t_0)^j,

``c_j`` in SI units per ``degC^j``, ``T`` the temperature of the sensor the element belongs to (degC).  Its
one-sigma band is ``sqrt(v^T C v)`` with ``v = [(T - t0)^j]``.  Its ``k``-th Taylor coefficient at another
temperature ``t1`` (what a result at reference temperature ``t1`` calls ``p``, ``p_tc``, ``p_tc2``...) is
``sum_j binom(j, k) (t1 - t0)^(j-k) c_j`` (:func:`taylor_at`).

No degree is assumed anywhere here: a curve has as many coefficients as it is given.
"""

from __future__ import annotations

from math import comb

import numpy as np


def power_rows(T, t0_degC, degree):
    """``(T - t0)^j`` for ``j = 0..degree``.

    Parameters
    ----------
    T : array_like, shape (N,) or scalar
        Temperatures, degC.
    t0_degC : float
    degree : int

    Returns
    -------
    ndarray, shape (N, degree + 1)
    """
    d = np.atleast_1d(np.asarray(T, dtype=float)).reshape(-1) - float(t0_degC)
    return d[:, None] ** np.arange(int(degree) + 1)[None, :]


def evaluate_polynomial_curve(coefficients, T, *, t0_degC, covariance=None):
    """Value (and one sigma) of a temperature curve at temperatures ``T``.

    Parameters
    ----------
    coefficients : array_like, shape (d+1,)
        ``[c_0, c_1, ..., c_d]``, SI per ``degC^j``.
    T : array_like, shape (N,) or scalar
        Temperatures, degC (the element's own sensor's).
    t0_degC : float
        Expansion point, degC.
    covariance : array_like, shape (d+1, d+1), optional
        Covariance of the coefficients.

    Returns
    -------
    value : ndarray, shape (N,)
        SI.
    sigma : ndarray, shape (N,)
        One sigma from ``covariance`` (zeros without one).
    """
    c = np.atleast_1d(np.asarray(coefficients, dtype=float))
    V = power_rows(T, t0_degC, c.size - 1)
    value = V @ c
    if covariance is None:
        return value, np.zeros_like(value)
    C = np.asarray(covariance, dtype=float).reshape(c.size, c.size)
    var = np.einsum("ni,ij,nj->n", V, C, V)
    return value, np.sqrt(np.clip(var, 0.0, None))


def taylor_matrix(degree, shift_degC):
    """Matrix ``M`` with ``M @ c`` the Taylor coefficients at ``t0 + shift`` of the curve ``c`` about ``t0``.

    ``M[k, j] = binom(j, k) shift^(j-k)`` for ``j >= k``; shape (degree+1, degree+1).
    """
    n = int(degree) + 1
    M = np.zeros((n, n))
    for k in range(n):
        for j in range(k, n):
            M[k, j] = comb(j, k) * float(shift_degC) ** (j - k)
    return M


def taylor_at(coefficients, t1_degC, *, t0_degC, covariance=None):
    """The curve's Taylor coefficients at ``t1`` (``[p, p_tc, p_tc2, ...]`` of a result at ``T_ref = t1``).

    Returns
    -------
    coefficients : ndarray, shape (d+1,)
    covariance : ndarray, shape (d+1, d+1) or None
    """
    c = np.atleast_1d(np.asarray(coefficients, dtype=float))
    M = taylor_matrix(c.size - 1, float(t1_degC) - float(t0_degC))
    cov = None if covariance is None else M @ np.asarray(covariance, dtype=float) @ M.T
    return M @ c, cov


__all__ = ["power_rows", "evaluate_polynomial_curve", "taylor_matrix", "taylor_at"]
