"""The grade chosen from the data when none is named (graph_calib/records/grade_choice.py)."""

import json

import numpy as np
import pytest

from graph_calib.cli import main
from graph_calib.records.grade_choice import choose_grade
from graph_calib.importers import import_mpu6050, import_xsens
from graph_calib.simulation import simulate

from _shared import REAL_DATA, require_real


def _sim(name, **kw):
    return simulate(name, rng=np.random.default_rng(1), **kw).run()[0].experiment


@pytest.mark.parametrize("scenario, kw, grade", [("nav-subrange-short", {"hours": 0.1}, "navigation"),
                                                  ("nav-subrange", {"hours": 0.5}, "navigation"),
                                                  ("consumer-handheld", {}, "consumer")])
def test_simulated_units_get_their_grade(scenario, kw, grade):
    choice = choose_grade(_sim(scenario, **kw))
    assert choice.grade == grade, choice.reason
    assert grade in choice.reason


def test_measured_consumer_units_are_not_run_as_navigation_grade():
    xs = require_real(REAL_DATA / "imu_tk_xsens")
    mpu = require_real(REAL_DATA / "mpu6050_uncuyo")
    for exp in (import_xsens(xs / "xsens_acc.mat", xs / "xsens_gyro.mat"),
                import_mpu6050(mpu / "example_data_calibration.csv")):
        choice = choose_grade(exp)
        assert choice.grade == "consumer", choice.reason
        assert "static rate" in choice.reason or "noise" in choice.reason    # it names the measured figure


def test_calibrate_prints_and_records_the_choice(tmp_path, capsys):
    data = tmp_path / "sim"
    assert main(["simulate", "nav-subrange-short", "--seed", "3", "--hours", "0.05", "--out", str(data)]) == 0
    (h5,) = data.glob("*.h5")
    rc = main(["calibrate", str(h5), "--out", str(tmp_path / "cal"), "--solver", "factor-graph"])
    out = capsys.readouterr().out
    assert rc in (0, 3)
    assert "grade: navigation" in out
    doc = json.loads((tmp_path / "cal" / "factor-graph.json").read_text())
    assert doc["grade"] == "navigation" and doc["grade_choice"]["grade"] == "navigation"
    # the choice judges the densities the solvers use: those of the record's own keyframe
    rc = main(["calibrate", str(h5), "--out", str(tmp_path / "cal05"), "--solver", "factor-graph", "--keyframe", "0.5"])
    doc = json.loads((tmp_path / "cal05" / "factor-graph.json").read_text())
    assert doc["noise"]["identified"]["gyro"]["keyframe_s"] == 0.5
    assert doc["grade_choice"]["gyro_noise_rad_per_sqrt_s"] == doc["noise"]["identified"]["gyro"]["density"]
    assert doc["grade_choice"]["accel_noise_mps_per_sqrt_s"] == doc["noise"]["identified"]["accel"]["density"]
    # a named grade is used as given, and no choice is recorded
    rc = main(["calibrate", str(h5), "--out", str(tmp_path / "cal2"), "--solver", "factor-graph",
               "--grade", "tactical"])
    doc = json.loads((tmp_path / "cal2" / "factor-graph.json").read_text())
    assert doc["grade"] == "tactical" and "grade_choice" not in doc


def test_grade_is_about_priors_a_noisier_navigation_unit_stays_navigation():
    # three times the navigation table's densities (the old rule called it tactical above 3x)
    choice = choose_grade(_sim("nav-subrange-short", hours=0.1, noise_factor=3.0))
    assert choice.grade == "navigation", choice.reason


def test_noise_alone_rules_a_grade_out_only_when_both_sensors_are_of_another_class():
    from graph_calib.records.grade_choice import _misfit
    from graph_calib.sensors.params import GRADES
    nav = GRADES["navigation"]
    quiet = dict(rate_offset=0.0, force_offset=0.0, gravity=9.8)
    assert _misfit("navigation", gyro_noise=nav.gyro_noise, accel_noise=10 * nav.accel_noise, **quiet) == []
    assert _misfit("navigation", gyro_noise=100 * nav.gyro_noise, accel_noise=100 * nav.accel_noise, **quiet)


def test_a_record_without_a_rest_cannot_tell_its_grade():
    from dataclasses import replace
    from graph_calib.errors import InputError
    exp = _sim("nav-subrange-short", hours=0.05)
    t = exp.t
    dv = exp.dv.copy()
    dv += 0.02 * np.sin(2 * np.pi * 0.9 * t)[:, None] * exp.dt[:, None]    # swaying throughout
    dth = exp.dtheta + 0.05 * np.cos(2 * np.pi * 0.6 * t)[:, None] * exp.dt[:, None]
    with pytest.raises(InputError, match=r"--grade.*cannot choose the IMU grade: no rest"):
        choose_grade(replace(exp, dv=dv, dtheta=dth))


def test_hand_held_record_without_a_rest_is_refused_not_crashed(tmp_path, capsys):
    # the hand sways the unit throughout and no pose lasts 2 s: the grade choice once carried NaN figures
    # into the result file, and the JSON writer ended the run with an internal error (exit 1)
    from graph_calib import io
    se = simulate("consumer-handheld", rng=np.random.default_rng(1), initial_static_s=1.0, hold_s=(1.0, 1.8),
                  hand_accel_mps2=0.3, pivot_m=0.1).run()[0]
    h5 = tmp_path / "hh.h5"
    io.write_experiment(se.experiment, h5)
    rc = main(["calibrate", str(h5), "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "--grade" in err and "no rest" in err
    assert not (tmp_path / "cal").exists()



def test_the_python_api_chooses_the_grade_as_the_commands_do():
    """No grade named in ``ModelOptions`` (the API's default): ``build_problem`` lets the rests choose the priors'
    grade, with its reason in the result (``grade_choice``), instead of giving a MEMS unit navigation priors (on the
    measured Xsens session those ran both variance factors to their bound of 1e4)."""
    from graph_calib.calibrate import CalibrationOptions, build_problem
    from graph_calib.model import ModelOptions
    from graph_calib.solvers.results import to_result
    from graph_calib.solvers.registry import solve

    xs = require_real(REAL_DATA / "imu_tk_xsens")
    exp = import_xsens(xs / "xsens_acc.mat", xs / "xsens_gyro.mat")
    problem = build_problem(exp, options=CalibrationOptions())
    assert problem.model.options.grade == "consumer"
    assert problem.model.options.grade_choice == choose_grade(exp).to_json()
    result = to_result(problem.model, solve("factor-graph", problem, options=CalibrationOptions()))
    assert result.extra["grade"] == "consumer" and result.extra["grade_choice"]["grade"] == "consumer"
    # a grade named is used as given, and no choice is recorded
    named = build_problem(exp, options=CalibrationOptions(model=ModelOptions(grade="tactical")))
    assert named.model.options.grade == "tactical" and named.model.options.grade_choice == {}


def test_the_python_api_says_so_where_the_rests_cannot_tell():
    """A noise-free simulated record shows no rest with its noise: the API takes the default grade and says so in
    the choice (the commands refuse it, exit 2 naming --grade)."""
    from graph_calib.calibrate import CalibrationOptions, build_problem
    exp = simulate("nav-subrange-short", rng=np.random.default_rng(1), hours=0.05, noise=False).run()[0].experiment
    with pytest.raises(Exception, match="no rest"):
        choose_grade(exp)
    options = build_problem(exp, options=CalibrationOptions()).model.options
    assert options.grade == "navigation"
    assert options.grade_choice["reason"].startswith("navigation, the default: the record has no rest of 2 s")


def test_a_named_grade_the_rests_contradict_is_warned_of():
    """--grade navigation on a consumer unit: the verdict then blamed a missing effect; the command now says the rests
    contradict the priors (a looser grade named is no contradiction)."""
    from graph_calib.records.grade_choice import grade_warning, named_grade_misfit

    exp = _sim("consumer-handheld")
    why = named_grade_misfit(exp, "navigation")
    assert "static rate" in why and "off the Earth rate" in why
    assert named_grade_misfit(exp, "consumer") == "" and grade_warning(exp, "consumer") == ""
    assert grade_warning(exp, "navigation").startswith(f"warning: --grade navigation: the record's rests do not fit "
                                                       f"its priors ({why})")
