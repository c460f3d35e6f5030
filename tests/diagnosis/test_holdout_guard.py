"""The loop's held-out guard (graph_calib.diagnosis.holdout, issue 22)."""

import pytest

from graph_calib.diagnosis import DiagnosisOptions, diagnose
from graph_calib.diagnosis import loop as loop_module
from graph_calib.diagnosis.holdout import GUARDED, HoldOutCheck, held_out_check
from graph_calib.model import ModelOptions
from graph_calib.importers import import_mpu6050
from graph_calib.options import CalibrationOptions, GraphOptions

from _shared import REAL_DATA, make_experiment, require_real

CONSUMER = CalibrationOptions(model=ModelOptions(grade="consumer"))


def test_a_check_is_adopted_only_when_no_guarded_figure_grows():
    before = {"transitions_rms_deg": 0.5, "static_norm_std_mps2": 1e-3, "static_rate_rms_dps": 0.01}
    better = HoldOutCheck(effect="gyro.g_sensitivity", before=before,
                          after={**before, "transitions_rms_deg": 0.2, "static_rate_rms_dps": 0.02}, worse=())
    assert better.adopted and "0.5 -> 0.2" in better.text()
    worse = HoldOutCheck(effect="accel.nonlinearity", before=before,
                         after={**before, "static_norm_std_mps2": 3e-3}, worse=("static_norm_std_mps2",))
    assert not worse.adopted and worse.text().startswith("not adopted") and "static_norm_std_mps2" in worse.text()
    assert worse.to_json()["adopted"] is False
    assert "static_rate_rms_dps" not in GUARDED


def test_a_record_with_a_table_is_not_guarded():
    exp = make_experiment(n=3000, with_table=True)
    grown = CalibrationOptions(model=ModelOptions(grade="consumer", extra_effects=("gyro.g_sensitivity",)))
    assert held_out_check(exp, options=CONSUMER, grown=grown, solver="factor-graph") is None


@pytest.mark.slow
@pytest.mark.measured
def test_the_loop_does_not_add_an_effect_the_held_out_figures_refuse(monkeypatch):
    # the MPU-6050 session kept whole (not cut at its saturated turns): the loop's first effect is
    # gyro.g_sensitivity (tests/diagnosis/test_diagnosis.py)
    exp = import_mpu6050(require_real(REAL_DATA / "mpu6050_uncuyo" / "example_data_calibration.csv"),
                         cut_saturated=False)
    options = CalibrationOptions(model=ModelOptions(grade="consumer"), graph=GraphOptions(max_iterations=300))
    seen = []

    def refuse(experiment, *, options, grown, solver, folds=2):
        seen.append(grown.model.extra_effects[-1])
        f = {"transitions_rms_deg": 0.1, "static_norm_std_mps2": 1e-3, "static_rate_rms_dps": 0.01}
        return HoldOutCheck(effect=seen[-1], before=f, after={**f, "transitions_rms_deg": 0.2},
                            worse=("transitions_rms_deg",))

    monkeypatch.setattr(loop_module, "held_out_check", refuse)
    diag = diagnose(exp, options=options, diagnosis=DiagnosisOptions(solvers=("factor-graph",), holdout=True))
    assert seen == ["gyro.g_sensitivity"]
    assert diag.added == []
    last = diag.rounds[-1].to_json()
    assert last["added"] is None and last["held_out"]["adopted"] is False
    assert "not adopted" in last["decision"]


@pytest.mark.slow
def test_the_guard_fits_each_fold_as_calibrate_does():
    """The guard's fold fits (the layers below ``calibrate``, which imports the diagnosis) are ``calibrate``'s
    with one solver and no structure tests: the same held-out figures."""
    import numpy as np

    from graph_calib.calibrate import calibrate
    from graph_calib.compensation.calibration import Calibration
    from graph_calib.evaluation.crossval import cross_validate
    from graph_calib.simulation import simulate

    exp = simulate("consumer-ferraris", rng=np.random.default_rng(3)).run()[0].experiment
    grown = CalibrationOptions(model=ModelOptions(grade="consumer", extra_effects=("gyro.g_sensitivity",)))
    check = held_out_check(exp, options=CONSUMER, grown=grown, solver="factor-graph")
    assert check is not None and check.effect == "gyro.g_sensitivity"

    def fit(train):
        opts = CalibrationOptions(model=ModelOptions(grade="consumer"), structure_tests=False)
        return Calibration.from_result(calibrate(train, options=opts, solvers=("factor-graph",)).results["factor-graph"])

    direct = cross_validate(exp, fit=fit, folds=2, by="pairs").pooled("calibrated")
    for k in GUARDED:
        assert np.isfinite(check.before[k]) and check.before[k] > 0
        np.testing.assert_allclose(check.before[k], direct[k], rtol=1e-6)


def test_a_record_too_short_to_judge_an_effect_held_out_does_not_adopt_it(real_data):
    """The MPU-6050 90-degree record has two rests: no two folds of two, so no effect can be shown to hold out; the
    tests' choice (gyro.g_sensitivity, score 42 against 16) is not adopted, and the round says why and how to adopt
    on the tests alone."""
    from dataclasses import replace

    exp = import_mpu6050(real_data / "mpu6050_uncuyo" / "imu_90_x_rot.csv")
    options = CalibrationOptions(model=ModelOptions(grade="consumer"))
    guarded = diagnose(exp, options=options, diagnosis=DiagnosisOptions(solvers=("factor-graph",)))
    assert guarded.added == []
    first = guarded.rounds[0].to_json()
    held = first["held_out"]
    assert held["adopted"] is False and "rests are too few for 2 folds of two" in held["unjudged"]
    assert "cannot be judged held out (--no-holdout adopts on the score tests alone)" in first["decision"]
    free = diagnose(exp, options=options,
                    diagnosis=replace(DiagnosisOptions(solvers=("factor-graph",)), holdout=False))
    assert free.added[:1] == ["gyro.g_sensitivity"]


def test_the_command_line_guards_by_default_and_no_holdout_adopts_on_the_tests(real_data, tmp_path, capsys):
    """``graph-calib diagnose``: the two-rest record exits 3 with nothing adopted; ``--no-holdout`` adopts the tests'
    choice and exits 0."""
    import json

    from graph_calib.cli import main

    exp = tmp_path / "x90.h5"
    assert main(["import", "mpu6050", str(real_data / "mpu6050_uncuyo" / "imu_90_x_rot.csv"), "--out", str(exp)]) == 0
    assert main(["diagnose", str(exp), "--out", str(tmp_path / "guarded"), "--solver", "factor-graph"]) == 3
    assert json.loads((tmp_path / "guarded" / "diagnosis.json").read_text())["added"] == []
    assert main(["diagnose", str(exp), "--out", str(tmp_path / "free"), "--solver", "factor-graph",
                 "--no-holdout"]) == 0
    assert json.loads((tmp_path / "free" / "diagnosis.json").read_text())["added"] == ["gyro.g_sensitivity"]
