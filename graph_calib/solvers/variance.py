r"""Variance components: one variance factor per measurement kind, estimated with the solve.

The noise the solvers use is identified from the record (:mod:`graph_calib.noise`), but each kind of
factor approximates what that noise does to it (a hand's sway reaches the gravity factors; a dwell's
scatter cannot show the table's unread direction, whose variance is a floor).  Helmert's and Förstner's
variance component estimation rescales each component's covariance by its ``chi2 / redundancy``
(:func:`graph_calib.model.redundancy.fit_statistics`) and solves again, until every factor has settled:
each component's ``chi2 / redundancy`` is then 1 and the sigmas follow from the data, neither optimistic nor
pessimistic.  A kind whose residuals the free attitudes partly absorb answers a factor ``f`` as
``c / f^a`` with ``a < 1``: after the first Helmert step ``a`` is taken from the last
two solves (a secant in logarithms, ``a`` in ``[MIN_EXPONENT, 1]``), so that two or three solves do.

The components are not the kinds one for one.  A table reading's variance has three parts: its own noise
(factor ``encoder``), the floor of a floored component (factor :data:`FLOORED`, from its own Förstner step,
:func:`_floor_step`) and the gyro's noise from the keyframe, which is the rotation factors' noise and takes
their factor (``rotation``: the gyro's).  Each factor is estimated from the share of every residual
component's variance that its part makes (:attr:`graph_calib.model.redundancy.FitStatistics.components`), so
the rotation kind's own ``chi2 / redundancy`` scatters about 1 as a chi-square of its redundancy does instead of
being forced to it (docs/model.md, "The noise of a table reading").

This is an outer iteration around any registered solver (solve, rescale, re-solve from the previous
solution), so that it does not depend on a solver's internals; the factors live in the model's
:class:`graph_calib.model.factors.Noise` (``ModelOptions.variance_factors``), so every solver that then
solves the problem uses the same ones.  A kind whose redundancy is below :data:`MIN_REDUNDANCY` keeps its
factor (too few degrees of freedom to estimate one), and so does a kind the caller fixes; one below
:data:`MIN_LOWERING_REDUNDANCY` has its factor raised where its residuals ask, never lowered below 1; no factor goes
below :data:`FACTOR_MIN` or above :data:`FACTOR_MAX`.

Moving keyframes.  Without a table the gravity factor of a keyframe in motion has the sigma
``ModelOptions.moving_sigma`` (default 1 m/s^2), a guess at what the hand's own acceleration adds.  With
``ModelOptions(moving_sigma="estimate")`` (``--moving-sigma estimate``) it is estimated the same way, from
the moving keyframes' own ``chi2 / redundancy`` (the pseudo-kind :data:`graph_calib.model.redundancy.MOVING`),
within :data:`MOVING_SIGMA_BOUNDS`: a hand that turns the unit about itself accelerates it by a few cm/s^2,
and a guess twenty times that leaves the attitude in a turn, and so the gyro's cross-axis terms, to the
rotation factors alone.  Not the default: on the MPU-6050 session it
settles at 0.09 m/s^2 and the held-out transitions (two folds by pairs) grow from 2.24 to 3.61 deg while the
|f| spread falls from 0.126 to 0.082 m/s^2 (measured while every rest shorter than two keyframes had keyframes of its
own; by default, as on main, 2.48 deg and 0.155 m/s^2).  Whether the moving keyframes' sigma is the guess or
estimated, the gravity kind's factor is estimated from the static keyframes' ``chi2 / redundancy`` alone: the
moving rows' sigma does not follow it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from graph_calib.model import CalibrationModel
from graph_calib.model.redundancy import FLOORED, MOVING, fit_statistics, static_gravity
from graph_calib.records.problem import MOVING_ESTIMATED
from graph_calib.solvers.registry import PRIMARY_SOLVER, loose, solve

#: The kinds that get a factor.
KINDS = ("rotation", "gravity", "encoder")
#: Least redundancy of a kind whose factor is estimated.
MIN_REDUNDANCY = 10.0
#: Least redundancy of a kind whose factor may go below 1 (its estimate scatters by about ``sqrt(2 / redundancy)``,
#: 20 % here).  Below it the factor only rises: a low ``chi2 / redundancy`` of so few degrees of freedom is as likely
#: their scatter as an overstated noise, and a factor below 1 would make the sigmas optimistic; a high one is a misfit
#: the sigmas must follow.  On the simulated consumer Ferraris sessions the rotation kind keeps a redundancy of about
#: 23 of its 390 components (the rests' gravity holds the attitudes), its ``chi2 / redundancy`` barely answers its
#: factor, and the iteration drove it to 0.16 where the gyro noise is the simulated one.
MIN_LOWERING_REDUNDANCY = 50.0
#: The iteration stops when no kind's chi2 / redundancy is further than this from 1.
TOLERANCE = 0.05
#: At most this many solves.
MAX_SOLVES = 5
#: No factor below this: a record without noise (a noise-free simulation) has no chi-square to scale by, and
#: factors driven to zero would leave the solvers a singular system.
FACTOR_MIN = 1e-2
#: No factor above this (100 times the identified sigma): a swaying hand's gravity factors need about 190.
FACTOR_MAX = 1e4
#: The floor's factor (:data:`graph_calib.model.encoder_noise.FLOORED`) goes no lower than this: the floor's sigma a
#: thousandth of what it was, where the gyro's noise between two readings dominates every floored component even at
#: a third of a navigation-grade gyro's (a table whose unread direction has no noise of its own).
FLOOR_FACTOR_MIN = 1e-6
#: Below this share of the floored components' variance (redundancy-weighted) the floor is negligible there.
FLOOR_SHARE_SETTLED = 0.05
#: Smallest exponent of a kind's response to its factor used for the step (module doc of the iteration).
MIN_EXPONENT = 0.25
#: Bounds of the moving keyframes' gravity sigma, m/s^2 (module doc).
MOVING_SIGMA_BOUNDS = (1e-3, 10.0)
#: The moving keyframes' ``chi2 / redundancy`` counts as settled within this of 1 (their sigma's order is what matters).
MOVING_TOLERANCE = 0.5
#: Largest step of the moving keyframes' log variance factor before it is bracketed (a factor of e^3, 20, per solve).
MOVING_STEP = 3.0
#: Further solves the loop may take when it estimates the moving keyframes' sigma.
MOVING_EXTRA_SOLVES = 3


@dataclass(frozen=True)
class VarianceComponents:
    """The estimated factors and the problem that carries them.

    Attributes
    ----------
    problem : graph_calib.records.problem.Problem
        The problem with ``ModelOptions.variance_factors`` set.
    factors : dict of str to float
        Each kind's variance factor (1 where not estimated).
    moving_sigma : float or None
        The moving keyframes' gravity sigma the problem carries, m/s^2 (None: every keyframe static).
    solves : int
    converged : bool
        Whether every estimated kind's ``chi2 / redundancy`` came within :data:`TOLERANCE` of 1.
    history : tuple of dict
        ``{kind: chi2 / redundancy}`` at each solve.
    initial : tuple (R, x)
        The last solution, to warm-start the solvers that follow.
    at_bound : tuple of str
        The kinds that had not settled when the iteration ended because their factor sat at :data:`FACTOR_MIN`
        or :data:`FACTOR_MAX` with the residuals asking for more (the iteration stops once every kind that has not
        settled is such).
    held : tuple of str
        The kinds whose residuals asked for a factor below 1 at the last solve but whose redundancy is below
        :data:`MIN_LOWERING_REDUNDANCY`: their factor stays 1 (sigmas perhaps conservative there).
    """

    problem: object
    factors: dict
    moving_sigma: object
    solves: int
    converged: bool
    history: tuple
    initial: tuple
    at_bound: tuple = ()
    held: tuple = ()


def with_variance_factors(problem, factors, *, moving_sigma=None):
    """``problem`` whose model carries the variance ``factors`` (and ``moving_sigma`` when given; the same record)."""
    model = problem.model
    options = replace(model.options, variance_factors=dict(factors))
    if moving_sigma is not None:
        options = replace(options, moving_sigma=float(moving_sigma))
    return replace(problem, model=CalibrationModel.from_record(model.record, options=options))


def estimate_variance_components(problem, *, options, solver=PRIMARY_SOLVER, fixed=(), progress=None,
                                 max_solves=MAX_SOLVES, tolerance=TOLERANCE, initial=None):
    """Estimate each kind's variance factor by solving, rescaling and solving again (module doc).

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
    options : graph_calib.options.CalibrationOptions
    solver : str
        The registered solver that iterates.
    fixed : iterable of str
        Kinds whose factor stays what the problem's options say.
    progress : callable, optional
    max_solves : int
    tolerance : float
    initial : tuple (R, x), optional
        Where the first solve starts (default: the solver's own start).

    Returns
    -------
    VarianceComponents
    """
    factors = {k: float(v) for k, v in (problem.model.options.variance_factors or {}).items()}
    fixed = set(fixed)
    moving = problem.model.options.moving_sigma
    estimate_moving = (moving is not None and MOVING not in fixed
                       and problem.model.options.noise_source.get("moving") == MOVING_ESTIMATED)
    factors.pop(MOVING, None)          # a fixed moving sigma is the options' own, not a factor
    # the floor of the readings' unread components: a factor of its own when the record has such components
    estimate_floor = FLOORED not in fixed
    if estimate_moving:
        # estimated as a factor on the moving rows' effective variance (moving_sigma^2 times the gravity
        # kind's factor, which scales every gravity row), turned back into a sigma below
        moving0 = float(moving)
        factors[MOVING] = factors.get("gravity", 1.0)
    history = []
    converged = False
    previous = {}                      # kind -> (log factor, log ratio) of the previous solve
    floor_stepped = False              # whether the floor's factor has taken its first (full) step
    bracket = [None, None]             # log factors of MOVING known too small (ratio > 1) and too large
    if estimate_moving and max_solves == MAX_SOLVES:
        max_solves += MOVING_EXTRA_SOLVES
    n = 0
    for n in range(1, max_solves + 1):
        out = solve(solver, problem, options=loose(options), progress=progress, initial=initial)
        initial = (out.attitudes, out.x)
        st = fit_statistics(problem.model, out.attitudes, out.x)
        # the moving rows have a sigma of their own (a guess, or estimated as MOVING): the gravity kind's factor is
        # the static rows'
        st = _static_gravity(st)
        if estimate_floor and FLOORED in st.kinds and st.kinds[FLOORED].redundancy >= MIN_REDUNDANCY:
            factors.setdefault(FLOORED, 1.0)
        # a kind's redundancy gate on the figures its factor is estimated from (the gyro's component takes the
        # rests' measurement rows of the still factors as well as the rotation kind's own)
        figures = {k: fig for k, fig in ((k, _component(st, k, factors)) for k in st.kinds)
                   if k in factors_estimated(factors) and k not in fixed and fig.redundancy >= MIN_REDUNDANCY}
        # a kind of little redundancy whose factor is down to 1 and whose residuals ask for less stays at 1
        rising = {k for k, f in figures.items() if k in KINDS and f.redundancy < MIN_LOWERING_REDUNDANCY}
        held = tuple(k for k, f in figures.items()
                     if k in rising and factors.get(k, 1.0) <= 1.0 and f.chi2 > 0 and f.chi2_per_redundancy < 1.0)
        ratios = {k: f.chi2_per_redundancy for k, f in figures.items() if f.chi2 > 0 and k not in held}
        history.append(dict(ratios))
        unsettled = [k for k, v in ratios.items() if not (abs(v - 1.0) <= (MOVING_TOLERANCE if k == MOVING else tolerance)
                                                          or (k == FLOORED and _floor_settled(factors[k], st.kinds[k])))]
        converged = not unsettled
        # a kind whose factor sits at a bound its residuals ask it to pass moves no further: once every kind that has
        # not settled is such, a further solve changes nothing (the verdict fails a factor that far from 1)
        bounded = tuple(k for k in unsettled if k in KINDS and _at_bound(factors.get(k, 1.0), ratios[k]))
        hold = ()
        if FLOORED in ratios and np.isfinite(ratios[FLOORED]):
            f0 = factors[FLOORED]
            factors[FLOORED] = _floor_step(f0, st.kinds[FLOORED], first=not floor_stepped)
            floor_stepped = True
            if abs(np.log(factors[FLOORED] / f0)) > np.log(2.0):
                # the readings' components share the floor with the gyro's and their own noise, whose figures
                # are the floor's share off while the floor is: those two wait for the next solve (and a secant
                # across this step would not hold)
                hold = ("rotation", "encoder")
                previous.clear()
        for k, v in ratios.items():
            if not np.isfinite(v) or k == FLOORED or k in hold:
                continue
            lf, lr = np.log(factors.get(k, 1.0)), np.log(v)
            if k == MOVING:
                # the moving rows' residuals are absorbed by the attitudes the more, the more weight they get: their
                # chi2 / redundancy answers a factor far from any power law; bracketed, then halved (in logs)
                bracket[0 if v > 1.0 else 1] = lf
                if bracket[0] is not None and bracket[1] is not None:
                    factors[k] = float(np.exp(0.5 * (bracket[0] + bracket[1])))
                else:
                    factors[k] = float(np.exp(lf + np.clip(lr, -MOVING_STEP, MOVING_STEP)))
                continue
            # chi2 / redundancy ~ c / factor^a: a kind whose residuals the attitudes partly absorb (a < 1) needs
            # a larger step than Helmert's (a = 1); a from the last two solves (secant in logs), within bounds
            a = 1.0
            if k in previous and abs(lf - previous[k][0]) > 0.05:      # a step large enough to read a from
                a = float(np.clip(-(lr - previous[k][1]) / (lf - previous[k][0]), MIN_EXPONENT, 1.0))
            previous[k] = (lf, lr)
            factors[k] = float(np.clip(np.exp(lf + lr / a), 1.0 if k in rising else FACTOR_MIN, FACTOR_MAX))
        # the last rescale is kept without a further solve: near 1 it moves the solution to second order only
        if estimate_moving:
            moving = float(np.clip(moving0 * np.sqrt(factors[MOVING] / factors.get("gravity", 1.0)),
                                   *MOVING_SIGMA_BOUNDS))
            factors[MOVING] = factors.get("gravity", 1.0) * (moving / moving0) ** 2
        problem = with_variance_factors(problem, {k: v for k, v in factors.items() if k in KINDS + (FLOORED,)},
                                        moving_sigma=moving)
        if converged or (unsettled and set(unsettled) <= set(bounded)):
            break
    out_factors = {k: factors.get(k, 1.0) for k in KINDS}
    if FLOORED in factors:
        out_factors[FLOORED] = factors[FLOORED]
    return VarianceComponents(problem=problem, factors=out_factors, moving_sigma=moving, solves=n,
                              converged=converged, history=tuple(history), initial=initial,
                              at_bound=() if converged else bounded, held=held)


def _at_bound(factor, ratio, *, low=FACTOR_MIN):
    """Whether a kind's ``factor`` sits at its lower bound ``low`` or at :data:`FACTOR_MAX` with its
    ``chi2 / redundancy`` asking it to pass that bound."""
    return ((factor >= FACTOR_MAX * (1.0 - 1e-9) and ratio > 1.0)
            or (factor <= low * (1.0 + 1e-9) and ratio < 1.0))


@dataclass(frozen=True)
class Weighted:
    """The problem a final solve takes, where it starts, and how the variance components that weighted it ended.

    Attributes
    ----------
    problem : graph_calib.records.problem.Problem
        The problem itself without the variance components, else the problem that carries the factors.
    initial : dict or None
        None without the variance components, else ``{solver: (R, x)}``, the iteration's last solution, as the
        ``initial`` of :func:`graph_calib.solvers.orchestration.run_solvers`.
    components : VarianceComponents or None
        The iteration (None without the variance components).
    """

    problem: object
    initial: object = None
    components: object = None

    def iteration(self):
        """The result's ``residuals.variance_iteration`` (data-format.md; None without the variance components):
        ``solves``, ``converged``, ``last``, each estimated kind's ``chi2 / redundancy`` at the last solve of
        the iteration (before its last rescale), ``at_bound``, the kinds that had not settled because their
        factor sat at a bound (:attr:`VarianceComponents.at_bound`), and ``held``, the kinds whose factor stayed 1 for
        too little redundancy to lower it (:attr:`VarianceComponents.held`)."""
        vc = self.components
        if vc is None:
            return None
        last = vc.history[-1] if vc.history else {}
        return {"solves": int(vc.solves), "converged": bool(vc.converged),
                "last": {k: float(v) for k, v in last.items()}, "at_bound": list(vc.at_bound),
                "held": list(vc.held)}


def weighted_problem(problem, *, options, solver, progress=None):
    """The problem a final solve takes, and where that solve starts: the variance components first when asked.

    With ``options.variance_components`` each kind's factor is estimated with ``solver``
    (:func:`estimate_variance_components`; the kinds whose factor the problem's options already set are kept),
    and the final solve of ``solver`` starts from the last solution of that iteration: the factors' last rescale
    moves the solution to second order only.  What ``calibrate`` and the diagnosis' held-out fold fits both do.

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
    options : graph_calib.options.CalibrationOptions
    solver : str
        The registered solver that iterates (the run's primary solver).
    progress : callable, optional
        Called with each solve's :class:`graph_calib.solvers.interface.ProgressEvent`.

    Returns
    -------
    Weighted
    """
    if not options.variance_components:
        return Weighted(problem=problem)
    vc = estimate_variance_components(problem, options=options, solver=solver,
                                      fixed=tuple(problem.model.options.variance_factors or ()), progress=progress)
    return Weighted(problem=vc.problem, initial={solver: vc.initial}, components=vc)


def tested_problem(identified, weighted):
    """The problem the closed loop's score tests judge with: the identified noise, not the kinds' factors.

    The loop (:func:`graph_calib.diagnosis.diagnose`) tests its candidates against the noise identified from the
    record (the kinds' factors the caller set, none estimated: a factor estimated from the residuals would absorb
    the misfit the tests look for), with the moving keyframes' gravity sigma as the variance components estimated
    it when they did.  ``calibrate``'s structure tests use the same problem at its solution, so that an effect
    they name is one the loop tests the same way.

    Parameters
    ----------
    identified : graph_calib.records.problem.Problem
        The problem as built (:func:`graph_calib.records.problem.build_problem`).
    weighted : graph_calib.records.problem.Problem
        ``identified`` with the variance components (:func:`weighted_problem`), or ``identified`` itself.

    Returns
    -------
    graph_calib.records.problem.Problem
    """
    options = identified.model.options
    if weighted is identified or options.noise_source.get("moving") != MOVING_ESTIMATED:
        return identified
    return with_variance_factors(identified, dict(options.variance_factors or {}),
                                 moving_sigma=weighted.model.options.moving_sigma)


def _static_gravity(st):
    """``st`` whose ``"gravity"`` counts the static keyframes only when the moving ones are apart
    (:func:`graph_calib.model.redundancy.static_gravity`)."""
    static = static_gravity(st.kinds)
    return st if static is None else replace(st, kinds={**st.kinds, "gravity": static})


def _component(st, kind, factors):
    """The figures a kind's factor is estimated from: the variance component's (the gyro's noise for ``rotation``,
    the readings' own for ``encoder``: :attr:`graph_calib.model.redundancy.FitStatistics.components`), else the
    kind's own.

    The gyro's factor takes the rotation kind's own figures when the readings' own factor sits at
    :data:`FACTOR_MIN` with their residuals asking for less (readings that do not scatter: their noise is the
    grade's, no measurement, and the verdict fails them in words): the readings' misfit would otherwise pass into
    the gyro's share of them and pull the gyro's factor down with it.
    """
    comps = st.components or {}
    if kind not in ("rotation", "encoder") or kind not in comps:
        return st.kinds[kind]
    enc = comps.get("encoder")
    if (kind == "rotation" and enc is not None and factors.get("encoder", 1.0) <= FACTOR_MIN * (1.0 + 1e-9)
            and enc.chi2_per_redundancy < 1.0):
        return st.kinds[kind]
    return comps[kind]


def _floor_step(factor, fit, *, first=True):
    """The floor's next factor: Förstner's estimate with the gyro term's share of the variance held.

    Each floored component's variance is ``factor F + G`` (``F`` the floor, ``G`` the gyro term from the
    keyframe or the previous reading, right as identified): ``chi2 ~ sum r_i (factor* F_i + G_i) / (factor F_i +
    G_i)``, linear in the factor sought, so one step takes it where the residuals put it (a plain Helmert step
    would need many when the gyro term dominates), within :data:`FLOOR_FACTOR_MIN` .. :data:`FACTOR_MAX`.  Once
    the floor is a negligible share of those components' variance (:func:`_floor_settled`) the data cannot tell
    its size, and it is kept.
    """
    share = float(fit.share_redundancy or 0.0)
    if not share > 0.0 or _floor_settled(factor, fit):
        return factor
    new = float(np.clip(factor * (fit.chi2 - (fit.redundancy - share)) / share, FLOOR_FACTOR_MIN, FACTOR_MAX))
    if first:
        return new
    # later steps half way in logarithms: the gyro term's share is not quite held (the readings' gains change with
    # the floor), and a full step overshoots once the floor is a minor part
    return float(np.sqrt(factor * new))


def _floor_settled(factor, fit):
    """Whether the floor's factor has settled: its components' ``chi2 / redundancy`` within :data:`TOLERANCE` of 1
    while the floor is a negligible share of their variance (below :data:`FLOOR_SHARE_SETTLED`; a table whose
    unread direction has no noise of its own, a simulated one), or the factor at a bound that the residuals ask it
    to pass."""
    ratio = fit.chi2_per_redundancy
    share = float(fit.share_redundancy or 0.0) / fit.redundancy if fit.redundancy > 0 else 0.0
    if share < FLOOR_SHARE_SETTLED and abs(ratio - 1.0) <= TOLERANCE:
        return True
    return _at_bound(factor, ratio, low=FLOOR_FACTOR_MIN)


def factors_estimated(factors):
    """The kinds whose factor the loop estimates: :data:`KINDS` and, when the record has them, MOVING (moving
    keyframes whose sigma is estimated) and FLOORED (readings with floored components)."""
    return KINDS + tuple(k for k in (MOVING, FLOORED) if k in factors)


__all__ = ["VarianceComponents", "Weighted", "estimate_variance_components", "weighted_problem", "with_variance_factors", "tested_problem", "KINDS",
           "MOVING_SIGMA_BOUNDS", "MIN_REDUNDANCY", "MIN_LOWERING_REDUNDANCY", "TOLERANCE", "MAX_SOLVES", "FACTOR_MIN", "FACTOR_MAX"]
