"""The full-length check of the closed loop: the 6 x 3 h navigation-grade campaign with temperature curvature.

Run by hand (heavy: the simulation about 80 s, each campaign minutes)::

    PYTHONPATH=. .venv/bin/python benchmarks/campaign_loop_full.py [--out /tmp/loop-full] [--hours 3]
                                                                  [--cubic-scale 2] [--seed 11] [--workers 2]

Simulates ``nav-campaign`` (six subranges over -10..50 degC, ``--hours`` each at 100 Hz) with a cubic term in the
bias curves (``--cubic-scale`` times the grade's typical size, :mod:`graph_calib.simulation.truth`) and an
independent 2 h record sweeping the whole range (20 Hz), then runs the campaign twice from a cold cache: without
the loop (``diagnose=False``) and with it (the default: every experiment's own loop, then the campaign's pooled
score tests and their waves).  Prints, per subrange and solver, the error against the truth of the declared
parameters (RMS normalised error, share within 3 sigma, largest) without and with the loop, with the effects each
experiment's loop added and those the pooled test adopted; the pooled decisions; the stitched curves against the
truth curves; validation; the two campaign times (with the loop: the first wave and the pooled waves apart).  docs/campaign.md and
docs/performance.md record what it measured.  Done means (issue 11): after the loop every subrange result of
both solvers has >= 95 % of its elements within 3 sigma and RMS normalised error <= 1.3, validation leaves at
most 0.01 deg/h and 2e-4 m/s^2, the linear model alone is 4 sigma or more off somewhere, and the campaign with
the loop takes at most twice the time of the campaign without it.  Exit status 1 when one of those fails.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from _report import report

from graph_calib import constants as c
from graph_calib import io
from graph_calib.campaign import CampaignOptions, run_campaign
from graph_calib.campaign.loop import truth_errors
from graph_calib.simulation import simulate, write_simulation
from graph_calib.evaluation.validation import simulate_validation_record


def _simulate(out, *, hours, cubic_scale, seed):
    data = out / "data"
    if (data / "campaign.toml").is_file() and (data / "validation.truth.json").is_file():
        print(f"reusing the simulation in {data}", flush=True)
        return data
    t0 = time.perf_counter()
    sim = simulate("nav-campaign", rng=np.random.default_rng(seed), hours=hours, cubic_scale=cubic_scale)
    write_simulation(sim, data)
    se = simulate_validation_record(sim, hours=2.0, rate_hz=20.0, seed=seed + 1)
    io.write_experiment(se.experiment, data / "validation.h5")
    io.write_result(se.truth, data / "validation.truth.json")
    print(f"simulated in {time.perf_counter() - t0:.0f} s", flush=True)
    return data


def _campaign(data, out, *, diagnose, workers):
    t0 = time.perf_counter()
    run = run_campaign(data / "campaign.toml", out, options=CampaignOptions(
        workers=workers, diagnose=diagnose, force=True, progress=True, validate=(str(data / "validation.h5"),)))
    return run, time.perf_counter() - t0


def _errors(run):
    """``{experiment: {solver: truth_errors}}`` of a run's results (the chosen models)."""
    return {name: {s: truth_errors(r, run.truths[name]) for s, r in res.items()} for name, res in run.results.items()}


def _adoption(a):
    """One campaign-level adoption in words: a pooled test's figures, or a carried joint curve (no statistic)."""
    if a.get("statistic") is None:
        return f"; {a.get('kind') or 'carried'}: {a['effect']}"
    return (f"; pooled: {a['effect']} ({a['kind']} {a['statistic']:.1f} > {a['threshold']:.1f}, "
            f"{a['dof']} dof, log10 p {a['log10_p']:.1f})")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="/tmp/loop-full")
    ap.add_argument("--hours", type=float, default=3.0)
    ap.add_argument("--cubic-scale", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    out = Path(args.out)
    data = _simulate(out, hours=args.hours, cubic_scale=args.cubic_scale, seed=args.seed)
    plain, t_plain = _campaign(data, out / "no-loop", diagnose=False, workers=args.workers)
    looped, t_loop = _campaign(data, out / "loop", diagnose=True, workers=args.workers)
    e_plain, e_loop = _errors(plain), _errors(looped)
    ok = True
    worst_linear = 0.0
    print("\nper subrange and solver: error vs truth, RMS z / share within 3 sigma / max |z|, without -> with the loop")
    for e in looped.document["experiments"]:
        name = e["name"]
        added = ", ".join(a["effect"] for a in e["loop"]["added"]) or "nothing"
        added += "".join(_adoption(a) for a in e["loop"].get("pooled") or [])
        for s in ("factor-graph", "sqrt-kf"):
            a, b = e_plain[name][s], e_loop[name][s]
            worst_linear = max(worst_linear, a["max_abs_z"])
            good = b["fraction_within_3sigma"] >= 0.95 and b["rms_z"] <= 1.3
            ok &= good
            print(f"  {name:12s} {s:12s} {a['rms_z']:.2f} / {100 * a['fraction_within_3sigma']:.0f} % / "
                  f"{a['max_abs_z']:.1f} ({a['worst']}) -> {b['rms_z']:.2f} / {100 * b['fraction_within_3sigma']:.0f} % "
                  f"/ {b['max_abs_z']:.1f}  [{'ok' if good else 'FAIL'}]  added: {added}")
    ok &= worst_linear >= 4.0
    pooled = looped.document["loop"].get("pooled") or {}
    for w in pooled.get("waves", []):
        best = ", ".join(f"{t['effect']} ({t['kind']}) {t['statistic']:.1f} vs {t['threshold']:.1f} [{t['dof']} dof]"
                         for t in w["tests"][:3])
        print(f"  pooled score test {w['wave']}: {w['decision']}\n      most significant: {best}")
    tim = looped.document["timing"]
    print(f"  time with the loop: first wave (every experiment's own loop) {tim['tasks_seconds']:.0f} s, pooled waves "
          f"{tim.get('pooled_seconds', 0.0):.0f} s ({pooled.get('tasks_computed', 0)} tasks), total {tim['total_seconds']:.0f} s")
    print(f"  the linear (declared) model alone: worst {worst_linear:.1f} sigma (needs >= 4 to be a test)")
    summary = {"hours": args.hours, "cubic_scale": args.cubic_scale, "seed": args.seed, "workers": args.workers,
               "seconds": {"no_loop": t_plain, "loop": t_loop}, "errors": {"no_loop": e_plain, "loop": e_loop},
               "linear_worst_z": worst_linear, "pooled": pooled,
               "timing": {"no_loop": plain.document["timing"], "loop": tim}}
    for label, run in (("without", plain), ("with", looped)):
        tc = run.document["truth_check"]["factor-graph"]["cubic"]
        print(f"stitched cubic vs truth curves ({label} the loop): max |z| {tc['max_abs_z']:.2f}, RMS z {tc['rms_z']:.2f}, "
              f"{100 * tc['fraction_within_2sigma']:.0f} % within 2 sigma ({tc['reference']})")
        summary[f"truth_check_{label}"] = {s: run.document["truth_check"][s]["cubic"] for s in run.stitched}
        for v in run.document["validation"]:
            for s, r in (v.get("results") or {}).items():
                r = r["cubic"]
                g, acc = r["largest"]["gyro_radps"], r["largest"]["accel_mps2"]
                print(f"validation ({label} the loop, {s}): gyro max {g * c.RS_TO_DH:.4f} deg/h, accel max {acc:.2e} "
                      f"m/s^2 -> {'pass' if r['pass']['all'] else 'FAIL'}")
                summary.setdefault(f"validation_{label}", {})[s] = r["largest"]
                if label == "with":
                    ok &= bool(r["pass"]["all"])
    ratio = t_loop / t_plain
    ok &= ratio <= 2.0
    print(f"campaign time: {t_plain:.0f} s without the loop, {t_loop:.0f} s with it (x{ratio:.2f}, target <= 2)")
    report("campaign_no_loop_s", t_plain, "s", f"campaign 6 x {args.hours:g} h without the loop")
    report("campaign_loop_s", t_loop, "s", f"campaign 6 x {args.hours:g} h with the loop")
    report("loop_ratio", ratio, "", "campaign time with the loop over without")
    summary["ok"] = bool(ok)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    print(f"{'all done-means figures hold' if ok else 'SOME FIGURE FAILS'}; -> {out / 'summary.json'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
