"""The closed loop inside a campaign: on a short campaign with strong temperature curvature the loop adopts
``accel.bias_tc2`` in each subrange and the error against the truth falls; ``campaign.json`` records the model
chosen and why; an interrupted campaign resumes with the loop's results kept; ``--no-diagnose`` (and the
manifest's ``[solver] diagnose = false``) skips it.

Two 18 min subranges at 50 Hz (the coldest and the warmest of nav-campaign, where the cubic's local curvature is
largest); about 40 s.  The full-length figures are in docs/campaign.md (benchmarks/campaign_loop_full.py).
"""

import json

import numpy as np
import pytest

from graph_calib import io
from graph_calib.campaign import CampaignOptions, run_campaign
from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.simulation import simulate

#: Whole campaigns with the closed loop on every experiment.
pytestmark = pytest.mark.slow

SEED = 11
CUBIC_SCALE = 6.0


def _manifest(path, files, extra=""):
    path.write_text('[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n' + extra
                    + "".join(f'\n[[experiment]]\nfile = "{f}"\n' for f in files))
    return path


@pytest.fixture(scope="module")
def curved(tmp_path_factory):
    """sub1 (-10..0 degC) and sub6 (40..50 degC) of nav-campaign with a strong cubic, their truth files."""
    d = tmp_path_factory.mktemp("loop-data")
    sim = simulate("nav-campaign", rng=np.random.default_rng(SEED), hours=0.3, rate_hz=50.0, cubic_scale=CUBIC_SCALE)
    files = []
    for i in (0, 5):
        se = sim.plans[i].run()
        io.write_experiment(se.experiment, d / se.file_name)
        io.write_result(se.truth, d / se.truth_name)
        files.append(se.file_name)
    _manifest(d / "campaign.toml", files)
    _manifest(d / "one.toml", files[:1])
    return d


@pytest.fixture(scope="module")
def resumed(curved, tmp_path_factory):
    """The campaign interrupted after its first experiment, then run again: ``(first record, final run)``."""
    out = tmp_path_factory.mktemp("loop-out")
    opts = CampaignOptions(workers=0, progress=False, report=False)

    def stop(outcome):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_campaign(curved / "campaign.toml", out, options=opts, on_done=stop)
    first = {s: io.read_result(out / "sub1_m10_0" / f"{s}.json").extra["campaign"]["loop"]
             for s in ("factor-graph", "sqrt-kf")}
    assert not (out / "sub6_40_50" / "factor-graph.json").exists()
    run = run_campaign(curved / "campaign.toml", out, options=CampaignOptions(workers=0, progress=False))
    return first, run


def test_loop_adopts_the_curvature_and_the_error_against_the_truth_falls(resumed):
    _, run = resumed
    for e in run.document["experiments"]:
        lp = e["loop"]
        assert [a["effect"] for a in lp["added"]] == ["accel.bias_tc2"], (e["name"], lp["added"])
        for solver in ("factor-graph", "sqrt-kf"):
            err = lp["error_vs_truth"][solver]
            b, a = err["before"], err["after"]
            assert b["max_abs_z"] > 4.0 and b["rms_z"] > 1.8, (e["name"], solver, b)
            assert a["max_abs_z"] < 3.5 and a["rms_z"] < 1.3, (e["name"], solver, a)
            assert a["fraction_within_3sigma"] >= 0.95
        assert e["verdict"]["passed"] and e["comparison"]["agree"]


def test_campaign_json_records_the_model_chosen_and_why(resumed):
    _, run = resumed
    doc = json.loads((run.out / "campaign.json").read_text())
    assert doc["loop"]["enabled"] and {c["name"] for c in doc["loop"]["changed"]} == {"sub1_m10_0", "sub6_40_50"}
    e = doc["experiments"][0]
    lp = e["loop"]
    assert "accel.bias_tc2" in lp["chosen"] and "accel.bias_tc2" not in lp["declared"]
    a = lp["added"][0]
    assert a["statistic"] > a["threshold"] > 0 and a["log10_p"] < -5 and "added accel.bias_tc2" in a["decision"]
    assert lp["residual_rms"]["before"]["factor-graph"]["overall"] > 0
    assert set(lp["residual_rms"]["after"]) == {"factor-graph", "sqrt-kf"}
    # the chosen model is what each solver's result holds; the declared one is kept beside it
    folder = run.out / e["name"]
    r = io.read_result(folder / "factor-graph.json")
    assert "accel.bias_tc2.y" in r.values and "accel.bias_tc2" in r.effects
    d = io.read_result(folder / "declared" / "sqrt-kf.json")
    assert "accel.bias_tc2.y" not in d.values
    assert (folder / "diagnosis.json").is_file()
    # stitched from the chosen models, with the truth check against the truth curves
    assert "accel.bias.y" in run.stitched["factor-graph"].curves
    assert doc["truth_check"]["factor-graph"]["cubic"]["reference"] == "temperature_curves"
    assert "The closed loop" in (run.out / "report.html").read_text() and "accel.bias_tc2 (score" in \
        (run.out / "report.html").read_text()


def test_resume_after_an_interruption_keeps_the_loops_results(resumed):
    first, run = resumed
    tim = run.document["timing"]
    assert tim["tasks_cached"] == 2 and tim["tasks_computed"] == 2
    e = run.document["experiments"][0]
    # the first wave's files of the interrupted run are kept as they were (cached, not recomputed) ...
    kept = io.read_result(run.out / "sub1_m10_0" / "factor-graph.json").extra["campaign"]["loop"]
    assert kept == first["factor-graph"] == first["sqrt-kf"]
    # ... and the final results are the joint curvature wave's, started from them: the pooled test adopted
    # nothing more here, the joint curves' orders the loop did not choose were carried (curvature_wave.py)
    assert e["loop"]["pooled"] and all(a["kind"] == "joint" for a in e["loop"]["pooled"])
    assert e["results"]["factor-graph"]["file"].startswith("sub1_m10_0/pooled/")
    assert e["loop"]["declared"] == first["factor-graph"]["declared"]
    assert e["loop"]["residual_rms"]["before"] == first["factor-graph"]["residual_rms"]["before"]


def test_no_diagnose_skips_the_loop(curved, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["campaign", str(curved / "one.toml"), "--out", str(out), "--workers", "0", "--solver",
                 "factor-graph", "--no-diagnose", "--no-report", "--quiet"])
    assert code in (0, 3)
    doc = json.loads((out / "campaign.json").read_text())
    assert doc["loop"] == {"enabled": False, "options": None, "changed": [], "pooled": None}
    assert "loop" not in doc["experiments"][0]
    assert not (out / "sub1_m10_0" / "diagnosis.json").exists()
    r = io.read_result(out / "sub1_m10_0" / "factor-graph.json")
    assert "loop" not in r.extra["campaign"] and "accel.bias_tc2.y" not in r.values
    assert "loop:" not in capsys.readouterr().out


def test_manifest_switch_and_its_refusal(curved, tmp_path):
    files = ["sub1_m10_0.h5"]
    off = _manifest(curved / "off.toml", files, extra='\n[solver]\nsolvers = "factor-graph"\ndiagnose = false\n')
    run = run_campaign(off, tmp_path / "off", options=CampaignOptions(workers=0, progress=False, report=False))
    assert not run.document["loop"]["enabled"] and not (tmp_path / "off" / "sub1_m10_0" / "diagnosis.json").exists()
    bad = _manifest(curved / "bad.toml", files, extra='\n[solver]\ndiagnose = "no"\n')
    with pytest.raises(InputError) as ei:
        run_campaign(bad, tmp_path / "bad", options=CampaignOptions(workers=0, progress=False))
    assert "bad.toml" in str(ei.value) and "[solver].diagnose" in str(ei.value) and "true or false" in str(ei.value)
