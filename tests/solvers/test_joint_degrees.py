"""The joint curves' degree by the Wald test at the loop's alpha, and the test of the next order per family."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from graph_calib.sensors.effects import REGISTRY
from graph_calib.sensors.params import Layout
from graph_calib.solvers.joint.degrees import DEGREE_ALPHA, choose_degrees_wald
from graph_calib.solvers.joint.unknowns import MAX_DEGREE, curve_label, plan_unknowns


def _unknowns():
    lay = Layout.declared(extra=tuple(e.name for e in REGISTRY if e.temperature_order >= 2))
    return plan_unknowns([lay, lay], [5.0, 35.0], degrees=dict(MAX_DEGREE))


def _plant(u, orders):
    """theta with unit covariance: family -> {order: wald statistic of its three coefficients}."""
    idx = u.z_index()
    n = u.nz + sum(len(s) for s in u.setup_names)
    th = np.zeros(n)
    for base, per in orders.items():
        elements = [f for f in u.curve_elements() if f.startswith(base + ".")]
        for order, wald in per.items():
            for f in elements:
                th[idx[curve_label(f, order)]] = np.sqrt(wald / len(elements))
    return th, np.eye(n)


def test_the_degree_is_the_highest_order_past_the_wald_threshold():
    u = _unknowns()
    thr = stats.chi2.isf(DEGREE_ALPHA, 3)
    assert thr == pytest.approx(11.34, abs=0.01)
    th, C = _plant(u, {"accel.bias": {3: 2.0 * thr, 4: 0.5 * thr}, "accel.scale": {5: 1.5 * thr},
                       "gyro.bias": {2: 0.9 * thr}, "gyro.scale": {2: 1.2 * thr}})
    reduced, keep, th_c, C_c, choices = choose_degrees_wald(u, th, C)
    by = {c.family: c for c in choices}
    assert {f: c.degree for f, c in by.items()} == {"accel.bias": 3, "accel.scale": 5, "gyro.bias": 1,
                                                     "gyro.scale": 2}
    assert reduced.degrees == {f: c.degree for f, c in by.items()}
    # BIC with 300,000 measurements would have dropped an order of Wald 1.2 x 11.3 (its price: 3 ln n = 37.8)
    assert 1.2 * thr < 3 * np.log(300_000)
    # the dropped coefficients are zero and out of the kept set
    idx = u.z_index()
    for f in [f for f in u.curve_elements() if f.startswith("accel.bias.")]:
        assert not keep[idx[curve_label(f, 4)]] and th_c[idx[curve_label(f, 4)]] == 0.0
        assert keep[idx[curve_label(f, 3)]]


def test_the_next_order_past_the_chosen_one_is_tested_for_every_family():
    u = _unknowns()
    thr = stats.chi2.isf(DEGREE_ALPHA, 3)
    th, C = _plant(u, {"accel.bias": {3: 2.0 * thr, 4: 0.5 * thr}, "accel.scale": {5: 1.5 * thr}})
    by = {c.family: c for c in choose_degrees_wald(u, th, C)[4]}
    nxt = by["accel.bias"].next_order
    assert nxt["order"] == 4 and nxt["passed"] and nxt["wald"] == pytest.approx(0.5 * thr, rel=1e-9)
    assert by["gyro.bias"].next_order["order"] == 2 and by["gyro.bias"].next_order["passed"]
    top = by["accel.scale"].next_order
    assert top["order"] == 6 and top["passed"] is False and "cannot be ruled out" in top["text"]
    js = by["accel.scale"].to_json()
    assert js["rule"] == "wald" and js["next_order"]["passed"] is False


def test_the_evidence_stays_finite_far_in_the_tail():
    """A curvature thousands of sigma from zero (a long campaign's bias curve) gives a finite log10 p (the result
    file is JSON)."""
    u = _unknowns()
    th, C = _plant(u, {"accel.bias": {3: 1e6}})
    by = {c.family: c for c in choose_degrees_wald(u, th, C)[4]}
    t = next(t for t in by["accel.bias"].tests if t["order"] == 3)
    assert np.isfinite(t["log10_p"]) and t["log10_p"] < -1e5
    assert by["accel.bias"].degree == 3
