"""The solver interface: one signature, a registry by name, one output and progress event, one result assembly.

- :mod:`graph_calib.solvers.interface`: :class:`SolverOutput`, :class:`ResidualSeries`,
  :class:`ProgressEvent`, the :class:`Solver` protocol;
- :mod:`graph_calib.solvers.registry`: solvers by name (entry points), :func:`solve`;
- :mod:`graph_calib.solvers.results`: the result file and ``comparison.json`` from solver outputs.
"""

from graph_calib.solvers.interface import ProgressEvent, ResidualSeries, Solver, SolverOutput
from graph_calib.solvers.registry import DEFAULT_SOLVERS, get_solver, solve, solver_names
from graph_calib.solvers.results import compare, to_result

__all__ = ["ProgressEvent", "ResidualSeries", "Solver", "SolverOutput", "DEFAULT_SOLVERS", "get_solver", "solve",
           "solver_names", "compare", "to_result"]
