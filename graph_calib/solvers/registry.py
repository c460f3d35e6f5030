"""Solvers by name: one dispatch for the command line, the campaign, the diagnosis and the tests.

Solvers register through the ``graph_calib.solvers`` entry-point group of the package metadata
(``pyproject.toml``), so a solver module imports this interface and the shared model, and nothing
here imports a solver: the layers stay one-way.  A new solver is a class with ``name`` and
``solve(problem, *, options, progress=None, initial=None) -> SolverOutput`` plus one line in
``[project.entry-points."graph_calib.solvers"]``; a solver that takes a whole campaign at once also has
``campaign = True`` and ``solve_campaign``.  The command line's ``--solver`` values, the manifest's
``[solver] solvers``, the campaign's tasks and the diagnosis all read their solvers from here: this module
and the solvers' own modules are the only places that spell a solver's name.

>>> solver_names()                                               # doctest: +SKIP
('factor-graph', 'joint', 'sqrt-kf')
>>> output = solve(PRIMARY_SOLVER, problem, options=CalibrationOptions())   # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from importlib.metadata import entry_points

import numpy as np

#: The entry-point group solvers register in.
ENTRY_POINT_GROUP = "graph_calib.solvers"

#: The per-experiment solvers run by default, in the order results are compared (filter first).
DEFAULT_SOLVERS = ("sqrt-kf", "factor-graph")

#: The solver a run leans on when it has it: the diagnosis' rounds linearise at its solution, a campaign
#: stitches, validates and starts its joint solve from its results, reports show it first.
PRIMARY_SOLVER = "factor-graph"

#: The ``solver`` of a prediction's result file (``graph-calib predict``): sigmas a calibration would reach, no
#: calibration (apply and export refuse it).
PREDICTION_SOLVER = "prediction"

#: What reports call the registered solvers (a solver not listed is called by its name).
SOLVER_LABELS = {"sqrt-kf": "square-root KF", "factor-graph": "factor graph"}

#: The ``--solver`` / ``[solver] solvers`` value that stands for :data:`DEFAULT_SOLVERS` (and, for a campaign,
#: every registered campaign solver too); ``per-subrange`` is the default solvers without the campaign solvers.
BOTH = "both"
PER_SUBRANGE = "per-subrange"


@lru_cache(maxsize=None)
def _entry_points():
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def solver_names():
    """Names of the registered solvers, sorted (read from the package metadata: no solver is imported)."""
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


def is_campaign_solver(name):
    """Whether the solver ``name`` takes every experiment of a campaign at once (``campaign = True``)."""
    return bool(getattr(get_solver(name), "campaign", False))


def experiment_solvers():
    """Registered per-experiment solvers, the default ones first in their order, then the others sorted."""
    names = [n for n in solver_names() if not is_campaign_solver(n)]
    return tuple(n for n in DEFAULT_SOLVERS if n in names) + tuple(n for n in names if n not in DEFAULT_SOLVERS)


def campaign_solvers():
    """Registered campaign solvers, sorted."""
    return tuple(n for n in solver_names() if is_campaign_solver(n))


def comparison_order(names):
    """``names`` in the order their results are compared: the default solvers' order first, then as given."""
    names = tuple(names)
    return tuple(n for n in DEFAULT_SOLVERS if n in names) + tuple(n for n in names if n not in DEFAULT_SOLVERS)


def primary_first(names):
    """``names`` with :data:`PRIMARY_SOLVER` first when it is one of them (the diagnosis' order)."""
    names = tuple(names)
    return tuple(n for n in names if n == PRIMARY_SOLVER) + tuple(n for n in names if n != PRIMARY_SOLVER)


def primary_of(names):
    """The solver of ``names`` a run leans on: :data:`PRIMARY_SOLVER` when present, else the first (None if none)."""
    names = tuple(names)
    return PRIMARY_SOLVER if PRIMARY_SOLVER in names else (names[0] if names else None)


def choice_help(*, campaign=False):
    """What ``--solver`` (or ``[solver] solvers``) accepts, in words, from the registered names."""
    names = ", ".join(solver_names())
    if campaign:
        return (f"'{BOTH}' (the default solvers and every campaign solver), '{PER_SUBRANGE}' (the default solvers), "
                f"or registered solver names joined by '+' ({names})")
    return f"'{BOTH}' (the default solvers) or registered per-experiment solver names joined by '+' ({names})"


def parse_choice(value, *, campaign=False):
    """The solvers a ``--solver`` / ``[solver] solvers`` value stands for: ``(per-experiment, campaign)`` names.

    ``both``: :data:`DEFAULT_SOLVERS` (and every campaign solver when ``campaign``); ``per-subrange``
    (``campaign`` only): the default solvers alone; else registered names joined by ``+`` (campaign solvers
    only when ``campaign``).  ``ValueError`` saying what is accepted otherwise.
    """
    if not isinstance(value, str) or not value:
        raise ValueError(f"must be {choice_help(campaign=campaign)}")
    if value == BOTH:
        return DEFAULT_SOLVERS, (campaign_solvers() if campaign else ())
    if value == PER_SUBRANGE and campaign:
        return DEFAULT_SOLVERS, ()
    names = value.split("+")
    unknown = [n for n in names if n not in _entry_points()]
    if unknown:
        raise ValueError(f"unknown solver {', '.join(map(repr, unknown))}: must be {choice_help(campaign=campaign)}")
    if len(set(names)) != len(names):
        raise ValueError(f"a solver named twice in {value!r}: must be {choice_help(campaign=campaign)}")
    per, whole = [], []
    for n in names:
        (whole if is_campaign_solver(n) else per).append(n)
    if whole and not campaign:
        raise ValueError(f"{', '.join(whole)} solves a whole campaign (graph-calib campaign), not one experiment")
    return comparison_order(per), tuple(whole)


#: A solve whose solution only starts another (a cold start's first solve, :func:`_solve_cold`; the variance
#: components' solves before the final one) stops once a factor-graph iteration lowers the cost by less than this
#: fraction ...
LOOSE_REL_TOL = 1e-4
#: ... or a filter pass moves every calibration element by less than this fraction of its sigma.
LOOSE_X_TOL = 0.1


def loose(options):
    """``options`` with the tolerances of a solve whose solution only starts another (:data:`LOOSE_REL_TOL`)."""
    return replace(options, graph=replace(options.graph, rel_tol=max(options.graph.rel_tol, LOOSE_REL_TOL),
                                          covariance=False),
                   filter=replace(options.filter, x_tol=max(options.filter.x_tol, LOOSE_X_TOL),
                                  attitude_tol=max(options.filter.attitude_tol, 10 * LOOSE_X_TOL)))


def _solve_cold(solver, problem, *, options, progress):
    """``solver`` on ``problem`` from its own start.

    A model whose keyframe gravity and rotation factors share the gyros' noise (``ModelOptions.gravity_gyro_shared``)
    is solved first with the two independent, then from that solution: far from the solution the conditioned
    rotation factor carries the gravity factor's misfit at the gyro's small sigma (:mod:`graph_calib.model.
    gravity_gyro_noise`), and from a dead-reckoned start the factor graph crept for hundreds of iterations and the
    filter stopped in another minimum (the Xsens hold-out record); the two models' solutions lie within a fraction
    of a sigma of each other.
    """
    model = getattr(problem, "model", None)
    if model is None or not model.options.gravity_gyro_shared:
        return solver.solve(problem, options=options, progress=progress, initial=None)
    first = solver.solve(replace(problem, model=model.with_options(gravity_gyro_shared=False, heading_axes=False)),
                         options=loose(options), progress=progress, initial=None)
    return solver.solve(problem, options=options, progress=progress, initial=(first.attitudes, first.x))


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
        Starting keyframe attitudes (K+1, 3, 3) and calibration (P,); None: the solver's own start (:func:`_solve_cold`).

    Returns
    -------
    graph_calib.solvers.interface.SolverOutput
        As the solver gave it, its covariance with the data's information removed along the directions
        the record cannot resolve (``problem.model.resolved_covariance``: a heading drift that looks
        like a g-sensitivity on a hand-held consumer record; docs/model.md), one place for every solver.
    """
    solver = get_solver(name)
    if initial is None:
        output = _solve_cold(solver, problem, options=options, progress=progress)
    else:
        output = solver.solve(problem, options=options, progress=progress, initial=initial)
    model = getattr(problem, "model", None)
    if model is None or output.layout.names != model.layout.names or not np.all(np.isfinite(output.covariance)):
        return output
    covariance = model.resolved_covariance(output.x, output.covariance)
    return output if covariance is output.covariance else replace(output, covariance=covariance)


__all__ = ["ENTRY_POINT_GROUP", "DEFAULT_SOLVERS", "PRIMARY_SOLVER", "PREDICTION_SOLVER", "SOLVER_LABELS", "BOTH", "PER_SUBRANGE", "solver_names",
           "get_solver", "is_campaign_solver", "experiment_solvers", "campaign_solvers", "comparison_order",
           "primary_first", "primary_of", "choice_help", "parse_choice", "solve"]
