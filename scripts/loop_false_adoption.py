"""The closed loop's false adoptions on clean simulated records at 0.3x, 1x and 3x the grade's noise (issue #21).

Issue #21 asks that the loop (:func:`graph_calib.diagnosis.diagnose`, ``alpha = 0.01`` for the whole decision)
adopt an effect on at most 1 % of clean records, 200 records or more, at every noise factor: true noise at 0.3,
1 and 3 times the declared (navigation) grade's densities.  Each run simulates ``nav-subrange-short`` for
``--hours`` with one seed and the case's ``noise_factor`` (the cases ``clean``, ``noise-0.3x`` and ``noise-3x``
of ``scripts/noise_monte_carlo.py``) and runs the loop on it as ``graph-calib diagnose EXPERIMENT --out DIR``
does with its default options: the grade chosen from the record's rests (:func:`choose_grade`, recorded),
keyframes of 1 s, ``T_ref`` from the record, every further effect a candidate, ``DiagnosisOptions()`` (alpha
0.01, at most 4 effects, the encompassing check, no held-out guard) with both default solvers.  What the
command does after the loop (the final model solved again with variance components, the files and the
report) decides nothing and is left out; so is the truth, which only gives the error against it.

Clean means that nothing outside the declared model is in the data: the temperature curves are exactly
linear (``curvature=False``; the simulator's default adds a small ``*_tc2`` curvature, an effect the loop
may rightly find) and no further effect is switched on, so every adopted effect is a false adoption.

The solvers: the rounds linearise at, test at and re-solve with the primary solver (the factor graph) only
(``diagnosis/loop.py``: ``_round``, ``_add_effect`` and ``diagnosis/decision.py`` take the primary's solution); the second
solver (the square-root filter) runs only in the stages before and after, which give the verdict and the
residual figures, not the decisions.  So ``--solvers factor-graph`` gives the same adoptions (checked: the
150 clean records of seeds 0-149 at 0.4 h rerun with the factor graph alone gave every round-1 statistic
identical and the same adoptions); the default keeps both (about 1 s more a record) so that the declared
model's verdict is ``diagnose``'s, solver comparison included.

Each record writes one JSON file ``OUT/CASE/seed-NNNN.json``: the effects adopted; per round the most
significant candidate (score statistic, chi-square threshold at ``alpha / m``, dof, log10 p), the significant
candidates, every tested candidate's and driver group's statistic, the encompassing checks and the decision in
words; the declared model's verdict (and the final model's when an effect was adopted), the grade chosen and
the seconds (simulation, loop, total).  A file that exists is not run again (the study resumes after an
interruption); ``--interleave`` runs seed by seed over the cases, so a study stopped early has equal counts.
The random generator of a record is ``numpy.random.default_rng(70_000 + CASE_OFFSET[case] + seed)``
(``noise_monte_carlo.py`` uses 50_000 + seed; each case has its own offset, so the three cases are independent
records, not one record's noise scaled): the same seed gives the same record and, on the same code, the same
decisions.  ``--summary`` prints per case: records, false adoptions (any adopted effect) with the rate, its 95 %
Clopper-Pearson interval (``scipy.stats.binomtest(...).proportion_ci()``) and the one-sided p-value of "rate <=
1 %", the adopted effects with their statistics, the largest round-1 statistic over its threshold, each
candidate's round-1 statistics against their chi-square null (the share below the unadjusted 5 % and 1 %
points, the mean statistic over dof, a Kolmogorov-Smirnov p), the verdicts and the time per record.

Usage::

    python scripts/loop_false_adoption.py --out /work/fa-study --cases clean,noise-0.3x,noise-3x --seeds 0:3 --hours 0.4
    nohup python scripts/loop_false_adoption.py --out /work/fa-study --seeds 0:200 --hours 0.4 --interleave \\
        > /work/fa-study/log 2>&1 &
    python scripts/loop_false_adoption.py --out /work/fa-study --summary
"""

import argparse
import collections
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

from graph_calib.diagnosis import DiagnosisOptions, diagnose
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.records.grade_choice import choose_grade
from graph_calib.simulation import simulate

from _seed_study import cases_of, run_resumable, seed_range  # scripts/: run as a script, its folder on sys.path

#: The cases: name -> the simulator's noise options (``noise_monte_carlo.py``'s names).
CASES = {
    "noise-0.3x": {"noise_factor": 0.3},
    "clean": {},
    "noise-3x": {"noise_factor": 3.0},
}

#: Each case's records come from their own seeds: ``SEED_BASE + CASE_OFFSET[case] + seed``.
SEED_BASE = 70_000
CASE_OFFSET = {"noise-0.3x": 0, "clean": 10_000, "noise-3x": 20_000}

#: The rate issue #21 allows.
TARGET = 0.01


def _candidate(t):
    return {"name": t.name, "statistic": float(t.statistic), "threshold": float(t.threshold), "dof": int(t.dof),
            "log10_p": float(t.log10_p), "significant": bool(t.significant)}


def _verdict(v):
    return {"passed": bool(v.passed), "problems": list(v.problems), "notes": list(v.notes),
            "agree": None if v.agree is None else bool(v.agree),
            "max_difference_sigma": None if v.max_difference_sigma is None else float(v.max_difference_sigma)}


def run_one(case, seed, *, hours, solvers=None):
    """One clean record of ``case`` through the loop as ``graph-calib diagnose`` runs it; a JSON-ready dict."""
    t0 = time.perf_counter()
    rng_seed = SEED_BASE + CASE_OFFSET[case] + seed
    se = simulate("nav-subrange-short", rng=np.random.default_rng(rng_seed), hours=hours, curvature=False,
                  **CASES[case]).run()[0]
    t_sim = time.perf_counter() - t0
    choice = choose_grade(se.experiment)                           # as the command does without --grade
    options = CalibrationOptions(model=ModelOptions(grade=choice.grade))
    dopts = DiagnosisOptions() if solvers is None else DiagnosisOptions(solvers=tuple(solvers))
    t1 = time.perf_counter()
    d = diagnose(se.experiment, options=options, diagnosis=dopts)
    t_loop = time.perf_counter() - t1
    rounds = []
    for r in d.rounds:
        tested = [t for t in r.candidates if not t.skipped]
        best = min(tested, key=lambda t: t.log10_p, default=None)
        rounds.append({
            "index": r.index, "added": r.added, "decision": r.decision, "n_tested": len(tested),
            "best": None if best is None else _candidate(best),
            "best_ratio": None if best is None else float(best.statistic / best.threshold),
            "significant": [_candidate(t) for t in tested if t.significant],
            "tested": [_candidate(t) for t in tested],
            "drivers": [{"group": t.group, "axis": t.axis, "statistic": float(t.statistic), "dof": int(t.dof),
                         "threshold": float(t.threshold), "log10_p": float(t.log10_p),
                         "significant": bool(t.significant)} for t in r.drivers],
            "checks": r.checks, "variance_factor": float(r.variance_factor),
            "chi2_per_dof": float(r.chi2_per_dof), "seconds": float(r.seconds)})
    sim = se.truth.extra["simulation"]
    out = {"case": case, "seed": seed, "rng_seed": rng_seed, "hours": hours,
           "duration_s": float(d.context["duration_s"]), "noise_factor": CASES[case].get("noise_factor", 1.0),
           "curvature": False, "simulated_noise": sim.get("noise"), "unmodelled": sim.get("unmodelled"),
           "grade": choice.grade, "grade_reason": choice.reason, "solvers": list(dopts.solvers),
           "added": list(d.added), "unexplained": bool(d.unexplained),
           "signature": [{"group": t.group, "axis": t.axis, "statistic": float(t.statistic),
                          "threshold": float(t.threshold)} for t in d.signature],
           "rounds": rounds, "verdict": _verdict(d.before.verdict),
           "verdict_after": _verdict(d.after.verdict) if d.added else None,
           "seconds_simulation": t_sim, "seconds_loop": t_loop}
    out["seconds"] = time.perf_counter() - t0
    return out


def _ci(k, n):
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    return ci.low, ci.high


def _null_table(first):
    """Round 1, each candidate's statistics against its chi-square null: the share of records above the
    unadjusted 5 % and 1 % points (0.05, 0.01 when the null holds), above the Bonferroni threshold, the mean
    statistic over the mean dof (1) and the Kolmogorov-Smirnov p-value of the p-values' uniformity."""
    if not first:
        return
    by = collections.defaultdict(list)
    for x in first:
        for t in x["tested"]:
            by[t["name"]].append(t)
    everything = [t for ts in by.values() for t in ts]
    p_all = stats.chi2.sf([t["statistic"] for t in everything], [t["dof"] for t in everything])
    ratio_all = np.mean([t["statistic"] for t in everything]) / np.mean([t["dof"] for t in everything])
    print(f"   round 1, every candidate test pooled ({len(everything)} tests): share with unadjusted p below 0.05 / "
          f"0.01 / 0.001: {np.mean(p_all < 0.05):.3f} / {np.mean(p_all < 0.01):.4f} / {np.mean(p_all < 0.001):.4f} "
          f"(the null's 0.05 / 0.01 / 0.001); mean statistic over mean dof {ratio_all:.3f} (null 1)")
    rows = []
    for name, ts in by.items():
        T = np.array([t["statistic"] for t in ts])
        dof = np.array([t["dof"] for t in ts])
        p = stats.chi2.sf(T, dof)
        rows.append((np.mean(p < 0.05), name, len(ts), np.mean(p < 0.01), np.mean(T > [t["threshold"] for t in ts]),
                     T.mean() / dof.mean(), stats.kstest(p, "uniform").pvalue, sorted(set(dof.tolist()))))
    print("   round 1 per candidate (null: p<0.05 0.05, p<0.01 0.01, mean T / dof 1):")
    for share5, name, m, share1, above, ratio, ks, dofs in sorted(rows, reverse=True):
        print(f"      {name:22s} {m:4d} records, dof {dofs}: p<0.05 {share5:.3f}, p<0.01 {share1:.3f}, "
              f"above threshold {above:.3f}, mean T / dof {ratio:.2f}, KS p {ks:.2g}")


def summarise(root):
    """Print each case's figures from the files under ``root``."""
    pooled_k = pooled_n = 0
    for case in CASES:
        files = sorted((root / case).glob("seed-*.json"))
        if not files:
            continue
        runs = [json.loads(f.read_text()) for f in files]
        n = len(runs)
        k = sum(bool(r["added"]) for r in runs)
        pooled_k, pooled_n = pooled_k + k, pooled_n + n
        lo, hi = _ci(k, n)
        p_above = stats.binomtest(k, n, TARGET, alternative="greater").pvalue
        hours = sorted({r["hours"] for r in runs})
        print(f"\n== {case}: {n} records ({', '.join(f'{h:g}' for h in hours)} h, seeds "
              f"{runs[0]['seed']}..{runs[-1]['seed']}, solvers {'+'.join(runs[0]['solvers'])})")
        print(f"   false adoptions {k} / {n} = {100 * k / n:.2f} %, 95 % Clopper-Pearson "
              f"{100 * lo:.2f}..{100 * hi:.2f} %; one-sided p of 'rate <= {100 * TARGET:g} %' {p_above:.3g}")
        adopted = collections.Counter(e for r in runs for e in r["added"])
        print(f"   adopted effects: {dict(adopted) if adopted else 'none'}")
        for r in runs:
            if r["added"]:
                why = "; ".join(f"round {x['index']}: {x['decision']}" for x in r["rounds"] if x["added"])
                print(f"      seed {r['seed']}: {why}")
        mimics = [r["seed"] for r in runs if not r["added"] and any(x["significant"] for x in r["rounds"])]
        print(f"   records with a significant candidate not adopted (encompassing check): {len(mimics)}"
              + (f" (seeds {mimics})" if mimics else ""))
        first = [r["rounds"][0] for r in runs if r["rounds"][0]["best"] is not None]
        ratios = np.array([x["best_ratio"] for x in first])
        top = max(first, key=lambda x: x["best_ratio"])
        best_names = collections.Counter(x["best"]["name"] for x in first)
        print(f"   round 1, most significant candidate's statistic / threshold: median {np.median(ratios):.2f}, "
              f"max {ratios.max():.2f} ({top['best']['name']} {top['best']['statistic']:.1f} vs "
              f"{top['best']['threshold']:.1f}, {top['best']['dof']} dof); most often {best_names.most_common(3)}")
        p1 = np.array([10.0 ** x["best"]["log10_p"] * x["n_tested"] for x in first])
        print(f"   round 1, Bonferroni p of the most significant candidate below 0.05 / 0.01: "
              f"{np.mean(p1 < 0.05):.3f} / {np.mean(p1 < 0.01):.3f}")
        _null_table([x for x in first if "tested" in x])
        unexplained = sum(r["unexplained"] for r in runs)
        grades = collections.Counter(r["grade"] for r in runs)
        passed = sum(r["verdict"]["passed"] for r in runs)
        print(f"   declared model's verdict passed {passed} / {n}; driver signatures left (unexplained) {unexplained}; "
              f"grades {dict(grades)}")
        problems = collections.Counter(p.split(":")[0] for r in runs for p in r["verdict"]["problems"])
        if problems:
            print(f"      verdict problems: {dict(problems)}")
        sec = np.array([r["seconds"] for r in runs])
        print(f"   seconds per record: median {np.median(sec):.1f}, mean {sec.mean():.1f} (loop "
              f"{np.median([r['seconds_loop'] for r in runs]):.1f}, simulation "
              f"{np.median([r['seconds_simulation'] for r in runs]):.1f}), total {sec.sum() / 60:.1f} min")
    if pooled_n:
        lo, hi = _ci(pooled_k, pooled_n)
        print(f"\n== all cases: false adoptions {pooled_k} / {pooled_n} = {100 * pooled_k / pooled_n:.2f} %, "
              f"95 % Clopper-Pearson {100 * lo:.2f}..{100 * hi:.2f} %")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    p.add_argument("--seeds", type=seed_range, default=range(0, 200), help="A:B, the seeds A..B-1")
    p.add_argument("--hours", type=float, default=0.3, help="record length, h (the scenario's default 0.3)")
    p.add_argument("--solvers", default=None,
                   help="comma-separated, the primary first (default DiagnosisOptions': both default solvers)")
    p.add_argument("--interleave", action="store_true",
                   help="seed by seed over the cases (equal counts per case at any time) instead of case by case")
    p.add_argument("--summary", action="store_true")
    args = p.parse_args(argv)
    if args.summary:
        summarise(args.out)
        return 0
    cases = cases_of(p, args.cases, CASES)
    solvers = args.solvers.split(",") if args.solvers else None
    order = ([(c, s) for s in args.seeds for c in cases] if args.interleave
             else [(c, s) for c in cases for s in args.seeds])

    def line(case, seed, record):
        b = record["rounds"][0]["best"]
        return (f"{case} seed {seed}: added {', '.join(record['added']) or 'nothing'}"
                + (f" (round 1 best {b['name']} {b['statistic']:.1f} vs {b['threshold']:.1f})" if b else "")
                + f", verdict {'pass' if record['verdict']['passed'] else 'FAIL'}, {record['seconds']:.1f} s")

    run_resumable(args.out, order, lambda case, seed: run_one(case, seed, hours=args.hours, solvers=solvers), line)
    return 0

if __name__ == "__main__":
    sys.exit(main())
