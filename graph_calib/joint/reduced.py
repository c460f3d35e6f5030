r"""One experiment's linearised factors with its attitudes eliminated (:mod:`graph_calib.joint.solver`).

The joint graph's variables are every experiment's keyframe attitudes and the unknowns ``theta_e = (u_z,
u_s)`` it touches (in units of their prior sigmas: ``x_e = M_e theta_e``).  Linearised, one experiment's
factors (rotation, gravity, encoder: the model's own, whitened; the prior of its first attitude) give the
normal equations

    [ H_RR   H_Rt ] [dR]      [ g_R ]
    [ H_tR   H_tt ] [dt]  = - [ g_t ]

where ``H_RR`` is block tridiagonal (3 x 3 blocks: a rotation factor ties keyframe ``k`` to ``k+1``, every
other factor touches one keyframe).  Eliminating the attitudes, as GTSAM's elimination of each experiment's
chain does, leaves on ``theta_e`` the Schur complement ``H_tt - H_tR (H_RR + lam I)^-1 H_Rt`` (and the
same for the gradient): the joint solver hands GTSAM that reduced factor per experiment, GTSAM solves the
reduced graph of the unknowns, and each experiment's attitude step follows by back-substitution.  The
band of ``H_RR`` (half-width 5) is factored by LAPACK's banded Cholesky
(:mod:`graph_calib.model.attitude_elimination`, the closed loop's too); no per-factor Python callback,
and the linear system of a 3 h experiment is a few tens of MB instead of GTSAM's 0.3 GB of Jacobian
factors.  ``tests/test_joint_reduced.py`` checks cost, step and covariance against GTSAM's linearisation
and elimination of the whole graph (every attitude a variable, the model's factors as callbacks).

Robust losses are GTSAM's (``noiseModel.Robust``): a factor's whitened rows scaled by the square root of
the M-estimator's weight of the norm of its whole whitened residual, its cost the estimator's loss.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.model.attitude_elimination import NormalEquations, eliminate
from graph_calib.rotations import exp_so3

#: Factors whitened and chained per block (bounds the temporaries of the 3 h records' 85,000 readings).
CHUNK = 8192


def _robust(e, kind, k):
    """``(loss, weight)`` of GTSAM's M-estimator ``kind`` (``huber``, ``cauchy``) at whitened norms ``e``."""
    if kind == "huber":
        big = e > k
        loss = np.where(big, k * e - 0.5 * k * k, 0.5 * e * e)
        return loss, np.where(big, k / np.maximum(e, 1e-300), 1.0)
    if kind == "cauchy":
        q = (e / k) ** 2
        return 0.5 * k * k * np.log1p(q), 1.0 / (1.0 + q)
    raise ValueError(f"unknown robust loss {kind!r}")


@dataclass(frozen=True)
class ExperimentSystem:
    """One experiment's normal equations at one point (module docstring).

    Attributes
    ----------
    cost : float
        The experiment's share of the graph's error (its factors and its first attitude's prior).
    H_RR_diag, H_RR_off : ndarray, shapes (K+1, 3, 3), (K, 3, 3)
        ``H_RR``'s diagonal blocks and its blocks ``(k, k+1)``, undamped.
    H_Rt : ndarray, shape (3 (K+1), Nt)
    g_R : ndarray, shape (3 (K+1),)
    H_tt : ndarray, shape (Nt, Nt)
    g_t : ndarray, shape (Nt,)
    whitened : tuple of ndarray
        Whitened residuals (r / sigma, no robust weight) of the rotation, gravity and encoder factors,
        each (F, 3).
    """

    cost: float
    H_RR_diag: np.ndarray
    H_RR_off: np.ndarray
    H_Rt: np.ndarray
    g_R: np.ndarray
    H_tt: np.ndarray
    g_t: np.ndarray
    whitened: tuple

    def reduce(self, lam):
        """The Schur complement on ``theta_e`` with ``lam I`` added to the attitudes' information.

        Returns
        -------
        H, g : ndarray, shapes (Nt, Nt), (Nt,)
            Reduced information and gradient (``lam`` not added on ``theta_e``: the caller damps it).
        attitudes : graph_calib.model.attitude_elimination.AttitudeSolve
            The back-substitution, for :meth:`attitude_step`.

        Raises
        ------
        RuntimeError
            ``H_RR + lam I`` not positive definite in floating point.
        """
        return eliminate(self.H_RR_diag, self.H_RR_off, self.H_Rt, self.g_R, self.H_tt, self.g_t, lam=lam,
                         definite=True)

    @staticmethod
    def attitude_step(attitudes, d_theta):
        """The attitudes' step (K+1, 3) given the unknowns' step ``d_theta`` (Nt,) (back-substitution)."""
        return attitudes.step(d_theta)

    def attitude_only_step(self, lam):
        """The attitudes' step (K+1, 3) with the unknowns held."""
        _, _, att = eliminate(self.H_RR_diag, self.H_RR_off, np.zeros((self.g_R.size, 0)), self.g_R,
                              np.zeros((0, 0)), np.zeros(0), lam=lam, definite=True)
        return att.step(np.zeros(0))


def retract(R, dR):
    """``R_k Exp(dR_k)`` for every keyframe (GTSAM's ``Rot3`` retraction), (K+1, 3, 3)."""
    return R @ exp_so3(dR)


class _Accumulator(NormalEquations):
    """Sums one experiment's whitened factors into its normal equations, in the calibration vector's
    columns (P): ``theta_e``'s blocks are ``M_u^T (.) M_u`` of them, formed once at the end."""

    def __init__(self, n_keys, P):
        super().__init__(n_keys, P)
        self.cost = 0.0

    def add_factors(self, res, *, robust=None, k=None, group=None):
        """A kind of factors (:class:`graph_calib.model.factors.Residuals`), whitened, in chunks.

        ``group`` (F,) int: the factors that share one robust loss (GTSAM's factor: an encoder factor holds
        every reading of its keyframe); ``k`` its threshold per factor, (G,) or scalar.
        """
        F = res.r.shape[0]
        if F == 0:
            return np.zeros((0, 3))
        if res.sigma.ndim != 2:
            raise ValueError("the reduced system takes diagonal factor noise only")
        w = res.r / res.sigma
        if robust is None:
            s = 1.0 / res.sigma
            self.cost += 0.5 * float(np.sum(w * w))
        else:
            g = np.arange(F) if group is None else group
            e = np.sqrt(np.bincount(g, weights=np.sum(w * w, axis=1)))
            loss, weight = _robust(e, robust, k)
            self.cost += float(np.sum(loss))
            s = np.sqrt(weight)[g][:, None] / res.sigma
        for lo in range(0, F, CHUNK):
            sl = slice(lo, min(lo + CHUNK, F))
            sc = s[sl][:, :, None]
            self.add_rows(res.key[sl], res.r[sl] * s[sl], res.H_R[sl] * sc, res.H_x[sl] * sc,
                          B=None if res.H_R_next is None else res.H_R_next[sl] * sc)
        return w

    def system(self, M_u, whitened):
        n = self.H_aa_diag.shape[0]
        H_tt = M_u.T @ self.H_xx @ M_u
        return ExperimentSystem(cost=self.cost, H_RR_diag=self.H_aa_diag, H_RR_off=self.H_aa_off,
                                H_Rt=self.H_ax.reshape(3 * n, -1) @ M_u, g_R=self.g_a.reshape(-1),
                                H_tt=0.5 * (H_tt + H_tt.T), g_t=M_u.T @ self.g_x, whitened=whitened)


def linearise(model, preint, R, x, M_u, *, R_prior, robust=None, robust_k=3.0):
    """One experiment's factors at ``(R, x)``, linearised, as an :class:`ExperimentSystem`.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    preint : graph_calib.model.preintegration.Preintegrated
    R : ndarray, shape (K+1, 3, 3)
        Keyframe attitudes.
    x : ndarray, shape (P,)
        The experiment's calibration vector, ``M_u @ theta_e``.
    M_u : ndarray, shape (P, Nt)
        ``d x / d theta_e``.
    R_prior : ndarray, shape (3, 3)
        The first keyframe's prior attitude (the alignment).
    robust : str or None
        GTSAM's M-estimator on the gravity and encoder factors (``huber``, ``cauchy``).
    robust_k : float
        Its threshold for one 3-row factor; an encoder factor of ``m`` readings uses ``robust_k sqrt(m)``
        (:func:`graph_calib.factor_graph.build_graph`).
    """
    acc = _Accumulator(R.shape[0], M_u.shape[0])
    prior = model.attitude_prior(R[0], R_prior=R_prior)
    acc.add_attitude_prior(0, prior.H, prior.r)
    acc.cost += prior.cost
    rot = model.rotation_factors(R, preint, x)
    w_rot = acc.add_factors(rot)
    del rot
    grav = model.gravity_factors(R, preint, x)
    w_grav = acc.add_factors(grav, robust=robust, k=robust_k)
    del grav
    enc = model.encoder_factors(R, preint, x)
    group = k_enc = None
    if robust is not None and enc.key.size:
        _, group, counts = np.unique(enc.key, return_inverse=True, return_counts=True)
        k_enc = robust_k * np.sqrt(counts)
    w_enc = acc.add_factors(enc, robust=robust, k=k_enc, group=group)
    del enc
    return acc.system(M_u, (w_rot, w_grav, w_enc))


__all__ = ["ExperimentSystem", "linearise", "retract"]
