r"""The linear square-root Kalman filter over keyframes (numba), and the state layout.

The filter here knows nothing about IMUs: it runs a linear Gaussian recursion
whose matrices :mod:`kf_reference.passes` takes from the shared model's
factors.  Error state at keyframe ``k`` (names used everywhere, never bare
indices)::

    s = [delta_k (ATT: 3, rad), dx (CAL: P)]

Time update (from rotation factor ``k``, ``w ~ N(0, G G^T)`` already mapped
through ``N^-1``)

.. math::

    \delta_{k+1} = B_k \delta_k + A_k\,dx + c_k + G_k w,\qquad dx_{k+1} = dx_k .

Scalar measurement (one component of a gravity or encoder factor)

.. math::

    z = h^T s + v,\qquad v \sim N(0, \sigma^2).

Square-root form
    ``P = U U^T`` with ``U`` upper triangular, held transposed (``Ut = U^T``,
    lower triangular, row-major) so that every inner loop runs over contiguous
    memory.  With the attitude first, the time update leaves the calibration
    rows of ``U`` untouched: the cross block becomes ``B U_dx + A U_xx`` and only
    the 3x3 attitude block is re-triangularised, by column Givens rotations of
    the 3x6 pre-array ``[B U_dd, G]`` (a QR factorisation of its transpose).
    Measurement updates are Carlson's scalar update, which keeps ``U`` upper
    triangular (Carlson 1973; Grewal & Andrews, *Kalman Filtering*, sec. 6.5).
"""

from __future__ import annotations

import numba
import numpy as np

from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

#: The attitude error (right perturbation of the keyframe attitude, body axes), rad.
ATT = slice(0, 3)
#: Offset of the calibration error ``dx`` in the state.
N_ATT = 3


def cal_slice(P):
    """Slice of the calibration error ``dx`` in a state with ``P`` calibration elements."""
    return slice(N_ATT, N_ATT + P)


@numba.njit(cache=True)
def carlson_update(Ut, s, h, z, r_var, w):
    """Carlson's scalar measurement update, in place.

    Parameters
    ----------
    Ut : ndarray, shape (n, n)
        Transpose of the upper-triangular square root ``U`` (``P = U U^T``); updated.
    s : ndarray, shape (n,)
        State estimate; updated.
    h : ndarray, shape (n,)
        Measurement row, ``z = h @ s + v``.
    z : float
        Measurement.
    r_var : float
        Measurement noise variance, > 0.
    w : ndarray, shape (n,)
        Workspace.

    Returns
    -------
    innovation, innovation_variance : float
    """
    n = s.shape[0]
    nu = z
    for i in range(n):
        nu -= h[i] * s[i]
    alpha = r_var
    for j in range(n):
        row = Ut[j]
        f = 0.0
        for i in range(j + 1):
            f += row[i] * h[i]
        w[j] = 0.0
        if f == 0.0:
            continue  # column j of U is orthogonal to h: nothing changes
        beta = alpha
        alpha = alpha + f * f
        gamma = np.sqrt(alpha * beta)
        eta = beta / gamma
        zeta = f / gamma
        for i in range(j + 1):
            tau = row[i]
            row[i] = eta * tau - zeta * w[i]
            w[i] += tau * f
    eps = nu / alpha
    for i in range(n):
        s[i] += w[i] * eps
    return nu, alpha


@numba.njit(cache=True)
def _givens_columns(M, row, a, c):
    """Rotate columns ``a`` and ``c`` of ``M`` so that ``M[row, c] = 0``."""
    x = M[row, a]
    y = M[row, c]
    if y == 0.0:
        return
    r = np.hypot(x, y)
    cs = x / r
    sn = y / r
    for i in range(M.shape[0]):
        ma = M[i, a]
        mc = M[i, c]
        M[i, a] = cs * ma + sn * mc
        M[i, c] = cs * mc - sn * ma


@numba.njit(cache=True)
def time_update(Ut, s, B, A, G, c, work, pre):
    """Propagate the attitude error with ``delta' = B delta + A dx + c + G w``, in place.

    Parameters
    ----------
    Ut : ndarray, shape (n, n)
        Transposed upper-triangular square root; updated.
    s : ndarray, shape (n,)
        State estimate; updated.
    B : (3, 3), A : (3, P), G : (3, 3), c : (3,)
    work : (3,) and pre : (3, 6) workspaces.
    """
    n = s.shape[0]
    m = N_ATT
    # mean
    for i in range(m):
        v = c[i]
        for l in range(m):
            v += B[i, l] * s[l]
        for l in range(n - m):
            v += A[i, l] * s[m + l]
        work[i] = v
    for i in range(m):
        s[i] = work[i]
    # cross block: U_dx' = B U_dx + A U_xx, one column of U (one row of Ut) at a time
    for r in range(m, n):
        row = Ut[r]
        for i in range(m):
            v = 0.0
            for l in range(m):
                v += B[i, l] * row[l]
            for l in range(r - m + 1):
                v += A[i, l] * row[m + l]
            work[i] = v
        for i in range(m):
            row[i] = work[i]
    # attitude block: [B U_dd, G] -> [U_dd', 0], U_dd' upper triangular
    for i in range(m):
        for j in range(m):
            v = 0.0
            for l in range(j + 1):
                v += B[i, l] * Ut[j, l]       # U_dd[l, j] = Ut[j, l], l <= j
            pre[i, j] = v
            pre[i, m + j] = G[i, j]
    for i in range(m - 1, -1, -1):
        for cc in range(2 * m):
            if cc != i and (cc < i or cc >= m):
                _givens_columns(pre, i, i, cc)
    for i in range(m):
        for j in range(m):
            Ut[j, i] = pre[i, j] if i <= j else 0.0


@numba.njit(cache=True)
def run(Ut, s, B, A, G, c, H, z, sigma, lo, delta_out, att_sigma_out, innov_out, innov_var_out):
    """One filter pass over ``K`` keyframes (``K + 1`` attitude boundaries), in place.

    At each keyframe ``k``: the scalar measurements ``lo[k]:lo[k+1]`` (rows of
    ``H``, ``z``, ``sigma``), then the filtered attitude error and its sigma are
    recorded, then (``k < K``) the time update with ``B[k], A[k], G[k], c[k]``.

    Parameters
    ----------
    Ut : (n, n), s : (n,)
        Initial square root (transposed, see module docstring) and mean; final on return.
    B : (K, 3, 3), A : (K, 3, P), G : (K, 3, 3), c : (K, 3)
    H : (m, n), z : (m,), sigma : (m,)
    lo : (K + 2,) int
        Row ranges of the measurements of each boundary.
    delta_out : (K + 1, 3), att_sigma_out : (K + 1, 3)
        Filtered attitude error and its one sigma at each boundary.
    innov_out, innov_var_out : (m,)
        Innovation of each scalar measurement and its variance.
    """
    n = s.shape[0]
    K = B.shape[0]
    w = np.empty(n)
    work = np.empty(N_ATT)
    pre = np.empty((N_ATT, 2 * N_ATT))
    for k in range(K + 1):
        for q in range(lo[k], lo[k + 1]):
            nu, a = carlson_update(Ut, s, H[q], z[q], sigma[q] * sigma[q], w)
            innov_out[q] = nu
            innov_var_out[q] = a
        for i in range(N_ATT):
            delta_out[k, i] = s[i]
            v = 0.0
            for r in range(i, n):                # P_ii = sum_r U[i, r]^2 = sum_r Ut[r, i]^2
                v += Ut[r, i] * Ut[r, i]
            att_sigma_out[k, i] = np.sqrt(v)
        if k < K:
            time_update(Ut, s, B[k], A[k], G[k], c[k], work, pre)


@numba.njit(cache=True)
def smooth_attitude(Ut0, s0, B, G, c, H, z, sigma, lo, mean_out, sigma_out):
    """Rauch-Tung-Striebel smoother of the attitude chain alone (state ``delta``, 3), in place.

    The recursion of :func:`run` with the calibration error held at a known value
    (the caller folds ``A dx`` into ``c`` and ``H_x dx`` into ``z``): a
    square-root forward pass (Carlson updates, Givens time updates) that keeps
    every filtered and predicted factor, then the backward RTS recursion
    ``m_k = m_k|k + C_k (m_k+1 - m_k+1|k)``, ``C_k = P_k|k B_k^T P_k+1|k^-1``.

    Parameters
    ----------
    Ut0 : (3, 3), s0 : (3,)
        Prior square root (transposed) and mean of ``delta_0``.
    B : (K, 3, 3), G : (K, 3, 3), c : (K, 3)
    H : (m, 3), z : (m,), sigma : (m,), lo : (K + 2,)
        As in :func:`run`, restricted to the attitude.
    mean_out, sigma_out : (K + 1, 3)
        Smoothed attitude error and its one sigma (given the calibration).
    """
    K = B.shape[0]
    m = N_ATT
    Uf = np.empty((K + 1, m, m))
    sf = np.empty((K + 1, m))
    Up = np.empty((K + 1, m, m))
    sp = np.empty((K + 1, m))
    Ut = Ut0.copy()
    s = s0.copy()
    w = np.empty(m)
    work = np.empty(m)
    pre = np.empty((m, 2 * m))
    A0 = np.empty((m, 0))
    for k in range(K + 1):
        for q in range(lo[k], lo[k + 1]):
            carlson_update(Ut, s, H[q], z[q], sigma[q] * sigma[q], w)
        Uf[k] = Ut
        sf[k] = s
        if k < K:
            time_update(Ut, s, B[k], A0, G[k], c[k], work, pre)
            Up[k + 1] = Ut
            sp[k + 1] = s
    Ps = np.empty((m, m))
    Pf = np.empty((m, m))
    Pp = np.empty((m, m))
    BPf = np.empty((m, m))
    C = np.empty((m, m))
    T = np.empty((m, m))
    d = np.empty(m)
    ms = sf[K].copy()
    _utu(Uf[K], Ps)
    mean_out[K] = ms
    for i in range(m):
        sigma_out[K, i] = np.sqrt(Ps[i, i])
    for k in range(K - 1, -1, -1):
        _utu(Uf[k], Pf)
        _utu(Up[k + 1], Pp)
        # C = Pf B^T Pp^-1, i.e. Pp C^T = B Pf
        for i in range(m):
            for j in range(m):
                v = 0.0
                for r in range(m):
                    v += B[k, i, r] * Pf[r, j]
                BPf[i, j] = v
        _solve_transposed(Pp, BPf, C)
        for i in range(m):
            d[i] = ms[i] - sp[k + 1, i]
        for i in range(m):
            v = 0.0
            for j in range(m):
                v += C[i, j] * d[j]
            ms[i] = sf[k, i] + v
        # Ps = Pf + C (Ps - Pp) C^T
        for i in range(m):
            for j in range(m):
                v = 0.0
                for r in range(m):
                    v += C[i, r] * (Ps[r, j] - Pp[r, j])
                T[i, j] = v
        for i in range(m):
            for j in range(m):
                v = 0.0
                for r in range(m):
                    v += T[i, r] * C[j, r]
                Ps[i, j] = Pf[i, j] + v
        mean_out[k] = ms
        for i in range(m):
            sigma_out[k, i] = np.sqrt(max(Ps[i, i], 0.0))


@numba.njit(cache=True, _nrt=False)
def _utu(Ut, out):
    """``out = Ut^T Ut`` for a square ``Ut`` (the covariance ``U U^T`` from its stored transpose)."""
    n = Ut.shape[0]
    for i in range(n):
        for j in range(n):
            v = 0.0
            for r in range(n):
                v += Ut[r, i] * Ut[r, j]
            out[i, j] = v


@numba.njit(cache=True)
def _solve_transposed(A, Y, X):
    """``X`` with ``A X^T = Y`` for small square ``A`` (LU with partial pivoting, as LAPACK's ``gesv``).

    Written out rather than ``np.linalg.solve``, whose numba implementation took most of this module's
    compile time (docs/performance.md, "Compiling the kernels").
    """
    n = A.shape[0]
    LU = A.copy()
    Z = Y.copy()
    for c in range(n):
        p = c
        big = abs(LU[c, c])
        for r in range(c + 1, n):
            if abs(LU[r, c]) > big:
                big = abs(LU[r, c])
                p = r
        if p != c:
            for q in range(n):
                t = LU[c, q]
                LU[c, q] = LU[p, q]
                LU[p, q] = t
                t = Z[c, q]
                Z[c, q] = Z[p, q]
                Z[p, q] = t
        for r in range(c + 1, n):
            f = LU[r, c] / LU[c, c]
            LU[r, c] = f
            for q in range(c + 1, n):
                LU[r, q] -= f * LU[c, q]
            for q in range(n):
                Z[r, q] -= f * Z[c, q]
    for c in range(n - 1, -1, -1):
        for q in range(n):
            v = Z[c, q]
            for r in range(c + 1, n):
                v -= LU[c, r] * Z[r, q]
            Z[c, q] = v / LU[c, c]
    for i in range(n):
        for q in range(n):
            X[q, i] = Z[i, q]


def covariance(Ut):
    """``P = U U^T`` from the stored transpose, shape (n, n)."""
    return Ut.T @ Ut
