"""The one evaluation of a temperature curve, through every consumer, at every degree the registry allows.

The polynomials are typed by hand (their values, slopes and Taylor coefficients written out below), so that
a consumer that drops a term (a cubic left out of a subrange's own model, a truth applied only to
``dT^2``) fails here, in the fast tests.
"""

from __future__ import annotations

import numpy as np
import pytest

from graph_calib.compensation.joint import JointCalibration, JointCurve
from graph_calib.campaign.joint_run import _curve_truth
from graph_calib.evaluation.validation import ResultCalibration, TruthCurves, sensor_errors
from graph_calib.records.experiment import Result
from graph_calib.reports.campaign_figures import point_minus_reference
from graph_calib.sensors.curves import evaluate_polynomial_curve, taylor_at
from graph_calib.sensors.effects import MAX_TEMPERATURE_ORDER, temperature_family
from graph_calib.stitching import result_points

T0 = 20.0
#: accel.bias.y about 20 degC, m/s^2 per degC^j
BIAS = (1.2e-4, -3.0e-6, 4.0e-8, -5.0e-10, 6.0e-12, -7.0e-14)
#: gyro.scale.x about 20 degC, 1 per degC^j
SCALE = (40e-6, 0.8e-6, -2.0e-9, 3.0e-10, -4.0e-12, 5.0e-14)
T_REF = 31.0
TEMPS = np.array([-10.0, 5.0, 31.0, 38.5, 50.0])


def by_hand(c, T, d):
    """The polynomial of degree ``d`` written out term by term."""
    x = np.asarray(T, dtype=float) - T0
    terms = [c[0], c[1] * x, c[2] * x * x, c[3] * x * x * x, c[4] * x * x * x * x, c[5] * x * x * x * x * x]
    return sum(terms[: d + 1])


def taylor_by_hand(c, t1, d):
    """``[p, p', p''/2, ...]`` of the degree-``d`` polynomial at ``t1``, the derivatives written out."""
    c = list(c[: d + 1]) + [0.0] * (5 - d)
    h = t1 - T0
    return np.array([
        c[0] + c[1] * h + c[2] * h**2 + c[3] * h**3 + c[4] * h**4 + c[5] * h**5,
        c[1] + 2 * c[2] * h + 3 * c[3] * h**2 + 4 * c[4] * h**3 + 5 * c[5] * h**4,
        c[2] + 3 * c[3] * h + 6 * c[4] * h**2 + 10 * c[5] * h**3,
        c[3] + 4 * c[4] * h + 10 * c[5] * h**2,
        c[4] + 5 * c[5] * h,
        c[5],
    ])[: d + 1]


def _names(flat, d):
    base, el = flat.rsplit(".", 1)
    orders = temperature_family(base)[1]
    return [flat] + [f"{orders[k]}.{el}" for k in range(1, d + 1)]


def _result(d, *, solver="factor-graph"):
    """A result at T_REF holding both elements' Taylor coefficients up to order ``d`` (by hand)."""
    values = {}
    for flat, c in (("accel.bias.y", BIAS), ("gyro.scale.x", SCALE)):
        values.update(dict(zip(_names(flat, d), taylor_by_hand(c, T_REF, d))))
    sig = None if solver == "truth" else {n: 1e-3 * abs(v) + 1e-15 for n, v in values.items()}
    effects = tuple(dict.fromkeys(n.rsplit(".", 1)[0] for n in values))
    return Result(source="hand", solver=solver, t_ref_degC=T_REF, temperature_range_degC=(-10.0, 50.0),
                  effects=effects, values=values, sigmas=sig)


DEGREES = range(1, min(MAX_TEMPERATURE_ORDER["accel.bias"], MAX_TEMPERATURE_ORDER["gyro.scale"]) + 1)


def test_the_registry_allows_degree_five_in_every_temperature_family():
    assert MAX_TEMPERATURE_ORDER == {"gyro.bias": 5, "gyro.scale": 5, "accel.bias": 5, "accel.scale": 5}


@pytest.mark.parametrize("d", DEGREES)
def test_the_curve_and_its_taylor_coefficients(d):
    np.testing.assert_allclose(evaluate_polynomial_curve(BIAS[: d + 1], TEMPS, t0_degC=T0)[0], by_hand(BIAS, TEMPS, d),
                               rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(taylor_at(SCALE[: d + 1], T_REF, t0_degC=T0)[0], taylor_by_hand(SCALE, T_REF, d),
                               rtol=1e-12, atol=1e-22)


@pytest.mark.parametrize("d", DEGREES)
def test_a_subrange_point_predicts_every_order_it_holds(d):
    """stitching and validation: SubrangePoint.predict carries every coefficient the result has."""
    pts = result_points(_result(d))
    assert pts["accel.bias.y"].coef.size == d + 1
    np.testing.assert_allclose(pts["accel.bias.y"].predict(TEMPS)[0], by_hand(BIAS, TEMPS, d), rtol=1e-9, atol=1e-17)
    np.testing.assert_allclose(pts["gyro.scale.x"].predict(TEMPS)[0], by_hand(SCALE, TEMPS, d), rtol=1e-9, atol=1e-17)


@pytest.mark.parametrize("d", DEGREES)
def test_validation_applies_a_result_and_a_truth_curve_over_temperature(d):
    """validation: a single result (through its elements and through the sensor model) and a truth file's
    ``temperature_curves`` give the hand values of bias and scale factor at each window's temperature."""
    T = np.tile(TEMPS[:, None], (1, 6))
    rc = ResultCalibration(_result(d, solver="truth"))
    np.testing.assert_allclose(rc.evaluate(T)["accel.bias.y"], by_hand(BIAS, TEMPS, d), rtol=1e-9, atol=1e-17)
    omega = np.tile([0.3, 0.0, 0.0], (TEMPS.size, 1))         # turning about x: gyro x sees its scale factor
    f = np.tile([0.0, 0.0, 9.8], (TEMPS.size, 1))
    eg, ea = rc.sensor_errors(T, omega, f)
    np.testing.assert_allclose(ea[:, 1], by_hand(BIAS, TEMPS, d), rtol=1e-9, atol=1e-17)
    np.testing.assert_allclose(eg[:, 0], 0.3 * by_hand(SCALE, TEMPS, d), rtol=1e-9, atol=1e-17)
    curves = {"accel.bias.y": {"t0_degC": T0, "coefficients": list(BIAS[: d + 1])},
              "gyro.scale.x": {"t0_degC": T0, "coefficients": list(SCALE[: d + 1])}}
    truth = Result(source="hand", solver="truth", t_ref_degC=T_REF, temperature_range_degC=(29.0, 33.0),
                   effects=("accel.bias", "gyro.scale"), values={"accel.bias.y": 0.0, "gyro.scale.x": 0.0},
                   extra={"temperature_curves": curves})
    tc = TruthCurves(truth).evaluate(T)
    np.testing.assert_allclose(tc["accel.bias.y"], by_hand(BIAS, TEMPS, d), rtol=1e-12, atol=1e-18)
    eg_t, ea_t = sensor_errors(tc, omega, f)
    np.testing.assert_allclose(eg_t[:, 0], 0.3 * by_hand(SCALE, TEMPS, d), rtol=1e-12, atol=1e-18)
    # the joint phase's truth check reads the same curves
    np.testing.assert_allclose(_curve_truth(curves, "gyro.scale.x", TEMPS), by_hand(SCALE, TEMPS, d), rtol=1e-12)


@pytest.mark.parametrize("d", DEGREES)
def test_the_joint_calibration_export_and_apply_carry_every_order(d):
    """compensation: a joint curve evaluates, tabulates and feeds the per-sample calibration vector (apply)
    with every order."""
    cov = np.diag((1e-3 * np.abs(np.array(BIAS[: d + 1]))) ** 2)
    cal = JointCalibration(curves={"accel.bias.y": JointCurve(np.array(BIAS[: d + 1]), cov, T0, (-10.0, 50.0))},
                           constants={}, info={"imu_id": "hand"})
    v, s = cal.curves["accel.bias.y"].evaluate(TEMPS)
    np.testing.assert_allclose(v, by_hand(BIAS, TEMPS, d), rtol=1e-12, atol=1e-18)
    assert np.all(s > 0)
    T = np.tile(TEMPS[:, None], (1, 6))
    X = cal.rows(T)
    col = cal.layout.element_names().index("accel.bias.y")
    np.testing.assert_allclose(X[:, col], by_hand(BIAS, TEMPS, d), rtol=1e-12, atol=1e-18)
    table = cal.table(step_degC=5.0)
    grid = np.asarray(table.grid_degC, dtype=float)
    np.testing.assert_allclose(table.curves["accel.bias.y"].values, by_hand(BIAS, grid, d), rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("d", DEGREES)
def test_the_report_subtracts_the_truth_at_the_points_own_temperature(d):
    """reports: a point exactly on the truth is drawn at zero in the 'minus truth' panel, wherever it is drawn."""
    pt = result_points(_result(d))["accel.bias.y"]
    truth = lambda T: by_hand(BIAS, T, d)         # noqa: E731
    assert point_minus_reference(pt, truth) == pytest.approx(0.0, abs=1e-15)


# ---------------------------------------------------------------------------
# the sensor terms of the higher orders: forward by hand, inverse, Jacobian against finite differences
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("triad", ["gyro", "accel"])
def test_the_higher_temperature_orders_enter_the_sensor_model_as_written(triad):
    from graph_calib.sensors.effects import CURVE_ORDERS
    from graph_calib.sensors.params import Layout
    from graph_calib.sensors.sensor_model import correct, correct_with_jacobian, measure

    rng = np.random.default_rng(77)
    n = 64
    layout = Layout.declared(extra=CURVE_ORDERS)
    x = layout.zeros()
    v = {}
    for name in [n_ for n_ in layout.names if n_.startswith(triad + ".") and "_tc" in n_ and n_[-1] in "345"]:
        x[layout.slice(name)] = rng.uniform(-1e-6, 1e-6, 3) / 10.0 ** int(name[-1])
        v[name] = x[layout.slice(name)].copy()
    signal = (rng.uniform(-1.0, 1.0, (n, 3)) if triad == "gyro" else np.array([0.5, -0.3, 9.8]) + rng.uniform(-1, 1, (n, 3)))
    dT = rng.uniform(-25.0, 25.0, (n, 3))
    out = measure(layout, x, triad, signal, dT=dT)
    expected = signal.copy()
    for k in (3, 4, 5):
        if k >= 4:
            expected += v[f"{triad}.bias_tc{k}"] * dT**k
        expected += v[f"{triad}.scale_tc{k}"] * signal * dT**k
    np.testing.assert_allclose(out, expected, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(correct(layout, x, triad, out, dT=dT), signal, rtol=0, atol=1e-12)
    s, J = correct_with_jacobian(layout, x, triad, out, dT=dT)
    cols = [i for i, e in enumerate(layout.element_names()) if e.rsplit(".", 1)[0] in v]
    for i in cols:
        h = 1e-3 * max(abs(x[i]), 1e-12)
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        fd = (correct(layout, xp, triad, out, dT=dT) - correct(layout, xm, triad, out, dT=dT)) / (2 * h)
        np.testing.assert_allclose(J[:, :, i], fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max())
