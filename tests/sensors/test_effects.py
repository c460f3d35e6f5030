"""The effect registry's rules (``graph_calib/sensors/effects.py``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from graph_calib.io.manifest import Campaign
from graph_calib.model import CalibrationModel, ModelOptions
from graph_calib.sensors.effects import CURVE_ORDERS, EFFECTS, FURTHER_EFFECTS, with_lower_orders

from _synthetic import wobbly_experiment


def test_a_curve_order_comes_with_the_orders_below_it():
    assert with_lower_orders(("accel.bias_tc3",)) == ("accel.bias_tc2", "accel.bias_tc3")
    assert with_lower_orders(("gyro.scale_tc5", "gyro.g_sensitivity")) == (
        "gyro.scale_tc2", "gyro.scale_tc3", "gyro.scale_tc4", "gyro.scale_tc5", "gyro.g_sensitivity")
    # held already: nothing doubled, the order given kept
    assert with_lower_orders(("accel.bias_tc2", "time_lag.accel", "accel.bias_tc3")) == (
        "accel.bias_tc2", "time_lag.accel", "accel.bias_tc3")
    # order 2 needs only the declared slope; other effects pass unchanged
    assert with_lower_orders(("accel.scale_tc2", "accel.bias_dtdt")) == ("accel.scale_tc2", "accel.bias_dtdt")
    # every name it returns is a known parameter, each temperature order preceded by the one below
    out = with_lower_orders(FURTHER_EFFECTS + CURVE_ORDERS)
    assert len(out) == len(set(out)) and set(out) == set(FURTHER_EFFECTS + CURVE_ORDERS)
    for name in out:
        e = EFFECTS[name]
        if e.temperature_order >= 3:
            below = next(b.name for b in EFFECTS.values()
                         if b.temperature_of == e.temperature_of and b.temperature_order == e.temperature_order - 1)
            assert out.index(below) < out.index(name)


def test_the_calibration_model_holds_the_orders_below_an_added_one():
    exp = wobbly_experiment(rng=np.random.default_rng(3))
    model = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, extra_effects=("accel.bias_tc3",)))
    assert "accel.bias_tc2" in model.layout and "accel.bias_tc3" in model.layout
    assert model.layout.names.index("accel.bias_tc2") < model.layout.names.index("accel.bias_tc3")
    assert "gyro.bias_tc2" not in model.layout


def test_a_manifests_layout_holds_the_orders_below_its_effects():
    camp = Campaign(path=Path("/nowhere/campaign.toml"), imu_id="X", grade="navigation", experiments=(),
                    effects=("gyro.bias_tc3",))
    assert camp.layout().names[-2:] == ("gyro.bias_tc2", "gyro.bias_tc3")
