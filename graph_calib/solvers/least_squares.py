r"""The one Levenberg-Marquardt driver: the factor graph (one experiment) and the joint solver (N experiments).

The graph: the keyframe attitudes of every experiment, and unknowns ``theta`` (GTSAM vector variables, in
the solver's units) on which each experiment's calibration depends linearly, ``x_e = M_e theta_e``
(:class:`Experiment`; the factor graph: ``x = theta``, ``M = I``; the joint solver: curve coefficients and
set-ups in units of their prior sigmas).  Factors: each experiment's residual list (the model's factor
kinds and its attitude priors) and the unknowns' prior (:class:`graph_calib.model.factors.PriorResidual`).

Each iteration linearises every experiment's factors vectorised and eliminates its attitudes
(:func:`graph_calib.model.normal_equations.linearise`, :meth:`LinearSystem.reduce`, damped by ``lam``): one
reduced factor per experiment, which GTSAM solves with the unknowns' prior and the damping ``sqrt(lam) I``
on every unknown (``(J^T J + lam I) d = -J^T r`` over every variable, attitudes eliminated first); the
attitudes' steps follow by back-substitution.  The covariance is the inverse of the unknowns' reduced
information at the solution (the experiments preintegrated there again, all or the stale ones; the
attitudes' band factored by Cholesky, a sparse LU should it not be definite in floating point): GTSAM
assembles it from the same factors.

The loop (damping, acceptance and stopping rules) with:

- the attitude pre-fit (:data:`ATTITUDE_FIT_ITERATIONS` Gauss-Newton passes over the attitudes alone, the
  unknowns held) when the starting attitudes are dead-reckoned with an uncalibrated gyro;
- first-order judging of a trial (:data:`FIRST_ORDER_JUDGE_TOL`): a trial far enough from an experiment's
  preintegration point to need a new one is judged first with the first-order-corrected preintegration
  and rejected on that cost alone when it is clearly worse (a rejected trial needs no Jacobians);
- Anderson mixing (:mod:`graph_calib.solvers.acceleration`) near the minimum, kept only if it lowers the cost;
- the heading hook (:mod:`graph_calib.solvers.heading`): a table-less record's heading searched once the
  calibration settles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from graph_calib.model.factors import calibration_prior
from graph_calib.model.normal_equations import cost as factor_cost, cost_by_key, linearise, retract
from graph_calib.navigation.rotations import exp_so3, log_so3
from graph_calib.solvers.acceleration import Anderson
from graph_calib.solvers.heading import search_heading
from graph_calib.solvers.interface import ProgressEvent

#: Attitude-only Gauss-Newton passes at most before the first iteration (the pre-fit) ...
ATTITUDE_FIT_ITERATIONS = 10
#: ... until no keyframe attitude moves by more than this, rad.
ATTITUDE_FIT_TOL = 1e-2
#: The pre-fit's damping of the attitudes (the calibration held).
ATTITUDE_FIT_DAMPING = 1e-9
#: Damping is multiplied by this after a rejected step and divided by it after an accepted one.
DAMPING_FACTOR = 10.0
#: Smallest damping after an accepted step ...
DAMPING_MIN = 1e-9
#: ... and after a numerically indeterminate system, damped harder.
DAMPING_RESTART = 1e-6
#: Damping beyond which a rejected step ends the iterations (an indeterminate system raises).
DAMPING_MAX = 1e8
#: A trial that raises the cost by no more than this fraction of it is a step at convergence (rounding).
ROUNDING_REL = 1e-10
#: Trials whose largest first-order keyframe rotation change exceeds ``GraphOptions.repreintegrate_tol`` but
#: not this (rad) are judged first with the first-order-corrected preintegration ...
FIRST_ORDER_JUDGE_TOL = 1e-3
#: ... and rejected on that cost alone when it exceeds the current cost by more than this fraction (a margin
#: far above the first-order error; a point that may be accepted is always judged exactly).
FIRST_ORDER_REJECT_REL = 1e-4
#: Steps are mixed once an accepted step lowered the cost by less than this fraction (near the minimum,
#: where the iterations converge linearly).
ACCELERATE_BELOW_REL = 1e-2


@dataclass
class Experiment:
    """One experiment of the graph (the driver updates ``R`` and ``preint``).

    Attributes
    ----------
    model : graph_calib.model.CalibrationModel
    R : ndarray (K+1, 3, 3)
        Keyframe attitudes.
    R_prior : ndarray (S, 3, 3)
        Each segment's alignment.
    preint : graph_calib.model.preintegration.Preintegrated
    keys : list of int
        The GTSAM keys of the unknowns it touches (its ``theta_e``, in this order).
    M : ndarray (P, n_e) or None
        ``d x_e / d theta_e``; None: ``x_e = theta_e``.
    search_heading : bool
        Search its heading once the calibration settles (a table-less record of one segment, dead-reckoned).
    """

    model: object
    R: np.ndarray
    R_prior: np.ndarray
    preint: object
    keys: list
    M: np.ndarray | None = None
    search_heading: bool = False
    cols: np.ndarray = field(default=None, repr=False)

    def x_of(self, theta):
        th = theta[self.cols]
        return th if self.M is None else self.M @ th


@dataclass(frozen=True)
class Solution:
    """What the driver concludes.

    Attributes
    ----------
    theta : ndarray (N,)
        The unknowns, solver units.
    covariance : ndarray (N, N)
        Their marginal covariance over every attitude, solver units.
    whitened : list of dict
        Per experiment, ``{kind: r / sigma (F, 3)}`` at the solution.
    iterations, converged, cost_history
    """

    theta: np.ndarray
    covariance: np.ndarray
    whitened: list
    iterations: int
    converged: bool
    cost_history: list


class _Mixing:
    """Anderson mixing of the steps in the coordinates ``D [theta; log(R_ref^T R) of every experiment]``.

    ``D`` is the square root of the diagonal of the Gauss-Newton information (every factor, the priors) at
    the point that starts the history, ``R_ref`` the attitudes there.  Points are ``(R list, theta)``.
    """

    def __init__(self, prior_information):
        self.acc = Anderson()
        self.prior_information = prior_information
        self.N = prior_information.size
        self.ref = None

    def reset(self):
        self.acc.reset()
        self.ref = None

    def _encode(self, point):
        Rs, theta = point
        R_ref, D = self.ref
        return D * np.concatenate([theta] + [log_so3(np.swapaxes(a, 1, 2) @ b).ravel() for a, b in zip(R_ref, Rs)])

    def next(self, point, trial, exps, systems):
        """The mixed point from ``point`` and its step's ``trial``; None while only one step is held."""
        if self.ref is None:
            d_theta = np.zeros(self.N)
            for c, s in zip(exps, systems):
                d_theta[c.cols] += np.diag(s.H_xx)
            D = np.sqrt(np.concatenate([d_theta + self.prior_information]
                                       + [np.einsum("kii->ki", s.H_aa_diag).ravel() for s in systems]))
            self.ref = ([R for R in point[0]], np.where(D > 0, D, 1.0))
        u = self._encode(point)
        u_new = self.acc.next(u, self._encode(trial) - u)
        if self.acc.depth < 2:
            return None
        R_ref, D = self.ref
        u_new = u_new / D
        Rs, at = [], self.N
        for R in R_ref:
            n = R.shape[0] * 3
            Rs.append(R @ exp_so3(u_new[at:at + n].reshape(-1, 3)))
            at += n
        return Rs, u_new[:self.N]


def _hessian_factor(keys, dims, H, g):
    """A reduced system ``(H, g)`` over one or two keys as GTSAM's ``HessianFactor``."""
    if len(keys) == 1:
        return gtsam.HessianFactor(keys[0], H, -g, 0.0)
    a = dims[0]
    return gtsam.HessianFactor(keys[0], keys[1], H[:a, :a], H[:a, a:], -g[:a], H[a:, a:], -g[a:], 0.0)


class LeastSquares:
    """The graph of ``experiments`` and unknowns ``theta`` (module docstring).

    Parameters
    ----------
    experiments : list of Experiment
    theta_keys : list of (int, int)
        Every unknown's GTSAM key and dimension, in ``theta``'s order.
    prior_mean, prior_sigma : ndarray (N,)
        The unknowns' prior (solver units).
    options : graph_calib.options.GraphOptions
    solver : str
        The name its progress events carry.
    exact_at_solution : bool
        Preintegrate every experiment again at the solution for the covariance and the residual series
        (else only those whose calibration moved beyond ``repreintegrate_tol`` from their preintegration
        point: a second and 0.3 GB per 3 h experiment spared, the Jacobians first-order exact there).
    """

    def __init__(self, experiments, *, theta_keys, prior_mean, prior_sigma, options, solver, exact_at_solution=True):
        self.exps, self.options, self.solver = list(experiments), options, solver
        self.exact_at_solution = exact_at_solution
        self.prior_mean, self.prior_sigma = np.asarray(prior_mean, float), np.asarray(prior_sigma, float)
        self.slices, at = {}, 0
        for key, d in theta_keys:
            self.slices[key] = slice(at, at + d)
            at += d
        self.theta_keys = [k for k, _ in theta_keys]
        for c in self.exps:
            c.cols = np.concatenate([np.arange(self.slices[k].start, self.slices[k].stop) for k in c.keys])
        # the experiments' own unknowns eliminated first, the shared ones last
        self.ordering = gtsam.Ordering()
        shared = self.exps[0].keys[0]
        for k in [k for k in self.theta_keys if k != shared] + [shared]:
            self.ordering.push_back(k)
        self.fargs = dict(robust=options.robust, robust_k=options.robust_k)

    # -- the graph's pieces ---------------------------------------------------------------------------

    def prior(self, theta):
        return calibration_prior(theta, mean=self.prior_mean, sigma=self.prior_sigma)

    def linearise(self, c, pre, R, theta):
        return linearise(c.model, pre, R, c.x_of(theta), R_prior=c.R_prior, M=c.M, **self.fargs)

    def linear_graph(self, theta, systems, lam, *, definite=True):
        """The linearised graph, every experiment's attitudes eliminated (``lam`` their damping), and each
        experiment's back-substitution."""
        gfg = gtsam.GaussianFactorGraph()
        pr = self.prior(theta)
        for k in self.theta_keys:
            sl = self.slices[k]
            d = sl.stop - sl.start
            gfg.add(gtsam.JacobianFactor(k, pr.H[sl, sl], -pr.r[sl], gtsam.noiseModel.Unit.Create(d)))
        atts = []
        for c, s in zip(self.exps, systems):
            H, g, att = s.reduce(lam, definite=definite)
            gfg.add(_hessian_factor(c.keys, [self.slices[k].stop - self.slices[k].start for k in c.keys], H, g))
            atts.append(att)
        return gfg, atts

    def step(self, theta, systems, lam):
        """``(attitude steps per experiment, d theta)`` of the damped system; RuntimeError when indeterminate."""
        gfg, atts = self.linear_graph(theta, systems, lam)
        s = np.sqrt(lam)
        for k in self.theta_keys:
            d = self.slices[k].stop - self.slices[k].start
            gfg.add(gtsam.JacobianFactor(k, s * np.eye(d), np.zeros(d), gtsam.noiseModel.Unit.Create(d)))
        delta = gfg.optimize(self.ordering)
        dtheta = np.concatenate([np.asarray(delta.at(k), dtype=float) for k in self.theta_keys])
        return [att.step(dtheta[c.cols]) for c, att in zip(self.exps, atts)], dtheta

    def cost_at(self, Rs, theta, cost):
        """``(cost, (preintegrations, systems) or None)`` at ``(Rs, theta)``.

        An experiment whose calibration moved beyond ``repreintegrate_tol`` from its preintegration point
        is preintegrated again; while every such one lies within :data:`FIRST_ORDER_JUDGE_TOL`, the
        first-order-corrected preintegrations judge first, and a cost above ``cost`` by more than
        :data:`FIRST_ORDER_REJECT_REL` rejects the point without linearising.
        """
        o = self.options
        xs = [c.x_of(theta) for c in self.exps]
        stale = [c.preint.needs_repreintegration(x, tol=o.repreintegrate_tol) for c, x in zip(self.exps, xs)]
        if any(stale) and not any(c.preint.needs_repreintegration(x, tol=FIRST_ORDER_JUDGE_TOL)
                                  for c, x, s in zip(self.exps, xs, stale) if s):
            first_order = sum(factor_cost(c.model, c.preint, R, x, R_prior=c.R_prior, **self.fargs)
                              for c, R, x in zip(self.exps, Rs, xs)) + self.prior(theta).cost
            if first_order > cost * (1.0 + FIRST_ORDER_REJECT_REL):
                return first_order, None
        if len(self.exps) == 1:       # the trial's preintegration held beside the current one
            pres = [c.model.preintegrate(x) if s else c.preint for c, x, s in zip(self.exps, xs, stale)]
        else:                         # one held per experiment (0.3 GB for 3 h): replaced, restored if rejected
            for c, x, s in zip(self.exps, xs, stale):
                if s:
                    c.preint = None
                    c.preint = c.model.preintegrate(x)
            pres = [c.preint for c in self.exps]
        systems = [self.linearise(c, p, R, theta) for c, p, R in zip(self.exps, pres, Rs)]
        return self.prior(theta).cost + sum(s.cost for s in systems), (pres, systems)

    def restore(self, x_lin):
        """Every experiment's preintegration formed at ``x_lin`` again where a rejected trial replaced it."""
        for c, xl in zip(self.exps, x_lin):
            if not np.array_equal(c.preint.x_lin, xl):
                c.preint = None
                c.preint = c.model.preintegrate(xl)

    # -- the loop -------------------------------------------------------------------------------------

    def prefit_attitudes(self, theta):
        """Attitude-only Gauss-Newton passes from dead-reckoned attitudes (the calibration held)."""
        for _ in range(ATTITUDE_FIT_ITERATIONS):
            moved = 0.0
            for c in self.exps:
                d = self.linearise(c, c.preint, c.R, theta).attitude_only_step(ATTITUDE_FIT_DAMPING)
                c.R = retract(c.R, d)
                moved = max(moved, float(np.max(np.linalg.norm(d, axis=1))))
            if moved < ATTITUDE_FIT_TOL:
                break

    def _turn_headings(self, theta):
        """Every searching experiment's attitudes turned to the heading of least cost, or None."""
        Rs, turned = [c.R for c in self.exps], False
        for i, c in enumerate(self.exps):
            if not c.search_heading:
                continue
            x = c.x_of(theta)
            R_h = search_heading(c.model, lambda R_t, c=c, x=x: cost_by_key(c.model, c.preint, R_t, x, R_prior=c.R_prior,
                                                                            **self.fargs), c.R)
            if R_h is not None:
                Rs[i], turned = R_h, True
        return Rs if turned else None

    def solve(self, theta, *, prefit=False, progress=None):
        """Levenberg-Marquardt from ``theta`` and the experiments' attitudes; a :class:`Solution`."""
        o = self.options
        theta = np.asarray(theta, dtype=float).copy()
        if prefit:
            self.prefit_attitudes(theta)
        systems = [self.linearise(c, c.preint, c.R, theta) for c in self.exps]
        cost = self.prior(theta).cost + sum(s.cost for s in systems)
        history, lam, it, converged = [cost], o.lambda_initial, 0, False
        # a trial that raises the cost by no more than this is a step at convergence: rounding, or within the
        # tolerance a solve that only starts another is given (graph_calib.solvers.registry.loose)
        flat = max(ROUNDING_REL, o.rel_tol)
        mixing = _Mixing(1.0 / self.prior_sigma**2)
        accelerate = False
        heading_pending = any(c.search_heading for c in self.exps)
        held = [c.preint.x_lin for c in self.exps]          # where the accepted point's preintegrations were formed
        for it in range(1, o.max_iterations + 1):
            mixed = False
            while True:
                try:
                    dRs, dtheta = self.step(theta, systems, lam)
                except RuntimeError:            # numerically indeterminate: damp harder
                    if lam > DAMPING_MAX:
                        raise
                    lam = max(lam * DAMPING_FACTOR, DAMPING_RESTART)
                    continue
                trial = ([retract(c.R, d) for c, d in zip(self.exps, dRs)], theta + dtheta)
                if accelerate:
                    # near the minimum: the mixed point of the last steps, kept if it lowers the cost
                    accelerate = False
                    point = mixing.next(([c.R for c in self.exps], theta), trial, self.exps, systems)
                    if point is not None:
                        mixed_cost, judged = self.cost_at(*point, cost)
                        if mixed_cost <= cost:
                            trial, new_cost, mixed = point, mixed_cost, True
                            break
                        self.restore(held)
                        mixing.reset()
                new_cost, judged = self.cost_at(*trial, cost)
                # at convergence a step may change the cost only by rounding: stop damping then
                if new_cost <= cost or lam > DAMPING_MAX or new_cost - cost <= flat * cost:
                    break
                self.restore(held)
                lam *= DAMPING_FACTOR
            accepted = new_cost <= cost
            if accepted:
                theta = trial[1]
                pres, systems = judged
                for c, R, p in zip(self.exps, trial[0], pres):
                    c.R, c.preint = R, p
                held = [c.preint.x_lin for c in self.exps]
                if not mixed:
                    lam = max(lam / DAMPING_FACTOR, DAMPING_MIN)
            else:
                self.restore(held)
            judged = None
            rel = (cost - new_cost) / max(cost, 1e-300)
            cost = min(cost, new_cost)
            turned = False
            if heading_pending and accepted and not mixed and o.rel_tol <= rel < ACCELERATE_BELOW_REL:
                # the calibration has settled: each searching experiment's heading of least cost, kept only if
                # it lowers the cost
                heading_pending = False
                Rs = self._turn_headings(theta)
                if Rs is not None:
                    cost_h, judged_h = self.cost_at(Rs, theta, cost)      # theta unchanged: judged exactly
                    if cost_h < cost:
                        for c, R, p in zip(self.exps, Rs, judged_h[0]):
                            c.R, c.preint = R, p
                        held = [c.preint.x_lin for c in self.exps]
                        systems, cost, turned = judged_h[1], cost_h, True
                        mixing.reset()
                    else:
                        self.restore(held)
            history.append(cost)
            if progress is not None:
                progress(ProgressEvent(solver=self.solver, iteration=it, cost=float(cost)))
            if turned:
                accelerate = False
                continue
            if mixed:
                # a mixed step that barely lowers the cost hands over to a plain step: plain steps alone decide
                # convergence (the stopping rules below), so the mixing cannot stop the iterations short
                accelerate = rel >= o.rel_tol
                if not accelerate:
                    mixing.reset()
                continue
            if accepted and (abs(rel) < o.rel_tol or o.step_tol_sigma > 0
                             and np.all(np.abs(dtheta) < o.step_tol_sigma * self.prior_sigma)):
                converged = True
                break
            if not accepted and (lam > DAMPING_MAX or new_cost - cost <= flat * cost):
                converged = True
                break
            accelerate = accepted and rel < ACCELERATE_BELOW_REL
            if not accelerate:
                mixing.reset()
        if o.covariance:
            systems = None
            cov, whitened = self.covariance(theta)
        else:
            # a solve that only starts another: the last accepted linearisation's residuals, no covariance
            whitened = [s.whitened for s in systems]
            cov = np.full((theta.size, theta.size), np.nan)
        return Solution(theta=theta, covariance=cov, whitened=whitened, iterations=it, converged=converged,
                        cost_history=history)

    def covariance(self, theta):
        """The unknowns' covariance at ``theta`` (the inverse of their reduced information) and each
        experiment's whitened residuals there (preintegrated again as ``exact_at_solution`` says)."""
        systems = []
        for c in self.exps:
            x = c.x_of(theta)
            if (not np.array_equal(c.preint.x_lin, x) if self.exact_at_solution
                    else c.preint.needs_repreintegration(x, tol=self.options.repreintegrate_tol)):
                c.preint = None                  # one preintegration held at a time (0.3 GB for 3 h)
                c.preint = c.model.preintegrate(x)
            systems.append(self.linearise(c, c.preint, c.R, theta))
        whitened = [s.whitened for s in systems]
        gfg, _ = self.linear_graph(theta, systems, 0.0, definite=False)
        systems = None
        keep = gtsam.Ordering()
        for k in self.theta_keys:
            keep.push_back(k)
        info = np.asarray(gfg.hessian(keep)[0], dtype=float)
        n = self.prior_sigma.size
        info = 0.5 * (info[:n, :n] + info[:n, :n].T)
        Linv = np.linalg.solve(np.linalg.cholesky(info), np.eye(n))
        cov = Linv.T @ Linv
        return 0.5 * (cov + cov.T), whitened


__all__ = ["Experiment", "LeastSquares", "Solution", "ATTITUDE_FIT_ITERATIONS", "ATTITUDE_FIT_TOL",
           "FIRST_ORDER_JUDGE_TOL", "FIRST_ORDER_REJECT_REL", "ACCELERATE_BELOW_REL"]
