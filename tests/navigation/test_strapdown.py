"""Tests of graph_calib.navigation.strapdown: attitude integration."""

import numpy as np
import pytest

from graph_calib.navigation import strapdown as sd
from graph_calib.constants import omega_ie_n
from graph_calib.navigation.rotations import (
    quat_conjugate,
    quat_multiply,
    quat_to_dcm,
    rotvec_to_quat,
)

from _strapdown_helpers import LAT, quat_angle, random_quat, sample_dt


# ---------------------------------------------------------------------------
# attitude integration
# ---------------------------------------------------------------------------


def test_constant_rate_about_body_axis_is_exact():
    """C_nb(t) = Exp(-omega_ie_n T) C_nb0 Exp(omega_b T) for a constant inertial rate about a body axis."""
    rng = np.random.default_rng(10)
    rate_hz = 100.0
    n = 20_000
    dt = 0.01 + 0.001 * rng.uniform(-1, 1, n)  # irregular sampling
    t = 3.0 + np.cumsum(dt)
    dt = sample_dt(t, rate_hz)
    omega_b = np.array([0.3, -0.2, 0.4])  # rad/s, about a fixed body axis
    q0 = random_quat(rng)
    q = sd.integrate_attitude(omega_b * dt[:, None], t=t, rate_hz=rate_hz, q_nb0=q0, latitude_rad=LAT)
    assert q.shape == (n + 1, 4)
    T = sd.attitude_times(t, rate_hz) - (t[0] - 1.0 / rate_hz)
    q_true = quat_multiply(quat_multiply(rotvec_to_quat(-omega_ie_n(LAT) * T[:, None]), q0),
                           rotvec_to_quat(omega_b * T[:, None]))
    err = quat_angle(q, q_true)
    assert err.max() < 1e-12, err.max()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-14)
    # without the coning term the result is the same (parallel increments)
    q_nc = sd.integrate_attitude(omega_b * dt[:, None], t=t, rate_hz=rate_hz, q_nb0=q0, latitude_rad=LAT,
                                 coning=False)
    assert quat_angle(q_nc, q_true).max() < 1e-12


def test_static_at_latitude_keeps_attitude_over_hours():
    """Exact increments of the Earth rate seen by a body at rest: q_nb must not move (4 h at 100 Hz)."""
    rng = np.random.default_rng(11)
    rate_hz = 100.0
    n = int(4 * 3600 * rate_hz)
    t = np.arange(1, n + 1) / rate_hz
    q0 = random_quat(rng)
    C_nb = quat_to_dcm(q0)
    omega_ib_b = C_nb.T @ omega_ie_n(LAT)
    dtheta = np.broadcast_to(omega_ib_b / rate_hz, (n, 3))
    q = sd.integrate_attitude(dtheta, t=t, rate_hz=rate_hz, q_nb0=q0, latitude_rad=LAT)
    err = quat_angle(q[:: 997], q0)
    assert err.max() < 1e-10, err.max()
    assert quat_angle(q[-1], q0) < 1e-10
    # the same increments integrated at the wrong latitude: the level frame's turn is taken off about the wrong
    # axis, C_nb(T) = Exp(-w(-LAT) T) Exp(w(LAT) T) C_nb0 (hand-made), 0.11 rad after 1000 s
    m = 100_000
    T = m / rate_hz
    q_wrong_lat = sd.integrate_attitude(dtheta[:m], t=t[:m], rate_hz=rate_hz, q_nb0=q0, latitude_rad=-LAT)
    expected = _rodrigues(-_earth_rate_enu(-LAT) * T) @ _rodrigues(_earth_rate_enu(LAT) * T) @ _dcm_by_hand(q0)
    assert _dcm_angle(_dcm_by_hand(q_wrong_lat[-1]), expected) < 1e-10
    assert _dcm_angle(expected, _dcm_by_hand(q0)) > 0.1  # the test can see a wrong Earth rate


#: model.md: OMEGA_E = 7.292115e-5 rad/s, omega_ie_n = OMEGA_E [0, cos(lat), sin(lat)] in East-North-Up
def _earth_rate_enu(lat):
    return 7.292115e-5 * np.array([0.0, np.cos(lat), np.sin(lat)])


def _rodrigues(v):
    """Rotation matrix of the rotation vector ``v`` (by hand, independent of graph_calib.navigation.rotations)."""
    a = np.linalg.norm(v)
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]) / a
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * K @ K


def _dcm_by_hand(q):
    """C_ab of the scalar-first Hamilton quaternion q_ab (model.md)."""
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _dcm_angle(A, B):
    """Angle of the rotation between two rotation matrices, rad (accurate for small angles too)."""
    D = A @ B.T
    return float(np.arctan2(0.5 * np.linalg.norm([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]]),
                            0.5 * (np.trace(D) - 1.0)))


@pytest.mark.parametrize("lat", [0.0, LAT, -LAT, np.pi / 2])
def test_earth_rate_turns_a_body_at_rest_in_inertial_space(lat):
    """The Earth-rate contribution alone: zero gyro increments (a body not turning against inertial space)
    must come out as C_nb(t) = Exp(-omega_ie_n t) C_nb0, i.e. drift by exactly OMEGA_E t about -omega_ie_n
    (at the equator about North, at the pole about Up), against a hand-made expectation."""
    rng = np.random.default_rng(12)
    rate_hz = 50.0
    n = int(3600 * rate_hz)                     # 1 h: OMEGA_E * 1 h = 0.26 rad
    t = 7.0 + np.arange(n) / rate_hz
    q0 = random_quat(rng)
    C0 = _dcm_by_hand(q0)
    q = sd.integrate_attitude(np.zeros((n, 3)), t=t, rate_hz=rate_hz, q_nb0=q0, latitude_rad=lat)
    T = sd.attitude_times(t, rate_hz) - (t[0] - 1.0 / rate_hz)
    w = _earth_rate_enu(lat)
    for k in (1, n // 3, n // 2 + 17, n):
        expected = _rodrigues(-w * T[k]) @ C0
        assert _dcm_angle(_dcm_by_hand(q[k]), expected) < 1e-10, (k, lat)
    assert T[-1] == pytest.approx(3600.0)
    assert _dcm_angle(_dcm_by_hand(q[-1]), C0) == pytest.approx(7.292115e-5 * 3600.0, rel=1e-9)
    # the axis of the drift, in n: -omega_ie_n
    D = _dcm_by_hand(q[-1]) @ C0.T
    axis = np.array([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]])
    np.testing.assert_allclose(axis / np.linalg.norm(axis), -w / np.linalg.norm(w), atol=1e-9)


def _coning_truth(alpha, Omega, t):
    """Classic coning: q_ib(t) = [cos(a/2), sin(a/2) cos(Wt), sin(a/2) sin(Wt), 0]."""
    s = np.sin(alpha / 2)
    return np.column_stack([np.full_like(t, np.cos(alpha / 2)), s * np.cos(Omega * t), s * np.sin(Omega * t),
                            np.zeros_like(t)])


def _coning_rate(alpha, Omega, t):
    """omega_ib_b = 2 vec(q* dq/dt) of the coning motion, rad/s, shape (len(t), 3)."""
    q = _coning_truth(alpha, Omega, t)
    s = np.sin(alpha / 2)
    dq = np.column_stack([np.zeros_like(t), -s * Omega * np.sin(Omega * t), s * Omega * np.cos(Omega * t),
                          np.zeros_like(t)])
    return 2.0 * quat_multiply(quat_conjugate(q), dq)[:, 1:]


def _coning_errors(alpha, Omega, rate_hz, duration, coning):
    """Attitude error (rad) per output row when integrating exact coning increments."""
    n = int(round(duration * rate_hz))
    t = np.arange(1, n + 1) / rate_hz
    # exact increments: 8-point Gauss-Legendre over each sample interval
    x, w = np.polynomial.legendre.leggauss(8)
    a, b = t - 1 / rate_hz, t
    tt = 0.5 * (b - a)[:, None] * x[None, :] + 0.5 * (a + b)[:, None]
    rate = _coning_rate(alpha, Omega, tt.ravel()).reshape(n, 8, 3)
    dtheta = 0.5 / rate_hz * np.einsum("k,nkc->nc", w, rate)
    q0 = _coning_truth(alpha, Omega, np.array([0.0]))[0]
    T = sd.attitude_times(t, rate_hz)
    q_true = quat_multiply(rotvec_to_quat(-omega_ie_n(LAT) * T[:, None]), _coning_truth(alpha, Omega, T))
    q = sd.integrate_attitude(dtheta, t=t, rate_hz=rate_hz, q_nb0=q0, latitude_rad=LAT, coning=coning)
    return quat_angle(q, q_true)


def test_coning_correction_reduces_error():
    """Coning of 0.05 rad half angle at 2 Hz: the correction cuts the drift and raises its order.

    Without it the drift over 20 s falls 4x when the rate doubles (second order in
    Omega dt); with the two-sample correction it falls 16x (fourth order).
    """
    alpha, Omega = 0.05, 2 * np.pi * 2.0
    err_c = _coning_errors(alpha, Omega, 100.0, 20.0, True)
    err_n = _coning_errors(alpha, Omega, 100.0, 20.0, False)
    print(f"\nconing 20 s at 100 Hz: error with correction {err_c[-1]:.3e} rad, without {err_n[-1]:.3e} rad")
    assert err_n[-1] > 5e-4  # the uncorrected drift is real
    assert err_c[-1] < err_n[-1] / 100
    # order of the drift (error growth after the first sample, which has no predecessor)
    err_c2 = _coning_errors(alpha, Omega, 200.0, 20.0, True)
    err_n2 = _coning_errors(alpha, Omega, 200.0, 20.0, False)
    ratio_c = (err_c[-1] - err_c[1]) / (err_c2[-1] - err_c2[1])
    ratio_n = err_n[-1] / err_n2[-1]
    assert 3.5 < ratio_n < 4.5, ratio_n
    assert 13.0 < ratio_c < 19.0, ratio_c


def test_slerp_on_a_geodesic():
    rng = np.random.default_rng(12)
    q0 = random_quat(rng)
    omega = np.array([0.2, 0.5, -0.1])
    tq = np.linspace(0.0, 10.0, 11)
    q = quat_multiply(q0, rotvec_to_quat(omega * tq[:, None]))
    q[3] *= -1  # sign flips must not matter
    tx = np.array([0.0, 0.25, 3.5, 3.99, 9.7, 10.0])
    expect = quat_multiply(q0, rotvec_to_quat(omega * tx[:, None]))
    got = sd.slerp_attitude(q, tq, tx)
    assert quat_angle(got, expect).max() < 1e-13
    assert sd.slerp_attitude(q, tq, 3.5).shape == (4,)
    with pytest.raises(ValueError, match="outside"):
        sd.slerp_attitude(q, tq, [10.5])


def test_integrate_attitude_checks_shapes():
    with pytest.raises(ValueError, match="shape"):
        sd.integrate_attitude(np.zeros((5, 2)), t=np.arange(5.0), rate_hz=1.0, q_nb0=[1, 0, 0, 0],
                              latitude_rad=0.0)
    with pytest.raises(ValueError, match="q_nb0"):
        sd.integrate_attitude(np.zeros((5, 3)), t=np.arange(5.0), rate_hz=1.0, q_nb0=[0, 0, 0, 0],
                              latitude_rad=0.0)
