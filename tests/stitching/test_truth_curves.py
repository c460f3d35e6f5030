"""Truth over temperature: the simulator's ``temperature_curves`` (round trip, reader refusal, the cubic
option leaving every seed's default data unchanged) and the campaign's truth check that never extrapolates a
per-subrange truth."""

import hashlib
import json

import numpy as np
import pytest

from graph_calib import io
from graph_calib.campaign import truth_check
from graph_calib.errors import InputError
from graph_calib.records.experiment import Result
from graph_calib.simulation import simulate
from graph_calib.stitching import stitch
from graph_calib.evaluation.validation import ResultCalibration, TruthCurves, truth_reference

#: SHA-256 of nav-subrange-short seed 3, 0.02 h (increments, temperatures, table) before the cubic option existed.
DEFAULT_DATA_SHA256 = "54857b4a92d9c032dbbfff33b24805b69f857bec14a25b30958ff9e03ef47ff9"


def _sim(seed=3, **kw):
    return simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=0.02, **kw).plans[0].run()


def _sha(e):
    h = hashlib.sha256()
    for a in (e.experiment.dtheta, e.experiment.dv, e.experiment.temperature, e.experiment.table.q_nf):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def test_default_data_of_a_seed_unchanged():
    assert _sha(_sim()) == DEFAULT_DATA_SHA256


def test_cubic_option_changes_only_the_bias_curves():
    plain, cubic = _sim(), _sim(cubic_scale=3.0)
    tc_plain, tc_cubic = plain.truth.extra["temperature_curves"], cubic.truth.extra["temperature_curves"]
    assert len(tc_plain["accel.bias.y"]["coefficients"]) == 3 and len(tc_cubic["accel.bias.y"]["coefficients"]) == 4
    assert tc_cubic["accel.bias.y"]["coefficients"][3] != 0.0
    # the other draws of the seed are the same: the scale curves and the misalignments
    assert tc_plain["gyro.scale.x"] == tc_cubic["gyro.scale.x"]
    assert plain.truth.values["gyro.misalignment.xy"] == cubic.truth.values["gyro.misalignment.xy"]
    assert plain.truth.values["accel.bias.y"] != cubic.truth.values["accel.bias.y"]


def test_truth_curves_round_trip_and_agree_with_the_truth_at_t_ref(tmp_path):
    se = _sim(cubic_scale=3.0)
    p = tmp_path / "x.truth.json"
    io.write_result(se.truth, p)
    truth = io.read_result(p)
    assert truth.extra["temperature_curves"] == se.truth.extra["temperature_curves"]
    ref = truth_reference(truth)
    assert isinstance(ref, TruthCurves)
    T = np.full((1, 6), truth.t_ref_degC)
    got = ref.evaluate(T)
    for name in ("gyro.bias.x", "gyro.scale.z", "accel.bias.y", "accel.scale.x", "gyro.misalignment.xy"):
        assert got[name][0] == pytest.approx(truth.values[name], rel=1e-9, abs=1e-18), name
    # the slope of the curve at T_ref is the truth's *_tc
    h = 1e-3
    d = (ref.evaluate(T + h)["accel.bias.y"] - ref.evaluate(T - h)["accel.bias.y"]) / (2 * h)
    assert d[0] == pytest.approx(truth.values["accel.bias_tc.y"], rel=1e-6)
    # a truth without curves stands for itself, valid only inside its own range
    bare = Result(**{**truth.__dict__, "extra": {}})
    rc = truth_reference(bare)
    assert isinstance(rc, ResultCalibration) and rc.valid_range_degC == truth.temperature_range_degC


def _truth_doc(tmp_path):
    se = _sim(cubic_scale=3.0)
    p = tmp_path / "t.truth.json"
    io.write_result(se.truth, p)
    return json.loads(p.read_text()), p


@pytest.mark.parametrize("curves, message", [
    ([1, 2], "must be an object"),
    ({"accel.bias.w": {"t0_degC": 20.0, "coefficients": [0.0]}}, "unknown parameter element 'accel.bias.w'"),
    ({"gyro.misalignment.xy": {"t0_degC": 20.0, "coefficients": [0.0]}}, "not an element of a temperature-dependent"),
    ({"accel.bias.y": {"t0_degC": 20.0}}, "exactly 't0_degC' and 'coefficients'"),
    ({"accel.bias.y": {"t0_degC": "warm", "coefficients": [0.0]}}, "must be a finite number"),
    ({"accel.bias.y": {"t0_degC": 20.0, "coefficients": []}}, "non-empty list"),
    ({"accel.bias.y": {"t0_degC": 20.0, "coefficients": [0.0, "x"]}}, "coefficient must be a finite number"),
])
def test_reader_refuses_bad_temperature_curves(tmp_path, curves, message):
    doc, p = _truth_doc(tmp_path)
    doc["temperature_curves"] = curves
    p.write_text(json.dumps(doc))
    with pytest.raises(InputError) as ei:
        io.read_result(p)
    text = str(ei.value)
    assert message in text and "t.truth.json" in text and "temperature_curves" in text


# --- the truth check never extrapolates a per-subrange truth -------------------------------------------------

C = (2e-4, 3e-6, 4e-7)    # accel.bias.x(T) = c0 + c1 (T - 20) + c2 (T - 20)^2, m/s^2: strongly curved
SIGMA = 2e-6


def _curve(T):
    d = np.asarray(T, dtype=float) - 20.0
    return C[0] + C[1] * d + C[2] * d * d


def _subrange(lo, hi, *, solver, with_curves=False):
    """A subrange's result (estimate: the truth's value and slope, small sigmas) or truth over ``lo..hi``."""
    t_ref = 0.5 * (lo + hi)
    d = t_ref - 20.0
    values = {"accel.bias.x": float(_curve(t_ref)), "accel.bias_tc.x": C[1] + 2 * C[2] * d}
    extra = {}
    if with_curves:
        extra["temperature_curves"] = {"accel.bias.x": {"t0_degC": 20.0, "coefficients": list(C)}}
    sig = None if solver == "truth" else {"accel.bias.x": SIGMA, "accel.bias_tc.x": SIGMA / 3.0}
    return Result(source=f"s{lo:g}", solver=solver, t_ref_degC=t_ref, temperature_range_degC=(lo, hi),
                  effects=("accel.bias", "accel.bias_tc"), values=values, sigmas=sig, extra=extra)


def test_truth_check_uses_each_subrange_truth_only_inside_its_range():
    ranges = [(0.0, 4.0), (10.0, 14.0), (20.0, 24.0), (30.0, 34.0)]
    est = [_subrange(lo, hi, solver="factor-graph") for lo, hi in ranges]
    st = stitch(est, names=[r.source for r in est])
    truths = {r.source: _subrange(lo, hi, solver="truth") for r, (lo, hi) in zip(est, ranges)}
    tc = truth_check(st, truths, model="cubic")
    assert tc["reference"] == "subrange_truths"
    assert tc["consistent"] and tc["max_abs_z"] < 1.5, tc   # the linear truth inside +-2 degC
    # the first subrange's truth extrapolated over the whole range (what the check did before) is far off
    old = truth_check(st, ResultCalibration(truths["s0"]), model="cubic")
    assert old["max_abs_z"] > 20.0
    # with temperature curves the check covers the whole range against them
    truths_c = {k: _subrange(*ranges[i], solver="truth", with_curves=True) for i, k in enumerate(truths)}
    tcc = truth_check(st, truths_c, model="cubic")
    assert tcc["reference"] == "temperature_curves" and tcc["consistent"], tcc


def test_subranges_with_different_layouts_stitch():
    """One subrange's model has ``accel.bias_tc2`` (the loop added it there), the others not: the stitch uses
    each point with the coefficients it has, and the curve still follows the truth."""
    ranges = [(0.0, 4.0), (10.0, 14.0), (20.0, 24.0), (30.0, 34.0)]
    est = [_subrange(lo, hi, solver="factor-graph") for lo, hi in ranges]
    r0 = est[0]
    curved = Result(**{**r0.__dict__, "effects": r0.effects + ("accel.bias_tc2",),
                       "values": {**r0.values, "accel.bias_tc2.x": C[2]},
                       "sigmas": {**r0.sigmas, "accel.bias_tc2.x": SIGMA / 30.0}})
    st = stitch([curved] + est[1:], names=[r.source for r in est])
    cv = st.curves["accel.bias.x"]
    assert [p.coef.size for p in cv.points] == [3, 2, 2, 2]
    truths = {r.source: _subrange(lo, hi, solver="truth", with_curves=True) for r, (lo, hi) in zip(est, ranges)}
    tc = truth_check(st, truths, model="cubic")
    assert tc["consistent"] and tc["max_abs_z"] < 1.5, tc
