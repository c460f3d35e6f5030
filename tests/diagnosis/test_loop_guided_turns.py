"""The closed loop on a record with guided full turns: the turn kind goes through the loop's residual statistics,
its report and its verdict like every other kind (it once stopped the loop with a KeyError)."""

import json

import numpy as np

from graph_calib import io
from graph_calib.cli import main
from graph_calib.simulation.scenarios import GUIDED_FERRARIS, simulate


def test_diagnose_a_guided_ferraris_session(tmp_path):
    made = simulate("consumer-ferraris", rng=np.random.default_rng(2), **GUIDED_FERRARIS).plans[0].make()
    path = tmp_path / "guided.h5"
    io.write_experiment(made.experiment, path)
    assert main(["diagnose", str(path), "--out", str(tmp_path / "d")]) == 0
    doc = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    for solver in ("factor-graph", "sqrt-kf"):
        turn = doc["before"]["residuals"][solver]["turn"]
        assert turn["count"] == 21 and "closure" in turn["components"]
    assert (tmp_path / "d" / "report.html").stat().st_size > 0
    result = json.loads((tmp_path / "d" / "factor-graph.json").read_text())
    assert result["noise"]["guided_turns"]["count"] == 3
