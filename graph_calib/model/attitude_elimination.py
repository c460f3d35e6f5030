r"""The keyframe attitudes eliminated from one record's Gauss-Newton system: written once.

Linearised, a record's factors (:mod:`graph_calib.model.factors`, whitened) give the normal equations in
the keyframe attitudes ``a`` (right perturbations ``R_k Exp(delta_k)``, 3 per keyframe) and a set of
columns ``x`` (the calibration vector, or the unknowns a solver maps it from)

    [ H_aa   H_ax ] [da]      [ g_a ]
    [ H_xa   H_xx ] [dx]  = - [ g_x ]

``H_aa`` is block tridiagonal with 3 x 3 blocks (a rotation factor ties keyframe ``k`` to ``k+1``; every
other factor and prior touches one keyframe): a symmetric band of half-width :data:`HALF_BANDWIDTH`.
Eliminating the attitudes, as GTSAM's elimination of the keyframe chain does, leaves on ``x`` the Schur
complement ``A = H_xx - H_xa (H_aa + lam I)^-1 H_ax`` and ``b = g_x - H_xa (H_aa + lam I)^-1 g_a``; the
attitudes' share of any step ``dx`` is ``da = -(H_aa + lam I)^-1 (g_a + H_ax dx)`` (back-substitution).

- :class:`NormalEquations` sums whitened factor rows into ``H_aa`` (diagonal and super-diagonal blocks),
  ``H_ax``, ``g_a``, ``H_xx``, ``g_x``;
- :func:`eliminate` factors the band by LAPACK's banded Cholesky (``pbtrf``) and forms ``(A, b)`` with
  one banded triangular solve (``Y = L^-1 [H_ax g_a]``, ``H_xa H_aa^-1 H_ax = Y^T Y``); should the band not
  be positive definite in floating point, a sparse LU does the same;
- :class:`AttitudeSolve` keeps what the back-substitution needs.

Users: every solve, score test and prediction, through the one builder of the normal equations
(:mod:`graph_calib.model.normal_equations`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import blas, lapack

from graph_calib.model.factors import sum_by_key

#: Half-bandwidth of the attitudes' block-tridiagonal information (3 x 3 blocks, neighbours only).
HALF_BANDWIDTH = 5


def gram(X):
    """``X^T X`` of ``X`` (m, n), symmetric (BLAS ``syrk``: half the products of ``X.T @ X``)."""
    X = np.asarray(X, dtype=float)
    if X.shape[1] == 0:
        return np.zeros((0, 0))
    C = blas.dsyrk(1.0, X, trans=1) if X.flags.f_contiguous else blas.dsyrk(1.0, X.T, trans=0)
    return np.triu(C) + np.triu(C, 1).T


class NormalEquations:
    """The normal equations of keyframe attitudes and ``n_cols`` columns, summed from whitened rows.

    Attributes (summed in place; :func:`eliminate` takes them)
    ----------
    H_aa_diag : ndarray, shape (K+1, 3, 3)
        Diagonal blocks of ``H_aa``.
    H_aa_off : ndarray, shape (K, 3, 3)
        Blocks ``(k, k+1)`` of ``H_aa``.
    H_ax : ndarray, shape (K+1, 3, n_cols)
    g_a : ndarray, shape (K+1, 3)
    H_xx : ndarray, shape (n_cols, n_cols)
    g_x : ndarray, shape (n_cols,)
    """

    def __init__(self, n_keys, n_cols):
        self.H_aa_diag = np.zeros((n_keys, 3, 3))
        self.H_aa_off = np.zeros((max(n_keys - 1, 0), 3, 3))
        self.H_ax = np.zeros((n_keys, 3, n_cols))
        self.g_a = np.zeros((n_keys, 3))
        self.H_xx = np.zeros((n_cols, n_cols))
        self.g_x = np.zeros(n_cols)

    def add_rows(self, key, r, A, X, *, B=None, cols=None):
        """Add whitened factor rows: residuals ``r`` (F, m), Jacobians ``A`` in attitude ``key``, ``B`` in
        ``key + 1`` (F, m, 3; None when the factor touches one keyframe), ``X`` in the columns ``cols``
        (F, m, len(cols); every column when None).  ``key`` (F,) non-decreasing is fastest
        (:func:`graph_calib.model.factors.sum_by_key`)."""
        At = np.swapaxes(A, 1, 2)
        n_keys = self.H_aa_diag.shape[0]
        whole = cols is None
        H_ax = self.H_ax if whole else np.zeros((n_keys, 3, X.shape[2]))
        sum_by_key(self.H_aa_diag, key, At @ A)
        sum_by_key(self.g_a, key, np.einsum("fji,fj->fi", A, r))
        sum_by_key(H_ax, key, At @ X)
        if B is not None:
            Bt = np.swapaxes(B, 1, 2)
            sum_by_key(self.H_aa_diag, key + 1, Bt @ B)
            sum_by_key(self.H_aa_off, key, At @ B)
            sum_by_key(self.g_a, key + 1, np.einsum("fji,fj->fi", B, r))
            sum_by_key(H_ax, key + 1, Bt @ X)
        Xf = X.reshape(-1, X.shape[2])
        if whole:
            self.H_xx += gram(Xf)
            self.g_x += Xf.T @ r.reshape(-1)
        else:
            self.H_ax[:, :, cols] += H_ax
            self.H_xx[np.ix_(cols, cols)] += gram(Xf)
            self.g_x[cols] += Xf.T @ r.reshape(-1)

    def add_attitude_prior(self, k, H, r):
        """A prior on keyframe ``k``'s attitude: whitened Jacobian ``H`` (3, 3) and residual ``r`` (3,)."""
        self.H_aa_diag[k] += H.T @ H
        self.g_a[k] += H.T @ r


@dataclass(frozen=True)
class AttitudeSolve:
    """``(H_aa + lam I)^-1 (g_a + H_ax dx)`` for any step ``dx``: the eliminated attitudes' share of a step.

    Attributes
    ----------
    chol : ndarray (6, 3 (K+1)) or None
        Lower banded Cholesky factor ``L`` of ``H_aa + lam I`` (None where the sparse LU solved instead).
    Y : ndarray (3 (K+1), Q + 1)
        ``L^-1 [H_ax, g_a]`` (``(H_aa + lam I)^-1 [H_ax, g_a]`` without ``chol``).
    """

    chol: np.ndarray | None
    Y: np.ndarray

    def solve(self, dx):
        """``(H_aa + lam I)^-1 (g_a + H_ax dx)``, shape (3 (K+1),), for ``dx`` (Q,)."""
        v = self.Y[:, -1] + self.Y[:, :-1] @ np.asarray(dx, dtype=float)
        if self.chol is None:
            return v
        v, info = lapack.dtbtrs(self.chol, v[:, None], uplo="L", trans="T")
        return v[:, 0]

    def step(self, dx):
        """The attitudes' step ``da = -(H_aa + lam I)^-1 (g_a + H_ax dx)``, shape (K+1, 3), rad."""
        return -self.solve(dx).reshape(-1, 3)


def _lower_band(H_aa_diag, H_aa_off, lam):
    """``H_aa + lam I`` in LAPACK's lower band storage ``ab[i - j, j] = H[i, j]``, ``0 <= i - j <= 5``."""
    K = H_aa_off.shape[0]
    ab = np.zeros((HALF_BANDWIDTH + 1, 3 * (K + 1)))
    i3, j3 = np.tril_indices(3)
    for a_, b_ in zip(i3, j3):
        ab[a_ - b_, 3 * np.arange(K + 1) + b_] = H_aa_diag[:, a_, b_]
    for a_ in range(3):
        for b_ in range(3):
            # block (k+1, k) = H_aa_off[k]^T: row 3k+3+a_, column 3k+b_
            ab[3 + a_ - b_, 3 * np.arange(K) + b_] = H_aa_off[:, b_, a_]
    ab[0] += lam
    return ab


def eliminate(H_aa_diag, H_aa_off, H_ax, g_a, H_xx, g_x, *, lam=0.0, definite=False):
    """Eliminate the attitudes: ``A = H_xx - H_xa (H_aa + lam I)^-1 H_ax``, ``b = g_x - H_xa (H_aa + lam I)^-1 g_a``.

    Parameters
    ----------
    H_aa_diag : ndarray (K+1, 3, 3)
    H_aa_off : ndarray (K, 3, 3)
        Block ``(k, k+1)``.
    H_ax : ndarray (3 (K+1), Q)
    g_a : ndarray (3 (K+1),)
    H_xx : ndarray (Q, Q)
    g_x : ndarray (Q,)
    lam : float
        Damping added to the attitudes' information only (the caller damps the columns).
    definite : bool
        Raise ``RuntimeError`` when ``H_aa + lam I`` is not positive definite in floating point (a damped
        solver then damps harder) instead of solving by the sparse LU.

    Returns
    -------
    A : ndarray (Q, Q)
        Symmetric.
    b : ndarray (Q,)
    attitudes : AttitudeSolve
    """
    na, Q = H_ax.shape
    K = H_aa_off.shape[0]
    rhs = np.asfortranarray(np.column_stack([H_ax, g_a]))
    c, info = lapack.dpbtrf(_lower_band(H_aa_diag, H_aa_off, lam), lower=1)
    if info == 0:
        Y, info = lapack.dtbtrs(c, rhs, uplo="L", overwrite_b=1)
    if info == 0:
        Yx = Y[:, :Q]
        A = H_xx - gram(Yx)
        b = g_x - Yx.T @ Y[:, Q]
        att = AttitudeSolve(chol=c, Y=Y)
    elif definite:
        raise RuntimeError(f"attitudes' information not positive definite (LAPACK info {info})")
    else:
        # scipy.sparse only here, in the rare fallback: its import is 0.05 s of every calibrate's start otherwise
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla

        base = np.arange(3)
        br, bc = np.repeat(base, 3), np.tile(base, 3)          # a 3 x 3 block, row-major
        kd = 3 * np.arange(K + 1)[:, None]
        ko = 3 * np.arange(K)[:, None]
        rows = np.concatenate([(kd + br).ravel(), (ko + br).ravel(), (ko + 3 + br).ravel(), np.arange(na)])
        cols = np.concatenate([(kd + bc).ravel(), (ko + 3 + bc).ravel(), (ko + bc).ravel(), np.arange(na)])
        vals = np.concatenate([H_aa_diag.ravel(), H_aa_off.ravel(), np.swapaxes(H_aa_off, 1, 2).ravel(),
                               np.full(na, float(lam))])
        H_aa = sp.csc_matrix((vals, (rows, cols)), shape=(na, na))
        sol = spla.splu(H_aa).solve(np.column_stack([H_ax, g_a]))
        A = H_xx - H_ax.T @ sol[:, :Q]
        b = g_x - H_ax.T @ sol[:, Q]
        att = AttitudeSolve(chol=None, Y=sol)
    return 0.5 * (A + A.T), b, att


__all__ = ["HALF_BANDWIDTH", "NormalEquations", "AttitudeSolve", "eliminate", "gram"]
