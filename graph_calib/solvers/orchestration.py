"""Every requested solver on one problem, their results, the comparison of the first two and the verdict.

One function, :func:`run_solvers`, for every caller: ``calibrate`` (:mod:`graph_calib.calibrate`), the
campaign's jobs (:mod:`graph_calib.campaign.execution`) and the diagnosis' stages
(:mod:`graph_calib.diagnosis.loop`).  :func:`judge` is its last step on its own, for results that were
solved elsewhere and read back (a campaign's cached tasks, :mod:`graph_calib.campaign.run`).  Nothing here
names a solver: they come from the registry (:mod:`graph_calib.solvers.registry`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Mapping

from graph_calib.solvers.concurrent import solve_pair
from graph_calib.solvers.interface import SolverOutput
from graph_calib.solvers.registry import solve
from graph_calib.solvers.results import compare, to_result
from graph_calib.solvers.verdict import Verdict, verdict_of


@dataclass(frozen=True)
class CalibrationRun:
    """One problem solved by one or more solvers.

    Attributes
    ----------
    problem : graph_calib.records.problem.Problem
    outputs : mapping of str to SolverOutput
        Each solver's output, by solver name, in the order run (a solver that failed is absent).
    results : mapping of str to Result
        Each solver's result file contents, the verdict included (key ``verdict``).
    comparison : dict or None
        ``comparison.json`` of the first two solvers (None with fewer than two), the verdict included.
    verdict : Verdict
        Converged, solvers agree, residuals consistent (:mod:`graph_calib.solvers.verdict`).
    errors : mapping of str to Exception
        The solvers that failed, with ``keep_going`` (empty otherwise: the first error is raised).
    """

    problem: object
    outputs: Mapping[str, SolverOutput]
    results: Mapping
    comparison: dict | None
    verdict: Verdict
    errors: Mapping[str, BaseException] = field(default_factory=dict)


def judge(results, *, order=None, stamp=True, structure=()):
    """The comparison of the first two of ``results`` and the verdict, stamped into both.

    Parameters
    ----------
    results : mapping of str to graph_calib.records.experiment.Result
    order : sequence of str, optional
        Comparison order (default: the mapping's); names without a result are passed over.
    stamp : bool
        Write the verdict into each result (``extra["verdict"]``); the comparison always holds it.
    structure : sequence, optional
        Score tests of the known effects at the solution (:mod:`graph_calib.diagnosis.structure`), judged
        by the verdict.

    Returns
    -------
    results : dict of str to Result
        With ``extra["verdict"]`` (with ``stamp``).
    comparison : dict or None
        ``comparison.json`` with its ``verdict``.
    verdict : Verdict
    """
    names = [n for n in (results if order is None else order) if n in results]
    comparison = compare(results[names[0]], results[names[1]]) if len(names) >= 2 else None
    verdict = verdict_of(dict(results), comparison, structure=structure)
    stamped = ({s: replace(r, extra={**r.extra, "verdict": verdict.to_json()}) for s, r in results.items()}
               if stamp else dict(results))
    if comparison is not None:
        comparison = {**comparison, "verdict": verdict.to_json()}
    return stamped, comparison, verdict


def run_solvers(problem, *, options, solvers, progress=None, concurrent=False, initial=None, outputs=None,
                order=None, on_start=None, on_output=None, on_solved=None, keep_going=False, stamp=True):
    """Solve ``problem`` with each of ``solvers``, make their results, compare the first two, give the verdict.

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
    options : graph_calib.options.CalibrationOptions
    solvers : sequence of str
        Registered solver names, in the order run (and of the results).
    progress : callable, optional
        Called with each solver's :class:`graph_calib.solvers.interface.ProgressEvent`.
    concurrent : bool
        With two solvers to run, the first in a forked worker process while the second runs here
        (:func:`graph_calib.solvers.concurrent.solve_pair`: the same outputs, events and errors as one
        after the other).
    order : sequence of str, optional
        The comparison order (default ``solvers``'): the first two of it are compared.
    initial : mapping of str to (R, x), optional
        A solver's starting keyframe attitudes and calibration; the others start on their own.
    outputs : mapping of str to SolverOutput, optional
        Solvers already solved (the diagnosis' primary solver): their outputs are taken, not solved again.
    on_start : callable, optional
        ``on_start(name)`` before each solver is run here (a campaign's job starts its clock there).
    on_output : callable, optional
        ``on_output(name, output)`` as each solver run here returns (not those of ``outputs``), before its
        result is made; run concurrently, the one solved in this process is passed on while the other still
        runs in its worker.
    on_solved : callable, optional
        ``on_solved(name, output, result)`` as each solver's result is made (before the verdict: a campaign
        writes its task files there); an exception it raises counts as that solver's.
    keep_going : bool
        A failing solver is recorded in :attr:`CalibrationRun.errors` and the others still run; by default
        its error is raised.
    stamp : bool
        Write the verdict into each result (:func:`judge`).

    Returns
    -------
    CalibrationRun
    """
    solvers = tuple(solvers)
    initial = dict(initial or {})
    given = dict(outputs or {})
    todo = [n for n in solvers if n not in given]
    solved, errors = {}, {}
    if concurrent and len(todo) == 2 and not keep_going:
        solved.update(zip(todo, solve_pair(todo, problem, options=options, progress=progress, initial=initial,
                                           on_output=on_output)))
    results = {}
    for name in solvers:
        try:
            if name in given:
                output = given[name]
            elif name in solved:
                output = solved[name]
            else:
                if on_start is not None:
                    on_start(name)
                output = solve(name, problem, options=options, progress=progress, initial=initial.get(name))
                if on_output is not None:
                    on_output(name, output)
            result = to_result(problem.model, output)
            if on_solved is not None:
                on_solved(name, output, result)
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:
            if not keep_going:
                raise
            errors[name] = exc
            continue
        solved[name], results[name] = output, result
    results, comparison, verdict = judge(results, order=solvers if order is None else order, stamp=stamp)
    return CalibrationRun(problem=problem, outputs={n: solved[n] for n in solvers if n in results}, results=results,
                          comparison=comparison, verdict=verdict, errors=errors)


__all__ = ["CalibrationRun", "judge", "run_solvers"]
