"""Calibrating one experiment with each solver: the public Python API behind ``graph-calib calibrate``.

>>> from graph_calib import io
>>> from graph_calib.calibrate import CalibrationOptions, calibrate
>>> run = calibrate(io.read_experiment("sim/sub1_20_30.h5"), options=CalibrationOptions())   # doctest: +SKIP
>>> run.results[PRIMARY_SOLVER].values["gyro.bias.x"]                                          # doctest: +SKIP
>>> run.comparison["summary"]["agree"]                                                          # doctest: +SKIP

Every solver is reached through :mod:`graph_calib.solvers` by name; the problem (shared model and
alignment) is built once and solved by each (:func:`graph_calib.solvers.orchestration.run_solvers`).
"""

from __future__ import annotations

from dataclasses import replace

from threadpoolctl import threadpool_limits

from graph_calib.model.calibration_model import reusing_preintegrations
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.solvers.orchestration import CalibrationRun, judge, run_solvers
from graph_calib.solvers.registry import DEFAULT_SOLVERS, PRIMARY_SOLVER, primary_of
from graph_calib.solvers.results import to_result
from graph_calib.solvers.staged import stage
from graph_calib.solvers.variance import tested_problem, weighted_problem


def solve_problem(problem, *, options=CalibrationOptions(), solvers=DEFAULT_SOLVERS, progress=None,
                  concurrent=False):
    """Solve a built ``problem`` with each of ``solvers`` (names) and compare the first two.

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
    options : CalibrationOptions
    solvers : sequence of str
        Registered solver names (:func:`graph_calib.solvers.solver_names`).
    progress : callable, optional
        Called with each solver's :class:`graph_calib.solvers.interface.ProgressEvent`.
    concurrent : bool
        With two solvers, run the first in a forked worker process while the second runs here
        (:func:`graph_calib.solvers.concurrent.solve_pair`: the same outputs, progress events and errors
        as one after the other; one after the other where the platform cannot fork).

    Returns
    -------
    CalibrationRun
    """
    solvers = tuple(solvers)
    # one record solved several times: a preintegration at a point just solved is not formed again; BLAS on one
    # thread (as inside each solve) also for the fit statistics and the structure tests between the solves:
    # their products are small, and OpenBLAS's threads spin against each other (docs/performance.md)
    with reusing_preintegrations(), threadpool_limits(limits=1, user_api="blas"):
        # one variance factor per measurement kind when asked, estimated with the primary solver; the primary
        # solver's final solve starts from its last solution, every other solver from its own start
        identified = problem
        weighted = weighted_problem(problem, options=options, solver=primary_of(solvers), progress=progress)
        problem, initial = weighted.problem, weighted.initial
        # a table-less record whose gyro model does not fit: the accelerometer from gravity alone when the gyro's
        # misfit pulls it, every solver then solving the same pinned problem (graph_calib.solvers.staged)
        staging = stage(problem, options=options, solver=primary_of(solvers),
                        initial=(initial or {}).get(primary_of(solvers)),
                        fixed=tuple(identified.model.options.variance_factors or ()), progress=progress)
        staged = staging is not None and staging.staged
        tests = {}

        def structure_of(name, output):
            """The structure tests at the primary solver's solution, as soon as it is solved (with two solvers
            run concurrently, while the other still runs), against the noise the loop tests with (the identified
            one: variance factors estimated from these residuals would absorb the misfit the tests look for)."""
            if options.structure_tests and name == primary_of(solvers):
                # the diagnosis package only when it is used: `calibrate --help` and a run without the tests
                # import none of it
                from graph_calib.diagnosis.structure import structure_tests

                tests[name] = structure_tests(tested_problem(identified, problem), output)

        run = run_solvers(staging.problem if staged else problem, options=options, solvers=solvers,
                          progress=progress, concurrent=concurrent,
                          initial={primary_of(solvers): staging.initial} if staged else initial,
                          on_output=structure_of, stamp=False)
        if staged:
            # each output with the honest covariance, its result with the record's own priors and the staging said
            outputs = {n: staging.finish(o) for n, o in run.outputs.items()}
            problem = staging.result_problem
            results = {n: to_result(problem.model, o, extra={"staged": staging.to_json()}) for n, o in outputs.items()}
            run = replace(run, problem=problem, outputs=outputs, results=results)
    results = run.results
    iteration = weighted.iteration()
    if iteration is not None:
        # how the variance components ended, which the verdict notes when they did not settle
        results = {n: replace(r, residuals={**r.residuals, "variance_iteration": iteration}) for n, r in results.items()}
    structure = tests[primary_of(solvers)] if options.structure_tests else ()
    results, comparison, verdict = judge(results, order=solvers, structure=structure)
    return replace(run, results=results, comparison=comparison, verdict=verdict)


def calibrate(experiment, *, options=CalibrationOptions(), solvers=DEFAULT_SOLVERS, progress=None):
    """Calibrate ``experiment`` with each of ``solvers``: :func:`build_problem`, then :func:`solve_problem`.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    options : CalibrationOptions
    solvers : sequence of str
    progress : callable, optional

    Returns
    -------
    CalibrationRun
    """
    problem = build_problem(experiment, options=options)
    return solve_problem(problem, options=options, solvers=solvers, progress=progress)


def calibrate_with_effects(experiment, *, added, options=CalibrationOptions(), solvers=DEFAULT_SOLVERS, progress=None,
                           concurrent=False):
    """Calibrate ``experiment`` with the further effects ``added`` on top of ``options``' model.

    What ``graph-calib diagnose`` writes as its final calibration: the model the closed loop ended with (its
    ``Diagnosis.added``), solved as :func:`calibrate` solves (variance components, structure tests, the verdict),
    where the loop itself tests on the identified noise, unscaled.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    added : sequence of str
        Further effects (model.md) added to ``options.model.extra_effects``.
    options : CalibrationOptions
    solvers : sequence of str
    progress : callable, optional
    concurrent : bool
        As for :func:`solve_problem`.

    Returns
    -------
    CalibrationRun
    """
    final = options.with_added_effects(added)
    return solve_problem(build_problem(experiment, options=final), options=final, solvers=solvers, progress=progress,
                         concurrent=concurrent)


__all__ = ["CalibrationOptions", "CalibrationRun", "PRIMARY_SOLVER", "build_problem", "solve_problem", "calibrate",
           "calibrate_with_effects"]
