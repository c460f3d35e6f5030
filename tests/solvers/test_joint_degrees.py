"""The joint curves' degree: the Wald test at the loop's alpha finds the orders the data show, an order they do
not show leaves the curve only where holding it would widen the curve's sigma by more than RHO_MAX, and the
test of the next order per family."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from graph_calib.sensors.effects import REGISTRY
from graph_calib.sensors.params import Layout
from graph_calib.solvers.joint.degrees import DEGREE_ALPHA, RHO_MAX, choose_degrees
from graph_calib.solvers.joint.unknowns import MAX_DEGREE, curve_label, curve_row, plan_unknowns

#: Every sensor over -10..50 degC (t0 = 20 degC).
SPANS = np.tile([-10.0, 50.0], (6, 1))


def _unknowns():
    lay = Layout.declared(extra=tuple(e.name for e in REGISTRY if e.temperature_order >= 2))
    return plan_unknowns([lay, lay], [5.0, 35.0], degrees=dict(MAX_DEGREE))


def _plant(u, orders, sd=None):
    """theta, covariance: family -> {order: wald statistic of its three coefficients}; every coefficient's sigma
    1 (a coefficient of dT^k with sigma 1 widens a curve over +-30 degC by far more than RHO_MAX) unless ``sd``
    gives ``{(family, order): sigma}``."""
    idx = u.z_index()
    n = u.nz + sum(len(s) for s in u.setup_names)
    th, sig = np.zeros(n), np.ones(n)
    for (base, order), s in (sd or {}).items():
        for f in [f for f in u.curve_elements() if f.startswith(base + ".")]:
            sig[idx[curve_label(f, order)]] = s
    for base, per in orders.items():
        elements = [f for f in u.curve_elements() if f.startswith(base + ".")]
        for order, wald in per.items():
            for f in elements:
                th[idx[curve_label(f, order)]] = np.sqrt(wald / len(elements)) * sig[idx[curve_label(f, order)]]
    return th, np.diag(sig**2)


def test_the_degree_is_the_highest_significant_order_where_the_others_cost_much():
    u = _unknowns()
    thr = stats.chi2.isf(DEGREE_ALPHA, 3)
    assert thr == pytest.approx(11.34, abs=0.01)
    th, C = _plant(u, {"accel.bias": {3: 2.0 * thr, 4: 0.5 * thr}, "accel.scale": {5: 1.5 * thr},
                       "gyro.bias": {2: 0.9 * thr}, "gyro.scale": {2: 1.2 * thr}})
    reduced, keep, th_c, C_c, choices = choose_degrees(u, th, C, sensor_spans=SPANS)
    by = {c.family: c for c in choices}
    assert {f: c.degree for f, c in by.items()} == {"accel.bias": 3, "accel.scale": 5, "gyro.bias": 1,
                                                     "gyro.scale": 2}
    assert {f: c.significant_degree for f, c in by.items()} == {f: c.degree for f, c in by.items()}
    assert reduced.degrees == {f: c.degree for f, c in by.items()}
    # every order dropped was dropped for its cost
    assert all(t["rho"] > RHO_MAX for c in choices for t in c.tests if not t["kept"])
    assert all(c.widening == 1.0 for c in choices)
    # BIC with 300,000 measurements would have dropped an order of Wald 1.2 x 11.3 (its price: 3 ln n = 37.8)
    assert 1.2 * thr < 3 * np.log(300_000)
    # the dropped coefficients are zero and out of the kept set
    idx = u.z_index()
    for f in [f for f in u.curve_elements() if f.startswith("accel.bias.")]:
        assert not keep[idx[curve_label(f, 4)]] and th_c[idx[curve_label(f, 4)]] == 0.0
        assert keep[idx[curve_label(f, 3)]]


def test_an_order_the_test_does_not_see_stays_in_the_curve_when_it_costs_little():
    """accel.bias: orders 4 and 5 not significant but so well determined that holding them widens the curve by
    almost nothing: the curve keeps them, unconditioned, and the evidence still says the data show order 3."""
    u = _unknowns()
    thr = stats.chi2.isf(DEGREE_ALPHA, 3)
    tiny = {("accel.bias", 4): 1e-9, ("accel.bias", 5): 1e-11}
    th, C = _plant(u, {"accel.bias": {3: 2.0 * thr, 4: 0.5 * thr, 5: 0.3 * thr}}, sd=tiny)
    reduced, keep, th_c, C_c, choices = choose_degrees(u, th, C, sensor_spans=SPANS)
    c = {c.family: c for c in choices}["accel.bias"]
    assert (c.degree, c.significant_degree) == (5, 3)
    assert reduced.degrees["accel.bias"] == 5
    t5 = next(t for t in c.tests if t["order"] == 5)
    assert not t5["significant"] and t5["kept"] and 1.0 <= t5["rho"] <= RHO_MAX
    assert c.widening >= 1.0 and c.to_json()["widening"] == c.widening
    idx = u.z_index()
    for f in [f for f in u.curve_elements() if f.startswith("accel.bias.")]:
        for k in (4, 5):
            assert keep[idx[curve_label(f, k)]] and th_c[idx[curve_label(f, k)]] == th[idx[curve_label(f, k)]]
    # rho is the widening over the sensor's span: by hand for order 5 of accel.bias.x
    f = "accel.bias.x"
    T = np.linspace(-10.0, 50.0, 21)
    V = curve_row(T, u.t0_degC, 5)
    cols = [idx[curve_label(f, k)] for k in range(6)]
    with5 = np.sqrt(np.einsum("ij,jk,ik->i", V, C[np.ix_(cols, cols)], V))
    without = np.sqrt(np.einsum("ij,jk,ik->i", V[:, :5], C[np.ix_(cols[:5], cols[:5])], V[:, :5]))
    assert t5["rho"] == pytest.approx(np.max(with5 / without), rel=1e-9)
    # the next order past the significant degree is the evidence's (order 4, not significant)
    assert c.next_order["order"] == 4 and c.next_order["passed"]


def test_a_cheap_top_order_does_not_keep_a_dear_one_below_it():
    """accel.bias: order 5 held tight (by priors over a narrow range) but order 4 loose: the curve holds neither (it
    held both, and order 4's widening with them: two subranges kept degree 5 over a widening of 17-118)."""
    u = _unknowns()
    thr = stats.chi2.isf(DEGREE_ALPHA, 3)
    th, C = _plant(u, {"accel.bias": {3: 2.0 * thr, 4: 0.5 * thr, 5: 0.3 * thr}}, sd={("accel.bias", 5): 1e-11})
    reduced, keep, th_c, C_c, choices = choose_degrees(u, th, C, sensor_spans=SPANS)
    c = {c.family: c for c in choices}["accel.bias"]
    t = {t["order"]: t for t in c.tests}
    assert t[5]["rho"] <= RHO_MAX < t[4]["rho"]
    assert (c.degree, c.significant_degree, c.widening) == (3, 3, 1.0)
    assert not t[5]["kept"] and not t[4]["kept"] and reduced.degrees["accel.bias"] == 3
    idx = u.z_index()
    for f in [f for f in u.curve_elements() if f.startswith("accel.bias.")]:
        for k in (4, 5):
            assert not keep[idx[curve_label(f, k)]] and th_c[idx[curve_label(f, k)]] == 0.0


def test_the_next_order_past_the_significant_one_is_tested_for_every_family():
    u = _unknowns()
    thr = stats.chi2.isf(DEGREE_ALPHA, 3)
    th, C = _plant(u, {"accel.bias": {3: 2.0 * thr, 4: 0.5 * thr}, "accel.scale": {5: 1.5 * thr}})
    by = {c.family: c for c in choose_degrees(u, th, C, sensor_spans=SPANS)[4]}
    nxt = by["accel.bias"].next_order
    assert nxt["order"] == 4 and nxt["passed"] and nxt["wald"] == pytest.approx(0.5 * thr, rel=1e-9)
    assert by["gyro.bias"].next_order["order"] == 2 and by["gyro.bias"].next_order["passed"]
    top = by["accel.scale"].next_order
    assert top["order"] == 6 and top["passed"] is False and "cannot be ruled out" in top["text"]
    js = by["accel.scale"].to_json()
    assert js["rule"] == "wald+rho" and js["next_order"]["passed"] is False and js["significant_degree"] == 5


def test_the_evidence_stays_finite_far_in_the_tail():
    """A curvature thousands of sigma from zero (a long campaign's bias curve) gives a finite log10 p (the result
    file is JSON)."""
    u = _unknowns()
    th, C = _plant(u, {"accel.bias": {3: 1e6}})
    by = {c.family: c for c in choose_degrees(u, th, C, sensor_spans=SPANS)[4]}
    t = next(t for t in by["accel.bias"].tests if t["order"] == 3)
    assert np.isfinite(t["log10_p"]) and t["log10_p"] < -1e5
    assert by["accel.bias"].degree == 3
