r"""The fit statistic with expectation 1: each measurement kind's chi-square over its redundancy.

At a solution ``(R, x)`` (keyframe attitudes and calibration) the model's factors, whitened, give the
stacked residual ``r`` and Jacobian ``J`` in every unknown: three per keyframe attitude and the ``P``
calibration elements.  With ``N = J^T J`` (priors included as residuals) the whitened hat matrix is
``J N^-1 J^T``; the redundancy number of a residual component is ``r_i = 1 - h_ii`` (``h_ii`` the
diagonal of the hat matrix), and ``sum h_ii`` over every component, priors included, is the number of
unknowns.  A kind's redundancy is the sum of its components' ``r_i``: the share of the fit's degrees of
freedom (measurements minus unknowns) it carries, and ``E[chi2_kind] = redundancy_kind`` when the
noise model is right (engineering-facts.md, "Noise and the fit statistic").

Computed without a dense inverse of the whole system: the attitudes' information ``H_aa`` is block
tridiagonal (:mod:`graph_calib.model.attitude_elimination`), so with ``W = H_aa^-1 H_ax`` and the
calibration's covariance ``S = (H_xx - H_xa W)^-1``

.. math::

    N^{-1} = \begin{bmatrix} Z + W S W^T & -W S \\ -S W^T & S \end{bmatrix}, \qquad
    J N^{-1} J^T = J_a Z J_a^T + (J_a W - J_x) S (J_a W - J_x)^T

where only the diagonal and first off-diagonal 3 x 3 blocks of ``Z = H_aa^-1`` are needed (a factor
touches keyframes ``k`` and ``k+1`` at most): a selected inversion of the block-tridiagonal band,
linear in the number of keyframes.  The attitude priors enter the information with the Jacobian
``I / sigma`` (their ``Jr^-1`` of an alignment error of at most degrees differs from ``I`` by its
square) and are counted among the unknowns' total, not as a kind; the calibration prior is the kind
``prior``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy.linalg import lapack

from graph_calib.model.encoder_noise import FLOORED
from graph_calib.model.factors import encoder_variance
from graph_calib.model.normal_equations import linearise
from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

@dataclass(frozen=True)
class KindFit:
    """One measurement kind's fit at a solution.

    Attributes
    ----------
    count : int
        Factors.
    chi2 : float
        Sum of their squared whitened residuals.
    redundancy : float
        Sum of their components' redundancy numbers ``1 - h_ii``.
    share_redundancy : float or None
        The redundancy numbers weighted by the share of each component's variance that the kind's own variance
        factor scales (:data:`FLOORED`: the floor's share, the gyro term being the rest); None: all of it.
        Förstner's estimate of that factor, the rest of the variance held, is
        ``factor (chi2 - (redundancy - share_redundancy)) / share_redundancy``.
    """

    count: int
    chi2: float
    redundancy: float
    share_redundancy: float = None

    @property
    def chi2_per_redundancy(self):
        return self.chi2 / self.redundancy if self.redundancy > 0 else float("nan")

    def to_json(self):
        """``count``, ``chi2``, ``redundancy``, ``chi2_per_redundancy`` (data-format.md; null when none)."""
        v = self.chi2_per_redundancy
        return {"count": int(self.count), "chi2": float(self.chi2), "redundancy": float(self.redundancy),
                "chi2_per_redundancy": float(v) if np.isfinite(v) else None}


@dataclass(frozen=True)
class FitStatistics:
    """Every kind's :class:`KindFit`, and the check that the hat matrix's trace is the unknowns' number.

    Attributes
    ----------
    kinds : dict of str to KindFit
        ``rotation``, ``gravity``, ``encoder`` (when the record has valid readings) and ``prior``.
    components : dict of str to KindFit
        The variance components' own figures (:mod:`graph_calib.solvers.variance`): each component's chi-square
        and redundancy summed with the share of every residual component's variance that it makes (Förstner's
        estimate of its factor is ``chi2 / redundancy`` of these).  ``rotation``: the gyro's noise, all of a
        rotation factor and a table reading's gyro term; ``encoder``: the readings' own noise; ``gravity``: all
        of a gravity factor.  Their ``count`` is of the residual components that carry a share.
    n_unknowns : int
        ``3 (K+1) + P``.
    trace : float
        ``sum h_ii`` over every residual component, attitude priors included (``n_unknowns`` when the
        system has full rank).
    """

    kinds: dict
    n_unknowns: int
    trace: float
    components: dict = None


@numba.njit(cache=True)
def _selected_inverse(D, B):
    """Diagonal and super-diagonal 3 x 3 blocks of the inverse of a symmetric block-tridiagonal matrix.

    ``D`` (n, 3, 3) diagonal blocks, ``B`` (n-1, 3, 3) blocks ``(k, k+1)``.  Block LDL^T forward, then the
    backward recursion ``Z_{k,k+1} = -S_k^-1 B_k Z_{k+1,k+1}``,
    ``Z_kk = S_k^-1 + S_k^-1 B_k Z_{k+1,k+1} B_k^T S_k^-1``.
    """
    n = D.shape[0]
    S_inv = np.empty_like(D)
    S_inv[0] = np.linalg.inv(D[0])
    for k in range(1, n):
        S = D[k] - B[k - 1].T @ S_inv[k - 1] @ B[k - 1]
        S_inv[k] = np.linalg.inv(0.5 * (S + S.T))
    Zd = np.empty_like(D)
    Zo = np.empty_like(B)
    Zd[n - 1] = S_inv[n - 1]
    for k in range(n - 2, -1, -1):
        G = S_inv[k] @ B[k]
        Zo[k] = -G @ Zd[k + 1]
        Zd[k] = S_inv[k] + G @ Zd[k + 1] @ G.T
    return Zd, Zo


def fit_statistics(model, attitudes, x):
    """Each kind's count, chi-square and redundancy at the solution ``(attitudes, x)``.

    The information is the one builder's (:func:`graph_calib.model.normal_equations.linearise`: the residual
    list, its one whitening, the priors as the residuals they are; the attitude priors taken at the solution's
    own first-keyframe attitudes, whose Jacobian is then ``I / sigma``), its Schur complement the one
    elimination (:meth:`~graph_calib.model.normal_equations.LinearSystem.reduce`).

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    attitudes : ndarray, shape (K+1, 3, 3)
        Keyframe attitudes ``C_nb`` of the solution.
    x : ndarray, shape (P,)
        Calibration of the solution.

    Returns
    -------
    FitStatistics
        With, for a record whose moving keyframes have their own gravity sigma (``moving_sigma``), the
        pseudo-kind :data:`MOVING`: those keyframes' gravity factors again, on their own; and for a record whose
        readings have floored components, the pseudo-kind :data:`FLOORED`: those components again, on their own.
    """
    R = np.asarray(attitudes, dtype=float)
    x = np.asarray(x, dtype=float)
    P = model.layout.size
    n_keys = R.shape[0]
    rows = {}

    moving = ~np.asarray(model.record.static_key, dtype=bool) if model.options.moving_sigma is not None else None
    floored = None
    if model.record.has_valid_readings:
        # each reading component's own variance and its floor (graph_calib.model.factors.encoder_variance): after
        # the decorrelation a component's variance is those and the gyro's noise the earlier readings left
        floored = model.record.encoder_noise_frame(model.noise.encoder).floored
        parts = encoder_variance(model.record, model.noise)
        floor_var, own_var = parts.floor, parts.own + parts.floor

    still_share = model.still_share() if model.still_keys.size else None

    def shares_of(kind, res, sl):
        """``{component: (F, 3) share of each residual component's variance}`` of a block of ``kind``."""
        if kind.name == "still":
            # a rest's measurement row (graph_calib.model.still_fusion): the gyro's noise over the keyframe, and the
            # still factor's own small part
            c = np.broadcast_to(still_share[sl][:, None], res.r[sl].shape)
            return {"rotation": 1.0 - c, "still": c}
        if kind.name != "encoder":
            return {kind.name: 1.0}
        s2 = res.sigma[sl] ** 2
        own = np.clip(own_var[sl] / s2, 0.0, 1.0)
        fl = np.clip(floor_var[sl] / s2, 0.0, own)
        return {"rotation": 1.0 - own, "encoder": own - fl}

    def keep_rows(kind, res, sl, r, A, B, X, cols, ne):
        # a weightless row (sigma infinite: a guided turn's two-row tilt in a three-row factor) is no measurement
        weighted = np.isfinite(res.sigma[sl])
        rows.setdefault(kind.name, []).append((r, res.key[sl], A, B, X, None if weighted.all() else weighted,
                                               shares_of(kind, res, sl)))
        if kind.name == "gravity" and moving is not None:
            # the moving keyframes' gravity factors again, on their own (their sigma is moving_sigma's)
            m = moving[res.key[sl]]
            if np.any(m):
                rows.setdefault(MOVING, []).append((r[m], res.key[sl][m], A[m], None if B is None else B[m], X[m],
                                                    None, None))
        if kind.name == "encoder" and floored is not None:
            # the readings' floored components again, on their own (the decorrelation's unit-lower-triangular
            # whitening keeps each component's place: component j stays the reading's principal axis j)
            m = floored[sl]
            f = np.any(m, axis=1)
            if np.any(f):
                share = np.clip(floor_var[sl][f] / res.sigma[sl][f] ** 2, 0.0, 1.0)
                rows.setdefault(FLOORED, []).append((r[f], res.key[sl][f], A[f], None, X[f], m[f],
                                                     {FLOORED: share}))

    prior = model.calibration_prior(x)
    system = linearise(model, model.preintegrate(x), R, x, R_prior=R[np.asarray(model.segment_keys, dtype=np.int64)],
                       prior=(prior, np.arange(P)), on_kind=keep_rows)
    schur, _, att = system.reduce(0.0, definite=False)
    if att.chol is not None:
        W, info = lapack.dtbtrs(att.chol, np.asfortranarray(att.Y[:, :P]), uplo="L", trans="T")
    else:
        W = att.Y[:, :P]
    W = np.asarray(W).reshape(n_keys, 3, P)
    S = np.linalg.inv(schur)
    S = 0.5 * (S + S.T)
    Zd, Zo = _selected_inverse(np.ascontiguousarray(system.H_aa_diag),
                               np.ascontiguousarray(system.H_aa_off) if n_keys > 1 else np.zeros((0, 3, 3)))
    w, U = np.linalg.eigh(S)
    L = U * np.sqrt(np.maximum(w, 0.0))          # S = L L^T
    kinds = {}
    components = {}
    trace = 0.0
    for name, blocks in rows.items():
        chi2 = redundancy = share_redundancy = 0.0
        count = 0
        for r, key, A, B, X, mask, shares in blocks:
            V = A @ W[key] - X
            h = np.einsum("fij,fjl,fil->fi", A, Zd[key], A)
            if B is not None:
                V += B @ W[key + 1]
                h += 2.0 * np.einsum("fij,fjl,fil->fi", A, Zo[key], B)
                h += np.einsum("fij,fjl,fil->fi", B, Zd[key + 1], B)
            h += np.sum((V @ L) ** 2, axis=2)
            if name not in PSEUDO_KINDS:          # counted once, in their kind
                trace += float(h.sum())
            if mask is not None:                  # only the components of the pseudo-kind
                r, h = np.where(mask, r, 0.0), np.where(mask, h, 1.0)
            chi2 += float(np.sum(r**2))
            redundancy += float(np.sum(1.0 - h))
            count += int(r.shape[0] if mask is None or name not in PSEUDO_KINDS else np.count_nonzero(mask))
            if name == FLOORED:
                share_redundancy += float(np.sum((1.0 - h) * shares[FLOORED]))
            elif name not in PSEUDO_KINDS:
                for comp, c in shares.items():
                    c = np.broadcast_to(c, r.shape)
                    got = components.get(comp, (0, 0.0, 0.0))
                    components[comp] = (got[0] + int(np.count_nonzero(c)), got[1] + float(np.sum(c * r**2)),
                                        got[2] + float(np.sum(c * (1.0 - h))))
        kinds[name] = KindFit(count=count, chi2=chi2, redundancy=redundancy,
                              share_redundancy=share_redundancy if name == FLOORED else None)
    h_prior = np.diag(S) * np.diag(prior.H) ** 2
    trace += float(h_prior.sum())
    s_att = float(model.initial_attitude_sigma)
    for k in model.segment_keys:
        trace += float(np.trace(Zd[int(k)] + W[int(k)] @ S @ W[int(k)].T)) / s_att**2
    kinds["prior"] = KindFit(count=P, chi2=float(prior.r @ prior.r), redundancy=float(np.sum(1.0 - h_prior)))
    return FitStatistics(kinds=kinds, n_unknowns=3 * n_keys + P, trace=trace,
                         components={k: KindFit(count=n, chi2=c, redundancy=v) for k, (n, c, v) in components.items()})


#: A pseudo-kind of :func:`fit_statistics`: the gravity factors of the moving keyframes (also counted in
#: ``"gravity"``), whose sigma is ``ModelOptions.moving_sigma`` (:mod:`graph_calib.solvers.variance`).
MOVING = "gravity.moving"


def static_gravity(kinds):
    """The gravity factors of the static keyframes, :class:`KindFit` (None when the moving ones are not apart).

    ``kinds`` is :attr:`FitStatistics.kinds`.  Where the moving keyframes' gravity factors have a sigma of their
    own (:data:`MOVING`: ``ModelOptions.moving_sigma``, a guess or estimated), only the static keyframes' factors
    have the identified accelerometer noise that the gravity kind's variance factor scales and the verdict
    judges: with the guess of 1 m/s^2 the moving factors' chi-square is about nothing while each keeps a
    redundancy of nearly 3, and counted in they would drag the kind's ``chi2 / redundancy`` towards 0 (the
    Xsens session: 0.33 over all, 1.00 over the static keyframes).
    """
    g, m = kinds.get("gravity"), kinds.get(MOVING)
    if g is None or m is None:
        return None
    return KindFit(count=g.count - m.count, chi2=g.chi2 - m.chi2, redundancy=g.redundancy - m.redundancy)
#: The other pseudo-kinds: the table readings' floored components (also counted in ``"encoder"``; their count
#: is of components, not of readings), whose floor has its own variance factor.
PSEUDO_KINDS = (MOVING, FLOORED)

__all__ = ["KindFit", "FitStatistics", "fit_statistics", "static_gravity", "MOVING", "FLOORED", "PSEUDO_KINDS"]
