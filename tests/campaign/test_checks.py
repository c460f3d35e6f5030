"""The checks over the whole campaign: each one planted to fail, in words, and the exit code 3; inputs first."""

from __future__ import annotations

import json
import re
import shutil

import h5py
import numpy as np
import pytest

from graph_calib.campaign import CampaignOptions, run_campaign
from graph_calib.campaign.checks import (CURVATURE_FAIL_SIGMA, apply_to_verdict, campaign_checks, curvature_offsets)
from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.records.experiment import Result


def _summary(*, passed):
    return {"pass": {"gyro": True, "accel": passed, "all": passed},
            "largest": {"gyro_radps": 1e-8, "accel_mps2": 1e-5 if passed else 1.2e-3},
            "gyro_criterion": "static windows", "thresholds": {"gyro_radps": 4.8e-8, "accel_mps2": 2e-4}}


def _document(*, validation_passed=True, experiments=("sub1",)):
    return {"primary_solver": "factor-graph", "stitch_model": "cubic",
            "experiments": [{"name": n, "verdict": {"passed": True}} for n in experiments],
            "verdict": {"passed": True, "failed": []},
            "validation": [{"record": "/x/sweep.h5", "results": {"factor-graph": {"cubic": _summary(
                passed=validation_passed)}}}]}


def test_a_check_over_nothing_is_not_checked_and_does_not_pass():
    """One experiment, no joint: the joint's and the curvature's checks say 'not checked'."""
    checks = campaign_checks(_document(), results={"sub1": {}}, joint=None)
    by = {c["check"]: c for c in checks["checks"]}
    for name in ("joint against subranges", "curvature carried"):
        assert by[name]["checked"] is False and by[name]["passed"] is None
        assert by[name]["text"].startswith("not checked")
    assert checks["passed"]


def test_a_validation_record_not_met_fails_the_verdict_in_words():
    doc = _document(validation_passed=False)
    checks = campaign_checks(doc, results={}, joint=None)
    assert not checks["passed"]
    assert re.search(r"validation on sweep\.h5 of the stitched cubic calibration \(factor-graph\): .*accel max "
                     r"1\.20e-03 m/s\^2 -> NOT met", checks["failed"][0]), checks["failed"]
    v = apply_to_verdict(doc, checks)
    assert v["passed"] is False and v["campaign_checks_failed"] == checks["failed"]


def test_a_validation_record_that_could_not_be_validated_fails():
    doc = _document()
    doc["validation"] = [{"record": "/x/own.h5", "error": "the record's own calibration is missing"}]
    checks = campaign_checks(doc, results={}, joint=None)
    assert not checks["passed"] and "own.h5 was asked for and could not be done" in checks["failed"][0]


def test_curvature_offsets_of_a_quadratic_on_a_linear_subrange_model():
    """A quadratic c2 (T - t0)^2 seen by a model linear about T_ref over [T_ref - h, T_ref + h]: the estimate of
    p absorbs c2 * mean(dT^2) and its slope nothing (symmetric range); by hand on the evenly spread points."""
    c2, t0, t_ref, h = 3e-8, 20.0, 26.0, 4.0
    off = curvature_offsets([1e-4, 2e-6, c2], t0, t_ref, (t_ref - h, t_ref + h), 1)
    dT = np.linspace(-h, h, 41)
    assert off[0] == pytest.approx(c2 * np.mean(dT**2), rel=1e-10)
    assert off[1] == pytest.approx(0.0, abs=1e-20)
    # a model holding the quadratic lacks nothing
    np.testing.assert_allclose(curvature_offsets([1e-4, 2e-6, c2], t0, t_ref, (22.0, 30.0), 2), 0.0, atol=1e-20)


def _joint_result(coefficients, *, t0=20.0, degree_next_passed=True):
    """A joint result with one curve, accel.bias.x, and the evidence of its degree."""
    d = len(coefficients) - 1
    cov = np.diag([1e-12, 1e-16, 1e-18, 1e-20, 1e-22, 1e-24][: d + 1])
    block = {"t0_degC": t0, "degrees": {"accel.bias": d},
             "degree_choice": [{"family": "accel.bias", "degree": d,
                                "next_order": {"order": d + 1, "passed": degree_next_passed,
                                               "text": f"accel.bias: order {d + 1} planted"}}],
             "curves": {"accel.bias.x": {"degree": d, "coefficients": list(coefficients), "covariance": cov.tolist()}},
             "setups": {}, "experiments": ["sub1"]}
    return Result(source="campaign.toml", solver="joint", t_ref_degC=t0, temperature_range_degC=(0.0, 40.0),
                  effects=("accel.bias",), values={"accel.bias.x": coefficients[0]}, sigmas={"accel.bias.x": 1e-6},
                  extra={"joint": block, "verdict": {"passed": True, "text": "converged"}})


def _subrange(value, slope, *, sigma=2e-6, t_ref=30.0):
    return Result(source="sub1.h5", solver="factor-graph", t_ref_degC=t_ref, temperature_range_degC=(26.0, 34.0),
                  effects=("accel.bias", "accel.bias_tc"), values={"accel.bias.x": value, "accel.bias_tc.x": slope},
                  sigmas={"accel.bias.x": sigma, "accel.bias_tc.x": 1e-7})


def test_the_joint_model_against_a_subrange_beyond_their_covariances_fails():
    joint = _joint_result([1e-4, 2e-6])
    truth_at_30 = 1e-4 + 2e-6 * 10.0
    ok = campaign_checks(_document(), results={"sub1": {"factor-graph": _subrange(truth_at_30 + 1e-6, 2e-6)}},
                         joint=joint)
    assert next(c for c in ok["checks"] if c["check"] == "joint against subranges")["passed"]
    bad = campaign_checks(_document(), results={"sub1": {"factor-graph": _subrange(truth_at_30 + 2e-5, 2e-6)}},
                          joint=joint)
    c = next(c for c in bad["checks"] if c["check"] == "joint against subranges")
    assert c["passed"] is False
    assert re.search(r"DISAGREE beyond their two covariances: accel\.bias\.x of sub1 \(factor-graph\) -\d+\.\d+ sigma",
                     c["text"]), c["text"]


def test_a_subrange_lacking_the_curvature_the_joint_adopted_is_flagged_and_fails():
    """The joint's accel.bias is cubic; a linear subrange model over 26..34 degC absorbs its curvature: its
    estimate of accel.bias.x is known to be off by more than CURVATURE_FAIL_SIGMA of its sigma."""
    coef = [1e-4, 2e-6, 4e-7, 2e-8]
    joint = _joint_result(coef)
    sub = _subrange(1.2e-4, 2e-6, sigma=1e-6)
    checks = campaign_checks(_document(), results={"sub1": {"factor-graph": sub}}, joint=joint)
    c = next(c for c in checks["checks"] if c["check"] == "curvature carried")
    z = checks["curvature_bias"]["sub1"]["factor-graph"]["accel.bias.x"]
    assert abs(z) > CURVATURE_FAIL_SIGMA
    assert c["passed"] is False and "accel.bias: the joint's degree 3" in c["text"]
    assert "accel.bias.x of sub1 (factor-graph)" in c["text"] and "known to be off" in c["text"]
    doc = _document()
    apply_to_verdict(doc, checks)
    assert doc["experiments"][0]["curvature_bias"]["factor-graph"]["accel.bias.x"] == pytest.approx(z)


def test_a_family_that_needed_the_highest_order_fails_its_next_order_check():
    joint = _joint_result([1e-4, 2e-6], degree_next_passed=False)
    checks = campaign_checks(_document(), results={}, joint=joint)
    assert "accel.bias: order 2 planted" in checks["failed"]


# ---------------------------------------------------------------------------
# end to end: a campaign with a planted failing check exits 3 and says which; a bad input before any work
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """Two 3-minute subranges of one IMU and, as a 'validation record', a third subrange whose truth file is
    another IMU's: the validation cannot be met."""
    from graph_calib.simulation import simulate, write_simulation

    d = tmp_path_factory.mktemp("small")
    write_simulation(simulate("nav-campaign", rng=np.random.default_rng(3), hours=0.05), d)
    other = tmp_path_factory.mktemp("other")
    write_simulation(simulate("nav-campaign", rng=np.random.default_rng(4), hours=0.05), other)
    shutil.copy(d / "sub3_10_20.h5", d / "sweep.h5")
    shutil.copy(other / "sub3_10_20.truth.json", d / "sweep.truth.json")
    (d / "two.toml").write_text('[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n[solver]\nsolvers = "factor-graph"\n'
                                '[[experiment]]\nfile = "sub1_m10_0.h5"\n[[experiment]]\nfile = "sub2_0_10.h5"\n',
                                encoding="utf-8")
    return d


@pytest.mark.slow
def test_a_campaign_whose_validation_is_not_met_exits_3_and_says_which(small, tmp_path, capsys):
    rc = main(["campaign", str(small / "two.toml"), "--out", str(tmp_path / "out"), "--workers", "0", "--quiet",
               "--no-report", "--no-diagnose", "--validate", str(small / "sweep.h5")])
    out = capsys.readouterr().out
    assert rc == 3, out
    assert re.search(r"check validation sweep\.h5 \(stitched\): FAIL: validation on sweep\.h5 .* -> NOT met", out), out
    assert re.search(r"verdict: FAIL: \d+ check\(s\) over the whole campaign failed: validation on sweep\.h5", out), out
    doc = json.loads((tmp_path / "out" / "campaign.json").read_text(encoding="utf-8"))
    assert doc["verdict"]["passed"] is False and doc["verdict"]["campaign_checks_failed"]


def test_every_input_is_checked_before_the_first_experiment_starts(small, tmp_path):
    """A manifest whose second file lacks /imu/dv is refused before the first experiment is calibrated."""
    bad = tmp_path / "no_dv.h5"
    shutil.copy(small / "sub2_0_10.h5", bad)
    with h5py.File(bad, "r+") as f:
        del f["imu/dv"]
    shutil.copy(small / "sub1_m10_0.h5", tmp_path / "first.h5")
    manifest = tmp_path / "m.toml"
    manifest.write_text('[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n[solver]\nsolvers = "factor-graph"\n'
                        '[[experiment]]\nfile = "first.h5"\n[[experiment]]\nfile = "no_dv.h5"\n', encoding="utf-8")
    finished = []
    with pytest.raises(InputError, match=r"no_dv\.h5.*imu/dv"):
        run_campaign(manifest, tmp_path / "out", options=CampaignOptions(workers=0, progress=False, diagnose=False),
                     on_done=finished.append)
    assert finished == []
    assert not (tmp_path / "out" / "first" / "factor-graph.json").exists()


def test_curvature_adopted_in_one_experiment_is_carried_into_the_others_lowest_order_first():
    from types import SimpleNamespace

    from graph_calib.campaign.waves import carried_curvature

    decl = ("gyro.bias", "accel.bias", "accel.bias_tc")
    states = {"sub1": SimpleNamespace(record={"chosen": decl}),
              "sub2": SimpleNamespace(record={"chosen": decl + ("accel.bias_tc2", "accel.bias_tc3")}),
              "sub3": SimpleNamespace(record={"chosen": decl + ("accel.bias_tc2",)})}
    pick = carried_curvature(states)
    assert (pick.effect, pick.experiments, pick.sources) == ("accel.bias_tc2", ("sub1",), ("sub2", "sub3"))
    assert "carried accel.bias_tc2 into sub1" in pick.text()
    states["sub1"].record["chosen"] = decl + ("accel.bias_tc2",)
    assert carried_curvature(states).effect == "accel.bias_tc3"
    for st in states.values():
        st.record["chosen"] = decl + ("accel.bias_tc2", "accel.bias_tc3")
    assert carried_curvature(states) is None
    # a further effect that is no temperature curve (a g-sensitivity) is never carried
    states["sub1"].record["chosen"] = decl + ("accel.bias_tc2", "accel.bias_tc3", "gyro.g_sensitivity")
    assert carried_curvature(states) is None


def test_a_one_subrange_campaign_reports_its_boundaries_as_not_checked():
    from graph_calib.stitching import stitch

    r = Result(source="s", solver="factor-graph", t_ref_degC=25.0, temperature_range_degC=(20.0, 30.0),
               effects=("gyro.bias", "gyro.bias_tc"), values={"gyro.bias.x": 1e-7, "gyro.bias_tc.x": 1e-9},
               sigmas={"gyro.bias.x": 1e-9, "gyro.bias_tc.x": 1e-10})
    sm = stitch([r], names=["only"]).boundary_summary()
    assert sm["checks"] == 0 and sm["checked"] is False


def _truth_document(max_z_per_result, rms=1.0, n=39):
    exps = []
    for i, z in enumerate(max_z_per_result):
        a = {"rms_z": rms, "max_abs_z": z, "worst": "accel.scale_tc.x", "fraction_within_3sigma": 1.0, "n": n}
        exps.append({"name": f"sub{i + 1}", "loop": {"error_vs_truth": {"factor-graph": {"after": a}}}})
    return {"experiments": exps}


def test_the_subranges_truth_check_is_calibrated_for_many_elements():
    from graph_calib.campaign.checks import _truth_checks

    # one element at 3.0 sigma among 6 x 39: what a right model shows more often than not, passes
    (ok,) = _truth_checks(_truth_document([2.1, 2.5, 3.0, 2.2, 1.9, 2.4]))
    assert ok["passed"] and "limit 4.2" in ok["text"]
    # one at 5 sigma fails, naming it
    (bad,) = _truth_checks(_truth_document([2.1, 2.5, 5.0, 2.2, 1.9, 2.4]))
    assert not bad["passed"] and "sub3 accel.scale_tc.x 5.0 sigma" in bad["text"]
    # an RMS normalised error of 1.3 over 234 elements fails (its chi-square limit is about 1.12)
    (wide,) = _truth_checks(_truth_document([2.0] * 6, rms=1.3))
    assert not wide["passed"] and "RMS normalised error 1.30" in wide["text"]


def test_curvature_adopted_in_many_experiments_is_told_once_per_effect():
    """Carried orders in every experiment: each effect named once with where (a count past three), not once per
    experiment (a 6-subrange campaign carrying orders 2-5 of four families wrote 3,000 characters)."""
    names = [f"sub{i}" for i in range(1, 7)]
    doc = _document(experiments=names)
    for i, e in enumerate(doc["experiments"]):
        e["loop"] = {"added": [{"effect": "accel.bias_tc2"}] + ([{"effect": "gyro.bias_tc3"}] if i < 2 else []),
                     "pooled": [{"effect": "accel.bias_tc2"}]}
    checks = campaign_checks(doc, results={n: {} for n in names}, joint=_joint_result([1e-4, 2e-6, 4e-7]))
    text = next(c for c in checks["checks"] if c["check"] == "curvature carried")["text"]
    assert "accel.bias: the joint's degree 2, accel.bias_tc2 in every experiment" in text, text
    assert "gyro.bias: gyro.bias_tc3 in sub1, sub2" in text, text
    assert text.count("accel.bias_tc2") == 1, text


@pytest.mark.parametrize("consistent, passed", [(True, True), (False, False)])
def test_the_boundary_check_counts_in_the_campaigns_verdict(consistent, passed):
    """Subranges that disagree where they meet (the stitching's family-wise check) fail the campaign (a campaign whose
    boundaries were 321 sigma apart passed)."""
    bc = {"checked": True, "consistent": consistent, "max_abs_z": 2.0 if consistent else 321.5, "checks": 42,
          "family_limit": 3.63, "beyond_limit": 0 if consistent else 17, "limit": 3.0}
    doc = {"primary_solver": "factor-graph", "experiments": [],
           "stitching": {"factor-graph": {"boundary_check": bc}}}
    checks = campaign_checks(doc, results={})
    c = next(c for c in checks["checks"] if c["check"] == "boundaries")
    assert c["checked"] and c["passed"] is passed and checks["passed"] is passed
    assert "largest |z|" in c["text"] and "family-wise limit 3.63" in c["text"]
    doc["stitching"]["factor-graph"]["boundary_check"] = {"checked": False}
    c = next(c for c in campaign_checks(doc, results={})["checks"] if c["check"] == "boundaries")
    assert not c["checked"] and c["passed"] is None


@pytest.mark.parametrize("kind", ["estimate", "truth"])
def test_a_failed_validation_against_the_records_own_calibration_says_so(kind):
    """Without a truth file the reference is the record's own calibration, whose errors count in the figures: a
    failure said nothing of it."""
    doc = _document(validation_passed=False)
    doc["validation"][0]["reference_kind"] = kind
    c = next(c for c in campaign_checks(doc, results={"sub1": {}})["checks"] if c["check"].startswith("validation"))
    assert c["passed"] is False
    said = "the reference is the record's own factor-graph calibration, no truth" in c["text"]
    assert said is (kind == "estimate")
    doc = _document(validation_passed=True)
    doc["validation"][0]["reference_kind"] = kind
    c = next(c for c in campaign_checks(doc, results={"sub1": {}})["checks"] if c["check"].startswith("validation"))
    assert c["passed"] and "own factor-graph calibration" not in c["text"]
