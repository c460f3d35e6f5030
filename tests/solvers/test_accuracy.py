"""Both solvers against the simulator's truth: the accuracy points of the filter's and the graph's issues.

The simulator (graph_calib.simulation) makes its increments by quadrature of the
exact turntable kinematics, independently of the model's preintegration, so these
tests check the shared model's physics as well as the solvers:

- noise-free navigation-grade subrange: every estimated parameter within 0.1 sigma;
- Monte Carlo over 20 seeds of the shortened scenario: per parameter group the RMS
  of (estimate - truth) / sigma in [0.7, 1.3], at least 95 % within 3 sigma, and the
  two solvers on the same estimate (1e-3 of a sigma) every time;
- the full 1.5 h subrange with noise: the two solvers agree (0.1 sigma, sigma ratio
  in [0.9, 1.1]) and each one's calibration leaves sensor errors under 0.01 deg/h
  and 2e-4 m/s^2 over the subrange's temperatures (against the truth curves);
- the consumer hand-held scenario converges from a zero calibration.
"""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib import constants as c
from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.model import ModelOptions
from graph_calib.simulation import simulate
from graph_calib.evaluation.validation import ResultCalibration, validate

from graph_calib.solvers.registry import DEFAULT_SOLVERS as SOLVERS
from graph_calib.solvers.results import compare


def _run(solver, problem, *, options):
    """``(Result, SolverOutput)`` of one solver, through the one dispatch."""
    run = solve_problem(problem, options=options, solvers=(solver,))
    return run.results[solver], run.outputs[solver]


def _simulated(name, seed, **options):
    return simulate(name, rng=np.random.default_rng(seed), **options).run()[0]


def _problem(se, **model_options):
    opts = CalibrationOptions(model=ModelOptions(**model_options), t_ref_degC=se.truth.t_ref_degC)
    return build_problem(se.experiment, options=opts), opts


def _z(result, truth):
    """(estimate - truth) / sigma of every estimated element, in the result's order."""
    names = list(result.values)
    est = np.array([result.values[n] for n in names])
    sig = np.array([result.sigmas[n] for n in names])
    ref = np.array([truth.values[n] for n in names])
    return names, (est - ref) / sig


def _worst(names, z):
    i = int(np.argmax(np.abs(z)))
    return names[i], float(z[i])


# ---------------------------------------------------------------------------
# noise-free
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module", params=["static", "all"])
def noise_free_short(request):
    """Encoder readings valid only at rest (the usual bench), or also while the table turns."""
    se = _simulated("nav-subrange-short", 7, noise=False, curvature=False, table_valid=request.param)
    problem, opts = _problem(se)
    # without noise there is no chi-square to estimate variance factors from: the declared sigmas are the scale
    return se, problem, replace(opts, variance_components=False, structure_tests=False), request.param


@pytest.mark.parametrize("solver", SOLVERS)
def test_noise_free_subrange_within_a_tenth_of_sigma(noise_free_short, solver):
    se, problem, opts, valid = noise_free_short
    res, raw = _run(solver, problem, options=opts)
    assert raw.converged and res.residuals["converged"]
    names, z = _z(res, se.truth)
    assert np.abs(z).max() < 0.1, _worst(names, z)
    assert "lever_arm.x" in res.values
    if valid == "static":
        # what the data cannot inform is not reported as an estimate: a lag changes no reading at rest
        assert "time_lag.table" not in res.values
    else:
        # readings in motion determine the lag to well under a microsecond
        assert res.sigmas["time_lag.table"] < 1e-5


# ---------------------------------------------------------------------------
# Monte Carlo
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def monte_carlo():
    """20 seeds of the shortened scenario (noise, curved temperature truth), both solvers."""
    z = {s: [] for s in SOLVERS}
    between = []
    for seed in range(20):
        se = _simulated("nav-subrange-short", 1000 + seed, hours=0.25)
        problem, opts = _problem(se)
        res = {s: _run(s, problem, options=opts)[0] for s in SOLVERS}
        for s, r in res.items():
            names, zs = _z(r, se.truth)
            z[s].append(zs)
        between.append(compare(res["sqrt-kf"], res["factor-graph"])["summary"]["max_abs_difference_in_sigma"])
    return r.effects, names, {s: np.array(v) for s, v in z.items()}, np.array(between)


@pytest.mark.montecarlo
@pytest.mark.parametrize("solver", SOLVERS)
def test_monte_carlo_sigmas_are_consistent(monte_carlo, solver):
    groups, names, z_all, _ = monte_carlo
    z = z_all[solver]
    assert z.shape == (20, len(names)) and len(groups) >= 12
    assert np.mean(np.abs(z) < 3.0) >= 0.95, np.mean(np.abs(z) < 3.0)
    for g in groups:
        cols = [i for i, n in enumerate(names) if n == g or n.startswith(g + ".")]
        rms = float(np.sqrt(np.mean(z[:, cols] ** 2)))
        assert 0.7 <= rms <= 1.3, (g, rms)


@pytest.mark.montecarlo
def test_monte_carlo_solvers_on_the_same_estimate(monte_carlo):
    *_, between = monte_carlo
    assert between.max() < 1e-3, between


# ---------------------------------------------------------------------------
# the full navigation-grade subrange with noise
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def nav_subrange():
    se = _simulated("nav-subrange", 7)
    problem, opts = _problem(se)
    return se, {s: _run(s, problem, options=opts)[0] for s in SOLVERS}


@pytest.mark.slow
def test_solvers_agree_on_the_subrange(nav_subrange):
    _, res = nav_subrange
    cmp = compare(res["sqrt-kf"], res["factor-graph"])
    worst = max(cmp["parameters"].items(), key=lambda kv: abs(kv[1]["difference_in_sigma"]))
    assert cmp["summary"]["max_abs_difference_in_sigma"] <= 0.1, worst
    lo, hi = cmp["summary"]["sigma_ratio_range"]
    assert 0.9 <= lo and hi <= 1.1, (lo, hi)
    assert cmp["summary"]["agree"] and cmp["summary"]["parameters"] == len(res["sqrt-kf"].values)


@pytest.mark.slow
@pytest.mark.parametrize("solver", SOLVERS)
def test_remaining_sensor_errors_after_calibration(nav_subrange, solver):
    se, res = nav_subrange
    v = validate(se.experiment, ResultCalibration(res[solver]), se.truth).summary()
    g_static = np.array(v["gyro_radps"]["static"]["max"])
    a_all = np.array(v["accel_mps2"]["all"]["max"])
    assert v["gyro_criterion"] == "static windows" and v["pass"]["all"], v["largest"]
    assert np.all(g_static * c.RS_TO_DH < 0.01), g_static * c.RS_TO_DH
    assert np.all(a_all < 2e-4), a_all
    # not vacuous: the uncalibrated sensor errors are far above the thresholds
    raw = validate(se.experiment, ResultCalibration(_zero_like(res[solver])), se.truth).summary()
    assert np.max(raw["gyro_radps"]["static"]["max"]) * c.RS_TO_DH > 0.1
    assert np.max(raw["accel_mps2"]["all"]["max"]) > 2e-3


def _zero_like(result):
    from dataclasses import replace

    return replace(result, values={k: 0.0 for k in result.values})


# ---------------------------------------------------------------------------
# consumer MEMS, hand-held, no table
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def consumer_handheld():
    se = _simulated("consumer-handheld", 7)
    problem, opts = _problem(se, grade="consumer")
    return se, problem, opts


@pytest.mark.slow
@pytest.mark.parametrize("solver", SOLVERS)
def test_consumer_handheld_converges_from_zero_calibration(consumer_handheld, solver):
    se, problem, opts = consumer_handheld
    res, raw = _run(solver, problem, options=opts)
    assert raw.converged
    names, z = _z(res, se.truth)
    prior = problem.model.prior()[1]
    truth_in_prior_sigma = np.array([se.truth.values[n] for n in names]) / prior
    assert np.abs(truth_in_prior_sigma).max() > 0.5        # the truth is far from the zero start
    assert np.abs(z).max() < 3.5, _worst(names, z)
    assert np.sqrt(np.mean(z**2)) < 1.5
    assert "lever_arm.x" not in res.values and "mount.x" not in res.values
