"""The factor-graph batch calibrator: GTSAM over the shared model, one experiment.

Variables: a ``Rot3`` at every keyframe boundary and the calibration vector ``C(0)``.  Factors, their
residuals and Jacobians the model's (:mod:`graph_calib.model.residual_list`): a calibrated rotation
preintegration factor between consecutive keyframes, a gravity factor per keyframe, an encoder factor per
keyframe holding its valid table readings, the prior of each segment's first attitude (its alignment)
and the calibration prior (the grade's).  A record cut into segments (``/imu/segment``) has no rotation
factor from the last keyframe of a segment to the first of the next (:attr:`CalibrationModel.segment_keys`).

Python factors are slow when GTSAM's own optimiser calls them (``shared/notes/engineering-facts.md``), so
the Levenberg-Marquardt loop is the project's one driver (:mod:`graph_calib.solvers.least_squares`), this
graph its case of one experiment with ``x = theta``: each iteration linearises the factors vectorised, the
attitude chain eliminated by a banded Cholesky (as GTSAM's elimination of the chain does), and GTSAM
solves the reduced graph on ``C(0)`` (that factor, the calibration prior, the damping) and assembles the
marginal information at the solution.  ``tests/solvers/test_factor_graph_reduced.py`` checks cost, step and
covariance against GTSAM's own linearisation and elimination of the whole graph (every attitude a
variable, the model's factors as ``CustomFactor`` callbacks: ``tests/solvers/_gtsam_oracle.py``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from gtsam.symbol_shorthand import C
from threadpoolctl import threadpool_limits

from graph_calib.model.residual_list import FACTOR_KINDS
from graph_calib.options import GraphOptions
from graph_calib.sensors.params import Layout
from graph_calib.solvers.interface import WHITENED_RESIDUAL, ResidualSeries, SolverOutput
from graph_calib.solvers.least_squares import Experiment, LeastSquares


@dataclass(frozen=True)
class GraphResult:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    x : ndarray (P,)
        Calibration estimate (SI, ``layout`` order).
    covariance : ndarray (P, P)
        Its marginal covariance.
    layout : graph_calib.sensors.params.Layout
    attitudes : ndarray (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.
    residuals : dict
        Whitened residual series per factor kind: ``{kind: (times (F,), whitened (F, 3))}``.
    iterations : int
    cost_history : list of float
        The graph's error (half the sum of squared whitened residuals) after each iteration.
    seconds : float
    converged : bool
        Whether a stopping rule ended the iterations (else ``max_iterations`` did).
    """

    x: np.ndarray
    covariance: np.ndarray
    layout: Layout
    attitudes: np.ndarray
    residuals: dict
    iterations: int
    cost_history: list = field(default_factory=list)
    seconds: float = 0.0
    converged: bool = False


def solve(model, *, q_nb0, options=GraphOptions(), progress=None, initial=None):
    """Calibrate by Levenberg-Marquardt over the factor graph of ``model``.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    q_nb0 : ndarray, shape (4,) or (S, 4)
        Prior attitude at the start of the record (alignment), scalar first; one per segment for a
        record of ``S`` segments.
    options : GraphOptions
    progress : callable, optional
        Called with a :class:`graph_calib.solvers.interface.ProgressEvent` after each iteration.
    initial : tuple (R, x), optional
        Starting keyframe attitudes (K+1, 3, 3) and calibration (P,) instead of
        dead reckoning from the priors (e.g. a previous solution embedded in a
        larger layout, for a score test of a further effect).

    Returns
    -------
    GraphResult

    Notes
    -----
    BLAS runs on one thread inside the solve: its products have a few tens of columns, where OpenBLAS's
    threads gain nothing on two cores and, on a machine shared with other work (or beside the filter in
    ``calibrate``), spin.
    """
    t0 = time.perf_counter()
    x_prior, x_sigma = model.prior()
    R_prior = model.segment_priors(q_nb0)
    if initial is None:
        x = x_prior.copy()
        preint = model.preintegrate(x)
        R = model.propagate(R_prior, preint, x)
    else:
        R = np.asarray(initial[0], dtype=float)
        x = np.asarray(initial[1], dtype=float).copy()
        preint = model.preintegrate(x)
    # no table readings: the heading is held by the Earth rate alone; searched once the calibration settles
    # (one segment only: graph_calib.solvers.heading)
    heading = initial is None and model.record.reading_t.size == 0 and model.segment_keys.size == 1
    exp = Experiment(model=model, R=R, R_prior=R_prior, preint=preint, keys=[C(0)], search_heading=heading)
    lsq = LeastSquares([exp], theta_keys=[(C(0), x.size)], prior_mean=x_prior, prior_sigma=x_sigma,
                       options=options, solver=FactorGraphSolver.name)
    with threadpool_limits(limits=1, user_api="blas"):
        sol = lsq.solve(x, prefit=initial is None, progress=progress)
    residuals = {kind.name: (kind.times(model), sol.whitened[0][kind.name])
                 for kind in FACTOR_KINDS if kind.name in sol.whitened[0]}
    return GraphResult(x=sol.theta, covariance=sol.covariance, layout=model.layout, attitudes=exp.R.copy(),
                       residuals=residuals, iterations=sol.iterations, cost_history=sol.cost_history,
                       seconds=time.perf_counter() - t0, converged=sol.converged)


class FactorGraphSolver:
    """The factor graph behind the solver interface (registered under its ``name``)."""

    name = "factor-graph"

    def solve(self, problem, *, options, progress=None, initial=None):
        """Calibrate ``problem`` (:class:`graph_calib.records.problem.Problem`) with ``options.graph``.

        Returns
        -------
        graph_calib.solvers.interface.SolverOutput
            Residual series: the whitened residuals of every factor kind at the solution.
        """
        gr = solve(problem.model, q_nb0=problem.q_nb0, options=options.graph, progress=progress, initial=initial)
        return SolverOutput(
            solver=self.name, layout=gr.layout, x=gr.x, covariance=gr.covariance, t_key=problem.model.t_key.copy(),
            attitudes=gr.attitudes,
            residuals={kind: ResidualSeries(t=np.asarray(t, dtype=float), values=np.asarray(w, dtype=float))
                       for kind, (t, w) in gr.residuals.items()},
            residual_quantity=WHITENED_RESIDUAL, iterations=gr.iterations, converged=bool(gr.converged),
            final_cost=float(gr.cost_history[-1]), seconds=gr.seconds,
        )
