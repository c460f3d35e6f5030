"""The factor graph's iteration (graph_calib/solvers/factor_graph.py) against GTSAM's own graph.

Each iteration of the factor graph evaluates its cost from the model's vectorised residuals and solves its
damped step with the attitudes eliminated in numpy (graph_calib/solvers/reduced.py), GTSAM solving the
reduced graph on ``C(0)``.  The reference is the nonlinear graph itself (``build_graph``: every keyframe
attitude a ``Rot3``, the model's factors as ``CustomFactor`` callbacks, GTSAM's prior factors):
``graph.error`` and GTSAM's elimination of the whole damped linearisation.  At a point off the solution
(calibration and attitudes disturbed, the preintegration formed at another calibration so that its
first-order correction is in play), on a turntable record with encoder readings (with and without a robust
loss) and on a hand-held record cut into segments (a prior on each segment's first attitude, no rotation
factor across a cut), cost and step must be GTSAM's to rounding.
"""

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import C, X

from graph_calib.calibrate import build_problem
from graph_calib.solvers.factor_graph import _Cache, _damped, _Step, _values, build_graph
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.sensors.params import Layout, grade
from graph_calib.navigation.rotations import exp_so3
from graph_calib.simulation import simulate
from graph_calib.solvers import reduced

from _synthetic import turntable_experiment

DECL = Layout.declared()


def _turntable():
    rng = np.random.default_rng(5)
    x = rng.normal(size=DECL.size) * grade("navigation").prior_vector(DECL) * 0.1
    for n in ("mount", "lever_arm", "time_lag.table"):
        x[DECL.slice(n)] = 0.0
    exp, _ = turntable_experiment(layout=DECL, x=x, rng=rng, static_s=30.0, dwell_s=3.0,
                                  noise=(1e-4, 1e-4, 1e-5))
    return build_problem(exp)


def _cut_handheld():
    se = simulate("consumer-handheld", rng=np.random.default_rng(7), cut=True).run()[0]
    return build_problem(se.experiment, options=CalibrationOptions(model=ModelOptions(grade="consumer"),
                                                                    t_ref_degC=se.truth.t_ref_degC))


@pytest.fixture(scope="module", params=["turntable", "cut-handheld"])
def problem(request):
    return {"turntable": _turntable, "cut-handheld": _cut_handheld}[request.param]()


def _point(problem, rng):
    """A calibration 0.3 prior sigma from zero, the preintegration formed 1e-3 prior sigma away from it, the
    attitudes dead-reckoned and disturbed by 1 mrad."""
    m = problem.model
    _, sig = m.prior()
    x = 0.3 * sig * rng.normal(size=sig.size)
    preint = m.preintegrate(x + 1e-3 * sig * rng.normal(size=sig.size))
    R_prior = m.segment_priors(problem.q_nb0)
    R = m.propagate(R_prior, preint, x) @ exp_so3(1e-3 * rng.normal(size=(m.n_keyframes + 1, 3)))
    return x, preint, R, R_prior


@pytest.mark.parametrize("robust", [None, "huber"])
def test_cost_and_damped_step_are_gtsams(problem, robust):
    m = problem.model
    x, preint, R, R_prior = _point(problem, np.random.default_rng(3))
    x_prior, x_sigma = m.prior()
    K, P = m.n_keyframes, m.layout.size
    # GTSAM: the whole nonlinear graph, its error and its damped linearisation eliminated
    cache = _Cache(m, preint)
    cache.evaluate(R, x)
    graph = build_graph(m, cache, R_prior=R_prior, robust=robust)
    values = _values(R, x)
    cache.invalidate()
    error = graph.error(values)
    cache.invalidate()
    gfg = graph.linearize(values)
    ordering = gtsam.Ordering()
    for k in range(K + 1):
        ordering.push_back(X(k))
    ordering.push_back(C(0))
    # the solver's: the model's residuals vectorised, the attitudes eliminated, GTSAM on C(0)
    prior_graph = gtsam.NonlinearFactorGraph()
    prior_graph.add(gtsam.PriorFactorVector(C(0), x_prior, gtsam.noiseModel.Diagonal.Sigmas(x_sigma)))
    cal = gtsam.Values()
    cal.insert(C(0), x)
    system = reduced.linearise(m, preint, R, x, np.eye(P), R_prior=R_prior, robust=robust)
    cost = system.cost + prior_graph.error(cal)
    assert cost == pytest.approx(error, rel=1e-12)
    assert reduced.cost(m, preint, R, x, R_prior=R_prior, robust=robust) == system.cost
    step = _Step(prior_graph, P)
    for lam in (1e-9, 1e-3, 10.0):
        delta = _damped(gfg, [X(k) for k in range(K + 1)] + [C(0)], lam, [3] * (K + 1) + [P]).optimize(ordering)
        dR_ref = np.array([delta.at(X(k)) for k in range(K + 1)])
        dx_ref = np.asarray(delta.at(C(0)))
        dR, dx = step(system, x, lam)
        # in units of the prior sigmas (the calibration) and of the largest attitude change
        np.testing.assert_allclose(dx / x_sigma, dx_ref / x_sigma, rtol=0, atol=1e-7 * np.max(np.abs(dx_ref / x_sigma)))
        np.testing.assert_allclose(dR, dR_ref, rtol=0, atol=1e-7 * np.max(np.abs(dR_ref)))


@pytest.mark.parametrize("robust", [None, "huber"])
def test_cost_by_keyframe_sums_to_the_cost(problem, robust):
    m = problem.model
    x, preint, R, R_prior = _point(problem, np.random.default_rng(4))
    by_key = reduced.cost_by_key(m, preint, R, x, R_prior=R_prior, robust=robust)
    assert by_key.shape == (m.n_keyframes + 1,)
    assert np.sum(by_key) == pytest.approx(reduced.cost(m, preint, R, x, R_prior=R_prior, robust=robust), rel=1e-12)
    # each segment's share depends on that segment's attitudes alone: turn the last segment only
    last = int(m.segment_keys[-1])
    turned = R.copy()
    turned[last:] = exp_so3(np.array([0.0, 0.0, 1.0])) @ R[last:]
    other = reduced.cost_by_key(m, preint, turned, x, R_prior=R_prior, robust=robust)
    if last > 0:
        np.testing.assert_array_equal(other[:last - 1], by_key[:last - 1])
    assert not np.allclose(other[last:], by_key[last:])
