"""Time the factor-graph calibrator on a 1.5 h, 100 Hz turntable record (run by hand).

Uses the exact-increment generator of tests/_synthetic.py with navigation-grade noise.
Prints: preintegration time, solve time, iterations.

    .venv/bin/python benchmarks/bench_factor_graph.py [--static-s S]

``--static-s`` (default 3300) is the static time of the record, most of its length.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from _report import report

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _synthetic import turntable_experiment  # noqa: E402

from graph_calib.calibrate import CalibrationOptions, build_problem  # noqa: E402
from graph_calib.sensors.params import Layout, grade  # noqa: E402
from graph_calib.solvers import solve  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--static-s", type=float, default=3300.0)
    args = parser.parse_args()

    nav = grade("navigation")
    layout = Layout.declared()
    rng = np.random.default_rng(0)
    x = rng.normal(size=layout.size) * nav.prior_vector(layout) * 0.1
    for n in ("mount", "lever_arm", "time_lag.table"):
        x[layout.slice(n)] = 0.0
    t0 = time.perf_counter()
    exp, _ = turntable_experiment(layout=layout, x=x, rng=rng, static_s=args.static_s, dwell_s=60.0,
                                  noise=(nav.gyro_noise, nav.accel_noise, nav.encoder_noise))
    t1 = time.perf_counter()
    print(f"generated {exp.n_samples} samples ({exp.n_samples / 360000:.2f} h) in {t1 - t0:.1f} s")
    problem = build_problem(exp)
    t2 = time.perf_counter()
    problem.model.preintegrate(problem.model.prior()[0])      # warm (numba compiled and cached)
    t3 = time.perf_counter()
    problem.model.preintegrate(problem.model.prior()[0])
    t4 = time.perf_counter()
    print(f"setup {t2 - t1:.2f} s, preintegration {t4 - t3:.3f} s")
    gr = solve("factor-graph", problem, options=CalibrationOptions())
    t5 = time.perf_counter()
    print(f"factor graph: {gr.iterations} iterations, {t5 - t4:.1f} s total, {problem.model.n_keyframes} keyframes")
    report("preintegrate_s", t4 - t3, "s", f"preintegration, {exp.n_samples:,} samples (warm)")
    report("solve_s", t5 - t4, "s", f"factor graph solve, {gr.iterations} iterations")


if __name__ == "__main__":
    main()
