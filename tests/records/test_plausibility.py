"""Records whose gyro increments cannot be in radians are refused before any solver runs (graph_calib.records.plausibility).

The turn rule (gyro turns against the encoders') on a simulated turntable record, the static rule (static
rates against the loosest grade's bias) on a simulated hand-held one and on the measured sessions, and the
command line: exit 2, one line, nothing written.
"""

import re
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from graph_calib import constants as c
from graph_calib import io
from graph_calib.errors import InputError
from graph_calib.records.plausibility import check_record, static_rate_bound, turn_ratio, turns
from graph_calib.records.problem import build_problem
from graph_calib.simulation import simulate

ROOT = Path(__file__).resolve().parents[2]
DEG_FOR_RAD = 180.0 / np.pi


@pytest.fixture(scope="module")
def table_record():
    """The brief's record: nav-subrange-short, seed 1, 0.05 h (four 90-deg turns between static positions)."""
    return simulate("nav-subrange-short", rng=np.random.default_rng(1), hours=0.05).run()[0].experiment


@pytest.fixture(scope="module")
def handheld_record():
    return simulate("consumer-handheld", rng=np.random.default_rng(1)).run()[0].experiment


def _scaled(exp, factor):
    return replace(exp, dtheta=exp.dtheta * factor)


# --------------------------------------------------------------------------- the turn rule (a table)


def test_a_right_table_record_passes_with_every_turn_near_one(table_record):
    theta_e, ratio = turns(table_record)
    big = theta_e > np.radians(45.0)
    assert big.sum() >= 3
    assert np.allclose(ratio[big], 1.0, atol=0.01)
    assert turn_ratio(table_record) == pytest.approx(1.0, abs=0.01)
    check_record(table_record)
    build_problem(table_record)     # the single place calibrate, diagnose and campaign go through


def test_degrees_for_radians_on_a_table_is_refused_within_seconds_naming_the_cause(table_record):
    bad = _scaled(table_record, DEG_FOR_RAD)
    io.validate_experiment(bad, path="bad.h5")        # the reader's rate bound (35 rad/s) does not see it
    t0 = time.perf_counter()
    with pytest.raises(InputError) as err:
        build_problem(bad)
    assert time.perf_counter() - t0 < 30.0
    msg = str(err.value)
    assert "/imu/dtheta" in msg and "57.3 times" in msg and "degrees written for radians" in msg
    assert "\n" not in msg


@pytest.mark.parametrize("factor, cause", [
    (np.pi / 180.0, "rad/s imported as deg/s"),
    (100.0, "rates (rad/s) written for increments"),          # rate_hz = 100
    (3.0, "wrong units, or increments made with a wrong sample rate"),
    (0.3, "wrong units, or increments made with a wrong sample rate"),
])
def test_other_ratios_are_refused_with_their_likely_cause(table_record, factor, cause):
    with pytest.raises(InputError, match=re.escape(cause)):
        check_record(_scaled(table_record, factor))


@pytest.mark.parametrize("factor", [0.6, 0.97, 1.05, 1.8])
def test_scale_errors_inside_the_band_pass(table_record, factor):
    check_record(_scaled(table_record, factor))


def test_a_consumer_bias_and_scale_error_on_the_table_pass(table_record):
    """2 deg/s of bias and 5 % of scale error (consumer grade) leave the ratio near 1."""
    e = table_record
    bias = np.radians([2.0, -1.5, 1.0])
    check_record(replace(e, dtheta=1.05 * e.dtheta + bias * e.dt[:, None]))
    assert turn_ratio(replace(e, dtheta=1.05 * e.dtheta + bias * e.dt[:, None])) == pytest.approx(1.05, abs=0.05)


def test_dense_valid_readings_and_full_turns_are_judged_too():
    """Every reading valid (10 Hz, turns of a few degrees) and a longer record with full turns (encoder
    angle near zero, left out): right passes, degrees are refused."""
    for kw in ({"hours": 0.05, "table_valid": "all"}, {"hours": 0.2}):
        exp = simulate("nav-subrange-short", rng=np.random.default_rng(2), **kw).run()[0].experiment
        check_record(exp)
        with pytest.raises(InputError, match="degrees written for radians"):
            check_record(_scaled(exp, DEG_FOR_RAD))


def test_no_turn_is_counted_across_a_segment_boundary(table_record):
    theta_e, _ = turns(table_record)
    k = int(np.flatnonzero(theta_e > np.radians(45.0))[1])          # the second 90-deg turn, between two readings
    valid_t = table_record.table.t[table_record.table.valid]
    cut = int(np.searchsorted(table_record.t, 0.5 * (valid_t[k] + valid_t[k + 1])))
    segment = (np.arange(table_record.n_samples) >= cut).astype(np.int32)
    theta_cut, _ = turns(replace(table_record, segment=segment))
    assert theta_cut.size == theta_e.size - 1
    assert (theta_cut > np.radians(45.0)).sum() == (theta_e > np.radians(45.0)).sum() - 1


def test_a_table_without_valid_readings_leaves_the_static_rule(table_record):
    tab = replace(table_record.table, valid=np.zeros_like(table_record.table.valid))
    assert turn_ratio(replace(table_record, table=tab)) is None
    check_record(replace(table_record, table=tab))


# --------------------------------------------------------------------------- the static rule (no table)


def test_the_static_bound_is_the_loosest_grades_whatever_the_grade_asked_for():
    bound, name = static_rate_bound()
    assert name == "consumer"
    assert bound == pytest.approx(20 * 2.0 * c.DEG_TO_RAD + c.OMEGA_E)


def test_a_hand_held_consumer_record_passes_even_as_navigation_grade(handheld_record):
    from graph_calib.model import ModelOptions
    from graph_calib.options import CalibrationOptions

    assert handheld_record.table is None
    check_record(handheld_record)
    build_problem(handheld_record, options=CalibrationOptions(model=ModelOptions(grade="navigation")))


def test_a_turn_about_the_vertical_at_a_constant_rate_is_not_taken_for_rest(experiment_factory):
    """Quiet accelerometers while turning about the vertical at 100 deg/s: not a static interval for the
    rule (the rate differs from the first seconds'), with or without the table."""
    exp = experiment_factory(n=3000, rate_dps=100.0)
    check_record(exp)
    check_record(replace(exp, table=None))
    build_problem(exp)


def test_a_hand_held_record_in_degrees_is_refused_naming_the_grade(handheld_record):
    """The simulated consumer unit's bias (about 0.5 to 2 deg/s) written in degrees."""
    bias = np.radians([1.5, -1.0, 0.8])                 # a consumer bias, so the test does not hang on the draw
    e = replace(handheld_record, dtheta=handheld_record.dtheta + bias * handheld_record.dt[:, None])
    check_record(e)
    with pytest.raises(InputError) as err:
        check_record(_scaled(e, DEG_FOR_RAD))
    msg = str(err.value)
    assert "/imu/dtheta" in msg and "static interval" in msg and "consumer grade" in msg
    assert "degrees written for radians" in msg


def test_the_measured_sessions_pass_and_are_refused_in_degrees(real_data):
    from graph_calib import importers

    folder = real_data / "imu_tk_xsens"
    xs = importers.import_xsens(folder / "xsens_acc.mat", folder / "xsens_gyro.mat")
    mpu = importers.import_mpu6050(real_data / "mpu6050_uncuyo" / "example_data_calibration.csv")
    for exp in (xs, mpu):
        check_record(exp)
        with pytest.raises(InputError, match="degrees written for radians"):
            check_record(_scaled(exp, DEG_FOR_RAD))


def test_specific_force_in_g_is_the_readers_to_refuse(table_record):
    """Not duplicated here: rule 24 of docs/data-format.md (median |f| within 0.5..2 x gravity)."""
    bad = replace(table_record, dv=table_record.dv / table_record.gravity_mps2)
    with pytest.raises(InputError, match="g units"):
        io.validate_experiment(bad, path="bad.h5")


# --------------------------------------------------------------------------- the command line


def test_calibrate_on_degrees_exits_2_with_one_line_and_writes_nothing(table_record, tmp_path):
    bad = tmp_path / "BAD.h5"
    io.write_experiment(_scaled(table_record, DEG_FOR_RAD), bad)
    out = tmp_path / "D"
    out.mkdir()
    proc = subprocess.run([sys.executable, "-m", "graph_calib.cli", "calibrate", str(bad), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "BAD.h5" in lines[0] and "/imu/dtheta" in lines[0] and "degrees written for radians" in lines[0]
    assert "Traceback" not in proc.stderr
    assert "sqrt-kf" not in proc.stdout and "wrote" not in proc.stdout     # (the chosen grade may be printed)
    assert list(out.iterdir()) == []


# --------------------------------------------------------------------------- the tilt rule (no table)


def test_a_right_hand_held_record_has_tilt_ratio_near_one(handheld_record):
    from graph_calib.records.plausibility import tilt_ratio

    ratio, n, typical = tilt_ratio(handheld_record)
    assert n >= 5 and typical > 0.5 and abs(ratio - 1.0) < 0.05, (ratio, n, typical)


@pytest.mark.parametrize("factor, cause", [
    (c.DEG_TO_RAD, "radians taken for degrees and converted again (rad/s imported as deg/s: --gyro-units)?"),
    (0.2, "wrong units, or increments made with a wrong sample rate?"),
])
def test_a_hand_held_record_whose_gyros_turn_too_little_is_refused(handheld_record, factor, cause):
    """rad/s imported as deg/s leaves every static rate under the static rule's bound: the gyros' turns between the
    rests, against gravity's, tell (a lab user got a calibration blaming four missing effects instead)."""
    with pytest.raises(InputError, match=r"/imu/dtheta: the gyros turn gravity's direction ([0-9.e-]+) times as far "
                                         r"as the accelerometers see it turn between rests") as info:
        check_record(_scaled(handheld_record, factor))
    assert str(info.value).endswith(cause)
    assert float(re.search(r"direction ([0-9.e-]+) times", str(info.value)).group(1)) == pytest.approx(factor,
                                                                                                      rel=0.1)
