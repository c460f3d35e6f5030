r"""The joint campaign solver: every experiment of a campaign in one factor graph (GTSAM).

Variables: the keyframe attitudes of every experiment (``Rot3``), the shared unknowns ``Z(0)`` (the
temperature curves' coefficients and the shared elements, :mod:`graph_calib.joint.unknowns`) and each
experiment's set-up ``S(e)`` (mount, lever arm, table lag, damper stiffness where its layout has them).
Each experiment keeps its own :class:`graph_calib.model.CalibrationModel`, its layout extended by the
curves' higher temperature coefficients; its calibration vector is ``x_e = A_e z + B_e s_e`` (exact: a
polynomial's Taylor expansion at ``T_ref``), so its factors are the model's own (rotation, gravity,
encoder) with the parameter Jacobians chained, ``H_z = H_x A_e``, ``H_s = H_x B_e``.  Priors: the
grade's (or the manifest's) prior of each unknown, once: a curve coefficient of order ``j`` takes the
prior of the family's ``*_tc<j>`` about ``t0``; the alignment of each experiment's first attitude.

The Levenberg-Marquardt loop is :mod:`graph_calib.factor_graph`'s: our own around ``graph.linearize``,
the factors read from one vectorised cache per experiment (that module's), each experiment
re-preintegrated when its own calibration moves too far from its preintegration point.

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
from functools import partial

import gtsam
import numpy as np
from gtsam.symbol_shorthand import S, X, Z

from graph_calib.factor_graph import ATTITUDE_FIT_ITERATIONS, ATTITUDE_FIT_TOL, _Cache, _damped, _noise
from graph_calib.joint.marginal import unknowns_covariance
from graph_calib.joint.unknowns import MAX_DEGREE, Unknowns, coefficient_terms, curve_label, family_member, plan_unknowns
from graph_calib.options import GraphOptions
from graph_calib.params import Layout, split_element_name
from graph_calib.rotations import quat_to_dcm
from graph_calib.solvers.interface import WHITENED_RESIDUAL, ProgressEvent, ResidualSeries, SolverOutput

#: Name of the solver (entry point ``graph_calib.solvers``).
JOINT = "joint"
#: Keys of experiment ``e``'s attitudes: ``X(e * KEY_STRIDE + k)``.
KEY_STRIDE = 10**8


def _xkey(e, k):
    return X(e * KEY_STRIDE + k)


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
    unknowns : graph_calib.joint.unknowns.Unknowns
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


class _JointCache(_Cache):
    """One experiment's factors at one set of values (:class:`graph_calib.factor_graph._Cache`), read from
    its own keys; the callbacks chain the parameter Jacobians onto ``z`` and ``s_e`` factor by factor
    (``H_x A``, ``H_x B``: storing them chained for every factor would hold another 160 MB per 3-h
    experiment)."""

    def __init__(self, e, model, preint, A, B):
        super().__init__(model, preint)
        self.e, self.A, self.B = e, A, B
        self.has_setup = B.shape[1] > 0

    def x_of(self, z, s):
        return self.A @ z + (self.B @ s if self.has_setup else 0.0)

    def release(self):
        """Drop the evaluated factors (about 0.17 GB for 3 h): GTSAM's linear system holds them now; the next
        call into GTSAM evaluates again."""
        self.R = None
        self.rot = self.grav = self.enc = None

    def _read(self, values):
        R = np.empty((self.K + 1, 3, 3))
        for k in range(self.K + 1):
            R[k] = values.atRot3(_xkey(self.e, k)).matrix()
        z = np.asarray(values.atVector(Z(0)), dtype=float)
        s = np.asarray(values.atVector(S(self.e)), dtype=float) if self.has_setup else np.zeros(0)
        return R, self.x_of(z, s)

    def chained(self, kind):
        """``(H_z (F, 3, nz), H_s (F, 3, ns))`` of every factor ``kind`` (``rot``, ``grav``, ``enc``), at once."""
        H = getattr(self, kind).H_x
        flat = H.reshape(-1, H.shape[-1])
        return (flat @ self.A).reshape(H.shape[0], 3, -1), (flat @ self.B).reshape(H.shape[0], 3, -1)


def _rotation_error(cache, k, this, values, H):
    cache.ensure(values)
    f = cache.rot
    if H is not None:
        H[0] = f.H_R[k]
        H[1] = f.H_R_next[k]
        H[2] = f.H_x[k] @ cache.A
        if cache.has_setup:
            H[3] = f.H_x[k] @ cache.B
    return f.r[k]


def _gravity_error(cache, k, this, values, H):
    cache.ensure(values)
    f = cache.grav
    if H is not None:
        H[0] = f.H_R[k]
        H[1] = f.H_x[k] @ cache.A
        if cache.has_setup:
            H[2] = f.H_x[k] @ cache.B
    return f.r[k]


def _encoder_error(cache, lo, hi, this, values, H):
    cache.ensure(values)
    f = cache.enc
    if H is not None:
        Hx = f.H_x[lo:hi].reshape(-1, f.H_x.shape[2])
        H[0] = f.H_R[lo:hi].reshape(-1, 3)
        H[1] = Hx @ cache.A
        if cache.has_setup:
            H[2] = Hx @ cache.B
    return f.r[lo:hi].reshape(-1)


def _add_experiment(graph, cache, *, R_prior, s_sigma, robust, robust_k):
    """Experiment ``cache.e``'s factors: its first attitude's prior, its set-up's prior, the model's factors."""
    e, m = cache.e, cache.model
    graph.add(gtsam.PriorFactorRot3(_xkey(e, 0), gtsam.Rot3(R_prior),
                                    gtsam.noiseModel.Isotropic.Sigma(3, m.initial_attitude_sigma)))
    theta = [Z(0)]
    if s_sigma.size:
        graph.add(gtsam.PriorFactorVector(S(e), np.zeros(s_sigma.size), gtsam.noiseModel.Diagonal.Sigmas(s_sigma)))
        theta.append(S(e))
    for k in range(m.n_keyframes):
        graph.add(gtsam.CustomFactor(gtsam.noiseModel.Diagonal.Sigmas(cache.rot.sigma[k]),
                                     [_xkey(e, k), _xkey(e, k + 1)] + theta, partial(_rotation_error, cache, k)))
        graph.add(gtsam.CustomFactor(_noise(cache.grav.sigma[k], robust, robust_k), [_xkey(e, k)] + theta,
                                     partial(_gravity_error, cache, k)))
    keys = cache.enc.key
    if keys.size:
        bounds = np.flatnonzero(np.diff(keys)) + 1
        for lo, hi in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [keys.size]])):
            k_m = robust_k * np.sqrt(hi - lo)     # as in graph_calib.factor_graph.build_graph
            graph.add(gtsam.CustomFactor(_noise(cache.enc.sigma[lo:hi].reshape(-1), robust, k_m),
                                         [_xkey(e, int(keys[lo]))] + theta,
                                         partial(_encoder_error, cache, int(lo), int(hi))))


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
    layout : graph_calib.params.Layout
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
        """From a result file's values and sigmas (:class:`graph_calib.experiment.Result`)."""
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


def _fit_attitudes(graph, caches, values, *, x_keys, theta_keys, theta_dims, ordering):
    """:func:`graph_calib.factor_graph._fit_attitudes` over every experiment: attitudes only, unknowns held."""
    holds = [gtsam.JacobianFactor(k, 1e8 * np.eye(d), np.zeros(d), gtsam.noiseModel.Unit.Create(d))
             for k, d in zip(theta_keys, theta_dims)]
    held = {k: np.asarray(values.atVector(k), dtype=float) for k in theta_keys}
    for _ in range(ATTITUDE_FIT_ITERATIONS):
        for c in caches:
            c.invalidate()
        gfg = _damped(graph.linearize(values), x_keys, 1e-9, [3] * len(x_keys))
        for h in holds:
            gfg.add(h)
        delta = gfg.optimize(ordering)
        moved = max(float(np.linalg.norm(delta.at(k))) for k in x_keys)
        values = values.retract(delta)
        for k, v in held.items():
            values.update(k, v)
        if moved < ATTITUDE_FIT_TOL:
            break
    return values


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
    problems : sequence of graph_calib.problem.Problem
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
    """
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
    maps_u = [(A * z_sigma[None, :], B * s_sigmas[e][None, :]) for e, (A, B) in enumerate(maps)]
    u0 = theta / sig_theta
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorVector(Z(0), np.zeros(nz), gtsam.noiseModel.Unit.Create(nz)))
    values = gtsam.Values()
    values.insert(Z(0), u0[:nz])
    caches, x_keys, s_keys, s_dims = [], [], [], []
    have_attitudes = True
    for e, (p, (A, B)) in enumerate(zip(problems, maps_u)):
        m = p.model
        s0 = u0[offs[e]:offs[e + 1]]
        x = A @ theta[:nz] + (B @ s0 if B.shape[1] else 0.0)
        preint = m.preintegrate(x)
        R_prior = quat_to_dcm(p.q_nb0)
        ws = starts[e]
        if ws is not None and ws.attitudes is not None and ws.attitudes.shape == (m.n_keyframes + 1, 3, 3):
            R = np.asarray(ws.attitudes, dtype=float)
        else:
            R = m.propagate(R_prior, preint, x)
            have_attitudes = False
        cache = _JointCache(e, m, preint, A, B)
        cache.evaluate(R, x)
        caches.append(cache)
        _add_experiment(graph, cache, R_prior=R_prior, s_sigma=np.ones(B.shape[1]), robust=options.robust,
                        robust_k=options.robust_k)
        for k in range(m.n_keyframes + 1):
            values.insert(_xkey(e, k), gtsam.Rot3(R[k]))
            x_keys.append(_xkey(e, k))
        if B.shape[1]:
            values.insert(S(e), s0)
            s_keys.append(S(e))
            s_dims.append(B.shape[1])
    theta_keys = s_keys + [Z(0)]
    theta_dims = s_dims + [nz]
    keys = x_keys + theta_keys
    dims = [3] * len(x_keys) + theta_dims
    ordering = gtsam.Ordering()
    for k in keys:
        ordering.push_back(k)

    def invalidate():
        for c in caches:
            c.invalidate()

    def theta_of(v):
        u = np.concatenate([np.asarray(v.atVector(Z(0)), dtype=float)]
                           + [np.asarray(v.atVector(S(c.e)), dtype=float) for c in caches if c.B.shape[1]])
        return u * sig_theta

    def x_of(v, c):
        s = np.asarray(v.atVector(S(c.e)), dtype=float) if c.B.shape[1] else np.zeros(0)
        return c.x_of(np.asarray(v.atVector(Z(0)), dtype=float), s)

    # attitudes dead-reckoned with a warm calibration (every experiment's own solution) stay within the
    # alignment's error of the truth: no fit needed there (it costs a linearisation of the whole graph per pass)
    if not have_attitudes and not all(s is not None for s in starts):
        values = _fit_attitudes(graph, caches, values, x_keys=x_keys, theta_keys=theta_keys,
                                theta_dims=theta_dims, ordering=ordering)
        invalidate()
    # (else the caches already hold every factor at `values`: evaluated when the graph was built)
    cost = graph.error(values)
    history = [cost]
    lam = options.lambda_initial
    it, converged = 0, False
    # where each experiment's current preintegration was formed; a trial that re-preintegrates an experiment
    # replaces its preintegration (never two held per experiment: 0.3 GB each for 3 h), and a rejected trial
    # is undone by preintegrating again at the same point (the same arrays; rejections are rare)
    lin_x = [c.preint.x_lin for c in caches]

    def restore():
        for c, xl in zip(caches, lin_x):
            if not np.array_equal(c.preint.x_lin, xl):
                c.preint = None
                c.preint = c.model.preintegrate(xl)
        invalidate()

    # the caches hold every factor (residuals and Jacobians) at `values` after the cost of the starting point
    # and after an accepted step: the next linearisation reads them (a 3-h experiment's factors cost seconds
    # to evaluate; factor_graph.solve evaluates them again there)
    fresh = True
    for it in range(1, options.max_iterations + 1):
        if not fresh:
            restore()
        gfg = graph.linearize(values)
        for c in caches:
            c.release()
        while True:
            try:
                delta = _damped(gfg, keys, lam, dims).optimize(ordering)
            except RuntimeError:            # numerically indeterminate: damp harder
                if lam > 1e8:
                    raise
                lam = max(lam * 10.0, 1e-6)
                continue
            gfg = None                      # the linear system freed during the trial, rebuilt if it fails
            trial = values.retract(delta)
            for c in caches:
                x_t = x_of(trial, c)
                if c.preint.needs_repreintegration(x_t, tol=options.repreintegrate_tol):
                    c.preint = None
                    c.preint = c.model.preintegrate(x_t)
            invalidate()
            new_cost = graph.error(trial)
            if new_cost <= cost or lam > 1e8 or new_cost - cost <= 1e-10 * cost:
                break
            lam *= 10.0
            restore()
            gfg = graph.linearize(values)
            for c in caches:
                c.release()
        step = np.concatenate([np.asarray(delta.at(Z(0)))] + [np.asarray(delta.at(k)) for k in s_keys])
        accepted = new_cost <= cost
        fresh = accepted
        if accepted:
            values = trial
            lin_x = [c.preint.x_lin for c in caches]
            lam = max(lam / 10.0, 1e-9)
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
    gfg = None
    # covariance: an experiment whose calibration moved beyond the first-order range of its preintegration
    # (the solver's own test) is re-preintegrated at the solution, so that its Jacobians hold there; one
    # at a time, the preintegration it replaces freed first
    moved = False
    for c, xl in zip(caches, lin_x):
        x_c = x_of(values, c)
        if (not np.array_equal(c.preint.x_lin, xl)
                or c.preint.needs_repreintegration(x_c, tol=options.repreintegrate_tol)):
            c.preint = None
            c.preint = c.model.preintegrate(x_c)
            moved = True
    if moved or not fresh:      # else the caches hold every factor at the solution (its accepted trial)
        invalidate()
    gfg = graph.linearize(values)      # every factor evaluated at the solution: keep what the outputs need
    attitudes = [c.R for c in caches]
    whitened = [(c.rot.whitened(), c.grav.whitened(), c.enc.whitened()) for c in caches]
    n_meas = int(sum(3 * (c.grav.r.shape[0] + c.enc.r.shape[0]) for c in caches))
    for c in caches:
        c.release()
    tkeys = [Z(0)] + s_keys
    # in GTSAM's units (prior sigmas), back to SI
    cov = unknowns_covariance(gfg, x_keys, tkeys) * np.outer(sig_theta, sig_theta)
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
    for e, c in enumerate(caches):
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
    """The joint campaign solver behind the solver interface (registered as ``"joint"``).

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
