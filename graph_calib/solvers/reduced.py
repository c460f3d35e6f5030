r"""One experiment's linearised factors with its attitudes eliminated (the factor graph and the joint solver).

The variables of an experiment's graph are its keyframe attitudes and the unknowns ``theta_e`` its
calibration depends on (the factor graph: the calibration vector itself, ``M_e = I``; the joint solver:
the campaign's unknowns it touches, in units of their prior sigmas, ``x_e = M_e theta_e``).  Linearised, the
experiment's factors (rotation, gravity, encoder: the model's own, whitened; the prior of each segment's
first attitude) give the normal equations

    [ H_RR   H_Rt ] [dR]      [ g_R ]
    [ H_tR   H_tt ] [dt]  = - [ g_t ]

where ``H_RR`` is block tridiagonal (3 x 3 blocks: a rotation factor ties keyframe ``k`` to ``k+1``, every
other factor touches one keyframe).  Eliminating the attitudes, as GTSAM's elimination of the attitude chain
does, leaves on ``theta_e`` the Schur complement ``H_tt - H_tR (H_RR + lam I)^-1 H_Rt`` (and the same for
the gradient): the solver hands GTSAM that reduced factor, GTSAM solves the reduced graph of the unknowns
(with their priors and damping), and the attitude step follows by back-substitution.  The band of ``H_RR``
(half-width 5) is factored by LAPACK's banded Cholesky (:mod:`graph_calib.model.attitude_elimination`, the
closed loop's too); no per-factor Python callback, and the linear system of a 3 h experiment is a few tens of MB instead of GTSAM's 0.3 GB of Jacobian factors.
``tests/solvers/test_joint_reduced.py`` and ``tests/solvers/test_factor_graph_reduced.py`` check cost, step and covariance
against GTSAM's linearisation and elimination of the whole graph (every attitude a variable, the model's
factors as callbacks).

Robust losses are GTSAM's (``noiseModel.Robust``): a factor's whitened rows scaled by the square root of
the M-estimator's weight of the norm of its whole whitened residual, its cost the estimator's loss.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.model.attitude_elimination import NormalEquations, eliminate
from graph_calib.navigation.rotations import exp_so3

__all__ = ["ExperimentSystem", "cost", "cost_by_key", "linearise", "retract"]

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
        loss, w, s = _kind_cost(res, robust=robust, k=k, group=group)
        self.cost += loss
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


def _kind_cost(res, *, robust=None, k=None, group=None):
    """``(cost, whitened (F, 3), row scale s (F, 3))`` of a kind of factors: the cost GTSAM's error gives them
    (half the squared whitened norm, or the M-estimator's loss of each factor's whitened norm), and the
    scale of their rows in the linear system (1/sigma times the square root of the robust weight)."""
    if res.sigma.ndim != 2:
        raise ValueError("the reduced system takes diagonal factor noise only")
    w = res.r / res.sigma
    if robust is None:
        return 0.5 * float(np.sum(w * w)), w, 1.0 / res.sigma
    g = np.arange(w.shape[0]) if group is None else group
    e = np.sqrt(np.bincount(g, weights=np.sum(w * w, axis=1)))
    loss, weight = _robust(e, robust, k)
    return float(np.sum(loss)), w, np.sqrt(weight)[g][:, None] / res.sigma


def _encoder_groups(enc, robust, robust_k):
    """``(group, k)`` of the encoder readings: one robust loss per keyframe's readings (GTSAM's factor), its
    threshold ``robust_k sqrt(m)`` for ``m`` readings (:func:`graph_calib.solvers.factor_graph.build_graph`)."""
    if robust is None or not enc.key.size:
        return None, None
    _, group, counts = np.unique(enc.key, return_inverse=True, return_counts=True)
    return group, robust_k * np.sqrt(counts)


def _attitude_priors(model, R, R_prior):
    """The prior residual of every segment's first attitude; ``R_prior`` (3, 3) or (S, 3, 3)."""
    return model.attitude_priors(R, R_priors=np.asarray(R_prior, dtype=float).reshape(-1, 3, 3))


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
    R_prior : ndarray, shape (3, 3) or (S, 3, 3)
        The prior attitude (the alignment) of the first keyframe of each of the record's ``S`` segments
        (:attr:`graph_calib.model.CalibrationModel.segment_keys`).
    robust : str or None
        GTSAM's M-estimator on the gravity and encoder factors (``huber``, ``cauchy``).
    robust_k : float
        Its threshold for one 3-row factor; an encoder factor of ``m`` readings uses ``robust_k sqrt(m)``
        (:func:`graph_calib.solvers.factor_graph.build_graph`).
    """
    acc = _Accumulator(R.shape[0], M_u.shape[0])
    for key, prior in _attitude_priors(model, R, R_prior):
        acc.add_attitude_prior(key, prior.H, prior.r)
        acc.cost += prior.cost
    rot = model.rotation_factors(R, preint, x)
    w_rot = acc.add_factors(rot)
    del rot
    grav = model.gravity_factors(R, preint, x)
    w_grav = acc.add_factors(grav, robust=robust, k=robust_k)
    del grav
    enc = model.encoder_factors(R, preint, x)
    group, k_enc = _encoder_groups(enc, robust, robust_k)
    w_enc = acc.add_factors(enc, robust=robust, k=k_enc, group=group)
    del enc
    return acc.system(M_u, (w_rot, w_grav, w_enc))


def cost(model, preint, R, x, *, R_prior, robust=None, robust_k=3.0):
    """The experiment's share of the graph's error at ``(R, x)``, without linearising: its factors' and its
    attitude priors' cost, as :attr:`ExperimentSystem.cost` of :func:`linearise` (arguments as there)."""
    total = sum(prior.cost for _, prior in _attitude_priors(model, R, R_prior))
    total += _kind_cost(model.rotation_factors(R, preint, x))[0]
    total += _kind_cost(model.gravity_factors(R, preint, x), robust=robust, k=robust_k)[0]
    enc = model.encoder_factors(R, preint, x)
    if enc.r.shape[0]:
        group, k_enc = _encoder_groups(enc, robust, robust_k)
        total += _kind_cost(enc, robust=robust, k=k_enc, group=group)[0]
    return total


def cost_by_key(model, preint, R, x, *, R_prior, robust=None, robust_k=3.0):
    """:func:`cost` split by keyframe, (K+1,): each factor's cost (a robust factor's loss) on its first
    keyframe (``Residuals.key``; a rotation factor never crosses a segment boundary), each attitude prior's on
    its own.  Sums to :func:`cost` up to rounding."""
    out = np.zeros(R.shape[0])
    for key, prior in _attitude_priors(model, R, R_prior):
        out[key] += prior.cost
    kinds = [(model.rotation_factors(R, preint, x), None, None),
             (model.gravity_factors(R, preint, x), robust_k, None)]
    enc = model.encoder_factors(R, preint, x)
    if enc.r.shape[0]:
        group, k_enc = _encoder_groups(enc, robust, robust_k)
        kinds.append((enc, k_enc, group))
    for res, k, group in kinds:
        w = res.r / res.sigma
        squares = np.sum(w * w, axis=1)
        if robust is None or k is None:
            np.add.at(out, res.key, 0.5 * squares)
            continue
        g = np.arange(squares.size) if group is None else group
        loss, _ = _robust(np.sqrt(np.bincount(g, weights=squares)), robust, k)
        first = np.zeros(loss.size, dtype=np.int64)
        first[g[::-1]] = res.key[::-1]          # the key of each group's first factor
        np.add.at(out, first, loss)
    return out
