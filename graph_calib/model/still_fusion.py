r"""A rest's two factors on one pair of attitudes, made a process factor and a measurement.

Over a static keyframe ``k`` two factors tie ``R_k`` and ``R_{k+1}``: the rotation factor (the gyros' integral,
:func:`graph_calib.model.factors.rotation_factors`) and the still factor (a unit at rest turns with the Earth
alone, :func:`graph_calib.model.factors.still_factors`).  The batch solvers could take both as they are; the
filter takes one factor per pair as its time update and every other factor as a measurement of one keyframe
(``kf_reference.passes``).  So the residual list gives both solvers the same two factors after an orthogonal
map of their six whitened rows (linearised, with ``a = r_rot / s_rot``, ``A_N`` its whitened Jacobian in
``R_{k+1}``, ``b``, ``B_N`` the still factor's):

- the **process** rows ``U^-T (A_N^T [a, A] + B_N^T [b, B])`` with ``U^T U = A_N^T A_N + B_N^T B_N``: the pair's
  information on ``R_{k+1}`` (Jacobian in it ``U``), the rotation kind's;
- the **measurement** rows ``L^-1 ([b, B] - G [a, A])`` with ``G = B_N A_N^-1`` and ``L L^T = G G^T + I``: what
  the still factor says beyond what the rotation factor predicts, free of ``R_{k+1}`` (its Jacobian there is
  ``L^-1 (B_N - G A_N) = 0``), the still kind's; to first order the rest's gyro integral against the Earth's
  turn, over the gyro's noise.

The two blocks' rows are orthonormal and orthogonal to each other, so the map keeps the whitened rows
independent with unit variance and the cost (their sum of squares) unchanged; each row is whitened, its sigma
1.  The map depends on the factors' Jacobians in ``R_{k+1}`` at the linearisation point and is held fixed
through a Gauss-Newton step, as an elimination order's is.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from graph_calib.model.factors import Residuals


def _lower_solve(L, B):
    """``L^-1 B`` for batched lower-triangular ``L`` (F, 3, 3) and ``B`` (F, 3, n)."""
    return np.linalg.solve(L, B)


def fuse_still(rot, still):
    """The rotation and still factors of the static keyframes mapped as the module says.

    Parameters
    ----------
    rot : graph_calib.model.factors.Residuals
        Every rotation factor (its ``key`` ascending).
    still : graph_calib.model.factors.Residuals
        The still factors; each ``key`` has a rotation factor.

    Returns
    -------
    rot, still : graph_calib.model.factors.Residuals
        The rotation factors with those of the static keyframes replaced by the process rows (whitened: sigma
        1), and the still factors as measurements of ``R_k`` and the calibration (``H_R_next`` None, sigma 1).
    """
    if still.key.size == 0:
        return rot, replace(still, H_R_next=None)
    idx = np.searchsorted(rot.key, still.key)
    if np.any(idx >= rot.key.size) or np.any(rot.key[np.minimum(idx, rot.key.size - 1)] != still.key):
        raise ValueError("a still factor without the rotation factor of its keyframe")
    w1 = 1.0 / rot.sigma[idx]
    w2 = 1.0 / still.sigma
    a = rot.r[idx] * w1
    A_R = rot.H_R[idx] * w1[:, :, None]
    A_N = rot.H_R_next[idx] * w1[:, :, None]
    A_x = rot.H_x[idx] * w1[:, :, None]
    b = still.r * w2
    B_R = still.H_R * w2[:, :, None]
    B_N = still.H_R_next * w2[:, :, None]
    At, Bt = np.swapaxes(A_N, 1, 2), np.swapaxes(B_N, 1, 2)
    # the process rows: U^-T (A_N^T [.] + B_N^T [.]), U upper with U^T U = A_N^T A_N + B_N^T B_N
    Lp = np.linalg.cholesky(At @ A_N + Bt @ B_N)           # Lp Lp^T = M, U = Lp^T
    p_r = _lower_solve(Lp, (At @ a[:, :, None] + Bt @ b[:, :, None]))[:, :, 0]
    p_R = _lower_solve(Lp, At @ A_R + Bt @ B_R)
    p_x = _lower_solve(Lp, At @ A_x)
    # the measurement rows: L^-1 ([.]_still - G [.]_rot), G = B_N A_N^-1, L L^T = G G^T + I
    G = np.swapaxes(np.linalg.solve(At, Bt), 1, 2)          # (A_N^-T B_N^T)^T = B_N A_N^-1
    L = np.linalg.cholesky(G @ np.swapaxes(G, 1, 2) + np.eye(3))
    m_r = _lower_solve(L, (b - np.einsum("fij,fj->fi", G, a))[:, :, None])[:, :, 0]
    m_R = _lower_solve(L, B_R - G @ A_R)
    m_x = _lower_solve(L, -(G @ A_x))
    r, H_R, H_N, H_x, sigma = rot.r.copy(), rot.H_R.copy(), rot.H_R_next.copy(), rot.H_x.copy(), rot.sigma.copy()
    r[idx], H_R[idx], H_N[idx], H_x[idx], sigma[idx] = p_r, p_R, np.swapaxes(Lp, 1, 2), p_x, 1.0
    fused_rot = Residuals(r=r, key=rot.key, H_R=H_R, H_R_next=H_N, H_x=H_x, sigma=sigma)
    fused_still = Residuals(r=m_r, key=still.key.copy(), H_R=m_R, H_R_next=None, H_x=m_x, sigma=np.ones_like(m_r))
    return fused_rot, fused_still


__all__ = ["fuse_still"]
