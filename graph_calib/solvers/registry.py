"""Solvers by name: one dispatch for the command line, the campaign, the diagnosis and the tests.

Solvers register through the ``graph_calib.solvers`` entry-point group of the package metadata
(``pyproject.toml``), so a solver module imports this interface and the shared model, and nothing
here imports a solver: the layers stay one-way.  A new solver is a class with ``name`` and
``solve(problem, *, options, progress=None, initial=None) -> SolverOutput`` plus one line in
``[project.entry-points."graph_calib.solvers"]``.

>>> solver_names()                                               # doctest: +SKIP
('factor-graph', 'sqrt-kf')
>>> output = solve("factor-graph", problem, options=CalibrationOptions())   # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from importlib.metadata import entry_points

#: The entry-point group solvers register in.
ENTRY_POINT_GROUP = "graph_calib.solvers"

#: The per-experiment solvers run by default, in the order results are compared (filter first).
DEFAULT_SOLVERS = ("sqrt-kf", "factor-graph")


@lru_cache(maxsize=None)
def _entry_points():
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def solver_names():
    """Names of the registered solvers, sorted."""
    return tuple(sorted(_entry_points()))


@lru_cache(maxsize=None)
def get_solver(name):
    """The solver registered as ``name``; ``KeyError`` naming the known ones."""
    eps = _entry_points()
    if name not in eps:
        known = ", ".join(sorted(eps)) or "none (is the package installed? pip install -e .)"
        raise KeyError(f"unknown solver {name!r}; known: {known}")
    solver = eps[name].load()()
    if getattr(solver, "name", None) != name:
        raise TypeError(f"entry point {name!r} gives a solver named {getattr(solver, 'name', None)!r}")
    return solver


def solve(name, problem, *, options, progress=None, initial=None):
    """Calibrate ``problem`` with the solver ``name``.

    Parameters
    ----------
    name : str
        A registered solver name (:func:`solver_names`).
    problem : graph_calib.records.problem.Problem
    options : graph_calib.options.CalibrationOptions
    progress : callable, optional
        Called with a :class:`graph_calib.solvers.interface.ProgressEvent` after each iteration.
    initial : tuple (R, x), optional
        Starting keyframe attitudes (K+1, 3, 3) and calibration (P,).

    Returns
    -------
    graph_calib.solvers.interface.SolverOutput
        As the solver gave it, its covariance with the data's information removed along the directions
        the record cannot resolve (``problem.model.resolved_covariance``: a heading drift that looks
        like a g-sensitivity on a hand-held consumer record; docs/model.md), one place for every solver.
    """
    output = get_solver(name).solve(problem, options=options, progress=progress, initial=initial)
    model = getattr(problem, "model", None)
    if model is None or output.layout.names != model.layout.names:
        return output
    covariance = model.resolved_covariance(output.x, output.covariance)
    return output if covariance is output.covariance else replace(output, covariance=covariance)


__all__ = ["ENTRY_POINT_GROUP", "DEFAULT_SOLVERS", "solver_names", "get_solver", "solve"]
