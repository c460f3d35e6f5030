"""Guided full turns (a Ferraris session's turns about the vertical): where they are found, their factors' Jacobians
against finite differences, their weightless rows, and that a record without them is the same as before."""

import numpy as np
import pytest

from graph_calib.model import guided_turns
from graph_calib.model.redundancy import fit_statistics
from graph_calib.model.residual_list import residual_list
from graph_calib.navigation.rotations import exp_so3
from graph_calib.options import CalibrationOptions
from graph_calib.model import ModelOptions
from graph_calib.records.problem import build_problem
from graph_calib.simulation.scenarios import GUIDED_FERRARIS, SHORT_REST_FERRARIS, simulate
from graph_calib.solvers import solve

from _synthetic import assert_calibration_jacobian_matches_fd, perturbed_point

EPS = 1e-6
CONSUMER = CalibrationOptions(model=ModelOptions(grade="consumer"))


def _ferraris(seed, **kw):
    return simulate("consumer-ferraris", rng=np.random.default_rng(seed), **kw).plans[0].make().experiment


@pytest.fixture(scope="module")
def guided():
    problem = build_problem(_ferraris(1, **GUIDED_FERRARIS), options=CONSUMER)
    return (problem, *perturbed_point(problem.model, rng=np.random.default_rng(3)))


def test_the_three_guided_turns_are_found_each_a_whole_turn_about_the_rests_vertical(guided):
    problem, _, _, _ = guided
    rec, turns = problem.model.record, problem.model.turns
    assert turns.shape == (3, 2)
    for a, b in turns:
        assert rec.static_key[a] and rec.static_key[b - 1] and not rec.static_key[a + 1:b - 1].any()
        angle = np.degrees(np.sum(rec.w_raw[rec.k0[a]:rec.k0[b]] * rec.dt[rec.k0[a]:rec.k0[b], None], axis=0))
        up = rec.f_raw[rec.k0[a]:rec.k0[a + 1]].mean(axis=0)
        assert 330.0 < np.linalg.norm(angle) < 390.0
        assert abs(abs(angle @ up) / (np.linalg.norm(angle) * np.linalg.norm(up)) - 1.0) < 1e-2


@pytest.mark.parametrize("kw", [{}, SHORT_REST_FERRARIS], ids=["turns about a horizontal axis", "hand-held"])
def test_no_turn_is_guided_where_the_turns_are_about_a_horizontal_axis(kw):
    assert build_problem(_ferraris(1, **kw), options=CONSUMER).model.turns.shape == (0, 2)


def test_guided_turns_off_leaves_the_model_without_the_kind(guided):
    problem, x, preint, R = guided
    off = build_problem(problem.model.experiment, options=CalibrationOptions(
        model=ModelOptions(grade="consumer", guided_turns=False))).model
    assert off.turns.shape == (0, 2) and off.turn_sigma is None
    assert residual_list(off, R, preint, x)["turn"].key.size == 0


def test_turn_factor_jacobians_match_fd(guided):
    problem, x, preint, R = guided
    model = problem.model
    res = model.turn_factors(R, preint, x)
    assert res.r.shape[0] == np.sum(model.turns[:, 1] - model.turns[:, 0])
    assert res.H_R_next is None and np.all(res.key == model.turn_keys)
    for a in range(3):
        d = np.zeros(3)
        d[a] = EPS
        for i, k in enumerate(res.key):
            Rp, Rm = R.copy(), R.copy()
            Rp[k], Rm[k] = R[k] @ exp_so3(d), R[k] @ exp_so3(-d)
            fd = (model.turn_factors(Rp, preint, x).r[i] - model.turn_factors(Rm, preint, x).r[i]) / (2 * EPS)
            np.testing.assert_allclose(res.H_R[i][:, a], fd, atol=1e-8)
    assert_calibration_jacobian_matches_fd(model, model.turn_factors, R, x, H_x=res.H_x, eps=EPS, rtol=1e-6,
                                           atol=1e-9)


def test_a_tilt_row_is_two_rows_and_a_weightless_third_the_closure_three(guided):
    problem, x, preint, R = guided
    model = problem.model
    res = model.turn_factors(R, preint, x)
    last = np.cumsum(model.turns[:, 1] - model.turns[:, 0]) - 1          # each turn's closure row
    tilt = np.setdiff1d(np.arange(res.r.shape[0]), last)
    assert np.all(np.isfinite(res.sigma[last])) and np.all(np.isfinite(res.sigma[tilt, :2]))
    assert np.all(np.isinf(res.sigma[tilt, 2])) and not np.any(res.r[tilt, 2]) and not np.any(res.H_x[tilt, 2])
    # the protocol's spread and the gyro's noise over the turn so far, in quadrature
    T = np.concatenate([model.t_key[a + 1:b + 1] - model.t_key[a] for a, b in model.turns])
    np.testing.assert_allclose(res.sigma[:, 0], np.sqrt(guided_turns.DEFAULT_SIGMA**2 + model.noise.gyro**2 * T))


def test_weightless_rows_carry_no_redundancy(guided):
    problem, _, _, _ = guided
    out = solve("factor-graph", problem, options=CONSUMER)
    fs = fit_statistics(problem.model, out.attitudes, out.x)
    turn = fs.kinds["turn"]
    rows = problem.model.turns[:, 1] - problem.model.turns[:, 0]
    n_weighted = 3 * rows.size + 2 * int(np.sum(rows - 1))
    assert turn.count == rows.sum()
    # every weighted component's redundancy number lies in [0, 1]; a weightless one would add 1 each
    assert 0.0 < turn.redundancy < n_weighted
    assert abs(fs.trace - fs.n_unknowns) < 1e-4 * fs.n_unknowns


def test_a_series_rms_leaves_the_weightless_rows_out_for_the_turn_kind_alone():
    from graph_calib.model.residual_list import series_rms
    v = np.array([[1.0, 2.0, 0.0], [1.0, 2.0, 0.0], [1.0, 2.0, 3.0]])       # two tilt rows, one closure row
    per_axis, rms = series_rms("turn", v)
    np.testing.assert_allclose(per_axis, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(rms, np.sqrt((3 * 1.0 + 3 * 4.0 + 9.0) / 7))
    per_axis, _ = series_rms("rotation", v)                                  # a zero of another kind is a residual
    np.testing.assert_allclose(per_axis[2], np.sqrt(9.0 / 3))
