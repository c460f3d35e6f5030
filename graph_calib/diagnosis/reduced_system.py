r"""The Gauss-Newton system of an extended model at the current solution, with the attitudes eliminated.

At the solution ``(R_hat, x_hat)`` of the current model, :func:`linearise` linearises
the factors of the model *extended* by the candidates (same prepared record, same
static mask, same alignment; every candidate's parameters zero) once.  With ``J`` the
whitened Jacobian in the keyframe attitudes ``a`` and the calibration ``x`` and ``r``
the whitened residuals, the system is ``H = J^T J + priors``, ``g = J^T r``.  The
attitudes are eliminated (block-tridiagonal: banded Cholesky,
:mod:`graph_calib.model.attitude_elimination`, the joint solver's too), leaving
the :class:`ReducedSystem` ``(A, b)`` in the calibration columns, to which the generic
driver columns (:mod:`graph_calib.diagnosis.drivers`) are appended; a driver column is
its bias column times each factor's mean of the series, accumulated without forming it
(:func:`_driver_blocks`).  The factors are the residual list's: a table reading's and a rotation factor's
bias column is the one after their shared gyro noise is made independent
(:mod:`graph_calib.model.shared_gyro_noise`), which mixes the columns of the readings of one keyframe
interval, each with its own window; so a driver column there is a close stand-in for the series
taken through that map, not the map of each original column (any column of the data alone gives a score
test of the null's level; only the alternative it is most powerful against moves, within a keyframe).  The normal equations are the model's one builder
(:func:`graph_calib.model.normal_equations.linearise`, the solvers' too).  The score tests
(:mod:`graph_calib.diagnosis.score`) work on it; :meth:`ReducedSystem.gauss_newton_step` gives the step of a grown model from it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from graph_calib.diagnosis.drivers import SENSOR_AXES, TIME_SEGMENTS, DriverSums
from graph_calib.model.attitude_elimination import AttitudeSolve
from graph_calib.model.factors import PriorResidual
from graph_calib.model.normal_equations import add_prior, linearise as build
from graph_calib.sensors.params import Layout


@dataclass(frozen=True)
class ReducedSystem:
    """Gauss-Newton system in the calibration columns, attitudes eliminated.

    Shapes: ``Q`` columns (``layout.size`` calibration elements, then the drivers), ``K`` keyframes.

    Attributes
    ----------
    columns : list of str
        Flat parameter element names of the extended layout, then ``driver:<i>``.
    A : ndarray (Q, Q)
        Reduced information (data, plus the priors of the ``null`` columns).
    b : ndarray (Q,)
        Reduced gradient ``J^T r`` (plus the prior gradient of the ``null`` columns).
    null : ndarray of int
        Columns of the current model (layout of the solution).
    layout : Layout
        Extended layout (its elements are the first ``layout.size`` columns).
    prior_sigma : ndarray (layout.size,)
    chi2 : float
        Sum of squared whitened data residuals at the solution.
    dof : int
        Scalar data residuals minus the unknowns of the current model.
    n_drivers : int
        Driver columns (after the calibration columns).
    seconds : float
        Wall time of :func:`linearise`.
    driver_means : ndarray (K, D) or None
        Keyframe means of the driver series (None without the drivers).
    prior : PriorResidual or None
        The calibration prior at the linearisation point, every calibration column (for
        :meth:`gauss_newton_step`).
    attitudes : AttitudeSolve or None
        What the elimination leaves to recover the attitudes' step (for :meth:`gauss_newton_step`).
    factors : dict or None
        ``{kind: Residuals}`` of the linearisation point without their Jacobians (``keep_factors``):
        the current model's residuals, for :func:`graph_calib.diagnosis.residuals.factor_residuals`.
    """

    columns: list[str]
    A: np.ndarray
    b: np.ndarray
    null: np.ndarray
    layout: Layout
    prior_sigma: np.ndarray
    chi2: float
    dof: int
    n_drivers: int
    seconds: float = 0.0
    driver_means: np.ndarray | None = None
    prior: PriorResidual | None = field(default=None, repr=False, compare=False)
    attitudes: AttitudeSolve | None = field(default=None, repr=False, compare=False)
    factors: dict | None = field(default=None, repr=False, compare=False)

    @property
    def variance_factor(self):
        """``s^2 = max(1, chi^2 / dof)``: guards against noise densities that are too optimistic."""
        return max(1.0, self.chi2 / max(self.dof, 1))

    def gauss_newton_step(self, columns):
        """One Gauss-Newton step of the model whose calibration columns are ``columns``, every attitude free.

        The columns of the system left out (the other candidates, the drivers) are held where
        they are (zero).  The priors of ``columns`` outside :attr:`null` are added to the system.
        From the current solution with a candidate's columns added this is the first step of the
        grown model's solve, exactly as a solver takes it (without damping).

        Parameters
        ----------
        columns : ndarray of int
            Calibration columns (of :attr:`layout`) that move; they include :attr:`null`.

        Returns
        -------
        dx : ndarray (layout.size,)
            Step of the calibration, zero outside ``columns``.
        delta : ndarray (K+1, 3)
            Step of each keyframe attitude, rad (right perturbation: ``C_nb Exp(delta)``).
        """
        if self.attitudes is None or self.prior is None:
            raise ValueError("this reduced system keeps no attitude elimination (linearise(..., keep_step=True))")
        cols = np.asarray(columns, dtype=np.int64)
        A = self.A[np.ix_(cols, cols)].copy()
        b = self.b[cols].copy()
        extra = ~np.isin(cols, self.null)
        sub = PriorResidual(r=self.prior.r[cols], H=np.diag(np.diag(self.prior.H)[cols]), sigma=self.prior.sigma[cols])
        add_prior(A, b, sub, np.flatnonzero(extra))
        dxc = -sla.cho_solve(sla.cho_factor(A), b)
        dx = np.zeros(self.A.shape[0])
        dx[cols] = dxc
        delta = -self.attitudes.solve(dx)
        return dx[: self.layout.size], delta.reshape(-1, 3)


def _key_outer_sums(key, W, M, n_keys):
    """``sum over f with key_f = k of W_f M_f^T`` for every ``k``: shape (n_keys, w, s).

    ``key`` (F,) ascending; ``W`` (F, w), ``M`` (F, s).  The factors of each key are laid side by
    side (zero-padded to the most any key holds) and summed by one batched product, without
    forming the F outer products.
    """
    F = key.size
    out = np.zeros((n_keys, W.shape[1], M.shape[1]))
    if F == 0:
        return out
    first = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
    count = np.diff(np.concatenate([first, [F]]))
    pos = np.arange(F) - np.repeat(first, count)
    keys = key[first]
    n = int(count.max())
    Wp = np.zeros((keys.size, n, W.shape[1]))
    Mp = np.zeros((keys.size, n, M.shape[1]))
    grp = np.repeat(np.arange(keys.size), count)
    Wp[grp, pos] = W
    Mp[grp, pos] = M
    out[keys] = np.swapaxes(Wp, 1, 2) @ Mp
    return out


def _block(rows, cols):
    """Index of the block ``rows x cols`` (each a slice with a stop, or an index array) of a matrix."""
    if isinstance(rows, slice) and isinstance(cols, slice):
        return rows, cols

    def idx(a):
        return np.arange(a.start, a.stop) if isinstance(a, slice) else a

    return np.ix_(idx(rows), idx(cols))


def _driver_blocks(Hb, r, A_, B_, M, bi, sd, Xc, key, n_keys):
    """The driver columns' share of one kind of factor, from per-factor driver means.

    A driver column of factor ``f`` is its bias column times the factor's mean of the
    series, ``X_f[:, d] = Hb_f[:, bi_d] M_f[sd_d]``; its products with the other columns
    are therefore products of the bias columns weighted by the means, formed per bias
    axis without building ``X`` (F x 3 x drivers), and its coupling to the attitudes is a
    per-keyframe sum of ``(A_f^T Hb_f) M_f^T`` (:func:`_key_outer_sums`).

    Parameters
    ----------
    Hb : ndarray (F, 3, nb)
        Whitened Jacobian columns of the bias axes the drivers sit on.
    r : ndarray (F, 3)
        Whitened residuals.
    A_, B_ : ndarray (F, 3, 3)
        Whitened Jacobians in the attitudes ``key`` and ``key + 1`` (``B_`` None when absent).
    M : ndarray (F, D)
        Each factor's mean of every driver series.
    bi, sd : ndarray of int (nd,)
        Bias axis (column of ``Hb``) and series (column of ``M``) of each driver touched.
    Xc : ndarray (F, 3, nc)
        Whitened Jacobian in the calibration columns the kind touches.
    key : ndarray of int (F,)
        Keyframe of each factor, ascending.
    n_keys : int
        Keyframe boundaries (K+1).

    Returns
    -------
    DD : ndarray (nd, nd)
        Information among the drivers.
    CD : ndarray (nc, nd)
        Information between the calibration columns and the drivers.
    gD : ndarray (nd,)
        Gradient of the drivers.
    Hax_d : ndarray (K+1, 3, nd)
        Information between the attitudes and the drivers.
    """
    nd = bi.size
    F, _, nb = Hb.shape
    DD = np.zeros((nd, nd))
    CD = np.zeros((Xc.shape[2], nd))
    gD = np.zeros(nd)
    Ms = M[:, sd]                                                # (F, nd): each driver's means, once
    groups = []
    for b in np.unique(bi):
        jb = np.flatnonzero(bi == b)
        # the drivers of one axis are adjacent: a slice, so that its means are a view, not a copy
        sl = slice(int(jb[0]), int(jb[-1]) + 1) if jb.size == jb[-1] - jb[0] + 1 else jb
        groups.append((b, sl))
    for b, jb in groups:
        h = Hb[:, :, b]                                          # (F, 3)
        Mb = Ms[:, jb]                                           # (F, nb_d)
        CD[:, jb] = np.einsum("fic,fi->cf", Xc, h) @ Mb
        gD[jb] = np.einsum("fi,fi->f", h, r) @ Mb
        for b2, jb2 in groups:
            if b2 < b:
                continue
            g = np.einsum("fi,fi->f", h, Hb[:, :, b2])
            blk = (Mb * g[:, None]).T @ Ms[:, jb2]
            DD[_block(jb, jb2)] = blk
            DD[_block(jb2, jb)] = blk.T
    # attitudes: sum over each keyframe's factors of (A_f^T Hb_f)[:, b] M_f[s], then the (b, s) of each driver
    S = _key_outer_sums(key, np.einsum("fji,fjb->fib", A_, Hb).reshape(F, 3 * nb), M, n_keys)
    if B_ is not None:
        S += _key_outer_sums(key + 1, np.einsum("fji,fjb->fib", B_, Hb).reshape(F, 3 * nb), M, n_keys)
    Hax_d = np.stack([S[:, i * nb + bi, sd] for i in range(3)], axis=1)
    return DD, CD, gD, Hax_d


def linearise(model, R, x, *, q_nb0, null_names, drivers=True, n_segments=TIME_SEGMENTS, pre=None, sums=None,
              keep_step=False, keep_factors=False):
    """Linearise ``model`` (an extended layout) at ``(R, x)`` and eliminate the attitudes.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
        Its layout holds the current model's parameters (``null_names``) and the candidates.
    R : ndarray (K+1, 3, 3)
        Attitudes ``C_nb`` at the keyframe boundaries, of the current solution.
    x : ndarray (P,)
        The current solution embedded in ``model.layout`` (candidates zero).
    q_nb0 : ndarray (4,)
        The alignment (prior of the first attitude), as given to the solver.
    null_names : sequence of str
        Parameters of the current model (their priors enter the system).
    drivers : bool
        Append the generic driver columns.
    n_segments : int
        Cubic B-spline functions of the ``time`` driver (when ``sums`` is not given).
    pre : graph_calib.model.preintegration.Preintegrated, optional
        ``model.preintegrate(x)`` when the caller has it already.
    sums : graph_calib.diagnosis.drivers.DriverSums, optional
        The driver sums of ``model``'s record when the caller has them already (they depend on the
        record only: one serves every round of a loop).
    keep_step : bool
        Keep what :meth:`ReducedSystem.gauss_newton_step` needs (the attitudes' elimination,
        ``3 (K+1) x (Q+1)`` numbers).
    keep_factors : bool
        Keep the factors' residuals at ``(R, x)`` (:attr:`ReducedSystem.factors`).

    Returns
    -------
    ReducedSystem, list of Driver
    """
    t0 = time.perf_counter()
    layout = model.layout
    P = layout.size
    K = model.n_keyframes
    if pre is None:
        pre = model.preintegrate(x)
    dlist = []
    if drivers:
        if sums is None:
            sums = DriverSums.of(model, n_segments=n_segments)
        # a driver acts as a bias: none on a triad whose bias the model leaves out (a manifest's [model].exclude)
        dlist = [d for d in sums.drivers if f"{d.axis.split('.')[0]}.bias" in layout]
        axis_col = {}
        for ax in SENSOR_AXES:
            triad, el = ax.split(".")
            if f"{triad}.bias" in layout:
                axis_col[ax] = layout.slice(f"{triad}.bias").start + "xyz".index(el)
        d_bias = np.array([axis_col[d.axis] for d in dlist], dtype=np.int64)
        d_series = np.array([d.series for d in dlist], dtype=np.int64)
    ND = len(dlist)
    k0 = model.record.k0

    def add_drivers(kind, res, sl, r, A_, B_, Xc, nzc, ne):
        # the drivers on the bias axes this kind touches, from each factor's means of the series
        dsel = np.flatnonzero(np.isin(d_bias, nzc))
        if dsel.size == 0:
            return
        key = res.key[sl]
        hi = model.record.reading_sample[sl] + 1 if kind.name == "encoder" else k0[key + 1]
        M = sums.means(k0[key], hi)                                   # (F, series)
        bcols, bi = np.unique(d_bias[dsel], return_inverse=True)
        Hb = Xc[:, :, np.searchsorted(nzc, bcols)]                    # the bias columns (among nzc)
        DD, CD, gD, Hax_d = _driver_blocks(Hb, r, A_, B_, M, bi, d_series[dsel], Xc, key, K + 1)
        dcol = P + dsel
        ne.H_xx[np.ix_(dcol, dcol)] += DD
        ne.H_xx[np.ix_(nzc, dcol)] += CD
        ne.H_xx[np.ix_(dcol, nzc)] += CD.T
        ne.g_x[dcol] += gD
        ne.H_ax[:, :, dcol] += Hax_d

    # only the columns each kind of factor touches (a rotation or encoder factor sees no accelerometer
    # parameter, hence none of the accelerometer drivers); the priors of the current model's columns
    cal_prior = model.calibration_prior(x)
    null_idx = np.concatenate([np.arange(P)[layout.slice(n)] for n in null_names]).astype(np.int64)
    system = build(model, pre, R, x, R_prior=model.segment_priors(q_nb0), n_extra=ND, prior=(cal_prior, null_idx),
                   touched_columns=True, on_kind=add_drivers if drivers else None, keep_factors=keep_factors)
    A, b, att = system.reduce(0.0, definite=False)
    dof = system.n_residuals - 3 * (K + 1) - null_idx.size
    names = layout.element_names() + [f"driver:{i}" for i in range(ND)]
    means = sums.means(k0[:-1], k0[1:]) if drivers else None
    rs = ReducedSystem(columns=names, A=A, b=b, null=null_idx, layout=layout, prior_sigma=cal_prior.sigma,
                       chi2=system.chi2, dof=int(dof), n_drivers=ND, seconds=time.perf_counter() - t0,
                       driver_means=means, prior=cal_prior, attitudes=att if keep_step else None,
                       factors=system.factors)
    return rs, dlist
