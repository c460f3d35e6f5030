"""The staged solve when the gyro model does not fit (graph_calib.solvers.staged)."""

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from graph_calib.calibrate import calibrate
from graph_calib.compensation.calibration import Calibration
from graph_calib.evaluation.crossval import cross_validate, make_folds, record_rests, training_record
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.simulation.scenarios import simulate
from graph_calib.solvers.staged import GRAVITY_ONLY_FACTOR, Staging, gyro_misfit_gate
from graph_calib.solvers.verdict import STAGED_WORDS, VARIANCE_FACTOR_LIMIT, judge_kinds


def _fake_problem(*, has_table, factors):
    return SimpleNamespace(model=SimpleNamespace(record=SimpleNamespace(has_table=has_table),
                                                 options=SimpleNamespace(variance_factors=factors)))


def test_gate_opens_on_either_kind_without_a_table_only():
    big = 2.0 * VARIANCE_FACTOR_LIMIT
    assert gyro_misfit_gate(_fake_problem(has_table=False, factors={"rotation": big}))
    assert gyro_misfit_gate(_fake_problem(has_table=False, factors={"gravity": big}))
    assert not gyro_misfit_gate(_fake_problem(has_table=False, factors={"rotation": 1.5, "gravity": 0.5}))
    assert not gyro_misfit_gate(_fake_problem(has_table=True, factors={"rotation": big}))
    # the caller fixed the rotation kind's factor (a gravity-only fit): left alone
    assert not gyro_misfit_gate(_fake_problem(has_table=False, factors={"rotation": big}), fixed=("rotation",))


@dataclass(frozen=True)
class _Output:
    """The two fields of a SolverOutput that :meth:`Staging.finish` reads."""

    x: np.ndarray
    covariance: np.ndarray


def test_finish_propagates_the_gravity_only_covariance_exactly():
    rng = np.random.default_rng(4)
    P, a = 7, np.array([1, 4, 5])
    o = np.setdiff1d(np.arange(P), a)
    A = rng.normal(size=(12, P))
    lam = A.T @ A + 0.1 * np.eye(P)                      # information without the pin
    pin = np.zeros(P)
    pin[a] = 1e6                                        # the pinning prior's information
    sigma = np.linalg.inv(lam + np.diag(pin))           # what a staged solve reports
    B = rng.normal(size=(3, 3))
    cg = B @ B.T + 0.5 * np.eye(3)                      # the gravity-only stage's covariance of the pinned elements
    staging = Staging(rotation_factor=10.0, gravity_factor=1.0, elements=("a", "b", "c"), statistic=50.0,
                      threshold=16.3, dof=3, staged=True, problem=None, result_problem=None, initial=None,
                      x=np.zeros(P), covariance=np.zeros((P, P)), index=a)
    staging.covariance[np.ix_(a, a)] = cg
    out = staging.finish(_Output(x=np.zeros(P), covariance=sigma))
    # the others given the pinned elements: x_o = x_o* + S (x_a - x_a*), S = -lam_oo^-1 lam_oa
    loo_inv = np.linalg.inv(lam[np.ix_(o, o)])
    S = -loo_inv @ lam[np.ix_(o, a)]
    want = np.empty((P, P))
    want[np.ix_(a, a)] = cg
    want[np.ix_(o, a)] = S @ cg
    want[np.ix_(a, o)] = (S @ cg).T
    want[np.ix_(o, o)] = loo_inv + S @ cg @ S.T
    np.testing.assert_allclose(out.covariance, want, rtol=1e-7, atol=1e-12)


def test_verdict_says_the_gyro_model_does_not_fit():
    block = {"rotation_variance_factor": 1.0, "gravity_variance_factor": 109.0, "staged": True, "statistic": 2.3e4,
             "threshold": 54.6, "dof": 14, "gravity_only_rotation_factor": GRAVITY_ONLY_FACTOR,
             "pinned": ["accel.bias.x"]}
    result = SimpleNamespace(residuals={}, extra={"staged": block})
    _, problems, _ = judge_kinds(result)
    assert any(STAGED_WORDS in p and "gravity alone" in p for p in problems)
    _, problems, _ = judge_kinds(SimpleNamespace(residuals={}, extra={"staged": {**block, "staged": False}}))
    assert not problems


@pytest.mark.slow
def test_gyro_misfit_no_longer_spoils_the_accelerometer_held_out():
    """Seed 2 of scripts/triad_misfit_holdout.py: the product's held-out |f| spread was 10 times the gravity-only
    fit's; it is within 1.2 times, and the fold whose gyro misfit pulled the accelerometer says so.  With a keyframe's
    gravity and rotation factors sharing the gyro's noise (graph_calib.model.gravity_gyro_noise) the rotation kind
    takes the misfit (variance factor 561, gravity 0.90) and the accelerometer is a gravity-only fit's without the
    stage; where the accelerometer is pulled the stage pins it (the tests above)."""
    exp = simulate("consumer-handheld", rng=np.random.default_rng(2), n_poses=30, effects=("gyro.g_sensitivity",),
                   effect_scale=1e4).plans[0].make().experiment
    product = CalibrationOptions(model=ModelOptions(grade="consumer"))
    gravity_only = CalibrationOptions(model=ModelOptions(grade="consumer",
                                                         variance_factors={"rotation": GRAVITY_ONLY_FACTOR}))

    def fitter(options):
        return lambda train: Calibration.from_result(calibrate(train, options=options, solvers=("factor-graph",))
                                                     .results["factor-graph"])

    g = cross_validate(exp, fit=fitter(gravity_only), folds=2, by="pairs").pooled("calibrated")
    q = cross_validate(exp, fit=fitter(product), folds=2, by="pairs").pooled("calibrated")
    assert q["static_norm_std_mps2"] <= 1.2 * g["static_norm_std_mps2"]
    rests = record_rests(exp)
    train = training_record(exp, make_folds(exp, folds=2, by="pairs", rests=rests)[0], rests=rests)
    run = calibrate(train, options=product)
    assert not run.verdict.passed and "gyro.g_sensitivity" in run.verdict.text()
    r = run.results["factor-graph"]
    assert r.residuals["kinds"]["rotation"]["variance_factor"] > 100
    assert 0.8 < r.residuals["kinds"]["gravity"]["variance_factor"] < 1.25
    # the accelerometer's values and sigmas are a gravity-only fit's
    go = calibrate(train, options=gravity_only, solvers=("factor-graph",)).results["factor-graph"]
    for name in (n for n in go.values if n.startswith("accel.") and n not in go.extra.get("prior_dominated", {})):
        assert abs(r.values[name] - go.values[name]) < 0.5 * go.sigmas[name], name
        assert r.sigmas[name] == pytest.approx(go.sigmas[name], rel=0.25), name


def test_screen_gives_the_solved_statistic_to_first_order(monkeypatch):
    """A clean hand-held fold with the rotation kind's factor raised past the gate (as a gyro misfit would; its own
    estimate is 1 there), its gravity factor within the limit: the one linearisation's statistic is the solved
    gravity-only stage's within 10 %, and far below the threshold the stage is not solved."""
    from graph_calib.calibrate import build_problem
    from graph_calib.model.calibration_model import reusing_preintegrations
    from graph_calib.solvers import staged
    from graph_calib.solvers.variance import weighted_problem, with_variance_factors

    exp = simulate("consumer-handheld", rng=np.random.default_rng(3), n_poses=30).plans[0].make().experiment
    rests = record_rests(exp)
    train = training_record(exp, make_folds(exp, folds=2, by="pairs", rests=rests)[1], rests=rests)
    options = CalibrationOptions(model=ModelOptions(grade="consumer"))
    with reusing_preintegrations():
        weighted = weighted_problem(build_problem(train, options=options), options=options, solver="factor-graph")
        problem, initial = weighted.problem, weighted.initial
        assert not gyro_misfit_gate(problem)                      # a clean record's factors: the gate is closed
        factors = {**problem.model.options.variance_factors, "rotation": 2.0 * VARIANCE_FACTOR_LIMIT}
        problem = with_variance_factors(problem, factors)
        assert gyro_misfit_gate(problem) and factors["gravity"] <= VARIANCE_FACTOR_LIMIT
        start = initial["factor-graph"]
        gravity_only = with_variance_factors(problem, {**factors, "rotation": GRAVITY_ONLY_FACTOR})
        screen, dof = staged.screen_statistic(gravity_only, initial=start, options=options)
        assert staged.stage(problem, options=options, solver="factor-graph", initial=start) is None
        fraction = staged.SCREEN_FRACTION
        monkeypatch.setattr(staged, "SCREEN_FRACTION", 0.0)
        solved = staged.stage(problem, options=options, solver="factor-graph", initial=start)
    assert solved is not None and not solved.staged and solved.dof == dof
    assert screen == pytest.approx(solved.statistic, rel=0.1)
    assert 0.1 < solved.statistic < fraction * solved.threshold
