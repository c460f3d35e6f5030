"""The square-root filter behind graph-calib's solver interface (registered as :data:`kf_reference.passes.SOLVER_NAME`)."""

from __future__ import annotations

import time

import numpy as np

from graph_calib.solvers.interface import NORMALISED_INNOVATION, ResidualSeries, SolverOutput
from kf_reference.passes import SOLVER_NAME, calibrate


def output_of(fr, *, t_key, seconds=0.0):
    """The :class:`graph_calib.solvers.interface.SolverOutput` of a :class:`kf_reference.FilterResult`.

    Residual series: the normalised innovations of the last pass per measurement kind.
    """
    return SolverOutput(
        solver=SOLVER_NAME, layout=fr.layout, x=fr.x, covariance=fr.covariance, t_key=np.asarray(t_key),
        attitudes=fr.C_nb,
        residuals={kind: ResidualSeries(t=t, values=v) for kind, (t, v) in fr.innovation_series().items()},
        residual_quantity=NORMALISED_INNOVATION, iterations=fr.n_passes, converged=bool(fr.converged),
        final_cost=float(fr.passes[-1].cost), seconds=float(seconds),
        figures={"seconds_filter_per_pass": float(np.mean([p.seconds_filter for p in fr.passes]))},
    )


class SqrtKalmanSolver:
    """The iterated square-root Kalman filter of :mod:`kf_reference` as a graph-calib solver."""

    name = SOLVER_NAME

    def solve(self, problem, *, options, progress=None, initial=None):
        """Calibrate ``problem`` (:class:`graph_calib.records.problem.Problem`) with ``options.filter``."""
        t0 = time.perf_counter()
        fo = options.filter
        fr = calibrate(problem.model, q_nb0=problem.q_nb0, max_passes=fo.max_passes, x_tol=fo.x_tol,
                       attitude_tol=fo.attitude_tol, progress=progress, initial=initial)
        return output_of(fr, t_key=problem.model.t_key, seconds=time.perf_counter() - t0)


__all__ = ["SqrtKalmanSolver", "output_of"]
