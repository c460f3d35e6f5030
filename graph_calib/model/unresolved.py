r"""Directions of the calibration that a record cannot resolve, and the covariance without them.

A heading drift that looks like a g-sensitivity
    Turn the whole trajectory about the local vertical at a constant rate ``w_v``:
    ``C'_nb(t) = Exp(w_v t e_up) C_nb(t)``.  The gyros would see ``w_v C_nb^T e_up`` more, and where the
    bench does not accelerate (a hand turning the unit about its own centre, a turntable) the
    calibrated specific force is ``f_b = g C_nb^T e_up``, so that extra rate is ``(w_v / g) f_b``: the
    gyros' g-sensitivity ``G`` grown by ``kappa (I + diag(gyro.scale) + M_g)`` (``kappa = w_v / g``;
    ``omega_meas = (I + S + M_g) omega_ib_b + G f_b + ...``, so a rate ``kappa f_b`` more inside the
    bracket is ``G`` changed by ``kappa (I + S + M_g)``).  The accelerometers see nothing (gravity is
    the same after a turn about the vertical) and the rotation factors nothing (the attitudes turn
    with it).  Only two things tell the drift from the g-sensitivity: a heading reference (valid table
    readings, the encoders) and the Earth rate, whose horizontal part the gyros see through the
    heading.  Without a table, the Earth rate is all: for gyros that cannot gyrocompass (a bias prior
    above the horizontal Earth rate, consumer MEMS), the heading that the Earth rate gives is
    nonlinear and multimodal in the drift (the cost over ``kappa`` has local minima, 2e-3 rad/s per
    m/s^2 apart on the simulated Ferraris-style session, with a linearised sigma of 3e-4 at each:
    docs/model.md, "A heading drift that looks like a g-sensitivity"), so the linearised covariance
    claims a precision that the record does not have.

:func:`without_data_along` gives the covariance with the data's information along such a direction
removed (as if a free nuisance parameter moved the calibration along it), the priors kept: the
direction's own sigma is then its prior's, and every other element keeps the information the data
give it with that direction free.  The estimate itself is not moved.
"""

from __future__ import annotations

import numpy as np

#: Pairs (row, column) of ``M_g`` in the order of ``gyro.misalignment``'s elements (xy xz yx yz zx zy).
_MISALIGNMENT_ROWS_COLS = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))


def heading_drift_direction(layout, x):
    """The calibration direction of a heading drift, unit norm, shape (P,).

    ``G`` grown by ``kappa (I + diag(gyro.scale) + M_g)`` at the calibration ``x`` (module docstring);
    zero outside ``gyro.g_sensitivity``.  The scale's temperature coefficient is left out (``dT`` is
    a few degC about ``T_ref``: a relative change below 1e-3 of the direction for consumer MEMS).

    Parameters
    ----------
    layout : graph_calib.sensors.params.Layout
        Must hold ``gyro.g_sensitivity``.
    x : ndarray, shape (P,)
    """
    A = np.eye(3)
    if "gyro.scale" in layout:
        A += np.diag(layout.get(x, "gyro.scale"))
    if "gyro.misalignment" in layout:
        for (i, j), v in zip(_MISALIGNMENT_ROWS_COLS, layout.get(x, "gyro.misalignment")):
            A[i, j] += v
    u = np.zeros(layout.size)
    u[layout.slice("gyro.g_sensitivity")] = A.ravel()           # G[i, j] row-major: xx xy xz yx ...
    return u / np.linalg.norm(u)


def without_data_along(covariance, prior_sigma, directions):
    """The covariance with the data's information along ``directions`` removed, the priors kept.

    With ``Lambda = covariance^-1`` and the prior information ``Lambda_p = diag(prior_sigma^-2)``,
    the data's information ``Lambda_d = Lambda - Lambda_p`` is replaced by what it is when a free
    parameter ``t`` moves the calibration along ``u`` (``x + t u``, ``t`` eliminated):
    ``Lambda_d - Lambda_d u u^T Lambda_d / (u^T Lambda_d u)``, one direction after the other; the
    result is ``(Lambda_d' + Lambda_p)^-1``.  Every variance grows or stays.

    Parameters
    ----------
    covariance : ndarray, shape (P, P)
        Posterior covariance of the calibration (priors included).
    prior_sigma : ndarray, shape (P,)
    directions : ndarray, shape (D, P)
        Unit directions (D may be 0).

    Returns
    -------
    ndarray, shape (P, P)
        Symmetric.
    """
    covariance = np.asarray(covariance, dtype=float)
    directions = np.atleast_2d(np.asarray(directions, dtype=float))
    if directions.size == 0:
        return covariance
    # in units of the prior sigmas (x = D x_n): the prior information is I, and the elements' scales,
    # which span many decades, do not reach the inversions
    D = np.asarray(prior_sigma, dtype=float)
    Ld = np.linalg.inv(covariance / np.outer(D, D))
    Ld = 0.5 * (Ld + Ld.T) - np.eye(D.size)
    for u in directions / D:
        Lu = Ld @ u
        uLu = float(u @ Lu)
        if uLu > 0.0:
            Ld = Ld - np.outer(Lu, Lu) / uLu
    out = np.linalg.inv(Ld + np.eye(D.size))
    return 0.5 * (out + out.T) * np.outer(D, D)


__all__ = ["heading_drift_direction", "without_data_along"]
