"""The variance components' problem and warm start for a final solve (graph_calib.solvers.variance.weighted_problem)."""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.solvers.registry import PRIMARY_SOLVER
from graph_calib.solvers.variance import KINDS, estimate_variance_components, weighted_problem

from _shared import make_experiment

OPTIONS = CalibrationOptions()


@pytest.fixture(scope="module")
def problem():
    return build_problem(make_experiment(n=3000, seed=4), options=OPTIONS)


def test_without_variance_components_the_problem_is_unchanged_and_no_start(problem):
    got, initial = weighted_problem(problem, options=replace(OPTIONS, variance_components=False),
                                    solver=PRIMARY_SOLVER)
    assert got is problem and initial is None


def test_with_them_the_factors_problem_and_the_solvers_last_solution(problem):
    got, initial = weighted_problem(problem, options=OPTIONS, solver=PRIMARY_SOLVER)
    vc = estimate_variance_components(problem, options=OPTIONS, solver=PRIMARY_SOLVER)
    assert not problem.model.options.variance_factors
    assert got.model.options.variance_factors == vc.problem.model.options.variance_factors
    assert set(got.model.options.variance_factors) <= set(KINDS) and got.model.options.variance_factors
    assert list(initial) == [PRIMARY_SOLVER]
    (R, x), (R_vc, x_vc) = initial[PRIMARY_SOLVER], vc.initial
    np.testing.assert_array_equal(x, x_vc)
    np.testing.assert_array_equal(np.asarray(R), np.asarray(R_vc))
