"""The rate and angular acceleration at an instant (graph_calib.model.local_rates): exact on smooth motion, quiet
at rest under a ring-laser gyro's quantization, axis by axis during a turn; what the model takes from it."""

import numpy as np
import pytest

from graph_calib.constants import ARCSEC_TO_RAD
from graph_calib.model.local_rates import boundary_rate_correction, local_rates

H = 0.01
EARTH = np.array([0.0, 4.6e-5, 5.7e-5])          # a rest's rate, rad/s


def _turn(n=6000, *, rate=0.5, start=20.0, ramp=1.0, cruise=4.0):
    """Angle at the sample ends (n+1, 3) and the exact rate there: rest, a cosine ramp about x to ``rate``,
    a cruise, a ramp down, rest; y and z at a constant (Earth-like) rate."""
    te = np.arange(n + 1) * H
    u = te - start

    def ang(u):                    # the integral of the x rate from the ramp start
        up = np.clip(u, 0, ramp)
        a = rate / 2 * (up - ramp / np.pi * np.sin(np.pi * up / ramp))
        cr = np.clip(u - ramp, 0, cruise)
        dn = np.clip(u - ramp - cruise, 0, ramp)
        return a + rate * cr + rate / 2 * (dn + ramp / np.pi * np.sin(np.pi * dn / ramp))

    theta = np.column_stack([ang(u), EARTH[1] * te, EARTH[2] * te])
    w = np.where((u > 0) & (u < ramp), rate / 2 * (1 - np.cos(np.pi * u / ramp)), 0.0)
    w = np.where((u >= ramp) & (u < ramp + cruise), rate, w)
    d = u - ramp - cruise
    w = np.where((d >= 0) & (d < ramp), rate / 2 * (1 + np.cos(np.pi * d / ramp)), w)
    return te, theta, np.column_stack([w, np.full(n + 1, EARTH[1]), np.full(n + 1, EARTH[2])])


def _rates(dtheta, te, t_eval, **kw):
    n = dtheta.shape[0]
    t, dt = te[1:], np.full(n, H)
    return local_rates(dtheta, t, dt, bounds=np.array([[0, n]]), t_eval=t_eval, segment=np.zeros(t_eval.size, int),
                       **kw)


def test_a_quartic_angle_is_exact_and_the_acceleration_too():
    te = np.arange(2001) * H
    c = np.array([0.3, -0.2, 0.05, 0.01, -0.002])          # angle = sum c_p t^p on every axis
    theta = np.stack([sum(cp * (te * (1 + a)) ** p for p, cp in enumerate(c)) for a in range(3)], axis=1)
    t_eval = np.array([0.0, 0.333, 7.0, 19.995, 20.0])      # the ends too (windows moved inside)
    rate, acc, _ = _rates(np.diff(theta, axis=0), te, t_eval)
    for a in range(3):
        s = 1 + a
        exact_w = sum(p * cp * s**p * t_eval ** (p - 1) for p, cp in enumerate(c) if p)
        exact_a = sum(p * (p - 1) * cp * s**p * t_eval ** (p - 2) for p, cp in enumerate(c) if p > 1)
        np.testing.assert_allclose(rate[:, a], exact_w, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(acc[:, a], exact_a, rtol=1e-9, atol=1e-7)


def test_noise_free_turn_is_followed_as_the_four_sample_value():
    te, theta, w = _turn()
    k0 = np.arange(0, 6000, 100)
    rate, _, _ = _rates(np.diff(theta, axis=0), te, te[k0[1:]])
    wm = np.diff(theta, axis=0) / H
    four = 0.5 * (wm[k0[1:] - 1] + wm[k0[1:]]) + boundary_rate_correction(wm, np.append(k0, 6000))[1:-1]
    assert np.abs(rate - w[k0[1:]]).max() < 5e-7                 # the 1-s cosine ramps included
    assert np.abs(four - w[k0[1:]]).max() < 5e-7


def test_quantization_at_rest_and_on_the_axes_a_turn_is_not_about():
    te, theta, w = _turn()
    q = 0.5 * ARCSEC_TO_RAD
    rng = np.random.default_rng(5)
    noisy = theta + q * rng.standard_normal(theta.shape)
    t_eval = te[50:-50:10]
    rate, _, sigma = _rates(np.diff(noisy, axis=0), te, t_eval)
    err = rate - w[50:-50:10]
    at_rest = np.all(np.abs(w[50:-50:10, :1]) < 1e-12, axis=1)
    # a sample's own mean scatters by sqrt(2) Q / h (3.4e-4 rad/s), the four-sample value by 0.95 Q / h
    assert np.sqrt(np.mean(err[at_rest] ** 2)) < 0.01 * q / H
    # during the turn about x, y and z keep their long windows: the lever arm's x has no false information
    turning = ~at_rest
    assert np.sqrt(np.mean(err[turning, 1:] ** 2)) < 0.01 * q / H
    assert np.sqrt(np.mean(err[turning, 0] ** 2)) < 0.3 * q / H
    # the reported scatter is the fits' own: within a factor 2 of the error at rest
    ratio = np.sqrt(np.mean(err[at_rest] ** 2) / np.mean(sigma[at_rest] ** 2))
    assert 0.5 < ratio < 2.0, ratio


def test_a_window_never_crosses_a_segment_boundary():
    te = np.arange(401) * H
    theta = np.column_stack([0.2 * te, -0.1 * te, 0.0 * te])
    dth = np.diff(theta, axis=0)
    dth[200:] *= -3.0                                     # another piece of record: another rate
    t, dt = te[1:], np.full(400, H)
    t_eval = np.array([1.95, 2.05])
    rate, _, _ = local_rates(dth, t, dt, bounds=np.array([[0, 200], [200, 400]]), t_eval=t_eval,
                             segment=np.array([0, 1]))
    np.testing.assert_allclose(rate[0], [0.2, -0.1, 0.0], atol=1e-12)
    np.testing.assert_allclose(rate[1], [-0.6, 0.3, 0.0], atol=1e-12)
