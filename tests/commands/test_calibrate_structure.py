"""calibrate: the closed loop's score tests at its solution fail the verdict naming the effect; the noise block."""

import json

from graph_calib.cli import main


def test_calibrate_fails_naming_an_undeclared_effect_that_diagnose_would_add(tmp_path, capsys):
    data = tmp_path / "sim"
    assert main(["simulate", "effect-accel.bias_dtdt", "--seed", "1", "--hours", "0.1", "--out", str(data)]) == 0
    (h5,) = data.glob("*.h5")
    rc = main(["calibrate", str(h5), "--out", str(tmp_path / "cal"), "--solver", "factor-graph"])
    out = capsys.readouterr().out
    assert rc == 3
    line = next(ln for ln in out.splitlines() if ln.startswith("verdict: FAIL"))
    assert "RESIDUALS CARRY AN EFFECT THE MODEL LACKS: " in line and "accel.bias_dtdt (score" in line
    doc = json.loads((tmp_path / "cal" / "factor-graph.json").read_text())
    assert any(t["effect"] == "accel.bias_dtdt" and t["significant"] for t in doc["verdict"]["structure"])
    assert doc["noise"]["source"] == {"gyro": "identified", "accel": "identified", "encoder": "identified"}
