r"""Score (Lagrange-multiplier) tests through the factor graph.

At the solution ``(R_hat, x_hat)`` of the current model the factors of the
model *extended* by the candidates are linearised once and the attitudes
eliminated (:func:`graph_calib.diagnosis.reduced_system.linearise`), leaving the
reduced system ``(A, b)`` in the calibration columns.  For a candidate ``c``
against the current columns ``theta`` (with their priors)

.. math::

    u_c = b_c - A_{c\theta} A_{\theta\theta}^{-1} b_\theta, \qquad
    S_c = A_{cc} - A_{c\theta} A_{\theta\theta}^{-1} A_{\theta c}, \qquad
    T_c = u_c^T S_c^{-1} u_c / s^2,

which is twice the decrease of the cost in one Gauss-Newton step of the
extended model from ``(R_hat, x_hat, 0)`` minus that of the current model (the
parameters already estimated and every attitude move in the same step), i.e.
the score statistic; ``T_c ~ chi^2(dim c)`` under the hypothesis that the
effect is absent (linear-Gaussian model).  ``s^2 = max(1, chi^2 / dof)`` of the
current fit guards against noise densities that are too optimistic (measured
data).  No prior enters ``S_c``: the test is on the data alone.  A direction of
the candidate's parameter space counts only where the data determine it better
than the grade's prior (``lambda(D S_c D) >= 1`` with ``D`` the prior sigmas);
a candidate with no such direction is skipped as not identifiable.

Because every candidate's columns come from one linearisation of the extended
model, the whole catalogue costs one preintegration per round.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.special import chdtrc, gammaln

from graph_calib.model.normal_equations import add_prior


@dataclass(frozen=True)
class Score:
    """A score test of some columns against a base set.

    Attributes
    ----------
    statistic : float
        ``u^T S^+ u / s^2`` on the identifiable directions.
    dof : int
        Identifiable directions.
    dim : int
        Columns tested.
    estimate, sigma : ndarray (dim,)
        One-step estimate ``-S^+ u`` (on the identifiable directions) and its sigma
        from every direction (very large where a direction is not identifiable), SI.
    sigma_identifiable : ndarray (dim,)
        The sigma from the identifiable directions only (the spread of ``estimate``).
    u, S : ndarray (dim,), (dim, dim)
        The score ``u`` and its information ``S`` (the Schur complement given the base columns), divided by
        the variance factor, so that ``statistic = u^T S^+ u`` on the identifiable directions: what a
        campaign's pooled test of one value common to several experiments sums
        (:mod:`graph_calib.campaign.pooled`).
    """

    statistic: float
    dof: int
    dim: int
    estimate: np.ndarray
    sigma: np.ndarray
    sigma_identifiable: np.ndarray | None = None
    u: np.ndarray | None = None
    S: np.ndarray | None = None

    def p_value(self):
        return float(chdtrc(self.dof, self.statistic)) if self.dof else 1.0     # scipy.stats.chi2.sf

    def log10_p(self):
        """``log10`` of the p-value (finite far into the tail, where the p-value underflows)."""
        return log10_chi2_sf(self.statistic, self.dof)


def log10_chi2_sf(T, k):
    """``log10 P(chi^2_k > T)``; for huge ``T`` the leading term of the asymptotic series."""
    if k <= 0:
        return 0.0
    from scipy import stats        # loaded when used (calibrate's structure tests need none of it)

    v = stats.chi2.logsf(T, k)
    if np.isfinite(v):
        return float(v / np.log(10.0))
    a, z = 0.5 * k, 0.5 * T
    return float(((a - 1.0) * np.log(z) - z - gammaln(a)) / np.log(10.0))


def score_test(A, b, base, test, *, scale=None, min_eig=1e-3, scale_factor=1.0):
    """Score test of columns ``test`` given columns ``base`` in a reduced system ``(A, b)``.

    Parameters
    ----------
    A, b : ndarray (Q, Q), (Q,)
        Reduced information and gradient
        (:class:`~graph_calib.diagnosis.reduced_system.ReducedSystem`), with the priors of
        the ``base`` columns that have one.
    base, test : ndarray of int
        Column indices (``base`` normally ``rs.null`` plus already accepted columns).
    scale : ndarray (len(test),), optional
        Column scales: a direction counts when ``lambda(D S D) >= min_eig`` with ``D = diag(scale)``.
        Default: ``1 / sqrt(diag(A_tt))`` (the fraction of a column's information left
        after the base, ``min_eig`` relative).
    scale_factor : float
        Variance factor ``s^2`` dividing the statistic.

    Returns
    -------
    Score
    """
    base = np.asarray(base, dtype=np.int64)
    test = np.asarray(test, dtype=np.int64)
    Abb = A[np.ix_(base, base)]
    Abt = A[np.ix_(base, test)]
    Att = A[np.ix_(test, test)]
    # the base block may be singular along directions without a prior (drivers in the base)
    cb = sla.cho_factor(Abb + 1e-12 * np.diag(np.diag(Abb)) + 1e-300 * np.eye(base.size), lower=True)
    W = sla.cho_solve(cb, np.column_stack([Abt, b[base]]))
    S = Att - Abt.T @ W[:, :-1]
    u = b[test] - Abt.T @ W[:, -1]
    S = 0.5 * (S + S.T)
    if scale is None:
        d = np.diag(Att)
        scale = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 0.0)
    D = np.asarray(scale, dtype=float)
    lam, V = np.linalg.eigh(D[:, None] * S * D[None, :])
    keep = lam >= min_eig
    du = D * u
    proj = V[:, keep].T @ du
    T = float(np.sum(proj**2 / lam[keep])) / scale_factor
    # one-step estimate and sigma on the identifiable subspace
    Sinv = (V[:, keep] / lam[keep]) @ V[:, keep].T
    est = -D * (Sinv @ du)
    # sigma from every direction: a direction the data do not determine makes it (nearly) infinite
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        inv_lam = np.where(lam > 0, 1.0 / np.where(lam > 0, lam, 1.0), np.inf)
        contrib = np.where(V**2 > 0, V**2 * inv_lam[None, :], 0.0)
        var = D**2 * np.sum(contrib, axis=1) * scale_factor
        var = np.where(np.isnan(var), np.inf, var)
    sig = np.where(np.isfinite(var) & (var > 0), np.sqrt(np.where(np.isfinite(var), var, 0.0)), np.inf)
    sig_id = np.sqrt(D**2 * np.diag(Sinv) * scale_factor)
    return Score(statistic=T, dof=int(np.count_nonzero(keep)), dim=int(test.size), estimate=est, sigma=sig,
                 sigma_identifiable=sig_id, u=u / scale_factor, S=S / scale_factor)


def with_priors(rs, cols):
    """A copy of ``rs.A`` with the prior information of calibration columns ``cols`` added.

    ``rs`` is a :class:`~graph_calib.diagnosis.reduced_system.ReducedSystem`; driver columns
    (beyond ``rs.layout``) have no prior and are left as they are.
    """
    A = rs.A.copy()
    cols = np.asarray([c for c in cols if c < rs.layout.size], dtype=np.int64)
    if cols.size:
        add_prior(A, None, rs.prior, cols)
    return A

