r"""The Gauss-Newton system of an extended model at the current solution, with the attitudes eliminated.

At the solution ``(R_hat, x_hat)`` of the current model, :func:`linearise` linearises
the factors of the model *extended* by the candidates (same prepared record, same
static mask, same alignment; every candidate's parameters zero) once.  With ``J`` the
whitened Jacobian in the keyframe attitudes ``a`` and the calibration ``x`` and ``r``
the whitened residuals, the system is ``H = J^T J + priors``, ``g = J^T r``.  The
attitudes are eliminated (block-tridiagonal, sparse LU), leaving the
:class:`ReducedSystem` ``(A, b)`` in the calibration columns, to which the generic
driver columns (:mod:`graph_calib.diagnosis.drivers`) are appended.  The score tests
(:mod:`graph_calib.diagnosis.score`) work on it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from graph_calib.diagnosis.drivers import (
    SENSOR_AXES,
    TIME_SEGMENTS,
    cumulative_sums,
    driver_series,
    interval_means,
)
from graph_calib.params import Layout


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

    @property
    def variance_factor(self):
        """``s^2 = max(1, chi^2 / dof)``: guards against noise densities that are too optimistic."""
        return max(1.0, self.chi2 / max(self.dof, 1))


def _add_at(target, keys, values):
    """``target[keys] += values`` for keys in ascending order (duplicates summed)."""
    if keys.size == 0:
        return
    if keys.size == 1 or np.all(keys[1:] > keys[:-1]):
        target[keys] += values
        return
    starts = np.concatenate([[0], np.flatnonzero(np.diff(keys)) + 1])
    target[keys[starts]] += np.add.reduceat(values, starts, axis=0)


def linearise(model, R, x, *, q_nb0, null_names, drivers=True, n_segments=TIME_SEGMENTS, chunk=4096, pre=None):
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
        Cubic B-spline functions of the ``time`` driver.
    chunk : int
        Factors accumulated at a time (bounds the memory of the driver columns).
    pre : graph_calib.model.preintegration.Preintegrated, optional
        ``model.preintegrate(x)`` when the caller has it already.

    Returns
    -------
    ReducedSystem, list of Driver
    """
    t0 = time.perf_counter()
    layout = model.layout
    P = layout.size
    K = model.n_keyframes
    na = 3 * (K + 1)
    if pre is None:
        pre = model.preintegrate(x)
    kinds = (
        ("rotation", model.rotation_factors(R, pre, x)),
        ("gravity", model.gravity_factors(R, pre, x)),
        ("encoder", model.encoder_factors(R, pre, x)),
    )
    dlist = []
    if drivers:
        Phi, dlist = driver_series(model, n_segments=n_segments)
        Phi_cs = cumulative_sums(Phi)
        del Phi
        axis_col = {}
        for i, ax in enumerate(SENSOR_AXES):
            triad, el = ax.split(".")
            axis_col[ax] = layout.slice(f"{triad}.bias").start + "xyz".index(el)
        d_bias = np.array([axis_col[d.axis] for d in dlist], dtype=np.int64)
        d_series = np.array([d.series for d in dlist], dtype=np.int64)
    ND = len(dlist)
    Q = P + ND
    # block-tridiagonal attitude information and the coupling to the calibration
    Hdiag = np.zeros((K + 1, 3, 3))
    Hoff = np.zeros((K, 3, 3))            # block (k, k+1)
    Hax = np.zeros((K + 1, 3, Q))
    Hxx = np.zeros((Q, Q))
    ga = np.zeros((K + 1, 3))
    gx = np.zeros(Q)
    chi2 = 0.0
    m_data = 0
    k0 = model.record.k0
    for kind, res in kinds:
        F = res.r.shape[0]
        if F == 0:
            continue
        r, HR, HRn, Hx = res.whitened_system()
        chi2 += float(np.sum(r**2))
        m_data += r.size
        key = res.key
        # only the columns this kind of factor touches (a rotation or encoder factor sees no accelerometer
        # parameter, hence none of the accelerometer drivers): the columns left out are exactly zero
        nzc = np.flatnonzero(np.any(Hx != 0.0, axis=(0, 1)))
        if drivers:
            lo = k0[key]
            if kind == "encoder":
                hi = model.record.reading_sample + 1
            else:
                hi = k0[key + 1]
            dsel = np.flatnonzero(np.isin(d_bias, nzc))
            cols = np.concatenate([nzc, P + dsel])
        else:
            cols = nzc
        nc = cols.size
        Hax_k = np.zeros((K + 1, 3, nc))
        for a in range(0, F, chunk):
            sl = slice(a, min(F, a + chunk))
            Hx_c = Hx[sl]
            X = Hx_c[:, :, nzc]
            if drivers:
                means = interval_means(Phi_cs, lo[sl], hi[sl])           # (f, series)
                XD = Hx_c[:, :, d_bias[dsel]] * means[:, None, d_series[dsel]]      # (f, 3, drivers)
                X = np.concatenate([X, XD], axis=2)
            kk = key[sl]
            A_ = HR[sl]
            rr = r[sl]
            At = np.swapaxes(A_, 1, 2)
            _add_at(Hdiag, kk, At @ A_)
            _add_at(Hax_k, kk, At @ X)
            _add_at(ga, kk, np.einsum("fji,fj->fi", A_, rr))
            if HRn is not None:
                B_ = HRn[sl]
                Bt = np.swapaxes(B_, 1, 2)
                _add_at(Hdiag, kk + 1, Bt @ B_)
                _add_at(Hoff, kk, At @ B_)
                _add_at(Hax_k, kk + 1, Bt @ X)
                _add_at(ga, kk + 1, np.einsum("fji,fj->fi", B_, rr))
            Xf = X.reshape(-1, nc)
            Hxx[np.ix_(cols, cols)] += Xf.T @ Xf
            gx[cols] += Xf.T @ rr.reshape(-1)
        Hax[:, :, cols] += Hax_k
    # priors of the current model's calibration columns
    cal_prior = model.calibration_prior(x)
    x_sigma = cal_prior.sigma
    null_idx = np.concatenate([np.arange(P)[layout.slice(n)] for n in null_names]).astype(np.int64)
    h = np.diag(cal_prior.H)[null_idx]
    Hxx[null_idx, null_idx] += h**2
    gx[null_idx] += h * cal_prior.r[null_idx]
    # attitude prior on the first keyframe (as factor_graph.build_graph)
    # (the alignment prior: its residual at the solution is part of the current fit)
    # (one per segment of a record cut together, /imu/segment)
    for k, att_prior in model.attitude_priors(R, R_priors=model.segment_priors(q_nb0)):
        Hdiag[k] += att_prior.H.T @ att_prior.H
        ga[k] += att_prior.H.T @ att_prior.r
    # eliminate the attitudes
    base = np.arange(3)
    br, bc = np.repeat(base, 3), np.tile(base, 3)          # a 3 x 3 block, row-major
    kd = 3 * np.arange(K + 1)[:, None]
    ko = 3 * np.arange(K)[:, None]
    rows = np.concatenate([(kd + br).ravel(), (ko + br).ravel(), (ko + 3 + br).ravel()])
    cols = np.concatenate([(kd + bc).ravel(), (ko + 3 + bc).ravel(), (ko + bc).ravel()])
    vals = np.concatenate([Hdiag.ravel(), Hoff.ravel(), np.swapaxes(Hoff, 1, 2).ravel()])
    Haa = sp.csc_matrix((vals, (rows, cols)), shape=(na, na))
    lu = spla.splu(Haa)
    rhs = np.concatenate([Hax.reshape(na, Q), ga.reshape(na, 1)], axis=1)
    sol = lu.solve(rhs)
    Hax2 = Hax.reshape(na, Q)
    A = Hxx - Hax2.T @ sol[:, :Q]
    b = gx - Hax2.T @ sol[:, Q]
    A = 0.5 * (A + A.T)
    dof = m_data - na - null_idx.size
    names = layout.element_names() + [f"driver:{i}" for i in range(ND)]
    means = interval_means(Phi_cs, k0[:-1], k0[1:]) if drivers else None
    rs = ReducedSystem(columns=names, A=A, b=b, null=null_idx, layout=layout, prior_sigma=x_sigma,
                       chi2=chi2, dof=int(dof), n_drivers=ND, seconds=time.perf_counter() - t0,
                       driver_means=means)
    return rs, dlist

