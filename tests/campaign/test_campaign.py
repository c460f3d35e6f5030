"""The campaign end to end: a simulated six-subrange campaign, both solvers through Dask, stitching, validation,
the report; resuming after an interruption; one clear error per bad input.

The subranges are short (18 min each) to keep this module near two minutes; docs/campaign.md gives what the
full-length campaign reaches.
"""

import json
import os
import re
import shutil
import time

import numpy as np
import pytest

from graph_calib import constants as c
from graph_calib import io
from graph_calib.campaign import CampaignOptions, run_campaign
from graph_calib.cli import main
from graph_calib.errors import InputError

#: Every test here shares a simulated six-subrange campaign (minutes to simulate and run).
pytestmark = pytest.mark.slow

HOURS = 0.3
SEED = 11


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """Six subranges over -10..+50 degC and an independent 1.5 h record sweeping the range (same IMU)."""
    from graph_calib.simulation import simulate, write_simulation
    from graph_calib.evaluation.validation import simulate_validation_record

    d = tmp_path_factory.mktemp("campaign-data")
    sim = simulate("nav-campaign", rng=np.random.default_rng(SEED), hours=HOURS)
    write_simulation(sim, d)
    se = simulate_validation_record(sim, hours=1.5, rate_hz=20.0, seed=SEED + 1)
    io.write_experiment(se.experiment, d / "validation.h5")
    io.write_result(se.truth, d / "validation.truth.json")
    return d


@pytest.fixture(scope="module")
def campaign_run(simulated, tmp_path_factory):
    out = tmp_path_factory.mktemp("campaign-out")
    t0 = time.perf_counter()
    run = run_campaign(simulated / "campaign.toml", out,
                       options=CampaignOptions(workers=2, validate=(str(simulated / "validation.h5"),),
                                               progress=False))
    run.seconds = time.perf_counter() - t0
    return run


def test_files_of_every_experiment(campaign_run):
    out = campaign_run.out
    doc = json.loads((out / "campaign.json").read_text())
    assert doc["format"] == "imu-calibration-campaign" and len(doc["experiments"]) == 6
    assert not doc["failed"]
    for e in doc["experiments"]:
        folder = out / e["name"]
        for f in ("sqrt-kf.json", "factor-graph.json", "comparison.json", "summary.json",
                  "sqrt-kf.residuals.h5", "factor-graph.residuals.h5"):
            assert (folder / f).is_file(), f"{folder / f} missing"
        attrs, series = io.read_residuals(folder / "sqrt-kf.residuals.h5")
        assert attrs["solver"] == "sqrt-kf" and attrs["quantity"] == "normalised innovation" and series
        r = io.read_result(folder / "factor-graph.json")
        assert r.solver == "factor-graph" and len(r.extra["campaign"]["key"]) == 64
        assert e["results"]["sqrt-kf"]["status"] == "computed"
    assert not list(out.rglob(".*.tmp"))


def test_filter_and_graph_agree_subrange_by_subrange(campaign_run):
    for e in campaign_run.document["experiments"]:
        cmp_ = e["comparison"]
        assert cmp_["agree"], (e["name"], cmp_)
        assert cmp_["max_abs_difference_in_sigma"] < 0.1


def test_stitched_curves_match_the_truth_within_their_bands(campaign_run):
    tc = campaign_run.document["truth_check"]["factor-graph"]["cubic"]
    assert tc["consistent"], tc["max_abs_z"]
    assert tc["fraction_within_1sigma"] > 0.5
    assert tc["fraction_within_2sigma"] > 0.85
    # the stitched curves span the whole range
    st = campaign_run.stitched["factor-graph"]
    lo, hi = st.curves["gyro.bias.x"].t_span
    assert lo < -8.0 and hi > 46.0


def test_boundaries_are_consistent(campaign_run):
    sm = campaign_run.stitched["factor-graph"].boundary_summary()
    assert sm["checks"] == 5 * 21  # five boundaries, 21 stitched elements (12 temperature-dependent, 9 not)
    assert sm["consistent"]
    assert 0.6 < sm["rms_z"] < 1.5


def test_validation_errors_below_the_published_accuracy_over_the_whole_range(campaign_run):
    v = campaign_run.document["validation"][0]
    s = v["results"]["factor-graph"]["cubic"]
    assert v["reference_kind"] == "truth"
    assert s["pass"]["all"], s
    g = np.array(s["gyro_radps"]["static"]["max"]) * c.RS_TO_DH
    a = np.array(s["accel_mps2"]["all"]["max"])
    assert np.all(g < 0.01) and np.all(a < 2e-4)
    # the record covers the campaign's range
    lo, hi = s["calibrated_range_degC"]
    assert s["temperature_range_degC"][0] <= lo + 1.0 and s["temperature_range_degC"][1] >= hi - 5.0
    assert min(s["fraction_inside"]) > 0.7
    # the filter's stitched calibration passes too
    assert v["results"]["sqrt-kf"]["cubic"]["pass"]["all"]


def test_report_is_self_contained(campaign_run):
    html = (campaign_run.out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 10
    assert not re.search(r'src="(?!data:)', html)
    for text in ("Summary", "Filter against graph", "common boundaries", "Validation on an independent record",
                 "Residuals", "gyro.bias", "accel.scale", "deg/h", "micro-g", "ppm"):
        assert text in html


def test_rerun_does_nothing(campaign_run, simulated):
    t0 = time.perf_counter()
    run = run_campaign(simulated / "campaign.toml", campaign_run.out,
                       options=CampaignOptions(workers=2, report=False, progress=False))
    assert run.document["timing"]["tasks_computed"] == 0
    assert run.document["timing"]["tasks_cached"] == 12
    assert time.perf_counter() - t0 < 30.0


# ---------------------------------------------------------------------------
# resuming
# ---------------------------------------------------------------------------


def test_workers_load_the_kernels_the_warm_up_compiled(campaign_run):
    """The numba kernels are warmed in the main process before the Dask workers start; the workers load them
    from numba's on-disk cache, so no task compiles (a fresh clone used to compile in every worker's first job,
    and it showed as that job's seconds)."""
    tim = campaign_run.document["timing"]
    for k in ("warmup_seconds", "compile_seconds", "compiled_signatures", "tasks_seconds", "tasks_compile_seconds"):
        assert k in tim, k
    assert tim["compile_seconds"] <= tim["warmup_seconds"]
    assert tim["tasks_compile_seconds"] == 0.0
    for e in campaign_run.document["experiments"]:
        for s, info in e["results"].items():
            assert info["compile_seconds"] == 0.0, (e["name"], s)
            assert 0.0 < info["seconds"] < 120.0, (e["name"], s, info["seconds"])


def test_task_seconds_leave_numba_compiling_out(simulated, tmp_path, monkeypatch):
    """A task that compiles a kernel reports the compile time apart: its ``seconds`` are calibration time."""
    import numba

    from graph_calib.solvers import orchestration

    real_solve = orchestration.solve
    seen = {}

    def solve_after_compiling(name, problem, **kw):
        t0 = time.perf_counter()
        if not seen:
            @numba.njit(cache=False)
            def fresh(a):          # a kernel nobody has compiled: compiled here, inside the task
                out = 0.0
                for v in a:
                    out += np.sin(v) * np.cos(v) ** 2
                return out
            t1 = time.perf_counter()
            fresh(np.arange(3.0))
            seen["compile"] = time.perf_counter() - t1
        out = real_solve(name, problem, **kw)
        seen.setdefault("solve", time.perf_counter() - t0)
        return out

    monkeypatch.setattr(orchestration, "solve", solve_after_compiling)
    manifest = _small_manifest(simulated, tmp_path / "m")
    # the declared model's path (set-up, then each solver), whose solve is patched here; with the loop (the
    # default) the job is one diagnosis, its compiling measured the same way around it
    run = run_campaign(manifest, tmp_path / "out", options=CampaignOptions(workers=0, report=False, progress=False,
                                                                           diagnose=False))
    first = run.document["experiments"][0]
    extra = run.results[first["name"]]["factor-graph"].extra["campaign"]
    assert 0.5 * seen["compile"] <= extra["compile_seconds"] <= seen["compile"] + 0.05
    assert extra["solve_seconds"] + extra["compile_seconds"] >= 0.99 * seen["solve"]
    assert extra["solve_seconds"] <= seen["solve"] - 0.5 * seen["compile"] + 0.5
    assert first["results"]["factor-graph"]["compile_seconds"] == extra["compile_seconds"]
    assert run.document["timing"]["tasks_compile_seconds"] == pytest.approx(extra["compile_seconds"])
    for e in run.document["experiments"][1:]:
        assert e["results"]["factor-graph"]["compile_seconds"] == 0.0


def test_a_failed_warm_up_does_not_stop_the_campaign(simulated, tmp_path, monkeypatch, capsys):
    from graph_calib.campaign import execution

    def broken():
        raise OSError("no space left on device")

    monkeypatch.setattr(execution, "warm_kernels", broken)
    manifest = _small_manifest(simulated, tmp_path / "m")
    run = run_campaign(manifest, tmp_path / "out", options=CampaignOptions(workers=0, report=False))
    assert run.document["timing"]["tasks_computed"] == 3 and not run.failed
    assert run.document["timing"]["compiled_signatures"] == 0
    assert "warning: warming the numba kernels failed (OSError: no space left on device)" in capsys.readouterr().err


def _small_manifest(simulated, folder, t_ref=None):
    folder.mkdir(parents=True, exist_ok=True)
    lines = ['[imu]', 'id = "SIM-NAV 0001"', 'grade = "navigation"', '', '[solver]', 'solvers = "factor-graph"', '']
    for i, stem in enumerate(("sub2_0_10", "sub3_10_20", "sub4_20_30")):
        lines += ["[[experiment]]", f'file = "{simulated / (stem + ".h5")}"']
        if t_ref is not None and i == 1:
            lines.append(f"t_ref_degC = {t_ref}")
        lines.append("")
    p = folder / "campaign.toml"
    p.write_text("\n".join(lines))
    return p


def test_interrupted_campaign_resumes_without_redoing_finished_experiments(simulated, tmp_path):
    manifest = _small_manifest(simulated, tmp_path / "m")
    out = tmp_path / "out"
    done = []

    def stop_after_first(outcome):
        done.append(outcome)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_campaign(manifest, out, options=CampaignOptions(workers=0, progress=False), on_done=stop_after_first)
    assert len(done) == 1 and done[0]["status"] == "computed"
    first = out / done[0]["name"] / "factor-graph.json"
    stamp = first.stat().st_mtime_ns
    assert not (out / "campaign.json").exists()

    run = run_campaign(manifest, out, options=CampaignOptions(workers=0, report=False, progress=False))
    status = {e["name"]: e["results"]["factor-graph"]["status"] for e in run.document["experiments"]}
    assert status[done[0]["name"]] == "cached"
    assert sorted(status.values()) == ["cached", "computed", "computed"]
    assert first.stat().st_mtime_ns == stamp

    # a rerun does only what changed: a new reference temperature for one experiment
    manifest = _small_manifest(simulated, tmp_path / "m", t_ref=15.0)
    run = run_campaign(manifest, out, options=CampaignOptions(workers=0, report=False, progress=False))
    status = {e["name"]: e["results"]["factor-graph"]["status"] for e in run.document["experiments"]}
    assert status == {"sub2_0_10": "cached", "sub3_10_20": "computed", "sub4_20_30": "cached"}
    assert run.results["sub3_10_20"]["factor-graph"].t_ref_degC == 15.0


def test_command_interrupted_by_ctrl_c_keeps_finished_work(simulated, tmp_path, monkeypatch, capsys):
    """Ctrl-C in ``graph-calib campaign`` after the first finished task, made deterministic: the campaign's
    ``on_done`` raises KeyboardInterrupt there (in process, ``--workers 0``).  Exit 130 with one line, the
    finished result kept, nothing half-written; the rerun reuses it and ends with the results of a run that
    was never interrupted."""
    import graph_calib.campaign as campaign_module

    manifest = _small_manifest(simulated, tmp_path / "m")
    out = tmp_path / "out"
    argv = ["campaign", str(manifest), "--out", str(out), "--workers", "0", "--quiet", "--no-report"]
    done = []

    def interrupted(*args, **kwargs):
        def ctrl_c_after_first(outcome):
            done.append(outcome)
            raise KeyboardInterrupt

        return real_run_campaign(*args, **kwargs, on_done=ctrl_c_after_first)

    real_run_campaign = campaign_module.run_campaign
    monkeypatch.setattr(campaign_module, "run_campaign", interrupted)
    rc = main(argv)
    err = capsys.readouterr().err
    monkeypatch.undo()
    assert rc == 130, err
    assert [ln for ln in err.strip().splitlines() if ln] == ["graph-calib campaign: interrupted; finished work is kept"]
    assert len(done) == 1 and done[0]["status"] == "computed"
    finished = sorted(out.glob("*/factor-graph.json"))
    assert finished == [out / done[0]["name"] / "factor-graph.json"]
    kept = finished[0].read_bytes()
    io.read_result(finished[0])  # a complete, valid file
    assert not list(out.rglob(".*.tmp")) and not (out / "campaign.json").exists()

    # the rerun computes only the two unfinished experiments and leaves the finished one as it was
    assert main(argv) == 0
    doc = json.loads((out / "campaign.json").read_text())
    assert doc["timing"]["tasks_cached"] == 1 and doc["timing"]["tasks_computed"] == 2
    status = {e["name"]: e["results"]["factor-graph"]["status"] for e in doc["experiments"]}
    assert status.pop(done[0]["name"]) == "cached" and set(status.values()) == {"computed"}
    assert finished[0].read_bytes() == kept
    # ... and its results are those of an uninterrupted run
    fresh = tmp_path / "fresh"
    assert main(["campaign", str(manifest), "--out", str(fresh), "--workers", "0", "--quiet", "--no-report"]) == 0
    for e in doc["experiments"]:
        a = io.read_result(out / e["name"] / "factor-graph.json")
        b = io.read_result(fresh / e["name"] / "factor-graph.json")
        assert a.values.keys() == b.values.keys()
        for k in a.values:
            assert a.values[k] == pytest.approx(b.values[k], rel=1e-9, abs=1e-12 * a.sigmas[k]), (e["name"], k)
            assert a.sigmas[k] == pytest.approx(b.sigmas[k], rel=1e-9), (e["name"], k)


# ---------------------------------------------------------------------------
# bad input: one clear error each, exit code 2
# ---------------------------------------------------------------------------


def _write(path, text):
    path.write_text(text)
    return path


@pytest.mark.parametrize("case, pattern", [
    ("missing-manifest", r"campaign\.toml: file not found"),
    ("toml-syntax", r"TOML syntax error"),
    ("missing-experiment", r"\[\[experiment\]\] #1\.file: experiment file .*nowhere\.h5 not found"),
    ("unknown-grade", r"\[imu\]\.grade: unknown grade 'strategic'"),
    ("no-experiment", r"no \[\[experiment\]\] given"),
    ("not-hdf5", r"junk\.h5: not an HDF5 file"),
    ("missing-validation", r"--validate: validation record not found"),
    ("bad-workers", r"--workers: must be 0 or more"),
    ("out-is-file", r"--out: is a file; it names the folder to write into"),
])
def test_bad_input_gives_one_clear_error(case, pattern, simulated, tmp_path, capsys):
    good = simulated / "sub1_m10_0.h5"
    head = '[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n'
    manifest = tmp_path / "campaign.toml"
    extra = []
    out = tmp_path / "out"
    if case == "missing-manifest":
        pass
    elif case == "toml-syntax":
        _write(manifest, head + "[[experiment]\nfile = 'a.h5'\n")
    elif case == "missing-experiment":
        _write(manifest, head + '[[experiment]]\nfile = "nowhere.h5"\n')
    elif case == "unknown-grade":
        _write(manifest, '[imu]\nid = "SIM-NAV 0001"\ngrade = "strategic"\n[[experiment]]\nfile = "' + str(good) + '"\n')
    elif case == "no-experiment":
        _write(manifest, head)
    elif case == "not-hdf5":
        _write(tmp_path / "junk.h5", "not an hdf5 file")
        _write(manifest, head + '[[experiment]]\nfile = "junk.h5"\n')
    else:
        _write(manifest, head + f'[[experiment]]\nfile = "{good}"\n')
        if case == "missing-validation":
            extra = ["--validate", str(tmp_path / "none.h5")]
        elif case == "bad-workers":
            extra = ["--workers", "-1"]
        elif case == "out-is-file":
            out = _write(tmp_path / "out", "a file")
    rc = main(["campaign", str(manifest), "--out", str(out), "--quiet"] + extra)
    err = capsys.readouterr().err
    assert rc == 2
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert len(lines) == 1, err
    assert re.search(pattern, lines[0]), lines[0]
    assert "Traceback" not in err


def test_bad_experiment_content_found_by_a_worker_is_an_input_error(simulated, tmp_path, capsys):
    """A file that passes the header check but breaks a rule of the format: exit 2 naming it."""
    import h5py

    bad = tmp_path / "bad.h5"
    shutil.copy(simulated / "sub1_m10_0.h5", bad)
    with h5py.File(bad, "r+") as f:
        t = f["imu/t"][...]
        t[100] = t[99]  # not strictly increasing
        f["imu/t"][...] = t
    manifest = _write(tmp_path / "campaign.toml",
                      '[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n[solver]\nsolvers = "factor-graph"\n'
                      '[[experiment]]\nfile = "bad.h5"\n')
    rc = main(["campaign", str(manifest), "--out", str(tmp_path / "out"), "--workers", "0", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2
    assert re.search(r"bad\.h5.*imu/t.*increasing", err), err


def test_campaign_cli_prints_a_summary(campaign_run, simulated, capsys):
    rc = main(["campaign", str(simulated / "campaign.toml"), "--out", str(campaign_run.out), "--workers", "0",
               "--quiet", "--no-report", "--validate", str(simulated / "validation.h5")])
    out = capsys.readouterr().out
    assert rc == 0
    assert "0 task(s) computed, 12 cached" in out
    assert re.search(r"validation validation\.h5: gyro max 0\.00\d+ deg/h \(static\).* -> pass", out)


@pytest.mark.skipif(os.environ.get("GRAPH_CALIB_SKIP_DEMO") == "1", reason="demo skipped by environment")
def test_demo_runs_campaign_and_diagnose(tmp_path, capsys):
    """``graph-calib demo --out DIR`` (cli.md) with 72-s subranges, in process: exit 0 and every file it promises;
    the diagnosis, on the 20..30 degC subrange simulated again (0.2 h, the shortest the demo diagnoses) with
    accel.bias_dtdt, finds that effect and the error against the truth falls.

    About 30 s on two free cores: the report's figures, then the diagnosis (the twelve solver runs take a few
    seconds).
    """
    from graph_calib.sensors.effects import FURTHER_EFFECTS

    out = tmp_path / "demo"
    rc = main(["demo", "--out", str(out), "--hours", "0.02", "--workers", "0"])
    stdout = capsys.readouterr().out
    assert rc == 0, stdout
    # the simulated campaign: six subranges with their truth, the manifest, an independent validation record
    data = out / "data"
    stems = sorted(p.stem for p in data.glob("sub*.h5"))
    assert len(stems) == 6
    for stem in stems:
        truth = io.read_result(data / f"{stem}.truth.json")
        assert "gyro.bias.x" in truth.values
    exp = io.read_experiment(data / f"{stems[0]}.h5")
    assert exp.t[-1] - exp.t[0] + 1.0 / exp.rate_hz == pytest.approx(0.02 * 3600.0, rel=1e-3)  # --hours honoured
    assert (data / "campaign.toml").is_file() and (data / "validation.h5").is_file()
    io.read_result(data / "validation.truth.json")
    # what graph-calib campaign writes
    doc = json.loads((out / "campaign" / "campaign.json").read_text())
    assert doc["format"] == "imu-calibration-campaign" and len(doc["experiments"]) == 6
    assert not doc["failed"] and doc["timing"]["tasks_computed"] == 12
    for e in doc["experiments"]:
        folder = out / "campaign" / e["name"]
        for s in ("sqrt-kf", "factor-graph"):
            assert io.read_result(folder / f"{s}.json").solver == s
        assert json.loads((folder / "comparison.json").read_text())["summary"]["agree"], e["name"]
    assert doc["validation"][0]["reference_kind"] == "truth"
    html = (out / "campaign" / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 10 and not re.search(r'src="(?!data:)', html)
    # the diagnosed record: the 20..30 degC subrange of the same IMU simulated again with accel.bias_dtdt
    planted = data / "with_accel_bias_dtdt"
    truth = io.read_result(planted / "sub4_20_30.truth.json")
    assert "accel.bias_dtdt.x" in truth.values
    assert "accel.bias_dtdt.x" not in io.read_result(data / "sub4_20_30.truth.json").values
    exp = io.read_experiment(planted / "sub4_20_30.h5")
    assert exp.t[-1] - exp.t[0] + 1.0 / exp.rate_hz == pytest.approx(0.2 * 3600.0, rel=1e-3)
    # what graph-calib diagnose writes, on the 20..30 degC subrange by default (cli.md's minimum content)
    diag = json.loads((out / "diagnosis" / "diagnosis.json").read_text())
    assert diag["format"] == "imu-calibration-diagnosis" and diag["version"] == 1
    assert diag["source"] == "sub4_20_30.h5"
    assert isinstance(diag["added"], list) and set(diag["added"]) <= set(FURTHER_EFFECTS)
    assert isinstance(diag["unexplained"], bool)
    for k in ("before", "after"):
        assert isinstance(diag[k]["residual_rms"], dict) and diag[k]["residual_rms"]
    assert (out / "diagnosis" / "report.html").is_file()
    # the closed loop finds the planted effect, and the calibration gets closer to the truth
    assert diag["added"][:1] == ["accel.bias_dtdt"]
    before = diag["before"]["error_vs_truth"]["factor-graph"]["rms_z"]
    after = diag["after"]["error_vs_truth"]["factor-graph"]["rms_z"]
    assert before > 5.0 and after < 2.0
    line = next(ln for ln in stdout.splitlines() if ln.startswith("diagnosis: added"))
    assert "accel.bias_dtdt (score" in line and f"{before:.2f} -> {after:.2f} sigma" in line
    assert "(found)" in line
    assert "demo finished" in stdout and "diagnose: ->" in stdout
    assert not list(out.rglob(".*.tmp"))


def test_existing_dask_cluster_by_address(simulated, tmp_path):
    import logging

    from distributed import LocalCluster

    manifest = _small_manifest(simulated, tmp_path / "m")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.ERROR) as cluster:
        run = run_campaign(manifest, tmp_path / "out",
                           options=CampaignOptions(scheduler=cluster.scheduler_address, report=False, progress=False))
    assert run.document["timing"]["tasks_computed"] == 3 and not run.failed


def test_unreachable_scheduler_is_an_input_error(simulated, tmp_path, capsys, monkeypatch):
    from graph_calib.campaign import execution

    warmed = []
    monkeypatch.setattr(execution, "warm_kernels", lambda: warmed.append(1))
    manifest = _small_manifest(simulated, tmp_path / "m")
    rc = main(["campaign", str(manifest), "--out", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9",
               "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "--scheduler: cannot connect to the Dask scheduler" in err
    assert not warmed   # the address is tried first: a wrong one does not wait for a warm-up (minutes when cold)
    assert not (tmp_path / "out").exists()      # and the refused run leaves no empty output folder
    rc = main(["campaign", str(manifest), "--out", str(tmp_path / "out"), "--scheduler", "notanaddress", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "--scheduler: not a scheduler address (tcp://HOST:PORT)" in err and "internal error" not in err
    rc = main(["campaign", str(manifest), "--out", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9",
               "--workers", "0", "--quiet"])
    assert rc == 2 and "--workers 0 runs without Dask, --scheduler on a Dask cluster" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_validation_record_without_truth_is_checked_against_its_own_calibration(simulated, tmp_path):
    lines = ['[imu]', 'id = "SIM-NAV 0001"', 'grade = "navigation"', '[solver]', 'solvers = "factor-graph"']
    for stem in ("sub2_0_10", "sub4_20_30", "sub5_30_40"):
        lines += ["[[experiment]]", f'file = "{simulated / (stem + ".h5")}"']
    manifest = _write(tmp_path / "campaign.toml", "\n".join(lines) + "\n")
    record = tmp_path / "held_out.h5"
    shutil.copy(simulated / "sub3_10_20.h5", record)  # held out of the campaign, no truth file next to it
    run = run_campaign(manifest, tmp_path / "out",
                       options=CampaignOptions(workers=0, progress=False, validate=(str(record),)))
    v = run.document["validation"][0]
    assert v["reference_kind"] == "estimate"
    assert (tmp_path / "out" / "validation" / "held_out" / "factor-graph.json").is_file()
    s = v["results"]["factor-graph"]["cubic"]
    assert "factor-graph estimate of held_out.h5" in s["reference"]
    # the held-out subrange's own estimate and the stitch of its neighbours agree within their uncertainty
    # (an 18-min subrange's own bias is only good to about 0.01 deg/h at its ends: no verdict on 0.01 here,
    # but a few times that at most: 0.025 deg/h with this seed, largest_z 1.8; the bound is twice that)
    assert s["gyro_criterion"] == "static windows"
    assert s["largest"]["gyro_radps"] * c.RS_TO_DH < 0.05
    assert s["largest"]["accel_mps2"] < 2e-4
    assert s["largest_z"]["gyro"] < 4.0 and s["largest_z"]["accel"] < 4.0
    assert "held_out.h5" in (tmp_path / "out" / "report.html").read_text()


def test_a_campaign_whose_tasks_fail_never_says_pass(simulated, tmp_path, monkeypatch, capsys):
    """Every task failing with an internal error: exit 1, and the verdict line says FAIL naming them (it said pass)."""
    from graph_calib.campaign import execution
    from graph_calib.cli import main

    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(execution, "build_problem", broken)
    manifest = _small_manifest(simulated, tmp_path / "m")
    capsys.readouterr()
    assert main(["campaign", str(manifest), "--out", str(tmp_path / "out"), "--workers", "0", "--no-report",
                 "--no-diagnose"]) == 1
    out, err = capsys.readouterr()
    assert "verdict: FAIL: 3 task(s) did not finish (sub2_0_10 factor-graph, sub3_10_20 factor-graph, " \
           "sub4_20_30 factor-graph): their errors follow" in out
    assert "verdict: pass" not in out
    assert "sub2_0_10 factor-graph failed: RuntimeError: boom" in err


def test_a_campaign_that_excludes_a_bias_runs_its_loop(simulated, tmp_path):
    """The loop's drivers act as biases: none on a triad whose bias the manifest leaves out (was a KeyError)."""
    manifest = _small_manifest(simulated, tmp_path / "m")
    text = manifest.read_text().replace('[solver]', '[model]\nexclude = ["gyro.bias"]\n\n[solver]')
    manifest.write_text(text)
    run = run_campaign(manifest, tmp_path / "out", options=CampaignOptions(workers=0, report=False, progress=False))
    assert not run.failed
    res = run.results[run.document["experiments"][0]["name"]]["factor-graph"]
    assert not any(k.startswith("gyro.bias.") for k in res.values)


def test_a_refused_campaign_leaves_no_output_folder(simulated, tmp_path):
    manifest = _small_manifest(simulated, tmp_path / "m")
    bogus = tmp_path / "m" / "notes.h5"
    bogus.write_text("not HDF5")
    manifest.write_text(manifest.read_text() + f'[[experiment]]\nfile = "{bogus}"\n')
    out = tmp_path / "out"
    with pytest.raises(InputError, match="not an HDF5 file"):
        run_campaign(manifest, out, options=CampaignOptions(workers=0, report=False, progress=False))
    assert not out.exists()


def test_the_local_cluster_s_processes_leave_ctrl_c_to_this_one():
    """Started inside, a process ignores SIGINT (Dask's nannies and workers each printed the traceback of their own
    KeyboardInterrupt before the clean 'interrupted' line); outside, the handler is this process's again."""
    import signal
    import subprocess
    import sys

    from graph_calib.campaign import execution

    probe = [sys.executable, "-c", "import signal; print(signal.getsignal(signal.SIGINT) is signal.SIG_IGN)"]
    # as an interactive run has it (a test run started in the background inherits SIGINT ignored)
    outer = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        before = signal.getsignal(signal.SIGINT)
        with execution._children_ignore_interrupt():
            inside = subprocess.run(probe, capture_output=True, text=True, check=True).stdout.strip()
        assert inside == "True"
        assert signal.getsignal(signal.SIGINT) is before
        assert subprocess.run(probe, capture_output=True, text=True, check=True).stdout.strip() == "False"
    finally:
        signal.signal(signal.SIGINT, outer)


def test_a_record_of_another_imu_is_refused_before_any_work(simulated, tmp_path, capsys):
    """A campaign calibrates one IMU: an experiment or validation record naming another is exit 2 (records of two
    units were calibrated and stitched together, and passed)."""
    manifest = _small_manifest(simulated, tmp_path / "m")
    manifest.write_text(manifest.read_text().replace('id = "SIM-NAV 0001"', 'id = "SIM-NAV 0009"'))
    rc = main(["campaign", str(manifest), "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "sub2_0_10.h5: imu_id: a record of IMU 'SIM-NAV 0001'; the manifest's [imu].id is " \
                       "'SIM-NAV 0009': a campaign calibrates one IMU" in err, err
    assert not (tmp_path / "out").exists()


def test_a_validation_record_that_is_one_of_the_experiments_is_refused(simulated, tmp_path, capsys):
    manifest = _small_manifest(simulated, tmp_path / "m")
    own = simulated / "sub3_10_20.h5"
    rc = main(["campaign", str(manifest), "--out", str(tmp_path / "out"), "--validate", str(own), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "--validate: is one of the campaign's experiments" in err, err
    assert not (tmp_path / "out").exists()
