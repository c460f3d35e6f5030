"""The closed loop: calibrate, test every further effect, add the most significant one, repeat.

:func:`diagnose` calibrates with the declared model and then runs rounds until no
candidate is significant (or the limit of added effects is reached).  A round
(:func:`_round`) is a sequence of steps:

1. linearise the model extended by every untested candidate at the current solution
   and eliminate the attitudes (:func:`~graph_calib.diagnosis.reduced_system.linearise`);
2. score-test each candidate against the current model
   (:func:`~graph_calib.diagnosis.decision.test_candidates`);
3. score-test each generic driver group on each sensor axis
   (:func:`~graph_calib.diagnosis.decision.test_drivers`);
4. decide (:func:`~graph_calib.diagnosis.decision.decide`): add the most significant candidate that explains
   the significant driver signatures, or is needed beyond those it leaves.

After an effect is added the primary solver (the first of ``DiagnosisOptions.solvers``) re-solves the
same record from the previous solution (:func:`_add_effect`).  Driver signatures significant at the final
model are reported as ``unexplained``.

The loop solves one record several times (the primary solver, the fit statistics at each solution, the
further solvers, the grown model), so :func:`diagnose` and :func:`diagnose_from` run inside
:func:`graph_calib.model.calibration_model.reusing_preintegrations`: the fit statistics at the primary's
solution, or a solve from a point just preintegrated, take the preintegration already formed there (a
preintegration depends on the record, the layout, the Newton steps and ``x`` alone: the same values).  They
run BLAS on one thread, as ``calibrate`` does and as a campaign's Dask worker does anyway (its nanny sets
``OPENBLAS_NUM_THREADS=1``): the rounds' linearisations and the fit statistics multiply matrices of a few tens
to a hundred columns, where OpenBLAS's threads spin against each other (docs/performance.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from graph_calib.sensors import effects
from graph_calib.diagnosis.decision import decide, test_candidates, test_drivers
from graph_calib.diagnosis.rounds import Diagnosis, DiagnosisOptions, Round, Stage
from graph_calib.diagnosis.drivers import DriverSums, keyframe_context
from graph_calib.diagnosis.holdout import held_out_check
from graph_calib.diagnosis.reduced_system import linearise
from graph_calib.diagnosis.residuals import (
    error_against_truth,
    factor_residuals,
    filter_innovations,
    residual_statistics,
)
from graph_calib.model.calibration_model import reusing_preintegrations
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.navigation.rotations import exp_so3
from graph_calib.solvers.orchestration import run_solvers
from graph_calib.solvers.registry import SOLVER_LABELS, comparison_order, solve
from graph_calib.solvers.variance import KINDS, estimate_variance_components
from graph_calib.records.problem import MOVING_ESTIMATED


def _primary(diagnosis_options):
    """The solver the rounds linearise at: the first of ``diagnosis_options.solvers``."""
    return diagnosis_options.solvers[0]


def _solve_graph(problem, *, options, diagnosis_options, initial=None):
    """The primary solver's solution of ``problem`` (:func:`_primary`)."""
    return solve(_primary(diagnosis_options), problem, options=options, initial=initial)


# ---------------------------------------------------------------------------
# a calibrated stage (before, after)
# ---------------------------------------------------------------------------


def _make_stage(problem, graph, *, options, diagnosis_options, truth=None, fixed_sigmas=None, starts_from=None,
                starts_x=None, linearised=None, context=None, say=lambda msg: None):
    """The stage of ``problem`` solved by the primary solver (``graph``): the others, residuals, statistics, error.

    Every solver of ``diagnosis_options.solvers`` is run through
    :func:`graph_calib.solvers.orchestration.run_solvers` (the primary's output given), which makes the
    results, compares the first two (comparison order) and gives the verdict.
    ``linearised``: the :class:`_Linearised` of the round run at ``graph`` (:func:`_round`): the factor
    residuals are taken from its factors (the candidates zero, they are the current model's residuals)
    instead of preintegrating the record and evaluating the factors once more.
    ``starts_from``: ``{solver: SolverOutput}``, each further solver's solution of a smaller model, embedded in
    ``problem``'s layout as its first linearisation point (its own solution, not the primary's: the solvers
    stay independent; the fixed point is the same, only fewer passes reach it).  Without it a further
    solver starts from the prior calibration, as it does on its own, with the primary's keyframe attitudes
    as its first attitudes (instead of fitting attitudes at the prior).
    ``starts_x``: ``{solver: x}``, instead, its first calibration in ``problem``'s layout (its solution of a
    smaller model kept in a result file, :func:`diagnose_from`), with the primary's keyframe attitudes.
    ``context``: the record's :func:`~graph_calib.diagnosis.drivers.keyframe_context` (one for both stages).
    """
    model = problem.model
    primary = _primary(diagnosis_options)
    if linearised is None:
        series = factor_residuals(model, graph.attitudes, graph.x)
    else:
        series = factor_residuals(linearised.model, graph.attitudes, linearised.x, factors=linearised.factors)
    starts_from, starts_x = starts_from or {}, starts_x or {}
    initial = {}
    for name in diagnosis_options.solvers[1:]:
        if name in starts_from:
            initial[name] = (starts_from[name].attitudes, model.layout.embed(starts_from[name].layout,
                                                                             starts_from[name].x))
        elif name in starts_x:
            initial[name] = (graph.attitudes, np.asarray(starts_x[name], dtype=float))
        else:
            initial[name] = (graph.attitudes, model.prior()[0])
    if initial:
        say(f"  {', '.join(SOLVER_LABELS.get(n, n) for n in initial)} ...")
    run = run_solvers(problem, options=options, solvers=diagnosis_options.solvers,
                      order=comparison_order(diagnosis_options.solvers), outputs={primary: graph}, initial=initial,
                      stamp=False)
    outputs = {primary: graph, **{n: o for n, o in run.outputs.items() if n != primary}}
    results = {n: run.results[n] for n in outputs}
    stage = Stage(layout=tuple(model.layout.names), problem=problem, primary=primary, outputs=outputs,
                  results=results, comparison=run.comparison, verdict=run.verdict, residuals=series,
                  innovations={n: filter_innovations(o, model) for n, o in outputs.items() if n != primary})
    stage.statistics = residual_statistics(stage, context=context)
    if truth is not None:
        stage.error = {}
        for solver, res in stage.results.items():
            e = error_against_truth(res, truth)
            if fixed_sigmas is not None and solver in fixed_sigmas:
                e["rms_z_fixed"] = error_against_truth(res, truth, sigmas=fixed_sigmas[solver])["rms_z"]
            else:
                e["rms_z_fixed"] = e["rms_z"]
            stage.error[solver] = e
    return stage


# ---------------------------------------------------------------------------
# one round
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class _Linearised:
    """What a round keeps of its linearisation for the next steps of the loop.

    Attributes
    ----------
    model : graph_calib.model.CalibrationModel
        The extended model (the current one with every untested candidate).
    x : ndarray (P,)
        The current solution embedded in ``model.layout`` (candidates zero).
    pre : graph_calib.model.preintegration.Preintegrated
        ``model``'s preintegration, at ``x`` or near enough for a first-order update
        (:meth:`~graph_calib.model.preintegration.Preintegrated.needs_repreintegration`).
    factors : dict
        ``{kind: Residuals}`` at the solution (without Jacobians): the stage's factor residuals.
    start : tuple or None
        ``(R, x)`` after one Gauss-Newton step of the grown model from the current solution, ``x`` in
        ``model.layout``, when the round added an effect: where the grown model's solve starts.
    """

    model: object
    x: np.ndarray
    pre: object
    factors: dict
    start: tuple | None = None


def _extended_model(model, names, previous):
    """``model`` with the further effects ``names``: ``previous``'s extended model when it is the same one.

    The extended model of every round holds the same effects (those the current model holds plus
    those still untested), so the first round's serves every later one, in the same layout.
    """
    if previous is not None and set(previous.model.options.extra_effects) == set(names):
        return previous.model
    return model.with_effects(names)


def _round(index, *, options, problem, graph, diagnosis_options, candidates, allow_add=True, sums=None,
           previous=None):
    """One round: linearise the extended model at the solution, test, decide.

    ``sums``: the record's driver sums (:class:`~graph_calib.diagnosis.drivers.DriverSums`, one for
    every round).  ``previous``: the previous round's :class:`_Linearised`: its extended model and
    preintegration serve again when the solution moved so little that the preintegration is updated to
    first order (``GraphOptions.repreintegrate_tol``, as the solvers decide).

    Returns the :class:`Round` and the round's :class:`_Linearised`.
    """
    t0 = time.perf_counter()
    model = problem.model
    untested = [name for name in candidates if name not in model.layout]
    # the same prepared record, static intervals and alignment: only the layout grows
    extended = _extended_model(model, tuple(options.model.extra_effects) + tuple(untested), previous)
    x_extended = extended.layout.embed(model.layout, graph.x)
    if (previous is not None and previous.model is extended
            and not previous.pre.needs_repreintegration(x_extended, tol=options.graph.repreintegrate_tol)):
        pre = previous.pre
    else:
        pre = extended.preintegrate(x_extended)
    system, drivers = linearise(extended, graph.attitudes, x_extended, q_nb0=problem.q_nb0,
                                null_names=model.layout.names, n_segments=diagnosis_options.time_segments, pre=pre,
                                sums=sums, keep_step=allow_add, keep_factors=True)
    candidate_tests, candidate_columns = test_candidates(system, extended.layout, untested,
                                                          diagnosis_options=diagnosis_options)
    driver_tests, driver_columns = test_drivers(system, drivers, extended, diagnosis_options=diagnosis_options)
    added, decision, checks = decide(system, candidate_tests, candidate_columns, driver_tests, driver_columns,
                                      allow_add=allow_add, diagnosis_options=diagnosis_options)
    start = None
    if added is not None:
        below = [n for n in effects.with_lower_orders((added,))[:-1] if n not in model.layout]
        if below:   # the grown model holds them too (CalibrationModel's layout)
            decision += f"; with {', '.join(below)} below it (a curve grows from its low orders)"
        # the grown model's first Gauss-Newton step from the current solution, from this linearisation
        dx, delta = system.gauss_newton_step(np.concatenate([system.null, candidate_columns[added]]))
        if np.all(np.isfinite(dx)) and np.all(np.isfinite(delta)):
            start = (graph.attitudes @ exp_so3(delta), x_extended + dx)
    rnd = Round(index=index, layout=tuple(model.layout.names), candidates=candidate_tests, drivers=driver_tests,
                variance_factor=system.variance_factor, chi2_per_dof=system.chi2 / max(system.dof, 1),
                added=added, decision=decision, checks=checks, seconds=time.perf_counter() - t0)
    return rnd, _Linearised(model=extended, x=x_extended, pre=pre, factors=system.factors, start=start)


# ---------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------


def _add_effect(name, *, options, problem, graph, lin, diagnosis_options, say):
    """Add effect ``name`` to the model and re-solve: ``(options, problem, graph)``.

    The solve starts where the round's linearisation (``lin``, :class:`_Linearised`) put the first
    Gauss-Newton step of the grown model, else from the previous solution (the new parameters zero).
    Either way the solver iterates to its own fixed point; from the step it needs one iteration fewer.
    """
    options = options.with_added_effects((name,))
    grown = problem.with_effects(options.model.extra_effects)
    if lin is not None and lin.start is not None:
        initial = (lin.start[0], grown.model.layout.embed(lin.model.layout, lin.start[1]))
    else:
        initial = (graph.attitudes, grown.model.layout.embed(problem.model.layout, graph.x))
    say(f"re-solving with {name} ...")
    graph = _solve_graph(grown, options=options, diagnosis_options=diagnosis_options, initial=initial)
    return options, grown, graph


def _guard(rnd, experiment, *, options, diagnosis, say):
    """``rnd`` with its effect kept only when the held-out figures allow it (:mod:`graph_calib.diagnosis.holdout`)."""
    say(f"round {rnd.index}: {rnd.added} passes its test; held-out check (two folds) ...")
    check = held_out_check(experiment, options=options, solver=_primary(diagnosis),
                           grown=options.with_added_effects((rnd.added,)))
    if check is None:
        return rnd
    if check.adopted:
        return replace(rnd, held_out=check.to_json(), decision=f"{rnd.decision}; {check.text()}")
    return replace(rnd, added=None, held_out=check.to_json(), decision=f"{rnd.added}: {check.text()}")


def _context(experiment, *, model, options, diagnosis_options, truth):
    """The experiment and the run, for ``diagnosis.json`` (``model``: the declared model)."""
    e = experiment
    return {
        "n_samples": e.n_samples, "duration_s": float(e.t[-1] - e.t[0] + 1.0 / e.rate_hz),
        "rate_hz": float(e.rate_hz), "table": e.table is not None, "grade": options.model.grade,
        "keyframes": int(model.n_keyframes), "keyframe_s": float(options.model.keyframe_s),
        "t_ref_degC": float(model.t_ref_degC), "solvers": list(diagnosis_options.solvers),
        "temperature_range_degC": [float(model.temperatures.min()), float(model.temperatures.max())],
        "truth": truth is not None,
    }


def diagnose(experiment, *, options=None, diagnosis=DiagnosisOptions(), truth=None, progress=None):
    """The closed loop on one experiment.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    options : graph_calib.calibrate.CalibrationOptions, optional
        The declared model (grade, keyframes, effects already modelled, priors); with
        ``moving_sigma="estimate"`` the moving keyframes' gravity sigma is estimated first, as ``calibrate``
        does, and every round's model carries it (the kinds' variance factors are not estimated here).
    diagnosis : DiagnosisOptions
    truth : graph_calib.records.experiment.Result, optional
        A simulator's truth: the error of the declared parameters before and after.
    progress : callable, optional
        Called with one-line messages.

    Returns
    -------
    Diagnosis
    """
    t_start = time.perf_counter()
    say = progress or (lambda msg: None)
    options = CalibrationOptions() if options is None else options
    with reusing_preintegrations(), threadpool_limits(limits=1, user_api="blas"):    # module docstring
        problem = build_problem(experiment, options=options)
        # one T_ref and one grade for every model (the grade the record's rests chose, when none was named)
        chosen = problem.model.options
        options = replace(options, t_ref_degC=problem.model.t_ref_degC,
                          model=replace(options.model, grade=chosen.grade, grade_choice=dict(chosen.grade_choice)))
        if options.variance_components and problem.model.options.noise_source.get("moving") == MOVING_ESTIMATED:
            # the moving keyframes' gravity sigma as calibrate estimates it (moving_sigma="estimate"); the kinds'
            # factors stay the identified noise's: the rounds' tests measure a misfit against it, which factors
            # estimated from the same residuals would absorb (on the MPU-6050 session the rotation kind's is 72)
            say("the moving keyframes' gravity sigma ...")
            problem = estimate_variance_components(problem, options=options, solver=_primary(diagnosis),
                                                   fixed=KINDS).problem
        say(f"declared model: {problem.model.layout.size} parameters, {problem.model.n_keyframes} keyframes; "
            f"{SOLVER_LABELS.get(_primary(diagnosis), _primary(diagnosis))} ...")
        graph = _solve_graph(problem, options=options, diagnosis_options=diagnosis)
        return _loop_from(experiment, problem, graph, options=options, diagnosis=diagnosis, truth=truth,
                          max_added=diagnosis.max_added, starts_x=None, t_start=t_start, say=say)


def diagnose_from(experiment, *, options, start, diagnosis=DiagnosisOptions(), attitudes=None, starts=None,
                  max_added=None, progress=None):
    """The closed loop continued on a model grown from outside, warm-started from a smaller model's solution.

    What a campaign runs after its pooled score test adopted an effect in this experiment
    (:mod:`graph_calib.campaign.pooled`): ``options`` hold the model the experiment's own loop chose plus the
    adopted effect(s), ``start`` that model's solution by the primary solver (the first of
    ``diagnosis.solvers``).  The grown model is solved by the primary solver from ``start`` (the new
    parameters zero; the keyframe attitudes that solution's own, else dead-reckoned from the alignment with
    that calibration, which keeps them within the alignment's error, so no attitude-only fit), then the rounds of :func:`diagnose` run on it (at most ``max_added`` further effects).  Each further solver of
    ``diagnosis.solvers`` starts from its own solution of the smaller model (``starts``) with the primary's
    attitudes: the solvers keep their own fixed points, fewer passes reach them.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    options : CalibrationOptions
        The grown model; its ``t_ref_degC`` the smaller model's (one ``T_ref`` for every model).
    start : dict
        ``{flat element name: value}`` (SI) of the smaller model's primary solution
        (:attr:`graph_calib.records.experiment.Result.values`); elements not given start at zero.
    diagnosis : DiagnosisOptions
    attitudes : ndarray (K+1, 3, 3), optional
        The keyframe attitudes ``C_nb`` of the ``start`` solution (ignored when their shape does not fit).
    starts : dict, optional
        ``{solver: {flat element name: value}}``, the same of the further solvers' solutions (default: each
        starts from the prior calibration).
    max_added : int, optional
        Further effects the rounds may add (default ``diagnosis.max_added``).
    progress : callable, optional

    Returns
    -------
    Diagnosis
        ``before`` is the grown model's stage (not the declared model's), ``added`` what the rounds added to it.
    """
    t_start = time.perf_counter()
    say = progress or (lambda msg: None)
    with reusing_preintegrations(), threadpool_limits(limits=1, user_api="blas"):    # module docstring
        problem = build_problem(experiment, options=options)
        model = problem.model
        x0 = model.layout.from_dict(start)
        if attitudes is not None and np.shape(attitudes) == (model.n_keyframes + 1, 3, 3):
            R0 = np.asarray(attitudes, dtype=float)
        else:
            R0 = model.propagate(model.segment_priors(problem.q_nb0), model.preintegrate(x0), x0)
        say(f"grown model: {model.layout.size} parameters, warm start; "
            f"{SOLVER_LABELS.get(_primary(diagnosis), _primary(diagnosis))} ...")
        graph = _solve_graph(problem, options=options, diagnosis_options=diagnosis, initial=(R0, x0))
        starts_x = {s: model.layout.from_dict(v) for s, v in (starts or {}).items() if s in diagnosis.solvers[1:]}
        return _loop_from(experiment, problem, graph, options=options, diagnosis=diagnosis, truth=None,
                          max_added=diagnosis.max_added if max_added is None else max_added, starts_x=starts_x,
                          t_start=t_start, say=say)


def _loop_from(experiment, problem, graph, *, options, diagnosis, truth, max_added, starts_x, t_start, say):
    """The rounds from ``problem`` solved by the primary solver (``graph``) until nothing is added: the
    :class:`Diagnosis`."""
    candidates = tuple(diagnosis.candidates or effects.FURTHER_EFFECTS)
    declared = problem.model
    sums = DriverSums.of(declared, n_segments=diagnosis.time_segments)   # the record's: one for every round
    context = keyframe_context(declared)                                 # and one for both stages
    rounds, added = [], []
    before = None
    lin = None
    while True:
        rnd, lin = _round(len(rounds) + 1, options=options, problem=problem, graph=graph,
                          diagnosis_options=diagnosis, candidates=candidates,
                          allow_add=len(added) < max_added, sums=sums, previous=lin)
        if rnd.added is not None and diagnosis.holdout:
            rnd = _guard(rnd, experiment, options=options, diagnosis=diagnosis, say=say)
        rounds.append(rnd)
        say(f"round {rnd.index}: {rnd.decision}")
        if before is None:      # the starting model's stage, its residuals from the first round's linearisation
            before = _make_stage(problem, graph, options=options, diagnosis_options=diagnosis, truth=truth,
                                 starts_x=starts_x, linearised=lin, context=context, say=say)
            fixed = {s: r.sigmas for s, r in before.results.items()}
        if rnd.added is None:
            break
        added.append(rnd.added)
        options, problem, graph = _add_effect(rnd.added, options=options, problem=problem, graph=graph, lin=lin,
                                              diagnosis_options=diagnosis, say=say)
    after = before if not added else _make_stage(problem, graph, options=options, diagnosis_options=diagnosis,
                                                 truth=truth, fixed_sigmas=fixed,
                                                 starts_from={n: o for n, o in before.outputs.items()
                                                              if n != before.primary},
                                                 linearised=lin, context=context, say=say)
    signature = sorted((d for d in rounds[-1].drivers if d.significant), key=lambda d: d.log10_p)
    source = experiment.source.rsplit("/", 1)[-1] if experiment.source else ""
    return Diagnosis(source=source, added=added, unexplained=bool(signature), signature=signature, rounds=rounds,
                     before=before, after=after, options=diagnosis,
                     context=_context(experiment, model=declared, options=options, diagnosis_options=diagnosis,
                                      truth=truth),
                     seconds=time.perf_counter() - t_start)
