"""Time :meth:`graph_calib.model.CalibrationModel.preintegrate` per sample (run by hand).

    .venv/bin/python benchmarks/bench_preintegration.py [--static-s S] [--dwell-s D] [--repeat R]

The record is the exact-increment turntable experiment of tests/_synthetic.py with
navigation-grade errors and noise; the defaults give the 538,000-sample (1.5 h)
record of benchmarks/bench_factor_graph.py.  For the declared model and for the
declared model with every further effect, prints the best of ``R`` calls, in
microseconds per sample, with 1 and 2 numba threads (and all threads when the
machine has more), after a warm-up call that compiles or loads the kernel.
"""

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numba
import numpy as np
from _report import report

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _synthetic import turntable_experiment  # noqa: E402

from graph_calib.model import CalibrationModel, ModelOptions  # noqa: E402
from graph_calib.sensors.effects import FURTHER_EFFECTS
from graph_calib.sensors.params import Layout, grade  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--static-s", type=float, default=3300.0)
    parser.add_argument("--dwell-s", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    nav = grade("navigation")
    layout = Layout.declared()
    rng = np.random.default_rng(0)
    x_true = rng.normal(size=layout.size) * nav.prior_vector(layout) * 0.1
    for n in ("mount", "lever_arm", "time_lag.table"):
        x_true[layout.slice(n)] = 0.0
    exp, _ = turntable_experiment(layout=layout, x=x_true, rng=rng, static_s=args.static_s, dwell_s=args.dwell_s,
                                  noise=(nav.gyro_noise, nav.accel_noise, nav.encoder_noise))
    n = exp.n_samples
    print(f"machine: {platform.machine()} {platform.processor() or ''} cpus={os.cpu_count()}, "
          f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
          f"threading layer {numba.config.THREADING_LAYER}")
    print(f"record: {n} samples ({n / exp.rate_hz / 3600:.2f} h at {exp.rate_hz:g} Hz)")
    threads = sorted({1, min(2, numba.config.NUMBA_NUM_THREADS), numba.config.NUMBA_NUM_THREADS})
    for key, label, extra in (("declared", "declared", ()), ("further", "all further effects", FURTHER_EFFECTS)):
        model = CalibrationModel(exp, options=ModelOptions(extra_effects=extra))
        x = model.prior()[0] + rng.normal(size=model.layout.size) * model.prior()[1] * 0.1
        t0 = time.perf_counter()
        preint = model.preintegrate(x)
        warm = time.perf_counter() - t0
        assert np.all(np.isfinite(preint.J_S)) and np.all(np.isfinite(preint.reading_J))
        cols = model.terms.columns.size
        print(f"{label}: {model.layout.size} parameters, {cols} kernel columns, {model.n_keyframes} keyframes, "
              f"{model.record.reading_sample.size} encoder readings; first call {warm:.2f} s")
        for nt in threads:
            numba.set_num_threads(nt)
            best = np.inf
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                model.preintegrate(x)
                best = min(best, time.perf_counter() - t0)
            print(f"  {nt} thread{'s' if nt > 1 else ' '}: {best * 1e6 / n:6.3f} us/sample "
                  f"({best:.3f} s per call)")
            report(f"{key}_{nt}t", best * 1e6 / n, "us/sample",
                   f"preintegrate, {label}, {nt} thread{'s' if nt > 1 else ''}, best of {args.repeat}")
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


if __name__ == "__main__":
    main()
