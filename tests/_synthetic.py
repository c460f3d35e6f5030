"""Small synthetic experiments built directly from the containers (no simulator), for unit tests."""

import numpy as np

from graph_calib.records.experiment import Experiment, Table
from graph_calib.navigation.rotations import dcm_to_quat, exp_so3


def wobbly_experiment(*, rng, n=600, rate_hz=100.0, with_table=True, rate_scale=0.5):
    """Random smooth motion, a temperature ramp and all-valid table readings at 10 Hz.

    Not physically consistent (the table attitude does not follow the increments):
    good for Jacobian checks, not for calibration.
    """
    t = np.arange(1, n + 1) / rate_hz
    dt = 1.0 / rate_hz
    phase = rng.uniform(0, 2 * np.pi, size=(1, 3))
    w = rate_scale * np.sin(2 * np.pi * 0.3 * t[:, None] + phase) + 0.05 * rng.normal(size=(n, 3))
    f = np.array([0.3, -0.2, 9.8]) + 0.5 * np.sin(2 * np.pi * 0.2 * t[:, None] + phase) + 0.1 * rng.normal(size=(n, 3))
    temps = np.column_stack([20 + 0.01 * t, 21 + 0.012 * t + 0.001 * t**2])
    table = None
    if with_table:
        tt = np.arange(0.05, t[-1], 0.1)
        q = dcm_to_quat(exp_so3(rng.normal(size=(tt.size, 3))))
        table = Table(t=tt, q_nf=q, valid=np.ones(tt.size, bool), q_fb_nominal=np.array([1.0, 0, 0, 0]))
    return Experiment(
        t=t, dtheta=w * dt, dv=f * dt, temperature=temps, temperature_names=("a", "b"),
        temperature_map=np.array([0, 1, 0, 1, 0, 1]), rate_hz=rate_hz, latitude_rad=0.97,
        gravity_mps2=9.8155, imu_id="synthetic", table=table, source="synthetic",
    )


def _segments(*, static_s, dwell_s, rate):
    """(duration, body axis or None, rate) segments: rotations about each body axis, both directions."""
    seg = [(static_s, None, 0.0)]
    quarter = (np.pi / 2) / rate
    for axis, tilt in ((0, None), (1, None), (2, 0)):
        if tilt is not None:           # bring z horizontal first: 90 deg about x
            seg += [(quarter, tilt, rate), (dwell_s, None, 0.0)]
        for sign in (1.0, -1.0):
            for _ in range(4):
                seg += [(quarter, axis, sign * rate), (dwell_s, None, 0.0)]
            seg += [(4 * quarter, axis, sign * rate), (dwell_s, None, 0.0)]
    return seg


def turntable_experiment(*, layout, x, rng=None, noise=None, static_s=120.0, dwell_s=10.0,
                         rate=np.deg2rad(20.0), rate_hz=100.0, latitude_rad=0.97, gravity=9.8155,
                         temp=(20.0, 28.0), table_hz=10.0):
    """A consistent turntable experiment: exact increments of piecewise-constant-rate rotations.

    Rotations about body axes with the lever arm zero; Earth rate and gravity
    integrated by 4-point Gauss-Legendre quadrature per sample; sensor errors of
    ``x`` (``layout``) through ``sensor_model.measure``; white noise ``noise =
    (gyro rad/sqrt(s), accel m/s/sqrt(s), encoder rad)`` when given.
    Returns ``(experiment, true C_nb at every sample end (N, 3, 3))``.
    """
    from graph_calib.sensors import sensor_model as sm
    from graph_calib.constants import omega_ie_n

    h = 1.0 / rate_hz
    seg = _segments(static_s=static_s, dwell_s=dwell_s, rate=rate)
    counts = [max(1, int(round(d / h))) for d, _, _ in seg]
    N = int(sum(counts))
    t = np.arange(1, N + 1) * h
    w_nb = np.zeros((N, 3))
    C0 = np.empty((N, 3, 3))           # attitude at the start of each sample
    C = np.eye(3)
    i = 0
    for (d, axis, r), c in zip(seg, counts):
        wv = np.zeros(3)
        if axis is not None:
            wv[axis] = r
        w_nb[i:i + c] = wv
        C0[i:i + c] = C @ exp_so3(np.outer(np.arange(c) * h, wv))
        C = C @ exp_so3(wv * c * h)
        i += c
    gl_x, gl_w = np.polynomial.legendre.leggauss(4)
    tau = 0.5 * h * (gl_x + 1.0)
    w_ie = omega_ie_n(latitude_rad)
    g_up = np.array([0.0, 0.0, gravity])
    dth = w_nb * h
    dv = np.zeros((N, 3))
    for tq, wq in zip(tau, gl_w):
        Cq = C0 @ exp_so3(w_nb * tq)
        dth += 0.5 * h * wq * np.einsum("nji,j->ni", Cq, w_ie)
        dv += 0.5 * h * wq * np.einsum("nji,j->ni", Cq, g_up)
    C_end = C0 @ exp_so3(w_nb * h)
    T = np.linspace(temp[0], temp[1], N)
    dT = (T - T.mean())[:, None] * np.ones(3)
    f_mean = dv / h
    w_meas = sm.measure(layout, x, "gyro", dth / h, dT=dT, other=f_mean)
    f_meas = sm.measure(layout, x, "accel", f_mean, dT=dT, other=w_nb)
    dth_m, dv_m = w_meas * h, f_meas * h
    tt = np.arange(1.0 / table_hz, t[-1], 1.0 / table_hz)
    j = np.searchsorted(t, tt, side="right") - 1
    Ct = C_end[j] @ exp_so3(w_nb[np.minimum(j + 1, N - 1)] * (tt - t[j])[:, None])
    static = np.linalg.norm(w_nb[j], axis=1) == 0
    static &= np.linalg.norm(w_nb[np.minimum(j + 1, N - 1)], axis=1) == 0
    if noise is not None:
        sg, sa, se = noise
        dth_m = dth_m + rng.normal(size=(N, 3)) * sg * np.sqrt(h)
        dv_m = dv_m + rng.normal(size=(N, 3)) * sa * np.sqrt(h)
        Ct = Ct @ exp_so3(rng.normal(size=(tt.size, 3)) * se)
    table = Table(t=tt, q_nf=dcm_to_quat(Ct), valid=static, q_fb_nominal=np.array([1.0, 0, 0, 0]))
    exp = Experiment(t=t, dtheta=dth_m, dv=dv_m, temperature=T[:, None], temperature_names=("chamber",),
                     temperature_map=np.zeros(6, dtype=int), rate_hz=rate_hz, latitude_rad=latitude_rad,
                     gravity_mps2=gravity, imu_id="synthetic-turntable", table=table, source="synthetic")
    return exp, C_end


def perturbed_point(model, *, rng):
    """``(x, preint, R)``: a calibration of 1e-3 per element and the attitudes it propagates, each turned by 1e-2 rad
    at random: a linearisation point off the solution, where a Jacobian check means something."""
    x = rng.normal(size=model.layout.size) * 1e-3
    preint = model.preintegrate(x)
    R = model.propagate(np.eye(3), preint, x) @ exp_so3(rng.normal(size=(model.n_keyframes + 1, 3)) * 1e-2)
    return x, preint, R


def assert_calibration_jacobian_matches_fd(model, factors, R, x, *, H_x, eps, rtol, atol=0.0):
    """Each column of ``H_x`` (F, 3, P), the calibration Jacobian of ``factors(R, preint, x)`` (a model's
    factor method), against central differences of step ``eps``, each re-preintegrated:
    ``max |fd - H_x[:, :, c]| < rtol * scale + atol``, ``scale`` the larger of the two columns' maxima."""
    for c in range(model.layout.size):
        xp, xm = x.copy(), x.copy()
        xp[c] += eps
        xm[c] -= eps
        fd = (factors(R, model.preintegrate(xp), xp).r - factors(R, model.preintegrate(xm), xm).r) / (2 * eps)
        scale = np.abs(fd).max() + np.abs(H_x[:, :, c]).max() + 1e-12
        assert np.abs(fd - H_x[:, :, c]).max() < rtol * scale + atol, model.layout.element_names()[c]


def assert_pair_jacobians_match_fd(factors, R, *, index, key, H_R, H_R_next, eps, atol):
    """The Jacobians of factor ``index`` of ``factors(R)`` (a factor on keyframes ``key`` and ``key + 1``: its rows
    ``H_R`` and ``H_R_next``, (3, 3) each) against central differences of step ``eps`` in the right perturbation of
    each attitude."""
    for a in range(3):
        d = np.zeros(3)
        d[a] = eps
        for which, H in ((key, H_R), (key + 1, H_R_next)):
            Rp, Rm = R.copy(), R.copy()
            Rp[which] = R[which] @ exp_so3(d)
            Rm[which] = R[which] @ exp_so3(-d)
            fd = (factors(Rp).r[index] - factors(Rm).r[index]) / (2 * eps)
            np.testing.assert_allclose(H[:, a], fd, atol=atol)
