"""The variance components' problem and warm start for a final solve (graph_calib.solvers.variance.weighted_problem)."""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.solvers.registry import PRIMARY_SOLVER
from graph_calib.model.encoder_noise import FLOORED
from graph_calib.simulation import simulate
from graph_calib.calibrate import solve_problem
from graph_calib.solvers.variance import FACTOR_MAX, FLOOR_FACTOR_MIN, KINDS, estimate_variance_components, weighted_problem

from _shared import make_experiment

#: Navigation priors named: the made-up record's rests would choose a looser grade, whose priors absorb its contradiction.
OPTIONS = CalibrationOptions(model=ModelOptions(grade="navigation"))


@pytest.fixture(scope="module")
def problem():
    return build_problem(make_experiment(n=3000, seed=4), options=OPTIONS)


def test_without_variance_components_the_problem_is_unchanged_and_no_start(problem):
    weighted = weighted_problem(problem, options=replace(OPTIONS, variance_components=False), solver=PRIMARY_SOLVER)
    assert weighted.problem is problem and weighted.initial is None and weighted.components is None
    assert weighted.iteration() is None


def test_with_them_the_factors_problem_and_the_solvers_last_solution(problem):
    weighted = weighted_problem(problem, options=OPTIONS, solver=PRIMARY_SOLVER)
    got, initial = weighted.problem, weighted.initial
    vc = estimate_variance_components(problem, options=OPTIONS, solver=PRIMARY_SOLVER)
    assert weighted.iteration() == {"solves": vc.solves, "converged": vc.converged,
                                    "last": {k: float(v) for k, v in vc.history[-1].items()},
                                    "at_bound": list(vc.at_bound), "held": list(vc.held)}
    assert not problem.model.options.variance_factors
    assert got.model.options.variance_factors == vc.problem.model.options.variance_factors
    assert set(got.model.options.variance_factors) <= set(KINDS) and got.model.options.variance_factors
    assert list(initial) == [PRIMARY_SOLVER]
    (R, x), (R_vc, x_vc) = initial[PRIMARY_SOLVER], vc.initial
    np.testing.assert_array_equal(x, x_vc)
    np.testing.assert_array_equal(np.asarray(R), np.asarray(R_vc))


@pytest.fixture(scope="module")
def table_problem():
    """A 6-min navigation-grade table record simulated with the noise it is calibrated with (its table's unread
    direction noiseless, as the simulator's two encoders make it)."""
    se = simulate("nav-subrange-short", rng=np.random.default_rng(2), hours=0.1).run()[0]
    options = CalibrationOptions(t_ref_degC=se.truth.t_ref_degC)
    return build_problem(se.experiment, options=options), options


def test_the_floor_of_the_unread_direction_is_estimated_and_the_gyro_factor_is_then_right(table_problem):
    problem, options = table_problem
    assert problem.model.record.encoder_noise_frame(problem.model.noise.encoder).floored.any()
    vc = estimate_variance_components(problem, options=options)
    assert vc.converged and vc.solves <= 3
    # the simulated table has none of the axis errors the floor stands for: its factor goes to its bound, where
    # the readings' gyro term explains those components
    assert vc.factors[FLOORED] == pytest.approx(FLOOR_FACTOR_MIN)
    # the noise is the simulated one: the gyro's factor (rotation factors and the readings' gyro term) and the
    # readings' own are 1 within their scatter (the gyro's is informed by some 3000 floored components)
    assert 0.9 < vc.factors["rotation"] < 1.1 and 0.95 < vc.factors["encoder"] < 1.05, vc.factors
    # the control: the floor held where it was, the variance components make up for it on the gyro's factor, whose
    # sigmas then come out optimistic (this was calibrate's rotation factor of 0.56-0.85)
    held = estimate_variance_components(problem, options=options, fixed=(FLOORED,))
    assert FLOORED not in held.factors and held.factors["rotation"] < 0.7, held.factors


def test_calibrate_writes_how_the_iteration_ended(table_problem):
    """The result carries the iteration's end (``residuals.variance_iteration``), the same as the weighting's, and a
    settled one adds no note to the verdict."""
    problem, options = table_problem
    run = solve_problem(problem, options=options, solvers=(PRIMARY_SOLVER,))
    got = run.results[PRIMARY_SOLVER].residuals["variance_iteration"]
    assert got == weighted_problem(problem, options=options, solver=PRIMARY_SOLVER).iteration()
    assert got["converged"] and got["at_bound"] == [] and 1 <= got["solves"] <= 3
    assert all(abs(v - 1.0) <= 0.05 for v in got["last"].values()), got
    assert not any("did not settle" in n for n in run.verdict.notes)


def test_a_factor_at_its_bound_ends_the_iteration_and_is_named(problem):
    """The made-up record's table readings contradict its gravity (its mounting is not the one the readings say):
    the gravity kind's factor runs to its bound with the residuals asking for more, and the iteration stops there
    instead of spending its solves, not converged, naming the kind."""
    vc = estimate_variance_components(problem, options=OPTIONS, max_solves=10)
    assert not vc.converged and vc.solves < 10
    assert vc.at_bound == ("gravity",) and vc.factors["gravity"] == FACTOR_MAX
    assert vc.history[-1]["gravity"] > 1.05


@pytest.fixture(scope="module")
def hand_held_session():
    """A consumer Ferraris session by hand (seed 1, long rests): 45 of its 130 keyframes moving, whose gravity factors
    keep the guessed sigma of 1 m/s^2."""
    return build_problem(simulate("consumer-ferraris", rng=np.random.default_rng(1)).plans[0].make().experiment,
                         options=CalibrationOptions())


def test_the_gravity_factor_comes_from_the_static_keyframes_and_a_kind_of_little_redundancy_is_not_lowered(
        hand_held_session):
    """Counted in, the moving keyframes' factors (chi2 about 0, redundancy about 3 each) dragged the gravity factor to
    0.36 and, through the tilted attitudes, the rotation kind's to 2.6 on this record of the simulated noise; the
    rotation kind has a redundancy of about 23 there and its figure barely answers its factor, which then ran down to
    0.16 when the gravity factor was right."""
    run = solve_problem(hand_held_session, options=CalibrationOptions(), solvers=(PRIMARY_SOLVER,))
    kinds = run.results[PRIMARY_SOLVER].residuals["kinds"]
    gravity, rotation = kinds["gravity"], kinds["rotation"]
    assert gravity["moving"]["count"] == 45 and gravity["moving"]["chi2_per_redundancy"] < 1e-3
    assert abs(gravity["static"]["chi2_per_redundancy"] - 1.0) < 0.05           # the factor from these
    assert 0.6 < gravity["variance_factor"] < 1.0                               # 0.76 (noise as simulated: 1)
    assert gravity["chi2_per_redundancy"] < 0.7                                 # the whole kind's figure, diluted
    assert rotation["redundancy"] < 50 and rotation["chi2_per_redundancy"] < 1.0
    assert rotation["variance_factor"] == 1.0                                   # not lowered on so little
    assert run.results[PRIMARY_SOLVER].residuals["variance_iteration"]["held"] == ["rotation"]
    assert run.verdict.passed, run.verdict.text()
