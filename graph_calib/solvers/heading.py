r"""The heading of a record without table readings, searched on a grid (both solvers).

Without a table a record's heading is held only by the Earth rate (and the gyrocompass prior): along the
heading of a segment (every keyframe of it turned about the vertical, ``Exp([0, 0, psi]) C_nb``) the cost
varies like a sinusoid of small amplitude (on the measured Xsens session about 85 in a cost of 2,600),
over which Gauss-Newton crawls: its quadratic model of the sinusoid is poor, and the factor graph took
steps of 0.2-1 rad for twenty iterations, the filter for fifteen passes, with the calibration already
settled.  Once the calibration has settled, each solver turns each segment to the heading of least cost
found on a grid and at the least of a sinusoid fitted to it (:func:`search_heading`) and goes on from
there; the point is kept only where it lowers the cost, so the fixed point and the stopping rules are what
they were.

Turning a segment changes only the terms in the Earth rate's horizontal part and that segment's prior; no
factor ties two segments (:attr:`graph_calib.model.CalibrationModel.segment_keys`), so each segment takes its
own best heading from one cost evaluation per turn tried.  The solvers search only records of one segment:
on a record cut into segments the segments' headings are tied to each other through the calibration (the
gyro biases against each static face's view of the Earth rate), and turning each on its own at the settled
calibration led the factor graph on a cut Ferraris session (``consumer-ferraris``, seed 1, nine segments)
into a worse minimum (cost 117.009 against 116.279) that the filter did not share (3.3 sigma apart).
"""

from __future__ import annotations

import numpy as np

from graph_calib.navigation.rotations import exp_so3

#: Turns about the vertical tried first by :func:`search_heading`, rad: every 30 degrees, 0 (no turn) among them.
HEADING_GRID = np.radians(np.arange(-180.0, 180.0, 30.0))


def _sinusoid_minimum(psi, cost):
    """The least of ``a + b cos(psi) + c sin(psi)`` fitted to ``cost`` (G,) at ``psi`` (G,), rad; None when
    the fit is flat or fewer than three turns were tried."""
    if psi.size < 3:
        return None
    A = np.column_stack([np.ones_like(psi), np.cos(psi), np.sin(psi)])
    (_, b, c), *_ = np.linalg.lstsq(A, cost, rcond=None)
    if b == 0.0 and c == 0.0:
        return None
    return float(np.arctan2(-c, -b))


def search_heading(model, costs_by_key, R):
    """The attitudes with each segment turned about the vertical to the heading of least cost found.

    The cost of each segment is evaluated at the turns of :data:`HEADING_GRID` and fitted by a sinusoid of
    the turn (the Earth rate's horizontal part seen from a turned trajectory: to first order in the small
    terms, ``a + b cos(psi) + c sin(psi)``); its least is tried too, and each segment takes the turn of least
    evaluated cost among them all (``psi = 0``, the attitudes as they are, among them).

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    costs_by_key : callable
        ``costs_by_key(R)``: the cost per keyframe (K+1,) at attitudes ``R`` and the present calibration
        (:func:`graph_calib.model.normal_equations.cost_by_key`).
    R : ndarray, shape (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.

    Returns
    -------
    ndarray, shape (K+1, 3, 3), or None
        ``Exp([0, 0, psi_s]) R_k`` for every keyframe ``k`` of segment ``s``; None when every segment keeps
        its heading (``psi_s = 0``).
    """
    starts = np.asarray(model.segment_keys)
    seg = np.searchsorted(starts, np.arange(R.shape[0]), side="right") - 1

    def turn(psi):
        return exp_so3(np.column_stack([np.zeros((psi.size, 2)), psi]))

    def table(psi):                       # (len(psi), S): each segment's cost at each turn
        return np.array([np.bincount(seg, weights=costs_by_key(T @ R), minlength=starts.size) for T in turn(psi)])

    psi = np.asarray(HEADING_GRID, dtype=float)
    cost = table(psi)
    fitted = [_sinusoid_minimum(psi, cost[:, s]) for s in range(starts.size)]
    extra = np.array([p for p in fitted if p is not None])
    if extra.size:
        psi = np.concatenate([psi, extra])
        cost = np.vstack([cost, table(extra)])
    best = psi[np.argmin(cost, axis=0)]
    if np.all(best == 0.0):
        return None
    return turn(best)[seg] @ R


__all__ = ["HEADING_GRID", "search_heading"]
