"""``graph-calib apply`` refuses a failed verdict without --force and never applies an unresolved direction."""

from __future__ import annotations

import numpy as np
import pytest

from graph_calib import cli, io
from graph_calib import constants as c
from graph_calib.records.experiment import Result


def _result(path, *, passed=True, unresolved=False):
    """A result with a gyro bias and a gyro g-sensitivity (as a hand-held record leaves along its heading drift)."""
    values = {"gyro.bias.x": 1e-5, "gyro.bias.y": 0.0, "gyro.bias.z": 0.0}
    gs = {f"gyro.g_sensitivity.{r}{k}": 0.0 for r in "xyz" for k in "xyz"}
    gs["gyro.g_sensitivity.zz"] = 3.5e-3          # rad/s per m/s^2: -2 deg/s lying still if applied
    values.update(gs)
    extra = {"verdict": {"passed": passed, "text": "verdict: FAIL: residuals inconsistent (chi2/dof 156)"
                         if not passed else "verdict: pass"}}
    if unresolved:
        extra["unresolved"] = {"heading drift": {"gyro.g_sensitivity.zz": 1.0}}
    res = Result(source="still.h5", solver="factor-graph", t_ref_degC=20.0, temperature_range_degC=(19.0, 26.0),
                 effects=("gyro.bias", "gyro.g_sensitivity"), values=values,
                 sigmas={k: 1e-6 for k in values}, extra=extra)
    io.write_result(res, path)
    return path


def _cli(argv, capsys):
    code = cli.main([str(a) for a in argv])
    return (code, *capsys.readouterr())


@pytest.fixture
def still(tmp_path, experiment_factory):
    exp = experiment_factory(n=400, with_table=False)
    path = tmp_path / "still.h5"
    io.write_experiment(exp, path)
    return path


def test_a_failed_verdict_is_refused_naming_it_unless_forced(tmp_path, still, capsys):
    res = _result(tmp_path / "r.json", passed=False)
    code, out, err = _cli(["apply", res, still, "--out", tmp_path / "c.h5"], capsys)
    assert code == 2 and not (tmp_path / "c.h5").exists()
    assert ("verdict: its verdict failed (verdict: FAIL: residuals inconsistent (chi2/dof 156)); a calibration "
            "that failed its own checks is not applied without --force") in err
    code, out, err = _cli(["apply", res, still, "--out", tmp_path / "c.h5", "--force"], capsys)
    assert code == 0 and "applied with --force although its verdict failed" in err


def test_an_unresolved_g_sensitivity_is_not_applied(tmp_path, still, capsys):
    raw = io.read_experiment(still)
    for unresolved, expect_turn in ((False, True), (True, False)):
        out = tmp_path / f"c{unresolved}.h5"
        code, text, _ = _cli(["apply", _result(tmp_path / f"r{unresolved}.json", unresolved=unresolved), still,
                              "--out", out], capsys)
        assert code == 0
        corrected = io.read_experiment(out)
        still_half = slice(0, 200)
        dz = (corrected.dtheta[still_half, 2] - raw.dtheta[still_half, 2]) / raw.dt[still_half]
        turn_dps = float(np.mean(dz)) * c.RAD_TO_DEG
        if expect_turn:   # the g-sensitivity applied: the unit lying still turns at about -2 deg/s
            assert turn_dps < -1.5
        else:
            assert abs(turn_dps) < 1e-6
            assert "not applied: the result marks the direction 'heading drift' unresolved" in text
