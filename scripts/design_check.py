"""Confirm a designed program against the truth: simulate it, calibrate with both solvers, validate.

``PYTHONPATH=. python scripts/design_check.py PROGRAM.toml [PROGRAM.toml ...] [--seeds 3]``

For each program and seed (noise, every declared error and the curved temperature truth on): both solvers'
calibration of the record, their agreement, and the remaining sensor errors of each against the truth over
the record's windows (:mod:`graph_calib.evaluation.validation`: the largest static gyro error and the largest
accelerometer error), beside the predicted bound (:mod:`graph_calib.design.prediction`).  docs/design.md
records the figures.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from graph_calib import constants as c
from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.design.prediction import predict
from graph_calib.simulation.program import program_simulation, read_program
from graph_calib.solvers.registry import DEFAULT_SOLVERS
from graph_calib.evaluation.validation import ResultCalibration, validate


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("programs", nargs="+")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--first-seed", type=int, default=100)
    args = p.parse_args(argv)
    for path in args.programs:
        prog = read_program(path)
        print(f"{prog.name}: {prog.duration_s / 60:.1f} min")
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            t0 = time.perf_counter()
            se = program_simulation(prog, rng=np.random.default_rng(seed)).run()[0]
            opts = CalibrationOptions(t_ref_degC=se.truth.t_ref_degC)
            problem = build_problem(se.experiment, options=opts)
            b = predict(problem).bound.summary()
            run = solve_problem(problem, options=opts, solvers=DEFAULT_SOLVERS)
            cmp = run.comparison["summary"] if run.comparison else None
            line = [f"  seed {seed}: predicted gyro {max(b['gyro_radps']['bound']) * c.RS_TO_DH:.4f} deg/h, "
                    f"accel {max(b['accel_mps2']['bound']):.1e} m/s^2;"]
            for s in DEFAULT_SOLVERS:
                v = validate(se.experiment, ResultCalibration(run.results[s]), se.truth).summary()
                g = v["largest"]["gyro_radps"] * c.RS_TO_DH
                a = v["largest"]["accel_mps2"]
                line.append(f"{s} gyro {g:.4f} deg/h accel {a:.1e} ({'pass' if v['pass']['all'] else 'FAIL'}, "
                            f"{'converged' if run.outputs[s].converged else 'NOT converged'});")
            if cmp:
                line.append(f"solvers max diff {cmp['max_abs_difference_in_sigma']:.2e} sigma, "
                            f"agree {cmp['agree']}; {time.perf_counter() - t0:.0f} s")
            print(" ".join(line), flush=True)


if __name__ == "__main__":
    main()
