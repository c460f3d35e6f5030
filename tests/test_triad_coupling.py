"""``gyro.g_sensitivity`` sees the calibrated specific force (model.md; issue #13), end to end.

A consumer-grade Ferraris session (biases up to 1 m/s^2, where the raw specific force would put a
first-order error on ``G f``) simulated with g-sensitivity switched on, calibrated with the effect:

- both solvers from scratch: every ``G`` element within 3 sigma of the truth, filter and graph within a
  small fraction of sigma of each other;
- warm-started from the declared model's solution (as the closed loop does when it adds the effect):
  the same answer as from scratch, in both solvers.
"""

import numpy as np
import pytest

from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.model import ModelOptions
from graph_calib.simulation import simulate
from graph_calib.solvers.registry import solve

EFFECT = "gyro.g_sensitivity"
SOLVERS = ("sqrt-kf", "factor-graph")


def _options(se, effects):
    return CalibrationOptions(model=ModelOptions(grade="consumer", extra_effects=effects),
                              t_ref_degC=se.truth.t_ref_degC)


@pytest.fixture(scope="module")
def fits():
    se = simulate("consumer-ferraris", rng=np.random.default_rng(3), effects=(EFFECT,)).run()[0]
    opts = _options(se, (EFFECT,))
    problem = build_problem(se.experiment, options=opts)
    scratch = dict(solve_problem(problem, options=opts, solvers=SOLVERS).outputs)
    # warm start: the declared model's graph solution embedded in the layout with the effect
    opts0 = _options(se, ())
    problem0 = build_problem(se.experiment, options=opts0)
    out0 = solve("factor-graph", problem0, options=opts0)
    x0 = problem.model.layout.embed(problem0.model.layout, out0.x)
    warm = {name: solve(name, problem, options=opts, initial=(out0.attitudes, x0)) for name in SOLVERS}
    layout = problem.model.layout
    truth = np.array([se.truth.values[n] for n in layout.element_names()])
    g = np.arange(layout.size)[layout.slice(EFFECT)]
    return truth, scratch, warm, g


def _sigma(out):
    return np.sqrt(np.diag(out.covariance))


def test_the_g_sensitivity_is_estimated_within_3_sigma_by_both_solvers(fits):
    truth, scratch, warm, g = fits
    for name in SOLVERS:
        out = scratch[name]
        assert out.converged, name
        sig = _sigma(out)[g]
        z = (out.x[g] - truth[g]) / sig
        assert np.all(np.abs(z) < 3.0), (name, np.round(z, 2))
        assert np.sum(np.abs(truth[g]) > 3.0 * sig) >= 3, (name, sig, truth[g])   # the data see G


def test_filter_and_graph_agree_on_g_to_a_small_fraction_of_sigma(fits):
    truth, scratch, warm, g = fits
    kf, fg = scratch["sqrt-kf"], scratch["factor-graph"]
    d = (kf.x[g] - fg.x[g]) / _sigma(fg)[g]
    assert np.abs(d).max() < 0.1, np.round(d, 3)


def test_warm_start_gives_the_scratch_answer_in_both_solvers(fits):
    truth, scratch, warm, g = fits
    for name in SOLVERS:
        r, w = scratch[name], warm[name]
        assert w.converged, name
        d = (w.x - r.x) / _sigma(r)
        assert np.abs(d).max() < 0.02, (name, int(np.argmax(np.abs(d))), float(np.abs(d).max()))
        np.testing.assert_allclose(_sigma(w), _sigma(r), rtol=1e-3)
