r"""A staged solve when the gyro model does not fit: the accelerometer from gravity alone, then the gyro given it.

Without a table the attitudes of the rests come from two kinds of measurement: gravity (their tilt) and the gyro
integrals between keyframes (their relative attitudes).  When the gyro model fits, both agree and the joint solve is
the best estimate of everything.  When it does not (an unmodelled g-sensitivity, a bias drift), the gyro's
*systematic* misfit tilts the attitudes, and the accelerometer calibration follows them: a variance factor on the
rotation kind deweights the misfit's noise, not its pull (docs/crossval.md measures the accelerometer's held-out
|f| spread ten times that of a gravity-only fit).  So, on a table-less record:

1. The gate: the rotation or the gravity kind's variance factor (:mod:`graph_calib.solvers.variance`) above
   :data:`graph_calib.solvers.verdict.VARIANCE_FACTOR_LIMIT`, the verdict's own limit (the variance components may
   put a gyro misfit on either kind: it tilts the attitudes, and the gravity residuals grow with it).  A record whose
   factors are within the limit is solved as before (no extra solve, the same result).
2. The gravity-only stage: the same problem with the rotation kind's factor :data:`GRAVITY_ONLY_FACTOR` (the gyro
   integrals hardly weigh), solved by the primary solver; its gravity factor is the joint solve's when that is within
   the limit (one solve more), and estimated anew when it is not (the joint solve's then carries the gyro's misfit)
   or when the test stages the solve (the accelerometer's covariance is then that stage's own).  Where it keeps the
   joint's factor, one linearisation of it at the joint solution comes first (:func:`screen_statistic`, the
   test's statistic to first order): far below the threshold (:data:`SCREEN_FRACTION`), the stage is not solved
   and the record is solved as before.
3. The test: the accelerometer elements that stage informs (posterior sigma below
   :data:`graph_calib.solvers.results.PRIOR_DOMINATED_RATIO` of the prior) are compared between the joint solution
   and the gravity-only one, ``d^T C_g^{-1} d`` with ``C_g`` the gravity-only covariance, against the chi-square
   quantile ``1 -`` :data:`STAGE_ALPHA` of as many degrees of freedom.  Were both models right, ``d``'s
   covariance would be ``C_g - C_joint``, smaller than ``C_g``: the statistic is then below a chi-square, and the
   test rarely fires wrongly.  Not significant: the joint solve is kept (the gyro's misfit does not reach the
   accelerometer).
4. The staged solve: every solver solves the problem whose prior pins those accelerometer elements at the
   gravity-only values (a sigma :data:`PIN_RATIO` times theirs): the gyro, the attitudes and whatever else is
   calibrated given the accelerometer of stage 2.  Each solver's output is then made honest
   (:meth:`Staging.finish`): the pinned elements take the gravity-only covariance ``C_g``, and what the staged solve
   estimated given them takes it over linearly (``S = Sigma_oa Sigma_aa^-1``, the staged covariance's own
   sensitivity of the others to the pinned elements: ``C_oa = S C_g``,
   ``C_oo = Sigma_oo - S Sigma_aa S^T + S C_g S^T``).  The result is made with the problem's own priors (the pin is
   no prior belief) and says what was done (``staged``); the verdict says in words that the gyro model does not fit.

Both solvers solve the same pinned problem and their outputs are finished the same way, so they agree as before.
A record with a table is never staged: the encoders, not the gyro integrals, hold its attitudes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.special import gammaincinv    # not scipy.stats: 0.3 s of every command's start (docs/performance.md)

from graph_calib.model import CalibrationModel
from graph_calib.model.normal_equations import add_prior, linearise
from graph_calib.solvers.registry import solve
from graph_calib.solvers.results import PRIOR_DOMINATED_RATIO
from graph_calib.solvers.variance import FACTOR_MAX, estimate_variance_components, with_variance_factors
from graph_calib.solvers.verdict import VARIANCE_FACTOR_LIMIT

#: The rotation kind's variance factor of the gravity-only stage (its sigmas 100 times the gyro noise's).
GRAVITY_ONLY_FACTOR = FACTOR_MAX
#: Probability of the test firing on a record whose models both fit (at most, were the noise model exact; module doc).
#: Smaller than the verdict's 1e-3: the noise model's approximations (a sway taken for white noise, short rests)
#: stretch the statistic on right models (32.9 on a simulated Ferraris fold, 10 elements: 1e-3's quantile 29.6, this
#: level's 46.9), while a pull that spoils the accelerometer held out gives thousands (docs/crossval.md).
STAGE_ALPHA = 1e-6
#: The screen (:func:`screen_statistic`) skips the gravity-only stage when its one-step statistic is below this
#: fraction of the test's threshold.  Where the stage keeps the joint's gravity factor the screen's statistic was
#: within 0.9-1.1 of the solved one on 40 simulated hand-held folds and the Xsens session (docs/crossval.md).
SCREEN_FRACTION = 0.1
#: A pinned element's prior sigma, as a fraction of its gravity-only sigma.
PIN_RATIO = 1e-3
#: The sensor whose calibration the gravity-only stage gives.
PINNED_PREFIX = "accel."


@dataclass(frozen=True)
class Staging:
    """What the gate, the gravity-only stage and the test concluded (module doc).

    Attributes
    ----------
    rotation_factor, gravity_factor : float
        The joint solve's variance factors of the rotation and the gravity kind (one of them opened the gate).
    elements : tuple of str
        The accelerometer elements pinned when staged (those the gravity-only stage with its own gravity factor
        informs), else those compared.
    statistic : float
        ``d^T C_g^-1 d`` over ``elements``.
    threshold : float
        Its chi-square quantile (:data:`STAGE_ALPHA`, ``dof`` degrees of freedom).
    dof : int
        The number of accelerometer elements the test compared (those the gravity-only stage informs).
    staged : bool
        Whether the statistic exceeds the threshold: the solvers then solve :attr:`problem`.
    problem : graph_calib.records.problem.Problem
        What the solvers solve: with the pinning prior and the staged solve's variance factors (the weighted
        problem itself when not staged).
    result_problem : graph_calib.records.problem.Problem
        What the results are made with: :attr:`problem` with the record's own priors (the pin is no prior belief).
    initial : tuple (R, x)
        Where the primary solver's staged solve starts.
    x, covariance : ndarray
        The gravity-only solution's calibration and covariance, layout order.
    index : ndarray of int
        ``elements``' positions in the layout.
    """

    rotation_factor: float
    gravity_factor: float
    elements: tuple
    statistic: float
    threshold: float
    dof: int
    staged: bool
    problem: object
    result_problem: object
    initial: tuple
    x: np.ndarray
    covariance: np.ndarray
    index: np.ndarray

    def finish(self, output):
        """``output`` (a staged solve's) with the honest covariance of the module doc (``x`` as solved)."""
        a = self.index
        o = np.setdiff1d(np.arange(output.x.size), a)
        sigma = np.asarray(output.covariance, dtype=float)
        saa, soa, soo = sigma[np.ix_(a, a)], sigma[np.ix_(o, a)], sigma[np.ix_(o, o)]
        S = np.linalg.solve(saa, soa.T).T                    # Sigma_oa Sigma_aa^-1 (Sigma_aa symmetric)
        cg = self.covariance[np.ix_(a, a)]
        cov = np.empty_like(sigma)
        cov[np.ix_(a, a)] = cg
        cov[np.ix_(o, a)] = S @ cg
        cov[np.ix_(a, o)] = (S @ cg).T
        cov[np.ix_(o, o)] = soo - S @ saa @ S.T + S @ cg @ S.T
        return replace(output, covariance=0.5 * (cov + cov.T))

    def to_json(self):
        """The result file's ``staged`` block."""
        return {"rotation_variance_factor": float(self.rotation_factor),
                "gravity_variance_factor": float(self.gravity_factor), "staged": bool(self.staged),
                "statistic": float(self.statistic), "threshold": float(self.threshold),
                "dof": int(self.dof), "gravity_only_rotation_factor": float(GRAVITY_ONLY_FACTOR),
                "pinned": list(self.elements) if self.staged else []}


def gyro_misfit_gate(problem, *, fixed=()):
    """Whether ``problem`` (with its variance factors) is one the staging looks at (module doc).

    No table, the rotation kind's factor not fixed by the caller (``fixed``), and the rotation or the gravity kind's
    factor above :data:`graph_calib.solvers.verdict.VARIANCE_FACTOR_LIMIT`: the variance components may put a gyro
    misfit on either kind (it tilts the attitudes, so the gravity residuals grow with it).
    """
    factors = problem.model.options.variance_factors or {}
    return (not problem.model.record.has_table and "rotation" not in set(fixed)
            and max(float(factors.get(k, 1.0)) for k in ("rotation", "gravity")) > VARIANCE_FACTOR_LIMIT)


def stage(problem, *, options, solver, initial=None, fixed=(), progress=None):
    """The gravity-only stage, the test, and the staged problem on ``problem`` (the weighted problem; module doc).

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
        With the variance factors estimated (:func:`graph_calib.solvers.variance.weighted_problem`).
    options : graph_calib.options.CalibrationOptions
    solver : str
        The primary solver, which solves the stages.
    initial : tuple (R, x), optional
        The joint solution (the variance components' last): the test's other side.
    fixed : iterable of str
        The kinds whose variance factor the caller set (kept in every stage).
    progress : callable, optional

    Returns
    -------
    Staging or None
        None when the gate is closed (:func:`gyro_misfit_gate`).
    """
    fixed = tuple(fixed)
    if not gyro_misfit_gate(problem, fixed=fixed):
        return None
    factors = dict(problem.model.options.variance_factors or {})
    if initial is None:
        joint = solve(solver, problem, options=options, progress=progress)
        initial = (joint.attitudes, joint.x)
    gravity_only = with_variance_factors(problem, {**factors, "rotation": GRAVITY_ONLY_FACTOR})

    def gravity_stage(estimate):
        """The gravity-only solution, its gravity factor estimated anew when ``estimate`` (else the joint one's)."""
        if not estimate:
            return solve(solver, gravity_only, options=options, progress=progress, initial=initial), None
        vc = estimate_variance_components(gravity_only, options=options, solver=solver,
                                          fixed=fixed + ("rotation",), progress=progress, initial=initial)
        return solve(solver, vc.problem, options=options, progress=progress, initial=vc.initial), vc

    # the joint solve's gravity factor is kept for the test when within the limit (one solve more; the rotation kind
    # opened the gate) and estimated anew when not (it then carries the gyro's misfit): the accelerometer of a
    # staged solve always takes a gravity-only stage with its own factor
    reestimate = float(factors.get("gravity", 1.0)) > VARIANCE_FACTOR_LIMIT
    if not reestimate:
        # the stage would keep the joint's weights: its statistic to first order decides whether to solve it
        screen, screen_dof = screen_statistic(gravity_only, initial=initial, options=options)
        if screen_dof == 0 or screen < SCREEN_FRACTION * chi2_quantile(screen_dof):
            return None
    gravity, vc = gravity_stage(reestimate)
    model = problem.model
    _, prior = model.prior()
    names = gravity.layout.element_names()

    def informed(output):
        return informed_accel(names, output.sigma, prior)

    index = informed(gravity)
    if index.size == 0:
        return None
    d = np.asarray(initial[1], dtype=float)[index] - gravity.x[index]
    cg = gravity.covariance[np.ix_(index, index)]
    statistic = float(d @ np.linalg.solve(cg, d))
    threshold = chi2_quantile(index.size)
    staged = statistic > threshold
    dof = int(index.size)
    if staged and vc is None:
        gravity, vc = gravity_stage(True)
        index = informed(gravity)
        staged = index.size > 0
    result_problem, start = problem, (gravity.attitudes, gravity.x)
    sig = gravity.sigma
    if staged:
        # the staged solve's own variance factors, the accelerometer held at the gravity-only stage's
        start_factors = {**factors, "gravity": vc.factors.get("gravity", factors.get("gravity", 1.0))}
        pinned = pinned_problem(with_variance_factors(problem, start_factors, moving_sigma=vc.moving_sigma),
                                gravity.x, sig, index)
        vc2 = estimate_variance_components(pinned, options=options, solver=solver, fixed=fixed, progress=progress,
                                           initial=start)
        problem_solved, start = vc2.problem, vc2.initial
        o = model.options
        result_problem = replace(problem, model=CalibrationModel.from_record(
            model.record, options=replace(problem_solved.model.options, prior_mean=o.prior_mean,
                                          prior_sigma=o.prior_sigma)))
    else:
        problem_solved = problem
    return Staging(rotation_factor=factors.get("rotation", 1.0), gravity_factor=factors.get("gravity", 1.0),
                   elements=tuple(names[i] for i in index), statistic=statistic, threshold=threshold, dof=dof,
                   staged=staged,
                   problem=problem_solved, result_problem=result_problem, initial=start,
                   x=np.asarray(gravity.x, dtype=float), covariance=np.asarray(gravity.covariance, dtype=float),
                   index=index)


def informed_accel(names, sigma, prior_sigma):
    """Positions of the accelerometer elements whose ``sigma`` is below
    :data:`graph_calib.solvers.results.PRIOR_DOMINATED_RATIO` of their ``prior_sigma`` (those gravity informs)."""
    return np.array([i for i, n in enumerate(names)
                     if n.startswith(PINNED_PREFIX) and sigma[i] < PRIOR_DOMINATED_RATIO * prior_sigma[i]], dtype=int)


def chi2_quantile(dof):
    """The chi-square quantile ``1 -`` :data:`STAGE_ALPHA` of ``dof`` degrees of freedom (``chi2.ppf``)."""
    return float(2.0 * gammaincinv(0.5 * dof, 1.0 - STAGE_ALPHA))


def screen_statistic(gravity_only, *, initial, options):
    """The test's statistic to first order: one Gauss-Newton step of the gravity-only problem from the joint solution.

    At the joint solution ``(R, x)`` the gravity-only problem (``gravity_only``, its rotation kind deweighted) is
    linearised once, the attitudes eliminated; its step ``dx`` and the inverse ``C`` of its reduced information
    (the calibration prior included) stand for ``x_g - x`` and ``C_g``, and the statistic is
    ``dx_a^T C_aa^-1 dx_a`` over the accelerometer elements ``C`` informs (as :func:`stage` selects them).  One
    linearisation instead of a solve: where it is far below the threshold (:data:`SCREEN_FRACTION`) the stage
    cannot change the answer; near it, or above, :func:`stage` solves the stage and judges by the solved statistic.

    Returns
    -------
    statistic : float
    dof : int
        The number of accelerometer elements compared.
    """
    model = gravity_only.model
    R, x = initial
    R, x = np.asarray(R, dtype=float), np.asarray(x, dtype=float)
    system = linearise(model, model.preintegrate(x), R, x, R_prior=model.segment_priors(gravity_only.q_nb0),
                       robust=options.graph.robust, robust_k=options.graph.robust_k)
    A, b, _ = system.reduce(0.0, definite=False)
    A, b = A.copy(), b.copy()
    add_prior(A, b, model.calibration_prior(x), np.arange(x.size))
    C = np.linalg.inv(0.5 * (A + A.T))
    dx = -C @ b
    _, prior_sigma = model.prior()
    a = informed_accel(model.layout.element_names(), np.sqrt(np.diag(C)), prior_sigma)
    if a.size == 0:
        return 0.0, 0
    return float(dx[a] @ np.linalg.solve(C[np.ix_(a, a)], dx[a])), int(a.size)


def pinned_problem(problem, x, sigma, index):
    """``problem`` whose calibration prior holds the elements ``index`` at ``x`` with :data:`PIN_RATIO` ``* sigma``."""
    model = problem.model
    mean, prior = model.prior()
    mean, prior = mean.copy(), prior.copy()
    mean[index] = np.asarray(x, dtype=float)[index]
    prior[index] = PIN_RATIO * np.asarray(sigma, dtype=float)[index]
    layout = model.layout
    touched = {n for n in layout.names if np.intersect1d(np.arange(layout.size)[layout.slice(n)], index).size}
    o = model.options
    options = replace(o, prior_mean={**(o.prior_mean or {}), **{n: mean[layout.slice(n)] for n in touched}},
                      prior_sigma={**(o.prior_sigma or {}), **{n: prior[layout.slice(n)] for n in touched}})
    return replace(problem, model=CalibrationModel.from_record(model.record, options=options))


__all__ = ["Staging", "stage", "gyro_misfit_gate", "pinned_problem", "screen_statistic", "chi2_quantile",
           "SCREEN_FRACTION", "GRAVITY_ONLY_FACTOR",
           "STAGE_ALPHA", "PIN_RATIO"]
