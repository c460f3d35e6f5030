r"""Calibration with the iterated, linearised square-root Kalman filter.

Every equation comes from :class:`graph_calib.model.CalibrationModel`: one pass
computes all factors at a linearisation point (attitudes ``R_lin``, calibration
``x_lin``), stacks them into the matrices of a linear Gaussian recursion and
runs :func:`kf_reference.sqrt_kf.run` over the keyframes; a smoother of the
attitude chain given the final calibration (:func:`kf_reference.sqrt_kf.smooth_attitude`)
follows.  Passes repeat with the smoothed trajectory and the final calibration as
the new linearisation point until both stop moving: each pass is one
Gauss-Newton step of the batch problem.  ``docs/kf_reference.md`` gives the
derivation and why the fixed point is the batch (factor-graph) solution.

Segments (``/imu/segment``)
    At the first keyframe of a segment after the first the attitude restarts: the time update into
    it is ``delta = m + L w`` with ``m``, ``L L^T`` the mean and covariance of that segment's
    attitude prior (its alignment), independent of the previous attitude and of the calibration,
    so the calibration state and its covariance are kept while the attitude and its cross
    covariance start again (``B = 0``, ``A = 0``); the smoother's gain through that step is zero.

Factor conventions (``graph_calib.model.Residuals``)
    rotation ``k``: ``0 = r + H_R delta_k + H_R_next delta_{k+1} + H_x dx - w``;
    gravity and encoder: ``0 = r + H_R delta_key + H_x dx + v``, so the filter's
    measurement is ``z = -r`` with row ``h = [H_R, H_x]``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from graph_calib.options import GraphOptions
from graph_calib.sensors.params import Layout
from graph_calib.navigation.rotations import exp_so3, log_so3
from graph_calib.solvers.acceleration import Anderson
from graph_calib.solvers.heading import search_heading
from graph_calib.model.normal_equations import cost_by_key
from graph_calib.model.residual_list import FACTOR_KINDS, MEASUREMENT_KINDS, residual_list, whiten
from graph_calib.solvers.interface import ProgressEvent
from kf_reference import sqrt_kf
from kf_reference.sqrt_kf import ATT

#: The name the filter is registered under (:mod:`graph_calib.solvers.registry`).
SOLVER_NAME = "sqrt-kf"

#: The process (the factors that tie consecutive attitudes: the time update) and the measurement kinds of
#: the model's residual list (the filter's updates), their index the kind code of the innovation series.
PROCESS = next(k for k in FACTOR_KINDS if k.name not in MEASUREMENT_KINDS)
MEASUREMENTS = tuple(k for k in FACTOR_KINDS if k.name in MEASUREMENT_KINDS)
KIND_NAMES = tuple(k.name for k in MEASUREMENTS)
GRAVITY, ENCODER = KIND_NAMES.index("gravity"), KIND_NAMES.index("encoder")


@dataclass(frozen=True)
class PassInfo:
    """Convergence figures of one filter pass.

    Attributes
    ----------
    index : int
        Pass number, from 1.
    max_dx_sigma : float
        Largest ``|dx_hat_i| / sigma_i``: how far the pass moved the calibration, in its sigmas.
    max_attitude_correction : float
        Largest smoothed attitude correction ``|delta_{k|K}|`` over the keyframes, rad.
    max_attitude_correction_sigma : float
        The same in units of its sigma given the calibration (largest per-axis ratio).
    chi2_per_dof : float
        Mean squared normalised innovation over every scalar measurement.
    cost : float
        Half the batch cost at the pass's linearisation point (the factor graph's objective).
    seconds_model : float
        Preintegration and factors.
    seconds_filter : float
        The filter recursion.
    """

    index: int
    max_dx_sigma: float
    max_attitude_correction: float
    max_attitude_correction_sigma: float
    chi2_per_dof: float
    cost: float
    seconds_model: float
    seconds_filter: float


@dataclass(frozen=True)
class FilterResult:
    """What the filter concludes about one experiment.

    Shapes: ``P`` calibration elements, ``K`` keyframes, ``m`` scalar measurements.

    Attributes
    ----------
    layout : graph_calib.sensors.params.Layout
    x : ndarray, shape (P,)
        Calibration estimate, SI.
    covariance : ndarray, shape (P, P)
    t_key : ndarray, shape (K+1,)
        Time of each keyframe boundary, s.
    C_nb : ndarray, shape (K+1, 3, 3)
        Smoothed attitude at each boundary (given every measurement): the final
        linearisation point, the batch solution's attitudes.
    C_nb_filtered : ndarray, shape (K+1, 3, 3)
        Filtered attitude at each boundary (given the measurements up to it; the last one predicted).
    attitude_sigma_filtered : ndarray, shape (K+1, 3)
        One sigma of the filtered attitude error (right perturbation, body axes), rad.
    innovation_t : ndarray, shape (m,)
        Time of each scalar measurement: the keyframe start for gravity, the reading time for encoders.
    innovation_kind : ndarray of int, shape (m,)
        :data:`GRAVITY` or :data:`ENCODER`.
    innovation_axis : ndarray of int, shape (m,)
        Component 0, 1, 2 of the factor's residual (``n`` axes for gravity; the rotation
        vector of the encoder residual).
    innovation : ndarray, shape (m,)
        Normalised innovations ``nu / sqrt(var(nu))`` of the last pass; N(0, 1) for a consistent model.
    passes : tuple of PassInfo
    converged : bool
        Whether the last pass met the tolerances (else ``max_passes`` ended the iteration).
    initial_iterations : int
        Attitude-only iterations of :func:`initial_attitudes` before the first pass.
    """

    layout: Layout
    x: np.ndarray
    covariance: np.ndarray
    t_key: np.ndarray
    C_nb: np.ndarray
    C_nb_filtered: np.ndarray
    attitude_sigma_filtered: np.ndarray
    innovation_t: np.ndarray
    innovation_kind: np.ndarray
    innovation_axis: np.ndarray
    innovation: np.ndarray
    passes: tuple
    converged: bool
    initial_iterations: int = 0

    @property
    def n_passes(self):
        return len(self.passes)

    @property
    def sigma(self):
        """One sigma of every calibration element, shape (P,)."""
        return np.sqrt(np.diag(self.covariance))

    def innovation_series(self):
        """``{kind name: (t (F,), normalised innovations (F, 3))}``, one row per factor, in time order.

        The three components of a factor are consecutive rows of the filter's scalar
        updates (``innovation_axis`` 0, 1, 2), so each kind reshapes to (F, 3).
        """
        out = {}
        for code, name in enumerate(KIND_NAMES):
            m = self.innovation_kind == code
            if not np.any(m):
                continue
            ax = self.innovation_axis[m]
            if ax.size % 3 or np.any(ax.reshape(-1, 3) != np.arange(3)):
                raise ValueError(f"{name} innovations are not grouped in axis triples")
            out[name] = (self.innovation_t[m][::3].copy(), self.innovation[m].reshape(-1, 3).copy())
        return out

    def innovation_stats(self):
        """``{kind name: {"count", "rms", "rms_axis"}}`` of the normalised innovations."""
        return {name: {"count": int(v.size), "rms": float(np.sqrt(np.mean(v**2))),
                       "rms_axis": np.sqrt(np.mean(v**2, axis=0)).tolist()}
                for name, (_, v) in self.innovation_series().items()}


# ---------------------------------------------------------------------------
# one pass
# ---------------------------------------------------------------------------


def _transition(rot, *, K, restarts=()):
    """``B, A, G, c`` of ``delta_{k+1} = B delta_k + A dx + c + G w`` for ``k < K``.

    From the rotation factors (their ``key``), and at a segment boundary (``restarts``: ``(k, mean,
    Ut)`` with ``k + 1`` the first keyframe of a segment and ``mean``, ``Ut`` from
    :func:`_prior_state` of its attitude prior) the restart ``delta_{k+1} = mean + Ut^T w``.
    """
    N_inv = np.linalg.inv(rot.H_R_next)
    P = rot.H_x.shape[2]
    B, A, G, c = np.zeros((K, 3, 3)), np.zeros((K, 3, P)), np.zeros((K, 3, 3)), np.zeros((K, 3))
    k = rot.key
    G[k] = N_inv * rot.sigma[:, None, :]
    B[k] = -N_inv @ rot.H_R
    A[k] = -N_inv @ rot.H_x
    c[k] = -np.einsum("kij,kj->ki", N_inv, rot.r)
    for kr, mean, Ut in restarts:
        c[kr] = mean
        G[kr] = Ut.T
    return B, A, G, c


def _measurements(model, factors):
    """Scalar measurement rows sorted by keyframe: ``key, H, z, sigma, t, kind, axis``.

    The measurement kinds of the model's residual list (every kind but the process, the rotation
    factors), whitened once (:func:`graph_calib.model.residual_list.whiten`); within a keyframe in the
    list's order (gravity, then the encoder readings in time order).
    """
    parts = [(factors[k.name], code, k.times(model), k) for code, k in enumerate(MEASUREMENTS)]
    key = np.concatenate([np.repeat(res.key, 3) for res, _, _, _ in parts])
    dest = np.empty(key.size, dtype=np.int64)
    dest[np.argsort(key, kind="stable")] = np.arange(key.size)        # row of each factor component
    m, n = key.size, 3 + parts[0][0].H_x.shape[2]
    H, z, sig, t_out = np.empty((m, n)), np.empty(m), np.empty(m), np.empty(m)
    kind_out, axis = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    start = 0
    for res, kind, t, k in parts:
        _, _, s = whiten(k, res)
        F3 = 3 * res.r.shape[0]
        d = dest[start:start + F3]
        start += F3
        H[d, :3] = (res.H_R * s[:, :, None]).reshape(F3, 3)
        H[d, 3:] = (res.H_x * s[:, :, None]).reshape(F3, n - 3)
        z[d] = -(res.r * s).reshape(-1)
        sig[d] = 1.0
        t_out[d] = np.repeat(t, 3)
        kind_out[d] = kind
        axis[d] = np.tile(np.arange(3), F3 // 3)
    return np.sort(key, kind="stable"), H, z, sig, t_out, kind_out, axis


@dataclass(frozen=True)
class _Linearised:
    """The linear Gaussian recursion of the factors at one linearisation point (see :mod:`sqrt_kf`)."""

    B: np.ndarray
    A: np.ndarray
    G: np.ndarray
    c: np.ndarray
    H: np.ndarray
    z: np.ndarray
    sigma: np.ndarray
    lo: np.ndarray
    t: np.ndarray
    kind: np.ndarray
    axis: np.ndarray
    s0: np.ndarray
    Ut0: np.ndarray
    cost: float = 0.0      # the batch cost at the linearisation point: the factor graph's objective, x2


def _prior_state(prior):
    """Mean and transposed upper-triangular root of the covariance of a prior residual's variable error.

    A prior residual ``r + H delta`` (:class:`graph_calib.model.factors.PriorResidual`, whitened) is
    linear in ``delta``: ``delta`` has mean ``-H^-1 r`` and covariance ``(H^T H)^-1`` (exactly the
    batch factor's information, however far the linearisation point lies from the prior's centre).
    """
    H_inv = np.linalg.inv(prior.H)
    P = H_inv @ H_inv.T
    L = np.linalg.cholesky(P[::-1, ::-1])       # P = U U^T with U upper triangular: U = flip(chol(flip(P)))
    return -H_inv @ prior.r, L[::-1, ::-1].T


def _linearise(model, preint, R_lin, x_lin, *, R_prior):
    """Every factor at ``(R_lin, x_lin)`` (``preint`` preintegrated at ``x_lin``), as a :class:`_Linearised`.

    ``R_prior`` (S, 3, 3): the segments' alignments (:meth:`CalibrationModel.segment_priors`).
    """
    factors = residual_list(model, R_lin, preint, x_lin)
    rot = factors[PROCESS.name]
    att_priors = model.attitude_priors(R_lin, R_priors=R_prior)
    restarts = [(k - 1, *_prior_state(pr)) for k, pr in att_priors[1:]]
    B, A, G, c = _transition(rot, K=model.n_keyframes, restarts=restarts)
    key, H, z, sig, t, kind, axis = _measurements(model, factors)
    lo = np.searchsorted(key, np.arange(model.n_keyframes + 2)).astype(np.int64)
    CAL = sqrt_kf.cal_slice(x_lin.size)
    att_prior = att_priors[0][1]
    cal_prior = model.calibration_prior(x_lin)
    s0 = np.zeros(sqrt_kf.N_ATT + x_lin.size)
    Ut0 = np.zeros((s0.size, s0.size))
    s0[ATT], Ut0[ATT, ATT] = _prior_state(att_prior)
    s0[CAL], Ut0[CAL, CAL] = _prior_state(cal_prior)
    cost = (2.0 * whiten(PROCESS, rot)[0] + float(np.sum((z / sig) ** 2))
            + 2.0 * (cal_prior.cost + sum(pr.cost for _, pr in att_priors)))
    return _Linearised(B=B, A=A, G=G, c=c, H=H, z=z, sigma=sig, lo=lo, t=t, kind=kind, axis=axis, s0=s0, Ut0=Ut0,
                       cost=cost)


def _smooth_attitudes(lin, dx):
    """Smoothed attitude errors and their sigmas given the calibration error ``dx``, (K+1, 3) each.

    ``E[delta_k | all] = E[delta_k | all, dx = dx_hat]`` because the latter is affine in ``dx``.
    """
    CAL = sqrt_kf.cal_slice(dx.size)
    K = lin.B.shape[0]
    mean, sig = np.empty((K + 1, 3)), np.empty((K + 1, 3))
    sqrt_kf.smooth_attitude(np.ascontiguousarray(lin.Ut0[ATT, ATT]), lin.s0[ATT].copy(), lin.B, lin.G,
                            lin.c + lin.A @ dx, np.ascontiguousarray(lin.H[:, ATT]), lin.z - lin.H[:, CAL] @ dx,
                            lin.sigma, lin.lo, mean, sig)
    return mean, sig


@dataclass(frozen=True)
class _Pass:
    dx: np.ndarray
    cov_x: np.ndarray
    delta_filtered: np.ndarray
    sigma_filtered: np.ndarray
    delta_smoothed: np.ndarray
    sigma_smoothed: np.ndarray
    t: np.ndarray
    kind: np.ndarray
    axis: np.ndarray
    innovation: np.ndarray
    seconds_model: float
    seconds_filter: float
    cost: float = 0.0


def filter_pass(model, R_lin, x_lin, *, R_prior, preint=None):
    """One linearised pass at ``(R_lin, x_lin)``: the filter, then the attitude smoother.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    R_lin : ndarray, shape (K+1, 3, 3)
        Linearisation attitudes ``C_nb`` at the keyframe boundaries.
    x_lin : ndarray, shape (P,)
        Linearisation calibration.
    R_prior : ndarray, shape (S, 3, 3)
        Prior attitude at the first boundary of each segment (the model's attitude prior residuals are
        centred there; the calibration prior is the model's too).
    preint : graph_calib.model.Preintegrated, optional
        The preintegration at ``x_lin``; computed here when not given.

    Returns
    -------
    _Pass
        ``dx`` (the calibration error given every measurement) and its covariance;
        the filtered attitude errors ``delta_filtered`` (K+1, 3) and their sigmas;
        the smoothed ones ``delta_smoothed`` (given every measurement and ``dx``)
        and their sigmas (given ``dx``); the normalised innovations.
    """
    t0 = time.perf_counter()
    if preint is None:
        preint = model.preintegrate(x_lin)
    lin = _linearise(model, preint, R_lin, x_lin, R_prior=R_prior)
    return _run_filter(model, lin, x_lin, seconds_model=time.perf_counter() - t0)


def _run_filter(model, lin, x_lin, *, seconds_model):
    """The square-root filter and the attitude smoother over one linearisation (see :func:`filter_pass`)."""
    t1 = time.perf_counter()
    K = model.n_keyframes
    s, Ut = lin.s0.copy(), lin.Ut0.copy()
    delta_f, sigma_f = np.empty((K + 1, 3)), np.empty((K + 1, 3))
    nu, nu_var = np.empty(lin.z.size), np.empty(lin.z.size)
    sqrt_kf.run(Ut, s, lin.B, lin.A, lin.G, lin.c, lin.H, lin.z, lin.sigma, lin.lo, delta_f, sigma_f, nu, nu_var)
    CAL = sqrt_kf.cal_slice(x_lin.size)
    dx = s[CAL].copy()
    delta_s, sigma_s = _smooth_attitudes(lin, dx)
    t2 = time.perf_counter()
    cov = sqrt_kf.covariance(Ut)[CAL, CAL]
    return _Pass(dx=dx, cov_x=0.5 * (cov + cov.T), delta_filtered=delta_f, sigma_filtered=sigma_f,
                 delta_smoothed=delta_s, sigma_smoothed=sigma_s, t=lin.t, kind=lin.kind, axis=lin.axis,
                 innovation=nu / np.sqrt(nu_var), seconds_model=seconds_model, seconds_filter=t2 - t1,
                 cost=lin.cost)


def initial_attitudes(model, *, q_nb0, preint=None, max_iterations=10, tol_rad=1e-2):
    """Keyframe attitudes that fit the measurements at the prior calibration: the first linearisation point.

    Dead reckoning from ``q_nb0`` with the prior calibration (zero) drifts with the
    uncalibrated gyro errors: by degrees per minute for a consumer MEMS unit, far
    beyond where the factors may be linearised.  This Gauss-Newton iteration over
    the attitudes alone (the smoother of :func:`kf_reference.sqrt_kf.smooth_attitude`,
    calibration held at its prior mean) pulls that trajectory onto the gravity and
    encoder measurements first.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    q_nb0 : array_like, shape (4,) or (S, 4)
        Prior attitude ``q_nb`` (scalar first) at the start of the record (of each segment).
    preint : graph_calib.model.Preintegrated, optional
        The preintegration at the prior calibration; computed here when not given.
    max_iterations : int
    tol_rad : float
        Stop when no keyframe attitude moves by more than this, rad.

    Returns
    -------
    C_nb : ndarray, shape (K+1, 3, 3)
    iterations : int
    """
    R_prior = model.segment_priors(q_nb0)
    x_prior, x_sigma = model.prior()
    if preint is None:
        preint = model.preintegrate(x_prior)
    R = model.propagate(R_prior, preint, x_prior)
    for it in range(1, max_iterations + 1):
        lin = _linearise(model, preint, R, x_prior, R_prior=R_prior)
        delta, _ = _smooth_attitudes(lin, np.zeros_like(x_prior))
        R = R @ exp_so3(delta)
        if np.max(np.linalg.norm(delta, axis=1)) < tol_rad:
            break
    return R, it


# ---------------------------------------------------------------------------
# the iteration
# ---------------------------------------------------------------------------


#: A pass converges only when the step that led to its point lowered the batch cost (the factor graph's
#: objective) by less than this fraction of it: the factor graph's own stopping rule
#: (:attr:`graph_calib.options.GraphOptions.rel_tol`), so that a filter stopped above the graph's cost is
#: not called converged.
COST_REL_TOL = GraphOptions().rel_tol
#: Halvings of a pass's step before it is taken as it is.
MAX_HALVINGS = 8
#: The passes are mixed (Anderson, :mod:`graph_calib.solvers.acceleration`) once a pass moves every
#: calibration element by less than this many of its sigmas (the iteration is then near its fixed point,
#: where it is linear).
ACCELERATE_BELOW_SIGMA = 3.0


class _Mixing:
    """Anderson mixing of the passes in the coordinates ``(x / sigma_x, log(R_ref^T R) / sigma_R)``.

    The reference attitudes and the scales (the sigmas of the pass that started the history) are fixed
    while a history lasts.
    """

    def __init__(self):
        self.acc = Anderson()
        self.ref = None

    def reset(self):
        self.acc.reset()
        self.ref = None

    def _encode(self, x, R):
        R_ref, s_x, s_R = self.ref
        return np.concatenate([x / s_x, (log_so3(np.swapaxes(R_ref, 1, 2) @ R) / s_R).ravel()])

    def next(self, x, R, x_gn, R_gn, *, sigma_x, sigma_R):
        """The mixed next linearisation point from the point ``(x, R)`` and its pass's ``(x_gn, R_gn)``."""
        if self.ref is None:
            self.ref = (R.copy(), sigma_x.copy(), sigma_R.copy())
        u = self._encode(x, R)
        u_new = self.acc.next(u, self._encode(x_gn, R_gn) - u)
        if self.acc.depth < 2:
            return x_gn, R_gn        # one step held: the plain step, exactly
        R_ref, s_x, s_R = self.ref
        P = x.size
        return u_new[:P] * s_x, R_ref @ exp_so3(u_new[P:].reshape(-1, 3) * s_R)

def _keep_or_drop(model, preint, x):
    """``preint`` if it still serves at ``x`` to first order, else None (preintegrate again)."""
    if preint is None or preint.needs_repreintegration(x):
        return None
    return preint


def calibrate(model, *, q_nb0, max_passes=500, x_tol=1e-3, attitude_tol=1e-2, progress=None, initial=None):
    """Calibrate with the iterated square-root filter.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    q_nb0 : array_like, shape (4,) or (S, 4)
        Prior attitude ``q_nb`` (scalar first) at the start of the record, ``t[0] - 1/rate`` (at the
        start of each segment, for a record of ``S`` segments).
    max_passes : int
        Largest number of passes over the record.
    x_tol : float
        Converged when a pass moves every calibration element by less than ``x_tol`` of its sigma ...
    attitude_tol : float
        ... and every smoothed attitude correction is below ``attitude_tol`` of its sigma.
    progress : callable, optional
        Called with a :class:`graph_calib.solvers.interface.ProgressEvent` after each pass.
    initial : tuple (R, x), optional
        First linearisation point, keyframe attitudes (K+1, 3, 3) and calibration (P,), instead of
        :func:`initial_attitudes` at the prior calibration.

    Returns
    -------
    FilterResult
    """
    if max_passes < 1:
        raise ValueError(f"max_passes must be at least 1, not {max_passes}")
    R_prior = model.segment_priors(q_nb0)
    x_prior, x_sigma = model.prior()
    if initial is None:
        x_lin = x_prior.copy()
        preint = model.preintegrate(x_lin)
        R_lin, n_initial = initial_attitudes(model, q_nb0=q_nb0, preint=preint)
    else:
        R_lin = np.asarray(initial[0], dtype=float).copy()
        x_lin = np.asarray(initial[1], dtype=float).copy()
        preint = model.preintegrate(x_lin)
        n_initial = 0
    passes = []
    converged = False
    base = None          # (x, R, cost, dx, delta) of the last pass: the point and its Gauss-Newton step
    tau = 1.0
    mixing = _Mixing()
    mixed = False        # whether the current linearisation point is a mixed (or turned) one
    prev_cost = None     # the batch cost at the previous pass's linearisation point
    # no table readings: the heading is held by the Earth rate alone; searched once the calibration settles
    # (one segment only: graph_calib.solvers.heading)
    heading_pending = initial is None and model.record.reading_t.size == 0 and model.segment_keys.size == 1
    for i in range(1, max_passes + 1):
        # Step control: a pass's Gauss-Newton step is taken whole unless it raises the batch cost (the
        # factor graph's objective, evaluated by the next linearisation at no extra cost); then it is
        # halved, up to MAX_HALVINGS times.  Near the solution the whole step is always taken (the
        # passes stay quadratic); far from it, where an attitude direction is weakly held (the heading
        # of a hand-held unit without a table, known only through the Earth rate), a whole step can
        # overshoot and the passes would oscillate.  The fixed point is unchanged.
        while True:
            t0 = time.perf_counter()
            if preint is None:
                preint = model.preintegrate(x_lin)
            lin = _linearise(model, preint, R_lin, x_lin, R_prior=R_prior)
            if base is None or lin.cost <= base[2] * (1.0 + 1e-12) or tau <= 0.5**MAX_HALVINGS:
                break
            if mixed:
                # a mixed point that raises the cost: forget the history, take the plain step instead
                mixing.reset()
                mixed = False
            else:
                tau *= 0.5
            x_lin = base[0] + tau * base[3]
            R_lin = base[1] @ exp_so3(tau * base[4])
            preint = _keep_or_drop(model, preint, x_lin)
        p = _run_filter(model, lin, x_lin, seconds_model=time.perf_counter() - t0)
        if not (np.all(np.isfinite(p.dx)) and np.all(np.isfinite(p.delta_smoothed))):
            raise FloatingPointError(f"square-root filter pass {i} produced non-finite estimates")
        sig_x = np.sqrt(np.diag(p.cov_x))
        info = PassInfo(
            index=i,
            max_dx_sigma=float(np.max(np.abs(p.dx) / sig_x)) if sig_x.size else 0.0,
            max_attitude_correction=float(np.max(np.linalg.norm(p.delta_smoothed, axis=1))),
            max_attitude_correction_sigma=float(np.max(np.abs(p.delta_smoothed) / p.sigma_smoothed)),
            chi2_per_dof=float(np.mean(p.innovation**2)) if p.innovation.size else 0.0,
            cost=0.5 * p.cost,
            seconds_model=p.seconds_model,
            seconds_filter=p.seconds_filter,
        )
        passes.append(info)
        if progress is not None:
            progress(ProgressEvent(solver=SOLVER_NAME, iteration=i, cost=info.cost, max_step_sigma=info.max_dx_sigma,
                                   chi2_per_dof=info.chi2_per_dof))
        C_filtered = R_lin @ exp_so3(p.delta_filtered)
        base = (x_lin, R_lin, p.cost, p.dx, p.delta_smoothed)
        tau = 1.0
        x_gn = x_lin + p.dx
        R_gn = R_lin @ exp_so3(p.delta_smoothed)
        # converged as the factor graph judges it: the step is small, and the step that led here lowered
        # the batch cost by less than COST_REL_TOL of it (a point above the minimum's cost is not one)
        settled = prev_cost is not None and prev_cost - info.cost < COST_REL_TOL * prev_cost
        prev_cost = info.cost
        if info.max_dx_sigma < x_tol and info.max_attitude_correction_sigma < attitude_tol and settled:
            x_lin, R_lin = x_gn, R_gn        # the plain step from a point it certifies
            converged = True
            break
        if info.max_dx_sigma < ACCELERATE_BELOW_SIGMA:
            x_lin, R_lin = mixing.next(x_lin, R_lin, x_gn, R_gn, sigma_x=sig_x, sigma_R=p.sigma_smoothed)
            mixed = mixing.acc.depth >= 2
        else:
            mixing.reset()
            x_lin, R_lin, mixed = x_gn, R_gn, False
        preint = _keep_or_drop(model, preint, x_lin)
        if heading_pending and info.max_dx_sigma < ACCELERATE_BELOW_SIGMA:
            # the calibration has settled: each segment's heading of least cost (graph_calib.solvers.heading);
            # a turned point that raises the cost is dropped for the plain step, as a mixed one is
            heading_pending = False
            if preint is None:
                preint = model.preintegrate(x_lin)
            R_turned = search_heading(model, lambda R: cost_by_key(model, preint, R, x_lin, R_prior=R_prior), R_lin)
            if R_turned is not None:
                mixing.reset()
                R_lin, mixed = R_turned, True
    return FilterResult(
        layout=model.layout, x=x_lin, covariance=p.cov_x, t_key=model.t_key.copy(), C_nb=R_lin,
        C_nb_filtered=C_filtered, attitude_sigma_filtered=p.sigma_filtered, innovation_t=p.t,
        innovation_kind=p.kind, innovation_axis=p.axis, innovation=p.innovation, passes=tuple(passes),
        converged=converged, initial_iterations=n_initial,
    )

