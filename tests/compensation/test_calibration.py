"""The Calibration object: JSON round trip, correct() inverts the sensor model, sensor_errors() is model.md's."""

import json

import numpy as np
import pytest

from graph_calib.sensors import sensor_model as sm
from graph_calib.compensation.calibration import CALIBRATION_FORMAT, CALIBRATION_VERSION, Calibration, triad_errors
from graph_calib.errors import InputError
from graph_calib.records.experiment import Experiment, Result
from graph_calib.model import CalibrationModel
from graph_calib.sensors.effects import EFFECTS
from graph_calib.sensors.params import Layout
from graph_calib.evaluation.validation import ResultCalibration, sensor_error_sigmas, sensor_errors

#: Every parameter of the declared model that has a sensor term (mount, lever arm and table lag do not).
SENSOR_DECLARED = ("gyro.bias", "gyro.bias_tc", "gyro.scale", "gyro.scale_tc", "gyro.misalignment",
                   "accel.bias", "accel.bias_tc", "accel.scale", "accel.scale_tc", "accel.misalignment")
#: Sizes of the random parameter values, SI (navigation grade, inflated so that every term shows).
SIZE = {"bias": 1e-4, "bias_tc": 1e-6, "scale": 1e-3, "scale_tc": 1e-5, "misalignment": 1e-3,
        "bias_tc2": 1e-8, "scale_tc2": 1e-7, "bias_dtdt": 1e-3, "scale_asym": 1e-4, "g_sensitivity": 1e-6,
        "nonlinearity": 1e-5, "size_effect": 1e-2, "accel": 1e-3}


def random_calibration(rng, names, *, t_ref_degC=21.5):
    """A calibration of ``names`` with every element nonzero (random sign and size from :data:`SIZE`)."""
    layout = Layout(tuple(names))
    x = np.empty(layout.size)
    for n in layout.names:
        size = SIZE.get(n.rpartition(".")[2], 1e-3)
        s = layout.slice(n)
        x[s] = size * rng.uniform(0.5, 1.5, s.stop - s.start) * rng.choice([-1.0, 1.0], s.stop - s.start)
    return Calibration(layout=layout, x=x, t_ref_degC=t_ref_degC, source="random")


def true_motion(n, rate_hz=100.0, seed=0):
    """Smooth rates about every axis, specific force near g in changing directions, six temperatures."""
    rng = np.random.default_rng(seed)
    t = 10.0 + np.arange(1, n + 1) / rate_hz
    ph = rng.uniform(0, 2 * np.pi, (1, 3))
    omega = 0.4 * np.sin(2 * np.pi * 0.2 * t[:, None] + ph) + np.array([1e-5, -3e-5, 5e-5])
    f = 9.8 * np.column_stack([np.sin(0.1 * t), np.cos(0.1 * t) * np.sin(0.07 * t),
                               np.cos(0.1 * t) * np.cos(0.07 * t)])
    T = 18.0 + 0.004 * (t - t[0])[:, None] + np.array([0.0, 0.3, 0.6, 1.0, 1.2, 1.5])
    return t, omega, f, T


def experiment_of(t, w_meas, f_meas, T, rate_hz=100.0):
    dt = np.empty_like(t)
    dt[0] = 1.0 / rate_hz
    dt[1:] = np.diff(t)
    return Experiment(t=t, dtheta=w_meas * dt[:, None], dv=f_meas * dt[:, None], temperature=T,
                      temperature_names=tuple(f"t{i}" for i in range(6)), temperature_map=np.arange(6),
                      rate_hz=rate_hz, latitude_rad=0.9, gravity_mps2=9.81)


# ---------------------------------------------------------------------------
# file round trip
# ---------------------------------------------------------------------------


def test_round_trip_through_json_keeps_every_bit():
    rng = np.random.default_rng(1)
    cal = random_calibration(rng, SENSOR_DECLARED + ("mount", "time_lag.table", "gyro.g_sensitivity"))
    cal = Calibration(layout=cal.layout, x=cal.x, t_ref_degC=np.pi * 7, sigma=np.abs(cal.x) / 10, source="a.h5")
    doc = json.loads(json.dumps(cal.to_dict()))
    assert doc["format"] == CALIBRATION_FORMAT and doc["version"] == CALIBRATION_VERSION
    back = Calibration.from_dict(doc)
    assert back.layout == cal.layout and back.source == "a.h5"
    assert back.x.tobytes() == cal.x.tobytes() and back.sigma.tobytes() == cal.sigma.tobytes()
    assert back.t_ref_degC == cal.t_ref_degC
    truth = Calibration.from_dict(json.loads(json.dumps({**doc, "sigmas": None})))
    assert truth.sigma is None
    with pytest.raises(ValueError):
        cal.x[0] = 1.0  # frozen, numbers included


def test_from_dict_refuses_a_newer_version_and_other_documents():
    doc = random_calibration(np.random.default_rng(2), ("gyro.bias",)).to_dict()
    with pytest.raises(InputError, match=rf"version: version {CALIBRATION_VERSION + 1} is newer than this "
                                         rf"graph-calib reads \(up to {CALIBRATION_VERSION}\)"):
        Calibration.from_dict({**doc, "version": CALIBRATION_VERSION + 1})
    with pytest.raises(InputError, match="format is 'imu-calibration-result'"):
        Calibration.from_dict({**doc, "format": "imu-calibration-result"})
    with pytest.raises(InputError, match="no value for gyro.bias.z"):
        Calibration.from_dict({**doc, "values": {"gyro.bias.x": 0.0, "gyro.bias.y": 0.0}})
    with pytest.raises(InputError, match="parameters"):
        Calibration.from_dict({**doc, "parameters": ["gyro.bias", "gyro.wobble"]})


def test_from_result_takes_values_effects_sigmas_and_reference():
    res = Result(source="s.h5", solver="factor-graph", t_ref_degC=22.5, temperature_range_degC=(20, 25),
                 effects=("gyro.bias", "accel.misalignment"),
                 values={"gyro.bias.y": 1e-7, "accel.misalignment.zy": 2e-5},
                 sigmas={"gyro.bias.y": 1e-9, "accel.misalignment.zy": 1e-6})
    cal = Calibration.from_result(res)
    assert cal.layout.names == ("gyro.bias", "accel.misalignment") and cal.t_ref_degC == 22.5
    assert cal.values() == {"gyro.bias.x": 0.0, "gyro.bias.y": 1e-7, "gyro.bias.z": 0.0, "accel.misalignment.yx": 0.0,
                            "accel.misalignment.zx": 0.0, "accel.misalignment.zy": 2e-5}
    assert np.isnan(cal.sigma[0]) and cal.sigma[1] == 1e-9


# ---------------------------------------------------------------------------
# applying it
# ---------------------------------------------------------------------------


def test_correct_inverts_measure_with_every_declared_term():
    rng = np.random.default_rng(3)
    cal = random_calibration(rng, SENSOR_DECLARED)
    assert np.all(cal.x != 0)
    t, omega, f, T = true_motion(3000)
    dT = T - cal.t_ref_degC
    w_meas = sm.measure(cal.layout, cal.x, "gyro", omega, dT=dT[:, :3], other=f)
    f_meas = sm.measure(cal.layout, cal.x, "accel", f, dT=dT[:, 3:], other=omega)
    assert np.max(np.abs(w_meas - omega)) > 1e-4 and np.max(np.abs(f_meas - f)) > 1e-3  # the errors are there
    w_cal, f_cal = cal.correct(experiment_of(t, w_meas, f_meas, T))
    np.testing.assert_allclose(w_cal, omega, rtol=0, atol=1e-10 * np.abs(omega).max())
    np.testing.assert_allclose(f_cal, f, rtol=0, atol=1e-10 * np.abs(f).max())


def test_correct_feeds_the_model_as_the_solvers_do(experiment_factory):
    """Every context input matters with these further effects: the result is the solvers' inverse, bit for bit
    (accelerometers first; the gyros' g-sensitivity sees the calibrated specific force, model.md)."""
    rng = np.random.default_rng(4)
    names = SENSOR_DECLARED + ("gyro.bias_dtdt", "accel.bias_dtdt", "gyro.g_sensitivity", "gyro.scale_asym",
                               "accel.nonlinearity", "accel.size_effect", "time_lag.accel")
    cal = random_calibration(rng, names, t_ref_degC=23.0)
    exp = experiment_factory(n=800)
    model = CalibrationModel(exp, t_ref_degC=cal.t_ref_degC)
    n_iter = model.options.n_newton
    m = model.record
    f_ref = sm.correct(cal.layout, cal.x, "accel", m.f_raw, dT=m.dTa, dTdt=m.dTdta, other=m.w_raw,
                       domega=m.dw_raw, dsignal=m.df_raw, n_iter=n_iter)
    w_ref = sm.correct(cal.layout, cal.x, "gyro", m.w_raw, dT=m.dTg, dTdt=m.dTdtg, other=f_ref,
                       domega=m.dw_raw, dsignal=m.dw_raw, n_iter=n_iter)
    w_raw_f = sm.correct(cal.layout, cal.x, "gyro", m.w_raw, dT=m.dTg, dTdt=m.dTdtg, other=m.f_raw,
                         domega=m.dw_raw, dsignal=m.dw_raw, n_iter=n_iter)
    assert np.any(w_raw_f != w_ref)                     # the calibrated f is what the gyros see
    w_cal, f_cal = cal.correct(exp)
    np.testing.assert_array_equal(w_cal, w_ref)
    np.testing.assert_array_equal(f_cal, f_ref)


# ---------------------------------------------------------------------------
# the errors it predicts
# ---------------------------------------------------------------------------


def test_sensor_errors_are_model_md_equations():
    """Bias with its coefficient, scale with its coefficient, misalignment, g-sensitivity: written out by hand."""
    rng = np.random.default_rng(5)
    names = ("gyro.bias", "gyro.bias_tc", "gyro.scale", "gyro.misalignment", "gyro.g_sensitivity",
             "accel.bias", "accel.scale", "accel.scale_tc", "accel.misalignment")
    cal = random_calibration(rng, names)
    v = cal.values()
    _, omega, f, T = true_motion(50)
    dT = T - cal.t_ref_degC
    eg, ea = cal.sensor_errors(omega, f, dT=dT)

    def vec(p):
        return np.array([v[f"{p}.{a}"] for a in "xyz"])

    Mg = np.zeros((3, 3))
    for el in EFFECTS["gyro.misalignment"].elements:
        Mg["xyz".index(el[0]), "xyz".index(el[1])] = v[f"gyro.misalignment.{el}"]
    Ma = np.zeros((3, 3))
    for el in EFFECTS["accel.misalignment"].elements:
        Ma["xyz".index(el[0]), "xyz".index(el[1])] = v[f"accel.misalignment.{el}"]
    G = np.array([[v[f"gyro.g_sensitivity.{i}{j}"] for j in "xyz"] for i in "xyz"])
    # omega_meas = (I + diag(scale(T)) + M_g) omega + bias(T) + G f,  p(T) = p + p_tc dT
    eg_hand = vec("gyro.bias") + vec("gyro.bias_tc") * dT[:, :3] + vec("gyro.scale") * omega + omega @ Mg.T + f @ G.T
    ea_hand = vec("accel.bias") + (vec("accel.scale") + vec("accel.scale_tc") * dT[:, 3:]) * f + f @ Ma.T
    np.testing.assert_allclose(eg, eg_hand, rtol=1e-13, atol=0)
    np.testing.assert_allclose(ea, ea_hand, rtol=1e-13, atol=0)
    # ... and they are measure(signal) - signal, up to the rounding of that subtraction
    mg = sm.measure(cal.layout, cal.x, "gyro", omega, dT=dT[:, :3], other=f) - omega
    np.testing.assert_allclose(eg, mg, rtol=0, atol=4 * np.finfo(float).eps * np.abs(omega).max())


def test_result_calibration_errors_agree_with_its_element_values():
    """validation: a single result through its Calibration equals its elements evaluated at temperature."""
    names = ("gyro.bias", "gyro.bias_tc", "gyro.scale", "gyro.scale_tc", "gyro.misalignment",
             "accel.bias", "accel.bias_tc", "accel.scale", "accel.scale_tc", "accel.misalignment", "mount")
    cal = random_calibration(np.random.default_rng(6), names)
    truth = Result(source="t", solver="truth", t_ref_degC=cal.t_ref_degC, temperature_range_degC=(15, 30),
                   effects=names, values=cal.values(),
                   extra={"simulation": {"unmodelled": {"gyro.bias_tc2.z": 3e-9, "accel.scale_tc2.x": 2e-7}}})
    rc = ResultCalibration(truth)
    assert "mount" not in rc.calibration.layout and "gyro.bias_tc2" in rc.calibration.layout
    _, omega, f, T = true_motion(200)
    eg, ea = rc.sensor_errors(T, omega, f)
    eg_v, ea_v = sensor_errors(rc.evaluate(T), omega, f)
    np.testing.assert_allclose(eg, eg_v, rtol=1e-12, atol=0)
    np.testing.assert_allclose(ea, ea_v, rtol=1e-12, atol=0)


def test_error_sigmas_from_squared_terms():
    s = {"gyro.bias.x": 1e-8, "gyro.scale.x": 1e-6, "gyro.misalignment.xz": 2e-6, "accel.misalignment.zy": 5e-6}
    omega = np.array([[0.3, -0.2, 0.1]])
    f = np.array([[0.5, 1.0, 9.7]])
    sg, sa = sensor_error_sigmas(s, omega, f)
    np.testing.assert_allclose(sg[0], [np.sqrt(1e-16 + (1e-6 * 0.3) ** 2 + (2e-6 * 0.1) ** 2), 0, 0], rtol=1e-14)
    np.testing.assert_allclose(sa[0], [0, 0, 5e-6 * 1.0], rtol=1e-14)
    # triad_errors with power=2 is the same sum on one calibration vector
    lay = Layout(("gyro.bias", "gyro.scale", "gyro.misalignment"))
    var = triad_errors(lay, np.square(lay.from_dict(s)), "gyro", omega, power=2)
    np.testing.assert_allclose(np.sqrt(var), sg, rtol=1e-15)
