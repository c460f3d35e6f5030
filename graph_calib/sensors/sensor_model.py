r"""Sensor error model of ``model.md``: every term, forward (simulator) and inverse (solvers).

Each triad's error is linear in the calibration vector ``x``::

    measured = true + Phi(true, context) @ x

where every element of a parameter contributes one *term*: a scalar feature of
the true signal and the context (temperature offset ``dT``, its rate ``dT/dt``,
the other triad's signal) placed on one sensor axis.  A term row is
``(column of x, axis, code, aux)``:

==================  ===========================================  ==================
code                feature on ``axis`` (``s`` the triad signal)  parameters
==================  ===========================================  ==================
``BIAS``            1                                            ``*.bias``
``BIAS_TC``         ``dT``                                       ``*.bias_tc``
``BIAS_TC2``        ``dT**2``                                    ``*.bias_tc2``
``BIAS_DTDT``       ``dT/dt``                                    ``*.bias_dtdt``
``BIAS_TC3``        ``dT**3``                                    ``*.bias_tc3``
``SCALE``           ``s[axis]``                                  ``*.scale``
``SCALE_TC``        ``s[axis] * dT``                             ``*.scale_tc``
``SCALE_TC2``       ``s[axis] * dT**2``                          ``*.scale_tc2``
``BIAS_TC4/5``      ``dT**4``, ``dT**5``                         ``*.bias_tc4``, ``*.bias_tc5``
``SCALE_TC3/4/5``   ``s[axis] * dT**3`` (``**4``, ``**5``)        ``*.scale_tc3`` ... ``*.scale_tc5``
``SCALE_ASYM``      ``abs(s[axis])``                             ``gyro.scale_asym``
``CROSS``           ``s[aux]``                                   ``*.misalignment``
``GSENS``           ``f_b[aux]``                                 ``gyro.g_sensitivity``
``NONLIN``          ``s[axis]**2``                               ``accel.nonlinearity``
``SIZE``            ``(w' x e_aux + w x (w x e_aux))[axis]``     ``accel.size_effect``
``LAG``             ``-ds/dt[axis]``                             ``time_lag.accel``
==================  ===========================================  ==================

``dT`` and ``dT/dt`` are those of the sensor on ``axis``.  ``w`` and ``w'`` are
the angular rate and acceleration of the block, ``e_aux`` the unit vector of
the offset component.  The gyro-scale asymmetry ``p * sign(w) * w`` is written
``p * |w|``; the accelerometer time lag ``f(t - p) ~= f(t) - p * df/dt``.

Solvers invert the model: they find ``s`` with ``s + Phi(s) x = m`` by Newton's
method, and its Jacobian by implicit differentiation,
``ds/dx = -(I + dPhi x/ds)^-1 Phi(s)``.  The two triads are inverted together
(:func:`correct_pair`): the accelerometers first, then the gyros with the
*calibrated* specific force in ``GSENS`` (``model.md``: the other triad's true
signal).  That order is exact because no accelerometer feature depends on
the calibrated rate: ``SIZE``'s ``w``, ``w'`` and the derivatives ``dw/dt``,
``df/dt`` are taken from the raw measured signals (data, not functions of
``x``; ``docs/model.md``).  The gyro Jacobian is chained,
``dw/dx = -Ai_g (Phi_g + Gm df/dx)`` with ``Gm = d(Phi_g x)/df``
(:func:`gsens_coupling`).

Everything per sample is compiled with numba; the Python-level functions here
are vectorised wrappers for the simulator and for tests.  :func:`invert_sample` and
:func:`sample_features` are compiled once (``_nrt=False``: they allocate nothing, so
passing them arrays costs no reference counting) and called by every kernel that
needs them; the small helpers they use are inlined into them only
(docs/performance.md, "Compiling the kernels").
"""

from __future__ import annotations

import numba
import numpy as np

from graph_calib.sensors.effects import EFFECTS, XYZ
from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

BIAS, BIAS_TC, BIAS_TC2, BIAS_DTDT, SCALE, SCALE_TC, SCALE_TC2, SCALE_ASYM, CROSS, GSENS, NONLIN, SIZE, LAG = range(13)
BIAS_TC3 = 13
BIAS_TC4, BIAS_TC5, SCALE_TC3, SCALE_TC4, SCALE_TC5 = range(14, 19)

_AXIS = {"x": 0, "y": 1, "z": 2}

#: Term code of each sensor-term kind of the effect registry (``Effect.term``).
TERM_CODES = {
    "bias": BIAS, "bias_tc": BIAS_TC, "bias_tc2": BIAS_TC2, "bias_dtdt": BIAS_DTDT,
    "scale": SCALE, "scale_tc": SCALE_TC, "scale_tc2": SCALE_TC2, "scale_asym": SCALE_ASYM,
    "cross": CROSS, "gsens": GSENS, "nonlin": NONLIN, "size": SIZE, "lag": LAG, "bias_tc3": BIAS_TC3,
    "bias_tc4": BIAS_TC4, "bias_tc5": BIAS_TC5, "scale_tc3": SCALE_TC3, "scale_tc4": SCALE_TC4, "scale_tc5": SCALE_TC5,
}


def _axes(element):
    """``(axis, aux)`` of an element name: ``"y"`` -> (1, -1); ``"zx"`` -> (2, 0)."""
    if len(element) == 1:
        return _AXIS[element], -1
    return _AXIS[element[0]], _AXIS[element[1]]


def term_rows(layout, triad):
    """Term rows ``(col, axis, code, aux)`` of the ``"gyro"`` or ``"accel"`` triad in ``layout``.

    Read from the effect registry (:mod:`graph_calib.sensors.effects`): each element of a parameter whose
    ``triad`` is this one adds its ``term`` on the axis its name gives (a scalar parameter on all three).

    Returns
    -------
    ndarray of int64, shape (R, 4)
        One row per (parameter element, axis) pair; ``aux`` is -1 where unused.
    """
    if triad not in ("gyro", "accel"):
        raise ValueError(f"triad must be 'gyro' or 'accel', not {triad!r}")
    rows = []
    for name in layout.names:
        eff = EFFECTS[name]
        if eff.triad != triad or eff.term is None:
            continue
        code = TERM_CODES[eff.term]
        s = layout.slice(name)
        if not eff.elements:
            rows.extend((s.start, i, code, -1) for i in range(3))
            continue
        for k, el in enumerate(eff.elements):
            axis, aux = _axes(el)
            rows.append((s.start + k, axis, code, aux))
    return np.array(rows, dtype=np.int64).reshape(-1, 4)


@numba.njit(cache=True, inline="always")
def _is_slope_term(code):
    """Whether the term's feature depends on the triad's own signal (it then enters ``I + dPhi x/ds``)."""
    return (code == SCALE or code == SCALE_TC or code == SCALE_TC2 or code == SCALE_ASYM or code == CROSS
            or code == NONLIN or code == SCALE_TC3 or code == SCALE_TC4 or code == SCALE_TC5)


@numba.njit(cache=True, inline="always")
def _feature(code, axis, aux, s, dT, dTdt, other, domega, dsig):
    if code == BIAS:
        return 1.0
    if code == BIAS_TC:
        return dT[axis]
    if code == BIAS_TC2:
        return dT[axis] * dT[axis]
    if code == BIAS_DTDT:
        return dTdt[axis]
    if code == BIAS_TC3:
        return dT[axis] * dT[axis] * dT[axis]
    if code == SCALE:
        return s[axis]
    if code == SCALE_TC:
        return s[axis] * dT[axis]
    if code == SCALE_TC2:
        return s[axis] * dT[axis] * dT[axis]
    if code == SCALE_ASYM:
        return abs(s[axis])
    if code == CROSS:
        return s[aux]
    if code == GSENS:
        return other[aux]
    if code == NONLIN:
        return s[axis] * s[axis]
    if code == BIAS_TC4:
        return dT[axis] ** 4
    if code == BIAS_TC5:
        return dT[axis] ** 5
    if code == SCALE_TC3:
        return s[axis] * dT[axis] ** 3
    if code == SCALE_TC4:
        return s[axis] * dT[axis] ** 4
    if code == SCALE_TC5:
        return s[axis] * dT[axis] ** 5
    if code == SIZE:
        # (w' x e + w x (w x e))[axis] with e = e_aux, w = other, w' = domega
        e0 = 1.0 if aux == 0 else 0.0
        e1 = 1.0 if aux == 1 else 0.0
        e2 = 1.0 if aux == 2 else 0.0
        w0, w1, w2 = other[0], other[1], other[2]
        a0 = domega[1] * e2 - domega[2] * e1
        a1 = domega[2] * e0 - domega[0] * e2
        a2 = domega[0] * e1 - domega[1] * e0
        c0 = w1 * e2 - w2 * e1
        c1 = w2 * e0 - w0 * e2
        c2 = w0 * e1 - w1 * e0
        if axis == 0:
            return a0 + (w1 * c2 - w2 * c1)
        if axis == 1:
            return a1 + (w2 * c0 - w0 * c2)
        return a2 + (w0 * c1 - w1 * c0)
    if code == LAG:
        return -dsig[axis]
    return 0.0


@numba.njit(cache=True, inline="always")
def _dfeature(code, axis, aux, s, dT, k):
    """Derivative of the feature with respect to ``s[k]``."""
    if code == SCALE:
        return 1.0 if k == axis else 0.0
    if code == SCALE_TC:
        return dT[axis] if k == axis else 0.0
    if code == SCALE_TC2:
        return dT[axis] * dT[axis] if k == axis else 0.0
    if code == SCALE_TC3:
        return dT[axis] ** 3 if k == axis else 0.0
    if code == SCALE_TC4:
        return dT[axis] ** 4 if k == axis else 0.0
    if code == SCALE_TC5:
        return dT[axis] ** 5 if k == axis else 0.0
    if code == SCALE_ASYM:
        if k != axis:
            return 0.0
        return 1.0 if s[axis] >= 0.0 else -1.0
    if code == CROSS:
        return 1.0 if k == aux else 0.0
    if code == NONLIN:
        return 2.0 * s[axis] if k == axis else 0.0
    return 0.0


@numba.njit(cache=True, inline="always")
def _error(rows, x, s, dT, dTdt, other, domega, dsig, out):
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    for r in range(rows.shape[0]):
        col, axis, code, aux = rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3]
        out[axis] += x[col] * _feature(code, axis, aux, s, dT, dTdt, other, domega, dsig)


@numba.njit(cache=True, inline="always")
def _inv3(A, out):
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    d, e, f = A[1, 0], A[1, 1], A[1, 2]
    g, h, k = A[2, 0], A[2, 1], A[2, 2]
    c00 = e * k - f * h
    c01 = f * g - d * k
    c02 = d * h - e * g
    inv_det = 1.0 / (a * c00 + b * c01 + c * c02)
    out[0, 0] = c00 * inv_det
    out[1, 0] = c01 * inv_det
    out[2, 0] = c02 * inv_det
    out[0, 1] = (c * h - b * k) * inv_det
    out[1, 1] = (a * k - c * g) * inv_det
    out[2, 1] = (b * g - a * h) * inv_det
    out[0, 2] = (b * f - c * e) * inv_det
    out[1, 2] = (c * d - a * f) * inv_det
    out[2, 2] = (a * e - b * d) * inv_det


@numba.njit(cache=True, inline="always")
def _slope(rows, x, s, dT, A):
    """A = I + d(err)/ds at s."""
    for i in range(3):
        for k in range(3):
            A[i, k] = 1.0 if i == k else 0.0
    for r in range(rows.shape[0]):
        col, axis, code, aux = rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3]
        if not _is_slope_term(code):
            continue
        # every slope term has one nonzero derivative: in s[aux] (CROSS), else in s[axis]
        k = aux if code == CROSS else axis
        A[axis, k] += x[col] * _dfeature(code, axis, aux, s, dT, k)


@numba.njit(cache=True, inline="always")
def is_nonlinear(rows):
    """Whether any term of ``rows`` is nonlinear in the signal (then Newton needs several steps)."""
    for r in range(rows.shape[0]):
        if rows[r, 2] == SCALE_ASYM or rows[r, 2] == NONLIN:
            return True
    return False


@numba.njit(cache=True, _nrt=False)
def invert_sample(rows, x, m, dT, dTdt, other, domega, dsig, n_iter, nonlinear, s, A, Ai, err):
    """Newton inversion of one sample: ``s`` with ``s + Phi(s) x = m`` and ``Ai = (I + dPhi x/ds)^-1`` at ``s``.

    ``nonlinear`` is :func:`is_nonlinear` of ``rows`` (a model linear in ``s`` is
    inverted exactly by one step, and its ``Ai`` does not depend on ``s``).
    ``A`` (3, 3) and ``err`` (3,) are scratch, passed separately so that a
    per-sample loop need not slice a work array (every view costs an atomic
    reference-count pair).
    """
    steps = n_iter if nonlinear else 1
    s[0] = m[0]
    s[1] = m[1]
    s[2] = m[2]
    for _ in range(steps):
        _slope(rows, x, s, dT, A)
        _inv3(A, Ai)
        _error(rows, x, s, dT, dTdt, other, domega, dsig, err)
        r0 = s[0] + err[0] - m[0]
        r1 = s[1] + err[1] - m[1]
        r2 = s[2] + err[2] - m[2]
        for i in range(3):
            s[i] -= Ai[i, 0] * r0 + Ai[i, 1] * r1 + Ai[i, 2] * r2
    if nonlinear:
        _slope(rows, x, s, dT, A)
        _inv3(A, Ai)


@numba.njit(cache=True, _nrt=False)
def sample_features(rows, s, dT, dTdt, other, domega, dsig, feat):
    """``feat[r]``: the feature of term row ``r`` at ``s``; ``Phi[axis_r, col_r] = feat[r]``.

    With :func:`invert_sample`, ``ds/dx[:, col_r] = -Ai[:, axis_r] * feat[r]`` (summed over rows).
    """
    for r in range(rows.shape[0]):
        feat[r] = _feature(rows[r, 2], rows[r, 1], rows[r, 3], s, dT, dTdt, other, domega, dsig)


@numba.njit(cache=True)
def correct_sample(rows, x, m, dT, dTdt, other, domega, dsig, n_iter, s, J, want_jacobian, work):
    """Invert one sample: ``s`` with ``s + Phi(s) x = m``; ``J = ds/dx`` (3, n) when asked.

    Newton's method from ``s = m`` (exact in one step when the model is linear in
    ``s``).  ``J`` is overwritten only in the columns that ``rows`` name (others
    must be zero).  ``work`` is a scratch array of shape (8, 3).
    """
    Ai = work[5:8]
    invert_sample(rows, x, m, dT, dTdt, other, domega, dsig, n_iter, is_nonlinear(rows), s, work[2:5], Ai, work[0])
    if not want_jacobian:
        return
    for r in range(rows.shape[0]):
        for i in range(3):
            J[i, rows[r, 0]] = 0.0
    for r in range(rows.shape[0]):
        col, axis, code, aux = rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3]
        phi = _feature(code, axis, aux, s, dT, dTdt, other, domega, dsig)
        for i in range(3):
            J[i, col] -= Ai[i, axis] * phi


@numba.njit(cache=True, _nrt=False)
def _forward_many(rows, x, s, dT, dTdt, other, domega, dsig, out, e):
    # without reference counting (``_nrt=False``, ``e`` (3,) scratch from the caller) the per-sample views cost nothing
    for j in range(s.shape[0]):
        _error(rows, x, s[j], dT[j], dTdt[j], other[j], domega[j], dsig[j], e)
        out[j, 0] = s[j, 0] + e[0]
        out[j, 1] = s[j, 1] + e[1]
        out[j, 2] = s[j, 2] + e[2]


@numba.njit(cache=True)
def _inverse_many(rows, x, m, dT, dTdt, other, domega, dsig, n_iter, out, J, want_jacobian):
    work = np.empty((8, 3))
    for j in range(m.shape[0]):
        correct_sample(rows, x, m[j], dT[j], dTdt[j], other[j], domega[j], dsig[j], n_iter,
                       out[j], J[j], want_jacobian, work)


@numba.njit(cache=True, _nrt=False)
def gsens_coupling(grows, x, Gm):
    """``Gm = d(Phi_g x)/df`` (3, 3), the gyro error's slope in the calibrated specific force.

    Filled from the ``GSENS`` rows of the gyro term rows ``grows``; returns whether there is any
    (then the gyro inversion depends on the accelerometer's calibration).
    """
    for i in range(3):
        for k in range(3):
            Gm[i, k] = 0.0
    coupled = False
    for r in range(grows.shape[0]):
        if grows[r, 2] == GSENS:
            Gm[grows[r, 1], grows[r, 3]] += x[grows[r, 0]]
            coupled = True
    return coupled


@numba.njit(cache=True)
def _inverse_pair_many(grows, arows, x, w_raw, f_raw, dTg, dTdtg, dTa, dTdta, dw, df, n_iter,
                       w_out, f_out, Jw, Jf, want_jacobian):
    """Both triads, sample by sample: accelerometers, then gyros with the calibrated ``f``; chained Jacobian."""
    work = np.empty((8, 3))
    Gm = np.empty((3, 3))
    B = np.empty((3, 3))
    coupled = gsens_coupling(grows, x, Gm)
    for j in range(w_raw.shape[0]):
        correct_sample(arows, x, f_raw[j], dTa[j], dTdta[j], w_raw[j], dw[j], df[j], n_iter,
                       f_out[j], Jf[j], want_jacobian, work)
        fo = f_out[j] if coupled else f_raw[j]
        correct_sample(grows, x, w_raw[j], dTg[j], dTdtg[j], fo, dw[j], dw[j], n_iter,
                       w_out[j], Jw[j], want_jacobian, work)
        if not (want_jacobian and coupled):
            continue
        # dw/dx += -Ai_g Gm df/dx in the accelerometer columns (no gyro term names them)
        for i in range(3):
            for k in range(3):
                B[i, k] = work[5 + i, 0] * Gm[0, k] + work[5 + i, 1] * Gm[1, k] + work[5 + i, 2] * Gm[2, k]
        for r in range(arows.shape[0]):
            c = arows[r, 0]
            for i in range(3):
                Jw[j, i, c] = -(B[i, 0] * Jf[j, 0, c] + B[i, 1] * Jf[j, 1, c] + B[i, 2] * Jf[j, 2, c])


def _as3(a, n):
    if a is None:
        return np.zeros((n, 3))
    a = np.ascontiguousarray(a, dtype=float)
    if a.ndim == 1:
        a = np.broadcast_to(a, (n, 3)).copy()
    if a.shape != (n, 3):
        raise ValueError(f"expected shape ({n}, 3), got {a.shape}")
    return a


def measure(layout, x, triad, signal, *, dT=None, dTdt=None, other=None, domega=None, dsignal=None):
    """Forward model: what a triad measures, ``signal + Phi(signal) @ x``.

    Parameters
    ----------
    layout : graph_calib.sensors.params.Layout
    x : ndarray, shape (layout.size,)
        Calibration vector (SI).
    triad : {"gyro", "accel"}
    signal : ndarray, shape (N, 3)
        True angular rate ``omega_ib_b`` (rad/s) or specific force ``f_b`` (m/s^2).
    dT, dTdt : ndarray, shape (N, 3), optional
        Temperature offset from ``T_ref`` (degC) and its rate (degC/s) of the triad's three sensors.
    other : ndarray, shape (N, 3), optional
        Gyro: specific force ``f_b`` (for ``g_sensitivity``); accel: angular rate ``omega_nb_b``
        (for ``size_effect``).
    domega : ndarray, shape (N, 3), optional
        Angular acceleration, rad/s^2 (``size_effect``).
    dsignal : ndarray, shape (N, 3), optional
        Time derivative of ``signal`` (``time_lag.accel``).

    Returns
    -------
    ndarray, shape (N, 3)
    """
    signal = np.ascontiguousarray(signal, dtype=float)
    n = signal.shape[0]
    rows = term_rows(layout, triad)
    out = np.empty_like(signal)
    _forward_many(rows, np.array(x, dtype=float), signal, _as3(dT, n), _as3(dTdt, n),
                  _as3(other, n), _as3(domega, n), _as3(dsignal, n), out, np.empty(3))
    return out


def _inverse(layout, x, triad, measured, *, dT, dTdt, other, domega, dsignal, n_iter, jacobian):
    measured = np.ascontiguousarray(measured, dtype=float)
    n = measured.shape[0]
    rows = term_rows(layout, triad)
    out = np.empty_like(measured)
    J = np.zeros((n, 3, layout.size)) if jacobian else np.zeros((n, 3, 1))
    _inverse_many(rows, np.array(x, dtype=float), measured, _as3(dT, n), _as3(dTdt, n),
                  _as3(other, n), _as3(domega, n), _as3(dsignal, n), n_iter, out, J, jacobian)
    return out, J


def correct(layout, x, triad, measured, *, dT=None, dTdt=None, other=None, domega=None, dsignal=None, n_iter=3):
    """Inverse model: the true signal from the measured one.

    Parameters are those of :func:`measure`, with ``measured`` in place of ``signal``
    (``domega`` and ``dsignal`` from the raw measurements; ``other`` the raw rate for the accelerometers,
    the *calibrated* specific force for the gyros: :func:`correct_pair` does both triads that way).

    Returns
    -------
    ndarray, shape (N, 3)
    """
    return _inverse(layout, x, triad, measured, dT=dT, dTdt=dTdt, other=other, domega=domega, dsignal=dsignal,
                    n_iter=n_iter, jacobian=False)[0]


def correct_with_jacobian(layout, x, triad, measured, *, dT=None, dTdt=None, other=None, domega=None,
                          dsignal=None, n_iter=3):
    """:func:`correct` and the Jacobian of the true signal in the calibration.

    Returns
    -------
    signal : ndarray, shape (N, 3)
    J : ndarray, shape (N, 3, layout.size)
        ``d signal / d x``.
    """
    return _inverse(layout, x, triad, measured, dT=dT, dTdt=dTdt, other=other, domega=domega, dsignal=dsignal,
                    n_iter=n_iter, jacobian=True)


def _pair(layout, x, w_raw, f_raw, *, dTg, dTdtg, dTa, dTdta, domega, df, n_iter, jacobian):
    # fresh writable copies: one numba signature whether the caller's arrays are read-only or not
    w_raw = np.array(w_raw, dtype=float)
    f_raw = np.array(f_raw, dtype=float)
    n = w_raw.shape[0]
    if f_raw.shape != w_raw.shape:
        raise ValueError(f"w_raw and f_raw must have the same shape (N, 3), got {w_raw.shape} and {f_raw.shape}")
    w, f = np.empty_like(w_raw), np.empty_like(f_raw)
    shape = (n, 3, layout.size) if jacobian else (n, 3, 1)
    Jw, Jf = np.zeros(shape), np.zeros(shape)
    _inverse_pair_many(term_rows(layout, "gyro"), term_rows(layout, "accel"), np.array(x, dtype=float),
                       w_raw, f_raw, *(np.array(_as3(a, n)) for a in (dTg, dTdtg, dTa, dTdta, domega, df)),
                       int(n_iter), w, f, Jw, Jf, jacobian)
    return w, f, Jw, Jf


def correct_pair(layout, x, w_raw, f_raw, *, dTg=None, dTdtg=None, dTa=None, dTdta=None, domega=None, df=None,
                 n_iter=3):
    """Both triads' true signals from the measured ones, each seeing the other's as ``model.md`` says.

    The accelerometers are corrected first (their ``size_effect`` sees the raw rate ``w_raw`` and
    ``domega``, their time lag ``df``), then the gyros with the calibrated specific force in
    ``g_sensitivity``.

    Parameters
    ----------
    layout : graph_calib.sensors.params.Layout
    x : ndarray, shape (layout.size,)
    w_raw, f_raw : ndarray, shape (N, 3)
        Measured angular rate (rad/s) and specific force (m/s^2).
    dTg, dTdtg, dTa, dTdta : ndarray, shape (N, 3), optional
        Temperature offsets (degC) and rates (degC/s) of the gyro and accelerometer sensors.
    domega, df : ndarray, shape (N, 3), optional
        Raw angular acceleration (rad/s^2) and rate of the specific force (m/s^3).
    n_iter : int

    Returns
    -------
    omega_ib_b, f_b : ndarray, shape (N, 3)
    """
    return _pair(layout, x, w_raw, f_raw, dTg=dTg, dTdtg=dTdtg, dTa=dTa, dTdta=dTdta, domega=domega, df=df,
                 n_iter=n_iter, jacobian=False)[:2]


def correct_pair_with_jacobian(layout, x, w_raw, f_raw, *, dTg=None, dTdtg=None, dTa=None, dTdta=None,
                               domega=None, df=None, n_iter=3):
    """:func:`correct_pair` and both Jacobians in the calibration.

    Returns
    -------
    omega_ib_b, f_b : ndarray, shape (N, 3)
    J_omega, J_f : ndarray, shape (N, 3, layout.size)
        ``d omega / d x`` (accelerometer columns too where ``g_sensitivity`` couples) and ``d f / d x``.
    """
    return _pair(layout, x, w_raw, f_raw, dTg=dTg, dTdtg=dTdtg, dTa=dTa, dTdta=dTdta, domega=domega, df=df,
                 n_iter=n_iter, jacobian=True)


__all__ = ["correct_pair", "correct_pair_with_jacobian", "gsens_coupling", "term_rows", "measure", "correct", "correct_with_jacobian", "correct_sample", "invert_sample", "sample_features",
           "is_nonlinear", "XYZ"]
