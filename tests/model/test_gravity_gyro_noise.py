"""A keyframe's rotation factor made independent of its gravity factor: Jacobians against finite differences, the
pair's cost against their joint covariance written out, and the noise it models against a simulation of it."""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.model import CalibrationModel, ModelOptions
from graph_calib.model.factors import Noise
from graph_calib.model.gravity_gyro_noise import condition_on_gravity, conditioned
from graph_calib.model.residual_list import residual_list
from graph_calib.navigation.rotations import exp_so3, skew

from _synthetic import assert_calibration_jacobian_matches_fd, assert_pair_jacobians_match_fd, wobbly_experiment

EPS = 1e-6


@pytest.fixture(scope="module")
def problem():
    """A record without a table (every rotation factor conditioned), a MEMS gyro's noise (the gyro term a good part
    of the gravity factor's), the kinds' variance factors apart from 1."""
    rng = np.random.default_rng(11)
    exp = wobbly_experiment(rng=rng, with_table=False)
    options = ModelOptions(keyframe_s=0.5, gyro_noise=3e-3, accel_noise=2e-2,
                           variance_factors={"rotation": 1.7, "gravity": 0.6})
    model = CalibrationModel(exp, options=options)
    x = rng.normal(size=model.layout.size) * 1e-3
    preint = model.preintegrate(x)
    R = model.propagate(np.eye(3), preint, x) @ exp_so3(rng.normal(size=(model.n_keyframes + 1, 3)) * 1e-2)
    return model, x, preint, R


def _conditioned(model):
    def f(R, preint, x):
        return condition_on_gravity(model.record, preint, x, R, model.rotation_factors(R, preint, x),
                                    model.gravity_factors(R, preint, x), variance_factors=model.noise.variance_factors)
    return f


def test_every_rotation_factor_of_a_record_without_readings_is_conditioned(problem):
    model, x, preint, R = problem
    rot = model.rotation_factors(R, preint, x)
    assert rot.key.size > 5 and np.all(conditioned(model.record, rot))


def test_conditioned_factor_jacobians_match_fd(problem):
    model, x, preint, R = problem
    f = _conditioned(model)
    res = f(R, preint, x)
    assert_calibration_jacobian_matches_fd(model, f, R, x, H_x=res.H_x, eps=EPS, rtol=1e-5, atol=1e-9)
    for i in (0, res.key.size // 2, res.key.size - 1):
        assert_pair_jacobians_match_fd(lambda Rx: f(Rx, preint, x), R, index=i, key=int(res.key[i]), H_R=res.H_R[i],
                                       H_R_next=res.H_R_next[i], eps=EPS, atol=1e-8)


def test_the_pair_cost_is_their_mahalanobis_norm_under_the_joint_covariance(problem):
    """The conditioned rotation factor and the gravity factor, whitened, give the quadratic form of the rotation
    residual (in level axes) and the gravity residual under their joint covariance, the cross term
    ``-(q^2 T / 2) [g_up x]`` written out, each kind's block scaled by its variance factor and the cross block by
    the square root of their product."""
    model, x, preint, R = problem
    rot = model.rotation_factors(R, preint, x)
    grav = model.gravity_factors(R, preint, x)
    cond = condition_on_gravity(model.record, preint, x, R, rot, grav, variance_factors=model.noise.variance_factors)
    g = model.record.gravity
    G = skew(np.array([0.0, 0.0, g]))
    v_rot = model.noise.variance_factors["rotation"]
    v_grav = model.noise.variance_factors["gravity"]
    for i in range(rot.key.size):
        k = int(rot.key[i])
        T = model.record.T_key[k]
        q2T = model.noise.gyro**2 * T
        A = model.record.earth_turn(np.array([T]))[0] @ R[k] @ preint.corrected(x).dR[k]
        phi = A @ rot.r[i]
        C = np.zeros((6, 6))
        C[:3, :3] = v_rot * q2T * np.eye(3)
        C[3:, 3:] = np.diag(grav.sigma[k] ** 2)
        C[:3, 3:] = -0.5 * np.sqrt(v_rot * v_grav) * q2T * G
        C[3:, :3] = C[:3, 3:].T
        e = np.concatenate([phi, grav.r[k]])
        want = e @ np.linalg.solve(C, e)
        got = np.sum((cond.r[i] / cond.sigma[i]) ** 2) + np.sum((grav.r[k] / grav.sigma[k]) ** 2)
        assert got == pytest.approx(want, rel=1e-9)
        # the gravity factor's horizontal variance holds the gyro term, q^2 T g^2 / 3 (times its kind's factor)
        assert grav.sigma[k, 0] ** 2 >= v_grav * q2T * g**2 / 3.0 * (1 - 1e-12)


def test_the_modelled_cross_covariance_is_the_simulated_noise_s():
    """Gyro white noise integrated over a keyframe at rest: the end tilt and the mean tilt have covariance
    ``q^2 T / 2`` (correlation sqrt(3)/2), which the module's cross term assumes."""
    rng = np.random.default_rng(3)
    n, h, q = 50, 0.01, 1.0
    T = n * h
    steps = rng.normal(scale=q * np.sqrt(h), size=(20000, n))
    xi = np.cumsum(steps, axis=1)
    end, mean = xi[:, -1], xi.mean(axis=1)      # the sample ends' mean, as the gravity factor sums per sample
    assert np.var(end) == pytest.approx(q**2 * T, rel=0.03)
    assert np.mean(end * mean) == pytest.approx(q**2 * T / 2, rel=0.05)
    assert np.var(mean) == pytest.approx(q**2 * T / 3, rel=0.05)


def test_keyframes_with_readings_keep_their_factors(problem):
    """On a record with readings in every keyframe nothing is conditioned: the residual list's rotation factors are
    the ones the table readings' decorrelation gives."""
    rng = np.random.default_rng(5)
    exp = wobbly_experiment(rng=rng)
    model = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5))
    x = np.zeros(model.layout.size)
    preint = model.preintegrate(x)
    R = model.propagate(np.eye(3), preint, x)
    rot = model.rotation_factors(R, preint, x)
    assert not np.any(conditioned(model.record, rot))
    assert condition_on_gravity(model.record, preint, x, R, rot, model.gravity_factors(R, preint, x),
                                variance_factors={}) is rot


def test_the_residual_list_gives_the_conditioned_factors(problem):
    model, x, preint, R = problem
    listed = residual_list(model, R, preint, x)["rotation"]
    mine = _conditioned(model)(R, preint, x)
    np.testing.assert_allclose(listed.r, mine.r, rtol=0, atol=1e-15)
    np.testing.assert_allclose(listed.sigma, mine.sigma, rtol=1e-15)


def test_without_gyro_noise_in_the_gravity_factor_nothing_is_shared(problem):
    """A zero gyro noise: the rotation factors are not conditioned (their sigma is zero: nothing shared)."""
    model, x, preint, R = problem
    rot = model.rotation_factors(R, preint, x)
    rot0 = replace(rot, sigma=np.zeros_like(rot.sigma))
    assert not np.any(conditioned(model.record, rot0))
    assert isinstance(model.noise, Noise)


def test_the_option_off_leaves_the_two_factors_independent(problem):
    """``ModelOptions(gravity_gyro_shared=False)``: the residual list's rotation factors are the model's own (the
    first solve of a cold start, graph_calib.solvers.registry)."""
    model, x, preint, R = problem
    off = model.with_options(gravity_gyro_shared=False)
    listed = residual_list(off, R, preint, x)["rotation"]
    own = off.rotation_factors(R, preint, x)
    np.testing.assert_array_equal(listed.r, own.r)
    np.testing.assert_array_equal(listed.sigma, own.sigma)
    assert not np.allclose(residual_list(model, R, preint, x)["rotation"].r, own.r)
