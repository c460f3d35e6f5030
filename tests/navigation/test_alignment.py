"""Tests of graph_calib.navigation.alignment: levelling, gyrocompassing, table heading, alignment of an experiment."""

import numpy as np
import pytest

from graph_calib.navigation.alignment import align, alignment, gyrocompass, level
from graph_calib.constants import omega_ie_n
from graph_calib.records.experiment import Table
from graph_calib.navigation.rotations import (
    dcm_to_quat,
    quat_conjugate,
    quat_multiply,
    quat_to_dcm,
    quat_to_rotvec,
    rotvec_to_quat,
)
from graph_calib.navigation.static_detection import static_means
from graph_calib.navigation.strapdown import dcm_from_euler, euler_from_dcm, integrate_attitude

from _strapdown_helpers import LAT, G, make_experiment, quat_angle, random_quat


def test_level_recovers_roll_pitch():
    rng = np.random.default_rng(13)
    roll = rng.uniform(-np.pi + 1e-3, np.pi - 1e-3, 500)
    pitch = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, 500)
    heading = rng.uniform(-np.pi, np.pi, 500)
    C = dcm_from_euler(roll, pitch, heading)
    np.testing.assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape), atol=1e-15)
    f_b = G * C[:, 2, :]  # C_nb.T @ [0, 0, g]
    r, p = level(f_b)
    np.testing.assert_allclose(r, roll, rtol=0, atol=1e-12)
    np.testing.assert_allclose(p, pitch, rtol=0, atol=1e-12)
    r2, p2, h2 = euler_from_dcm(C)
    np.testing.assert_allclose(np.c_[r2, p2], np.c_[roll, pitch], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (h2 - heading))), 0.0, atol=1e-12)
    # a level body with z up reads +g on z: roll = pitch = 0
    assert level([0.0, 0.0, G]) == (0.0, 0.0)
    # convention check: heading is the angle from North clockwise to body y
    C = dcm_from_euler(0.0, 0.0, np.pi / 2)
    np.testing.assert_allclose(C @ [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], atol=1e-16)


def test_gyrocompass_heading_from_exact_static_rates():
    rng = np.random.default_rng(14)
    errs = []
    for lat in [0.0, 0.5, LAT, -1.2]:
        for _ in range(50):
            C_nb = quat_to_dcm(random_quat(rng))  # any attitude, any axis up
            f_b = C_nb.T @ np.array([0.0, 0.0, G])
            omega_ib_b = C_nb.T @ omega_ie_n(lat)
            C = gyrocompass(f_b, omega_ib_b)
            errs.append(np.linalg.norm(quat_to_rotvec(dcm_to_quat(C.T @ C_nb))))
    assert max(errs) < 1e-9, max(errs)
    # heading in the Euler sense, moderate tilts
    for heading in np.linspace(-3.1, 3.1, 13):
        C_nb = dcm_from_euler(0.02, -0.03, heading)
        C = gyrocompass(C_nb.T @ [0.0, 0.0, G], C_nb.T @ omega_ie_n(LAT))
        assert abs(np.angle(np.exp(1j * (euler_from_dcm(C)[2] - heading)))) < 1e-9


def _move_then_rest(rng, *, n_move, n_rest, rate_hz=100.0, omega_b=(0.2, -0.1, 0.3)):
    """Exact increments: a constant inertial rate about a body axis, then at rest; truth q_nb0."""
    q0 = random_quat(rng)
    omega_b = np.asarray(omega_b)
    n = n_move + n_rest
    t = np.arange(1, n + 1) / rate_hz
    T1 = n_move / rate_hz
    q1 = quat_multiply(quat_multiply(rotvec_to_quat(-omega_ie_n(LAT) * T1), q0), rotvec_to_quat(omega_b * T1))
    C1 = quat_to_dcm(q1)
    dtheta = np.empty((n, 3))
    dtheta[:n_move] = omega_b / rate_hz
    dtheta[n_move:] = C1.T @ omega_ie_n(LAT) / rate_hz
    dv = np.empty((n, 3))
    Tm = np.arange(1, n_move + 1) / rate_hz
    q_move = quat_multiply(quat_multiply(rotvec_to_quat(-omega_ie_n(LAT) * Tm[:, None]), q0),
                           rotvec_to_quat(omega_b * Tm[:, None]))
    dv[:n_move] = np.einsum("nji,j->ni", quat_to_dcm(q_move), [0.0, 0.0, G]) / rate_hz
    dv[n_move:] = C1.T @ [0.0, 0.0, G] / rate_hz
    return q0, q1, t, dtheta, dv


def test_alignment_static_from_start_and_after_motion():
    rng = np.random.default_rng(15)
    q0, q1, t, dtheta, dv = _move_then_rest(rng, n_move=0, n_rest=6000)
    exp = make_experiment(t, dtheta, dv, rate_hz=100.0)
    al = alignment(exp, interval=(0, 6000))
    assert quat_angle(al.q_nb0, q0) < 1e-9
    assert al.method == "gyrocompass" and al.interval == (0, 6000)
    assert al.sigma_tilt < 1e-12  # noiseless
    f_b, omega_b, dur = static_means(exp, [(0, 6000), (100, 200)])
    np.testing.assert_allclose(dur, [60.0, 1.0], rtol=1e-12)
    np.testing.assert_allclose(f_b[1], quat_to_dcm(q0).T @ [0.0, 0.0, G], rtol=0, atol=1e-12)
    np.testing.assert_allclose(omega_b[1], quat_to_dcm(q0).T @ omega_ie_n(LAT), rtol=0, atol=1e-17)
    # at rest only after 5 s of rotation: the attitude is carried back to the start
    q0, q1, t, dtheta, dv = _move_then_rest(rng, n_move=500, n_rest=6000)
    exp = make_experiment(t, dtheta, dv, rate_hz=100.0)
    al = alignment(exp, interval=(500, 6500))
    assert quat_angle(al.q_nb_interval, q1) < 1e-9
    assert quat_angle(al.q_nb0, q0) < 1e-9
    q = integrate_attitude(dtheta, t=t, rate_hz=100.0, q_nb0=align(exp, interval=(500, 6500)),
                           latitude_rad=LAT)
    assert quat_angle(q[-1], q1) < 1e-9


def test_alignment_from_table():
    rng = np.random.default_rng(16)
    q0, _, t, dtheta, dv = _move_then_rest(rng, n_move=0, n_rest=3000)
    q_fb = rotvec_to_quat(np.array([0.0, 0.0, np.pi / 2]))
    q_nf = quat_multiply(q0, quat_conjugate(q_fb))
    tt = np.arange(0.0, 30.0, 0.5)
    table = Table(t=tt, q_nf=np.tile(q_nf, (tt.size, 1)), valid=np.ones(tt.size, bool), q_fb_nominal=q_fb)
    exp = make_experiment(t, dtheta, dv, rate_hz=100.0, table=table)
    al = alignment(exp, interval=(0, 3000), method="table")
    assert quat_angle(al.q_nb0, q0) < 1e-12
    assert np.isnan(al.sigma_heading)
    # the heading comes from the table: turning the table reading by 0.1 rad about Up turns the result
    q_nf_turned = quat_multiply(rotvec_to_quat(np.array([0.0, 0.0, 0.1])), q_nf)
    table2 = Table(t=tt, q_nf=np.tile(q_nf_turned, (tt.size, 1)), valid=np.ones(tt.size, bool), q_fb_nominal=q_fb)
    al2 = alignment(make_experiment(t, dtheta, dv, rate_hz=100.0, table=table2), interval=(0, 3000),
                    method="table")
    assert abs(quat_angle(al2.q_nb0, q0) - 0.1) < 1e-12
    with pytest.raises(ValueError, match="table"):
        alignment(make_experiment(t, dtheta, dv, rate_hz=100.0), interval=(0, 3000), method="table")


def test_alignment_noisy_default_interval():
    """Navigation-grade noise, 60 s at rest: heading within a few of the rough sigmas."""
    rng = np.random.default_rng(17)
    rate_hz = 100.0
    q0, _, t, dtheta, dv = _move_then_rest(rng, n_move=0, n_rest=6000)
    arw = 0.002 * np.pi / 180 / 60  # 0.002 deg/sqrt(h) in rad/sqrt(s)
    vrw = 20e-6 * 9.81 / 10  # 20 micro-g at 100 Hz per sample
    dtheta = dtheta + arw * np.sqrt(1 / rate_hz) * rng.standard_normal(dtheta.shape)
    dv = dv + vrw / rate_hz * rng.standard_normal(dv.shape)
    exp = make_experiment(t, dtheta, dv, rate_hz=rate_hz)
    al = alignment(exp)
    assert al.interval == (0, 6000)
    C_err = quat_to_dcm(quat_multiply(quat_conjugate(q0), al.q_nb0))
    tilt = np.linalg.norm(quat_to_rotvec(dcm_to_quat(C_err)))
    assert 0 < tilt < 1e-2
    d_heading = np.angle(np.exp(1j * (al.heading - euler_from_dcm(quat_to_dcm(q0))[2])))
    assert abs(d_heading) < 5 * al.sigma_heading + 5 * al.sigma_tilt
    assert al.sigma_heading < 1e-2
