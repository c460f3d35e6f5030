"""``--gyro-range-dps`` on calibrate, diagnose and crossval: an experiment file cut after its saturated turns before
the work (graph_calib.records.saturation), as ``import --gyro-range-dps`` cuts a log."""

import json

import pytest

from graph_calib.cli import main


@pytest.fixture(scope="module")
def whole(real_data, tmp_path_factory):
    """The MPU-6050 calibration session as a bench would write it: one segment, its saturated turns in it."""
    out = tmp_path_factory.mktemp("gyro_range") / "mpu_whole.h5"
    assert main(["import", "mpu6050", str(real_data / "mpu6050_uncuyo" / "example_data_calibration.csv"),
                 "--out", str(out), "--keep-saturated"]) == 0
    return out


def test_calibrate_cuts_the_file_it_reads_and_the_declared_model_fits(whole, tmp_path, capsys):
    assert main(["calibrate", str(whole), "--out", str(tmp_path / "cut"), "--solver", "factor-graph",
                 "--gyro-range-dps", "250"]) == 0
    err = capsys.readouterr().err
    assert "note: The gyros are saturated in 18 samples (3 episodes, first samples 3910, 6662, 8766): the record " \
           "is cut after 3 of them" in err
    # without the range: the misfit fails the verdict, whose note names the option
    assert main(["calibrate", str(whole), "--out", str(tmp_path / "whole"), "--solver", "factor-graph"]) == 3
    result = json.loads((tmp_path / "whole" / "factor-graph.json").read_text())
    notes = " ".join(result["verdict"]["notes"])
    assert "the gyros sit at their largest output" in notes and "--gyro-range-dps" in notes


def test_diagnose_with_the_range_adds_nothing(whole, tmp_path):
    assert main(["diagnose", str(whole), "--out", str(tmp_path / "d"), "--solver", "factor-graph",
                 "--gyro-range-dps", "250"]) == 0
    assert json.loads((tmp_path / "d" / "diagnosis.json").read_text())["added"] == []


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "crossval"])
def test_a_range_that_is_not_positive_is_refused_before_the_work(whole, tmp_path, capsys, command):
    assert main([command, str(whole), "--out", str(tmp_path / "x"), "--gyro-range-dps", "0"]) == 2
    assert "--gyro-range-dps: must be a positive number of deg/s" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
