"""Monte Carlo of the campaign on drawn cubic truths (issue 23's done-means), one seed after the other, resumable.

Run by hand (heavy: per seed a simulation of 6 subranges and a 2 h sweep record, then a whole campaign with the
loop and the joint solver; minutes per seed at 1.5 h, more at 3 h; run it ``nice``'d on a shared machine)::

    PYTHONPATH=. .venv/bin/python benchmarks/campaign_cubic_seeds.py 1 2 3 [--hours 1.5] [--out /tmp/cubic-mc]
                                                                     [--workers 1] [--again]

Per seed ``S`` it simulates ``nav-campaign-cubic`` (six subranges over -10..+50 degC, every bias and scale factor
of both triads a cubic in its own sensor's temperature, each sensor lagging the chamber) with
``numpy.random.default_rng(S)`` into ``OUT/h<hours>/seed-S/data`` and an independent 2 h record sweeping the whole
range (20 Hz, seed ``S + 1000``), then runs ``graph-calib campaign MANIFEST --out .../run --validate SWEEP.h5``
as a command (its real exit code) and writes ``metrics.json`` beside it: per subrange and solver the share of
elements within 3 sigma of the truth and the RMS normalised error of the final result, the joint curves' share
of points within 2 sigma and largest |z| against the truth curves, each validation check, the campaign's
checks that failed, the exit code, the campaign's time.

Beside the final results' figures, those of the results the joint curvature wave started from
(``before_joint_wave``: what the campaign reported before that wave carried the joint's curvature).

Resumable: a seed whose ``metrics.json`` exists is only read back (``--again`` runs the campaign again, its
task cache reusing finished work; ``--no-run`` recomputes the metrics from the ``campaign.json`` on disk); a
simulation already on disk is reused; an interrupted campaign resumes from its cached tasks.  Seeds can run
in parallel as separate processes (each its own folder).  At the end one table over every seed asked for, with
each done-means figure (per subrange >= 99 % within 3 sigma and RMS <= 1.2, both solvers; joint >= 90 % within
2 sigma and none beyond 4; validation of the stitched and the joint calibration met), and ``summary.json``;
then per solver every seed's final per-subrange results pooled, each figure beside what a right model gives
(:func:`pooled_lines`: the per-result bar is out of a right model's reach over many results).
Exit status 1 when a seed misses one of them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.special import chdtrc

from graph_calib import io
from graph_calib.campaign.loop import truth_errors
from graph_calib.campaign.truth import truth_path
from graph_calib.evaluation.validation import simulate_validation_record
from graph_calib.simulation import simulate, write_simulation

#: The issue's done-means.
SUB_WITHIN_3 = 0.99
SUB_RMS = 1.2
JOINT_WITHIN_2 = 0.90
JOINT_MAX = 4.0
SCENARIO = "nav-campaign-cubic"


def _simulate(data, *, hours, seed):
    """The campaign's six experiments and the sweep record, simulated once into ``data``."""
    if (data / "campaign.toml").is_file() and (data / "validation.truth.json").is_file():
        return 0.0
    t0 = time.perf_counter()
    sim = simulate(SCENARIO, rng=np.random.default_rng(seed), hours=hours)
    write_simulation(sim, data)
    se = simulate_validation_record(sim, hours=2.0, rate_hz=20.0, seed=seed + 1000)
    io.write_experiment(se.experiment, data / "validation.h5")
    io.write_result(se.truth, data / "validation.truth.json")
    return time.perf_counter() - t0


def _campaign(data, run_dir, *, workers):
    """``graph-calib campaign`` as a command: its exit code and seconds (its output in ``campaign.log``)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "graph_calib.cli", "campaign", str(data / "campaign.toml"), "--out", str(run_dir),
           "--validate", str(data / "validation.h5"), "--workers", str(workers), "--no-report"]
    t0 = time.perf_counter()
    with open(run_dir.parent / "campaign.log", "w", encoding="utf-8") as log:
        rc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=os.environ.copy(), check=False).returncode
    return rc, time.perf_counter() - t0


def before_joint_wave(doc, run_dir):
    """Per subrange and solver, the truth errors of the results the joint curvature wave started from.

    For each experiment the wave re-solved, its results before it (the last earlier wave's folder, or its own),
    against its truth file (:func:`graph_calib.campaign.loop.truth_errors`): what the campaign reported before
    the joint's curvature was carried.
    """
    out = {}
    for e in doc["experiments"]:
        entries = (e.get("loop") or {}).get("pooled") or []
        if not any(a.get("kind") == "joint" for a in entries):
            continue
        earlier = [a["wave"] for a in entries if a.get("kind") != "joint"]
        folder = run_dir / e["name"] / "pooled" / str(max(earlier)) if earlier else run_dir / e["name"]
        truth = io.read_result(truth_path(e["file"]))
        for s in e["results"]:
            p = folder / f"{s}.json"
            if p.is_file():
                te = truth_errors(io.read_result(p), truth)
                if te:
                    out.setdefault(e["name"], {})[s] = te
    return out


def metrics(doc, *, exit_code, seconds):
    """The done-means figures of one campaign from its ``campaign.json`` content."""
    subs = {}
    for e in doc["experiments"]:
        for s, err in ((e.get("loop") or {}).get("error_vs_truth") or {}).items():
            a = (err or {}).get("after")
            if a:
                subs.setdefault(e["name"], {})[s] = {k: a[k] for k in ("fraction_within_3sigma", "rms_z", "max_abs_z",
                                                                       "worst", "n")}
    joint = ((doc.get("joint") or {}).get("joint") or {})
    tc = joint.get("truth_check") or {}
    checks = (doc.get("campaign_checks") or {}).get("checks") or []
    validation = {c["check"]: {"passed": c["passed"], "text": c["text"]} for c in checks
                  if c["check"].startswith("validation")}
    sub_ok = bool(subs) and all(m["fraction_within_3sigma"] >= SUB_WITHIN_3 and m["rms_z"] <= SUB_RMS
                                for per in subs.values() for m in per.values())
    joint_ok = bool(tc.get("points")) and tc["fraction_within_2sigma"] >= JOINT_WITHIN_2 and tc["max_abs_z"] <= JOINT_MAX
    val_ok = bool(validation) and all(v["passed"] for v in validation.values())
    return {"exit_code": exit_code, "seconds": seconds, "subranges": subs,
            "joint": {"fraction_within_2sigma": tc.get("fraction_within_2sigma"), "max_abs_z": tc.get("max_abs_z"),
                      "points": tc.get("points"), "worst": (tc.get("worst") or {}).get("element"),
                      "degrees": joint.get("degrees")},
            "validation": validation, "failed_checks": (doc.get("verdict") or {}).get("campaign_checks_failed", []),
            "carried": [w["adopted"]["effect"] for w in ((doc.get("loop") or {}).get("pooled") or {}).get("waves", [])
                        if w.get("adopted")],
            "ok": {"subranges": sub_ok, "joint": joint_ok, "validation": val_ok}}


def _worst(per_subrange):
    """The lowest share within 3 sigma, the largest RMS and |z| over every subrange and solver."""
    subs = [x for per in per_subrange.values() for x in per.values()]
    if not subs:
        return "-"
    return (f"{100 * min(x['fraction_within_3sigma'] for x in subs):.1f} / {max(x['rms_z'] for x in subs):.2f} / "
            f"{max(x['max_abs_z'] for x in subs):.2f}")


def pooled_lines(all_m):
    """Per solver, the final per-subrange results of every seed pooled, beside what a right model gives.

    The per-result bar (every result >= 99 % within 3 sigma and RMS <= 1.2) is out of reach of a right model
    over many results (with 39 elements, "99 %" means none beyond 3 sigma: 0.9973**39 = 0.90 per result); the
    pooled share within 3 sigma, the pooled RMS and the number of results with RMS above 1.2 are the figures
    to judge the sigmas by, each beside its expectation for a right model (Gaussian errors, unit variance).
    """
    out = []
    p_beyond = float(chdtrc(1, 9.0))        # P(|z| > 3) of a unit Gaussian
    solvers = sorted({s for m in all_m.values() for per in m["subranges"].values() for s in per})
    for s in solvers:
        res = [per[s] for m in all_m.values() for per in m["subranges"].values() if s in per]
        n = np.array([r["n"] for r in res], dtype=float)
        beyond = sum(round((1.0 - r["fraction_within_3sigma"]) * r["n"]) for r in res)
        rms = float(np.sqrt(np.sum(n * np.array([r["rms_z"] for r in res]) ** 2) / n.sum()))
        high = sum(r["rms_z"] > SUB_RMS for r in res)
        p_high = np.array([chdtrc(k, SUB_RMS**2 * k) for k in n])
        literal = sum(r["fraction_within_3sigma"] >= SUB_WITHIN_3 and r["rms_z"] <= SUB_RMS for r in res)
        out.append(f"{s}: {len(res)} results, {int(n.sum())} elements: {100 * (1 - beyond / n.sum()):.2f} % within "
                   f"3 sigma ({beyond} beyond; a right model {p_beyond * n.sum():.1f}), RMS {rms:.3f} (a right "
                   f"model 1 +- {1 / np.sqrt(2 * n.sum()):.3f}), RMS above {SUB_RMS:g} in {high} results (a right "
                   f"model {p_high.sum():.1f}); the per-result bar met by {literal} of {len(res)} (a right model "
                   f"about {np.sum((1 - p_beyond) ** n * (1 - p_high)):.0f})")
    return out


def _row(seed, m):
    j = m["joint"]
    val = "pass" if m["ok"]["validation"] else "FAIL"
    before = _worst(m.get("before_joint_wave") or {})
    return (f"| {seed} | {_worst(m['subranges'])} | {before} | {100 * (j['fraction_within_2sigma'] or 0):.0f} | "
            f"{j['max_abs_z'] or float('nan'):.2f} | {val} | {m['exit_code']} | {m['seconds']:.0f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seeds", type=int, nargs="+")
    ap.add_argument("--hours", type=float, default=1.5)
    ap.add_argument("--out", default="/tmp/cubic-mc")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--again", action="store_true", help="run the campaign again (its task cache still used)")
    ap.add_argument("--no-run", action="store_true",
                    help="recompute the metrics from the campaign.json on disk (its exit code from the verdict)")
    args = ap.parse_args(argv)
    root = Path(args.out) / f"h{args.hours:g}"
    all_m = {}
    for seed in args.seeds:
        sd = root / f"seed-{seed}"
        mfile = sd / "metrics.json"
        if mfile.is_file() and not (args.again or args.no_run):
            all_m[seed] = json.loads(mfile.read_text())
            print(f"seed {seed}: read back {mfile}", flush=True)
            continue
        doc_file = sd / "run" / "campaign.json"
        if args.no_run:
            if not doc_file.is_file():
                print(f"seed {seed}: no campaign.json yet", flush=True)
                continue
            old = json.loads(mfile.read_text()) if mfile.is_file() else {}
            doc = json.loads(doc_file.read_text())
            rc = old.get("exit_code", 0 if doc["verdict"]["passed"] else 3)
            t_sim, sec, load = old.get("simulation_seconds"), old.get("seconds", float("nan")), old.get("load_average")
        else:
            t_sim = _simulate(sd / "data", hours=args.hours, seed=seed)
            rc, sec = _campaign(sd / "data", sd / "run", workers=args.workers)
            load = os.getloadavg()
            if not doc_file.is_file():
                print(f"seed {seed}: the campaign wrote no campaign.json (exit {rc}); see {sd / 'campaign.log'}",
                      flush=True)
                continue
            doc = json.loads(doc_file.read_text())
        m = metrics(doc, exit_code=rc, seconds=sec)
        m["before_joint_wave"] = before_joint_wave(doc, sd / "run")
        m["simulation_seconds"] = t_sim
        m["load_average"] = load
        mfile.write_text(json.dumps(m, indent=1))
        all_m[seed] = m
        print(f"seed {seed}: exit {rc}, {sec:.0f} s", flush=True)
    print(f"\n{SCENARIO}, 6 x {args.hours:g} h; per subrange: the lowest share within 3 sigma (%), the largest RMS "
          f"normalised error and |z| over 6 subranges x 2 solvers, of the final results and of those the joint "
          f"curvature wave re-solved, before it; joint: share of the truth-curve points within 2 sigma, largest |z|")
    print("| seed | final: within 3 sigma min % / RMS max / max abs z | before the joint wave (re-solved ones) | "
          "joint within 2 sigma % | joint max abs z | validation | exit | campaign s |\n|---|---|---|---|---|---|---|---|")
    for seed, m in all_m.items():
        print(_row(seed, m))
    for line in pooled_lines(all_m):
        print(line)
    for seed, m in all_m.items():
        for t in m["failed_checks"]:
            print(f"  seed {seed} failed: {t}")
    ok = bool(all_m) and all(all(m["ok"].values()) for m in all_m.values())
    (root / "summary.json").write_text(json.dumps({str(k): v for k, v in all_m.items()}, indent=1))
    print(f"{'every seed meets the done-means' if ok else 'SOME SEED MISSES A DONE-MEANS FIGURE'}; "
          f"-> {root / 'summary.json'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
