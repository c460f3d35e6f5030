r"""The joint campaign solver: every experiment of a campaign in one factor graph (GTSAM).

Variables: the keyframe attitudes of every experiment (eliminated by the solver, experiment by
experiment: :mod:`graph_calib.solvers.reduced`), the shared unknowns ``Z(0)`` (the
temperature curves' coefficients and the shared elements, :mod:`graph_calib.solvers.joint.unknowns`) and each
experiment's set-up ``S(e)`` (mount, lever arm, table lag, damper stiffness where its layout has them).
Each experiment keeps its own :class:`graph_calib.model.CalibrationModel`, its layout extended by the
curves' higher temperature coefficients; its calibration vector is ``x_e = A_e z + B_e s_e`` (exact: a
polynomial's Taylor expansion at ``T_ref``), so its factors are the model's own (rotation, gravity,
encoder) with the parameter Jacobians chained, ``H_z = H_x A_e``, ``H_s = H_x B_e``.  Priors: the
grade's (or the manifest's) prior of each unknown, once: a curve coefficient of order ``j`` takes the
prior of the family's ``*_tc<j>`` about ``t0``; the alignment of each experiment's first attitude.

The Levenberg-Marquardt loop is :mod:`graph_calib.solvers.factor_graph`'s (the same damping of every variable, the
same acceptance and stopping rules, each experiment re-preintegrated when its own calibration moves too far
from its preintegration point), on the graph linearised with every experiment's attitudes eliminated
(:mod:`graph_calib.solvers.reduced`: each experiment's factors evaluated vectorised and reduced to one GTSAM
factor on the unknowns it touches, the attitude chain's band factored directly); GTSAM solves the reduced
graph of the unknowns, the attitudes' steps follow by back-substitution.  The cost is the graph's error:
the unknowns' priors (GTSAM's factors) plus each experiment's factors and attitude prior.

Curve degree by evidence
    The solve estimates every family at the highest degree the registry has (biases cubic, scales
    quadratic).  Then, per family, from the highest order down to 2, the Wald statistic of that order's
    coefficients (all three axes) from the joint covariance, ``W = c^T Sigma^-1 c``, is set against the
    Bayesian information criterion's price of those parameters, ``k ln n`` (``n`` scalar measurements:
    gravity and encoder components of every experiment); an order that does not pay is dropped, the
    estimate conditioned on it being zero (the Gauss-Newton solution of the smaller model at the same
    linearisation point), and the next lower order tested.  The linear terms are always kept (declared).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np
from gtsam.symbol_shorthand import S, Z
from threadpoolctl import threadpool_limits

from graph_calib.solvers.factor_graph import ATTITUDE_FIT_ITERATIONS, ATTITUDE_FIT_TOL, _damped
from graph_calib.solvers.joint.marginal import unknowns_covariance
from graph_calib.solvers.reduced import ExperimentSystem, linearise, retract
from graph_calib.solvers.joint.unknowns import MAX_DEGREE, Unknowns, coefficient_terms, curve_label, family_member, plan_unknowns
from graph_calib.options import GraphOptions
from graph_calib.sensors.params import Layout, split_element_name
from graph_calib.navigation.rotations import quat_to_dcm
from graph_calib.solvers.interface import WHITENED_RESIDUAL, ProgressEvent, ResidualSeries, SolverOutput

#: Name of the solver (entry point ``graph_calib.solvers``).
JOINT = "joint"
@dataclass(frozen=True)
class DegreeChoice:
    """The evidence for one curve family's degree.

    Attributes
    ----------
    family : str
        ``gyro.bias``, ...
    degree : int
        Degree kept.
    tests : list of dict
        Per order tested (highest first): ``order``, ``wald`` (chi-square of its coefficients), ``k``
        (their number), ``bic_price`` (``k ln n``), ``kept``.
    """

    family: str
    degree: int
    tests: list

    def to_json(self):
        return {"family": self.family, "degree": self.degree, "tests": list(self.tests)}


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
    degree_choices : tuple of DegreeChoice
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


class _Experiment:
    """One experiment of the joint graph: its model, its current preintegration, its attitudes (K+1, 3, 3)
    and ``M_u = d x_e / d theta_e`` (P, Nt), ``theta_e = (u_z, u_s)`` the unknowns it touches in GTSAM's
    units.  Its factors are linearised by :func:`graph_calib.solvers.reduced.linearise` one experiment at a
    time (their Jacobians, 0.2 GB for 3 h, released at once)."""

    def __init__(self, e, model, preint, M_u, nz, R, R_prior):
        self.e, self.model, self.preint, self.M_u, self.nz = e, model, preint, M_u, nz
        self.R, self.R_prior = R, R_prior
        self.has_setup = M_u.shape[1] > nz

    def theta_of(self, v):
        """``theta_e`` from GTSAM's ``Values`` or a ``VectorValues`` step."""
        get = v.atVector if isinstance(v, gtsam.Values) else v.at
        parts = [np.asarray(get(Z(0)), dtype=float)]
        if self.has_setup:
            parts.append(np.asarray(get(S(self.e)), dtype=float))
        return np.concatenate(parts)

    def x_of(self, v):
        return self.M_u @ self.theta_of(v)

    def linearise(self, values, R, options):
        return linearise(self.model, self.preint, R, self.x_of(values), self.M_u, R_prior=self.R_prior,
                         robust=options.robust, robust_k=options.robust_k)

    def reduced_factor(self, H, g):
        """The experiment's Schur complement as a GTSAM factor on ``Z(0)`` (and ``S(e)``)."""
        nz = self.nz
        if not self.has_setup:
            return gtsam.HessianFactor(Z(0), H, -g, 0.0)
        return gtsam.HessianFactor(Z(0), S(self.e), H[:nz, :nz], H[:nz, nz:], -g[:nz], H[nz:, nz:], -g[nz:], 0.0)


def _reduced_graph(exps, systems, prior_lin, lam):
    """The linearised graph with every experiment's attitudes eliminated (``lam`` their damping):
    the priors of the unknowns and one reduced factor per experiment; and each experiment's
    back-substitution (:meth:`graph_calib.solvers.reduced.ExperimentSystem.reduce`)."""
    gfg = gtsam.GaussianFactorGraph()
    gfg.push_back(prior_lin)
    Ys = []
    for c, sysm in zip(exps, systems):
        H, g, Y = sysm.reduce(lam)
        gfg.add(c.reduced_factor(H, g))
        Ys.append(Y)
    return gfg, Ys



def _extend(problem, unknowns_degrees):
    """The problem with the layout holding the curves' higher temperature coefficients."""
    need = coefficient_terms(unknowns_degrees)
    have = tuple(problem.model.options.extra_effects)
    extra = have + tuple(n for n in need if n not in have and n not in problem.model.options.exclude)
    return problem if extra == have else problem.with_effects(extra)


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


def choose_degrees(unknowns, theta, covariance, *, n_measurements):
    """Each curve family's degree by the Wald test against the BIC price (module docstring).

    Returns
    -------
    unknowns : Unknowns
        With the degrees kept.
    keep : ndarray of bool, shape (Nt,)
        Which entries of ``theta`` remain.
    theta, covariance : ndarray
        Conditioned on the dropped coefficients being zero (full size; dropped entries zero).
    choices : tuple of DegreeChoice
    """
    th = np.asarray(theta, dtype=float).copy()
    C = np.asarray(covariance, dtype=float).copy()
    keep = np.ones(th.size, dtype=bool)
    idx = unknowns.z_index()
    price_each = float(np.log(max(int(n_measurements), 2)))
    degrees, choices = dict(unknowns.degrees), []
    for base, d in unknowns.degrees.items():
        elements = [f for f in unknowns.curve_elements() if split_element_name(f)[0] == base]
        tests = []
        while d >= 2:
            D = [idx[curve_label(f, d)] for f in elements]
            cD, CD = th[D], C[np.ix_(D, D)]
            wald = float(cD @ np.linalg.solve(CD, cD))
            price = len(D) * price_each
            tests.append({"order": d, "wald": wald, "k": len(D), "bic_price": price, "kept": wald > price})
            if wald > price:
                break
            G = np.linalg.solve(CD, C[D, :]).T          # C[:, D] CD^-1
            th = th - G @ cD
            C = C - G @ C[D, :]
            C = 0.5 * (C + C.T)
            th[D] = 0.0
            C[D, :] = 0.0
            C[:, D] = 0.0
            keep[D] = False
            d -= 1
        degrees[base] = d
        choices.append(DegreeChoice(family=base, degree=d, tests=tests))
    z_names = tuple(n for n, k in zip(unknowns.z_names, keep[:unknowns.nz]) if k)
    reduced = replace(unknowns, degrees=degrees, z_names=z_names)
    return reduced, keep, th, C, tuple(choices)


def solve_joint(problems, *, options=GraphOptions(), progress=None, initial=None, select_degree=True):
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
    select_degree : bool
        Choose each family's degree by evidence (else keep the registry's highest).

    Returns
    -------
    JointOutput

    Notes
    -----
    BLAS runs on one thread inside the solve: its products are of a few tens of columns (an experiment's
    unknowns), where OpenBLAS's threads gain nothing on two cores and, on a machine shared with other
    work, spin: the Schur complement's ``H_Rt^T (H_RR^-1 H_Rt)`` of a 3 h experiment took 0.4-2.4 s with its
    threads instead of 0.04 s.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _solve_joint(problems, options=options, progress=progress, initial=initial,
                            select_degree=select_degree)


def _solve_joint(problems, *, options, progress, initial, select_degree):
    t_start = time.perf_counter()
    problems = list(problems)
    if not problems:
        raise ValueError("the joint solver needs at least one experiment")
    first = problems[0].model.layout
    from_registry = {b: d for b, d in MAX_DEGREE.items() if b in first}
    problems = [_extend(p, from_registry) for p in problems]
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
    # that Levenberg-Marquardt's isotropic damping and GTSAM's Cholesky see a well-scaled system (unscaled,
    # the damping crawled for 500 iterations on the demo's 72-s subranges and the marginals called the
    # system indeterminate)
    sig_theta = np.concatenate([z_sigma] + list(s_sigmas))
    u0 = theta / sig_theta
    # the graph's factors on the unknowns alone (their priors); every experiment's own factors (its
    # attitudes' prior, rotation, gravity, encoder) enter linearised with its attitudes eliminated
    prior_graph = gtsam.NonlinearFactorGraph()
    prior_graph.add(gtsam.PriorFactorVector(Z(0), np.zeros(nz), gtsam.noiseModel.Unit.Create(nz)))
    values = gtsam.Values()
    values.insert(Z(0), u0[:nz])
    exps, s_keys, s_dims = [], [], []
    have_attitudes = True
    for e, (p, (A, B)) in enumerate(zip(problems, maps)):
        m = p.model
        ns = B.shape[1]
        M_u = np.hstack([A * z_sigma[None, :], B * s_sigmas[e][None, :]])
        u_e = np.concatenate([u0[:nz], u0[offs[e]:offs[e + 1]]])
        x = M_u @ u_e
        preint = m.preintegrate(x)
        R_prior = quat_to_dcm(p.q_nb0)
        ws = starts[e]
        if ws is not None and ws.attitudes is not None and ws.attitudes.shape == (m.n_keyframes + 1, 3, 3):
            R = np.array(ws.attitudes, dtype=float)
        else:
            R = m.propagate(R_prior, preint, x)
            have_attitudes = False
        exps.append(_Experiment(e, m, preint, M_u, nz, R, R_prior))
        if ns:
            prior_graph.add(gtsam.PriorFactorVector(S(e), np.zeros(ns), gtsam.noiseModel.Unit.Create(ns)))
            values.insert(S(e), u0[offs[e]:offs[e + 1]])
            s_keys.append(S(e))
            s_dims.append(ns)
    theta_keys = s_keys + [Z(0)]
    theta_dims = s_dims + [nz]
    ordering = gtsam.Ordering()
    for k in theta_keys:
        ordering.push_back(k)

    def theta_of(v):
        u = np.concatenate([np.asarray(v.atVector(k), dtype=float) for k in [Z(0)] + s_keys])
        return u * sig_theta

    # attitudes dead-reckoned with a warm calibration (every experiment's own solution) stay within the
    # alignment's error of the truth: no fit needed there (graph_calib.solvers.factor_graph._fit_attitudes)
    if not have_attitudes and not all(s is not None for s in starts):
        for _ in range(ATTITUDE_FIT_ITERATIONS):
            moved = 0.0
            for c in exps:
                d = c.linearise(values, c.R, options).attitude_only_step(1e-9)
                c.R = retract(c.R, d)
                moved = max(moved, float(np.max(np.linalg.norm(d, axis=1))))
            if moved < ATTITUDE_FIT_TOL:
                break
    # each experiment's linearised system at `values` (a few tens of MB for 3 h; its factors released)
    systems = [c.linearise(values, c.R, options) for c in exps]
    cost = prior_graph.error(values) + sum(s.cost for s in systems)
    history = [cost]
    lam = options.lambda_initial
    it, converged = 0, False
    # where each experiment's current preintegration was formed; a trial that re-preintegrates an experiment
    # replaces its preintegration (never two held per experiment: 0.3 GB each for 3 h), and a rejected trial
    # is undone by preintegrating again at the same point (the same arrays; rejections are rare)
    lin_x = [c.preint.x_lin for c in exps]

    def restore():
        for c, xl in zip(exps, lin_x):
            if not np.array_equal(c.preint.x_lin, xl):
                c.preint = None
                c.preint = c.model.preintegrate(xl)

    fresh = True
    for it in range(1, options.max_iterations + 1):
        if not fresh:
            restore()
            if systems is None:
                systems = [c.linearise(values, c.R, options) for c in exps]
        prior_lin = prior_graph.linearize(values)
        while True:
            try:
                gfg, Ys = _reduced_graph(exps, systems, prior_lin, lam)
                delta = _damped(gfg, theta_keys, lam, theta_dims).optimize(ordering)
            except RuntimeError:            # numerically indeterminate: damp harder
                if lam > 1e8:
                    raise
                lam = max(lam * 10.0, 1e-6)
                continue
            gfg = None
            R_trial = [retract(c.R, ExperimentSystem.attitude_step(Y, c.theta_of(delta))) for c, Y in zip(exps, Ys)]
            Ys = systems = None     # freed during the trial (0.1 GB for six 3 h experiments), rebuilt if it fails
            trial = values.retract(delta)
            for c in exps:
                x_t = c.x_of(trial)
                if c.preint.needs_repreintegration(x_t, tol=options.repreintegrate_tol):
                    c.preint = None
                    c.preint = c.model.preintegrate(x_t)
            trial_systems = [c.linearise(trial, Rt, options) for c, Rt in zip(exps, R_trial)]
            new_cost = prior_graph.error(trial) + sum(s.cost for s in trial_systems)
            if new_cost <= cost or lam > 1e8 or new_cost - cost <= 1e-10 * cost:
                break
            lam *= 10.0
            trial_systems = None
            restore()
            systems = [c.linearise(values, c.R, options) for c in exps]
        step = np.concatenate([np.asarray(delta.at(Z(0)))] + [np.asarray(delta.at(k)) for k in s_keys])
        accepted = new_cost <= cost
        fresh = accepted
        if accepted:
            values, systems = trial, trial_systems
            for c, Rt in zip(exps, R_trial):
                c.R = Rt
            lin_x = [c.preint.x_lin for c in exps]
            lam = max(lam / 10.0, 1e-9)
        trial_systems = R_trial = None
        rel = (cost - new_cost) / max(cost, 1e-300)
        cost = min(cost, new_cost)
        history.append(cost)
        if progress is not None:
            progress(ProgressEvent(solver=JOINT, iteration=it, cost=float(cost)))
        if accepted and (abs(rel) < options.rel_tol or options.step_tol_sigma > 0
                         and np.all(np.abs(step) < options.step_tol_sigma)):     # the step in sigmas
            converged = True
            break
        if not accepted and (lam > 1e8 or new_cost - cost <= 1e-10 * cost):
            converged = True
            break
    # covariance: an experiment whose calibration moved beyond the first-order range of its preintegration
    # (the solver's own test) is re-preintegrated at the solution, so that its Jacobians hold there; one
    # at a time, the preintegration it replaces freed first
    if systems is None:         # the last trial failed: the systems at the solution were not kept
        systems = [None] * len(exps)
    for i, (c, xl) in enumerate(zip(exps, lin_x)):
        x_c = c.x_of(values)
        if (not np.array_equal(c.preint.x_lin, xl)
                or c.preint.needs_repreintegration(x_c, tol=options.repreintegrate_tol)):
            c.preint = None
            c.preint = c.model.preintegrate(x_c)
            systems[i] = None
        if systems[i] is None:
            systems[i] = c.linearise(values, c.R, options)
    attitudes = [c.R for c in exps]
    whitened = [s.whitened for s in systems]
    n_meas = int(sum(3 * (w[1].shape[0] + w[2].shape[0]) for w in whitened))
    tkeys = [Z(0)] + s_keys
    # the graph linearised at the solution, every attitude eliminated; in GTSAM's units (prior sigmas), back to SI
    gfg, _ = _reduced_graph(exps, systems, prior_graph.linearize(values), 0.0)
    systems = None
    cov = unknowns_covariance(gfg, [], tkeys) * np.outer(sig_theta, sig_theta)
    gfg = None
    theta = theta_of(values)
    if select_degree:
        reduced, keep, th_c, cov_c, choices = choose_degrees(unknowns, theta, cov, n_measurements=n_meas)
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
            attitudes=attitudes[e],
            residuals={"rotation": ResidualSeries(t=m.t_key[1:].copy(), values=whitened[e][0]),
                       "gravity": ResidualSeries(t=m.t_key[:-1].copy(), values=whitened[e][1]),
                       "encoder": ResidualSeries(t=m.record.reading_t.copy(), values=whitened[e][2])},
            residual_quantity=WHITENED_RESIDUAL, iterations=it, converged=bool(converged),
            final_cost=float(cost), seconds=seconds))
    names = reduced.z_names + tuple(f"{e}/{n}" for e, s in enumerate(reduced.setup_names) for n in s)
    return JointOutput(unknowns=reduced, theta_names=names, theta=theta_r, covariance=0.5 * (cov_r + cov_r.T),
                       outputs=tuple(outputs), degree_choices=choices, n_measurements=n_meas, iterations=it,
                       converged=bool(converged), final_cost=float(cost), seconds=seconds, cost_history=history)


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
