"""The factor graph's trial steps judged to first order (graph_calib.solvers.least_squares.FIRST_ORDER_JUDGE_TOL).

On the measured Xsens session (consumer grade, the iterations crawl and many trials are rejected) the
first-order judgement must leave every iteration as the exact judgement makes it, bit for bit, while
sparing the preintegrations of the trials it rejects.
"""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.solvers import factor_graph, least_squares
from graph_calib.model import CalibrationModel


@pytest.fixture(scope="module")
def problem(xsens_consumer):
    """The session with a keyframe's gravity and rotation factors independent: the model of a cold start's first
    solve (graph_calib.solvers.registry), where the first-order judging acts; the second starts at its solution."""
    prob, opts = xsens_consumer
    return replace(prob, model=prob.model.with_options(gravity_gyro_shared=False, heading_axes=False)), opts


def _solve(problem, opts, monkeypatch, judge_tol):
    monkeypatch.setattr(least_squares, "FIRST_ORDER_JUDGE_TOL", judge_tol)
    calls = {"n": 0}
    original = CalibrationModel.preintegrate

    def counting(self, *a, **k):
        calls["n"] += 1
        return original(self, *a, **k)

    monkeypatch.setattr(CalibrationModel, "preintegrate", counting)
    gr = factor_graph.solve(problem.model, q_nb0=problem.q_nb0, options=opts.graph)
    monkeypatch.undo()
    return gr, calls["n"]


@pytest.mark.slow
def test_first_order_judging_keeps_every_iteration_and_spares_preintegrations(problem, monkeypatch):
    prob, opts = problem
    exact, n_exact = _solve(prob, opts, monkeypatch, 0.0)        # every far trial preintegrated exactly
    judged, n_judged = _solve(prob, opts, monkeypatch, least_squares.FIRST_ORDER_JUDGE_TOL)
    assert exact.converged and judged.converged
    assert judged.cost_history == exact.cost_history
    assert np.array_equal(judged.x, exact.x) and np.array_equal(judged.covariance, exact.covariance)
    assert n_judged <= n_exact - 10, (n_judged, n_exact)
