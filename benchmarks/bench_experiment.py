"""Time one navigation-grade 1.5 h, 100 Hz experiment end to end (run by hand).

Simulate (nav-subrange), write, read, integrate attitude, then both solvers.
    .venv/bin/python benchmarks/bench_experiment.py [--hours H]

``--hours`` shortens the record (default: the scenario's 1.5 h).
"""

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from _report import report

from graph_calib import io
from graph_calib.calibrate import CalibrationOptions, build_problem
from graph_calib.solvers import compare, solve, to_result
from graph_calib.simulation import simulate
from graph_calib.navigation.strapdown import integrate_attitude


SECONDS = {}


def timed(label, fn, key=None):
    t = time.perf_counter()
    out = fn()
    el = time.perf_counter() - t
    print(f"{label:34s} {el:7.2f} s")
    if key:
        SECONDS[key] = (label, el)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=None, help="record length, h (default: the scenario's 1.5)")
    args = parser.parse_args()

    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    options = {} if args.hours is None else {"hours": args.hours}
    sim = simulate("nav-subrange", rng=np.random.default_rng(0), **options)
    (exp, truth), = timed(f"simulate {args.hours or 1.5:g} h at 100 Hz", sim.pairs, "simulate_s")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "exp.h5"
        timed("write experiment", lambda: io.write_experiment(exp, path))
        exp = timed("read (and validate) experiment", lambda: io.read_experiment(path))
    integrate_attitude(exp.dtheta[:1000], t=exp.t[:1000], rate_hz=exp.rate_hz, q_nb0=np.array([1.0, 0, 0, 0]),
                       latitude_rad=exp.latitude_rad)
    timed("integrate attitude", lambda: integrate_attitude(exp.dtheta, t=exp.t, rate_hz=exp.rate_hz,
                                                           q_nb0=np.array([1.0, 0, 0, 0]),
                                                           latitude_rad=exp.latitude_rad))
    problem = timed("set up model + alignment", lambda: build_problem(exp), "setup_s")
    timed("preintegrate (first call compiles or loads)", lambda: problem.model.preintegrate(problem.model.prior()[0]))
    opts = CalibrationOptions()
    gr = timed("factor graph solve", lambda: solve("factor-graph", problem, options=opts), "graph_s")
    fr = timed("square-root filter solve", lambda: solve("sqrt-kf", problem, options=opts), "filter_s")
    print(f"  factor graph iterations {gr.iterations}, filter passes {fr.iterations}")
    summary = compare(to_result(problem.model, fr), to_result(problem.model, gr))["summary"]
    print("  agreement:", summary)
    for key, (label, seconds) in SECONDS.items():
        report(key, seconds, "s", label)
    report("agreement_sigma", summary["max_abs_difference_in_sigma"], "sigma", "filter vs graph, max |difference|")


if __name__ == "__main__":
    main()
