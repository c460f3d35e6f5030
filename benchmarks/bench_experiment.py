"""Time one navigation-grade 1.5 h, 100 Hz experiment end to end (run by hand).

Simulate (nav-subrange), write, read, integrate attitude, then both solvers.
    .venv/bin/python benchmarks/bench_experiment.py
"""

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from graph_calib import io
from graph_calib.calibrate import build_problem, compare, run_factor_graph, run_sqrt_kf
from graph_calib.simulation import simulate
from graph_calib.strapdown import integrate_attitude


def timed(label, fn):
    t = time.perf_counter()
    out = fn()
    print(f"{label:34s} {time.perf_counter() - t:7.2f} s")
    return out


def main():
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    sim = simulate("nav-subrange", rng=np.random.default_rng(0))
    (exp, truth), = timed("simulate 1.5 h at 100 Hz", sim.pairs)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "exp.h5"
        timed("write experiment", lambda: io.write_experiment(exp, path))
        exp = timed("read (and validate) experiment", lambda: io.read_experiment(path))
    integrate_attitude(exp.dtheta[:1000], t=exp.t[:1000], rate_hz=exp.rate_hz, q_nb0=np.array([1.0, 0, 0, 0]),
                       latitude_rad=exp.latitude_rad)
    timed("integrate attitude", lambda: integrate_attitude(exp.dtheta, t=exp.t, rate_hz=exp.rate_hz,
                                                           q_nb0=np.array([1.0, 0, 0, 0]),
                                                           latitude_rad=exp.latitude_rad))
    problem = timed("set up model + alignment", lambda: build_problem(exp))
    timed("preintegrate (first call compiles or loads)", lambda: problem.model.preintegrate(problem.model.prior()[0]))
    graph, gr = timed("factor graph solve", lambda: run_factor_graph(problem))
    kf, fr = timed("square-root filter solve", lambda: run_sqrt_kf(problem))
    print(f"  factor graph iterations {gr.iterations}, filter passes {len(fr.passes)}")
    print("  agreement:", compare(kf, graph)["summary"])


if __name__ == "__main__":
    main()
