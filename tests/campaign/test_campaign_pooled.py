"""The campaign's pooled score test in the closed loop (graph_calib.campaign.pooled, graph_calib.campaign.waves).

A short campaign where each experiment's own loop leaves ``accel.bias_tc2`` below its threshold and the pooled
test over both adopts it: two 12 min subranges at 50 Hz of nav-campaign seed 11 with a strong cubic
(``cubic_scale = 9.5``), the coldest (-10..0 degC) and sub5 (30..40 degC); both solvers, in process.  Then the
cached re-run (nothing recomputed, the same decisions replayed from the records) and a clean campaign (linear
truth) where the pooled test adopts nothing.  About 30 s.
"""

import json

import numpy as np
import pytest
from scipy import stats

from graph_calib import io
from graph_calib.campaign import CampaignOptions, run_campaign
from graph_calib.simulation import simulate

#: Whole campaigns with the pooled score test's waves.
pytestmark = pytest.mark.slow

SEED = 11
OPTS = CampaignOptions(workers=0, progress=False, report=False, solvers="per-subrange")


def _campaign(folder, *, subranges, **sim):
    folder.mkdir(parents=True, exist_ok=True)
    s = simulate("nav-campaign", rng=np.random.default_rng(SEED), hours=0.2, rate_hz=50.0, **sim)
    files = []
    for i in subranges:
        se = s.plans[i].run()
        io.write_experiment(se.experiment, folder / se.file_name)
        io.write_result(se.truth, folder / se.truth_name)
        files.append(se.file_name)
    (folder / "campaign.toml").write_text('[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n'
                                          + "".join(f'\n[[experiment]]\nfile = "{f}"\n' for f in files))
    return folder / "campaign.toml"


@pytest.fixture(scope="module")
def pooled(tmp_path_factory):
    """The curved campaign run once, then again from its cache: ``(run, rerun, modification times)``."""
    d = tmp_path_factory.mktemp("pooled")
    manifest = _campaign(d / "data", subranges=(0, 4), cubic_scale=9.5)
    run = run_campaign(manifest, d / "out", options=OPTS)
    files = sorted((d / "out").rglob("*.json")) + sorted((d / "out").rglob("*.h5"))
    mtimes = {p: p.stat().st_mtime_ns for p in files if p.name not in ("campaign.json", "comparison.json")}
    rerun = run_campaign(manifest, d / "out", options=OPTS)
    return run, rerun, mtimes


def test_the_pooled_test_adopts_what_each_experiment_alone_does_not(pooled):
    run, _, _ = pooled
    doc = json.loads((run.out / "campaign.json").read_text())
    waves = doc["loop"]["pooled"]["waves"]
    adopted = waves[0]["adopted"]
    assert adopted["effect"] == "accel.bias_tc2" and adopted["kind"] == "sum"
    assert adopted["experiments"] == ["sub1_m10_0", "sub5_30_40"]
    # each experiment's own loop left it below its own threshold; the sum of those final-round statistics passes
    own = []
    for name in adopted["experiments"]:
        rec = io.read_result(run.out / name / "factor-graph.json").extra["campaign"]["loop"]
        assert rec["added"] == [] and "accel.bias_tc2" not in rec["chosen"]
        c = next(c for c in rec["final_round"]["candidates"] if c["effect"] == "accel.bias_tc2")
        assert 0 < c["statistic"] < c["threshold"] and c["dof"] == 3
        own.append(c["statistic"])
    assert adopted["statistic"] == pytest.approx(sum(own), rel=1e-12) and adopted["dof"] == 6
    m = adopted["n_tests"]
    assert m == len(waves[0]["tests"]) and m > 14       # both kinds of test, every candidate
    assert adopted["threshold"] == pytest.approx(stats.chi2.isf(0.01 / m, 6), rel=1e-12)
    assert adopted["threshold"] < adopted["statistic"]
    assert adopted["log10_p"] == pytest.approx(np.log10(stats.chi2.sf(adopted["statistic"], 6)), rel=1e-9)
    # the second pooled test, on the re-solved experiments' final rounds, adopts nothing more
    assert len(waves) == 2 and waves[1]["adopted"] is None and "no candidate significant" in waves[1]["decision"]


def test_campaign_json_records_the_pooled_adoption_and_the_chosen_model(pooled):
    run, _, _ = pooled
    doc = json.loads((run.out / "campaign.json").read_text())
    assert {c["name"]: c["pooled"] for c in doc["loop"]["changed"]} == {
        "sub1_m10_0": ["accel.bias_tc2"], "sub5_30_40": ["accel.bias_tc2"]}
    for e in doc["experiments"]:
        lp = e["loop"]
        (p,) = lp["pooled"]
        assert p["wave"] == 1 and p["effect"] == "accel.bias_tc2" and p["statistic"] > p["threshold"]
        assert {"dof", "log10_p", "experiments", "kind"} <= set(p)
        assert "accel.bias_tc2" in lp["chosen"] and lp["added"] == []
        for s in ("factor-graph", "sqrt-kf"):
            # the final results are the wave's, re-solved by both solvers with the adopted effect
            assert e["results"][s]["file"] == f"{e['name']}/pooled/1/{s}.json"
            r = run.results[e["name"]][s]
            assert "accel.bias_tc2.z" in r.values and r.extra["campaign"]["wave"] == 1
            assert (run.out / e["name"] / "pooled" / "1" / f"{s}.residuals.h5").is_file()
        assert e["verdict"]["passed"] and e["comparison"]["agree"]
    # the error against the truth: before = the declared model (the experiment's own loop added nothing)
    sub1 = doc["experiments"][0]["loop"]["error_vs_truth"]
    for s in ("factor-graph", "sqrt-kf"):
        b, a = sub1[s]["before"], sub1[s]["after"]
        assert b["rms_z"] > 1.3 and a["rms_z"] < 1.1 and a["fraction_within_3sigma"] == 1.0, (s, b, a)
    # the stitched curves come from the chosen models
    st = run.stitched["factor-graph"]
    assert "accel.bias.z" in st.curves and doc["timing"]["pooled_seconds"] > 0


def test_a_cached_rerun_recomputes_nothing_and_replays_the_decisions(pooled):
    run, rerun, mtimes = pooled
    assert rerun.document["timing"]["tasks_computed"] == 0 and rerun.document["timing"]["tasks_cached"] == 4
    pd = rerun.document["loop"]["pooled"]
    assert pd["tasks_computed"] == 0 and pd["tasks_cached"] == 4 and pd["tasks_failed"] == 0
    assert pd["waves"] == run.document["loop"]["pooled"]["waves"]
    assert all(p.stat().st_mtime_ns == t for p, t in mtimes.items()), "a cached file was rewritten"
    for name, res in run.results.items():
        for s, r in res.items():
            assert rerun.results[name][s].values == r.values


def test_clean_campaign_the_pooled_test_adopts_nothing(tmp_path):
    manifest = _campaign(tmp_path / "data", subranges=(0, 4), curvature=False)
    run = run_campaign(manifest, tmp_path / "out", options=CampaignOptions(
        workers=0, progress=False, report=False, solvers="factor-graph"))
    pd = run.document["loop"]["pooled"]
    assert [w["adopted"] for w in pd["waves"]] == [None] and pd["tasks_computed"] == 0
    assert run.document["loop"]["changed"] == []
    best = pd["waves"][0]["tests"][0]
    assert best["statistic"] < best["threshold"]
    assert not (tmp_path / "out" / "sub1_m10_0" / "pooled").exists()
