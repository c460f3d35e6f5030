"""Time the square-root filter on a simulated navigation-grade record.

Run by hand (not a test)::

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_kf.py [--hours 1.5] [--rate-hz 100] [--seed 3]

Simulates ``nav-subrange`` (1.5 h at 100 Hz by default: 540,000 samples, 5,400
keyframes of 1 s, 40 calibration states), then calibrates it and prints, per
pass, the seconds spent in the shared model (preintegration and factors) and in
the filter (the square-root recursion and the attitude smoother).
"""

import argparse
import time

import numpy as np
from _report import report

from graph_calib.calibrate import CalibrationOptions, build_problem
from graph_calib.simulation import simulate
from kf_reference import calibrate


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.5)
    parser.add_argument("--rate-hz", type=float, default=100.0)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()

    se = simulate("nav-subrange", rng=np.random.default_rng(args.seed), hours=args.hours,
                  rate_hz=args.rate_hz).run()[0]
    problem = build_problem(se.experiment, options=CalibrationOptions(t_ref_degC=se.truth.t_ref_degC))
    model = problem.model
    calibrate(model, q_nb0=problem.q_nb0, max_passes=1)          # compile (or load) the kernels
    print(f"{se.experiment.n_samples} samples, {model.n_keyframes} keyframes, {model.layout.size} states + 3, "
          f"{model.record.reading_sample.size} encoder readings")
    t0 = time.perf_counter()
    fr = calibrate(model, q_nb0=problem.q_nb0)
    total = time.perf_counter() - t0
    n = se.experiment.n_samples
    for p in fr.passes:
        both = p.seconds_model + p.seconds_filter
        print(f"pass {p.index}: model {p.seconds_model:.3f} s, filter {p.seconds_filter:.3f} s "
              f"({n / p.seconds_filter / 1e6:.2f} M samples/s; with the model's linearisation "
              f"{n / both / 1e6:.2f} M samples/s), step {p.max_dx_sigma:.3g} sigma")
    print(f"{fr.n_passes} passes after {fr.initial_iterations} attitude-only iteration(s), "
          f"converged {fr.converged}, {total:.2f} s in all (with preintegration, step control and covariance: "
          f"{n * fr.n_passes / total / 1e6:.2f} M samples/s per pass)")
    best = min(fr.passes, key=lambda p: p.seconds_filter)
    report("filter_pass_s", best.seconds_filter, "s", f"filter and smoother, fastest of {fr.n_passes} passes, "
           f"{n:,} samples")
    report("filter_rate", n / best.seconds_filter / 1e6, "M samples/s", "filter and smoother rate")
    report("calibrate_s", total, "s", f"whole calibration, {fr.n_passes} passes")


if __name__ == "__main__":
    main()
