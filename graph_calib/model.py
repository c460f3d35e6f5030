r"""The shared calibration model: one place for every equation both solvers use.

The record is cut into keyframe intervals (about 0.1-1 s).  For interval ``k``,
``R_k = C_nb`` at its start, and with the gyro and accelerometer samples
corrected by the calibration ``x`` (:mod:`graph_calib.sensor_model`):

Rotation (process) model
    ``R_{k+1} = E(T_k) @ R_k @ dR_k(x)``, with ``dR_k`` the preintegrated
    rotation of the corrected increments (two-sample coning correction) and
    ``E(T) = Exp(-omega_ie_n * T)`` the turn of the level frame with the Earth.
    Residual ``Log((E R_k dR_k)^T R_{k+1})``, covariance ``q_g^2 T_k I``
    (``q_g`` the gyro angle random walk).

Gravity measurement
    The specific force integrated in the level frame over the interval, each
    sample rotated with its own attitude,
    ``dv_n = sum_j C_nb(t_{j-1}) u_j``,
    ``u = dv + 1/2 dth x dv + 1/6 dth x (dth x dv) + h^2/12 (dth x fdot - alpha x dv)``
    (exact to third order in the sample interval ``h`` when the rate and the
    specific force vary linearly over the sample; the angular acceleration
    ``alpha`` and ``fdot = df_b/dt`` are taken from the raw data),
    equals ``g_up * T_k`` plus the change of the velocity of the accelerometer
    point, ``C_nb (omega_nb_b x l)`` (the rotation centre is fixed), and the
    Coriolis integral ``2 omega_ie_n x`` the change of its position ``C_nb l``:
    with ``v = C_nb (omega_ib_b x l) + omega_ie_n x (C_nb l)`` (which is both),
    ``r = (dv_n - [v(t_{k+1}) - v(t_k)]) / T_k - [0, 0, g]``.  With
    ``C_nb(t) = E(t - t_k) R_k dR(t)``, ``dv_n = R_k S - [omega_ie_n x] R_k S1``
    where ``S = sum dR_{j-1} u_j`` and ``S1 = sum (t_{j-1} + h_j/2 - t_k) dR_{j-1} u_j``
    are preintegrated once per calibration.  Covariance
    ``q_a^2 / T_k`` per axis plus ``g^2 q_g^2 T_k / 3`` on the horizontal axes
    (attitude noise inside the interval).

Encoder measurement
    A valid table reading at ``t_m`` (sample ``j``, ``dt_m = t_m - t_j``; the
    sample interval of length ``h`` holding ``t_m`` has the calibrated mean rate
    ``w(x)`` and the raw slope ``alpha``, the rate taken linear inside it):
    ``C_meas = C_nf(t_m) C_fb Exp(mount) Exp(a_lag) Exp(K f_m)`` against
    ``C_pred = E(t_m - t_k) R_k dR_{k,j} Exp(phi)``, residual
    ``Log(C_meas^T C_pred)``, with the turn from the sample end to the reading
    ``phi = w dt_m + alpha dt_m (dt_m - h) / 2`` and the turn over the lag before
    it ``a_lag = w_nb lag - alpha lag^2 / 2``, ``w_nb = w + alpha (dt_m - h/2) -
    (C_nf C_fb)^T omega_ie_n`` (the rate against the level frame at ``t_m``);
    ``f_m`` is the raw specific force of that interval and ``K``
    ``damping.stiffness`` when modelled.  Covariance ``sigma_enc^2 + q_g^2 (t_m - t_k)``.

Jacobians are with respect to the right perturbation of ``R_k``
(``R_k Exp(delta)``) and the calibration vector; the preintegration carries its
first-order Jacobian in ``x``, so a small change ``dx`` from the linearisation
point is applied as ``dR Exp(J dx)``, ``S + J_S dx``; the caller re-preintegrates
when ``dx`` grows (:meth:`CalibrationModel.needs_repreintegration`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from graph_calib.constants import omega_ie_n as _omega_ie_n
from graph_calib.effects import uninformed
from graph_calib.params import Layout, grade as _grade
from graph_calib.rotations import (
    exp_so3,
    exp_so3_nb,
    log_so3,
    quat_to_dcm,
    right_jacobian,
    right_jacobian_inv,
    right_jacobian_nb,
    skew,
)
from graph_calib.sensor_model import correct, invert_sample, is_nonlinear, sample_features, term_rows

# ---------------------------------------------------------------------------
# options
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelOptions:
    """How an experiment is turned into a calibration problem.

    Attributes
    ----------
    keyframe_s : float
        Keyframe interval, s.
    grade : str
        IMU grade for default priors and noise (``params.GRADES``).
    extra_effects : tuple of str
        Further effects of ``model.md`` added to the declared model.
    exclude : tuple of str
        Declared parameters not estimated (e.g. ``lever_arm`` without a table).
    prior_sigma : dict
        Overrides of the grade's prior sigmas, ``{parameter name: sigma}`` (SI).
    gyro_noise, accel_noise, encoder_noise : float or None
        Overrides of the grade's noise (rad/sqrt(s), m/s/sqrt(s), rad).
    initial_attitude_sigma : float or None
        Prior sigma of the first keyframe attitude around the alignment, rad.
        None: what the alignment can know (:attr:`CalibrationModel.initial_attitude_sigma`).
    moving_sigma : float or None
        Without a table the bench may translate: gravity measurements of keyframes
        that are not static get this sigma (m/s^2).  None: every keyframe counts.
    n_newton : int
        Newton steps of the sensor-model inversion.
    """

    keyframe_s: float = 1.0
    grade: str = "navigation"
    extra_effects: tuple = ()
    exclude: tuple = ()
    prior_sigma: dict | None = None
    gyro_noise: float | None = None
    accel_noise: float | None = None
    encoder_noise: float | None = None
    initial_attitude_sigma: float | None = None
    moving_sigma: float | None = None
    n_newton: int = 2


# ---------------------------------------------------------------------------
# the per-sample kernel
# ---------------------------------------------------------------------------


_C12 = 1.0 / 12.0   # coning Jacobians
_C6 = 1.0 / 6.0     # velocity-rotation Jacobians; the values divide by 6 as the recursion is written


@numba.njit(cache=True, inline="always")
def _mm3(A, B, out):
    """out = A @ B for 3x3 arrays (out must not alias A or B)."""
    for i in range(3):
        for m in range(3):
            out[i, m] = A[i, 0] * B[0, m] + A[i, 1] * B[1, m] + A[i, 2] * B[2, m]


@numba.njit(cache=True, inline="always")
def _skew_mul(a, J, out):
    """out = [a x] @ J for J of shape (3, n)."""
    for c in range(J.shape[1]):
        out[0, c] = a[1] * J[2, c] - a[2] * J[1, c]
        out[1, c] = a[2] * J[0, c] - a[0] * J[2, c]
        out[2, c] = a[0] * J[1, c] - a[1] * J[0, c]


@numba.njit(cache=True, inline="always")
def _add_skew_mul(a, J, B, out):
    """out = B + [a x] @ J for 3x3 arrays (out may alias B, not J)."""
    for c in range(3):
        out[0, c] = B[0, c] + (a[1] * J[2, c] - a[2] * J[1, c])
        out[1, c] = B[1, c] + (a[2] * J[0, c] - a[0] * J[2, c])
        out[2, c] = B[2, c] + (a[0] * J[1, c] - a[1] * J[0, c])


@numba.njit(cache=True, parallel=True, error_model="numpy")
def _preintegrate(dt, k0, x, grows, arows, dTg, dTdtg, dTa, dTdta,
                  w_raw, f_raw, dw_raw, df_raw, tap_idx, tap_lo, n_newton,
                  dR, JR, S, JS, S1, JS1, w_first, Jw_first, w_last, Jw_last, tapR, tapJ):
    r"""Preintegrate every keyframe ``k`` (parallel over keyframes).

    The Jacobian outputs (``JR``, ``JS``, ``JS1``, ``Jw_*``, ``tapJ``) must be zero
    on entry; the kernel adds into the columns that ``grows`` / ``arows`` name.

    What is computed is the sample recursion (``th = w h``, ``v = f h`` the
    corrected increments, ``pth`` the previous sample's)::

        phi = th + pth x th / 12                         (coning)
        u   = v + th x v / 2 + th x (th x v) / 6 + h^2/12 (th x fdot - alpha x v)
                                                         (velocity rotated to the sample start)
        S  += R u,  S1 += tm R u,  tm = mid-sample time since the keyframe start
        R  <- R Exp(phi)

    with the right-perturbation Jacobian ``J`` of ``R`` carried as
    ``J <- Exp(phi)^T J + Jr(phi) dphi/dx`` and ``dS += R (du/dx - [u x] J)``.

    It is not evaluated that way.  ``G = R J`` (the Jacobian in the keyframe-start
    frame) obeys ``G_j = G_{j-1} + R_j Jr_j dphi_j/dx``, and every ``x``-derivative
    of a sample is ``-h Ai Phi`` (:func:`graph_calib.sensor_model.invert_sample`):
    per term row one feature value on one axis.  So each sample costs 3x3 products
    plus a few multiply-adds per term row:

    - ``dphi_j = B_j dth_j + C_j dth_{j-1}``, ``B = I + [pth x]/12``, ``C = -[th x]/12``:
      ``dth_k`` enters ``G`` with ``P_k + Q_{k+1}`` (``P_j = R_j Jr_j B_j``,
      ``Q_j = R_j Jr_j C_j``), so a sample's term rows are added one sample late,
      when ``Q_{k+1}`` is known (taps and the keyframe end add the pending one).
    - ``du = M_a dv + M_g dth`` with ``M_a = I + [th x]/2 + [th x]^2/6 - h^2/12 [alpha x]`` and
      ``M_g = -[v x]/2 - ([th x][v x] + [(th x v) x])/6 - h^2/12 [fdot x]``.
    - ``sum_j R_{j-1} [u_j x] J_{j-1} = sum_j [a_j x] G_{j-1}`` (``a_j = R_{j-1} u_j``)
      ``= [S_end x] G_end - sum_i [S_i x] g_i`` with ``S_i`` the running sum of ``a``
      and ``g_i`` the increment of ``G``; likewise with ``tm``-weights for ``S1``.

    The gyro rows accumulate ``(G, H_S, H_S1)``, the accelerometer rows
    ``(dS, dS1)``; at the end ``J = R^T G``, ``dS = H_S - [S x] G`` and
    ``dS1 = H_S1 - [S1 x] G`` (tests/test_model.py checks this against the direct
    recursion).
    """
    K = k0.shape[0] - 1
    ng = grows.shape[0]
    na = arows.shape[0]
    g_nonlin = is_nonlinear(grows)
    a_nonlin = is_nonlinear(arows)
    for k in numba.prange(K):
        w = np.empty(3)
        fc = np.empty(3)
        Aig = np.empty((3, 3))
        Aia = np.empty((3, 3))
        featg = np.empty(ng)
        pfeat = np.empty(ng)
        feata = np.empty(na)
        A = np.empty((3, 3))
        err = np.empty(3)
        # the sample's data, copied so that no array views (reference counting) enter the loop
        mw = np.empty(3)
        mf = np.empty(3)
        dTg_j = np.empty(3)
        dTdtg_j = np.empty(3)
        dTa_j = np.empty(3)
        dTdta_j = np.empty(3)
        dw_j = np.empty(3)
        df_j = np.empty(3)
        R = np.eye(3)
        Rn = np.empty((3, 3))
        E = np.empty((3, 3))
        Jr = np.empty((3, 3))
        RJr = np.empty((3, 3))
        P = np.empty((3, 3))
        Q = np.empty((3, 3))
        Mg = np.empty((3, 3))
        Ma = np.empty((3, 3))
        RMg = np.empty((3, 3))
        T1 = np.empty((3, 3))
        T2 = np.empty((3, 3))
        Tg = np.empty((3, 3))
        pTg = np.empty((3, 3))
        pG = np.zeros((3, 3))
        pHs = np.zeros((3, 3))
        pHs1 = np.zeros((3, 3))
        NG = np.empty((3, 9))      # per axis: the columns of the three gyro coefficient matrices
        NA = np.empty((3, 6))      # per axis: the accelerometer ones
        accG = np.zeros((ng, 9))   # per gyro row: G, H_S, H_S1 (3 each)
        accA = np.zeros((na, 6))   # per accel row: dS, dS1
        s = np.zeros(3)
        s1 = np.zeros(3)
        pth = np.zeros(3)
        th = np.empty(3)
        vv = np.empty(3)
        c1 = np.empty(3)
        gv = np.empty(3)
        j0 = k0[k]
        j1 = k0[k + 1]
        has_prev = False
        if j0 > 0:
            jp = j0 - 1
            for i in range(3):
                mw[i] = w_raw[jp, i]
                mf[i] = f_raw[jp, i]
                dTg_j[i] = dTg[jp, i]
                dTdtg_j[i] = dTdtg[jp, i]
                dw_j[i] = dw_raw[jp, i]
            invert_sample(grows, x, mw, dTg_j, dTdtg_j, mf, dw_j, dw_j, n_newton, g_nonlin, w, A, Aig, err)
            sample_features(grows, w, dTg_j, dTdtg_j, mf, dw_j, dw_j, pfeat)
            hp = dt[jp]
            for i in range(3):
                pth[i] = w[i] * hp
                for m in range(3):
                    pTg[i, m] = -hp * Aig[i, m]
            has_prev = True
        tau = 0.0
        tp = tap_lo[k]
        for j in range(j0, j1):
            h = dt[j]
            for i in range(3):
                mw[i] = w_raw[j, i]
                mf[i] = f_raw[j, i]
                dTg_j[i] = dTg[j, i]
                dTdtg_j[i] = dTdtg[j, i]
                dTa_j[i] = dTa[j, i]
                dTdta_j[i] = dTdta[j, i]
                dw_j[i] = dw_raw[j, i]
                df_j[i] = df_raw[j, i]
            invert_sample(grows, x, mw, dTg_j, dTdtg_j, mf, dw_j, dw_j, n_newton, g_nonlin, w, A, Aig, err)
            sample_features(grows, w, dTg_j, dTdtg_j, mf, dw_j, dw_j, featg)
            invert_sample(arows, x, mf, dTa_j, dTdta_j, mw, dw_j, df_j, n_newton, a_nonlin, fc, A, Aia, err)
            sample_features(arows, fc, dTa_j, dTdta_j, mw, dw_j, df_j, feata)
            for i in range(3):
                th[i] = w[i] * h
                vv[i] = fc[i] * h
                for m in range(3):
                    Tg[i, m] = -h * Aig[i, m]
            if j == j0:
                for i in range(3):
                    w_first[k, i] = w[i]
                for r in range(ng):
                    col = grows[r, 0]
                    ax = grows[r, 1]
                    for i in range(3):
                        Jw_first[k, i, col] -= Aig[i, ax] * featg[r]
            th0, th1, th2 = th[0], th[1], th[2]
            v0, v1, v2 = vv[0], vv[1], vv[2]
            # coning: phi = th + (pth x th) / 12
            phi0 = th0 + (pth[1] * th2 - pth[2] * th1) / 12.0
            phi1 = th1 + (pth[2] * th0 - pth[0] * th2) / 12.0
            phi2 = th2 + (pth[0] * th1 - pth[1] * th0) / 12.0
            # velocity increment rotated to the sample start, exact to third order in h for a
            # linearly varying rate and specific force (data derivatives alpha = dw/dt, fdot = df/dt):
            # u = v + c1 / 2 + th x c1 / 6 + h^2/12 (th x fdot - alpha x v), c1 = th x v
            c1[0] = th1 * v2 - th2 * v1
            c1[1] = th2 * v0 - th0 * v2
            c1[2] = th0 * v1 - th1 * v0
            ka = h * h / 12.0
            al0, al1, al2 = ka * dw_j[0], ka * dw_j[1], ka * dw_j[2]
            fd0, fd1, fd2 = ka * df_j[0], ka * df_j[1], ka * df_j[2]
            u0 = (v0 + 0.5 * c1[0] + (th1 * c1[2] - th2 * c1[1]) / 6.0 - (al1 * v2 - al2 * v1)
                  + (th1 * fd2 - th2 * fd1))
            u1 = (v1 + 0.5 * c1[1] + (th2 * c1[0] - th0 * c1[2]) / 6.0 - (al2 * v0 - al0 * v2)
                  + (th2 * fd0 - th0 * fd2))
            u2 = (v2 + 0.5 * c1[2] + (th0 * c1[1] - th1 * c1[0]) / 6.0 - (al0 * v1 - al1 * v0)
                  + (th0 * fd1 - th1 * fd0))
            # du = Ma dv + Mg dth
            tv = th0 * v0 + th1 * v1 + th2 * v2
            tt = th0 * th0 + th1 * th1 + th2 * th2
            for i in range(3):
                for m in range(3):
                    Mg[i, m] = -vv[i] * th[m] * _C6
                    Ma[i, m] = th[i] * th[m] * _C6
                Mg[i, i] += tv * _C6
                Ma[i, i] += 1.0 - tt * _C6
            # -[v x] / 2 - [c1 x] / 6 - h^2/12 [fdot x]
            Mg[0, 1] += 0.5 * v2 + c1[2] * _C6 + fd2
            Mg[0, 2] -= 0.5 * v1 + c1[1] * _C6 + fd1
            Mg[1, 0] -= 0.5 * v2 + c1[2] * _C6 + fd2
            Mg[1, 2] += 0.5 * v0 + c1[0] * _C6 + fd0
            Mg[2, 0] += 0.5 * v1 + c1[1] * _C6 + fd1
            Mg[2, 1] -= 0.5 * v0 + c1[0] * _C6 + fd0
            # [th x] / 2 - h^2/12 [alpha x]
            Ma[0, 1] -= 0.5 * th2 - al2
            Ma[0, 2] += 0.5 * th1 - al1
            Ma[1, 0] += 0.5 * th2 - al2
            Ma[1, 2] -= 0.5 * th0 - al0
            Ma[2, 0] -= 0.5 * th1 - al1
            Ma[2, 1] += 0.5 * th0 - al0
            # S += R u, S1 += tm R u (the level frame turns during the sample: mid-sample time)
            tm = tau + 0.5 * h
            for i in range(3):
                ru = R[i, 0] * u0 + R[i, 1] * u1 + R[i, 2] * u2
                s[i] += ru
                s1[i] += tm * ru
            # rotation: R_j = R_{j-1} Exp(phi)
            exp_so3_nb(phi0, phi1, phi2, E)
            right_jacobian_nb(phi0, phi1, phi2, Jr)
            _mm3(R, E, Rn)
            _mm3(Rn, Jr, RJr)
            # P = RJr (I + [pth x] / 12), Q = -RJr [th x] / 12
            for i in range(3):
                r0, r1, r2 = RJr[i, 0], RJr[i, 1], RJr[i, 2]
                P[i, 0] = r0 + (r1 * pth[2] - r2 * pth[1]) * _C12
                P[i, 1] = r1 + (r2 * pth[0] - r0 * pth[2]) * _C12
                P[i, 2] = r2 + (r0 * pth[1] - r1 * pth[0]) * _C12
                Q[i, 0] = -(r1 * th2 - r2 * th1) * _C12
                Q[i, 1] = -(r2 * th0 - r0 * th2) * _C12
                Q[i, 2] = -(r0 * th1 - r1 * th0) * _C12
            # the previous sample's gyro rows, now that Q_j is known
            if has_prev:
                for i in range(3):
                    for m in range(3):
                        pG[i, m] += Q[i, m]
                _add_skew_mul(s, Q, pHs, pHs)
                _add_skew_mul(s1, Q, pHs1, pHs1)
                _mm3(pG, pTg, T1)
                for i in range(3):
                    for a in range(3):
                        NG[a, i] = T1[i, a]
                _mm3(pHs, pTg, T1)
                for i in range(3):
                    for a in range(3):
                        NG[a, 3 + i] = T1[i, a]
                _mm3(pHs1, pTg, T1)
                for i in range(3):
                    for a in range(3):
                        NG[a, 6 + i] = T1[i, a]
                for r in range(ng):
                    f = pfeat[r]
                    ax = grows[r, 1]
                    for q in range(9):
                        accG[r, q] += f * NG[ax, q]
            # this sample's share: P_j, R_{j-1} Mg + [S_j x] P_j, tm R_{j-1} Mg + [S1_j x] P_j
            _mm3(R, Mg, RMg)
            _add_skew_mul(s, P, RMg, pHs)
            for i in range(3):
                for m in range(3):
                    pG[i, m] = P[i, m]
                    T1[i, m] = tm * RMg[i, m]
            _add_skew_mul(s1, P, T1, pHs1)
            for i in range(3):
                for m in range(3):
                    pTg[i, m] = Tg[i, m]
            for r in range(ng):
                pfeat[r] = featg[r]
            has_prev = True
            # accelerometer rows: R_{j-1} Ma (-h Aia)
            _mm3(R, Ma, T1)
            _mm3(T1, Aia, T2)
            for i in range(3):
                for a in range(3):
                    d = -h * T2[i, a]
                    NA[a, i] = d
                    NA[a, 3 + i] = tm * d
            for r in range(na):
                f = feata[r]
                ax = arows[r, 1]
                for q in range(6):
                    accA[r, q] += f * NA[ax, q]
            for i in range(3):
                for m in range(3):
                    R[i, m] = Rn[i, m]
                pth[i] = th[i]
            tau += h
            if tp < tap_idx.shape[0] and tap_idx[tp] == j:
                # J = R^T G, G = accG + P_j dth_j (pending)
                _mm3(pG, pTg, T1)
                while tp < tap_idx.shape[0] and tap_idx[tp] == j:
                    for i in range(3):
                        for m in range(3):
                            tapR[tp, i, m] = R[i, m]
                    for r in range(ng):
                        f = pfeat[r]
                        ax = grows[r, 1]
                        col = grows[r, 0]
                        for i in range(3):
                            gv[i] = accG[r, i] + f * T1[i, ax]
                        for i in range(3):
                            tapJ[tp, i, col] += R[0, i] * gv[0] + R[1, i] * gv[1] + R[2, i] * gv[2]
                    tp += 1
        # the last sample's pending gyro rows
        _mm3(pG, pTg, T1)
        _mm3(pHs, pTg, T2)
        _mm3(pHs1, pTg, Rn)
        for r in range(ng):
            f = pfeat[r]
            ax = grows[r, 1]
            col = grows[r, 0]
            for i in range(3):
                gv[i] = accG[r, i] + f * T1[i, ax]
            g0, g1, g2 = gv[0], gv[1], gv[2]
            for i in range(3):
                JR[k, i, col] += R[0, i] * g0 + R[1, i] * g1 + R[2, i] * g2
            JS[k, 0, col] += accG[r, 3] + f * T2[0, ax] - (s[1] * g2 - s[2] * g1)
            JS[k, 1, col] += accG[r, 4] + f * T2[1, ax] - (s[2] * g0 - s[0] * g2)
            JS[k, 2, col] += accG[r, 5] + f * T2[2, ax] - (s[0] * g1 - s[1] * g0)
            JS1[k, 0, col] += accG[r, 6] + f * Rn[0, ax] - (s1[1] * g2 - s1[2] * g1)
            JS1[k, 1, col] += accG[r, 7] + f * Rn[1, ax] - (s1[2] * g0 - s1[0] * g2)
            JS1[k, 2, col] += accG[r, 8] + f * Rn[2, ax] - (s1[0] * g1 - s1[1] * g0)
            for i in range(3):
                Jw_last[k, i, col] -= Aig[i, ax] * f
        for r in range(na):
            col = arows[r, 0]
            for i in range(3):
                JS[k, i, col] += accA[r, i]
                JS1[k, i, col] += accA[r, 3 + i]
        for i in range(3):
            S[k, i] = s[i]
            S1[k, i] = s1[i]
            w_last[k, i] = w[i]
            for m in range(3):
                dR[k, i, m] = R[i, m]


# ---------------------------------------------------------------------------
# preintegrated quantities
# ---------------------------------------------------------------------------


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
    tap_dR, tap_J : (M, 3, 3), (M, 3, P)  partial preintegration up to each encoder reading
    tap_w, tap_Jw : (M, 3), (M, 3, P)  calibrated mean rate of the sample interval holding each reading
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
    tap_dR: np.ndarray
    tap_J: np.ndarray
    tap_w: np.ndarray | None = None
    tap_Jw: np.ndarray | None = None


@dataclass(frozen=True)
class Residuals:
    """One kind of factor, stacked: residual, Jacobians and one-sigma noise.

    Attributes
    ----------
    r : (F, 3)
    key : (F,) int       keyframe whose attitude the factor touches (the first one)
    H_R : (F, 3, 3)      d r / d delta of that keyframe
    H_R_next : (F, 3, 3) or None   d r / d delta of keyframe key+1 (rotation factors)
    H_x : (F, 3, P)      d r / d x
    sigma : (F, 3) or (F, 3, 3)   one sigma per component, or a full covariance per factor
    """

    r: np.ndarray
    key: np.ndarray
    H_R: np.ndarray
    H_R_next: np.ndarray | None
    H_x: np.ndarray
    sigma: np.ndarray

    def whitened(self):
        """Residuals divided by their sigmas (diagonal) or by the Cholesky factor (full)."""
        if self.sigma.ndim == 2:
            return self.r / self.sigma
        L = np.linalg.cholesky(self.sigma)
        return np.linalg.solve(L, self.r[..., None])[..., 0]


def _limited_derivative(y, t):
    """Time derivative of sample means ``y`` (N, 3) at each sample, slope-limited (minmod).

    Where the signal varies linearly both one-sided differences agree; at a jump
    (a rate step) one of them is zero and so is the estimate, instead of the
    spurious spike a central difference puts on both neighbours of the jump.
    """
    d = np.diff(y, axis=0) / np.diff(t)[:, None]
    back = np.vstack([d[:1], d])
    fwd = np.vstack([d, d[-1:]])
    same = np.sign(back) == np.sign(fwd)
    return np.where(same, np.sign(back) * np.minimum(np.abs(back), np.abs(fwd)), 0.0)


def _moving_slope(y, dt, window_s):
    """Least-squares slope of ``y`` (N, K) over a centred window of about ``window_s``, per sample.

    Temperature channels are slow and often quantised, so a long window is wanted.
    The series is first averaged over blocks of about 1 s, the quadratic
    Savitzky-Golay slope is taken on the block means, and it is interpolated back
    to the samples: O(N) and accurate for any smooth temperature.
    """
    from scipy.signal import savgol_filter

    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    per = max(1, int(round(1.0 / dt)))
    nb = n // per
    if nb < 7:
        if n < 2:
            return np.zeros_like(y)
        t = np.arange(n) * dt
        return np.broadcast_to(np.polyfit(t, y, 1)[0], y.shape).copy()
    yb = y[: nb * per].reshape(nb, per, -1).mean(axis=1)
    tb = (np.arange(nb) * per + 0.5 * (per - 1)) * dt
    win = int(round(window_s / (per * dt))) | 1
    win = max(5, min(win, nb if nb % 2 else nb - 1))
    sb = savgol_filter(yb, win, 2, deriv=1, delta=per * dt, axis=0, mode="interp")
    t = np.arange(n) * dt
    return np.column_stack([np.interp(t, tb, sb[:, i]) for i in range(y.shape[1])])


#: Largest first-order keyframe rotation change (rad) for which a preintegration is updated to first
#: order (``dR Exp(J dx)``, ``S + J_S dx``) instead of redone; both solvers use it.
REPREINTEGRATE_TOL = 1e-5


def boundary_rate_correction(w_mean, k0):
    """Correction from the two-sample mean to the angular rate at each keyframe boundary.

    The lever-arm term needs the rate at a boundary instant, but the data are
    interval means.  The mean of the two adjacent samples is off by ``h^2/6``
    times the rate's second derivative (at a turn's cosine ramp 3e-5 rad/s, i.e.
    0.3 sigma of a navigation-grade gravity factor with a 0.15 m lever arm); the
    four-sample value ``(-m[-2] + 7 m[-1] + 7 m[0] - m[1]) / 12`` is exact for
    cubics and also where a ramp starts exactly at the boundary.  At the ends of
    the record the first (last) sample is extrapolated linearly.  The correction
    is a property of the data: its dependence on the calibration is of the order
    of a scale error times itself and is left out.

    Parameters
    ----------
    w_mean : ndarray, shape (N, 3)
        Interval-mean rates of equally spaced samples, rad/s.
    k0 : ndarray of int, shape (K+1,)
        First sample of each keyframe, and N.

    Returns
    -------
    ndarray, shape (K+1, 3)
        Add to ``[m[0] of keyframe 0, (m[-1] + m[0]) / 2 at inner boundaries, m[-1] of the last]``.
    """
    w = np.asarray(w_mean, dtype=float)
    b = np.asarray(k0)
    n = w.shape[0]
    fix = np.zeros((b.size, 3))
    inner = np.arange(1, b.size - 1)
    ok = inner[(b[inner] >= 2) & (b[inner] + 1 < n)]
    j = b[ok]
    fix[ok] = (-w[j - 2] + w[j - 1] + w[j] - w[j + 1]) / 12.0
    if n >= 2:
        fix[0] = 0.5 * (w[0] - w[1])
        fix[-1] = 0.5 * (w[n - 1] - w[n - 2])
    return fix


def gyrocompass_attitude_sigma(options, *, latitude_rad):
    """Prior sigma (rad) of a gyrocompassed first attitude: gyro-bias prior over the horizontal Earth rate.

    Between :attr:`CalibrationModel.TABLE_ALIGNMENT_SIGMA` and pi (about 0.1 rad
    for a navigation-grade unit, pi for consumer MEMS).  ``options`` is a
    :class:`ModelOptions` (its grade and any ``gyro.bias`` prior override).
    """
    g = _grade(options.grade)
    horizontal = float(np.hypot(*_omega_ie_n(latitude_rad)[:2]))
    bias = float(np.max((options.prior_sigma or {}).get("gyro.bias", g.prior_sigma["gyro.bias"])))
    return float(min(np.pi, max(CalibrationModel.TABLE_ALIGNMENT_SIGMA, bias / max(horizontal, 1e-12))))


class CalibrationModel:
    """The calibration problem of one experiment: data, layout, priors, noise, factors.

    Parameters
    ----------
    experiment : graph_calib.experiment.Experiment
    options : ModelOptions
    t_ref_degC : float, optional
        Reference temperature; default the mean of the six sensors' temperatures.
    q_nb0 : ndarray, shape (4,), optional
        Attitude at the start of the record (alignment); needed by :meth:`initial_attitudes`.

    Notes
    -----
    Both solvers see the problem only through :meth:`preintegrate`,
    :meth:`rotation_factors`, :meth:`gravity_factors`, :meth:`encoder_factors`,
    :meth:`prior` and :meth:`initial_attitudes`.
    """

    def __init__(self, experiment, *, options=ModelOptions(), t_ref_degC=None, static_mask=None):
        self.experiment = experiment
        self.options = options
        self.grade = _grade(options.grade)
        self.omega_ie_n = _omega_ie_n(experiment.latitude_rad)
        self.t_ref_degC = float(experiment.default_t_ref() if t_ref_degC is None else t_ref_degC)
        self.gravity = float(experiment.gravity_mps2)
        self.gyro_noise = float(options.gyro_noise if options.gyro_noise is not None else self.grade.gyro_noise)
        self.accel_noise = float(options.accel_noise if options.accel_noise is not None else self.grade.accel_noise)
        self.encoder_noise = float(options.encoder_noise if options.encoder_noise is not None
                                   else self.grade.encoder_noise)
        # the data first (nothing here depends on which parameters are estimated) ...
        self._prepare_samples()
        self._prepare_keyframes()
        self._prepare_table()
        # ... which decides what the record can inform
        self.auto_excluded = self._unobservable()
        exclude = tuple(sorted(set(options.exclude) | set(self.auto_excluded)))
        self.layout = Layout.declared(extra=tuple(options.extra_effects), exclude=exclude)
        self.initial_attitude_sigma = self._initial_attitude_sigma(experiment)
        self._prepare_terms()
        self._static_keyframes(static_mask)

    #: A valid table reading counts as taken while the table turns above this rate
    #: against the level frame, rad/s (about 0.06 deg/s, 14 times the Earth rate).
    LAG_RATE_THRESHOLD = 1e-3

    def _unobservable(self):
        """Parameters the record cannot inform, left out of the layout (sorted tuple).

        What each parameter needs is in the effect registry (:func:`graph_calib.effects.uninformed`).
        Without a table nothing ties the attitude to the faceplate or to a fixed
        rotation centre: ``mount``, ``time_lag.table``, ``damping.stiffness`` and
        ``lever_arm`` go.  With a table whose valid readings are all taken at rest
        (the usual bench: encoders trusted only in static positions) a time lag
        changes no measurement, so ``time_lag.table`` goes too; estimating it
        would only return its prior mean as if it were a result.
        """
        tab = self.experiment.table
        has_valid = tab is not None and bool(np.any(tab.valid))
        in_motion = False
        if has_valid:
            w_nb_b = self.w_raw[self.tap_nxt] + self.tap_w_nb_offset      # raw rate against the level frame
            in_motion = bool(np.any(np.linalg.norm(w_nb_b, axis=1) > self.LAG_RATE_THRESHOLD))
        return uninformed(has_table=tab is not None, has_valid_readings=has_valid, readings_in_motion=in_motion)

    #: Prior sigma of the first attitude when valid table readings give it (faceplate
    #: attitude through the nominal mounting; the mounting error is estimated), rad.
    TABLE_ALIGNMENT_SIGMA = 0.05

    def _initial_attitude_sigma(self, experiment):
        """Prior sigma of the first keyframe attitude (isotropic), rad.

        With valid table readings the alignment takes the table's attitude:
        :attr:`TABLE_ALIGNMENT_SIGMA`.  Otherwise the heading comes from
        gyrocompassing, good to about the gyro bias over the horizontal Earth
        rate (0.1 rad for a navigation-grade unit, nothing at all for consumer
        MEMS, whose bias is a hundred times the Earth rate): the sigma is that,
        capped at pi.  The whole record then fixes the heading through the Earth
        rate; a tight prior around a wrong gyrocompass heading would instead turn
        the Earth-rate compensation into a false gyro bias (4 sigma on the
        consumer hand-held scenario).
        """
        if self.options.initial_attitude_sigma is not None:
            return float(self.options.initial_attitude_sigma)
        tab = experiment.table
        if tab is not None and np.any(tab.valid):
            return self.TABLE_ALIGNMENT_SIGMA
        return gyrocompass_attitude_sigma(self.options, latitude_rad=experiment.latitude_rad)

    # -- data preparation ---------------------------------------------------

    def _prepare_samples(self):
        e = self.experiment
        dt = e.dt
        self.dt = dt
        self.w_raw = e.dtheta / dt[:, None]
        self.f_raw = e.dv / dt[:, None]
        h = 1.0 / e.rate_hz
        self.dw_raw = _limited_derivative(self.w_raw, e.t)
        self.df_raw = _limited_derivative(self.f_raw, e.t)
        T = e.sensor_temperatures()
        self.temperatures = T
        dT = T - self.t_ref_degC
        dTdt = _moving_slope(T, h, 60.0)
        self.dTg = np.ascontiguousarray(dT[:, :3])
        self.dTa = np.ascontiguousarray(dT[:, 3:])
        self.dTdtg = np.ascontiguousarray(dTdt[:, :3])
        self.dTdta = np.ascontiguousarray(dTdt[:, 3:])

    def _prepare_terms(self):
        """The sensor-model term rows of the layout, and the columns the kernel fills."""
        self.grows_full = term_rows(self.layout, "gyro")
        self.arows_full = term_rows(self.layout, "accel")
        cols = np.unique(np.concatenate([self.grows_full[:, 0], self.arows_full[:, 0]]))
        self.kernel_cols = cols.astype(np.int64)
        g = self.grows_full[:, 0]
        # the columns gyro terms can touch, as one slice (views, not gathers; columns in between are zero)
        self.gyro_cols = slice(int(g.min()), int(g.max()) + 1) if g.size else slice(0, 0)
        remap = -np.ones(self.layout.size, dtype=np.int64)
        remap[cols] = np.arange(cols.size)
        self.grows = self.grows_full.copy()
        self.grows[:, 0] = remap[self.grows[:, 0]]
        self.arows = self.arows_full.copy()
        self.arows[:, 0] = remap[self.arows[:, 0]]

    def _prepare_keyframes(self):
        e = self.experiment
        n = e.n_samples
        per = max(1, int(round(self.options.keyframe_s * e.rate_hz)))
        k0 = np.arange(0, n, per, dtype=np.int64)
        if n - k0[-1] < max(1, per // 2) and k0.size > 1:
            k0 = k0[:-1]
        self.k0 = np.append(k0, n).astype(np.int64)
        self.n_keyframes = self.k0.size - 1
        t_start = e.t - self.dt
        self.t_key = np.append(t_start[self.k0[:-1]], e.t[-1])  # time of each boundary, (K+1,)
        self.T_key = np.diff(self.t_key)
        self.w_b_fix = boundary_rate_correction(self.w_raw, self.k0)


    def _prepare_table(self):
        e = self.experiment
        tab = e.table
        self.has_table = tab is not None
        empty3 = np.zeros((0, 3))
        if tab is None or not np.any(tab.valid):
            self.tap_idx = np.zeros(0, dtype=np.int64)
            self.tap_t = np.zeros(0)
            self.tap_key = np.zeros(0, dtype=np.int64)
            self.tap_dt = np.zeros(0)
            self.tap_tau = np.zeros(0)
            self.tap_C_nf = np.zeros((0, 3, 3))
            self.tap_nxt = np.zeros(0, dtype=np.int64)
            self.tap_f = empty3
            self.tap_alpha = empty3
            self.tap_phi_shape = empty3
            self.C_fb = np.eye(3) if tab is None else quat_to_dcm(tab.q_fb_nominal)
        else:
            tm = tab.t[tab.valid]
            q = tab.q_nf[tab.valid]
            j = np.searchsorted(e.t, tm, side="right") - 1
            keep = (j >= 0) & (tm <= e.t[-1])
            tm, q, j = tm[keep], q[keep], j[keep]
            self.tap_idx = j.astype(np.int64)
            self.tap_t = tm
            self.tap_key = (np.searchsorted(self.k0, j, side="right") - 1).astype(np.int64)
            self.tap_dt = tm - e.t[j]
            self.tap_tau = tm - self.t_key[self.tap_key]
            self.tap_C_nf = quat_to_dcm(q)
            nxt = np.minimum(j + 1, e.n_samples - 1)      # the sample interval holding t_m
            self.tap_nxt = nxt.astype(np.int64)
            # Inside that interval the rate is taken linear, mean w (the increment over h) and slope
            # alpha (slope-limited, from the neighbouring means): at the reading it is
            # w + alpha (dt_m - h/2), and the turn from the sample end to the reading is
            # w dt_m + alpha dt_m (dt_m - h) / 2.  The mean alone is off by alpha h^2/8 (1.5 arcsec,
            # 0.75 sigma of a navigation-grade encoder, in a table ramp) when readings are valid in motion.
            h = self.dt[nxt]
            self.tap_alpha = self.dw_raw[nxt]
            self.tap_phi_shape = self.tap_alpha * (0.5 * self.tap_dt * (self.tap_dt - h))[:, None]
            self.tap_f = self.f_raw[nxt]
            self.C_fb = quat_to_dcm(tab.q_fb_nominal)
            # the rate against the level frame at the reading (for the lag) is the calibrated interval
            # mean plus this: the slope term, minus the Earth rate in b (from the readings' attitude)
            C_bn = np.swapaxes(self.tap_C_nf @ self.C_fb, 1, 2)
            self.tap_w_nb_offset = self.tap_alpha * (self.tap_dt - 0.5 * h)[:, None] - C_bn @ self.omega_ie_n
        if tab is None or not np.any(tab.valid):
            self.tap_w_nb_offset = empty3
        self.tap_lo = np.searchsorted(self.tap_idx, self.k0[:-1], side="left").astype(np.int64)
        # data-only pieces of the encoder factor, formed once: the Earth turn since the keyframe start,
        # the nominal faceplate-to-level attitude
        self.tap_E = self.earth_turn(self.tap_tau)
        self.tap_C_nb_nominal = self.tap_C_nf @ self.C_fb

    def _static_keyframes(self, static_mask):
        if static_mask is None:
            self.static_key = np.ones(self.n_keyframes, dtype=bool)
        else:
            m = np.asarray(static_mask, dtype=bool)
            self.static_key = np.logical_and.reduceat(m, self.k0[:-1])

    # -- priors -------------------------------------------------------------

    def prior(self):
        """Prior mean and one sigma of the calibration vector, shapes (P,), (P,)."""
        sig = self.grade.prior_vector(self.layout)
        for name, value in (self.options.prior_sigma or {}).items():
            if name in self.layout:
                sig[self.layout.slice(name)] = value
        return self.layout.zeros(), sig

    def priors_used(self):
        """``{parameter name: sigma}`` actually used (for the result file)."""
        _, sig = self.prior()
        return {n: sig[self.layout.slice(n)].tolist() for n in self.layout.names}

    # -- preintegration -------------------------------------------------------

    def preintegrate(self, x):
        """Preintegrate every keyframe and encoder tap at calibration ``x`` (P,)."""
        x = np.ascontiguousarray(x, dtype=float)
        K = self.n_keyframes
        M = self.tap_idx.size
        P = self.layout.size
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
        tapR = np.empty((M, 3, 3))
        tapJ = np.zeros((M, 3, P))
        # term rows with layout columns: the kernel adds straight into the (..., 3, P) arrays
        _preintegrate(self.dt, self.k0, x, self.grows_full, self.arows_full,
                      self.dTg, self.dTdtg, self.dTa, self.dTdta, self.w_raw, self.f_raw,
                      self.dw_raw, self.df_raw, self.tap_idx, self.tap_lo, self.options.n_newton,
                      dR, JR, S, JS, S1, JS1, wf, Jwf, wl, Jwl, tapR, tapJ)
        w_b = np.empty((K + 1, 3))
        Jw_b = np.empty((K + 1, 3, P))
        w_b[0], Jw_b[0] = wf[0], Jwf[0]
        w_b[K], Jw_b[K] = wl[K - 1], Jwl[K - 1]
        w_b[1:K] = 0.5 * (wl[:-1] + wf[1:])
        Jw_b[1:K] = 0.5 * (Jwl[:-1] + Jwf[1:])
        w_b += self.w_b_fix
        n = self.tap_nxt
        tap_w, tap_Jw = correct(self.layout, x, "gyro", self.w_raw[n], dT=self.dTg[n], dTdt=self.dTdtg[n],
                                other=self.f_raw[n], domega=self.dw_raw[n], dsignal=self.dw_raw[n],
                                n_iter=self.options.n_newton, jacobian=True)
        return Preintegrated(x_lin=x.copy(), dR=dR, J_dR=JR, S=S, J_S=JS, S1=S1,
                             J_S1=JS1, w_b=w_b, J_w_b=Jw_b, tap_dR=tapR, tap_J=tapJ, tap_w=tap_w,
                             tap_Jw=np.ascontiguousarray(tap_Jw[:, :, self.gyro_cols]))

    def needs_repreintegration(self, pre, x, *, tol=REPREINTEGRATE_TOL):
        """Whether ``x`` moved so far from ``pre.x_lin`` that first-order updates lose accuracy.

        The test is the largest first-order change of a keyframe rotation, rad.
        """
        dx = np.asarray(x) - pre.x_lin
        return float(np.max(np.abs(pre.J_dR @ dx))) > tol

    def _updated(self, pre, x):
        dx = np.asarray(x) - pre.x_lin
        dR = pre.dR @ exp_so3(pre.J_dR @ dx)
        S = pre.S + pre.J_S @ dx
        S1 = pre.S1 + pre.J_S1 @ dx
        w_b = pre.w_b + pre.J_w_b @ dx
        return dR, S, S1, w_b

    def earth_turn(self, T):
        """``E(T) = Exp(-omega_ie_n T)``, shape (..., 3, 3)."""
        T = np.asarray(T, dtype=float)
        return exp_so3(-T[..., None] * self.omega_ie_n)

    # -- attitudes ------------------------------------------------------------

    def propagate(self, R0, pre, x):
        """Dead-reckoned attitude at every keyframe boundary from ``R0``, shape (K+1, 3, 3)."""
        dR, *_ = self._updated(pre, x)
        E = self.earth_turn(self.T_key)
        R = np.empty((self.n_keyframes + 1, 3, 3))
        R[0] = R0
        for k in range(self.n_keyframes):  # keyframe rate, not sample rate
            R[k + 1] = E[k] @ R[k] @ dR[k]
        return R

    # -- factors --------------------------------------------------------------

    def rotation_factors(self, R, pre, x):
        """Residuals between consecutive keyframe attitudes ``R`` (K+1, 3, 3)."""
        dR, *_ = self._updated(pre, x)
        E = self.earth_turn(self.T_key)
        A = E @ R[:-1] @ dR
        r = log_so3(np.swapaxes(A, 1, 2) @ R[1:])
        Jr_inv = right_jacobian_inv(r)
        Jl_inv = right_jacobian_inv(-r)
        H_next = Jr_inv
        H_prev = -Jl_inv @ np.swapaxes(dR, 1, 2)
        H_x = -Jl_inv @ pre.J_dR
        sigma = self.gyro_noise * np.sqrt(self.T_key)[:, None] * np.ones(3)
        return Residuals(r=r, key=np.arange(self.n_keyframes), H_R=H_prev, H_R_next=H_next,
                         H_x=H_x, sigma=sigma)

    def _lever_arm(self, x):
        return self.layout.get(x, "lever_arm", np.zeros(3))

    def gravity_factors(self, R, pre, x):
        """Gravity (reaction-force) mismatch of every keyframe, m/s^2; ``R`` (K+1 or K, 3, 3)."""
        K = self.n_keyframes
        Rk = R[:K]
        dR, S, S1, w_b = self._updated(pre, x)
        W = skew(self.omega_ie_n)
        T = self.T_key
        l = self._lever_arm(x)
        E = self.earth_turn(T)
        C1 = E @ Rk @ dR                                         # attitude at the keyframe end
        dv_n = np.einsum("kij,kj->ki", Rk, S) - np.einsum("ij,kjl,kl->ki", W, Rk, S1)
        a0 = np.cross(w_b[:-1], l)                               # omega x l at the start
        a1 = np.cross(w_b[1:], l)
        # v = C (omega_ib x l) + omega_ie x (C l): the point's velocity in the Earth-fixed level frame,
        # C (omega_nb x l), plus 2 omega_ie x (C l) whose change is the Coriolis integral
        v0 = np.einsum("kij,kj->ki", Rk, a0) + np.cross(self.omega_ie_n, np.einsum("kij,j->ki", Rk, l))
        v1 = np.einsum("kij,kj->ki", C1, a1) + np.cross(self.omega_ie_n, np.einsum("kij,j->ki", C1, l))
        g_up = np.array([0.0, 0.0, self.gravity])
        r = (dv_n - (v1 - v0)) / T[:, None] - g_up
        # Jacobian in the right perturbation of R_k
        H_R = -Rk @ skew(S) + W @ Rk @ skew(S1)
        H_R += -Rk @ skew(a0) - W @ Rk @ skew(l)                 # -(-dv0)
        dRT = np.swapaxes(dR, 1, 2)
        H_R -= (-C1 @ skew(a1) - W @ C1 @ skew(l)) @ dRT
        # Jacobian in x
        H_x = Rk @ pre.J_S - W @ Rk @ pre.J_S1
        # v0 = Rk (w0 x l) + ...: d/dw0 = -Rk [l x]; d/dl = Rk [w0 x] + W Rk
        H_x -= Rk @ skew(l) @ pre.J_w_b[:-1]
        H_x -= -C1 @ skew(l) @ pre.J_w_b[1:]
        # C1 depends on x through dR: d(C1 a) = -C1 [a x] J
        H_x -= (-C1 @ skew(a1) - W @ C1 @ skew(l)) @ pre.J_dR
        if "lever_arm" in self.layout:
            s = self.layout.slice("lever_arm")
            H_x[:, :, s] += Rk @ skew(w_b[:-1]) + W @ Rk
            H_x[:, :, s] -= C1 @ skew(w_b[1:]) + W @ C1
        r_scale = 1.0 / T[:, None, None]
        H_R = H_R * r_scale
        H_x = H_x * r_scale
        var = np.empty((K, 3))
        var[:] = (self.accel_noise**2 / T)[:, None]
        var[:, :2] += (self.gravity * self.gyro_noise) ** 2 * T[:, None] / 3.0
        sigma = np.sqrt(var)
        if self.options.moving_sigma is not None:
            sigma[~self.static_key] = np.maximum(sigma[~self.static_key], self.options.moving_sigma)
        return Residuals(r=r, key=np.arange(K), H_R=H_R, H_R_next=None, H_x=H_x, sigma=sigma)

    def encoder_factors(self, R, pre, x):
        """Gyro attitude against every valid table reading, rad; ``R`` (K+1 or K, 3, 3)."""
        M = self.tap_idx.size
        P = self.layout.size
        if M == 0:
            z = np.zeros((0, 3))
            return Residuals(r=z, key=np.zeros(0, dtype=np.int64), H_R=np.zeros((0, 3, 3)), H_R_next=None,
                             H_x=np.zeros((0, 3, P)), sigma=z)
        dx = np.asarray(x) - pre.x_lin
        tapR = pre.tap_dR @ exp_so3(pre.tap_J @ dx) if np.any(dx) else pre.tap_dR
        # the turn from the sample end to the reading, with the calibrated rate of that sample interval
        # (preintegrated with its Jacobian in the gyro columns, updated to first order like the rest)
        gc = self.gyro_cols
        J_w = pre.tap_Jw
        w_c = pre.tap_w + J_w @ dx[gc] if np.any(dx) else pre.tap_w
        phi = w_c * self.tap_dt[:, None] + self.tap_phi_shape
        Ew = exp_so3(phi)
        Bp = tapR @ Ew
        Rk = R[self.tap_key]
        C_pred = self.tap_E @ Rk @ Bp
        mount = self.layout.get(x, "mount", np.zeros(3))
        lag = self.layout.get(x, "time_lag.table", np.zeros(1))[0]
        Kd = self.layout.get(x, "damping.stiffness", np.zeros(9)).reshape(3, 3)
        w_nb = w_c + self.tap_w_nb_offset                                  # calibrated, at the reading
        a_lag = w_nb * lag - (0.5 * lag * lag) * self.tap_alpha               # the turn over the lag before t_m
        a_damp = self.tap_f @ Kd.T
        Ed = exp_so3(a_damp) if np.any(Kd) else np.broadcast_to(np.eye(3), (M, 3, 3))
        B = exp_so3(a_lag) @ Ed if lag != 0.0 else Ed
        C_meas = self.tap_C_nb_nominal @ (exp_so3(mount) @ B)
        r = log_so3(np.swapaxes(C_meas, 1, 2) @ C_pred)
        Jr_inv = right_jacobian_inv(r)
        Jl_inv = right_jacobian_inv(-r)
        H_R = Jr_inv @ np.swapaxes(Bp, 1, 2)
        # the preintegration and the corrected rate depend on the gyro columns only
        H_x = np.zeros((M, 3, P))
        H_x[:, :, gc] = Jr_inv @ (np.swapaxes(Ew, 1, 2) @ pre.tap_J[:, :, gc]
                                  + (right_jacobian(phi) * self.tap_dt[:, None, None]) @ J_w)
        if "mount" in self.layout:
            H_x[:, :, self.layout.slice("mount")] = -Jl_inv @ np.swapaxes(B, 1, 2) @ right_jacobian(mount)
        if "time_lag.table" in self.layout:
            G_lag = -Jl_inv @ np.swapaxes(Ed, 1, 2) @ right_jacobian(a_lag)  # d r / d a_lag
            da = w_nb - lag * self.tap_alpha
            H_x[:, :, self.layout.slice("time_lag.table")] = G_lag @ da[..., None]
            if lag != 0.0:
                H_x[:, :, gc] += G_lag @ (lag * J_w)                       # the calibrated rate in the lag
        if "damping.stiffness" in self.layout:
            G = -Jl_inv @ right_jacobian(a_damp)                   # (M, 3, 3) per d(a_damp)
            # a_damp_i = sum_j K_ij f_j  ->  d a_damp / d K_ij = e_i f_j
            dK = np.einsum("mab,mj->mabj", G, self.tap_f).reshape(M, 3, 9)
            H_x[:, :, self.layout.slice("damping.stiffness")] = dK
        var = self.encoder_noise**2 + self.gyro_noise**2 * self.tap_tau
        sigma = np.sqrt(var)[:, None] * np.ones(3)
        return Residuals(r=r, key=self.tap_key.copy(), H_R=H_R, H_R_next=None, H_x=H_x, sigma=sigma)

    def initial_attitudes(self, q_nb0, x=None, pre=None):
        """Attitude at every keyframe boundary dead-reckoned from the alignment ``q_nb0``."""
        if pre is None:
            x = self.prior()[0] if x is None else x
            pre = self.preintegrate(x)
        return self.propagate(quat_to_dcm(q_nb0), pre, pre.x_lin if x is None else x)
