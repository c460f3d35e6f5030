"""Where ``graph-calib calibrate`` spends its time on the Xsens session (51,175 samples; run by hand).

    .venv/bin/python benchmarks/bench_xsens_calibrate.py [--repeat N]

The session is imported from ``../shared/data/real/imu_tk_xsens`` into a temporary file, then the
command is timed whole (``python -m graph_calib.cli calibrate``, a fresh process, kernels from the
on-disk cache: warm), and its parts in this process: start-up (importing the command and building its
parser, in a fresh process), reading, the grade choice, ``build_problem`` (static detection, alignment,
the plausibility check, the model), each solver (seconds, iterations, preintegrations), both at once as
the command runs them (``solve_pair``: the filter in a forked worker), the variance components (the
primary solver's solves, ``solvers/variance.py``), the structure tests at the solution
(``diagnosis/structure.py``) and writing.
Figures in docs/performance.md, 'calibrate on the Xsens session'.
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import report

from graph_calib import io
from graph_calib.calibrate import build_problem
from graph_calib.records.grade_choice import choose_grade
from graph_calib.importers import import_xsens
from graph_calib.model import CalibrationModel
from graph_calib.options import CalibrationOptions, ModelOptions
from graph_calib.solvers import solve, to_result
from graph_calib.solvers.concurrent import solve_pair
from graph_calib.solvers.registry import PRIMARY_SOLVER
from graph_calib.solvers.variance import estimate_variance_components
from graph_calib.diagnosis.structure import structure_tests
from graph_calib.model.calibration_model import reusing_preintegrations
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real" / "imu_tk_xsens"
STARTUP = ("import time; t = time.perf_counter(); from graph_calib.cli import build_parser; "
           "build_parser(only='calibrate'); print(time.perf_counter() - t)")


def timed(label, fn):
    t = time.perf_counter()
    out = fn()
    el = time.perf_counter() - t
    print(f"{label:40s} {el:7.2f} s")
    return out, el


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1, help="whole-command runs (the best is reported)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "xsens.h5"
        io.write_experiment(import_xsens(REAL / "xsens_acc.mat", REAL / "xsens_gyro.mat"), path)
        whole, cpu = [], []
        for _ in range(args.repeat):
            load = os.getloadavg()[0]
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t = time.perf_counter()
            rc = subprocess.run([sys.executable, "-m", "graph_calib.cli", "calibrate", str(path), "--out",
                                 str(Path(d) / "out")], cwd=ROOT, capture_output=True).returncode
            whole.append(time.perf_counter() - t)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
            print(f"{'graph-calib calibrate (exit %d)' % rc:40s} {whole[-1]:7.2f} s  (CPU {cpu[-1]:.2f} s, "
                  f"load average {load:.2f})")
        start = float(subprocess.run([sys.executable, "-c", STARTUP], cwd=ROOT, capture_output=True, text=True,
                                     check=True).stdout)
        print(f"{'start-up (import, parser)':40s} {start:7.2f} s")
        exp, t_read = timed("read the experiment", lambda: io.read_experiment(path))
        choice, t_grade = timed("grade choice", lambda: choose_grade(exp))
        opts = CalibrationOptions(model=ModelOptions(grade=choice.grade))
        problem, t_build = timed("build_problem", lambda: build_problem(exp, options=opts))
        calls = {"n": 0}
        original = CalibrationModel.preintegrate

        def counting(self, *a, **k):
            calls["n"] += 1
            return original(self, *a, **k)

        CalibrationModel.preintegrate = counting
        solved = {}
        for s in ("sqrt-kf", "factor-graph"):
            calls["n"] = 0
            out, el = timed(s, lambda: solve(s, problem, options=opts))
            print(f"  {out.iterations} iterations, {calls['n']} preintegrations, converged {out.converged}")
            solved[s] = (out, el, calls["n"])
        CalibrationModel.preintegrate = original
        _, t_pair = timed("both at once (solve_pair)", lambda: solve_pair(("sqrt-kf", "factor-graph"), problem,
                                                                         options=opts))
        with reusing_preintegrations(), threadpool_limits(limits=1, user_api="blas"):     # as calibrate runs them
            vc, t_vc = timed("variance components", lambda: estimate_variance_components(
                problem, options=opts, solver=PRIMARY_SOLVER))
            print(f"  {vc.solves} solves, converged {vc.converged}")
            _, t_structure = timed("structure tests", lambda: structure_tests(vc.problem, solved[PRIMARY_SOLVER][0]))
        _, t_write = timed("results written", lambda: [io.write_result(to_result(problem.model, o),
                                                                       Path(d) / f"{s}.json")
                                                       for s, (o, _, _) in solved.items()])
    report("calibrate_s", min(whole), "s", "graph-calib calibrate, Xsens session, both solvers, warm")
    report("calibrate_cpu_s", min(cpu), "s", "its CPU time (the command and its forked worker)")
    report("startup_s", start, "s", "start-up: import and parser of calibrate")
    report("build_s", t_build, "s", "build_problem")
    for s, (o, el, n) in solved.items():
        report(f"{s}_s", el, "s", f"{s} solve ({o.iterations} iterations, {n} preintegrations)")
    report("both_at_once_s", t_pair, "s", "both solvers at once, the filter in a forked worker (calibrate's way)")
    report("variance_components_s", t_vc, "s", f"variance components ({vc.solves} solves of {PRIMARY_SOLVER})")
    report("structure_tests_s", t_structure, "s", "structure tests at the solution (one linearisation)")


if __name__ == "__main__":
    main()
