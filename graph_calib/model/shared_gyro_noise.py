r"""The gyro noise the table readings of a keyframe interval share with each other and with its rotation factor.

An encoder reading ``i`` at ``tau_i`` into keyframe interval ``k`` compares the table's attitude with
``R_k dR(tau_i)``, and the rotation factor of ``k`` compares ``R_{k+1}`` with ``R_k dR(T_k)``.  Both
preintegrated rotations carry the same gyro noise up to the earlier time: with ``W(tau) = sum_s dR_s n_s h``
(the gyro's white noise ``n`` integrated in the keyframe's body frame, covariance ``q_g^2 tau I``), a reading's
residual (:func:`graph_calib.model.factors.encoder_factors`, turned into its noise frame ``U_i``) holds
``U_i^T dR_i^T W(tau_i)`` and the rotation factor ``-dR_T^T W(T_k)``, so

.. math::

    \operatorname{cov}(e_i, e_j) = q_g^2 \min(\tau_i, \tau_j)\, U_i^T dR_i^T dR_j U_j + \delta_{ij} D_i, \qquad
    \operatorname{cov}(e_i, \rho_k) = -q_g^2 \tau_i\, U_i^T dR_i^T dR_T,

``D_i`` the reading's own noise (the table's and a ring-laser gyro's quantization).  Treated as independent,
the interval's readings and its rotation factor count the same gyro noise several times: the mean of an
interval's readings then has more variance than the model gives it (with ten readings a second, about a
tenth more on a navigation-grade table of 2 arcsec when the gyro's noise is three times the grade's), which the
score tests of the gyro's candidates read as structure (docs/model.md, "The loop's false adoptions").

This module replaces, exactly and linearly, an interval's readings and its rotation factor by independent
ones: a Kalman recursion over the interval's readings in time order, its state ``W``, gives each reading's
innovation ``e_i - U_i^T dR_i^T W_hat`` (independent of the earlier readings) with its covariance ``S_i``, and
the rotation factor less its expectation given every reading of the interval,
``rho + dR_T^T W_hat`` (independent of them all), with covariance
``dR_T^T (P + q_g^2 (T_k - tau_last) I) dR_T``.  Each is then whitened by the unit-lower-triangular factor of
its covariance (``S = L D L^T``: ``L^-1 e`` has the independent sigmas ``sqrt(D)``, and its components stay
nearest the reading's noise frame, so the residual still reads as body axes).  Residuals and Jacobians go
through the same map (it depends on the record, the preintegration's rotations at its linearisation point and
the noise, never on the attitudes or the calibration), so the Jacobians stay those of the residual.  The
chi-square of the interval is unchanged in form: the Mahalanobis norm of the original residuals under the
covariance above.  An interval without readings keeps its rotation factor as it was.

The variance factors (:class:`graph_calib.model.factors.Noise`): the rotation kind's factor ``v_rot`` is the
gyro's, on every term of its noise: the rotation factor's ``v_rot q_g^2 T`` and the readings' ``v_rot q_g^2
tau_i``, so the shared noise stays one noise; the encoder kind's ``v_enc`` scales the readings' own ``D_i``
alone.  (Scaling a reading's gyro term by ``v_enc`` made the two kinds claim different sizes of one noise: with the
floor of the table's unread direction estimated small, that direction's readings know the interval's gyro noise,
and a rotation factor above 1 then added ``(sqrt(v_rot / v_enc) - 1)`` of it back, so that its ``chi2 /
redundancy`` grew with its factor and the variance components diverged.)  The keyframe attitudes are the gyros'
indicated ones, so a quantization error at the keyframe is in neither and nothing else is shared.

Under a robust loss (``GraphOptions.robust``) the map is the same: the readings' robust groups are judged on
their innovations, but the rotation factor, which takes no robust loss, carries the interval's readings
through ``W_hat`` with the gain ``K ~ q_g^2 tau / sigma_enc^2`` (about 4e-3 for a navigation-grade gyro and
2 arcsec readings): a gross reading error of ``e`` moves it by about ``K e``, some 3 of its sigmas for a
100 arcsec spike (9 at three times the gyro noise), where the readings taken as independent kept it out.
Kept so: the filter takes no robust loss, and the two solvers must solve one model.

The gains depend on the record, the preintegration and the noise alone; the record holds those of its last
preintegration and noise (``PreparedRecord.shared_gyro_gains``), so the evaluations of one linearisation point
and its line search form them once.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, replace

import numba
import numpy as np

from graph_calib import kernel_cache
from graph_calib.model.encoder_noise import FLOORED

kernel_cache.install()     # before the first kernel

#: A reading's own variance is never taken below this (rad^2): a record declared noiseless on the table.
MIN_VARIANCE = 1e-30


@numba.njit(cache=True, inline="always")
def _ldl3(S, Ci, L_inv, sigma):
    """``S = L D L^T`` of one symmetric 3 x 3 (``L`` unit lower triangular, its Cholesky factor ``C`` written
    out): ``Ci = C^-1``, ``L_inv = diag(C) C^-1`` (3, 3) and ``sigma = sqrt(D) = diag(C)`` (3,) written."""
    c00 = np.sqrt(S[0, 0])
    c10 = 0.5 * (S[1, 0] + S[0, 1]) / c00
    c20 = 0.5 * (S[2, 0] + S[0, 2]) / c00
    c11 = np.sqrt(S[1, 1] - c10 * c10)
    c21 = (0.5 * (S[2, 1] + S[1, 2]) - c20 * c10) / c11
    c22 = np.sqrt(S[2, 2] - c20 * c20 - c21 * c21)
    Ci[:] = 0.0
    Ci[0, 0], Ci[1, 1], Ci[2, 2] = 1.0 / c00, 1.0 / c11, 1.0 / c22
    Ci[1, 0] = -c10 * Ci[0, 0] / c11
    Ci[2, 1] = -c21 * Ci[1, 1] / c22
    Ci[2, 0] = -(c20 * Ci[0, 0] + c21 * Ci[1, 0]) / c22
    sigma[0], sigma[1], sigma[2] = c00, c11, c22
    for a in range(3):
        for b in range(3):
            L_inv[a, b] = sigma[a] * Ci[a, b]


@numba.njit(cache=True)
def _ldl_many(S, L_inv, sigma):
    """:func:`_ldl3` of each of ``S`` (n, 3, 3) into ``L_inv`` (n, 3, 3) and ``sigma`` (n, 3)."""
    Ci = np.empty((3, 3))
    for n in range(S.shape[0]):
        _ldl3(S[n], Ci, L_inv[n], sigma[n])


@numba.njit(cache=True)
def _gains(order, group, tau, U, dR, D, q2, H, K, L_inv, sigma, Pw, tau_last):
    """The recursion's gains, reading by reading in ``order``: ``H = U^T dR^T``, ``K``, ``L_inv`` (M, 3, 3) and
    ``sigma`` (M, 3) written; ``Pw`` (G, 3, 3) and ``tau_last`` (G,), zero on entry, end as each interval's
    covariance of its gyro noise given its readings and its last reading's time.

    ``P = Pw_g + q2 (tau_i - tau_last_g) I``, ``S = H_i P H_i^T + diag(D_i) = C C^T`` (:func:`_ldl3`),
    ``K_i = P H_i^T S^-1``, ``Pw_g = P - K_i H_i P``, ``L_inv`` and ``sigma`` those of :func:`_ldl3`.
    """
    P = np.empty((3, 3))
    PHt = np.empty((3, 3))
    S = np.empty((3, 3))
    Ci = np.empty((3, 3))
    Si = np.empty((3, 3))
    KH = np.empty((3, 3))
    for n in range(order.size):
        i = order[n]
        g = group[i]
        for a in range(3):                               # H = U^T dR^T: H[a, b] = sum_c U[c, a] dR[b, c]
            for b in range(3):
                H[i, a, b] = U[i, 0, a] * dR[i, b, 0] + U[i, 1, a] * dR[i, b, 1] + U[i, 2, a] * dR[i, b, 2]
        dq = q2 * (tau[i] - tau_last[g])
        for a in range(3):
            for b in range(3):
                P[a, b] = Pw[g, a, b] + (dq if a == b else 0.0)
        for a in range(3):
            for b in range(3):
                PHt[a, b] = P[a, 0] * H[i, b, 0] + P[a, 1] * H[i, b, 1] + P[a, 2] * H[i, b, 2]
        for a in range(3):
            for b in range(3):
                S[a, b] = H[i, a, 0] * PHt[0, b] + H[i, a, 1] * PHt[1, b] + H[i, a, 2] * PHt[2, b]
        for a in range(3):
            S[a, a] += D[i, a]
        _ldl3(S, Ci, L_inv[i], sigma[i])
        for a in range(3):                               # S^-1 = C^-T C^-1
            for b in range(3):
                Si[a, b] = Ci[0, a] * Ci[0, b] + Ci[1, a] * Ci[1, b] + Ci[2, a] * Ci[2, b]
        for a in range(3):
            for b in range(3):
                K[i, a, b] = PHt[a, 0] * Si[0, b] + PHt[a, 1] * Si[1, b] + PHt[a, 2] * Si[2, b]
        for a in range(3):
            for b in range(3):
                KH[a, b] = K[i, a, 0] * H[i, 0, b] + K[i, a, 1] * H[i, 1, b] + K[i, a, 2] * H[i, 2, b]
        for a in range(3):
            for b in range(3):
                Pw[g, a, b] = P[a, b] - (KH[a, 0] * P[0, b] + KH[a, 1] * P[1, b] + KH[a, 2] * P[2, b])
        tau_last[g] = tau[i]


@numba.njit(cache=True)
def _innovations(order, group, H, K, L_inv, Y, out, W, cols):
    """The readings' whitened innovations: the columns ``cols`` of ``out`` (M, 3, C) from those of ``Y``, the
    residuals or a Jacobian (its other columns zero and left alone).

    In ``order`` (interval by interval, each in time), reading ``i`` of interval ``group[i]``:
    ``e = Y_i - H_i W_g``, ``W_g += K_i e``, ``out_i = L_inv_i e``; ``W`` (G, 3, len(cols)), zero on entry, ends
    as each interval's estimate of its gyro noise given its readings, in those columns.
    """
    n_c = cols.size
    e = np.empty((3, n_c))
    for n in range(order.size):
        i = order[n]
        g = group[i]
        for a in range(3):
            for j in range(n_c):
                e[a, j] = (Y[i, a, cols[j]] - H[i, a, 0] * W[g, 0, j] - H[i, a, 1] * W[g, 1, j]
                           - H[i, a, 2] * W[g, 2, j])
        for a in range(3):
            for j in range(n_c):
                W[g, a, j] += K[i, a, 0] * e[0, j] + K[i, a, 1] * e[1, j] + K[i, a, 2] * e[2, j]
                out[i, a, cols[j]] = L_inv[i, a, 0] * e[0, j] + L_inv[i, a, 1] * e[1, j] + L_inv[i, a, 2] * e[2, j]


@dataclass(frozen=True)
class _Gains:
    """The map of one record, preintegration and noise (its arrays shared by every evaluation there).

    ``order``, ``group`` (M,): the readings interval by interval in time, and each one's interval; ``keys``
    (G,): each interval's keyframe; ``H``, ``K``, ``L_inv`` (M, 3, 3), ``sigma`` (M, 3): :func:`_gains`; ``f``:
    the rotation factors whose interval has readings, ``g`` that interval; ``A`` (F, 3, 3): the gyro noise
    estimate's map into each such factor, ``rot_L_inv`` (F, 3, 3) and ``rot_sigma`` (F, 3): its whitening.
    """

    order: np.ndarray
    group: np.ndarray
    keys: np.ndarray
    H: np.ndarray
    K: np.ndarray
    L_inv: np.ndarray
    sigma: np.ndarray
    f: np.ndarray
    g: np.ndarray
    A: np.ndarray
    rot_L_inv: np.ndarray
    rot_sigma: np.ndarray


def _cached_gains(record, preint, noise, rot, enc):
    """The :class:`_Gains` of ``record``, ``preint`` and ``noise``: the record's one-entry cache when it holds
    this preintegration and noise (the map depends on nothing else), else formed and held."""
    v_enc = float(noise.variance_factors.get("encoder", 1.0))
    v_rot = float(noise.variance_factors.get("rotation", 1.0))
    q2 = noise.gyro**2
    key = (q2, v_enc, v_rot, float(noise.variance_factors.get(FLOORED, 1.0)), float(noise.encoder),
           float(noise.gyro_quantization), enc.key.size, rot.key.size)
    held = getattr(record, "shared_gyro_gains", None)
    if held is not None and held[0]() is preint and held[1] == key:
        return held[2]
    M = enc.key.size
    tau = record.reading_tau
    q2v = v_rot * q2                    # the gyro's noise, the rotation kind's factor applied (factors.encoder_factors)
    D = np.maximum(enc.sigma**2 - (q2v * tau)[:, None], MIN_VARIANCE)       # the reading's own noise
    # the readings interval by interval, each in time (the record's order already, or sorted)
    k = np.asarray(enc.key, dtype=np.int64)
    if np.all(np.diff(k) >= 0) and np.all((np.diff(tau) >= 0) | (np.diff(k) > 0)):
        order = np.arange(M, dtype=np.int64)
    else:
        order = np.lexsort((tau, k)).astype(np.int64)
    new = np.empty(M, dtype=bool)
    new[0], new[1:] = True, np.diff(k[order]) != 0
    group = np.empty(M, dtype=np.int64)
    group[order] = np.cumsum(new) - 1
    keys = k[order][new]
    c = np.ascontiguousarray
    H, K, L_inv, sigma = np.empty((M, 3, 3)), np.empty((M, 3, 3)), np.empty((M, 3, 3)), np.empty((M, 3))
    Pw, tau_last = np.zeros((keys.size, 3, 3)), np.zeros(keys.size)
    _gains(order, group, c(tau, dtype=float), c(record.encoder_noise_frame(noise.encoder).U, dtype=float),
           c(preint.reading_dR, dtype=float), c(D), q2v, H, K, L_inv, sigma, Pw, tau_last)
    # each rotation factor less its expectation given its interval's readings: the map of that expectation and
    # the remaining covariance's whitening
    f = np.flatnonzero(np.isin(rot.key, keys))
    g = np.searchsorted(keys, rot.key[f])
    dR_T = preint.dR[rot.key[f]]
    dR_Tt = np.swapaxes(dR_T, 1, 2)
    rest = (q2v * (record.T_key[rot.key[f]] - tau_last[g]))[:, None, None] * np.eye(3)
    C = dR_Tt @ (Pw[g] + rest) @ dR_T
    rot_L_inv, rot_sigma = np.empty((f.size, 3, 3)), np.empty((f.size, 3))
    _ldl_many(c(0.5 * (C + np.swapaxes(C, 1, 2))), rot_L_inv, rot_sigma)
    gains = _Gains(order=order, group=group, keys=keys, H=H, K=K, L_inv=L_inv, sigma=sigma, f=f, g=g,
                   A=dR_Tt, rot_L_inv=rot_L_inv, rot_sigma=rot_sigma)
    record.shared_gyro_gains = (weakref.ref(preint), key, gains)
    return gains


def decorrelate(record, preint, noise, rot, enc, *, columns=None, overwrite_input=False):
    """The rotation and encoder factors with their shared gyro noise made independent (module docstring).

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
    preint : graph_calib.model.preintegration.Preintegrated
        Its rotations at the linearisation point set the frames of the map.
    noise : graph_calib.model.factors.Noise
        The model's noise, its variance factors included.
    rot, enc : graph_calib.model.factors.Residuals
        The rotation and encoder factors as the model gives them (each kind's variance factor applied).
    columns : ndarray of int, optional
        The calibration columns the encoder factors' Jacobian can touch (:func:`graph_calib.model.factors.encoder_columns`;
        default every column): the others are zero and stay zero, and are not mapped.
    overwrite_input : bool
        Write the results into the factors' own residual and Jacobian arrays (C-contiguous float64) instead of
        new ones (scipy.linalg's ``overwrite_a``): the residual list's fresh factors, whose Jacobians on a 3 h
        record are some 80 MB.

    Returns
    -------
    rot, enc : graph_calib.model.factors.Residuals
        The same factors after the map: same keys and shapes; the readings' and the rotation factors' sigmas
        those of the independent residuals.
    """
    if enc.key.size == 0 or noise.gyro <= 0.0:
        return rot, enc
    m = _cached_gains(record, preint, noise, rot, enc)
    c = np.ascontiguousarray
    cols = np.arange(enc.H_x.shape[2], dtype=np.int64) if columns is None else np.asarray(columns, dtype=np.int64)
    G = m.keys.size
    W_r, W_R, W_x = np.zeros((G, 3, 1)), np.zeros((G, 3, 3)), np.zeros((G, 3, cols.size))
    ins = [c(enc.r, dtype=float)[:, :, None], c(enc.H_R, dtype=float), c(enc.H_x, dtype=float)]
    r, H_R, H_x = ins if overwrite_input else [np.zeros_like(a) for a in ins]
    for Y, out, W, cl in zip(ins, (r, H_R, H_x), (W_r, W_R, W_x),
                             (np.arange(1, dtype=np.int64), np.arange(3, dtype=np.int64), cols)):
        _innovations(m.order, m.group, m.H, m.K, m.L_inv, Y, out, W, cl)
    enc = replace(enc, r=r[:, :, 0], H_R=H_R, H_x=H_x, sigma=m.sigma.copy())
    if m.f.size == 0:
        return rot, enc
    if overwrite_input:
        rr, rR, rx, rN, rs = rot.r, rot.H_R, rot.H_x, rot.H_R_next, rot.sigma
    else:
        rr, rR, rx, rN, rs = rot.r.copy(), rot.H_R.copy(), rot.H_x.copy(), rot.H_R_next.copy(), rot.sigma.copy()
    f, g, A, L = m.f, m.g, m.A, m.rot_L_inv
    rr[f] = np.einsum("nab,nb->na", L, rr[f] + np.einsum("nab,nb->na", A, W_r[g, :, 0]))
    rR[f] = L @ (rR[f] + A @ W_R[g])
    x_f = rx[f]
    x_f[:, :, cols] += A @ W_x[g]
    rx[f] = L @ x_f
    rN[f] = L @ rN[f]
    rs[f] = m.rot_sigma
    return replace(rot, r=rr, H_R=rR, H_R_next=rN, H_x=rx, sigma=rs), enc


__all__ = ["decorrelate", "MIN_VARIANCE"]
