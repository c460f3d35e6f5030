"""The decorrelation of the table readings and rotation factors that share gyro noise, against the covariance
written out in full (graph_calib.model.shared_gyro_noise)."""

from types import SimpleNamespace

import numpy as np

from graph_calib.model.factors import Noise, Residuals
from graph_calib.model.shared_gyro_noise import decorrelate
from graph_calib.navigation.rotations import exp_so3

Q = 3e-6                                           # gyro angle random walk, rad/sqrt(s)


class _Namespace(SimpleNamespace):
    """A stand-in record or preintegration (weakly referable, as the real ones are)."""


def _case(rng):
    """Three keyframe intervals: three readings in the first, one in the second, none in the third."""
    T = np.array([1.0, 0.8, 1.0])
    key = np.array([0, 0, 0, 1])
    tau = np.array([0.25, 1.0, 0.5, 0.4])        # not in time order within the first interval
    M, K = key.size, T.size
    U = exp_so3(rng.normal(size=(M, 3)) * 0.3)
    dR_i = exp_so3(rng.normal(size=(M, 3)))
    dR_T = exp_so3(rng.normal(size=(K, 3)))
    D = rng.uniform(1.0, 4.0, size=(M, 3)) * 1e-12  # each reading's own variance in its noise frame
    record = _Namespace(reading_tau=tau, T_key=T, encoder_noise_frame=lambda enc: SimpleNamespace(U=U))
    preint = _Namespace(reading_dR=dR_i, dR=dR_T)
    return record, preint, key, tau, T, U, dR_i, dR_T, D


def _full_covariance(key, tau, T, U, dR_i, dR_T, D, v_enc, v_rot):
    """The covariance of [readings..., rotation factors...] from W(tau), cov q^2 tau I, per interval."""
    M, K = key.size, T.size
    n = 3 * (M + K)
    # each factor's noise as a linear map of the interval's W at its time: reading U^T dR_i^T sqrt(v_rot) W(tau),
    # rotation -sqrt(v_rot) dR_T^T W(T): the rotation kind's factor is the gyro's, on both (the readings' own noise
    # takes the encoder kind's)
    maps = [(key[i], tau[i], np.sqrt(v_rot) * U[i].T @ dR_i[i].T) for i in range(M)]
    maps += [(k, T[k], -np.sqrt(v_rot) * dR_T[k].T) for k in range(K)]
    S = np.zeros((n, n))
    for a, (ka, ta, Ma) in enumerate(maps):
        for b, (kb, tb, Mb) in enumerate(maps):
            if ka == kb:
                S[3 * a:3 * a + 3, 3 * b:3 * b + 3] = Q**2 * min(ta, tb) * Ma @ Mb.T
    S[:3 * M, :3 * M] += np.diag(v_enc * D.reshape(-1))
    return S


def _residuals(key, Lrows, sigma, rng, with_next):
    F = key.size
    return Residuals(r=np.zeros((F, 3)), key=key, H_R=rng.normal(size=(F, 3, 3)),
                     H_R_next=rng.normal(size=(F, 3, 3)) if with_next else None, H_x=Lrows, sigma=sigma)


def test_the_whitened_factors_are_independent_with_unit_variance():
    rng = np.random.default_rng(4)
    record, preint, key, tau, T, U, dR_i, dR_T, D = _case(rng)
    v_enc, v_rot = 1.7, 0.6
    M, K = key.size, T.size
    S = _full_covariance(key, tau, T, U, dR_i, dR_T, D, v_enc, v_rot)
    L = np.linalg.cholesky(S)
    # the probe: H_x of every factor its rows of L, so that H_x = noise with identity covariance mapped through L
    enc = _residuals(key, L[:3 * M].reshape(M, 3, -1), np.sqrt(v_enc * D + v_rot * Q**2 * tau[:, None]), rng, False)
    rot = _residuals(np.arange(K), L[3 * M:].reshape(K, 3, -1), np.sqrt(v_rot * Q**2 * T)[:, None] * np.ones(3),
                     rng, True)
    # the marginal sigmas the model gives each kind are the covariance's own diagonal
    np.testing.assert_allclose(np.concatenate([enc.sigma, rot.sigma]).reshape(-1) ** 2, np.diag(S), rtol=1e-12)
    noise = Noise(gyro=Q, accel=1e-5, encoder=1e-5, variance_factors={"encoder": v_enc, "rotation": v_rot})
    rot2, enc2 = decorrelate(record, preint, noise, rot, enc)
    Z = np.concatenate([enc2.H_x / enc2.sigma[:, :, None], rot2.H_x / rot2.sigma[:, :, None]]).reshape(3 * (M + K), -1)
    np.testing.assert_allclose(Z @ Z.T, np.eye(3 * (M + K)), atol=1e-9)
    # treated as independent, the same factors are far from it (the test can fail)
    Z0 = np.concatenate([enc.H_x / enc.sigma[:, :, None], rot.H_x / rot.sigma[:, :, None]]).reshape(3 * (M + K), -1)
    assert np.abs(Z0 @ Z0.T - np.eye(3 * (M + K))).max() > 0.3
    # the interval without readings keeps its rotation factor; H_R_next only rescaled by the factor's own L
    np.testing.assert_array_equal(rot2.H_x[2], rot.H_x[2])
    np.testing.assert_array_equal(rot2.sigma[2], rot.sigma[2])


def test_residuals_and_jacobians_go_through_one_linear_map():
    rng = np.random.default_rng(5)
    record, preint, key, tau, T, U, dR_i, dR_T, D = _case(rng)
    M, K = key.size, T.size
    noise = Noise(gyro=Q, accel=1e-5, encoder=1e-5)
    P = 4
    enc = Residuals(r=rng.normal(size=(M, 3)), key=key, H_R=rng.normal(size=(M, 3, 3)), H_R_next=None,
                    H_x=rng.normal(size=(M, 3, P)), sigma=np.sqrt(D + Q**2 * tau[:, None]))
    rot = Residuals(r=rng.normal(size=(K, 3)), key=np.arange(K), H_R=rng.normal(size=(K, 3, 3)),
                    H_R_next=rng.normal(size=(K, 3, 3)), H_x=rng.normal(size=(K, 3, P)),
                    sigma=Q * np.sqrt(T)[:, None] * np.ones(3))
    rot2, enc2 = decorrelate(record, preint, noise, rot, enc)
    # the residual moved by a step dx, d_delta of every attitude, equals the map of the moved inputs (linearity)
    dx, dd = rng.normal(size=P), rng.normal(size=(K + 1, 3))
    moved_enc = Residuals(r=enc.r + enc.H_x @ dx + np.einsum("fab,fb->fa", enc.H_R, dd[key]), key=key, H_R=enc.H_R,
                          H_R_next=None, H_x=enc.H_x, sigma=enc.sigma)
    moved_rot = Residuals(r=rot.r + rot.H_x @ dx + np.einsum("fab,fb->fa", rot.H_R, dd[:K])
                          + np.einsum("fab,fb->fa", rot.H_R_next, dd[1:]), key=rot.key, H_R=rot.H_R,
                          H_R_next=rot.H_R_next, H_x=rot.H_x, sigma=rot.sigma)
    rot3, enc3 = decorrelate(record, preint, noise, moved_rot, moved_enc)
    np.testing.assert_allclose(enc3.r, enc2.r + enc2.H_x @ dx + np.einsum("fab,fb->fa", enc2.H_R, dd[key]),
                               rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(rot3.r, rot2.r + rot2.H_x @ dx + np.einsum("fab,fb->fa", rot2.H_R, dd[:K])
                               + np.einsum("fab,fb->fa", rot2.H_R_next, dd[1:]), rtol=1e-10, atol=1e-12)


def test_without_readings_or_gyro_noise_nothing_changes():
    rng = np.random.default_rng(6)
    record, preint, key, tau, T, U, dR_i, dR_T, D = _case(rng)
    rot = Residuals(r=rng.normal(size=(3, 3)), key=np.arange(3), H_R=rng.normal(size=(3, 3, 3)),
                    H_R_next=rng.normal(size=(3, 3, 3)), H_x=rng.normal(size=(3, 3, 2)), sigma=np.ones((3, 3)))
    empty = Residuals(r=np.zeros((0, 3)), key=np.zeros(0, dtype=np.int64), H_R=np.zeros((0, 3, 3)), H_R_next=None,
                      H_x=np.zeros((0, 3, 2)), sigma=np.zeros((0, 3)))
    out_rot, out_enc = decorrelate(record, preint, Noise(gyro=Q, accel=1e-5, encoder=1e-5), rot, empty)
    assert out_rot is rot and out_enc is empty


def test_the_gains_are_reused_only_for_the_same_preintegration_and_noise():
    rng = np.random.default_rng(8)
    record, preint, key, tau, T, U, dR_i, dR_T, D = _case(rng)
    M, K = key.size, T.size
    enc = Residuals(r=rng.normal(size=(M, 3)), key=key, H_R=rng.normal(size=(M, 3, 3)), H_R_next=None,
                    H_x=rng.normal(size=(M, 3, 2)), sigma=np.sqrt(D + Q**2 * tau[:, None]))
    rot = Residuals(r=rng.normal(size=(K, 3)), key=np.arange(K), H_R=rng.normal(size=(K, 3, 3)),
                    H_R_next=rng.normal(size=(K, 3, 3)), H_x=rng.normal(size=(K, 3, 2)),
                    sigma=Q * np.sqrt(T)[:, None] * np.ones(3))
    noise = Noise(gyro=Q, accel=1e-5, encoder=1e-5)
    first = decorrelate(record, preint, noise, rot, enc)[1]
    held = record.shared_gyro_gains
    assert decorrelate(record, preint, noise, rot, enc)[1].sigma.tolist() == first.sigma.tolist()
    assert record.shared_gyro_gains is held                                 # reused
    other = _Namespace(reading_dR=dR_i, dR=dR_T)                            # another preintegration: computed again
    decorrelate(record, other, noise, rot, enc)
    assert record.shared_gyro_gains is not held
    held = record.shared_gyro_gains
    louder = Noise(gyro=2 * Q, accel=1e-5, encoder=1e-5)
    enc2 = Residuals(r=enc.r, key=key, H_R=enc.H_R, H_R_next=None, H_x=enc.H_x,
                     sigma=np.sqrt(D + (2 * Q) ** 2 * tau[:, None]))
    assert not np.allclose(decorrelate(record, other, louder, rot, enc2)[1].sigma, first.sigma)
    assert record.shared_gyro_gains is not held
