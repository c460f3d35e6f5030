"""Every Jacobian of the shared model against central finite differences."""

from dataclasses import replace

import numba
import numpy as np
import pytest

from graph_calib.sensors import sensor_model as sm
from graph_calib.model import CalibrationModel, ModelOptions, boundary_rate_correction
from graph_calib.model.calibration_model import reusing_preintegrations
from graph_calib.model.preintegration import _reading_rates
from graph_calib.sensors.effects import FURTHER_EFFECTS
from graph_calib.sensors.params import Layout
from graph_calib.navigation.rotations import dcm_to_quat, exp_so3, exp_so3_nb, right_jacobian_nb

from _synthetic import assert_calibration_jacobian_matches_fd, wobbly_experiment

EPS = 1e-6


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(1)
    exp = wobbly_experiment(rng=rng)
    model = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, extra_effects=FURTHER_EFFECTS))
    x = rng.normal(size=model.layout.size) * 1e-3
    preint = model.preintegrate(x)
    R = model.propagate(np.eye(3), preint, x) @ exp_so3(rng.normal(size=(model.n_keyframes + 1, 3)) * 1e-2)
    return model, x, preint, R


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
    s, J = sm.correct_with_jacobian(layout, x, triad, meas, **ctx)
    np.testing.assert_allclose(s, sig, atol=1e-12)
    for c in range(layout.size):
        xp, xm = x.copy(), x.copy()
        xp[c] += EPS
        xm[c] -= EPS
        fd = (sm.correct(layout, xp, triad, meas, **ctx) - sm.correct(layout, xm, triad, meas, **ctx)) / (2 * EPS)
        np.testing.assert_allclose(J[:, :, c], fd, atol=1e-6 * (1 + np.abs(fd).max()),
                                   err_msg=layout.element_names()[c])


def test_pair_inverse_uses_calibrated_specific_force_and_its_jacobian_matches_fd():
    """The gyros' g-sensitivity sees the calibrated f (model.md): the pair inversion recovers the true rate
    of a record measured with the true f, where the raw f misses by G @ (f_raw - f), and its chained
    Jacobian (gyro rate in the accelerometer columns) matches central differences."""
    rng = np.random.default_rng(8)
    layout = Layout.declared(extra=FURTHER_EFFECTS)
    x = rng.normal(size=layout.size) * 0.01                 # percent-level: consumer-grade errors
    x[layout.slice("gyro.g_sensitivity")] = rng.normal(size=9) * 1e-3
    x[layout.slice("accel.bias")] = rng.normal(size=3) * 0.5     # consumer biases: ~1 m/s^2
    n = 200
    w, f = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 5.0
    ctx = dict(dTg=rng.normal(size=(n, 3)), dTdtg=rng.normal(size=(n, 3)) * 0.01, dTa=rng.normal(size=(n, 3)),
               dTdta=rng.normal(size=(n, 3)) * 0.01, domega=rng.normal(size=(n, 3)), df=rng.normal(size=(n, 3)))
    w_m = sm.measure(layout, x, "gyro", w, dT=ctx["dTg"], dTdt=ctx["dTdtg"], other=f, domega=ctx["domega"],
                     dsignal=ctx["domega"])
    # the accelerometers' size effect sees the raw rate (documented approximation): measured with it
    f_m = sm.measure(layout, x, "accel", f, dT=ctx["dTa"], dTdt=ctx["dTdta"], other=w_m, domega=ctx["domega"],
                     dsignal=ctx["df"])
    w_c, f_c, Jw, Jf = sm.correct_pair_with_jacobian(layout, x, w_m, f_m, **ctx)
    np.testing.assert_allclose(f_c, f, atol=1e-12)
    np.testing.assert_allclose(w_c, w, atol=1e-12)
    w_raw_f = sm.correct(layout, x, "gyro", w_m, dT=ctx["dTg"], dTdt=ctx["dTdtg"], other=f_m,
                         domega=ctx["domega"], dsignal=ctx["domega"])
    assert np.abs(w_raw_f - w).max() > 1e-4                 # the raw f would be first-order wrong here
    acc = layout.slice("accel.bias")
    assert np.abs(Jw[:, :, acc]).max() > 1e-4                # the triads really couple
    for c in range(layout.size):
        xp, xm = x.copy(), x.copy()
        xp[c] += EPS
        xm[c] -= EPS
        wp, fp = sm.correct_pair(layout, xp, w_m, f_m, **ctx)
        wm, fm = sm.correct_pair(layout, xm, w_m, f_m, **ctx)
        for J, fd in ((Jw, (wp - wm) / (2 * EPS)), (Jf, (fp - fm) / (2 * EPS))):
            # against each column's own scale (the coupled columns are small), floored at the rounding
            np.testing.assert_allclose(J[:, :, c], fd, rtol=0, atol=1e-6 * np.abs(fd).max() + 1e-8,
                                       err_msg=layout.element_names()[c])


@pytest.mark.parametrize("kind", ["rotation_factors", "gravity_factors", "encoder_factors"])
def test_factor_jacobian_in_calibration_matches_fd(problem, kind):
    model, x, preint, R = problem
    f = getattr(model, kind)
    res = f(R, preint, x)
    assert res.r.shape[0] > 0
    # floor: the central difference's rounding, ~1e-16 |r| / EPS = 1e-10 (the columns that reach the gyro
    # rate only through g-sensitivity, e.g. accel.bias_dtdt, are ~1e-5 here)
    assert_calibration_jacobian_matches_fd(model, f, R, x, H_x=res.H_x, eps=EPS, rtol=1e-5, atol=1e-9)


def test_encoder_jacobian_with_readings_inside_sample_intervals_matches_fd():
    """Readings between sample ends, in motion, with a time lag: the partial-sample turn and the lag use
    the calibrated rate of the interval holding the reading, so both depend on x."""
    rng = np.random.default_rng(12)
    exp = wobbly_experiment(rng=rng)
    tt = np.sort(rng.uniform(0.02, exp.t[-1] - 0.02, size=120))
    table = replace(exp.table, t=tt, q_nf=dcm_to_quat(exp_so3(rng.normal(size=(tt.size, 3)))),
                    valid=np.ones(tt.size, bool))
    model = CalibrationModel(replace(exp, table=table), options=ModelOptions(keyframe_s=0.5))
    assert np.abs(model.record.reading_dt).min() > 1e-6 and "time_lag.table" in model.layout
    x = rng.normal(size=model.layout.size) * 1e-3
    x[model.layout.slice("time_lag.table")] = 0.01
    R = model.propagate(np.eye(3), model.preintegrate(x), x)
    res = model.encoder_factors(R, model.preintegrate(x), x)
    assert_calibration_jacobian_matches_fd(model, model.encoder_factors, R, x, H_x=res.H_x, eps=EPS, rtol=1e-5)


@pytest.mark.parametrize("kind", ["gravity_factors", "encoder_factors"])
def test_unary_factor_jacobian_in_attitude_matches_fd(problem, kind):
    model, x, preint, R = problem
    f = getattr(model, kind)
    res = f(R, preint, x)
    for a in range(3):
        d = np.zeros(3)
        d[a] = EPS
        fd = (f(R @ exp_so3(d), preint, x).r - f(R @ exp_so3(-d), preint, x).r) / (2 * EPS)
        np.testing.assert_allclose(res.H_R[:, :, a], fd, atol=1e-7 * (1 + np.abs(fd).max()))


def test_rotation_factor_jacobians_in_both_attitudes_match_fd(problem):
    model, x, preint, R = problem
    res = model.rotation_factors(R, preint, x)
    for k in (1, 3, model.n_keyframes - 1):
        for a in range(3):
            d = np.zeros(3)
            d[a] = EPS
            Rp, Rm = R.copy(), R.copy()
            Rp[k] = R[k] @ exp_so3(d)
            Rm[k] = R[k] @ exp_so3(-d)
            fd = (model.rotation_factors(Rp, preint, x).r - model.rotation_factors(Rm, preint, x).r) / (2 * EPS)
            np.testing.assert_allclose(res.H_R[k][:, a], fd[k], atol=1e-8)
            np.testing.assert_allclose(res.H_R_next[k - 1][:, a], fd[k - 1], atol=1e-8)


def test_first_order_update_tracks_repreintegration(problem):
    model, x, preint, R = problem
    dx = np.random.default_rng(3).normal(size=x.size) * 1e-6
    a = model.gravity_factors(R, preint, x + dx).r
    b = model.gravity_factors(R, model.preintegrate(x + dx), x + dx).r
    c0 = model.gravity_factors(R, preint, x).r
    assert np.abs(a - b).max() < 1e-3 * np.abs(b - c0).max()


def test_preintegrations_reused_only_inside_the_block_and_only_at_the_same_point(problem):
    model, x, preint, R = problem
    assert model.preintegrate(x) is not model.preintegrate(x)           # off outside the block
    other = CalibrationModel.from_record(model.record, options=replace(model.options, variance_factors={"gravity": 4.0}))
    smaller = model.with_effects(())
    with reusing_preintegrations():
        p = model.preintegrate(x)
        assert other.preintegrate(x.copy()) is p                         # noise and variance factors play no part
        nudged = x.copy()
        nudged[0] += 1e-15
        q = model.preintegrate(nudged)
        assert q is not p and q.x_lin[0] == nudged[0]                    # bit for bit, or formed again
        assert model.preintegrate(x) is p                                # the last two are held
        assert smaller.preintegrate(x[:smaller.layout.size]) is not p    # another layout: its own
        with reusing_preintegrations():                                  # nested: the outer block's held ones
            assert model.preintegrate(nudged) is q
    np.testing.assert_array_equal(p.J_dR, preint.J_dR)                   # the very preintegration, unchanged
    assert model.preintegrate(x) is not p


def test_readings_rate_jacobian_is_kept_at_the_linearisation_point(problem):
    """The readings' rate Jacobian is formed once, with the preintegration: after the encoder factors were
    evaluated away from ``x_lin`` it is still, bit for bit, the sensor model's inversion at ``x_lin`` (not at
    the evaluation point), read-only, and it matches central differences of the readings' rates."""
    model, x, preint, R = problem
    rng = np.random.default_rng(4)
    x1 = x + rng.normal(size=x.size) * 1e-4
    model.encoder_factors(R, preint, x1)
    gc = preint.gyro_cols
    n_newton = model.options.n_newton
    w0, J0 = _reading_rates(model.record, model.layout, preint.x_lin, n_newton, gc)
    assert preint.reading_J_w.shape == (model.record.reading_sample.size, 3, gc.size)
    np.testing.assert_array_equal(preint.reading_J_w, J0)
    np.testing.assert_array_equal(preint.reading_w, w0)
    np.testing.assert_array_equal(preint.reading_rate_jacobian(slice(3, 17)), J0[3:17])
    assert not np.array_equal(_reading_rates(model.record, model.layout, x1, n_newton, gc)[1], J0)
    with pytest.raises(ValueError):
        preint.reading_J_w[0, 0, 0] = 1.0
    for i, j in enumerate(gc):
        d = np.zeros(x.size)
        d[j] = EPS
        wp = _reading_rates(model.record, model.layout, preint.x_lin + d, n_newton, gc)[0]
        wm = _reading_rates(model.record, model.layout, preint.x_lin - d, n_newton, gc)[0]
        fd = (wp - wm) / (2 * EPS)
        np.testing.assert_allclose(preint.reading_J_w[:, :, i], fd, rtol=1e-6,
                                   atol=1e-9 * (1 + np.abs(fd).max()))


# ---------------------------------------------------------------------------
# the preintegration kernel against the direct recursion
# ---------------------------------------------------------------------------


@numba.njit
def _skew_mul(a, J, out):
    for c in range(J.shape[1]):
        out[0, c] = a[1] * J[2, c] - a[2] * J[1, c]
        out[1, c] = a[2] * J[0, c] - a[0] * J[2, c]
        out[2, c] = a[0] * J[1, c] - a[1] * J[0, c]


@numba.njit
def _reference_preintegrate(dt, k0, x, grows, arows, dTg, dTdtg, dTa, dTdta, w_raw, f_raw, dw_raw, df_raw,
                            tap_idx, tap_lo, n_newton, nc, Gm,
                            dR, JR, S, JS, S1, JS1, w_first, Jw_first, w_last, Jw_last, tapR, tapJ):
    """The recursion of ``model._preintegrate`` as written, full (3, nc) Jacobians through every sample.

    Each sample: accelerometers first, then gyros with the calibrated ``f`` (``Gm = d(Phi_g x)/df``), the gyro
    Jacobian chained, ``Jw -= Ai_g Gm Jf``."""
    for k in range(k0.shape[0] - 1):
        R = np.eye(3)
        J = np.zeros((3, nc))
        s = np.zeros(3)
        js = np.zeros((3, nc))
        s1 = np.zeros(3)
        js1 = np.zeros((3, nc))
        w = np.empty(3)
        Jw = np.zeros((3, nc))
        fc = np.empty(3)
        Jf = np.zeros((3, nc))
        pth = np.zeros(3)
        pJth = np.zeros((3, nc))
        th = np.empty(3)
        Jth = np.zeros((3, nc))
        vv = np.empty(3)
        Jvv = np.zeros((3, nc))
        phi = np.empty(3)
        Jphi = np.zeros((3, nc))
        u = np.empty(3)
        Ju = np.zeros((3, nc))
        c1 = np.empty(3)
        c2 = np.empty(3)
        tmp = np.zeros((3, nc))
        tmp2 = np.zeros((3, nc))
        E = np.empty((3, 3))
        Jr = np.empty((3, 3))
        work = np.empty((8, 3))
        j0 = k0[k]
        if j0 > 0:
            jp = j0 - 1
            Jf[:] = 0.0
            Jw[:] = 0.0
            sm.correct_sample(arows, x, f_raw[jp], dTa[jp], dTdta[jp], w_raw[jp], dw_raw[jp], df_raw[jp],
                              n_newton, fc, Jf, True, work)
            sm.correct_sample(grows, x, w_raw[jp], dTg[jp], dTdtg[jp], fc,
                              dw_raw[jp], dw_raw[jp], n_newton, w, Jw, True, work)
            Jw -= work[5:8] @ Gm @ Jf
            pth[:] = w * dt[j0 - 1]
            pJth[:] = Jw * dt[j0 - 1]
        tau = 0.0
        tp = tap_lo[k]
        for j in range(j0, k0[k + 1]):
            h = dt[j]
            Jf[:] = 0.0
            Jw[:] = 0.0
            sm.correct_sample(arows, x, f_raw[j], dTa[j], dTdta[j], w_raw[j], dw_raw[j], df_raw[j],
                              n_newton, fc, Jf, True, work)
            sm.correct_sample(grows, x, w_raw[j], dTg[j], dTdtg[j], fc, dw_raw[j], dw_raw[j],
                              n_newton, w, Jw, True, work)
            Jw -= work[5:8] @ Gm @ Jf
            th[:] = w * h
            vv[:] = fc * h
            Jth[:] = Jw * h
            Jvv[:] = Jf * h
            if j == j0:
                w_first[k] = w
                Jw_first[k] = Jw
            # coning: phi = th + pth x th / 12
            c1[:] = np.cross(pth, th)
            _skew_mul(pth, Jth, tmp)
            _skew_mul(th, pJth, tmp2)
            phi[:] = th + c1 / 12.0
            Jphi[:] = Jth + (tmp - tmp2) / 12.0
            # u = v + th x v / 2 + th x (th x v) / 6 + h^2/12 (th x fdot - alpha x v)
            ka = h * h / 12.0
            c1[:] = np.cross(th, vv)
            c2[:] = np.cross(th, c1)
            _skew_mul(th, Jvv, tmp)
            _skew_mul(vv, Jth, tmp2)
            tmp -= tmp2                                   # d(th x v)
            _skew_mul(th, tmp, tmp2)
            u[:] = vv + 0.5 * c1 + c2 / 6.0 + ka * (np.cross(th, df_raw[j]) - np.cross(dw_raw[j], vv))
            Ju[:] = Jvv + 0.5 * tmp + tmp2 / 6.0
            _skew_mul(c1, Jth, tmp2)
            Ju -= tmp2 / 6.0
            _skew_mul(df_raw[j], Jth, tmp2)
            Ju -= ka * tmp2
            _skew_mul(dw_raw[j], Jvv, tmp2)
            Ju -= ka * tmp2
            # S += R u, dS += R (du - [u x] J)
            _skew_mul(u, J, tmp)
            tmp2[:] = Ju - tmp
            tm = tau + 0.5 * h
            ru = R @ u
            d = R @ tmp2
            s += ru
            s1 += tm * ru
            js += d
            js1 += tm * d
            # R <- R Exp(phi), J <- Exp(phi)^T J + Jr(phi) dphi
            exp_so3_nb(phi[0], phi[1], phi[2], E)
            right_jacobian_nb(phi[0], phi[1], phi[2], Jr)
            J[:] = E.T @ J + Jr @ Jphi
            R[:] = R @ E
            tau += h
            while tp < tap_idx.shape[0] and tap_idx[tp] == j:
                tapR[tp] = R
                tapJ[tp] = J
                tp += 1
            pth[:] = th
            pJth[:] = Jth
        dR[k] = R
        JR[k] = J
        S[k] = s
        JS[k] = js
        S1[k] = s1
        JS1[k] = js1
        w_last[k] = w
        Jw_last[k] = Jw


def _reference_preintegration(model, x):
    """Preintegrated quantities of ``model`` at ``x`` by the direct recursion, as a dict."""
    nc = model.terms.columns.size
    K = model.n_keyframes
    M = model.record.reading_sample.size
    out = dict(dR=np.empty((K, 3, 3)), J_dR=np.zeros((K, 3, nc)), S=np.empty((K, 3)), J_S=np.zeros((K, 3, nc)),
               S1=np.empty((K, 3)), J_S1=np.zeros((K, 3, nc)), wf=np.empty((K, 3)), Jwf=np.zeros((K, 3, nc)),
               wl=np.empty((K, 3)), Jwl=np.zeros((K, 3, nc)), reading_dR=np.empty((M, 3, 3)),
               reading_J=np.zeros((M, 3, nc)))
    rec, terms = model.record, model.terms
    xc = x[terms.columns]
    Gm = np.zeros((3, 3))
    for col, axis, code, aux in terms.gyro_rows_compact:
        if code == sm.GSENS:
            Gm[axis, aux] += xc[col]
    _reference_preintegrate(rec.dt, rec.k0, xc, terms.gyro_rows_compact, terms.accel_rows_compact,
                            rec.dTg, rec.dTdtg, rec.dTa, rec.dTdta, rec.w_raw, rec.f_raw, rec.dw_raw, rec.df_raw,
                            rec.reading_sample, rec.reading_lo, model.options.n_newton, nc, Gm, *out.values())
    wf, Jwf, wl, Jwl = out.pop("wf"), out.pop("Jwf"), out.pop("wl"), out.pop("Jwl")
    out["w_b"] = np.concatenate([wf[:1], 0.5 * (wl[:-1] + wf[1:]), wl[-1:]])
    out["w_b"] += model.record.w_b_fix
    out["J_w_b"] = np.concatenate([Jwf[:1], 0.5 * (Jwl[:-1] + Jwf[1:]), Jwl[-1:]])
    return out


def test_boundary_rate_exact_for_cubics_and_ramp_starts():
    h, n = 0.01, 60
    k0 = np.array([0, 20, 40, 60])
    edges = np.arange(n + 1) * h
    c = np.array([[0.3, -2.0, 5.0, 40.0], [0.0, 1.0, -7.0, 3.0], [0.1, 0.0, 0.0, 0.0]])   # per axis, t^0..t^3

    def means(F):                          # interval means from an antiderivative F(t), (n, 3)
        return np.diff(F(edges), axis=0) / h

    w = means(lambda t: np.stack([sum(c[a, p] * t ** (p + 1) / (p + 1) for p in range(4)) for a in range(3)], 1))
    w_b = np.concatenate([w[:1], 0.5 * (w[k0[1:-1] - 1] + w[k0[1:-1]]), w[-1:]]) + boundary_rate_correction(w, k0)
    t_b = k0 * h
    exact = np.stack([sum(c[a, p] * t_b**p for p in range(4)) for a in range(3)], 1)
    np.testing.assert_allclose(w_b[1:-1], exact[1:-1], rtol=0, atol=1e-12)      # inner boundaries: cubic exact
    # the two ends are linear extrapolations: exact for the linear axis 2, off by O(h^2 w'') elsewhere
    np.testing.assert_allclose(w_b[[0, -1], 2], exact[[0, -1], 2], atol=1e-14)
    # a cosine-like ramp starting at the boundary t = 0.2 s: rate a (t - 0.2)^2 after it, zero before
    a = 2.0
    ramp = means(lambda t: np.repeat((a / 3 * np.clip(t - 0.2, 0, None) ** 3)[:, None], 3, 1))
    w_b = 0.5 * (ramp[19] + ramp[20]) + boundary_rate_correction(ramp, k0)[1]
    assert np.abs(w_b).max() < 1e-15
    assert abs(0.5 * (ramp[19, 0] + ramp[20, 0]) - a * h**2 / 6) < 1e-15      # what the plain mean is off by


@pytest.mark.parametrize("extra, keyframe_s", [((), 0.37), (FURTHER_EFFECTS, 0.37), (FURTHER_EFFECTS, 1.0)])
@pytest.mark.slow
def test_preintegration_kernel_matches_direct_recursion(extra, keyframe_s):
    rng = np.random.default_rng(11)
    exp = wobbly_experiment(rng=rng, n=700, rate_scale=1.5)
    # table readings faster than the samples: several fall in one sample interval, some at keyframe ends
    tt = np.unique(np.concatenate([rng.uniform(0.0, exp.t[-1], size=300), exp.t[::37] - 1e-4, exp.t[36::37]]))
    tt = tt[tt < exp.t[-1]]
    table = replace(exp.table, t=tt, q_nf=dcm_to_quat(exp_so3(rng.normal(size=(tt.size, 3)))),
                    valid=np.ones(tt.size, bool))
    model = CalibrationModel(replace(exp, table=table),
                             options=ModelOptions(keyframe_s=keyframe_s, extra_effects=extra))
    assert np.any(np.diff(model.record.reading_sample) == 0)
    x = rng.normal(size=model.layout.size) * 1e-2       # percent level: the nonlinear terms matter
    preint = model.preintegrate(x)
    ref = _reference_preintegration(model, x)
    cols = model.terms.columns
    others = np.setdiff1d(np.arange(model.layout.size), cols)
    for name, b in ref.items():
        a = getattr(preint, name)
        if name == "reading_J":                 # kept in the gyro columns alone: the others must be zero
            a = np.zeros(a.shape[:-1] + (model.layout.size,))
            a[..., preint.gyro_cols] = preint.reading_J
        assert a.shape[:-1] == b.shape[:-1], name
        if name.startswith(("J_", "reading_J")):
            assert not np.any(a[..., others]), name
            a = a[..., cols]
            # each column against its own scale
            scale = np.abs(b).max(axis=tuple(range(b.ndim - 1)))
            assert np.all(a[..., scale == 0] == 0), name          # e.g. accelerometer columns of J_dR
            err = np.abs(a - b).max(axis=tuple(range(b.ndim - 1))) / np.where(scale > 0, scale, 1.0)
            assert err.max() < 1e-10, (name, model.layout.element_names()[cols[np.argmax(err)]], err.max())
        else:
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max(), err_msg=name)
