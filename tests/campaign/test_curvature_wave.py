"""The joint curve's curvature carried into the subranges that lack it: the priors (typed by hand), the prior
mean both solvers honour, the wave's place in a campaign."""

from __future__ import annotations

import numpy as np
import pytest
from _shared import make_experiment

from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.campaign.checks import campaign_checks
from graph_calib.campaign.curvature_wave import joint_priors
from graph_calib.model import ModelOptions
from graph_calib.records.experiment import Result

T0 = 20.0
#: accel.bias.{x,y,z} cubic about T0: c0, c1, c2, c3 per element
COEF = {"x": [1e-4, 2e-6, 4e-8, 2e-9], "y": [-3e-4, 1e-6, -6e-8, 5e-9], "z": [2e-4, -1e-6, 1e-8, -3e-9]}
#: their covariance (the same for each element), with a c2-c3 correlation
COV = np.diag([1e-12, 1e-16, 1e-18, 1e-20])
COV[2, 3] = COV[3, 2] = 5e-20


def _joint(degree=3):
    curves = {f"accel.bias.{el}": {"degree": degree, "coefficients": c[: degree + 1],
                                   "covariance": COV[: degree + 1, : degree + 1].tolist()} for el, c in COEF.items()}
    block = {"t0_degC": T0, "degrees": {"accel.bias": degree}, "degree_choice": [], "curves": curves, "setups": {},
             "experiments": ["sub1"]}
    return Result(source="campaign.toml", solver="joint", t_ref_degC=T0, temperature_range_degC=(-10.0, 50.0),
                  effects=("accel.bias",), values={f"accel.bias.{el}": c[0] for el, c in COEF.items()},
                  sigmas={f"accel.bias.{el}": 1e-6 for el in COEF}, extra={"joint": block})


def _subrange(effects, *, t_ref=45.0):
    values = {f"{e}.{el}": 0.0 for e in effects for el in "xyz"}
    return Result(source="sub6.h5", solver="factor-graph", t_ref_degC=t_ref, temperature_range_degC=(40.0, 50.0),
                  effects=tuple(effects), values=values, sigmas={n: 1e-6 for n in values})


def test_the_orders_a_subrange_lacks_get_the_joint_curves_taylor_coefficients_as_their_prior():
    """At T_ref = 45 (d = 25 from t0): p_tc2 = c2 + 3 c3 d, p_tc3 = c3; their variances by hand from the
    coefficients' covariance: var(tc2) = C22 + 6 d C23 + 9 d^2 C33, var(tc3) = C33."""
    d = 25.0
    pr = joint_priors(_joint(), _subrange(("accel.bias", "accel.bias_tc")))
    assert list(pr) == ["accel.bias_tc2", "accel.bias_tc3"]
    m2, s2 = pr["accel.bias_tc2"]
    m3, s3 = pr["accel.bias_tc3"]
    for i, el in enumerate("xyz"):
        c = COEF[el]
        assert m2[i] == pytest.approx(c[2] + 3 * c[3] * d, rel=1e-12)
        assert m3[i] == pytest.approx(c[3], rel=1e-12)
    assert s2 == pytest.approx([np.sqrt(1e-18 + 6 * d * 5e-20 + 9 * d**2 * 1e-20)] * 3, rel=1e-12)
    assert s3 == pytest.approx([1e-10] * 3, rel=1e-12)
    # a subrange that holds the quadratic lacks only the cubic; one that holds the cubic lacks nothing
    assert list(joint_priors(_joint(), _subrange(("accel.bias", "accel.bias_tc", "accel.bias_tc2")))) == \
        ["accel.bias_tc3"]
    assert joint_priors(_joint(), _subrange(("accel.bias", "accel.bias_tc", "accel.bias_tc2", "accel.bias_tc3"))) == {}
    # a linear joint curve has no curvature to carry
    assert joint_priors(_joint(degree=1), _subrange(("accel.bias", "accel.bias_tc"))) == {}


def test_a_subrange_holding_the_joint_orders_is_no_longer_flagged():
    """Once the wave carried the orders, the campaign's check 'curvature carried' finds nothing lacking."""
    doc = {"primary_solver": "factor-graph", "stitch_model": "cubic", "validation": [],
           "experiments": [{"name": "sub6", "verdict": {"passed": True}}], "verdict": {"passed": True, "failed": []}}
    full = _subrange(("accel.bias", "accel.bias_tc", "accel.bias_tc2", "accel.bias_tc3"))
    checks = campaign_checks(doc, results={"sub6": {"factor-graph": full}}, joint=_joint())
    c = next(c for c in checks["checks"] if c["check"] == "curvature carried")
    assert c["passed"] is True and "every subrange holds it" in c["text"]
    lacking = _subrange(("accel.bias", "accel.bias_tc"))
    lacking.values.update({"accel.bias.x": 1.0})
    checks = campaign_checks(doc, results={"sub6": {"factor-graph": lacking}}, joint=_joint())
    assert checks["curvature_bias"]["sub6"]["factor-graph"]


def test_a_prior_mean_is_honoured_by_both_solvers():
    """A parameter the record cannot see (a 5 degC ramp and 6 s: accel.bias_tc3), its prior tight at a mean other
    than zero: both solvers return that mean; the model's prior and the result file say it."""
    exp = make_experiment(n=600)
    mean = [3e-9, -2e-9, 1e-9]
    model = ModelOptions(extra_effects=("accel.bias_tc2", "accel.bias_tc3"), prior_sigma={"accel.bias_tc3": 1e-15},
                         prior_mean={"accel.bias_tc3": mean})
    opts = CalibrationOptions(model=model, variance_components=False, structure_tests=False)
    problem = build_problem(exp, options=opts)
    m, s = problem.model.prior()
    sl = problem.model.layout.slice("accel.bias_tc3")
    np.testing.assert_array_equal(m[sl], mean)
    np.testing.assert_array_equal(s[sl], 1e-15)
    assert np.count_nonzero(m) == 3
    run = solve_problem(problem, options=opts, solvers=("factor-graph", "sqrt-kf"))
    for solver, r in run.results.items():
        got = [r.values[f"accel.bias_tc3.{el}"] for el in "xyz"]
        np.testing.assert_allclose(got, mean, rtol=1e-4, err_msg=solver)
        assert r.extra["prior_means"] == {"accel.bias_tc3": mean}


@pytest.fixture(scope="module")
def carried(tmp_path_factory):
    """Three 12 min subranges (50 Hz) of nav-campaign seed 11 with a strong cubic, both solvers and the joint, in
    process; then the same campaign again from its cache: ``(run, rerun)``."""
    from graph_calib import io
    from graph_calib.campaign import CampaignOptions, run_campaign
    from graph_calib.simulation import simulate

    d = tmp_path_factory.mktemp("carried")
    data = d / "data"
    data.mkdir()
    s = simulate("nav-campaign", rng=np.random.default_rng(11), hours=0.2, rate_hz=50.0, cubic_scale=9.5)
    files = []
    for i in (0, 2, 4):
        se = s.plans[i].run()
        io.write_experiment(se.experiment, data / se.file_name)
        io.write_result(se.truth, data / se.truth_name)
        files.append(se.file_name)
    manifest = data / "campaign.toml"
    manifest.write_text('[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n'
                        + "".join(f'\n[[experiment]]\nfile = "{f}"\n' for f in files))
    opts = CampaignOptions(workers=0, progress=False, report=False)
    # 12 min subranges have wide sigmas: what they lack shifts them by less than CARRY_SIGMA, and the wave would
    # skip them; carried whatever the shift here (the wave runs in this process)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("graph_calib.campaign.curvature_wave.CARRY_SIGMA", 0.0)
        return run_campaign(manifest, d / "out", options=opts), run_campaign(manifest, d / "out", options=opts)


@pytest.mark.slow
def test_a_campaign_carries_the_joint_curves_orders_into_every_subrange_lacking_them(carried):
    """The joint's degree above what a subrange's loop chose: a pooled wave that solves it again, or else the
    joint's own last wave, re-solves it with the missing orders, their priors the joint curve's Taylor coefficients at its T_ref (read independently through
    joint_element_at); every final result then holds every order of the joint curves (nothing left for the check
    'curvature carried' to flag), and a cached re-run recomputes nothing."""
    from graph_calib.solvers.joint.result import joint_element_at

    run, rerun = carried
    doc = run.document
    degrees = doc["joint"]["joint"]["degrees"]
    assert max(degrees.values()) >= 2, degrees
    # carried by the pooled waves that solve an experiment again anyway, else by the joint's own wave
    waves = [w for w in doc["loop"]["pooled"]["waves"] if w.get("priors")]
    assert waves and sum(w.get("kind") == "joint" for w in doc["loop"]["pooled"]["waves"]) <= 1, \
        doc["loop"]["pooled"]["waves"]
    priors = {}
    for w in waves:
        for name, per in w["priors"].items():
            priors.setdefault(name, {}).update(per)
    assert priors
    for name, per in priors.items():
        e = next(e for e in doc["experiments"] if e["name"] == name)
        assert {a["effect"] for a in e["loop"]["pooled"] if a["kind"] == "joint"} == set(per)
        for solver, r in run.results[name].items():
            assert set(per) <= set(r.effects), (name, solver)
            for effect, pr in per.items():
                assert r.extra["prior_means"][effect] == pytest.approx(pr["mean"], rel=1e-12)
                assert r.extra["priors"][effect] == pytest.approx(pr["sigma"], rel=1e-12)
                for i, el in enumerate("xyz"):
                    v, sig = joint_element_at(run.joint, f"{effect}.{el}", r.t_ref_degC)
                    assert pr["mean"][i] == pytest.approx(v, rel=1e-9, abs=1e-30)
                    assert pr["sigma"][i] == pytest.approx(sig, rel=1e-9)
    assert not doc["loop"]["pooled"].get("joint_not_carried")
    assert not doc["campaign_checks"]["curvature_bias"], doc["campaign_checks"]["curvature_bias"]
    c = next(c for c in doc["campaign_checks"]["checks"] if c["check"] == "curvature carried")
    assert c["passed"] is True, c["text"]
    assert rerun.document["timing"]["tasks_computed"] == 0
    assert rerun.document["loop"]["pooled"]["tasks_computed"] == 0
    assert [w["decision"] for w in rerun.document["loop"]["pooled"]["waves"]] == \
        [w["decision"] for w in doc["loop"]["pooled"]["waves"]]


def test_a_joint_whose_verdict_failed_is_no_prior_and_nothing_is_carried():
    """The joint did not converge: no wave runs, its entry says why, and the lacking subrange stays flagged."""
    from types import SimpleNamespace

    from graph_calib.campaign import CampaignOptions
    from graph_calib.campaign.curvature_wave import run_curvature_wave
    from graph_calib.campaign.waves import PooledRun

    joint = _joint()
    joint.extra["verdict"] = {"passed": False, "text": "the joint solve did not converge"}
    sub = _subrange(("accel.bias", "accel.bias_tc"))
    pooled = PooledRun(folders={}, outcomes={}, document={"waves": []}, adopted={},
                       states={"sub6": SimpleNamespace(results={"factor-graph": sub})})
    out = run_curvature_wave(SimpleNamespace(todo=[], done=[]), pooled, joint,
                             options=CampaignOptions(workers=0, progress=False))
    assert out is pooled and not out.outcomes and not out.adopted
    (entry,) = out.document["waves"]
    assert entry["adopted"] is None and "not carried into sub6: the joint's verdict failed" in entry["decision"]
    # a joint that passed would carry the cubic's two orders there
    assert list(joint_priors(_joint(), sub)) == ["accel.bias_tc2", "accel.bias_tc3"]


def test_a_subrange_whose_lacking_orders_shift_nothing_that_matters_is_not_solved_again():
    """The joint's cubic scaled down a thousandfold: what the linear subrange lacks shifts its estimates by
    hundredths of a sigma, below CARRY_SIGMA: no re-solve, the entry says how little it lacks."""
    from types import SimpleNamespace

    from graph_calib.campaign import CampaignOptions
    from graph_calib.campaign.curvature_wave import CARRY_SIGMA, run_curvature_wave
    from graph_calib.campaign.waves import PooledRun

    joint = _joint()
    for cv in joint.extra["joint"]["curves"].values():
        cv["coefficients"] = cv["coefficients"][:2] + [c * 1e-3 for c in cv["coefficients"][2:]]
    joint.extra["verdict"] = {"passed": True}
    pooled = PooledRun(folders={}, outcomes={}, document={"waves": []}, adopted={},
                       states={"sub6": SimpleNamespace(results={"factor-graph": _subrange(("accel.bias",
                                                                                          "accel.bias_tc"))})})
    out = run_curvature_wave(SimpleNamespace(todo=[], done=[]), pooled, joint,
                             options=CampaignOptions(workers=0, progress=False))
    assert not out.outcomes and not out.document["waves"]
    assert 0 < out.document["joint_not_carried"]["sub6"] < CARRY_SIGMA
