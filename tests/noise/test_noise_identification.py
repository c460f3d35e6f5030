"""The noise package: Allan deviation against allantools, the IEEE terms, every rest, densities from simulated records."""

import numpy as np
import pytest

from graph_calib.constants import ARCSEC_TO_RAD
from graph_calib.noise import find_rests, identify_noise, overlapping_allan
from graph_calib.noise.identify import nonnegative_least_squares, sensor_noise
from graph_calib.records.experiment import Experiment
from graph_calib.simulation.scenarios import simulate


def test_overlapping_allan_agrees_with_allantools():
    allantools = pytest.importorskip("allantools")
    rng = np.random.default_rng(3)
    tau0 = 0.01
    d = 1e-5 * rng.standard_normal((20000, 1)) + 1e-7 * np.cumsum(rng.standard_normal((20000, 1)), axis=0)
    m = np.array([1, 2, 5, 10, 50, 200, 1000])
    ours = overlapping_allan(d, [(0, d.shape[0])], tau0=tau0, m=m)
    taus, adev, _, _ = allantools.oadev(d[:, 0] / tau0, rate=1.0 / tau0, data_type="freq", taus=m * tau0)
    np.testing.assert_allclose(ours.tau, taus)
    np.testing.assert_allclose(ours.adev[:, 0], adev, rtol=1e-9)


def test_nonnegative_least_squares_is_scipys_nnls():
    from scipy.optimize import nnls

    rng = np.random.default_rng(5)
    clipped = 0
    for _ in range(300):
        A = rng.standard_normal((int(rng.integers(5, 40)), 5)) * 10.0 ** rng.uniform(-2, 2, size=5)
        b = rng.standard_normal(A.shape[0])
        ours, theirs = nonnegative_least_squares(A, b), nnls(A, b)[0]
        np.testing.assert_array_equal(ours > 0, theirs > 0)
        np.testing.assert_allclose(ours, theirs, rtol=1e-8, atol=1e-12 * np.max(np.abs(theirs), initial=1.0))
        clipped += int(np.any(theirs == 0) and np.any(theirs > 0))
    assert clipped > 50                          # the constraint binds in many of them
    assert not np.any(nonnegative_least_squares(np.eye(3), -np.ones(3)))    # nothing positive fits: zero


def test_allan_pools_rests_and_never_spans_the_motion_between():
    rng = np.random.default_rng(4)
    d = 1e-4 * rng.standard_normal((3000, 3))
    d[1000:2000] += 0.5                          # "motion": a large offset between two rests
    one = overlapping_allan(d, [(0, 1000), (2000, 3000)], tau0=0.01, m=[1, 4, 16])
    assert np.all(np.abs(one.adev / (1e-4 / 0.01 / np.sqrt(one.tau[:, None] / 0.01)) - 1) < 0.15)
    assert one.n_terms[0] == 2 * (1000 - 1)      # 1001 phase points per rest, none across the motion


def _white_record(n, *, gyro, accel, q_gyro=0.0, seed=0, rate_hz=100.0):
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    dth = gyro * np.sqrt(dt) * rng.standard_normal((n, 3))
    if q_gyro:
        dth += np.diff(q_gyro * rng.standard_normal((n + 1, 3)), axis=0)
    dv = accel * np.sqrt(dt) * rng.standard_normal((n, 3)) + np.array([0.0, 0.0, 9.8]) * dt
    return dth, dv


def test_white_noise_density_and_quantization_are_told_apart():
    tau0, T = 0.01, 1.0
    N, Q = 3e-6, 0.5 * ARCSEC_TO_RAD
    dth, _ = _white_record(60000, gyro=N, accel=1e-4, q_gyro=Q)
    sn = sensor_noise(dth, [(0, 60000)], tau0=tau0, keyframe_s=T, sensor="gyro")
    assert "quantization" in sn.channels[0].supported
    assert abs(sn.term("quantization") / Q - 1) < 0.1
    assert abs(sn.density / np.sqrt(N**2 + 2 * Q**2 / T) - 1) < 0.1
    # the per-sample scatter read as white rate noise would be sqrt(2/tau0) Q: far above
    assert np.sqrt(2 / tau0) * Q > 5 * sn.density


def test_too_short_a_rest_identifies_nothing():
    dth, dv = _white_record(100, gyro=1e-5, accel=1e-4)
    assert sensor_noise(dth, [(0, 100)], tau0=0.01, keyframe_s=1.0, sensor="gyro") is None


def _experiment(dth, dv, rate_hz=100.0):
    n = dth.shape[0]
    return Experiment(t=np.arange(1, n + 1) / rate_hz, dtheta=dth, dv=dv, temperature=np.full((n, 1), 20.0),
                      temperature_names=("t",), temperature_map=np.zeros(6, dtype=int), rate_hz=rate_hz,
                      latitude_rad=1.0, gravity_mps2=9.8, imu_id="x", description="", table=None, source="")


def test_every_rest_found_when_the_record_starts_in_motion():
    dth, dv = _white_record(9000, gyro=1e-5, accel=1e-3, seed=5)
    t = np.arange(9000) / 100.0
    moving = (t < 15.0) | ((t > 40.0) & (t < 50.0))
    dv[moving] += 0.05 * np.sin(2 * np.pi * 1.3 * t[moving])[:, None] * 0.01
    dth[moving] += 0.2 * np.cos(2 * np.pi * 0.7 * t[moving])[:, None] * 0.01
    rests = find_rests(_experiment(dth, dv))
    assert rests.shape[0] == 2
    assert 14.0 < rests[0, 0] / 100.0 < 16.5 and rests[1, 1] == 9000
    ni = identify_noise(_experiment(dth, dv), keyframe_s=1.0)
    assert abs(ni.gyro.density / 1e-5 - 1) < 0.1 and abs(ni.accel.density / 1e-3 - 1) < 0.1


@pytest.mark.parametrize("options, gyro_q", [({"noise_factor": 0.3}, 0.0), ({"noise_factor": 3.0}, 0.0),
                                              ({"gyro_quantization_arcsec": 0.5}, 0.5 * ARCSEC_TO_RAD),
                                              ({"start_in_motion": True}, 0.0)])
def test_simulated_turntable_densities_within_ten_percent(options, gyro_q):
    se = simulate("nav-subrange-short", rng=np.random.default_rng(1), hours=0.15, **options).run()[0]
    nz = se.truth.extra["simulation"]["noise"]
    ni = identify_noise(se.experiment, keyframe_s=1.0)
    assert abs(ni.gyro.density / np.sqrt(nz["gyro_noise"] ** 2 + 2 * gyro_q**2) - 1) < 0.1
    assert abs(ni.accel.density / nz["accel_noise"] - 1) < 0.1
    # the white rate noise the rotation factors use, also where the quantization dominates each sample (from the
    # rests' spectra there: graph_calib.noise.spectral)
    assert abs(ni.gyro.term("white") / nz["gyro_noise"] - 1) < 0.1
    assert {c.estimator for c in ni.gyro.channels} == ({"whittle"} if gyro_q else {"allan"})
    if options.get("start_in_motion"):
        assert se.experiment.n_samples < 0.15 * 3600 * 100
