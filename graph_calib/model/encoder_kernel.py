r"""The compiled rows of the encoder factors (numba), one table reading after the other.

:func:`graph_calib.model.factors.encoder_factors` calls :func:`encoder_rows` on blocks of readings; nothing else
should.  Per reading ``i`` (the formulas of that function's docstring, written out):

- the turn from the sample end to the reading with the calibrated rate, to first order in ``dx`` from the
  preintegration point: ``readR = reading_dR Exp(reading_J dx_g)``, ``w_c = reading_w + J_w dx_g``,
  ``phi = w_c dt + phi_shape``, ``Bp = readR Exp(phi)``;
- the predicted attitude ``C_pred = E R_k Bp`` and the measured one ``C_meas = C_nominal (Exp(mount) B)``,
  ``B = Exp(a_lag) Ed`` (``a_lag = w_nb lag - lag^2 alpha / 2``, ``Ed = Exp(K f)`` for the damping stiffness
  ``K``), the residual ``r = Log(C_meas^T C_pred)``;
- the Jacobians: ``H_R = Jr^-1(r) Bp^T``; in the gyro columns ``Jr^-1(r) (Exp(phi)^T reading_J + Jr(phi) dt J_w)``
  (plus ``G_lag lag J_w`` with a lag); ``mount``, ``time_lag.table`` and ``damping.stiffness`` their own;
- the reading noise's principal axes (``rotated`` readings): ``r``, ``H_R`` and the written columns of ``H_x``
  turned by ``U^T``.

Every small product is a loop over 3 x 3 blocks, with no temporaries: the numpy version this replaces formed
``(m, 3, G)`` stacks for each step (docs/performance.md, "One 3 h job of the first wave";
``tests/model/test_encoder_kernel.py`` keeps it as the oracle).
"""

from __future__ import annotations

import numba
import numpy as np

from graph_calib import kernel_cache
from graph_calib.navigation.rotations import (
    exp_so3_nb,
    log_so3_nb,
    mat3_mul_nb as _mul,
    mat3_mult_nb as _mul_bt,
    mat3_tmul_nb as _mul_t,
    right_jacobian_inv_nb,
    right_jacobian_nb,
)

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on


@numba.njit(cache=True)
def encoder_rows(reading_dR, reading_w, reading_J, J_w, dx_g, dt, phi_shape, key, E, R, w_offset, alpha, f,
                 C_nominal, mount, lag, K_damp, damped, gyro_cols, mount_col, lag_col, damp_col, written, U,
                 rotated, r, H_R, H_x):
    """Residuals, attitude and calibration Jacobians of a block of ``m`` readings (the module docstring).

    Parameters
    ----------
    reading_dR : (m, 3, 3)
        Preintegrated turns to the readings at the preintegration point.
    reading_w, J_w : (m, 3), (m, 3, G)
        The readings' calibrated mean rates there and their Jacobian in the gyro columns.
    reading_J : (m, 3, G)
        The turns' Jacobian in the gyro columns.
    dx_g : (G,)
        ``x - x_lin`` in the gyro columns.
    dt, phi_shape, key, E, w_offset, alpha, f, C_nominal : (m,), (m, 3), (m,) int, (m, 3, 3), (m, 3), (m, 3),
        (m, 3), (m, 3, 3)
        The prepared record's reading arrays (:class:`graph_calib.model.record.PreparedRecord`).
    R : (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.
    mount, lag, K_damp : (3,), float, (3, 3)
        Their values (zero when the layout lacks them).
    damped : bool
        Whether ``K_damp`` has a non-zero element (else ``Ed = I``).
    gyro_cols : (G,) int
        Layout columns of the gyro columns.
    mount_col, lag_col, damp_col : int
        First layout column of ``mount`` (3), ``time_lag.table`` (1), ``damping.stiffness`` (9); -1 when absent.
    written : (W,) int
        Every column written above, once each (those the noise's axes turn).
    U, rotated : (m, 3, 3), (m,) bool
        The reading noise's principal axes and whether a reading is turned into them.
    r, H_R, H_x : (m, 3), (m, 3, 3), (m, 3, P)
        Written; ``H_x`` zero on entry (only the model's columns are written).
    """
    m = dt.shape[0]
    G = gyro_cols.shape[0]
    Em = np.empty((3, 3))
    exp_so3_nb(mount[0], mount[1], mount[2], Em)
    Jm = np.empty((3, 3))
    right_jacobian_nb(mount[0], mount[1], mount[2], Jm)
    T1 = np.empty((3, 3))
    T2 = np.empty((3, 3))
    T3 = np.empty((3, 3))
    readR = np.empty((3, 3))
    Ew = np.empty((3, 3))
    Bp = np.empty((3, 3))
    Ed = np.empty((3, 3))
    El = np.empty((3, 3))
    B = np.empty((3, 3))
    EmB = np.empty((3, 3))
    Cm = np.empty((3, 3))
    Jri = np.empty((3, 3))
    Jli = np.empty((3, 3))
    Jphi = np.empty((3, 3))
    Glag = np.empty((3, 3))
    H = np.empty((3, 3))
    a = np.empty(3)
    w_c = np.empty(3)
    phi = np.empty(3)
    w_nb = np.empty(3)
    a_lag = np.empty(3)
    a_damp = np.empty(3)
    res = np.empty(3)
    da = np.empty(3)
    col = np.empty(3)
    for i in range(m):
        # the turn to the reading and the calibrated rate, to first order from the preintegration point
        for c in range(3):
            s = 0.0
            sw = 0.0
            for g in range(G):
                s += reading_J[i, c, g] * dx_g[g]
                sw += J_w[i, c, g] * dx_g[g]
            a[c] = s
            w_c[c] = reading_w[i, c] + sw
        exp_so3_nb(a[0], a[1], a[2], T1)
        _mul(reading_dR[i], T1, readR)
        for c in range(3):
            phi[c] = w_c[c] * dt[i] + phi_shape[i, c]
            w_nb[c] = w_c[c] + w_offset[i, c]
            a_lag[c] = w_nb[c] * lag - (0.5 * lag * lag) * alpha[i, c]
            a_damp[c] = f[i, 0] * K_damp[c, 0] + f[i, 1] * K_damp[c, 1] + f[i, 2] * K_damp[c, 2]
        exp_so3_nb(phi[0], phi[1], phi[2], Ew)
        _mul(readR, Ew, Bp)
        _mul(E[i], R[key[i]], T1)
        _mul(T1, Bp, T2)                                    # C_pred
        if damped:
            exp_so3_nb(a_damp[0], a_damp[1], a_damp[2], Ed)
        else:
            for p in range(3):
                for q in range(3):
                    Ed[p, q] = 1.0 if p == q else 0.0
        if lag != 0.0:
            exp_so3_nb(a_lag[0], a_lag[1], a_lag[2], El)
            _mul(El, Ed, B)
        else:
            for p in range(3):
                for q in range(3):
                    B[p, q] = Ed[p, q]
        _mul(Em, B, EmB)
        _mul(C_nominal[i], EmB, Cm)                         # C_meas
        _mul_t(Cm, T2, T3)
        log_so3_nb(T3, res)
        right_jacobian_inv_nb(res[0], res[1], res[2], Jri)
        right_jacobian_inv_nb(-res[0], -res[1], -res[2], Jli)
        _mul_bt(Jri, Bp, T1)
        for p in range(3):
            r[i, p] = res[p]
            for q in range(3):
                H_R[i, p, q] = T1[p, q]
        # the gyro columns: Jr^-1(r) (Exp(phi)^T reading_J + Jr(phi) dt J_w)
        right_jacobian_nb(phi[0], phi[1], phi[2], Jphi)
        for p in range(3):
            for q in range(3):
                Jphi[p, q] *= dt[i]
        for g in range(G):
            for p in range(3):
                col[p] = ((Ew[0, p] * reading_J[i, 0, g] + Ew[1, p] * reading_J[i, 1, g]
                           + Ew[2, p] * reading_J[i, 2, g])
                          + (Jphi[p, 0] * J_w[i, 0, g] + Jphi[p, 1] * J_w[i, 1, g] + Jphi[p, 2] * J_w[i, 2, g]))
            cg = gyro_cols[g]
            for p in range(3):
                H_x[i, p, cg] = Jri[p, 0] * col[0] + Jri[p, 1] * col[1] + Jri[p, 2] * col[2]
        if mount_col >= 0:
            for p in range(3):
                for q in range(3):
                    T1[p, q] = -Jli[p, q]
            _mul_bt(T1, B, T2)
            _mul(T2, Jm, T3)
            for p in range(3):
                for q in range(3):
                    H_x[i, p, mount_col + q] = T3[p, q]
        if lag_col >= 0:
            for p in range(3):
                for q in range(3):
                    T1[p, q] = -Jli[p, q]
            _mul_bt(T1, Ed, T2)
            right_jacobian_nb(a_lag[0], a_lag[1], a_lag[2], T3)
            _mul(T2, T3, Glag)
            for c in range(3):
                da[c] = w_nb[c] - lag * alpha[i, c]
            for p in range(3):
                H_x[i, p, lag_col] = Glag[p, 0] * da[0] + Glag[p, 1] * da[1] + Glag[p, 2] * da[2]
            if lag != 0.0:
                for g in range(G):
                    cg = gyro_cols[g]
                    for p in range(3):
                        H_x[i, p, cg] += (Glag[p, 0] * (lag * J_w[i, 0, g]) + Glag[p, 1] * (lag * J_w[i, 1, g])
                                          + Glag[p, 2] * (lag * J_w[i, 2, g]))
        if damp_col >= 0:
            for p in range(3):
                for q in range(3):
                    T1[p, q] = -Jli[p, q]
            right_jacobian_nb(a_damp[0], a_damp[1], a_damp[2], T2)
            _mul(T1, T2, H)
            for p in range(3):
                for q in range(3):
                    for j in range(3):
                        H_x[i, p, damp_col + 3 * q + j] = H[p, q] * f[i, j]
        if rotated[i]:
            # into the noise's principal axes: U^T r, U^T H_R, U^T H_x (the columns written above)
            for p in range(3):
                col[p] = U[i, 0, p] * r[i, 0] + U[i, 1, p] * r[i, 1] + U[i, 2, p] * r[i, 2]
            for p in range(3):
                r[i, p] = col[p]
            for q in range(3):
                for p in range(3):
                    col[p] = U[i, 0, p] * H_R[i, 0, q] + U[i, 1, p] * H_R[i, 1, q] + U[i, 2, p] * H_R[i, 2, q]
                for p in range(3):
                    H_R[i, p, q] = col[p]
            for w in range(written.shape[0]):
                cw = written[w]
                for p in range(3):
                    col[p] = U[i, 0, p] * H_x[i, 0, cw] + U[i, 1, p] * H_x[i, 1, cw] + U[i, 2, p] * H_x[i, 2, cw]
                for p in range(3):
                    H_x[i, p, cw] = col[p]


__all__ = ["encoder_rows"]
