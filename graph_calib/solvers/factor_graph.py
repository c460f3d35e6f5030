"""The factor-graph batch calibrator: GTSAM over the shared model.

Variables: a ``Rot3`` ``X(k)`` at every keyframe boundary and the calibration
vector ``C(0)``.  Factors, all ``gtsam.CustomFactor`` whose residuals and
Jacobians come from :class:`graph_calib.model.CalibrationModel`:

- a calibrated rotation preintegration factor ``(X(k), X(k+1), C(0))`` per keyframe,
- a gravity factor ``(X(k), C(0))`` per keyframe,
- an encoder factor ``(X(k), C(0))`` per keyframe holding that keyframe's valid
  table readings (stacked, 3 rows per reading),
- priors on ``X(0)`` (the alignment) and ``C(0)`` (the grade's priors).

A record cut into segments (``/imu/segment``) has no rotation factor from the last keyframe of a
segment to the first of the next, and a prior on the first keyframe of every segment (its own
alignment): :attr:`CalibrationModel.segment_keys`.

Python factors are slow when GTSAM's own optimiser calls them
(``shared/notes/engineering-facts.md``), so the Levenberg-Marquardt loop is our
own.  Each iteration linearises the graph's factors vectorised (the model's
residuals and Jacobians of every factor of a kind in one call) with the attitude
chain eliminated by a banded Cholesky (:mod:`graph_calib.solvers.reduced`, as
GTSAM's elimination of the chain does), and GTSAM solves the reduced graph on
``C(0)``: that factor, the calibration prior and the damping.  The cost of a
point is the graph's error evaluated from the same vectorised residuals.  The
nonlinear graph itself (the factors as ``CustomFactor`` callbacks reading a
cache of that evaluation) gives the marginal covariance at the solution; tests
check the reduced step and cost against its own linearisation and error.  The
preintegration is redone when the calibration moves too far from its
linearisation point.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial

import gtsam
import numpy as np
from gtsam.symbol_shorthand import C, X
from threadpoolctl import threadpool_limits

from graph_calib.options import GraphOptions
from graph_calib.sensors.params import Layout
from graph_calib.navigation.rotations import exp_so3, log_so3
from graph_calib.solvers import reduced
from graph_calib.solvers.acceleration import Anderson
from graph_calib.solvers.heading import search_heading
from graph_calib.solvers.interface import WHITENED_RESIDUAL, ProgressEvent, ResidualSeries, SolverOutput


@dataclass(frozen=True)
class GraphResult:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    x : ndarray (P,)
        Calibration estimate (SI, ``layout`` order).
    covariance : ndarray (P, P)
        Its marginal covariance.
    layout : graph_calib.sensors.params.Layout
    attitudes : ndarray (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.
    residuals : dict
        Whitened residual series per factor kind: ``{kind: (times (F,), whitened (F, 3))}``.
    iterations : int
    cost_history : list of float
        The graph's error (half the sum of squared whitened residuals) after each iteration.
    seconds : float
    converged : bool
        Whether a stopping rule ended the iterations (else ``max_iterations`` did).
    """

    x: np.ndarray
    covariance: np.ndarray
    layout: Layout
    attitudes: np.ndarray
    residuals: dict
    iterations: int
    cost_history: list = field(default_factory=list)
    seconds: float = 0.0
    converged: bool = False


class _Cache:
    """Vectorised evaluation of every factor at one set of values, for the callbacks of :func:`build_graph`.

    The first callback of a call into GTSAM (a linearisation, an error, the marginals) evaluates every
    factor of every kind at once (:meth:`ensure`), the others read the cache; :meth:`invalidate` before
    each call.  (Comparing the values in every callback, as a guard, cost a third of the solve: 400,000
    comparisons on the 1.5 h record's diagnosis.)
    """

    def __init__(self, model, preint):
        self.model = model
        self.preint = preint
        self.K = model.n_keyframes
        self.R = None
        self.x = None
        self._x_keys = [X(k) for k in range(self.K + 1)]

    def invalidate(self):
        """Forget the evaluation: the next callback evaluates at the values GTSAM then hands over."""
        self.R = None

    def ensure(self, values):
        """Make sure the cache holds the factors at ``values`` (evaluated once per call into GTSAM)."""
        if self.R is None:
            R = np.array([values.atRot3(k).matrix() for k in self._x_keys]).reshape(self.K + 1, 3, 3)
            self.evaluate(R, np.asarray(values.atVector(C(0)), dtype=float))

    def evaluate(self, R, x):
        m = self.model
        self.R, self.x = R, x
        self.rot = m.rotation_factors(R, self.preint, x)
        self.grav = m.gravity_factors(R, self.preint, x)
        self.enc = m.encoder_factors(R, self.preint, x)


def _rotation_error(cache, k, this, values, H):
    cache.ensure(values)
    f = cache.rot
    if H is not None:
        H[0] = f.H_R[k]
        H[1] = f.H_R_next[k]
        H[2] = f.H_x[k]
    return f.r[k]


def _gravity_error(cache, k, this, values, H):
    cache.ensure(values)
    f = cache.grav
    if H is not None:
        H[0] = f.H_R[k]
        H[1] = f.H_x[k]
    return f.r[k]


def _encoder_error(cache, k, lo, hi, this, values, H):
    cache.ensure(values)
    f = cache.enc
    if H is not None:
        H[0] = f.H_R[lo:hi].reshape(-1, 3)
        H[1] = f.H_x[lo:hi].reshape(-1, f.H_x.shape[2])
    return f.r[lo:hi].reshape(-1)


def _noise(sigmas, robust, k):
    base = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))
    if robust is None:
        return base
    est = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy}[robust]
    return gtsam.noiseModel.Robust.Create(est.Create(k), base)


def build_graph(model, cache, *, R_prior, robust=None, robust_k=3.0):
    """The nonlinear factor graph of ``model`` (callbacks bound to ``cache``).

    The priors are the model's (:meth:`CalibrationModel.attitude_prior`, :meth:`CalibrationModel.calibration_prior`:
    the alignment with ``initial_attitude_sigma``, the grade's priors), posted as GTSAM's native prior
    factors: their error and Jacobians are the model's prior residuals (tests/solvers/test_factor_graph.py checks
    it), computed in C++, and they keep the graph's iterations bit for bit what they were.
    """
    graph = gtsam.NonlinearFactorGraph()
    K = model.n_keyframes
    x_prior, x_sigma = model.prior()
    for k, Rp in zip(model.segment_keys, np.asarray(R_prior, dtype=float).reshape(-1, 3, 3)):
        graph.add(gtsam.PriorFactorRot3(X(int(k)), gtsam.Rot3(Rp),
                                        gtsam.noiseModel.Isotropic.Sigma(3, model.initial_attitude_sigma)))
    graph.add(gtsam.PriorFactorVector(C(0), x_prior, gtsam.noiseModel.Diagonal.Sigmas(x_sigma)))
    rot_sigma = cache.rot.sigma
    grav_sigma = cache.grav.sigma
    rot_row = {k: i for i, k in enumerate(cache.rot.key.tolist())}   # every keyframe but the last of each segment
    for k in range(K):
        if k in rot_row:
            i = rot_row[k]
            graph.add(gtsam.CustomFactor(gtsam.noiseModel.Diagonal.Sigmas(rot_sigma[i]), [X(k), X(k + 1), C(0)],
                                         partial(_rotation_error, cache, i)))
        graph.add(gtsam.CustomFactor(_noise(grav_sigma[k], robust, robust_k), [X(k), C(0)],
                                     partial(_gravity_error, cache, k)))
    keys = cache.enc.key
    if keys.size:
        bounds = np.flatnonzero(np.diff(keys)) + 1
        starts = np.concatenate([[0], bounds])
        ends = np.concatenate([bounds, [keys.size]])
        for lo, hi in zip(starts, ends):
            k = int(keys[lo])
            # GTSAM's robust loss weighs a factor by the norm of its whole whitened residual: a factor of
            # m stacked readings (norm about sqrt(3 m) at pure noise) gets the threshold k sqrt(m), so
            # it is down-weighted no sooner than one reading would be
            k_m = robust_k * np.sqrt(hi - lo)
            graph.add(gtsam.CustomFactor(_noise(cache.enc.sigma[lo:hi].reshape(-1), robust, k_m),
                                         [X(k), C(0)], partial(_encoder_error, cache, k, int(lo), int(hi))))
    return graph


def _values(R, x):
    v = gtsam.Values()
    for k in range(R.shape[0]):
        v.insert(X(k), gtsam.Rot3(R[k]))
    v.insert(C(0), np.asarray(x, dtype=float))
    return v


def _damped(gfg, values_keys, lam, dims):
    damped = gtsam.GaussianFactorGraph()
    damped.push_back(gfg)
    s = np.sqrt(lam)
    for key, d in zip(values_keys, dims):
        damped.add(gtsam.JacobianFactor(key, s * np.eye(d), np.zeros(d), gtsam.noiseModel.Unit.Create(d)))
    return damped


def marginal_covariance(graph, values, keys):
    """Joint marginal covariance of the vector variables ``keys`` at ``values``, (sum of dims, same).

    GTSAM's ``Marginals`` first.  Its Cholesky calls a system indeterminate when a direction is held
    a billion times more loosely than the rest: the heading of a short segment of a record cut
    together (``/imu/segment``), known only through its prior (pi for consumer MEMS) against rotation
    factors of 1e8 in information, or a joint campaign of short subranges.  Then the same linearised
    system is solved as the diagnosis does (``graph_calib.diagnosis.reduced_system``): every other
    variable (the attitudes) eliminated with a sparse LU of its block, the information of ``keys`` the
    Schur complement, inverted.
    """
    keys = list(keys)
    try:
        m = gtsam.Marginals(graph, values)
        if len(keys) == 1:
            return np.asarray(m.marginalCovariance(keys[0]))
        jm = m.jointMarginalCovariance(gtsam.KeyVector(keys))
        return np.block([[np.asarray(jm.at(a, b)) for b in keys] for a in keys])
    except RuntimeError:
        pass
    # scipy.sparse only here, in the rare fallback: its import is 0.05 s of every calibrate's start otherwise
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    ijv = np.asarray(graph.linearize(values).sparseJacobian_())
    i, j, v = ijv[0].astype(np.int64) - 1, ijv[1].astype(np.int64) - 1, ijv[2]
    # sparseJacobian_ orders the columns by key (GTSAM's KeySet); its last column is the right-hand side
    all_keys = sorted(int(k) for k in values.keys())
    dims = {k: (3 if values.exists(k) and _is_rot(values, k) else values.atVector(k).size) for k in all_keys}
    start, offset = {}, 0
    for k in all_keys:
        start[k] = offset
        offset += dims[k]
    keep = j < offset
    A = sp.csc_matrix((v[keep], (i[keep], j[keep])), shape=(int(i.max()) + 1, offset))
    H = (A.T @ A).tocsc()
    sel = np.concatenate([np.arange(start[int(k)], start[int(k)] + dims[int(k)]) for k in keys])
    rest = np.setdiff1d(np.arange(offset), sel)
    Hss = H[sel][:, sel].toarray()
    Hrs = H[rest][:, sel].toarray()
    Hrr = H[rest][:, rest].tocsc()
    info = Hss - Hrs.T @ spla.splu(Hrr).solve(Hrs)
    return np.linalg.inv(0.5 * (info + info.T))


def _is_rot(values, k):
    try:
        values.atRot3(k)
        return True
    except RuntimeError:
        return False


#: Attitude-only Gauss-Newton passes at most, before the first joint iteration (see :func:`_fit_attitudes`).
ATTITUDE_FIT_ITERATIONS = 10
#: ... until no keyframe attitude moves by more than this, rad.
ATTITUDE_FIT_TOL = 1e-2


def _fit_attitudes(lin, preint, R, x):
    """Keyframe attitudes that fit the measurements at the starting calibration: the first linearisation point.

    Dead reckoning from the alignment with the prior calibration (zero) drifts with the uncalibrated gyro
    errors, by degrees per minute for a consumer MEMS unit: far beyond where the factors may be linearised,
    and Levenberg-Marquardt then walks the calibration into a wrong minimum (on the measured Xsens session
    cut to 26,103 rows: an accelerometer scale error of 21, chi2/dof 1,263, while the filter, which starts
    this way, converged).  A few Gauss-Newton passes over the attitudes alone (the calibration held, the
    attitudes damped by ``1e-9``) pull the trajectory onto the gravity and encoder measurements first, as the
    filter's :func:`kf_reference.passes.initial_attitudes` does.  ``lin(preint, R, x)`` linearises
    (:class:`graph_calib.solvers.reduced.ExperimentSystem`).
    """
    for _ in range(ATTITUDE_FIT_ITERATIONS):
        d = lin(preint, R, x).attitude_only_step(1e-9)
        R = reduced.retract(R, d)
        if float(np.max(np.linalg.norm(d, axis=1))) < ATTITUDE_FIT_TOL:
            break
    return R


#: Trials whose largest first-order keyframe rotation change exceeds ``GraphOptions.repreintegrate_tol`` but
#: not this (rad) are judged first with the first-order-corrected preintegration (``Preintegrated.corrected``,
#: as GTSAM's preintegration objects own their bias correction): on the Xsens session its cost differed from
#: the exact one by at most 1.7e-4 (of 2,600) up to 2.8e-4 rad, 6.8e-4 at 7.7e-4 rad, but 4.8 at 9.2e-3 rad.
FIRST_ORDER_JUDGE_TOL = 1e-3
#: ... and rejected on that cost alone when it exceeds the current cost by more than this fraction (a margin
#: hundreds of times the first-order error above; a point that may be accepted is always judged exactly).
FIRST_ORDER_REJECT_REL = 1e-4

#: Steps are mixed (Anderson, :mod:`graph_calib.solvers.acceleration`) once an accepted step lowered the cost
#: by less than this fraction (the iterations are then near the minimum, where they converge linearly).
ACCELERATE_BELOW_REL = 1e-2


class _Mixing:
    """Anderson mixing of the steps in the coordinates ``D [x; log(R_ref^T R)]``.

    ``D`` is the square root of the diagonal of the Gauss-Newton information ``J^T J`` (every factor, both
    priors) at the point that starts the history (every element in units of its own curvature), ``R_ref``
    the attitudes there.  Points are ``(R (K+1, 3, 3), x (P,))``.
    """

    def __init__(self, prior_information):
        self.acc = Anderson()
        self.prior_information = prior_information     # (P,): 1 / sigma^2 of the calibration prior
        self.P = prior_information.size
        self.ref = None

    def reset(self):
        self.acc.reset()
        self.ref = None

    def _encode(self, point):
        R, x = point
        R_ref, D = self.ref
        return D * np.concatenate([x, log_so3(np.swapaxes(R_ref, 1, 2) @ R).ravel()])

    def next(self, point, trial, system):
        """The mixed point from ``point`` and its step's ``trial``; None while only one step is held.

        ``system``: the :class:`graph_calib.solvers.reduced.ExperimentSystem` linearised at ``point``.
        """
        if self.ref is None:
            D = np.sqrt(np.concatenate([np.diag(system.H_tt) + self.prior_information, np.einsum("kii->ki", system.H_RR_diag).ravel()]))
            self.ref = (point[0], np.where(D > 0, D, 1.0))
        u = self._encode(point)
        u_new = self.acc.next(u, self._encode(trial) - u)
        if self.acc.depth < 2:
            return None
        R_ref, D = self.ref
        u_new = u_new / D
        return R_ref @ exp_so3(u_new[self.P:].reshape(-1, 3)), u_new[:self.P]


def solve(model, *, q_nb0, options=GraphOptions(), progress=None, initial=None):
    """Calibrate by Levenberg-Marquardt over the factor graph of ``model``.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    q_nb0 : ndarray, shape (4,) or (S, 4)
        Prior attitude at the start of the record (alignment), scalar first; one per segment for a
        record of ``S`` segments.
    options : GraphOptions
    progress : callable, optional
        Called with a :class:`graph_calib.solvers.interface.ProgressEvent` after each iteration.
    initial : tuple (R, x), optional
        Starting keyframe attitudes (K+1, 3, 3) and calibration (P,) instead of
        dead reckoning from the priors (e.g. a previous solution embedded in a
        larger layout, for a score test of a further effect).

    Returns
    -------
    GraphResult

    Notes
    -----
    BLAS runs on one thread inside the solve: its products have a few tens of columns, where OpenBLAS's
    threads gain nothing on two cores and, on a machine shared with other work (or beside the filter in
    ``calibrate``), spin: one linearisation of the Xsens session took 77 ms with them, 6 ms without.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _solve(model, q_nb0=q_nb0, options=options, progress=progress, initial=initial)


class _Step:
    """The damped Levenberg-Marquardt step on the graph linearised at one point, attitudes eliminated.

    GTSAM solves the reduced graph on ``C(0)``: the attitudes' Schur complement
    (:meth:`graph_calib.solvers.reduced.ExperimentSystem.reduce`, ``lam I`` added on every attitude), the
    calibration prior (GTSAM's own factor, linearised) and ``sqrt(lam) I`` on ``C(0)``; that is
    ``(J^T J + lam I) d = -J^T r`` over every variable, eliminated attitudes first, as GTSAM's elimination
    of the whole graph in the ordering ``X(0) .. X(K), C(0)``.  The attitude step follows by back-substitution.
    """

    def __init__(self, prior_graph, P):
        self.prior_graph, self.P = prior_graph, P
        self.ordering = gtsam.Ordering()
        self.ordering.push_back(C(0))

    def __call__(self, system, x, lam):
        """``(dR (K+1, 3), dx (P,))``; RuntimeError when the damped system is indeterminate."""
        H, g, Y = system.reduce(lam)
        gfg = self.prior_graph.linearize(_calibration_values(x))
        gfg.add(gtsam.HessianFactor(C(0), H, -g, 0.0))
        gfg = _damped(gfg, [C(0)], lam, [self.P])
        dx = np.asarray(gfg.optimize(self.ordering).at(C(0)), dtype=float)
        return reduced.ExperimentSystem.attitude_step(Y, dx), dx


def _calibration_values(x):
    v = gtsam.Values()
    v.insert(C(0), np.asarray(x, dtype=float))
    return v


def _solve(model, *, q_nb0, options, progress, initial):
    t0 = time.perf_counter()
    x_prior, x_sigma = model.prior()
    R_prior = model.segment_priors(q_nb0)
    if initial is None:
        x = x_prior.copy()
        preint = model.preintegrate(x)
        R = model.propagate(R_prior, preint, x)
    else:
        R = np.asarray(initial[0], dtype=float)
        x = np.asarray(initial[1], dtype=float).copy()
        preint = model.preintegrate(x)
    P = model.layout.size
    eye = np.eye(P)
    # the calibration prior is GTSAM's factor (its cost and linearisation); every other factor is evaluated and
    # linearised vectorised by the model, the attitudes eliminated (graph_calib.solvers.reduced)
    prior_graph = gtsam.NonlinearFactorGraph()
    prior_graph.add(gtsam.PriorFactorVector(C(0), x_prior, gtsam.noiseModel.Diagonal.Sigmas(x_sigma)))
    factor_args = dict(R_prior=R_prior, robust=options.robust, robust_k=options.robust_k)

    def lin(pre, R, x):
        return reduced.linearise(model, pre, R, x, eye, **factor_args)

    def prior_cost(x):
        return prior_graph.error(_calibration_values(x))

    if initial is None:
        R = _fit_attitudes(lin, preint, R, x)
    system = lin(preint, R, x)
    cost = system.cost + prior_cost(x)
    history = [cost]
    lam = options.lambda_initial
    it = 0
    converged = False
    preint_current = preint                # preintegrated at the current calibration: its cost is exact

    def cost_at(R_t, x_t, cost):
        """``(cost, (preintegration, linearised system) or None)`` at ``(R_t, x_t)``, judged by an exact
        preintegration when it is far from ``preint_current``.

        Between ``repreintegrate_tol`` and :data:`FIRST_ORDER_JUDGE_TOL` the first-order-corrected
        ``preint_current`` judges first: a cost above ``cost`` by more than :data:`FIRST_ORDER_REJECT_REL`
        rejects the point without the exact preintegration (a rejected trial needs no Jacobians); any
        other point, which may be accepted, is judged exactly and linearised there.
        """
        pre = preint_current
        if pre.needs_repreintegration(x_t, tol=options.repreintegrate_tol):
            if not pre.needs_repreintegration(x_t, tol=FIRST_ORDER_JUDGE_TOL):
                first_order = reduced.cost(model, pre, R_t, x_t, **factor_args) + prior_cost(x_t)
                if first_order > cost * (1.0 + FIRST_ORDER_REJECT_REL):
                    return first_order, None
            pre = model.preintegrate(x_t)
        sys_t = lin(pre, R_t, x_t)
        return sys_t.cost + prior_cost(x_t), (pre, sys_t)

    mixing = _Mixing(1.0 / x_sigma**2)
    step_of = _Step(prior_graph, P)
    accelerate = False
    # no table readings: the heading is held by the Earth rate alone; searched once the calibration settles
    # (one segment only: graph_calib.solvers.heading)
    heading_pending = initial is None and model.record.reading_t.size == 0 and model.segment_keys.size == 1
    for it in range(1, options.max_iterations + 1):
        mixed = False
        while True:
            try:
                dR, dx = step_of(system, x, lam)
            except RuntimeError:            # numerically indeterminate: damp harder
                if lam > 1e8:
                    raise
                lam = max(lam * 10.0, 1e-6)
                continue
            trial = (reduced.retract(R, dR), x + dx)
            if accelerate:
                # near the minimum: the mixed point of the last steps, kept if it lowers the cost
                accelerate = False
                point = mixing.next((R, x), trial, system)
                if point is not None:
                    mixed_cost, judged = cost_at(*point, cost)
                    if mixed_cost <= cost:
                        trial, new_cost, mixed = point, mixed_cost, True
                        break
                    mixing.reset()
            new_cost, judged = cost_at(*trial, cost)
            # at convergence a step may change the cost only by rounding: stop damping then
            if new_cost <= cost or lam > 1e8 or new_cost - cost <= 1e-10 * cost:
                break
            lam *= 10.0
        accepted = new_cost <= cost
        if accepted:
            R, x = trial
            preint_current, system = judged
            if not mixed:
                lam = max(lam / 10.0, 1e-9)
        rel = (cost - new_cost) / max(cost, 1e-300)
        cost = min(cost, new_cost)
        turned = False
        if heading_pending and accepted and not mixed and options.rel_tol <= rel < ACCELERATE_BELOW_REL:
            # the calibration has settled: each segment's heading of least cost (graph_calib.solvers.heading),
            # kept only if it lowers the cost
            heading_pending = False
            R_h = search_heading(model, lambda R_t: reduced.cost_by_key(model, preint_current, R_t, x,
                                                                        **factor_args), R)
            if R_h is not None:
                cost_h, judged_h = cost_at(R_h, x, cost)      # x unchanged: judged exactly
                if cost_h < cost:
                    R, (preint_current, system), cost, turned = R_h, judged_h, cost_h, True
                    mixing.reset()
        history.append(cost)
        if progress is not None:
            progress(ProgressEvent(solver=FactorGraphSolver.name, iteration=it, cost=float(cost)))
        if turned:
            accelerate = False
            continue
        if mixed:
            # a mixed step that barely lowers the cost hands over to a plain step: plain steps alone decide
            # convergence (the stopping rules below), so the mixing cannot stop the iterations short
            accelerate = rel >= options.rel_tol
            if not accelerate:
                mixing.reset()
            continue
        if accepted and (abs(rel) < options.rel_tol or np.all(np.abs(dx) < options.step_tol_sigma * x_sigma)
                         and options.step_tol_sigma > 0):
            converged = True
            break
        if not accepted and (lam > 1e8 or new_cost - cost <= 1e-10 * cost):
            converged = True
            break
        accelerate = accepted and rel < ACCELERATE_BELOW_REL
        if not accelerate:
            mixing.reset()
    # covariance: GTSAM's marginal of the whole graph, re-preintegrated at the solution so the Jacobians are
    # exact there
    cache = _Cache(model, model.preintegrate(x))
    cache.evaluate(R, x)
    graph = build_graph(model, cache, R_prior=R_prior, robust=options.robust, robust_k=options.robust_k)
    values = _values(R, x)
    cache.invalidate()
    cov = marginal_covariance(graph, values, [C(0)])
    cache.ensure(values)
    residuals = {
        "rotation": (model.t_key[cache.rot.key + 1], cache.rot.whitened()),
        "gravity": (model.t_key[:-1], cache.grav.whitened()),
        "encoder": (model.record.reading_t, cache.enc.whitened()),
    }
    return GraphResult(x=x, covariance=0.5 * (cov + cov.T), layout=model.layout, attitudes=cache.R.copy(),
                       residuals=residuals, iterations=it, cost_history=history,
                       seconds=time.perf_counter() - t0, converged=converged)


class FactorGraphSolver:
    """The factor graph behind the solver interface (registered under its ``name``)."""

    name = "factor-graph"

    def solve(self, problem, *, options, progress=None, initial=None):
        """Calibrate ``problem`` (:class:`graph_calib.records.problem.Problem`) with ``options.graph``.

        Returns
        -------
        graph_calib.solvers.interface.SolverOutput
            Residual series: the whitened residuals of every factor kind at the solution.
        """
        gr = solve(problem.model, q_nb0=problem.q_nb0, options=options.graph, progress=progress, initial=initial)
        return SolverOutput(
            solver=self.name, layout=gr.layout, x=gr.x, covariance=gr.covariance, t_key=problem.model.t_key.copy(),
            attitudes=gr.attitudes,
            residuals={kind: ResidualSeries(t=np.asarray(t, dtype=float), values=np.asarray(w, dtype=float))
                       for kind, (t, w) in gr.residuals.items()},
            residual_quantity=WHITENED_RESIDUAL, iterations=gr.iterations, converged=bool(gr.converged),
            final_cost=float(gr.cost_history[-1]), seconds=gr.seconds,
        )
