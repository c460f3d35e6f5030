"""Identities and round trips of graph_calib.navigation.rotations (numpy and numba helpers)."""

import numpy as np
import pytest

from graph_calib.navigation import rotations as r


def _random_rotvecs(rng, n, max_angle=np.pi):
    axis = rng.standard_normal((n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return axis * rng.uniform(0.0, max_angle, size=(n, 1))


def _special_rotvecs():
    """Angles at 0, near 0, near pi and at pi, about generic and coordinate axes."""
    axes = [np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]),
            np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])]
    angles = [0.0, 1e-12, 1e-8, 1e-7, 1.0000001e-7, 1e-5, 1e-3, 0.5, np.pi / 2,
              np.pi - 1e-3, np.pi - 1e-6, np.pi - 1e-9]
    return np.array([a * ax for a in angles for ax in axes])


def _angle_between(C1, C2):
    return np.linalg.norm(r.log_so3(np.swapaxes(C1, -1, -2) @ C2), axis=-1)


def test_skew_identity():
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal((2, 50, 3))
    S = r.skew(a)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", S, b), np.cross(a, b), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(S, -np.swapaxes(S, -1, -2))
    # [a x]^2 = a a^T - |a|^2 I
    np.testing.assert_allclose(S @ S, np.einsum("ni,nj->nij", a, a) - np.sum(a * a, 1)[:, None, None] * np.eye(3),
                               atol=1e-13)


def test_exp_is_rotation_and_matches_rodrigues():
    rng = np.random.default_rng(2)
    a = np.vstack([_random_rotvecs(rng, 200), _special_rotvecs()])
    C = r.exp_so3(a)
    np.testing.assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(C), 1.0, atol=1e-14)
    # rotating the axis leaves it unchanged; rotating a normal vector turns it by the angle
    theta = np.linalg.norm(a, axis=1)
    big = theta > 1e-3
    u = a[big] / theta[big, None]
    np.testing.assert_allclose(np.einsum("nij,nj->ni", C[big], u), u, atol=1e-14)
    v = np.cross(u, rng.standard_normal(u.shape))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    w = np.einsum("nij,nj->ni", C[big], v)
    expect = np.cos(theta[big, None]) * v + np.sin(theta[big, None]) * np.cross(u, v)
    np.testing.assert_allclose(w, expect, atol=1e-14)


def test_exp_log_round_trip():
    rng = np.random.default_rng(3)
    a = np.vstack([_random_rotvecs(rng, 500, max_angle=np.pi - 1e-3), _special_rotvecs()])
    b = r.log_so3(r.exp_so3(a))
    theta = np.linalg.norm(a, axis=1)
    near_pi = theta > np.pi - 1e-5
    # away from pi the rotation vector comes back; near pi, either a or the equivalent -a' direction
    np.testing.assert_allclose(b[~near_pi], a[~near_pi], rtol=0, atol=1e-12)
    np.testing.assert_allclose(_angle_between(r.exp_so3(b), r.exp_so3(a)), 0.0, atol=1e-12)
    assert np.all(np.linalg.norm(b, axis=1) <= np.pi + 1e-15)
    # angle exactly pi: log gives an angle-pi vector on the same axis (either sign)
    for axis in np.eye(3):
        bb = r.log_so3(r.exp_so3(np.pi * axis))
        assert abs(np.linalg.norm(bb) - np.pi) < 1e-12
        np.testing.assert_allclose(np.abs(bb), np.pi * axis, atol=1e-12)


def test_quat_dcm_round_trips():
    rng = np.random.default_rng(4)
    a = np.vstack([_random_rotvecs(rng, 500), _special_rotvecs()])
    q = r.rotvec_to_quat(a)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    C = r.quat_to_dcm(q)
    np.testing.assert_allclose(C, r.exp_so3(a), atol=1e-14)
    q2 = r.dcm_to_quat(C)
    # same rotation: q2 = +-q, with w >= 0
    sign = np.where(np.sum(q * q2, axis=1) < 0, -1.0, 1.0)
    np.testing.assert_allclose(q2 * sign[:, None], q, atol=1e-13)
    assert np.all(q2[:, 0] >= 0)
    np.testing.assert_allclose(r.quat_to_dcm(q2), C, atol=1e-14)
    # rotvec <-> quat (angles in [0, pi] come back; w >= 0 chosen)
    a_small = a[np.linalg.norm(a, axis=1) < np.pi - 1e-6]
    np.testing.assert_allclose(r.quat_to_rotvec(r.rotvec_to_quat(a_small)), a_small, rtol=0, atol=1e-12)
    # single items keep their shape
    assert r.dcm_to_quat(np.eye(3)).shape == (4,)
    assert r.quat_to_dcm(np.array([1.0, 0, 0, 0])).shape == (3, 3)


def test_dcm_to_quat_every_branch():
    # rotations by ~pi about each axis force the diagonal branches of dcm_to_quat
    for axis in [np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]),
                 np.array([1.0, 1.0, 0]) / np.sqrt(2), np.array([0.2, 0.3, -0.9])]:
        for angle in [np.pi, np.pi - 1e-4, 2.5, 1e-9, 0.0]:
            C = r.exp_so3(angle * axis)
            q = r.dcm_to_quat(C)
            np.testing.assert_allclose(r.quat_to_dcm(q), C, atol=1e-14)


def test_hamilton_product_matches_matrix_product():
    rng = np.random.default_rng(5)
    p = r.rotvec_to_quat(_random_rotvecs(rng, 300))
    q = r.rotvec_to_quat(_random_rotvecs(rng, 300))
    np.testing.assert_allclose(r.quat_to_dcm(r.quat_multiply(p, q)), r.quat_to_dcm(p) @ r.quat_to_dcm(q),
                               atol=1e-14)
    # conjugate is the inverse
    e = r.quat_multiply(p, r.quat_conjugate(p))
    np.testing.assert_allclose(e, np.tile([1.0, 0, 0, 0], (300, 1)), atol=1e-15)
    # Hamilton convention: i * j = k
    np.testing.assert_array_equal(r.quat_multiply([0, 1.0, 0, 0], [0, 0, 1.0, 0]), [0, 0, 0, 1.0])
    # q * (0, v) * q^-1 rotates v as C(q) does
    v = rng.standard_normal((300, 3))
    qv = np.column_stack([np.zeros(300), v])
    rot = r.quat_multiply(r.quat_multiply(p, qv), r.quat_conjugate(p))[:, 1:]
    np.testing.assert_allclose(rot, np.einsum("nij,nj->ni", r.quat_to_dcm(p), v), atol=1e-13)


def test_exp_of_sum_small_and_composition():
    # exp(a) exp(b) == exp(a + b) for parallel vectors
    rng = np.random.default_rng(6)
    u = _random_rotvecs(rng, 50, 1.0)
    np.testing.assert_allclose(r.exp_so3(0.3 * u) @ r.exp_so3(0.7 * u), r.exp_so3(u), atol=1e-14)


@pytest.mark.parametrize("scale", [1e-9, 1e-6, 1e-3, 0.3, 1.5, 3.0])
def test_right_jacobian_finite_differences(scale):
    rng = np.random.default_rng(7)
    for a in _random_rotvecs(rng, 10, 1.0) * scale:
        Jr = r.right_jacobian(a)
        h = 1e-6
        J_fd = np.empty((3, 3))
        C = r.exp_so3(a)
        for j in range(3):
            d = np.zeros(3)
            d[j] = h
            # Exp(a + d) = Exp(a) Exp(Jr d)  ->  Jr[:, j] = Log(Exp(a)^T Exp(a + h e_j)) / h (central)
            plus = r.log_so3(C.T @ r.exp_so3(a + d))
            minus = r.log_so3(C.T @ r.exp_so3(a - d))
            J_fd[:, j] = (plus - minus) / (2 * h)
        np.testing.assert_allclose(Jr, J_fd, atol=1e-8)
        np.testing.assert_allclose(r.right_jacobian_inv(a) @ Jr, np.eye(3), atol=1e-12)


def test_right_jacobian_small_angle_branch_continuous():
    u = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    below = r.right_jacobian(u * 0.99e-5)
    above = r.right_jacobian(u * 1.01e-5)
    np.testing.assert_allclose(below, above, atol=1e-7)
    np.testing.assert_allclose(r.right_jacobian_inv(u * 0.99e-5), r.right_jacobian_inv(u * 1.01e-5), atol=1e-7)


def test_numba_helpers_equal_numpy():
    rng = np.random.default_rng(8)
    a = np.vstack([_random_rotvecs(rng, 200), _special_rotvecs(), [[0.0, 0.0, 0.0]]])
    out = np.empty((3, 3))
    for v in a:
        r.exp_so3_nb(v[0], v[1], v[2], out)
        np.testing.assert_allclose(out, r.exp_so3(v), rtol=0, atol=1e-15)
        r.right_jacobian_nb(v[0], v[1], v[2], out)
        np.testing.assert_allclose(out, r.right_jacobian(v), rtol=0, atol=1e-15)


@pytest.mark.parametrize("theta", [3e-2, 1e-2, 1e-3, 1e-4, 3e-5, 1.1e-5])
def test_right_jacobian_precise_at_small_angles(theta):
    # Taylor series (exact to double precision at these angles) against the closed form;
    # a (1 - cos t) / t^2 coefficient loses eps / t here (4e-12 at t = 3e-5).
    u = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    a = theta * u
    K = r.skew(a)
    t2 = theta * theta
    A = 0.5 - t2 / 24 + t2 * t2 / 720 - t2**3 / 40320
    B = 1 / 6 - t2 / 120 + t2 * t2 / 5040 - t2**3 / 362880
    Jr = np.eye(3) - A * K + B * (K @ K)
    np.testing.assert_allclose(r.right_jacobian(a), Jr, rtol=0, atol=3e-16)
    out = np.empty((3, 3))
    r.right_jacobian_nb(a[0], a[1], a[2], out)
    np.testing.assert_allclose(out, Jr, rtol=0, atol=3e-16)
