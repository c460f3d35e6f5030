"""The table readings' noise model (graph_calib.model.encoder_noise) and the encoder factor's whitening.

- a static dwell's scatter of two-axis encoder noise gives the declared sigma about the two axes and
  the floor about the direction perpendicular to both; readings in motion and short runs keep the
  declared isotropic noise exactly;
- the encoder factor, turned into the principal axes, has unit-variance whitened components on the
  two read axes at the truth, and its Jacobians still match finite differences;
- ``predict`` on a bench program takes the declared noise about the program's two axes, and agrees
  with ``predict`` on a noisy simulated run of the same program (which sees the scatter).
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from graph_calib.calibrate import CalibrationOptions, build_problem
from graph_calib.constants import omega_ie_n
from graph_calib.records.experiment import Experiment, Table
from graph_calib.model import CalibrationModel, ModelOptions
from graph_calib.model.encoder_noise import FLOOR_FRACTION, MIN_DWELL_READINGS, dwell_scatter, noise_frame
from graph_calib.design.prediction import predict
from graph_calib.navigation.rotations import dcm_to_quat, exp_so3
from graph_calib.simulation.program import nominal_experiment, program_simulation, read_program

from _synthetic import assert_calibration_jacobian_matches_fd

SIGMA = 1e-5                       # rad, the encoder noise of the synthetic readings
EPS = 1e-6
PROGRAM = Path(__file__).resolve().parents[2] / "data" / "programs" / "nav-subrange-short.toml"


def _two_axis_readings(rng, *, n, beta, C_nf0=np.eye(3)):
    """``n`` readings of a faceplate at rest, noise ``SIGMA`` on the outer and inner angles at ``beta``."""
    outer = np.array([np.cos(beta), -np.sin(beta), 0.0])
    inner = np.array([0.0, 0.0, 1.0])
    e = SIGMA * (rng.standard_normal((n, 1)) * outer + rng.standard_normal((n, 1)) * inner)
    return C_nf0 @ exp_so3(e), np.cross(outer, inner)


def test_dwell_scatter_finds_the_two_axes_and_floors_the_third():
    rng = np.random.default_rng(3)
    C1, n1 = _two_axis_readings(rng, n=400, beta=0.3)
    C2, n2 = _two_axis_readings(rng, n=400, beta=1.2, C_nf0=exp_so3(np.array([0.5, -0.2, 1.0])))
    C_nf = np.concatenate([C1, C2])
    t = np.concatenate([np.arange(400) * 0.1, 100.0 + np.arange(400) * 0.1])   # a gap between the dwells
    sc = dwell_scatter(t, C_nf, np.ones(800, bool), C_fb=np.eye(3))
    assert sc.n_dwells == 2 and np.all(sc.n == 400)
    fr = noise_frame(sc, None, encoder_noise=2 * SIGMA)
    assert np.all(fr.rotated) and np.all(fr.source == 1)
    for rows, n_perp in ((slice(0, 400), n1), (slice(400, 800), n2)):
        U, var, fl = fr.U[rows][0], fr.var[rows][0], fr.floored[rows][0]
        assert fl.sum() == 1                                     # one direction is read without noise
        np.testing.assert_allclose(var[fl], (FLOOR_FRACTION * 2 * SIGMA) ** 2)
        assert abs(U[:, fl][:, 0] @ n_perp) > 0.999              # ... and it is the one perpendicular to both axes
        # the two read axes: their scatter, within its sampling error (400 readings: ~7 % in variance)
        np.testing.assert_allclose(var[~fl], SIGMA**2, rtol=0.2)
        np.testing.assert_allclose(U.T @ U, np.eye(3), atol=1e-12)
        assert np.all(np.diag(U) > 0) and np.argmax(np.abs(U[:, 2])) == 2     # ordered nearest the body axes


def test_a_dwell_without_scatter_keeps_the_declared_noise():
    """Identical readings (noiseless, or quantised coarser than the noise) show nothing about the noise."""
    C = np.broadcast_to(exp_so3(np.array([0.1, 0.2, 0.3])), (100, 3, 3)).copy()
    sc = dwell_scatter(np.arange(100) * 0.1, C, np.ones(100, bool), C_fb=np.eye(3))
    assert sc.n_dwells == 1
    fr = noise_frame(sc, None, encoder_noise=2 * SIGMA)
    assert np.all(fr.source == 3) and np.all(fr.var == (2 * SIGMA) ** 2) and not np.any(fr.rotated)


def test_readings_in_motion_and_short_runs_keep_the_declared_noise():
    rng = np.random.default_rng(4)
    C, _ = _two_axis_readings(rng, n=200, beta=0.0)
    at_rest = np.ones(200, bool)
    at_rest[50] = False                                   # a reading in motion splits the run
    at_rest[150:] = False                                 # the last 50 move
    t = np.arange(200) * 0.1
    t[100:] += 5.0                                        # a gap: 51..99 and 100..149 are runs of their own
    sc = dwell_scatter(t, C, at_rest, C_fb=np.eye(3))
    assert sc.n_dwells == 3 and np.all(sc.n[:50] == 50) and np.all(sc.n[51:100] == 49)
    assert np.all(sc.n[100:150] == 50) and np.all(sc.n[150:] == 0) and sc.n[50] == 0
    short = dwell_scatter(t[:MIN_DWELL_READINGS - 1], C[:MIN_DWELL_READINGS - 1],
                          np.ones(MIN_DWELL_READINGS - 1, bool), C_fb=np.eye(3))
    assert short.n_dwells == 0
    fr = noise_frame(sc, None, encoder_noise=2 * SIGMA)
    off = sc.n == 0
    assert np.all(fr.source[off] == 3) and not np.any(fr.rotated[off])
    assert np.array_equal(fr.U[off], np.broadcast_to(np.eye(3), (off.sum(), 3, 3)))
    assert np.all(fr.var[off] == (2 * SIGMA) ** 2)


def _static_experiment(rng, *, n_dwells=3, dwell_s=30.0, rate_hz=100.0, gyro_noise=0.0):
    """A unit at rest on the faceplate in ``n_dwells`` poses (no motion between them: a jump, for the
    factor only), gyros reading the Earth rate, readings at 10 Hz with two-axis noise."""
    betas = np.linspace(0.2, 2.5, n_dwells)
    poses = [exp_so3(np.array([0.3 * i, 0.2, b])) for i, b in enumerate(betas)]
    lat = 0.97
    w_ie = omega_ie_n(lat)
    n_per = int(dwell_s * rate_hz)
    t = np.arange(1, n_dwells * n_per + 1) / rate_hz
    C_of_sample = np.repeat(np.array(poses), n_per, axis=0)
    w_b = np.einsum("kji,j->ki", C_of_sample, w_ie)
    g_b = np.einsum("kji,j->ki", C_of_sample, np.array([0.0, 0.0, 9.8155]))
    dtheta = w_b / rate_hz + gyro_noise * np.sqrt(1.0 / rate_hz) * rng.standard_normal(w_b.shape)
    tt = np.arange(1, int(t[-1] * 10)) / 10.0
    which = np.minimum((tt * rate_hz).astype(int) // n_per, n_dwells - 1)
    # readings valid in the dwells only, 1 s clear of each change of pose (as a bench marks them)
    phase = tt - which * dwell_s
    keep = (phase > 1.0) & (phase < dwell_s - 1.0)
    tt, which = tt[keep], which[keep]
    C_nf = np.empty((tt.size, 3, 3))
    perp = np.empty((tt.size, 3))
    for d in range(n_dwells):
        m = which == d
        C_nf[m], perp[m] = _two_axis_readings(rng, n=int(m.sum()), beta=betas[d], C_nf0=poses[d])
    table = Table(t=tt, q_nf=dcm_to_quat(C_nf), valid=np.ones(tt.size, bool))
    exp = Experiment(t=t, dtheta=dtheta, dv=g_b / rate_hz, temperature=np.full((t.size, 1), 25.0),
                     temperature_names=("T",), temperature_map=np.zeros(6, dtype=int), rate_hz=rate_hz,
                     latitude_rad=lat, gravity_mps2=9.8155, imu_id="static", table=table, source="static")
    return exp, np.array(poses), which, perp


def test_encoder_factor_whitens_two_axis_noise_to_unit_variance():
    rng = np.random.default_rng(5)
    exp, poses, _, _ = _static_experiment(rng)
    model = CalibrationModel(exp, options=ModelOptions(encoder_noise=2 * SIGMA))
    x = model.layout.zeros()
    pre = model.preintegrate(x)
    R = poses[np.minimum(np.searchsorted(np.arange(3) * 30.0, model.t_key, side="right") - 1, 2)]
    res = model.encoder_factors(R, pre, x)
    fr = model.record.encoder_noise_frame(2 * SIGMA)
    assert np.all(fr.rotated) and np.all(fr.floored.sum(axis=1) == 1)
    assert model.record.reading_scatter.n_dwells == 3
    w = res.whitened()
    read = ~fr.floored
    rms_read = np.sqrt(np.mean(w[read] ** 2))
    assert 0.95 < rms_read < 1.05, rms_read
    # the direction no encoder reads has (nearly) no noise: far below its floored sigma
    assert np.sqrt(np.mean(w[~read] ** 2)) < 0.05
    # the same readings whitened isotropically with the declared noise (the former model) overstate it
    rms_iso = np.sqrt(np.mean((res.r / (2 * SIGMA)) ** 2))
    assert rms_iso < 0.45


def test_rotated_encoder_factor_jacobians_match_fd():
    rng = np.random.default_rng(6)
    exp, poses, _, _ = _static_experiment(rng, n_dwells=2, dwell_s=10.0)
    model = CalibrationModel(exp, options=ModelOptions(encoder_noise=2 * SIGMA, keyframe_s=0.5))
    assert np.all(model.record.encoder_noise_frame(2 * SIGMA).rotated)
    x = rng.normal(size=model.layout.size) * 1e-4
    pre = model.preintegrate(x)
    R = model.propagate(poses[0], pre, x) @ exp_so3(rng.normal(size=(model.n_keyframes + 1, 3)) * 1e-3)
    res = model.encoder_factors(R, pre, x)
    assert_calibration_jacobian_matches_fd(model, model.encoder_factors, R, x, H_x=res.H_x, eps=EPS, rtol=1e-5,
                                           atol=1e-9)
    for a in range(3):
        d = np.zeros(3)
        d[a] = EPS
        fd = (model.encoder_factors(R @ exp_so3(d), pre, x).r - model.encoder_factors(R @ exp_so3(-d), pre, x).r) / (2 * EPS)
        np.testing.assert_allclose(res.H_R[:, :, a], fd, atol=1e-7 * (1 + np.abs(fd).max()))


@pytest.fixture(scope="module")
def program_predictions():
    program = read_program(PROGRAM)
    nominal = nominal_experiment(program)
    noisy = program_simulation(program, rng=np.random.default_rng(11), curvature=False).run()[0].experiment
    out = {}
    for name, exp in (("program", nominal), ("noisy run", noisy),
                      ("program, no axes", replace(nominal, table=replace(nominal.table, axes_f=None)))):
        problem = build_problem(exp, options=CalibrationOptions(model=ModelOptions(grade="navigation")))
        out[name] = (problem, predict(problem).sigmas())
    return nominal, out


@pytest.mark.slow
def test_program_prediction_takes_the_noise_about_the_programs_axes(program_predictions):
    nominal, out = program_predictions
    axes = nominal.table.axes_f
    assert axes.shape == (nominal.table.t.size, 2, 3)
    np.testing.assert_allclose(np.linalg.norm(axes, axis=2), 1.0)
    np.testing.assert_allclose(np.einsum("mi,mi->m", axes[:, 0], axes[:, 1]), 0.0, atol=1e-15)
    fr = out["program"][0].model.record.encoder_noise_frame(out["program"][0].model.encoder_noise)
    assert np.mean(fr.source == 2) > 0.5 and np.all(fr.floored[fr.source == 2].sum(axis=1) == 1)
    # without the axes the noiseless readings show no scatter in any direction: that says nothing about
    # the noise, so the declared noise stands (isotropic, the former model) and the mount is predicted worse
    fr_iso = out["program, no axes"][0].model.record.encoder_noise_frame(out["program"][0].model.encoder_noise)
    assert np.all(fr_iso.source == 3) and not np.any(fr_iso.rotated)
    assert out["program, no axes"][1]["mount.y"] > 1.15 * out["program"][1]["mount.y"]
    # the program's prediction is what a noisy run of it predicts from its dwells' scatter (within the
    # scatter's sampling error and the run's own truth), on every element
    prog, run = out["program"][1], out["noisy run"][1]
    ratio = np.array([prog[n] / run[n] for n in prog])
    assert np.all(np.abs(ratio - 1.0) < 0.05), (ratio.min(), ratio.max())
