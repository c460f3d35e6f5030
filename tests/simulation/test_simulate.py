"""The simulator: exact kinematics, quadrature, truth consistency, noise, reproducibility, files, CLI."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from graph_calib.sensors import effects, params
from graph_calib import io
from graph_calib.cli import main
from graph_calib.constants import ARCSEC_TO_RAD, DH_TO_RS, RAD_TO_ARCSEC, omega_ie_n
from graph_calib.navigation.rotations import exp_so3, log_so3, quat_to_dcm
from graph_calib.sensors.sensor_model import correct
from graph_calib.simulation import SCENARIOS, scenario_names, simulate, write_simulation
from graph_calib.simulation.handheld import HandheldMotion
from graph_calib.simulation.imu import SignalModel, simulate_increments
from graph_calib.simulation.thermal import ThermalModel
from graph_calib.simulation.turntable import INNER, OUTER, ProgramBuilder, TurntableMotion, rot_z
from graph_calib.navigation.strapdown import integrate_attitude

SHORT = 0.03  # hours: enough for a few rotations, fast


def _one(name, seed=0, **options):
    return simulate(name, rng=np.random.default_rng(seed), **options).run()[0]


def _rotation_angle(C1, C2):
    return np.linalg.norm(log_so3(np.swapaxes(C1, -1, -2) @ C2), axis=-1)


def _level_specific_force(se):
    """Each sample's specific force in the level frame, from its dv and dtheta and the true attitude.

    ``C_nb(t_{k-1}) (dv + 1/2 dtheta x dv) / dt - 1/2 omega_ie_n x C_nb(t_{k-1}) dv``: the
    second term is the turn of the level frame during the sample (the Earth rate).
    """
    e = se.experiment
    dt = 1.0 / e.rate_hz
    C_prev = se.attitude(e.t - dt)
    u = e.dv + 0.5 * np.cross(e.dtheta, e.dv)
    fn = np.einsum("nij,nj->ni", C_prev, u) / dt
    fn -= 0.5 * np.cross(omega_ie_n(e.latitude_rad), np.einsum("nij,nj->ni", C_prev, e.dv))
    return fn


@pytest.fixture(scope="module")
def ideal_full():
    """nav-subrange at full length (1.5 h at 100 Hz), no noise, no errors."""
    return _one("nav-subrange", seed=11, noise=False, errors=False)


# ---------------------------------------------------------------------------
# the acceptance test: strapdown of noise-free increments follows the table
# ---------------------------------------------------------------------------


def test_strapdown_follows_table_attitude_over_full_experiment(ideal_full):
    se = ideal_full
    e = se.experiment
    assert e.n_samples == 540_000 and e.rate_hz == 100.0
    q0 = io_q(se.attitude(np.array([e.t[0] - 1.0 / e.rate_hz]))[0])
    q = integrate_attitude(e.dtheta, t=e.t, rate_hz=e.rate_hz, q_nb0=q0, latitude_rad=e.latitude_rad)
    idx = np.unique(np.concatenate([np.linspace(0, e.n_samples - 1, 2000).astype(int), [e.n_samples - 1]]))
    err = _rotation_angle(se.attitude(e.t[idx]), quat_to_dcm(q[idx + 1])) * RAD_TO_ARCSEC
    assert err.max() < 0.1, f"strapdown departs from the table by {err.max():.3g} arcsec"
    # the experiment really moves: every instrument axis was turned about
    turned = np.abs(e.dtheta).sum(axis=0)
    assert np.all(turned > 10 * 2 * np.pi)


def io_q(C):
    from graph_calib.navigation.rotations import dcm_to_quat

    return dcm_to_quat(C)


def test_static_specific_force_is_gravity(ideal_full):
    se = ideal_full
    e = se.experiment
    dt = 1.0 / e.rate_hz
    static = se.motion.is_static(e.t - 0.5 * dt, margin=dt)
    assert 0.5 < static.mean() < 0.95
    fn = _level_specific_force(se)
    err = np.abs(fn[static] - [0.0, 0.0, e.gravity_mps2])
    assert err.max() < 1e-7
    # and while turning the accelerometers do see the rotation (no lever arm: still gravity only,
    # but the sample-start attitude rotation is then only approximate)
    assert np.abs(fn[~static] - [0.0, 0.0, e.gravity_mps2]).max() < 1e-3


def test_nav_subrange_design(ideal_full):
    se = ideal_full
    segs = se.motion.program.segments()
    assert segs[0][0] == "dwell" and segs[0][2] == pytest.approx(900.0)
    moves = [s for s in segs if s[0] != "dwell"]
    dwells = [s for s in segs[1:-1] if s[0] == "dwell"]
    assert len(moves) > 60
    rates = [abs(s[3]) / (s[2] - 1.0) for s in moves]  # peak rate = angle / (ramp + cruise)
    assert 10.0 <= np.degrees(min(rates)) and np.degrees(max(rates)) <= 30.5
    assert all(20.0 - 0.01 <= d[2] <= 40.0 + 0.01 for d in dwells)
    # both directions on both table axes, quarter and full turns
    ang = np.array([s[3] for s in moves])
    axes = [s[0] for s in moves]
    assert {"outer", "inner"} <= set(axes)
    assert (ang > 0).any() and (ang < 0).any()
    assert np.any(np.isclose(np.abs(ang), 2 * np.pi)) and np.any(np.isclose(np.abs(ang), np.pi / 2))
    # sensors drift 5-10 degC, never settling
    T = se.experiment.sensor_temperatures()
    assert 5.0 <= T.mean(axis=1).max() - T.mean(axis=1).min() <= 10.0
    assert np.all(np.diff(se.thermal.chamber_T) > 0)


# ---------------------------------------------------------------------------
# kinematics and quadrature
# ---------------------------------------------------------------------------


def _program(rate_hz=100.0):
    b = ProgramBuilder(rate_hz)
    b.dwell(1.0)
    b.move(OUTER, np.pi / 2, rate=np.radians(20.0))
    b.dwell(0.5)
    b.move(INNER, -2 * np.pi, rate=np.radians(27.0), ramp=0.7)
    b.move(OUTER, -np.pi / 2, rate=np.radians(13.0))
    b.dwell(1.0)
    return b.build()


def test_table_moves_turn_exactly_and_rates_are_derivatives():
    p = _program()
    assert np.allclose(p.final_angles, [0.0, -2 * np.pi], atol=1e-14)
    motion = TurntableMotion(p, C_n0=rot_z(0.3), C_fb=exp_so3(np.array([1e-3, -2e-3, 3e-3])))
    t = np.linspace(0.9, p.duration - 0.5, 777)
    h = 1e-6
    k = motion.kinematics(t)
    Cp, Cm = motion.kinematics(t + h).C_nb, motion.kinematics(t - h).C_nb
    # C^T dC/dt = [omega x]
    S = np.swapaxes(k.C_nb, 1, 2) @ (Cp - Cm) / (2 * h)
    w_fd = np.column_stack([S[:, 2, 1], S[:, 0, 2], S[:, 1, 0]])
    assert np.abs(w_fd - k.omega_nb_b).max() < 1e-8
    dw_fd = (motion.kinematics(t + h).omega_nb_b - motion.kinematics(t - h).omega_nb_b) / (2 * h)
    assert np.abs(dw_fd - k.domega_nb_b).max() < 1e-6
    assert np.degrees(np.abs(k.omega_nb_b).max()) == pytest.approx(27.0, rel=0.02)


def test_specific_force_from_lever_arm_point_trajectory():
    """f_b against C_bn (g_up + r'' + 2 omega_ie x r') of the lever-arm point r_n = C_nb l (numerical)."""
    p = _program()
    motion = TurntableMotion(p, C_n0=rot_z(0.2), C_fb=exp_so3(np.array([2e-3, 1e-3, -1e-3])))
    lever = np.array([0.1, -0.07, 0.12])
    sm = SignalModel(motion, latitude_rad=0.9, gravity_mps2=9.81, lever_arm=lever, rate_hz=p.rate_hz)
    h = 1e-3
    t = np.linspace(1.0, p.duration - 1.0, 400)
    # keep the difference stencils inside one segment and ramp (the jerk jumps at their ends)
    bounds = np.concatenate([p.start_tick, p.start_tick + p.ramp_ticks,
                             p.start_tick + p.ramp_ticks + p.cruise_ticks]) / p.rate_hz
    t = t[np.min(np.abs(t[:, None] - bounds[None, :]), axis=1) > 3 * h]
    r = [np.einsum("nij,j->ni", motion.kinematics(t + k * h).C_nb, lever) for k in (-2, -1, 0, 1, 2)]
    v = (r[0] - 8 * r[1] + 8 * r[3] - r[4]) / (12 * h)
    a = (-r[0] + 16 * r[1] - 30 * r[2] + 16 * r[3] - r[4]) / (12 * h * h)
    w_ie = omega_ie_n(0.9)
    f_n = a + 2 * np.cross(w_ie, v) + [0.0, 0.0, 9.81]
    s = sm.signals(t)
    f_ref = np.einsum("nji,nj->ni", s["C_nb"], f_n)
    assert np.abs(s["f_b"] - f_ref).max() < 1e-7  # the Coriolis term alone is ~5e-6 here
    assert np.abs(np.cross(w_ie, v)).max() > 2e-6


def test_quadrature_matches_adaptive_integration():
    """Increments (Earth rate, lever arm, ramps) against scipy's adaptive quadrature."""
    p = _program()
    motion = TurntableMotion(p, C_n0=rot_z(0.2), C_fb=exp_so3(np.array([2e-3, 1e-3, -1e-3])))
    sm = SignalModel(motion, latitude_rad=0.9, gravity_mps2=9.81, lever_arm=[0.1, -0.07, 0.12], rate_hz=p.rate_hz)
    layout = params.Layout.declared()
    thermal = ThermalModel(chamber_t=np.array([0.0, 100.0]), chamber_T=np.array([20.0, 21.0]), names=("a",),
                           tau=np.array([600.0]), offset=np.array([0.0]), initial=np.array([20.0]))
    t, dth, dv = simulate_increments(sm, thermal, rate_hz=p.rate_hz, n_samples=p.n_ticks, layout=layout,
                                     x=layout.zeros(), t_ref=20.0, temperature_map=np.zeros(6, int))
    moving = ~motion.is_static(t - 0.005, margin=0.01)
    rng = np.random.default_rng(0)
    picks = np.sort(rng.choice(np.flatnonzero(moving), size=200, replace=False))
    # reference: composite 8-node Gauss-Legendre over 32 sub-intervals of each sample interval
    xi, wq = np.polynomial.legendre.leggauss(8)
    sub = 32
    h = 1.0 / p.rate_hz
    left = (t[picks] - h)[:, None, None] + (np.arange(sub) * h / sub)[None, :, None]
    ts = (left + (0.5 * (1 + xi) * h / sub)[None, None, :]).ravel()
    s = sm.signals(ts)
    wts = np.tile(0.5 * wq * h / sub, sub)
    ref_w = np.einsum("kmj,m->kj", s["omega_ib_b"].reshape(picks.size, -1, 3), wts)
    ref_f = np.einsum("kmj,m->kj", s["f_b"].reshape(picks.size, -1, 3), wts)
    assert np.abs(dth[picks] - ref_w).max() < 1e-15
    assert np.abs(dv[picks] - ref_f).max() < 2e-15


def test_thermal_closed_form_solves_the_lag_equation():
    th = ThermalModel(chamber_t=np.array([0.0, 600.0, 1500.0, 3000.0]), chamber_T=np.array([20.0, 24.0, 25.0, 31.0]),
                      names=("a", "b", "c"), tau=np.array([900.0, 1800.0, 0.0]), offset=np.array([0.5, -0.2, 0.0]),
                      initial=np.array([20.1, 19.6, 0.0]))
    tq = np.linspace(0.0, 3200.0, 321)

    def f(t, y):
        u = th.chamber(np.array([t]))[0]
        return (u + th.offset[:2] - y) / th.tau[:2]

    sol = solve_ivp(f, (0.0, 3200.0), th.initial[:2], t_eval=tq, rtol=1e-11, atol=1e-11, max_step=10.0)
    T = th.temperature(tq)
    assert np.abs(T[:, :2] - sol.y.T).max() < 1e-7
    assert np.allclose(T[:, 2], th.chamber(tq))
    h = 1e-3
    rate_fd = (th.temperature(tq[1:-1] + h) - th.temperature(tq[1:-1] - h)) / (2 * h)
    assert np.abs(rate_fd[:, :2] - th.rate(tq[1:-1])[:, :2]).max() < 1e-8
    assert np.allclose(th.temperature(tq, [1, 0]), T[:, [1, 0]])


def test_handheld_kinematics_and_static_poses():
    rng = np.random.default_rng(4)
    m = HandheldMotion(100.0, rot_z(0.4))
    m.hold(2.0)
    m.turn(np.array([0.5, -1.2, 0.8]), 1.5, displacement_n=np.array([0.03, -0.02, 0.05]))
    m.hold(3.0)
    m.turn(rng.normal(size=3), 2.0)
    m.hold(1.0)
    t = np.linspace(1.9, m.duration - 0.5, 500)
    h = 1e-6
    k = m.kinematics(t)
    S = np.swapaxes(k.C_nb, 1, 2) @ (m.kinematics(t + h).C_nb - m.kinematics(t - h).C_nb) / (2 * h)
    assert np.abs(np.column_stack([S[:, 2, 1], S[:, 0, 2], S[:, 1, 0]]) - k.omega_nb_b).max() < 1e-7
    dv_fd = (m.kinematics(t + h).vel_n - m.kinematics(t - h).vel_n) / (2 * h)
    assert np.abs(dv_fd - k.acc_n).max() < 1e-6
    assert np.array_equal(m.kinematics(np.array([3.51])).C_nb[0], m.kinematics(np.array([6.49])).C_nb[0])
    assert not np.allclose(m.kinematics(np.array([3.49])).C_nb[0], m.kinematics(np.array([6.49])).C_nb[0])
    # a scenario: static samples feel gravity only
    se = _one("consumer-handheld", seed=2, noise=False, errors=False, hours=0.01)
    e = se.experiment
    assert e.table is None
    static = se.motion.is_static(e.t - 0.005, margin=0.01)
    fn = _level_specific_force(se)
    assert np.abs(fn[static] - [0, 0, e.gravity_mps2]).max() < 1e-7
    assert np.abs(fn[~static] - [0, 0, e.gravity_mps2]).max() > 1e-3  # the hand moves it


# ---------------------------------------------------------------------------
# truth: the files describe the data
# ---------------------------------------------------------------------------


def test_truth_explains_static_data_and_encoders():
    """Correcting static samples with the truth file's parameters gives gravity and the Earth rate."""
    se = _one("nav-subrange-short", seed=5, noise=False, curvature=False, hours=0.05)
    e, truth = se.experiment, se.truth
    layout = params.Layout(truth.effects)
    assert layout.names == se.layout.names  # no curvature: the truth is the whole model
    x = layout.from_dict(truth.values)
    assert np.all(x[layout.slice("mount")] != 0) and x[layout.index("time_lag.table")] > 0
    dt = 1.0 / e.rate_hz
    dT = e.sensor_temperatures() - truth.t_ref_degC
    f = correct(layout, x, "accel", e.dv / dt, dT=dT[:, 3:])
    w = correct(layout, x, "gyro", e.dtheta / dt, dT=dT[:, :3])
    # encoders: a reading stamped t shows the faceplate at t - time_lag.table
    tab = e.table
    lag = truth.values["time_lag.table"]
    assert np.abs(_rotation_angle(quat_to_dcm(tab.q_nf), se.motion.C_nf(tab.t - lag))).max() < 1e-12
    assert np.abs(_rotation_angle(quat_to_dcm(tab.q_nf), se.motion.C_nf(tab.t))).max() > 1e-4
    # static readings, through the nominal mounting and the truth mount, give C_nb
    C_fb = quat_to_dcm(tab.q_fb_nominal) @ exp_so3(x[layout.slice("mount")])
    k = np.searchsorted(e.t, tab.t[tab.valid])
    C_nb = quat_to_dcm(tab.q_nf[tab.valid]) @ C_fb
    assert _rotation_angle(C_nb, se.attitude(e.t[k])).max() < 1e-12
    f_n = np.einsum("nij,nj->ni", C_nb, f[k])
    assert np.abs(f_n - [0, 0, e.gravity_mps2]).max() < 1e-7
    w_n = np.einsum("nij,nj->ni", C_nb, w[k])
    assert np.abs(w_n - omega_ie_n(e.latitude_rad)).max() < 1e-11
    # without the correction the errors are plainly there
    assert np.abs(np.einsum("nij,nj->ni", C_nb, e.dv[k] / dt) - [0, 0, e.gravity_mps2]).max() > 1e-4


def test_truth_magnitudes_and_curves():
    sim = simulate("nav-campaign", rng=np.random.default_rng(9), hours=SHORT, noise=False)
    assert len(sim) == 6
    imu = sim.imu
    mags = {
        "gyro.bias": (0.01 * DH_TO_RS, 0.1 * DH_TO_RS), "gyro.misalignment": (10 * ARCSEC_TO_RAD, 60 * ARCSEC_TO_RAD),
        "accel.misalignment": (10 * ARCSEC_TO_RAD, 60 * ARCSEC_TO_RAD), "lever_arm": (0.05, 0.15),
        "mount": (60 * ARCSEC_TO_RAD, 300 * ARCSEC_TO_RAD), "time_lag.table": (0.002, 0.01),
    }
    for name, (lo, hi) in mags.items():
        v = np.abs(imu.constants[name]) if name in imu.constants else np.abs(imu.curves[name][0])
        assert np.all((lo <= v) & (v <= hi)), name
    runs = sim.run()
    t_refs = [se.truth.t_ref_degC for se in runs]
    assert np.all(np.diff(t_refs) > 5) and t_refs[0] < 0 < 40 < t_refs[-1]
    for se in runs:
        d = se.truth.t_ref_degC - imu.t_center
        c0, c1, c2 = imu.curves["gyro.bias"]
        v = np.array([se.truth.values[f"gyro.bias.{a}"] for a in "xyz"])
        s = np.array([se.truth.values[f"gyro.bias_tc.{a}"] for a in "xyz"])
        assert np.allclose(v, c0 + c1 * d + c2 * d * d, rtol=1e-12, atol=0)
        assert np.allclose(s, c1 + 2 * c2 * d, rtol=1e-12, atol=0)
        un = se.truth.extra["simulation"]["unmodelled"]
        assert [un[f"gyro.bias_tc2.{a}"] for a in "xyz"] == pytest.approx(c2.tolist())
        assert "gyro.bias_tc2" not in se.truth.effects
    # not linear over the campaign: the slope changes from the coldest to the hottest subrange
    s_cold = np.array([runs[0].truth.values[f"gyro.bias_tc.{a}"] for a in "xyz"])
    s_hot = np.array([runs[-1].truth.values[f"gyro.bias_tc.{a}"] for a in "xyz"])
    assert np.all(np.abs(s_hot - s_cold) > 0.0005 * DH_TO_RS)


def test_truth_file_round_trip(tmp_path):
    se = _one("nav-subrange-short", seed=3, hours=SHORT)
    path = tmp_path / se.truth_name
    io.write_result(se.truth, path)
    back = io.read_result(path)
    assert back.solver == "truth" and back.sigmas is None
    assert back.values == se.truth.values
    assert back.effects == se.truth.effects
    assert back.t_ref_degC == se.truth.t_ref_degC
    assert back.temperature_range_degC == se.truth.temperature_range_degC
    assert back.extra["simulation"]["unmodelled"] == se.truth.extra["simulation"]["unmodelled"]
    assert back.t_ref_degC == pytest.approx(se.experiment.default_t_ref(), abs=1e-12)


# ---------------------------------------------------------------------------
# randomness and noise
# ---------------------------------------------------------------------------


def _arrays(se):
    e = se.experiment
    return [e.t, e.dtheta, e.dv, e.temperature, e.table.t, e.table.q_nf, e.table.valid,
            np.array(list(se.truth.values.values()))]


def test_reproducible_bit_for_bit():
    a = _arrays(_one("nav-subrange-short", seed=21, hours=SHORT))
    b = _arrays(_one("nav-subrange-short", seed=21, hours=SHORT))
    c = _arrays(_one("nav-subrange-short", seed=22, hours=SHORT))
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    for i in (1, 2, 3, 5, 7):
        assert not np.array_equal(a[i], c[i])


def test_noise_density_and_independence():
    noisy = _one("nav-subrange-short", seed=8, hours=0.1)
    clean = _one("nav-subrange-short", seed=8, hours=0.1, noise=False)
    e, e0 = noisy.experiment, clean.experiment
    # noise switches nothing else: same programme, same IMU (the truth moves only with T_ref, which
    # the temperature noise shifts by micro-degrees)
    assert np.array_equal(e.table.t, e0.table.t) and np.array_equal(e.table.valid, e0.table.valid)
    assert abs(noisy.truth.t_ref_degC - clean.truth.t_ref_degC) < 1e-4
    assert np.allclose(list(noisy.truth.values.values()), list(clean.truth.values.values()), rtol=1e-5, atol=0)
    assert noisy.truth.extra["temperature_curves"] == clean.truth.extra["temperature_curves"]
    g = params.GRADES["navigation"]
    dt = 1.0 / e.rate_hz
    static = noisy.motion.is_static(e.t - 0.5 * dt, margin=dt)
    n_g = (e.dtheta - e0.dtheta)[static]
    n_a = (e.dv - e0.dv)[static]
    assert np.std(n_g, axis=0) == pytest.approx(np.full(3, g.gyro_noise * np.sqrt(dt)), rel=0.03)
    assert np.std(n_a, axis=0) == pytest.approx(np.full(3, g.accel_noise * np.sqrt(dt)), rel=0.03)
    assert np.abs(np.mean(n_g, axis=0)).max() < 4 * g.gyro_noise * np.sqrt(dt) / np.sqrt(n_g.shape[0])
    # white: neighbouring increments uncorrelated
    r = np.corrcoef(n_g[1:, 0], n_g[:-1, 0])[0, 1]
    assert abs(r) < 0.02
    # encoders: noise on the two axis angles
    ang = _rotation_angle(quat_to_dcm(e.table.q_nf), quat_to_dcm(e0.table.q_nf))
    assert np.sqrt(np.mean(ang**2)) == pytest.approx(np.sqrt(2) * g.encoder_noise, rel=0.05)
    # the noise-free data are not noisy
    assert np.array_equal(e0.temperature, clean.thermal.temperature(e0.t))


# ---------------------------------------------------------------------------
# scenarios, files, command line
# ---------------------------------------------------------------------------


def test_registry_has_every_effect():
    names = scenario_names()
    for required in ("nav-subrange", "nav-subrange-short", "nav-campaign", "consumer-handheld", "consumer-ferraris"):
        assert required in names
    for effect in effects.FURTHER_EFFECTS:
        assert f"effect-{effect}" in names


@pytest.mark.parametrize("name", [n for n in SCENARIOS if not n.startswith("effect-")])
def test_scenario_writes_valid_files(name, tmp_path):
    hours = {"consumer-handheld": 0.01, "consumer-ferraris": None}.get(name, SHORT)
    sim = simulate(name, rng=np.random.default_rng(1), hours=hours)
    written = write_simulation(sim, tmp_path)
    campaign = io.read_manifest(tmp_path / "campaign.toml")
    assert campaign.grade == sim.grade and len(campaign.experiments) == len(sim.plans)
    for w, ce in zip(written[:-1], campaign.experiments):
        exp = io.read_experiment(w["file"])
        truth = io.read_result(w["truth"])
        assert ce.file == w["file"].resolve()
        assert truth.source == w["file"].name
        assert truth.t_ref_degC == pytest.approx(exp.default_t_ref(), abs=1e-9)
        lo, hi = truth.temperature_range_degC
        T = exp.sensor_temperatures()
        assert lo == T.min() and hi == T.max()
        assert set(truth.effects) <= set(campaign.layout().names) | set(effects.FURTHER_EFFECTS)
        if name.startswith("consumer-"):
            assert exp.table is None and "lever_arm" not in truth.effects
            assert {"mount", "lever_arm", "time_lag.table"} == set(campaign.exclude)
        else:
            assert exp.table is not None and 0 < exp.table.valid.mean() < 1
    if name == "nav-campaign":
        assert [ce.file.name for ce in campaign.experiments][0] == "sub1_m10_0.h5"


@pytest.mark.parametrize("effect", effects.FURTHER_EFFECTS)
def test_effect_scenario_switches_its_effect_on(effect):
    on = _one(f"effect-{effect}", seed=6, hours=SHORT, noise=False)
    off = _one(f"effect-{effect}", seed=6, hours=SHORT, noise=False, effect_scale=0.0)
    assert effect in on.truth.effects
    spec = effects.EFFECTS[effect]
    v = np.array([on.truth.values[n] for n in spec.element_names()])
    assert np.all(v != 0)
    # everything else is the same IMU, so the difference in the data is the effect's
    common = [n for n in on.truth.values if not n.startswith(effect)]
    assert all(on.truth.values[n] == off.truth.values[n] for n in common)
    d_g = np.abs(on.experiment.dtheta - off.experiment.dtheta).max()
    d_a = np.abs(on.experiment.dv - off.experiment.dv).max()
    assert max(d_g, d_a) > 0
    if effect.startswith("gyro."):
        assert d_a == 0
    if effect.startswith("accel.") or effect == "time_lag.accel":
        assert d_g == 0


def test_cli_simulate(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["simulate", "nav-subrange-short", "--out", str(out), "--hours", "0.01", "--seed", "3"]) == 0
    text = capsys.readouterr().out
    assert "sub1_20_25.h5" in text and "truth" in text
    assert (out / "sub1_20_25.h5").is_file() and (out / "sub1_20_25.truth.json").is_file()
    assert (out / "campaign.toml").is_file()
    a = io.read_experiment(out / "sub1_20_25.h5")
    assert main(["simulate", "nav-subrange-short", "--out", str(tmp_path / "p"), "--hours", "0.01", "--seed", "3"]) == 0
    b = io.read_experiment(tmp_path / "p" / "sub1_20_25.h5")
    assert np.array_equal(a.dtheta, b.dtheta)
    capsys.readouterr()
    assert main(["simulate", "no-such-scenario", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "unknown scenario" in err and "nav-campaign" in err and "effect-damping.stiffness" in err
    assert main(["simulate", "--list"]) == 0
    assert "consumer-handheld" in capsys.readouterr().out
    assert main(["simulate", "nav-subrange", "--out", str(out), "--hours", "-1"]) == 2
    assert main(["simulate", "nav-subrange", "--out", str(out), "--effect", "gyro.nothing"]) == 2
    assert main(["simulate", "nav-subrange"]) == 2


def test_further_experiment_of_the_same_imu_and_its_refusal_without_a_table():
    from graph_calib.simulation import simulate as _simulate

    sim = _simulate("nav-campaign", rng=np.random.default_rng(2), hours=0.05, rate_hz=20.0)
    assert sim.temperature_range() == (-10.0, 50.0)
    se = sim.further_experiment(file_name="v.h5", seed=5, hours=0.05, start_degC=0.0, span_degC=30.0,
                                rate_hz=20.0, description="check")
    first = sim.plans[0].run()
    constant = [k for k in first.truth.values if k.startswith(("mount", "lever_arm", "gyro.misalignment"))]
    assert len(constant) == 12
    assert all(se.truth.values[k] == first.truth.values[k] for k in constant)   # the same IMU and bench
    assert se.experiment.n_samples == 3600 and se.file_name == "v.h5"
    assert not np.array_equal(se.experiment.dtheta[:100], first.experiment.dtheta[:100])   # its own noise
    hh = _simulate("consumer-handheld", rng=np.random.default_rng(2))
    with pytest.raises(ValueError, match="'consumer-handheld' has no turntable experiment to extend"):
        hh.further_experiment(file_name="v.h5", seed=5, hours=0.1, start_degC=0.0, span_degC=10.0)


@pytest.mark.parametrize("hours, words", [("0", "--hours must be a positive number, got 0.0"),
                                          ("nan", "--hours must be a positive number, got nan"),
                                          ("100000", "--hours must be at most 100 (a record of 100000 h is no bench's)")])
def test_simulate_refuses_a_length_no_bench_records(tmp_path, capsys, hours, words):
    """A record of 1e5 h ran until it was killed and left an empty folder."""
    from graph_calib.cli import main
    out = tmp_path / "s"
    assert main(["simulate", "nav-subrange-short", "--hours", hours, "--out", str(out)]) == 2
    assert words in capsys.readouterr().err
    assert not out.exists()
