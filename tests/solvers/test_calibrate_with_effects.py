"""``calibrate.calibrate_with_effects``: the final calibration ``graph-calib diagnose`` writes."""

from dataclasses import replace

import numpy as np

from graph_calib.calibrate import calibrate, calibrate_with_effects
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions

from _shared import make_experiment


def test_it_is_calibrate_with_the_effects_added_to_the_model():
    exp = make_experiment(n=3000, seed=4)
    base = CalibrationOptions(model=ModelOptions(extra_effects=("time_lag.accel",)), structure_tests=False)
    added = ("accel.bias_tc3",)
    got = calibrate_with_effects(exp, added=added, options=base, solvers=("factor-graph",))
    want = calibrate(exp, options=replace(base, model=replace(base.model, extra_effects=("time_lag.accel",) + added)),
                     solvers=("factor-graph",))
    g, w = got.results["factor-graph"], want.results["factor-graph"]
    # the options' own effects kept, the added ones with them, a curve's lower order with its own
    assert {"time_lag.accel", "accel.bias_tc2", "accel.bias_tc3"} <= set(g.effects)
    assert g.effects == w.effects and g.values.keys() == w.values.keys()
    np.testing.assert_array_equal([g.values[k] for k in g.values], [w.values[k] for k in w.values])
    assert got.verdict.text() == want.verdict.text()
