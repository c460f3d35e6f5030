"""The factor graph's heading search (graph_calib.solvers.heading) on the measured Xsens session.

Without a table the session's heading is held by the Earth rate alone; Levenberg-Marquardt crawled along it
for twenty iterations with the calibration already settled.  With the search (once, when the calibration has
settled) the graph must reach the same point (the stopping rules unchanged: estimates within 1e-3 of their
sigmas, the same cost to 1e-10 relative) in far fewer iterations; a grid holding only the present heading
turns nothing and gives the crawl back.
"""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.solvers import factor_graph
from graph_calib.calibrate import build_problem
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.solvers import heading, solve


@pytest.fixture(scope="module")
def problem(xsens_consumer):
    """The session with a keyframe's gravity and rotation factors independent: the model of a cold start's first
    solve (graph_calib.solvers.registry), where the heading search acts; the second starts at its solution."""
    prob, opts = xsens_consumer
    return replace(prob, model=prob.model.with_options(gravity_gyro_shared=False, heading_axes=False)), opts


@pytest.mark.slow
def test_the_heading_search_reaches_the_same_point_in_fewer_iterations(problem, monkeypatch):
    prob, opts = problem
    searched = factor_graph.solve(prob.model, q_nb0=prob.q_nb0, options=opts.graph)
    monkeypatch.setattr(heading, "HEADING_GRID", np.zeros(1))
    crawled = factor_graph.solve(prob.model, q_nb0=prob.q_nb0, options=opts.graph)
    assert searched.converged and crawled.converged
    # (16 against 28 with the noise identified from the session's rests; 30 or more with the first rest's
    # per-sample scatter)
    assert searched.iterations <= 20 and crawled.iterations >= searched.iterations + 10, (searched.iterations,
                                                                                          crawled.iterations)
    sigma = np.sqrt(np.diag(crawled.covariance))
    assert np.max(np.abs(searched.x - crawled.x) / sigma) < 1e-3
    np.testing.assert_allclose(np.sqrt(np.diag(searched.covariance)), sigma, rtol=1e-6)
    assert searched.cost_history[-1] == pytest.approx(crawled.cost_history[-1], rel=1e-10)
    # the turn is kept only where it lowers the cost: the cost never rises
    assert np.all(np.diff(searched.cost_history) <= 0)


@pytest.mark.slow
def test_the_filter_reaches_the_same_point_in_fewer_passes(problem, monkeypatch):
    prob, opts = problem
    searched = solve("sqrt-kf", prob, options=opts)
    monkeypatch.setattr(heading, "HEADING_GRID", np.zeros(1))
    crawled = solve("sqrt-kf", prob, options=opts)
    assert searched.converged and crawled.converged
    assert searched.iterations <= 15 and crawled.iterations >= 20, (searched.iterations, crawled.iterations)
    sigma = np.sqrt(np.diag(crawled.covariance))
    assert np.max(np.abs(searched.x - crawled.x) / sigma) < 1e-3
    np.testing.assert_allclose(np.sqrt(np.diag(searched.covariance)), sigma, rtol=1e-4)


@pytest.mark.slow
def test_records_cut_into_segments_are_left_to_the_iterations(monkeypatch):
    """Several segments: their headings are tied through the calibration, so neither solver turns them
    (graph_calib.solvers.heading): the results are those of a grid holding only the present heading."""
    from graph_calib.simulation import simulate

    se = simulate("consumer-handheld", rng=np.random.default_rng(7), cut=True).run()[0]
    opts = CalibrationOptions(model=ModelOptions(grade="consumer"), t_ref_degC=se.truth.t_ref_degC)
    prob = build_problem(se.experiment, options=opts)
    assert prob.model.segment_keys.size > 1 and prob.model.record.reading_t.size == 0
    default = [solve(s, prob, options=opts) for s in ("factor-graph", "sqrt-kf")]
    monkeypatch.setattr(heading, "HEADING_GRID", np.zeros(1))
    for a, b in zip(default, [solve(s, prob, options=opts) for s in ("factor-graph", "sqrt-kf")]):
        assert a.iterations == b.iterations and np.array_equal(a.x, b.x)
