"""The simulated noise cases of issue #21 the model had wrong: a ring-laser gyro's quantization, table readings
without noise, and the table noise identified (6-min nav-subrange-short, both solvers, variance components).

Measured (docs/model.md, "Noise from the record"): with 0.5 arcsec quantization, seeds 1-8, calibrated with the
simulator's draw RMS as the priors, the RMS normalised error over the elements that are not prior-dominated is
0.86-1.33 per seed, 1.07 pooled, every kind's chi2/redundancy 0.99-1.05 and every verdict passes (before the
quantization was modelled: time_lag.table 64 sigma off, the gravity kind's factor 4.9, the verdict failed).  On
the grade's priors the same records give 0.83 pooled: the grade's priors are wider than the simulator's draws.
"""

import numpy as np
import pytest

from graph_calib.calibrate import CalibrationOptions, build_problem, calibrate
from graph_calib.constants import ARCSEC_TO_RAD
from graph_calib.model import ModelOptions
from graph_calib.noise import identify_noise
from graph_calib.records.problem import noise_options
from graph_calib.simulation import simulate
from graph_calib.simulation.truth import draw_rms
from graph_calib.solvers.registry import DEFAULT_SOLVERS as SOLVERS


def _simulated(seed, **options):
    return simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=0.1, **options).run()[0]


def _z(result, truth):
    """(estimate - truth) / sigma of the elements that are not prior-dominated, by name."""
    skip = set(result.extra.get("prior_dominated", ()))
    return {n: (result.values[n] - truth.values[n]) / result.sigmas[n] for n in result.values if n not in skip}


def test_the_identified_gyro_density_is_split_into_white_noise_and_quantization():
    se = _simulated(2, gyro_quantization_arcsec=0.5)
    nz = se.truth.extra["simulation"]["noise"]
    o = noise_options(identify_noise(se.experiment, keyframe_s=1.0), ModelOptions())
    assert o.noise_source["gyro"] == "identified"
    assert abs(o.gyro_quantization / (0.5 * ARCSEC_TO_RAD) - 1) < 0.05
    # the rotation factors get the white rate noise alone (the keyframe attitudes absorb Q): 0.22 of the
    # keyframe density sqrt(N^2 + 2 Q^2) here
    assert abs(o.gyro_noise / nz["gyro_noise"] - 1) < 0.25
    # without quantization the white noise is the keyframe density, and no quantization worth the name
    clean = noise_options(identify_noise(_simulated(2).experiment, keyframe_s=1.0), ModelOptions())
    assert clean.gyro_quantization < 0.01 * ARCSEC_TO_RAD
    assert abs(clean.gyro_noise / nz["gyro_noise"] - 1) < 0.05


@pytest.fixture(scope="module")
def quantized_runs():
    """Seeds 1-8 with 0.5 arcsec quantization, calibrated with the simulator's draw RMS as the priors (so that the
    truth has the priors' second moments and the normalised errors are unit-variance when the sigmas hold):
    ``(simulated experiment, run)`` each."""
    out = []
    for seed in range(1, 9):
        se = _simulated(seed, gyro_quantization_arcsec=0.5)
        options = CalibrationOptions(t_ref_degC=se.truth.t_ref_degC,
                                     model=ModelOptions(prior_sigma=draw_rms("navigation")))
        run = calibrate(se.experiment, options=options)
        out.append((se, run))
    return out


@pytest.mark.montecarlo
@pytest.mark.parametrize("solver", SOLVERS)
def test_quantized_records_calibrate_with_sigmas_that_hold(quantized_runs, solver):
    zs = []
    for se, run in quantized_runs:
        res = run.results[solver]
        z = _z(res, se.truth)
        zs.extend(z.values())
        # the readings are all taken at rest: no lag to estimate from the gyro's scatter (it was, 64 sigma off)
        assert "time_lag.table" not in res.values
        for n in ("lever_arm.y", "lever_arm.z"):
            assert abs(z[n]) < 3.0, (n, z[n])
        for kind in ("rotation", "gravity", "encoder"):
            k = res.residuals["kinds"][kind]
            assert 0.85 <= k["chi2_per_redundancy"] <= 1.15, (kind, k)
            assert 0.25 < k["variance_factor"] < 4.0, (kind, k)
        assert res.extra["noise"]["gyro_quantization_rad"] == pytest.approx(0.5 * ARCSEC_TO_RAD, rel=0.05)
    rms = float(np.sqrt(np.mean(np.square(zs))))
    assert 0.85 <= rms <= 1.15, rms
    assert all(run.verdict.passed for _, run in quantized_runs), [run.verdict.text() for _, run in quantized_runs]


@pytest.mark.slow
def test_table_readings_without_noise_fail_the_verdict_in_words():
    se = _simulated(1, encoder_noise_arcsec=0.0)
    run = calibrate(se.experiment, options=CalibrationOptions(t_ref_degC=se.truth.t_ref_degC))
    v = run.verdict
    assert not v.passed and v.text().startswith("verdict: FAIL")
    assert "RESIDUALS INCONSISTENT WITH THE NOISE MODEL: encoder" in v.text()
    (words,) = {p.split(": ", 1)[1] for p in v.problems}     # the same for both solvers, and nothing else
    assert "the table readings do not scatter" in words and "not reliable" in words
    assert "encoder_noise" in words
    res = run.results["factor-graph"]
    assert res.extra["noise"]["source"]["encoder"] == "grade"
    assert res.extra["noise"]["identified"]["encoder"]["below_rad"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("arcsec", [0.5, 2.0, 5.0])
def test_table_noise_identified_within_a_fifth(arcsec):
    for seed in (1, 2):
        se = _simulated(seed, encoder_noise_arcsec=arcsec)
        p = build_problem(se.experiment, options=CalibrationOptions(t_ref_degC=se.truth.t_ref_degC))
        assert p.model.options.noise_source["encoder"] == "identified"
        assert abs(p.model.encoder_noise / (arcsec * ARCSEC_TO_RAD) - 1) < 0.2


@pytest.mark.slow
def test_the_pessimistic_elements_of_the_clean_case_are_the_priors_not_the_noise():
    """Issue #21's clean-case mount and accelerometer scale sigmas, 2-3 times the Monte Carlo's errors, are the
    prior's share along the directions the 6-min record does not determine: the linear sandwich with the
    simulator's truth spread (narrower than the grade's priors) predicts that ratio, and with the priors set to
    that spread the ratio is 1 (docs/model.md, "Noise from the record")."""
    import importlib
    import sys
    from pathlib import Path

    scripts = str(Path(__file__).resolve().parents[2] / "scripts")
    sys.path.insert(0, scripts)
    try:
        sandwich = importlib.import_module("prior_spread_sandwich")
    finally:
        sys.path.remove(scripts)
    se = _simulated(50_000)                   # seed 0 of scripts/noise_monte_carlo.py
    names, ratio, dominated = sandwich.prior_spread_ratio(se)
    r = dict(zip(names, ratio))
    dom = {n for n, d in zip(names, dominated) if d > 0.7}
    assert {"accel.scale.x", "accel.misalignment.yx", "accel.misalignment.zx"} <= dom
    # the Monte Carlo's pessimistic elements (60 seeds: mount 0.38-0.50, accel.scale.z 0.36), predicted without noise
    for name in ("mount.x", "mount.y", "accel.scale.z", "accel.misalignment.zy"):
        assert name not in dom and r[name] < 0.6, (name, r[name])
    # elements the priors do not reach keep their sigma
    for name in ("accel.bias_tc.x", "accel.scale_tc.y"):
        assert abs(r[name] - 1.0) < 0.02, (name, r[name])
