"""Calibrating one experiment with each solver: the public Python API behind ``graph-calib calibrate``.

>>> from graph_calib import io
>>> from graph_calib.calibrate import CalibrationOptions, calibrate
>>> run = calibrate(io.read_experiment("sim/sub1_20_30.h5"), options=CalibrationOptions())   # doctest: +SKIP
>>> run.results["factor-graph"].values["gyro.bias.x"]                                          # doctest: +SKIP
>>> run.comparison["summary"]["agree"]                                                          # doctest: +SKIP

Every solver is reached through :mod:`graph_calib.solvers` by name; the problem (shared model and
alignment) is built once and solved by each.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping

from graph_calib.records.experiment import Result
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import Problem, build_problem
from graph_calib.solvers.concurrent import solve_pair
from graph_calib.solvers.interface import SolverOutput
from graph_calib.solvers.registry import DEFAULT_SOLVERS, solve
from graph_calib.solvers.results import compare, to_result
from graph_calib.solvers.variance import estimate_variance_components
from graph_calib.solvers.verdict import Verdict, verdict_of


@dataclass(frozen=True)
class CalibrationRun:
    """One experiment calibrated by one or more solvers.

    Attributes
    ----------
    problem : graph_calib.records.problem.Problem
    outputs : mapping of str to SolverOutput
        Each solver's output, by solver name, in the order run.
    results : mapping of str to Result
        Each solver's result file contents, the verdict included (key ``verdict``).
    comparison : dict or None
        ``comparison.json`` of the first two solvers (None with one solver), the verdict included.
    verdict : Verdict
        Converged, solvers agree, residuals consistent (:mod:`graph_calib.solvers.verdict`).
    """

    problem: Problem
    outputs: Mapping[str, SolverOutput]
    results: Mapping[str, Result]
    comparison: dict | None
    verdict: Verdict


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
    if options.variance_components:
        vce_solver = "factor-graph" if "factor-graph" in solvers else solvers[0]
        problem = estimate_variance_components(problem, options=options, solver=vce_solver,
                                               fixed=tuple(problem.model.options.variance_factors or ()),
                                               progress=progress).problem
    if concurrent and len(solvers) == 2:
        outputs = dict(zip(solvers, solve_pair(solvers, problem, options=options, progress=progress)))
    else:
        outputs = {name: solve(name, problem, options=options, progress=progress) for name in solvers}
    results = {name: to_result(problem.model, out) for name, out in outputs.items()}
    names = list(results)
    comparison = compare(results[names[0]], results[names[1]]) if len(names) >= 2 else None
    structure = ()
    if options.structure_tests:
        # the diagnosis package only when it is used: `calibrate --help` and a run without the tests import none of it
        from graph_calib.diagnosis.structure import structure_tests

        batch = "factor-graph" if "factor-graph" in outputs else names[0]
        structure = structure_tests(problem, outputs[batch])
    verdict = verdict_of(results, comparison, structure=structure)
    results = {s: replace(r, extra={**r.extra, "verdict": verdict.to_json()}) for s, r in results.items()}
    if comparison is not None:
        comparison = {**comparison, "verdict": verdict.to_json()}
    return CalibrationRun(problem=problem, outputs=outputs, results=results, comparison=comparison,
                          verdict=verdict)


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


__all__ = ["CalibrationOptions", "CalibrationRun", "build_problem", "solve_problem", "calibrate"]
