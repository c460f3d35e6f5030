r"""The one normal-equations builder: a record's residual list linearised, whitened once, attitudes eliminated.

At a point ``(R, x)`` every factor kind of the model (:data:`graph_calib.model.residual_list.FACTOR_KINDS`)
and the prior of each segment's first attitude are linearised in the keyframe attitudes ``a`` (right
perturbations ``R_k Exp(delta_k)``) and a set of columns: the calibration vector's own, or ``theta``
through a column map ``x = M theta`` (the joint solver's unknowns), then any further columns a caller fills
(the diagnosis's drivers).  Whitened (:func:`graph_calib.model.residual_list.whiten`, robust losses
included) they give

    [ H_aa   H_ax ] [da]      [ g_a ]
    [ H_xa   H_xx ] [dx]  = - [ g_x ]

and :meth:`LinearSystem.reduce` eliminates the attitudes (the banded Cholesky of
:mod:`graph_calib.model.attitude_elimination`): the Schur complement every user solves with.  Users: the
least-squares driver (:mod:`graph_calib.solvers.least_squares`: the factor graph and the joint solver, one
reduced GTSAM factor per experiment), the closed loop's score tests (:mod:`graph_calib.diagnosis.reduced_system`,
with driver columns) and ``predict`` (:mod:`graph_calib.design.prediction`).  Priors enter as the residuals
they are (:class:`graph_calib.model.factors.PriorResidual`): the attitude priors here, a calibration prior on
chosen columns when the caller passes one (the solvers put the unknowns' prior in the GTSAM graph instead).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.model.attitude_elimination import NormalEquations, eliminate
from graph_calib.model.residual_list import FACTOR_KINDS, cost_by_key as _kind_cost_by_key, residual_list, whiten
from graph_calib.navigation.rotations import exp_so3

#: Factors whitened and summed per block (bounds the temporaries of a 3 h record's 85,000 readings).
CHUNK = 8192


@dataclass(frozen=True)
class LinearSystem:
    """A record's normal equations at one point (module docstring).

    Attributes
    ----------
    cost : float
        Half the squared whitened norm (robust losses where asked) of every factor and prior it holds.
    H_aa_diag, H_aa_off : ndarray, shapes (K+1, 3, 3), (K, 3, 3)
        Diagonal blocks of ``H_aa`` and its blocks ``(k, k+1)``, undamped.
    H_ax : ndarray, shape (3 (K+1), N)
    g_a : ndarray, shape (3 (K+1),)
    H_xx : ndarray, shape (N, N)
    g_x : ndarray, shape (N,)
    whitened : dict
        ``{kind name: r / sigma (F, 3)}`` (no robust weight) of every factor kind.
    factors : dict or None
        ``{kind name: Residuals}`` without Jacobians, when kept (``keep_factors``).
    """

    cost: float
    H_aa_diag: np.ndarray
    H_aa_off: np.ndarray
    H_ax: np.ndarray
    g_a: np.ndarray
    H_xx: np.ndarray
    g_x: np.ndarray
    whitened: dict
    factors: dict | None = None

    @property
    def chi2(self):
        """Sum of the squared whitened residuals of every factor (no prior)."""
        return float(sum(np.sum(w**2) for w in self.whitened.values()))

    @property
    def n_residuals(self):
        """Scalar factor residuals."""
        return int(sum(w.size for w in self.whitened.values()))

    def reduce(self, lam=0.0, *, definite=True):
        """The Schur complement on the columns with ``lam I`` added to the attitudes' information.

        Returns ``(A (N, N), b (N,), attitudes)``: reduced information and gradient (``lam`` not added on
        the columns: the caller damps them) and the back-substitution
        (:class:`graph_calib.model.attitude_elimination.AttitudeSolve`).  ``definite``: raise
        ``RuntimeError`` when ``H_aa + lam I`` is not positive definite (a damped solver then damps harder),
        else solve by the sparse LU (:func:`graph_calib.model.attitude_elimination.eliminate`).
        """
        return eliminate(self.H_aa_diag, self.H_aa_off, self.H_ax, self.g_a, self.H_xx, self.g_x, lam=lam,
                         definite=definite)

    def attitude_only_step(self, lam):
        """The attitudes' step (K+1, 3) with the columns held."""
        _, _, att = eliminate(self.H_aa_diag, self.H_aa_off, np.zeros((self.g_a.size, 0)), self.g_a,
                              np.zeros((0, 0)), np.zeros(0), lam=lam, definite=True)
        return att.step(np.zeros(0))


def add_prior(H, g, prior, cols):
    """Add a diagonal prior residual (:class:`graph_calib.model.factors.PriorResidual`) on the columns ``cols``
    to an information ``H`` and a gradient ``g`` (None: information only), in place: ``H^T H`` and
    ``H^T r`` of its rows ``cols``.  Returns its cost there."""
    cols = np.asarray(cols, dtype=np.int64)
    h = np.diag(prior.H)[cols]
    H[cols, cols] += h**2
    if g is not None:
        g[cols] += h * prior.r[cols]
    return 0.5 * float(np.sum(prior.r[cols] ** 2))


def retract(R, dR):
    """``R_k Exp(dR_k)`` for every keyframe (GTSAM's ``Rot3`` retraction), (K+1, 3, 3)."""
    return R @ exp_so3(dR)


def linearise(model, preint, R, x, *, R_prior, M=None, n_extra=0, robust=None, robust_k=3.0, prior=None,
              touched_columns=False, on_kind=None, keep_factors=False):
    """The model's residual list at ``(R, x)`` linearised into a :class:`LinearSystem`.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    preint : graph_calib.model.preintegration.Preintegrated
    R : ndarray, shape (K+1, 3, 3)
    x : ndarray, shape (P,)
    R_prior : ndarray, shape (3, 3) or (S, 3, 3)
        The alignment of each segment's first keyframe (:meth:`CalibrationModel.segment_priors`).
    M : ndarray, shape (P, Nt), optional
        ``d x / d theta``: the columns are ``theta``'s (default the calibration vector's own).
    n_extra : int
        Further columns after them, zero here (a caller's ``on_kind`` fills them).
    robust, robust_k : str or None, float
        The robust loss on the kinds that take one, and its threshold for one 3-row factor.
    prior : (PriorResidual, ndarray of int), optional
        A prior on the columns ``cols`` (its residual and Jacobian restricted to them).
    touched_columns : bool
        Sum each kind into only the calibration columns its Jacobian touches (faster with many columns).
    on_kind : callable, optional
        ``on_kind(kind, res, sl, r, A, B, X, cols, ne)`` after each block ``sl`` (a slice) of a kind's factors,
        with their whitened rows (``cols`` the columns of ``X``) and the :class:`~graph_calib.model.attitude_elimination.NormalEquations`.
    keep_factors : bool
        Keep the factors' residuals without their Jacobians (:attr:`LinearSystem.factors`).
    """
    P = model.layout.size
    n_cols = P + int(n_extra)
    ne = NormalEquations(R.shape[0], n_cols)
    cost = 0.0
    for key, att_prior in model.attitude_priors(R, R_priors=np.asarray(R_prior, dtype=float).reshape(-1, 3, 3)):
        ne.add_attitude_prior(key, att_prior.H, att_prior.r)
        cost += att_prior.cost
    whitened, kept = {}, {}
    factors = residual_list(model, R, preint, x)
    for kind in FACTOR_KINDS:
        res = factors.pop(kind.name)
        F = res.r.shape[0]
        if keep_factors:
            kept[kind.name] = _without_jacobians(res)
        if F == 0:
            if kind.listed(res):
                whitened[kind.name] = np.zeros((0, 3))
            continue
        c, w, s = whiten(kind, res, robust=robust, robust_k=robust_k)
        cost += c
        whitened[kind.name] = w
        cols = np.flatnonzero(np.any(res.H_x != 0.0, axis=(0, 1))) if touched_columns else None
        into = cols if cols is not None or n_cols == P else np.arange(P)     # None: every column
        for lo in range(0, F, CHUNK):
            sl = slice(lo, min(lo + CHUNK, F))
            sc = s[sl][:, :, None]
            X = res.H_x[sl] if cols is None else res.H_x[sl][:, :, cols]
            r, A, X = res.r[sl] * s[sl], res.H_R[sl] * sc, X * sc
            B = None if res.H_R_next is None else res.H_R_next[sl] * sc
            ne.add_rows(res.key[sl], r, A, X, B=B, cols=into)
            if on_kind is not None:
                on_kind(kind, res, sl, r, A, B, X, np.arange(P) if cols is None else cols, ne)
        del res
    if prior is not None:
        cost += add_prior(ne.H_xx, ne.g_x, *prior)
    n = R.shape[0]
    H_ax, H_xx, g_x = ne.H_ax.reshape(3 * n, -1), ne.H_xx, ne.g_x
    if M is not None:
        H_xx = M.T @ H_xx @ M
        H_xx = 0.5 * (H_xx + H_xx.T)
        H_ax, g_x = H_ax @ M, M.T @ g_x
    return LinearSystem(cost=cost, H_aa_diag=ne.H_aa_diag, H_aa_off=ne.H_aa_off, H_ax=H_ax, g_a=ne.g_a.reshape(-1),
                        H_xx=H_xx, g_x=g_x, whitened=whitened, factors=kept if keep_factors else None)


def _without_jacobians(res):
    return type(res)(r=res.r, key=res.key, H_R=None, H_R_next=None, H_x=None, sigma=res.sigma)


def _costs(model, preint, R, x, R_prior, robust, robust_k):
    priors = model.attitude_priors(R, R_priors=np.asarray(R_prior, dtype=float).reshape(-1, 3, 3))
    return priors, [(kind, res) for kind, res in zip(FACTOR_KINDS, residual_list(model, R, preint, x).values())]


def cost(model, preint, R, x, *, R_prior, robust=None, robust_k=3.0):
    """The cost of :func:`linearise` (no calibration prior) at ``(R, x)``, without linearising."""
    priors, kinds = _costs(model, preint, R, x, R_prior, robust, robust_k)
    total = sum(pr.cost for _, pr in priors)
    for kind, res in kinds:
        if res.r.shape[0]:
            total += whiten(kind, res, robust=robust, robust_k=robust_k)[0]
    return total


def cost_by_key(model, preint, R, x, *, R_prior, robust=None, robust_k=3.0):
    """:func:`cost` split by keyframe, (K+1,): each factor's cost (a robust group's loss) on its first keyframe
    (a rotation factor never crosses a segment boundary), each attitude prior's on its own.  Sums to
    :func:`cost` up to rounding."""
    priors, kinds = _costs(model, preint, R, x, R_prior, robust, robust_k)
    out = np.zeros(R.shape[0])
    for key, pr in priors:
        out[key] += pr.cost
    for kind, res in kinds:
        if res.r.shape[0]:
            out += _kind_cost_by_key(kind, res, R.shape[0], robust=robust, robust_k=robust_k)
    return out


__all__ = ["LinearSystem", "linearise", "add_prior", "cost", "cost_by_key", "retract", "CHUNK"]
