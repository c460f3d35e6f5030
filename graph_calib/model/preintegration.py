r"""Calibrated preintegration: the samples of every keyframe and encoder reading at one calibration.

:func:`preintegrate` runs the compiled kernel (:mod:`graph_calib.model.kernel`) over a
:class:`graph_calib.model.record.PreparedRecord`; the :class:`Preintegrated` it returns owns its
first-order correction (as GTSAM's ``PreintegratedRotation`` owns its bias correction): a small
change ``dx`` of the calibration is applied as ``dR Exp(J dx)``, ``S + J_S dx``, ... by
:meth:`Preintegrated.corrected`, and :meth:`Preintegrated.needs_repreintegration` says when ``dx``
has grown too large for that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.model.kernel import _preintegrate
from graph_calib.navigation.rotations import exp_so3
from graph_calib.sensors.sensor_model import GSENS, correct_pair_with_jacobian, term_rows

#: Largest first-order keyframe rotation change (rad) for which a preintegration is updated to first
#: order (``dR Exp(J dx)``, ``S + J_S dx``) instead of redone; every solver uses it.
REPREINTEGRATE_TOL = 1e-5


@dataclass(frozen=True)
class SensorTerms:
    """The sensor-model term rows of a layout, as the kernel and the factors use them.

    Attributes
    ----------
    gyro_rows, accel_rows : ndarray of int64, shape (R, 4)
        Term rows ``(column of x, axis, code, aux)`` (:func:`graph_calib.sensors.sensor_model.term_rows`).
    columns : ndarray of int64
        The columns of ``x`` any term touches.
    gyro_rows_compact, accel_rows_compact : ndarray of int64
        The same rows with columns renumbered into ``columns``.
    gyro_cols : ndarray of int64
        The columns the calibrated rate depends on, ascending: the gyro terms', and with
        ``gyro.g_sensitivity`` the accelerometer terms' too (the gyros see the calibrated specific force).
        The rate's and the rotation's Jacobians are zero in every other column.
    """

    gyro_rows: np.ndarray
    accel_rows: np.ndarray
    columns: np.ndarray
    gyro_rows_compact: np.ndarray
    accel_rows_compact: np.ndarray
    gyro_cols: np.ndarray

    @classmethod
    def of(cls, layout):
        """The terms of ``layout`` (:class:`graph_calib.sensors.params.Layout`)."""
        gyro = term_rows(layout, "gyro")
        accel = term_rows(layout, "accel")
        cols = np.unique(np.concatenate([gyro[:, 0], accel[:, 0]])).astype(np.int64)
        g = gyro[:, 0]
        if np.any(gyro[:, 2] == GSENS):
            g = np.concatenate([g, accel[:, 0]])
        gyro_cols = np.unique(g).astype(np.int64)
        remap = -np.ones(layout.size, dtype=np.int64)
        remap[cols] = np.arange(cols.size)
        gyro_c, accel_c = gyro.copy(), accel.copy()
        gyro_c[:, 0] = remap[gyro_c[:, 0]]
        accel_c[:, 0] = remap[accel_c[:, 0]]
        return cls(gyro_rows=gyro, accel_rows=accel, columns=cols, gyro_rows_compact=gyro_c,
                   accel_rows_compact=accel_c, gyro_cols=gyro_cols)


@dataclass(frozen=True)
class Corrected:
    """The keyframe quantities of a preintegration corrected to first order (:meth:`Preintegrated.corrected`)."""

    dR: np.ndarray
    S: np.ndarray
    S1: np.ndarray
    w_b: np.ndarray


@dataclass(frozen=True)
class Preintegrated:
    """Everything the factors need from the samples, at one calibration ``x_lin``.

    Shapes: K keyframes, M encoder readings, P = layout size.

    Attributes
    ----------
    x_lin : (P,)
    dR : (K, 3, 3)      preintegrated rotation of each keyframe
    J_dR : (K, 3, P)    its right-perturbation Jacobian in x
    S, J_S : (K, 3), (K, 3, P)     velocity increment in the keyframe-start body frame, m/s
    S1, J_S1 : (K, 3), (K, 3, P)   the same weighted by time since the keyframe start, m s
    w_b, J_w_b : (K+1, 3), (K+1, 3, P)  corrected angular rate omega_ib_b at each boundary, rad/s
    reading_dR : (M, 3, 3)  partial preintegration up to each encoder reading
    reading_J : (M, 3, G)  its right-perturbation Jacobian in the columns ``gyro_cols`` (G of them; the rotation
        depends on no other column of ``x``)
    reading_w : (M, 3)  calibrated mean rate of the sample interval holding each reading, rad/s
    reading_J_w : (M, 3, G)  its Jacobian in the columns ``gyro_cols``, at ``x_lin``, read-only: formed once
        with ``reading_w`` (the sensor model's inversion gives both), read by every evaluation of the encoder
        factors (:meth:`reading_rate_jacobian`); 37 MB for a 3-h record's 85,800 readings and the declared
        model's 18 gyro columns
    gyro_cols : ndarray of int64
        The columns of ``x`` the calibrated rate and the rotations depend on (:class:`SensorTerms`), G of them.
    record, layout, n_newton
        What the preintegration was formed from (references: which record, layout and Newton steps it is of).
    """

    x_lin: np.ndarray
    dR: np.ndarray
    J_dR: np.ndarray
    S: np.ndarray
    J_S: np.ndarray
    S1: np.ndarray
    J_S1: np.ndarray
    w_b: np.ndarray
    J_w_b: np.ndarray
    reading_dR: np.ndarray
    reading_J: np.ndarray
    reading_w: np.ndarray
    reading_J_w: np.ndarray
    gyro_cols: np.ndarray
    record: object
    layout: object
    n_newton: int

    def needs_repreintegration(self, x, *, tol=REPREINTEGRATE_TOL):
        """Whether ``x`` moved so far from ``x_lin`` that first-order updates lose accuracy.

        The test is the largest first-order change of a keyframe rotation, rad.
        """
        dx = np.asarray(x) - self.x_lin
        return float(np.max(np.abs(self.J_dR @ dx))) > tol

    def corrected(self, x):
        """The preintegrated quantities at ``x``, to first order in ``dx = x - x_lin``.

        Returns
        -------
        Corrected
            ``dR Exp(J_dR dx)``, ``S + J_S dx``, ``S1 + J_S1 dx``, ``w_b + J_w_b dx``.
        """
        dx = np.asarray(x) - self.x_lin
        return Corrected(dR=self.dR @ exp_so3(self.J_dR @ dx), S=self.S + self.J_S @ dx,
                         S1=self.S1 + self.J_S1 @ dx, w_b=self.w_b + self.J_w_b @ dx)

    def reading_rate_jacobian(self, readings=slice(None)):
        """``d reading_w / d x`` in the columns ``gyro_cols``, (m, 3, G), at ``x_lin``, of the readings
        ``readings`` (a slice): a read-only view of :attr:`reading_J_w`."""
        return self.reading_J_w[readings]


#: Readings per block in :func:`_reading_rates` (the sensor model's (n, 3, P) Jacobians are temporaries: 0.35-0.4 GB
#: for a 3-h record's readings at once).
READING_BLOCK = 8192


def _reading_rates(record, layout, x, n_newton, gyro_cols):
    """Calibrated mean rate of each reading's sample interval (M, 3), rad/s, and its Jacobian in ``gyro_cols``
    (M, 3, G).

    Sample by sample (the sensor model's inversion is per sample), in blocks of :data:`READING_BLOCK`.
    """
    r = record
    n_all = r.reading_interval
    M = n_all.size
    w = np.empty((M, 3))
    J = np.empty((M, 3, gyro_cols.size))
    for lo in range(0, M, READING_BLOCK):
        n = n_all[lo:lo + READING_BLOCK]
        wb, _, Jb, _ = correct_pair_with_jacobian(layout, x, r.w_raw[n], r.f_raw[n], dTg=r.dTg[n], dTdtg=r.dTdtg[n],
                                                  dTa=r.dTa[n], dTdta=r.dTdta[n], domega=r.dw_raw[n],
                                                  df=r.df_raw[n], n_iter=n_newton)
        w[lo:lo + n.size] = wb
        J[lo:lo + n.size] = Jb[:, :, gyro_cols]
    return w, J


def preintegrate(record, terms, x, *, layout, n_newton):
    """Preintegrate every keyframe and encoder reading of ``record`` at calibration ``x`` (P,).

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
    terms : SensorTerms
        The sensor terms of ``layout``.
    x : ndarray, shape (P,)
    layout : graph_calib.sensors.params.Layout
    n_newton : int
        Newton steps of the sensor-model inversion.

    Returns
    -------
    Preintegrated
    """
    x = np.array(x, dtype=float)   # a copy, C-contiguous and writable: one kernel signature
    K = record.n_keyframes
    M = record.reading_sample.size
    P = layout.size
    dR = np.empty((K, 3, 3))
    JR = np.zeros((K, 3, P))
    S = np.empty((K, 3))
    JS = np.zeros((K, 3, P))
    S1 = np.empty((K, 3))
    JS1 = np.zeros((K, 3, P))
    wf = np.empty((K, 3))
    Jwf = np.zeros((K, 3, P))
    wl = np.empty((K, 3))
    Jwl = np.zeros((K, 3, P))
    readR = np.empty((M, 3, 3))
    readJ = np.zeros((M, 3, P))
    r = record
    # term rows with layout columns: the kernel adds straight into the (..., 3, P) arrays
    _preintegrate(r.dt, r.k0, x, terms.gyro_rows, terms.accel_rows,
                  r.dTg, r.dTdtg, r.dTa, r.dTdta, r.w_raw, r.f_raw,
                  r.dw_raw, r.df_raw, r.reading_sample, r.reading_lo, n_newton,
                  dR, JR, S, JS, S1, JS1, wf, Jwf, wl, Jwl, readR, readJ)
    w_b = np.empty((K + 1, 3))
    Jw_b = np.empty((K + 1, 3, P))
    w_b[0], Jw_b[0] = wf[0], Jwf[0]
    w_b[K], Jw_b[K] = wl[K - 1], Jwl[K - 1]
    w_b[1:K] = 0.5 * (wl[:-1] + wf[1:])
    Jw_b[1:K] = 0.5 * (Jwl[:-1] + Jwf[1:])
    w_b += r.w_b_fix
    # the readings' rates and their Jacobian in the gyro columns at once (the inversion forms both), kept:
    # every evaluation of the encoder factors at any x reads that Jacobian at x_lin
    read_w, read_Jw = _reading_rates(r, layout, x, n_newton, terms.gyro_cols)
    read_Jw.setflags(write=False)
    # the readings' rotation Jacobian kept in the gyro columns alone (the others are zero; the kernel's (M, 3, P)
    # array freed): with the rate Jacobian, less than the (M, 3, P) one alone wherever G < P / 2
    readJ = readJ[:, :, terms.gyro_cols]
    return Preintegrated(x_lin=x.copy(), dR=dR, J_dR=JR, S=S, J_S=JS, S1=S1, J_S1=JS1, w_b=w_b, J_w_b=Jw_b,
                         reading_dR=readR, reading_J=readJ, reading_w=read_w, reading_J_w=read_Jw,
                         gyro_cols=terms.gyro_cols,
                         record=record, layout=layout, n_newton=int(n_newton))


__all__ = ["READING_BLOCK", "REPREINTEGRATE_TOL", "SensorTerms", "Preintegrated", "Corrected", "preintegrate"]
