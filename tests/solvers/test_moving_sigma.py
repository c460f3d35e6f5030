"""The moving keyframes' gravity sigma estimated with the variance components (solvers/variance.py, issue 22).

A hand that turns the unit about itself accelerates it by a few cm/s^2; ``moving_sigma``'s default guess of
1 m/s^2 leaves the attitude in a turn, and the gyro's cross-axis terms, to the rotation factors alone.
"""

import numpy as np
import pytest

from graph_calib.calibrate import build_problem
from graph_calib.model import ModelOptions
from graph_calib.model.redundancy import MOVING
from graph_calib.options import CalibrationOptions
from graph_calib.simulation.scenarios import SHORT_REST_FERRARIS, simulate
from graph_calib.solvers.variance import MOVING_SIGMA_BOUNDS, estimate_variance_components

pytestmark = pytest.mark.slow

OPTIONS = CalibrationOptions(model=ModelOptions(grade="consumer", moving_sigma="estimate"))


@pytest.fixture(scope="module")
def problem():
    se = simulate("consumer-ferraris", rng=np.random.default_rng(1), **SHORT_REST_FERRARIS).plans[0].make()
    return build_problem(se.experiment, options=OPTIONS)


def test_the_moving_keyframes_sigma_follows_their_residuals(problem):
    assert problem.model.options.moving_sigma == 1.0                 # the guess the problem starts from
    vc = estimate_variance_components(problem, options=OPTIONS, solver="factor-graph")
    # the hand sways the unit by 0.05 m/s^2 rms and turns it about itself: far below the guess
    assert MOVING_SIGMA_BOUNDS[0] <= vc.moving_sigma < 0.3, vc.moving_sigma
    assert vc.problem.model.options.moving_sigma == vc.moving_sigma
    last = vc.history[-1]
    assert MOVING in last and abs(last[MOVING] - 1.0) < 0.5, vc.history


def test_a_fixed_moving_sigma_is_kept(problem):
    vc = estimate_variance_components(problem, options=OPTIONS, solver="factor-graph", fixed=(MOVING,))
    assert vc.moving_sigma == 1.0 and all(MOVING not in h for h in vc.history)


def test_the_default_keeps_the_guess(problem):
    plain = build_problem(problem.model.experiment, options=CalibrationOptions(model=ModelOptions(grade="consumer")))
    vc = estimate_variance_components(plain, options=OPTIONS, solver="factor-graph")
    assert vc.moving_sigma == 1.0 and all(MOVING not in h for h in vc.history)
    assert problem.model.options.noise_source["moving"] == "variance components"
    assert "moving" not in plain.model.options.noise_source
