"""Fitting one element over temperature: the generalised least squares, the knots, the boundary checks.

:func:`fit_element` fits every model of :data:`~graph_calib.stitching.pieces.MODELS`
to an element's subrange points and checks consecutive subranges at their common
boundary (:func:`boundary_temperature`).  The method is described in
:mod:`graph_calib.stitching`.
"""

from __future__ import annotations

import numpy as np

from graph_calib.sensors import params
from graph_calib.stitching.pieces import BoundaryCheck, ElementCurve, Fit, family, sensor_of

#: Two subranges closer than this (degC, reference temperatures) share a segment of the linear model.
MIN_KNOT_SPACING_DEGC = 1.0


def _gls(kind, points, *, knots=None, center=0.0, scale=1.0, degree=3, clamp=False, orders=None):
    """Generalised least squares of one family to the points' Taylor coefficients."""
    if kind == "linear":
        n_theta = knots.size
        proto = Fit(kind, np.zeros(n_theta), np.zeros((n_theta, n_theta)), 0.0, 0, knots=knots, clamp=clamp)
    else:
        n_theta = degree + 1
        proto = Fit(kind, np.zeros(n_theta), np.zeros((n_theta, n_theta)), 0.0, 0, center=center, scale=scale)
    A_rows, y_rows = [], []
    for p in points:
        d = p.coef.size if orders is None else min(orders, p.coef.size)
        A = np.vstack([proto.rows([p.t_ref_degC], k) for k in range(d)])
        y = p.coef[:d]
        S = p.cov[:d, :d]
        # whiten with the Cholesky factor (a tiny jitter guards exactly singular blocks)
        jitter = 1e-12 * np.max(np.diag(S)) if np.max(np.diag(S)) > 0 else 1e-300
        L = np.linalg.cholesky(S + jitter * np.eye(d))
        keep = np.any(A != 0.0, axis=1)  # a family without that derivative (linear: curvature) ignores it
        Aw = np.linalg.solve(L, A)
        yw = np.linalg.solve(L, y)
        if not np.all(keep):
            idx = np.flatnonzero(keep)
            S2 = S[np.ix_(idx, idx)] + jitter * np.eye(idx.size)
            L2 = np.linalg.cholesky(S2)
            Aw, yw = np.linalg.solve(L2, A[idx]), np.linalg.solve(L2, y[idx])
        A_rows.append(Aw)
        y_rows.append(yw)
    A = np.vstack(A_rows)
    y = np.concatenate(y_rows)
    theta, *_ = np.linalg.lstsq(A, y, rcond=None)
    N = A.T @ A
    cov = np.linalg.pinv(N)
    r = y - A @ theta
    chi2 = float(r @ r)
    dof = int(A.shape[0] - np.linalg.matrix_rank(A))
    if dof > 0 and chi2 / dof > 1.0:
        cov = cov * (chi2 / dof)
    return Fit(kind, theta, cov, chi2, dof, knots=proto.knots, center=center, scale=scale, clamp=clamp)


def boundary_temperature(lower, upper):
    """Common boundary of two consecutive subranges on one sensor's temperature axis, degC.

    The middle between the top of the lower subrange's coverage and the bottom of
    the upper one's (the middle of their overlap when they overlap), kept
    strictly between the two reference temperatures.
    """
    tb = 0.5 * (lower.t_range[1] + upper.t_range[0])
    lo, hi = lower.t_ref_degC, upper.t_ref_degC
    if hi > lo:
        tb = min(max(tb, lo + 0.05 * (hi - lo)), hi - 0.05 * (hi - lo))
    return float(tb)


def _merged_knots(temps):
    knots = np.array(sorted({round(float(t), 9) for t in temps}))
    merged = []
    for t in knots:  # knots closer than the spacing merge
        if not merged or t - merged[-1] >= MIN_KNOT_SPACING_DEGC:
            merged.append(t)
    return np.array(merged)


def fit_element(element, points):
    """Fit every model of one element and check its boundaries; an :class:`ElementCurve`.

    An element is temperature dependent when its parameter has temperature
    coefficients in the catalogue (``gyro.bias`` has ``gyro.bias_tc``), even if
    the results hold only its values (a calibration at constant temperature):
    then the ``linear`` model interpolates the values (knots at the reference
    temperatures, continued linearly outside) and the ``cubic`` fits the values
    alone; the boundary check needs the subranges' slopes and is skipped.
    """
    parameter = params.split_element_name(element)[0]
    points = tuple(sorted(points, key=lambda p: p.t_ref_degC))
    tdep = bool(family(parameter)[1]) or any(p.coef.size > 1 for p in points)
    slopes = all(p.coef.size > 1 for p in points)
    fits = {}
    lo = min(min(p.t_range[0] for p in points), points[0].t_ref_degC)
    hi = max(max(p.t_range[1] for p in points), points[-1].t_ref_degC)
    if tdep:
        if slopes:
            inner = []
            for a, b in zip(points[:-1], points[1:]):
                if b.t_ref_degC - a.t_ref_degC >= MIN_KNOT_SPACING_DEGC:
                    inner.append(boundary_temperature(a, b))
            knots = np.array([lo] + inner + [hi])
            if hi - lo < 1e-6:
                knots = np.array([lo, lo + 1.0])
        else:
            knots = _merged_knots([p.t_ref_degC for p in points])
        fits["linear"] = _gls("linear", points, knots=knots, orders=2)
        n_meas = sum(min(p.coef.size, 4) for p in points)
        center = 0.5 * (lo + hi)
        scale = max(0.5 * (hi - lo), 1.0)
        fits["cubic"] = _gls("cubic", points, center=center, scale=scale, degree=min(3, n_meas - 1))
    else:
        knots = _merged_knots([p.t_ref_degC for p in points])
        fits["linear"] = _gls("linear", points, knots=knots, clamp=True, orders=1)
        fits["constant"] = _gls("constant", points, center=0.0, scale=1.0, degree=0, orders=1)
    boundaries = []
    for a, b in zip(points[:-1], points[1:]):
        if tdep and not (a.coef.size > 1 and b.coef.size > 1):
            continue
        tb = boundary_temperature(a, b)
        va, sa = a.predict([tb])
        vb, sb = b.predict([tb])
        boundaries.append(BoundaryCheck(element, a.name, b.name, tb, float(va[0]), float(sa[0]),
                                        float(vb[0]), float(sb[0])))
    return ElementCurve(element=element, parameter=parameter, sensor=sensor_of(element), temperature_dependent=tdep,
                        points=points, fits=fits, boundaries=tuple(boundaries))


__all__ = ["MIN_KNOT_SPACING_DEGC", "boundary_temperature", "fit_element"]
