"""Constant-temperature steps stitched at their own sensor's temperature, not at the experiment's T_ref."""

import numpy as np

from graph_calib.records.experiment import Result
from graph_calib.stitching import result_points, stitch

#: Self-heating of each sensor above the chamber, degC (gyro x, y, z, accel x, y, z): T_ref, the mean of
#: all six, sits 0.2 degC above the accelerometers.
OFFSETS = np.array([0.8, 0.6, 1.0, 0.4, 0.4, 0.4])
STEPS = (-10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0)


def _curve(T):
    u = np.asarray(T) - 20.0
    return 1e-4 + 2e-5 * u + 3e-8 * u**2 - 2e-9 * u**3       # m/s^2: a cubic accelerometer bias


def _step(T_chamber):
    """A calibration at constant temperature: the value only, measured at accel x's own temperature."""
    T_sens = T_chamber + OFFSETS
    v = float(_curve(T_sens[3]))
    res = Result(source=f"step_{T_chamber:g}", solver="factor-graph", t_ref_degC=float(T_sens.mean()),
                 temperature_range_degC=(float(T_sens.min()), float(T_sens.max())), effects=("accel.bias",),
                 values={"accel.bias.x": v, "accel.bias.y": 0.0, "accel.bias.z": 0.0},
                 sigmas={"accel.bias.x": 1e-7, "accel.bias.y": 1e-7, "accel.bias.z": 1e-7},
                 covariance_names=("accel.bias.x", "accel.bias.y", "accel.bias.z"), covariance=np.eye(3) * 1e-14)
    return res, np.stack([T_sens, T_sens], axis=1)


def test_a_value_without_coefficients_sits_at_its_sensor_temperature():
    res, rg = _step(20.0)
    pt = result_points(res, sensor_ranges=rg)["accel.bias.x"]
    assert abs(pt.t_ref_degC - 20.4) < 1e-12          # accel x's own temperature, not T_ref = 20.6
    assert abs(result_points(res)["accel.bias.x"].t_ref_degC - 20.6) < 1e-12   # without ranges: T_ref as before


def test_stitched_steps_reproduce_a_cubic_at_the_sensor_temperature():
    steps = [_step(T) for T in STEPS]
    st = stitch([r for r, _ in steps], names=[r.source for r, _ in steps], sensor_ranges=[g for _, g in steps])
    T = np.linspace(-10.0, 50.0, 61)
    err = st.curves["accel.bias.x"].evaluate(T)[0] - _curve(T)
    assert np.max(np.abs(err)) < 1e-12
    # placed at T_ref (0.2 degC away) the same steps leave the slope times 0.2 degC, about 0.4 micro-g
    old = stitch([r for r, _ in steps], names=[r.source for r, _ in steps])
    err_old = old.curves["accel.bias.x"].evaluate(T)[0] - _curve(T)
    assert np.max(np.abs(err_old)) > 3e-6
