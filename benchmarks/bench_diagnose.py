"""Wall time of the closed loop (``diagnose``) on the 1.5 h navigation-grade record (run by hand).

    .venv/bin/python benchmarks/bench_diagnose.py [--hours H] [--solvers both|factor-graph]

Simulates ``effect-accel.bias_dtdt`` at the length of ``nav-subrange`` (a further effect for the loop to
find), then times :func:`graph_calib.diagnosis.diagnose`: the declared model's solve, one round of score
tests per added effect, the re-solve, the final round.  The same script runs on an older checkout
(``PYTHONPATH=OTHER python benchmarks/bench_diagnose.py``) for a before/after figure.
"""

import argparse
import os
import time

import numpy as np
from _report import report

from graph_calib.calibrate import CalibrationOptions
from graph_calib.diagnosis import DiagnosisOptions, diagnose
from graph_calib.simulation import simulate


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.5, help="record length, h (default 1.5)")
    parser.add_argument("--solvers", choices=("both", "factor-graph"), default="factor-graph")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    se = simulate("effect-accel.bias_dtdt", rng=np.random.default_rng(0), hours=args.hours).run()[0]
    solvers = ("factor-graph", "sqrt-kf") if args.solvers == "both" else ("factor-graph",)
    opts = CalibrationOptions()
    # warm the compiled kernels on a short record so that compilation is not timed
    short = simulate("effect-accel.bias_dtdt", rng=np.random.default_rng(1), hours=0.02).run()[0]
    diagnose(short.experiment, options=opts, diagnosis=DiagnosisOptions(solvers=solvers))
    t0 = time.perf_counter()
    d = diagnose(se.experiment, options=opts, diagnosis=DiagnosisOptions(solvers=solvers))
    seconds = time.perf_counter() - t0
    rounds = [r.seconds for r in d.rounds]
    print(f"diagnose {args.hours:g} h ({se.experiment.n_samples} samples): {seconds:.1f} s, added {d.added}, "
          f"rounds {', '.join(f'{s:.1f}' for s in rounds)} s")
    report("diagnose_s", seconds, "s", f"diagnose {args.hours:g} h, {'+'.join(solvers)}")
    report("rounds_s", sum(rounds), "s", "score-test rounds (linearise the extended model, tests)")


if __name__ == "__main__":
    main()
