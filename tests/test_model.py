"""Every Jacobian of the shared model against central finite differences."""

import numpy as np
import pytest

from graph_calib import sensor_model as sm
from graph_calib.model import CalibrationModel, ModelOptions
from graph_calib.params import FURTHER_EFFECTS, Layout
from graph_calib.rotations import exp_so3

from _synthetic import wobbly_experiment

EPS = 1e-6


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(1)
    exp = wobbly_experiment(rng=rng)
    model = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, extra_effects=FURTHER_EFFECTS))
    x = rng.normal(size=model.layout.size) * 1e-3
    pre = model.preintegrate(x)
    R = model.propagate(np.eye(3), pre, x) @ exp_so3(rng.normal(size=(model.n_keyframes + 1, 3)) * 1e-2)
    return model, x, pre, R


@pytest.mark.parametrize("triad", ["gyro", "accel"])
def test_sensor_inverse_is_exact_and_its_jacobian_matches_fd(triad):
    rng = np.random.default_rng(7)
    layout = Layout.declared(extra=FURTHER_EFFECTS)
    x = rng.normal(size=layout.size) * 0.01          # percent-level: consumer-grade errors
    n = 200
    sig = rng.normal(size=(n, 3)) * (1.0 if triad == "gyro" else 5.0)
    ctx = dict(dT=rng.normal(size=(n, 3)), dTdt=rng.normal(size=(n, 3)) * 0.01,
               other=rng.normal(size=(n, 3)), domega=rng.normal(size=(n, 3)), dsignal=rng.normal(size=(n, 3)))
    meas = sm.measure(layout, x, triad, sig, **ctx)
    assert np.abs(meas - sig).max() > 1e-3                  # the errors are really there
    s, J = sm.correct(layout, x, triad, meas, jacobian=True, **ctx)
    np.testing.assert_allclose(s, sig, atol=1e-12)
    for c in range(layout.size):
        xp, xm = x.copy(), x.copy()
        xp[c] += EPS
        xm[c] -= EPS
        fd = (sm.correct(layout, xp, triad, meas, **ctx) - sm.correct(layout, xm, triad, meas, **ctx)) / (2 * EPS)
        np.testing.assert_allclose(J[:, :, c], fd, atol=1e-6 * (1 + np.abs(fd).max()),
                                   err_msg=layout.element_names()[c])


@pytest.mark.parametrize("kind", ["rotation_factors", "gravity_factors", "encoder_factors"])
def test_factor_jacobian_in_calibration_matches_fd(problem, kind):
    model, x, pre, R = problem
    f = getattr(model, kind)
    res = f(R, pre, x)
    assert res.r.shape[0] > 0
    for c in range(model.layout.size):
        xp, xm = x.copy(), x.copy()
        xp[c] += EPS
        xm[c] -= EPS
        fd = (f(R, model.preintegrate(xp), xp).r - f(R, model.preintegrate(xm), xm).r) / (2 * EPS)
        scale = np.abs(fd).max() + np.abs(res.H_x[:, :, c]).max() + 1e-12
        assert np.abs(fd - res.H_x[:, :, c]).max() / scale < 1e-5, model.layout.element_names()[c]


@pytest.mark.parametrize("kind", ["gravity_factors", "encoder_factors"])
def test_unary_factor_jacobian_in_attitude_matches_fd(problem, kind):
    model, x, pre, R = problem
    f = getattr(model, kind)
    res = f(R, pre, x)
    for a in range(3):
        d = np.zeros(3)
        d[a] = EPS
        fd = (f(R @ exp_so3(d), pre, x).r - f(R @ exp_so3(-d), pre, x).r) / (2 * EPS)
        np.testing.assert_allclose(res.H_R[:, :, a], fd, atol=1e-7 * (1 + np.abs(fd).max()))


def test_rotation_factor_jacobians_in_both_attitudes_match_fd(problem):
    model, x, pre, R = problem
    res = model.rotation_factors(R, pre, x)
    for k in (1, 3, model.n_keyframes - 1):
        for a in range(3):
            d = np.zeros(3)
            d[a] = EPS
            Rp, Rm = R.copy(), R.copy()
            Rp[k] = R[k] @ exp_so3(d)
            Rm[k] = R[k] @ exp_so3(-d)
            fd = (model.rotation_factors(Rp, pre, x).r - model.rotation_factors(Rm, pre, x).r) / (2 * EPS)
            np.testing.assert_allclose(res.H_R[k][:, a], fd[k], atol=1e-8)
            np.testing.assert_allclose(res.H_R_next[k - 1][:, a], fd[k - 1], atol=1e-8)


def test_first_order_update_tracks_repreintegration(problem):
    model, x, pre, R = problem
    dx = np.random.default_rng(3).normal(size=x.size) * 1e-6
    a = model.gravity_factors(R, pre, x + dx).r
    b = model.gravity_factors(R, model.preintegrate(x + dx), x + dx).r
    c0 = model.gravity_factors(R, pre, x).r
    assert np.abs(a - b).max() < 1e-3 * np.abs(b - c0).max()
