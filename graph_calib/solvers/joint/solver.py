r"""The joint campaign solver: every experiment of a campaign in one factor graph (GTSAM).

Variables: the keyframe attitudes of every experiment (eliminated by the solver, experiment by
experiment: :mod:`graph_calib.model.normal_equations`), the shared unknowns ``Z(0)`` (the
temperature curves' coefficients and the shared elements, :mod:`graph_calib.solvers.joint.unknowns`) and each
experiment's set-up ``S(e)`` (mount, lever arm, table lag, damper stiffness where its layout has them).
Each experiment keeps its own :class:`graph_calib.model.CalibrationModel`, its layout extended by the
curves' higher temperature coefficients; its calibration vector is ``x_e = A_e z + B_e s_e`` (exact: a
polynomial's Taylor expansion at ``T_ref``), so its factors are the model's own (rotation, gravity,
encoder) with the parameter Jacobians chained, ``H_z = H_x A_e``, ``H_s = H_x B_e``.  Priors: the
grade's (or the manifest's) prior of each unknown, once: a curve coefficient of order ``j`` takes the
prior of the family's ``*_tc<j>`` about ``t0``; the alignment of each experiment's first attitude.

The Levenberg-Marquardt loop is the project's one driver (:mod:`graph_calib.solvers.least_squares`, the
factor graph's too: the same damping, acceptance and stopping rules, first-order judging, mixing), on the
graph linearised with every experiment's attitudes eliminated: each experiment's factors evaluated
vectorised and reduced to one GTSAM factor on the unknowns it touches; GTSAM solves the reduced graph of
the unknowns, the attitudes' steps follow by back-substitution, and the unknowns' covariance is the inverse
of their reduced information at the solution.  The cost is the graph's error: the unknowns' priors plus
each experiment's factors and attitude priors.

Curve degree by evidence
    The solve estimates every family at the highest degree the registry has; a Wald test of its highest
    orders at the loop's alpha finds the orders the data show, with the test of the next order past them;
    an order they do not show is dropped from the curve only where holding it would widen the curve's
    sigma much (:mod:`graph_calib.solvers.joint.degrees`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from gtsam.symbol_shorthand import S, Z
from threadpoolctl import threadpool_limits

from graph_calib.model.residual_list import FACTOR_KINDS, MEASUREMENT_KINDS
from graph_calib.solvers.least_squares import Experiment, LeastSquares
from graph_calib.solvers.joint.degrees import choose_degrees
from graph_calib.solvers.joint.unknowns import MAX_DEGREE, Unknowns, coefficient_terms, family_member, plan_unknowns
from graph_calib.options import GraphOptions
from graph_calib.sensors.params import Layout, split_element_name
from graph_calib.solvers.interface import WHITENED_RESIDUAL, ResidualSeries, SolverOutput

#: Name of the solver (entry point ``graph_calib.solvers``).
JOINT = "joint"
@dataclass(frozen=True)
class JointOutput:
    """What the joint solver concludes about a campaign.

    Attributes
    ----------
    unknowns : graph_calib.solvers.joint.unknowns.Unknowns
        With the degrees chosen.
    theta_names : tuple of str
        ``z`` names then every experiment's set-up as ``<experiment index>/<flat element>``.
    theta : ndarray, shape (Nt,)
    covariance : ndarray, shape (Nt, Nt)
        Marginal covariance of ``theta`` (over every attitude).
    outputs : tuple of graph_calib.solvers.interface.SolverOutput
        Per experiment, its calibration vector ``x_e`` (its extended layout) with covariance, attitudes and
        whitened residuals: each experiment's view of the joint solution.
    degree_choices : tuple of graph_calib.solvers.joint.degrees.DegreeEvidence
    n_measurements : int
    iterations : int
    converged : bool
    final_cost : float
    seconds : float
    cost_history : list of float
    """

    unknowns: Unknowns
    theta_names: tuple
    theta: np.ndarray
    covariance: np.ndarray
    outputs: tuple
    degree_choices: tuple
    n_measurements: int
    iterations: int
    converged: bool
    final_cost: float
    seconds: float
    cost_history: list = field(default_factory=list)

    def setup_slice(self, e):
        """Slice of ``theta`` holding experiment ``e``'s set-up."""
        start = self.unknowns.nz + sum(len(s) for s in self.unknowns.setup_names[:e])
        return slice(start, start + len(self.unknowns.setup_names[e]))


def _extend(problem, unknowns_degrees):
    """The problem with the layout holding the curves' higher temperature coefficients."""
    need = coefficient_terms(unknowns_degrees)
    have = tuple(problem.model.options.extra_effects)
    extra = have + tuple(n for n in need if n not in have and n not in problem.model.options.exclude)
    return problem if extra == have else problem.with_effects(extra)


def _sensor_spans(records):
    """Each sensor's temperature span over the records (gyro x, y, z, accel x, y, z), degC, shape (6, 2)."""
    lo, hi = np.full(6, np.inf), np.full(6, -np.inf)
    for r in records:
        dT = np.hstack([r.dTg, r.dTa])
        lo = np.minimum(lo, dT.min(axis=0) + r.t_ref_degC)
        hi = np.maximum(hi, dT.max(axis=0) + r.t_ref_degC)
    return np.column_stack([lo, hi])


def _priors(unknowns, models):
    """Prior sigma of ``z`` and of each set-up, from the experiments' own priors (grade and manifest).

    A curve coefficient of order ``j`` takes the prior of its family's member of that order
    (``gyro.bias.x:c2`` that of ``gyro.bias_tc2.x``).
    """
    sig = {}
    for m in models:
        for n, v in zip(m.layout.element_names(), m.prior()[1]):
            sig.setdefault(n, float(v))
    z_sigma = []
    for n in unknowns.z_names:
        if ":c" in n:
            flat, j = n.rsplit(":c", 1)
            p, el = split_element_name(flat)
            member = family_member(p, int(j))
            n = member if el is None else f"{member}.{el}"
        if n not in sig:
            raise ValueError(f"no prior for the joint unknown {n}")
        z_sigma.append(sig[n])
    s_sigmas = []
    for e, m in enumerate(models):
        own = dict(zip(m.layout.element_names(), m.prior()[1]))
        s_sigmas.append(np.array([own[n] for n in unknowns.setup_names[e]], dtype=float))
    return np.array(z_sigma), s_sigmas


@dataclass(frozen=True)
class WarmStart:
    """A starting point for one experiment: a per-experiment solution (e.g. the subrange's factor graph).

    Attributes
    ----------
    layout : graph_calib.sensors.params.Layout
    x : ndarray, shape (P,)
    sigma : ndarray, shape (P,), optional
        Weights of the fit of the joint unknowns to the starting values (default the priors).
    attitudes : ndarray, shape (K+1, 3, 3), optional
        Keyframe attitudes (else dead reckoning from the alignment with the starting calibration; fitted to
        the measurements first only when some experiment has no starting solution).
    """

    layout: object
    x: np.ndarray
    sigma: np.ndarray | None = None
    attitudes: np.ndarray | None = None

    @classmethod
    def from_result(cls, result):
        """From a result file's values and sigmas (:class:`graph_calib.records.experiment.Result`)."""
        from_layout = Layout(tuple(result.effects))
        names = from_layout.element_names()
        x = np.array([float(result.values.get(n, 0.0)) for n in names])
        sig = None if result.sigmas is None else np.array([float(result.sigmas.get(n, 0.0)) for n in names])
        return cls(layout=from_layout, x=x, sigma=sig)


def _warm_theta(unknowns, models, maps, starts, priors):
    """The unknowns that fit the starting solutions best (weighted least squares, the priors as rows)."""
    z_sigma, s_sigmas = priors
    sizes = [unknowns.nz] + [len(s) for s in unknowns.setup_names]
    offsets = np.cumsum([0] + sizes)
    sig_theta = np.concatenate([z_sigma] + list(s_sigmas))
    rows = [np.diag(1.0 / sig_theta)]
    rhs = [np.zeros(sig_theta.size)]
    for e, (m, (A, B), ws) in enumerate(zip(models, maps, starts)):
        if ws is None:
            continue
        sub = {n: i for i, n in enumerate(ws.layout.element_names())}
        prior_sigma = m.prior()[1]
        for i, n in enumerate(m.layout.element_names()):
            if n not in sub:
                continue
            j = sub[n]
            s = float(ws.sigma[j]) if ws.sigma is not None and ws.sigma[j] > 0 else float(prior_sigma[i])
            row = np.zeros(sig_theta.size)
            row[:unknowns.nz] = A[i]
            row[offsets[e + 1]:offsets[e + 2]] = B[i]
            rows.append(row[None, :] / s)
            rhs.append(np.array([ws.x[j] / s]))
    return np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]


def solve_joint(problems, *, options=GraphOptions(), progress=None, initial=None, degrees=None):
    """Solve every experiment of a campaign in one factor graph (module docstring).

    Parameters
    ----------
    problems : sequence of graph_calib.records.problem.Problem
        One per experiment (their layouts are extended here by the curves' higher coefficients).
    options : GraphOptions
    progress : callable, optional
        Called with a :class:`ProgressEvent` after each iteration.
    initial : sequence of WarmStart or None, optional
        Per experiment, a starting solution (e.g. its own factor graph's result).
    degrees : dict, optional
        ``{family: degree}`` of every temperature family, fixed: no choice, no evidence (``degree_choices``
        empty). Default: each family estimated at the registry's highest degree and its degree chosen by
        :func:`graph_calib.solvers.joint.degrees.choose_degrees`.

    Returns
    -------
    JointOutput

    Notes
    -----
    BLAS runs on one thread inside the solve: its products are of a few tens of columns (an experiment's
    unknowns), where OpenBLAS's threads gain nothing on two cores and, on a machine shared with other
    work, spin (the Schur complement ``H_xa H_aa^-1 H_ax`` of a 3 h experiment most).
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _solve_joint(problems, options=options, progress=progress, initial=initial,
                            degrees=degrees)


def _solve_joint(problems, *, options, progress, initial, degrees):
    t_start = time.perf_counter()
    problems = list(problems)
    if not problems:
        raise ValueError("the joint solver needs at least one experiment")
    first = problems[0].model.layout
    fixed = {b: int(d) for b, d in degrees.items() if b in first} if degrees is not None else None
    problems = [_extend(p, fixed if fixed is not None else {b: d for b, d in MAX_DEGREE.items() if b in first})
                for p in problems]
    models = [p.model for p in problems]
    unknowns = plan_unknowns([m.layout for m in models], [m.t_ref_degC for m in models])
    maps = [unknowns.experiment_map(e, m.layout, m.t_ref_degC) for e, m in enumerate(models)]
    priors = _priors(unknowns, models)
    z_sigma, s_sigmas = priors
    starts = list(initial) if initial is not None else [None] * len(problems)
    theta = (_warm_theta(unknowns, models, maps, starts, priors) if any(s is not None for s in starts)
             else np.zeros(unknowns.nz + sum(len(s) for s in s_sigmas)))
    nz = unknowns.nz
    offs = np.cumsum([nz] + [len(s) for s in s_sigmas])
    # GTSAM's variables are the unknowns in units of their prior sigmas, u = theta / sigma: the curve
    # coefficients span twenty orders of magnitude in SI (a bias in rad/s, its cubic in rad/s/degC^3), so
    # that Levenberg-Marquardt's isotropic damping and GTSAM's Cholesky see a well-scaled system
    sig_theta = np.concatenate([z_sigma] + list(s_sigmas))
    u0 = theta / sig_theta
    exps, theta_keys = [], [(Z(0), nz)]
    have_attitudes = True
    for e, (p, (A, B)) in enumerate(zip(problems, maps)):
        m = p.model
        ns = B.shape[1]
        M_u = np.hstack([A * z_sigma[None, :], B * s_sigmas[e][None, :]])
        x = M_u @ np.concatenate([u0[:nz], u0[offs[e]:offs[e + 1]]])
        preint = m.preintegrate(x)
        R_prior = m.segment_priors(p.q_nb0)
        ws = starts[e]
        if ws is not None and ws.attitudes is not None and ws.attitudes.shape == (m.n_keyframes + 1, 3, 3):
            R = np.array(ws.attitudes, dtype=float)
        else:
            R = m.propagate(R_prior, preint, x)
            have_attitudes = False
        keys = [Z(0)] + ([S(e)] if ns else [])
        if ns:
            theta_keys.append((S(e), ns))
        heading = ws is None and m.record.reading_t.size == 0 and m.segment_keys.size == 1
        exps.append(Experiment(model=m, R=R, R_prior=R_prior, preint=preint, keys=keys, M=M_u, search_heading=heading))
    lsq = LeastSquares(exps, theta_keys=theta_keys, prior_mean=np.zeros(sig_theta.size),
                       prior_sigma=np.ones(sig_theta.size), options=options, solver=JOINT, exact_at_solution=False)
    # attitudes dead-reckoned with a warm calibration (every experiment's own solution) stay within the
    # alignment's error of the truth: no pre-fit needed there
    sol = lsq.solve(u0, prefit=not have_attitudes and not all(s is not None for s in starts), progress=progress)
    it, converged, cost = sol.iterations, sol.converged, sol.cost_history[-1]
    whitened = sol.whitened
    n_meas = int(sum(3 * w[k].shape[0] for w in whitened for k in MEASUREMENT_KINDS if k in w))
    cov = sol.covariance * np.outer(sig_theta, sig_theta)
    theta = sol.theta * sig_theta
    if fixed is None:
        reduced, keep, th_c, cov_c, choices = choose_degrees(unknowns, theta, cov,
                                                             sensor_spans=_sensor_spans([m.record for m in models]))
    else:
        reduced, keep, th_c, cov_c, choices = unknowns, np.ones(theta.size, bool), theta, cov, ()
    theta_r, cov_r = th_c[keep], cov_c[np.ix_(keep, keep)]
    seconds = time.perf_counter() - t_start
    outputs = []
    offs_r = np.cumsum([reduced.nz] + [len(s) for s in reduced.setup_names])
    for e, c in enumerate(exps):
        m = c.model
        A, B = reduced.experiment_map(e, m.layout, m.t_ref_degC)
        sl = slice(offs_r[e], offs_r[e + 1])
        Mfull = np.hstack([A, B])
        cols = np.concatenate([np.arange(reduced.nz), np.arange(sl.start, sl.stop)]).astype(int)
        x_e = Mfull @ theta_r[cols]
        cov_e = Mfull @ cov_r[np.ix_(cols, cols)] @ Mfull.T
        outputs.append(SolverOutput(
            solver=JOINT, layout=m.layout, x=x_e, covariance=0.5 * (cov_e + cov_e.T), t_key=m.t_key.copy(),
            attitudes=c.R,
            residuals={k.name: ResidualSeries(t=np.array(k.times(m), dtype=float), values=whitened[e][k.name])
                       for k in FACTOR_KINDS if k.name in whitened[e]},
            residual_quantity=WHITENED_RESIDUAL, iterations=it, converged=bool(converged),
            final_cost=float(cost), seconds=seconds))
    names = reduced.z_names + tuple(f"{e}/{n}" for e, s in enumerate(reduced.setup_names) for n in s)
    return JointOutput(unknowns=reduced, theta_names=names, theta=theta_r, covariance=0.5 * (cov_r + cov_r.T),
                       outputs=tuple(outputs), degree_choices=choices, n_measurements=n_meas, iterations=it,
                       converged=bool(converged), final_cost=float(cost), seconds=seconds, cost_history=sol.cost_history)


class JointSolver:
    """The joint campaign solver behind the solver interface (registered as :data:`JOINT`).

    :meth:`solve_campaign` solves a campaign; :meth:`solve` (the per-experiment interface) solves one
    experiment as a campaign of one and returns its view (its extended layout, the curves' coefficients
    Taylor-expanded at its ``T_ref``).
    """

    name = JOINT
    #: Marks a solver that takes every experiment of a campaign at once.
    campaign = True

    def solve_campaign(self, problems, *, options, progress=None, initial=None):
        """:func:`solve_joint` with ``options.graph`` (``options``: :class:`graph_calib.options.CalibrationOptions`)."""
        return solve_joint(problems, options=options.graph, progress=progress, initial=initial)

    def solve(self, problem, *, options, progress=None, initial=None):
        """One experiment (``initial``: ``(R, x)`` in the problem's layout, as for every solver)."""
        start = None if initial is None else [WarmStart(layout=problem.model.layout, x=np.asarray(initial[1]),
                                                        attitudes=np.asarray(initial[0]))]
        return solve_joint([problem], options=options.graph, progress=progress, initial=start).outputs[0]
