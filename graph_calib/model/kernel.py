r"""The compiled per-sample preintegration kernel (numba), one keyframe after the other.

:func:`graph_calib.model.preintegration.preintegrate` calls it; nothing else should.  The
sensor-model inversion it applies per sample is :mod:`graph_calib.sensors.sensor_model`'s: the kernel calls
its compiled ``invert_sample`` and ``sample_features`` (compiled once, without reference counting),
and inlines only the small 3x3 helpers.  It is not ``parallel=True`` and does not inline the sensor
model: numba's parfor passes and inlining took three to four minutes of compiling on two cores, and
on the machine this was measured on (two cores, other jobs running) the second thread gained nothing
(docs/performance.md, "Compiling the kernels").
"""

from __future__ import annotations

import numba
import numpy as np

from graph_calib.navigation.rotations import exp_so3_nb, mat3_mul_nb as _mm3, right_jacobian_nb
from graph_calib.sensors.sensor_model import gsens_coupling, invert_sample, is_nonlinear, sample_features
from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

_C12 = 1.0 / 12.0   # coning Jacobians
_C6 = 1.0 / 6.0     # velocity-rotation Jacobians; the values divide by 6 as the recursion is written


@numba.njit(cache=True, inline="always")
def _add_skew_mul(a, J, B, out):
    """out = B + [a x] @ J for 3x3 arrays (out may alias B, not J)."""
    for c in range(3):
        out[0, c] = B[0, c] + (a[1] * J[2, c] - a[2] * J[1, c])
        out[1, c] = B[1, c] + (a[2] * J[0, c] - a[0] * J[2, c])
        out[2, c] = B[2, c] + (a[0] * J[1, c] - a[1] * J[0, c])


@numba.njit(cache=True, inline="always")
def _pending_rows(rows, feat, pG, pHs, pHs1, pT, T, N, acc):
    """acc[r] += feat[r] * (pG pT, pHs pT, pHs1 pT)[:, axis_r]: one pending sample's rows (T scratch)."""
    _mm3(pG, pT, T)
    for i in range(3):
        for a in range(3):
            N[a, i] = T[i, a]
    _mm3(pHs, pT, T)
    for i in range(3):
        for a in range(3):
            N[a, 3 + i] = T[i, a]
    _mm3(pHs1, pT, T)
    for i in range(3):
        for a in range(3):
            N[a, 6 + i] = T[i, a]
    for r in range(rows.shape[0]):
        f = feat[r]
        ax = rows[r, 1]
        for q in range(9):
            acc[r, q] += f * N[ax, q]


@numba.njit(cache=True, inline="always")
def _rate_rows(rows, feat, M, sign, J, k):
    """J[k, :, col_r] += sign * M[:, axis_r] * feat[r]: the calibrated rate's Jacobian of one sample's rows."""
    for r in range(rows.shape[0]):
        col = rows[r, 0]
        ax = rows[r, 1]
        for i in range(3):
            J[k, i, col] += sign * M[i, ax] * feat[r]


@numba.njit(cache=True, inline="always")
def _tap_rows(rows, feat, acc, T, R, tapJ, tp, gv):
    """tapJ[tp, :, col_r] += R^T (acc[r, :3] + feat[r] T[:, axis_r]): the rows at a reading (gv scratch)."""
    for r in range(rows.shape[0]):
        f = feat[r]
        ax = rows[r, 1]
        col = rows[r, 0]
        for i in range(3):
            gv[i] = acc[r, i] + f * T[i, ax]
        for i in range(3):
            tapJ[tp, i, col] += R[0, i] * gv[0] + R[1, i] * gv[1] + R[2, i] * gv[2]


@numba.njit(cache=True, inline="always")
def _keyframe_rows(rows, feat, acc, pG, pHs, pHs1, pT, R, s, s1, T1, T2, T3, gv, JR, JS, JS1, k):
    """The last sample's pending rows closed into keyframe ``k``'s JR, JS, JS1 (T1, T2, T3, gv scratch)."""
    _mm3(pG, pT, T1)
    _mm3(pHs, pT, T2)
    _mm3(pHs1, pT, T3)
    for r in range(rows.shape[0]):
        f = feat[r]
        ax = rows[r, 1]
        col = rows[r, 0]
        for i in range(3):
            gv[i] = acc[r, i] + f * T1[i, ax]
        g0, g1, g2 = gv[0], gv[1], gv[2]
        for i in range(3):
            JR[k, i, col] += R[0, i] * g0 + R[1, i] * g1 + R[2, i] * g2
        JS[k, 0, col] += acc[r, 3] + f * T2[0, ax] - (s[1] * g2 - s[2] * g1)
        JS[k, 1, col] += acc[r, 4] + f * T2[1, ax] - (s[2] * g0 - s[0] * g2)
        JS[k, 2, col] += acc[r, 5] + f * T2[2, ax] - (s[0] * g1 - s[1] * g0)
        JS1[k, 0, col] += acc[r, 6] + f * T3[0, ax] - (s1[1] * g2 - s1[2] * g1)
        JS1[k, 1, col] += acc[r, 7] + f * T3[1, ax] - (s1[2] * g0 - s1[0] * g2)
        JS1[k, 2, col] += acc[r, 8] + f * T3[2, ax] - (s1[0] * g1 - s1[1] * g0)


@numba.njit(cache=True, error_model="numpy")
def _preintegrate(dt, k0, x, grows, arows, dTg, dTdtg, dTa, dTdta,
                  w_raw, f_raw, dw_raw, df_raw, tap_idx, tap_lo, n_newton,
                  dR, JR, S, JS, S1, JS1, w_first, Jw_first, w_last, Jw_last, tapR, tapJ):
    r"""Preintegrate every keyframe ``k``.

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
    of a sample is ``-h Ai Phi`` (:func:`graph_calib.sensors.sensor_model.invert_sample`):
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
    ``dS1 = H_S1 - [S1 x] G`` (tests/model/test_model.py checks this against the direct
    recursion).

    With ``gyro.g_sensitivity`` the gyros see the calibrated specific force
    (:func:`graph_calib.sensors.sensor_model.correct_pair`): each sample is inverted
    accelerometers first, and ``dth`` gains ``h Ai_g Gm Ai_a`` per accelerometer
    term row (``Gm`` from :func:`graph_calib.sensors.sensor_model.gsens_coupling`), so the
    accelerometer rows also accumulate ``(G, H_S, H_S1)`` exactly like the gyro
    rows (``accGA``, pending one sample like them).  Without the coupling that
    path is skipped and the results are those of the uncoupled model bit for bit.
    """
    K = k0.shape[0] - 1
    ng = grows.shape[0]
    na = arows.shape[0]
    g_nonlin = is_nonlinear(grows)
    a_nonlin = is_nonlinear(arows)
    Gm = np.empty((3, 3))
    coupled = gsens_coupling(grows, x, Gm)
    for k in range(K):
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
        accGA = np.zeros((na, 9))  # per accel row: its G, H_S, H_S1 through g_sensitivity (coupled only)
        pfeata = np.zeros(na)
        Bga = np.zeros((3, 3))     # Ai_g Gm Ai_a of the current sample
        Tga = np.zeros((3, 3))     # h Bga
        pTga = np.zeros((3, 3))
        NGA = np.empty((3, 9))
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
                dTa_j[i] = dTa[jp, i]
                dTdta_j[i] = dTdta[jp, i]
                dw_j[i] = dw_raw[jp, i]
                df_j[i] = df_raw[jp, i]
            fo = mf
            if coupled:
                invert_sample(arows, x, mf, dTa_j, dTdta_j, mw, dw_j, df_j, n_newton, a_nonlin, fc, A, Aia, err)
                sample_features(arows, fc, dTa_j, dTdta_j, mw, dw_j, df_j, pfeata)
                fo = fc
            invert_sample(grows, x, mw, dTg_j, dTdtg_j, fo, dw_j, dw_j, n_newton, g_nonlin, w, A, Aig, err)
            sample_features(grows, w, dTg_j, dTdtg_j, fo, dw_j, dw_j, pfeat)
            hp = dt[jp]
            for i in range(3):
                pth[i] = w[i] * hp
                for m in range(3):
                    pTg[i, m] = -hp * Aig[i, m]
            if coupled:
                _mm3(Aig, Gm, T1)
                _mm3(T1, Aia, Bga)
                for i in range(3):
                    for m in range(3):
                        pTga[i, m] = hp * Bga[i, m]
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
            # accelerometers first: the gyros' g-sensitivity sees the calibrated specific force
            invert_sample(arows, x, mf, dTa_j, dTdta_j, mw, dw_j, df_j, n_newton, a_nonlin, fc, A, Aia, err)
            sample_features(arows, fc, dTa_j, dTdta_j, mw, dw_j, df_j, feata)
            invert_sample(grows, x, mw, dTg_j, dTdtg_j, fc, dw_j, dw_j, n_newton, g_nonlin, w, A, Aig, err)
            sample_features(grows, w, dTg_j, dTdtg_j, fc, dw_j, dw_j, featg)
            for i in range(3):
                th[i] = w[i] * h
                vv[i] = fc[i] * h
                for m in range(3):
                    Tg[i, m] = -h * Aig[i, m]
            if coupled:
                _mm3(Aig, Gm, T1)
                _mm3(T1, Aia, Bga)
                for i in range(3):
                    for m in range(3):
                        Tga[i, m] = h * Bga[i, m]
            if j == j0:
                for i in range(3):
                    w_first[k, i] = w[i]
                _rate_rows(grows, featg, Aig, -1.0, Jw_first, k)
                if coupled:
                    _rate_rows(arows, feata, Bga, 1.0, Jw_first, k)
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
                _pending_rows(grows, pfeat, pG, pHs, pHs1, pTg, T1, NG, accG)
                if coupled:
                    _pending_rows(arows, pfeata, pG, pHs, pHs1, pTga, T1, NGA, accGA)
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
            if coupled:
                for i in range(3):
                    for m in range(3):
                        pTga[i, m] = Tga[i, m]
                for r in range(na):
                    pfeata[r] = feata[r]
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
                    _tap_rows(grows, pfeat, accG, T1, R, tapJ, tp, gv)
                    if coupled:
                        _mm3(pG, pTga, T2)
                        _tap_rows(arows, pfeata, accGA, T2, R, tapJ, tp, gv)
                    tp += 1
        # the last sample's pending rows (Rn free now: scratch)
        _keyframe_rows(grows, pfeat, accG, pG, pHs, pHs1, pTg, R, s, s1, T1, T2, Rn, gv, JR, JS, JS1, k)
        _rate_rows(grows, pfeat, Aig, -1.0, Jw_last, k)
        if coupled:
            _keyframe_rows(arows, pfeata, accGA, pG, pHs, pHs1, pTga, R, s, s1, T1, T2, Rn, gv, JR, JS, JS1, k)
            _rate_rows(arows, pfeata, Bga, 1.0, Jw_last, k)
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
