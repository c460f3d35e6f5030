"""Residuals in axes a common heading does not turn (graph_calib.model.heading_axes).

The static keyframes' gravity factors and the rotation factors conditioned on them reach the solvers whitened and in
body axes: the cost is the level axes' own, the Jacobians match finite differences, a heading common to every
attitude no longer turns the residuals, and Gauss-Newton's curvature along that heading is the cost's own.  In level
axes it was 317 against a true 0.30 on a simulated hand-held record with a noisy gyro (seed 3 of
``tests/solvers/test_gravity_gyro_shared.py``), and the factor graph crept along the heading for 1,490 iterations.
"""

import numpy as np
import pytest

from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.model import CalibrationModel, ModelOptions
from graph_calib.model.heading_axes import to_body_axes
from graph_calib.model.residual_list import FACTOR_KINDS, residual_list, whiten
from graph_calib.navigation.rotations import exp_so3
from graph_calib.simulation import simulate

from _synthetic import assert_calibration_jacobian_matches_fd, assert_pair_jacobians_match_fd, wobbly_experiment

KINDS = {k.name: k for k in FACTOR_KINDS}


@pytest.fixture(scope="module")
def problem():
    """A record without a table, a MEMS gyro's noise, no moving sigma (so every gravity factor is turned)."""
    rng = np.random.default_rng(17)
    exp = wobbly_experiment(rng=rng, with_table=False)
    model = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, gyro_noise=3e-3, accel_noise=2e-2))
    x = rng.normal(size=model.layout.size) * 1e-3
    preint = model.preintegrate(x)
    R = model.propagate(np.eye(3), preint, x) @ exp_so3(rng.normal(size=(model.n_keyframes + 1, 3)) * 1e-2)
    return model, x, preint, R


def _whitened(model, R, preint, x, kind):
    return whiten(KINDS[kind], residual_list(model, R, preint, x)[kind])[1]


@pytest.mark.parametrize("kind", ["gravity", "rotation"])
def test_the_cost_is_the_level_axes_own(problem, kind):
    model, x, preint, R = problem
    level = model.with_options(heading_axes=False)
    body = _whitened(model, R, preint, x, kind)
    assert not np.allclose(body, _whitened(level, R, preint, x, kind))
    np.testing.assert_allclose(np.sum(body**2, axis=1), np.sum(_whitened(level, R, preint, x, kind) ** 2, axis=1),
                               rtol=1e-12)


def test_the_gravity_factors_jacobians_match_fd(problem):
    model, x, preint, R = problem

    def f(R_, preint_, x_):
        return residual_list(model, R_, preint_, x_)["gravity"]

    res = f(R, preint, x)
    assert_calibration_jacobian_matches_fd(model, f, R, x, H_x=res.H_x, eps=1e-6, rtol=1e-5, atol=1e-9)
    for i in (0, res.key.size // 2, res.key.size - 1):
        k = int(res.key[i])
        # a gravity factor touches its keyframe alone: the next keyframe's Jacobian is zero
        assert_pair_jacobians_match_fd(lambda Rx: f(Rx, preint, x), R, index=i, key=k, H_R=res.H_R[i],
                                       H_R_next=np.zeros((3, 3)), eps=1e-6, atol=1e-7)


def test_a_common_heading_no_longer_turns_the_residuals(problem):
    """Turned by 0.1 rad about the vertical, the level-axes residuals move by about 0.1 of their size; the body-axes
    ones only by the Earth rate's share."""
    model, x, preint, R = problem
    turned = exp_so3(np.array([0.0, 0.0, 0.1]))[None] @ R
    for kind in ("gravity", "rotation"):
        level = model.with_options(heading_axes=False)
        moved_level = np.abs(_whitened(level, turned, preint, x, kind) - _whitened(level, R, preint, x, kind)).max()
        moved_body = np.abs(_whitened(model, turned, preint, x, kind) - _whitened(model, R, preint, x, kind)).max()
        assert moved_body < 1e-2 * moved_level, (kind, moved_body, moved_level)


def test_no_rows_named_leaves_the_factors_as_they_are(problem):
    model, x, preint, R = problem
    grav = model.gravity_factors(R, preint, x)
    assert to_body_axes(grav, R[:0], rows=np.zeros(0, dtype=np.int64)) is grav


@pytest.mark.slow
def test_gauss_newtons_curvature_along_the_heading_is_the_costs_own():
    se = simulate("consumer-handheld", rng=np.random.default_rng(1003), gyro_noise_factor=6.6).run()[0]
    options = CalibrationOptions(t_ref_degC=se.truth.t_ref_degC)
    run = solve_problem(build_problem(se.experiment, options=options), options=options, solvers=("factor-graph",))
    assert run.verdict.converged["factor-graph"]
    model, out = run.problem.model, run.outputs["factor-graph"]
    preint = model.preintegrate(out.x)
    eps = 1e-4

    def stacked(m, psi):
        R = exp_so3(np.array([0.0, 0.0, psi]))[None] @ out.attitudes
        return np.concatenate([_whitened(m, R, preint, out.x, k).ravel() for k in ("rotation", "gravity")])

    def curvatures(m):
        w0, wp, wm = stacked(m, 0.0), stacked(m, eps), stacked(m, -eps)
        Jv = (wp - wm) / (2 * eps)
        true = (0.5 * wp @ wp + 0.5 * wm @ wm - w0 @ w0) / eps**2
        return float(Jv @ Jv), float(true)

    gn, true = curvatures(model)
    assert gn < 5.0 * max(true, 0.1), (gn, true)
    gn_level, true_level = curvatures(model.with_options(heading_axes=False))
    assert gn_level > 100.0 * max(true_level, 0.1), (gn_level, true_level)
