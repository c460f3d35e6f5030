"""The Xsens session against IMU-TK's figures (issue #13): defaults, hold-out, shortened records.

Usage::

    PYTHONPATH=. python scripts/xsens_targets.py [--cuts] [--sweep STEP] [--out FILE.json]

Runs, as ``graph-calib calibrate`` does with no options (grade chosen from the data,
both solvers, the verdict), on the Xsens MTi session of ``../shared/data/real/imu_tk_xsens``:

- **in-sample**: IMU-TK's figures (:mod:`graph_calib.evaluation.imu_tk`) of the default
  calibration and of IMU-TK's own fit, over IMU-TK's static intervals;
- **hold-out**: both fitted on the record up to the end of the 20th static interval,
  figures over the 18 transitions after it (the full record);
- ``--cuts``: the record cut to 26,103, 27,591, 28,455 and 30,000 rows (and, with
  ``--sweep STEP``, every STEP rows from 20,000): per cut, whether both solvers
  converged and agree, the verdict and what the exit code would be (0 or 3).

Prints one line per run; ``--out`` writes the figures as JSON (docs/measured-data.md).
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from graph_calib.calibrate import build_problem, solve_problem
from graph_calib.compensation.calibration import Calibration
from graph_calib.records.grade_choice import choose_grade
from graph_calib.importers import import_xsens
from graph_calib.evaluation.imu_tk import imu_tk_fit, imu_tk_static_intervals, transition_figures
from graph_calib.options import CalibrationOptions, ModelOptions

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "imu_tk_xsens"
CUTS = (26103, 27591, 28455, 30000)
HOLD_OUT_POSES = 20


def load():
    return import_xsens(REAL / "xsens_acc.mat", REAL / "xsens_gyro.mat")


def default_run(exp, *, effects=()):
    """``graph-calib calibrate`` with no options (``--effect`` for ``effects``): (grade choice, run, seconds)."""
    t0 = time.perf_counter()
    choice = choose_grade(exp)
    opts = CalibrationOptions(model=ModelOptions(grade=choice.grade, extra_effects=tuple(effects)))
    run = solve_problem(build_problem(exp, options=opts), options=opts)
    return choice, run, time.perf_counter() - t0


def figures(exp, cal, intervals, which=None):
    fig = transition_figures(exp, cal, intervals=intervals)
    rms, med, mx = fig.transitions_deg(which)
    norm = fig.static_norm if which is None else fig.static_norm[which[0]:]
    return {"static_std_mps2": float(np.std(norm)), "transitions_rms_deg": rms,
            "transitions_median_deg": med, "transitions_max_deg": mx}


def summary(run):
    v = run.verdict
    return {"converged": dict(v.converged), "agree": v.agree, "max_difference_sigma": v.max_difference_sigma,
            "fit_chi2": dict(v.fit_chi2), "passed": v.passed, "exit": 0 if v.passed else 3,
            "verdict": v.text()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cuts", action="store_true")
    ap.add_argument("--sweep", type=int, default=0)
    ap.add_argument("--effect", action="append", default=[])
    ap.add_argument("--skip-main", action="store_true")
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    exp = load()
    out = {"effects": list(args.effect)}
    intervals, mult = imu_tk_static_intervals(exp)
    out["intervals"] = {"count": int(intervals.shape[0]), "threshold_mult": mult}
    if not args.skip_main:
        ref, _ = imu_tk_fit(exp)
        out["imu_tk"] = figures(exp, ref, intervals)
        choice, run, sec = default_run(exp, effects=args.effect)
        out["defaults"] = {"grade": choice.grade, "reason": choice.reason, "seconds": sec, **summary(run),
                           **{s: figures(exp, Calibration.from_result(r), intervals)
                              for s, r in run.results.items()}}
        print("imu_tk", out["imu_tk"])
        print("defaults", out["defaults"])
        # hold-out: fit on the record up to the end of the 20th interval, test on the transitions after it
        k = HOLD_OUT_POSES - 1
        cut = exp.slice(0, int(intervals[k, 1]) + 1)
        which = np.arange(k, intervals.shape[0] - 1)
        ref_h, _ = imu_tk_fit(cut)
        _, run_h, sec_h = default_run(cut, effects=args.effect)
        out["hold_out"] = {"transitions": int(which.size), "imu_tk": figures(exp, ref_h, intervals, which),
                           **summary(run_h),
                           **{s: figures(exp, Calibration.from_result(r), intervals, which)
                              for s, r in run_h.results.items()}}
        print("hold-out", out["hold_out"])
    if args.cuts or args.sweep:
        rows = set(CUTS) if args.cuts else set()
        if args.sweep:
            rows |= set(range(20000, exp.n_samples, args.sweep))
        out["cuts"] = {}
        for n in sorted(rows):
            _, run_c, sec_c = default_run(exp.slice(0, n))
            s = summary(run_c)
            s["seconds"] = sec_c
            # what must hold: exit 3, or both solvers converged and agree
            s["honest"] = bool(s["exit"] == 3 or (all(s["converged"].values()) and s["agree"]))
            out["cuts"][n] = s
            print(n, s["verdict"], f"{sec_c:.0f} s")
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
