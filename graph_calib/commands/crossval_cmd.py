"""``graph-calib crossval EXPERIMENT.h5 --out DIR``: the calibration judged on poses it did not see.

Cuts the record's rests into folds (graph_calib.evaluation.crossval), calibrates without each fold
(``calibrate``, or the closed loop with ``--diagnose``) and prints IMU-TK's figures on the held-out
fold beside the raw samples' figures; writes ``crossval.json``.  Exit 3 when the calibration is worse
than none on the held-out poses.
"""

from __future__ import annotations

import sys
from pathlib import Path

from graph_calib import io
from graph_calib.calibrate import calibrate, calibrate_with_effects
from graph_calib.commands.calibrate_cmd import options_from_args
from graph_calib.commands.model_options import add_bench_options, finite_float, with_gyro_range
from graph_calib.commands.paths import make_output_folder, output_folder
from graph_calib.compensation.calibration import Calibration
from graph_calib.diagnosis import DiagnosisOptions, diagnose
from graph_calib.errors import InputError
from graph_calib.evaluation.crossval import cross_validate, crossval_table
from graph_calib.records.grade_choice import choose_grade
from graph_calib.solvers.registry import DEFAULT_SOLVERS


def add_arguments(p):
    p.add_argument("experiment", help="experiment file (HDF5, data-format.md): a multi-position record")
    p.add_argument("--out", required=True, help="output folder (crossval.json)")
    p.add_argument("--folds", type=int, default=2, help="number of folds (default 2)")
    p.add_argument("--by", choices=("pairs", "rests", "segments", "transitions", "faces"), default="pairs",
                   help="what is held out: consecutive pairs of rests in turn (default), contiguous blocks of rests, "
                        "whole segments of /imu/segment, only the rotations between rests, or only those between two "
                        "faces, every full turn kept (a Ferraris session judged as imucal never fits it; "
                        "docs/crossval.md)")
    p.add_argument("--solver", choices=DEFAULT_SOLVERS, default=DEFAULT_SOLVERS[-1],
                   help=f"the solver whose result is judged (default {DEFAULT_SOLVERS[-1]})")
    p.add_argument("--diagnose", action="store_true",
                   help="calibrate each fold with the closed loop (diagnose) instead of the declared model")
    p.add_argument("--grade", choices=("navigation", "tactical", "consumer"), default=None,
                   help="IMU grade (default: chosen from the whole record's rests, printed with the reason)")
    p.add_argument("--keyframe", type=finite_float, default=1.0, help="keyframe interval, s (default 1.0)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME",
                   help="model a further effect of model.md (repeatable)")
    p.add_argument("--t-ref", type=finite_float, default=None, help="reference temperature, degC")
    p.add_argument("--robust", choices=("huber", "cauchy"), default=None, help="robust loss (factor graph)")
    add_bench_options(p)


def run(args):
    path = Path(args.experiment)
    if not path.exists():
        raise InputError("no such file", path=path)
    if args.folds < 2:
        raise InputError("must be at least 2", dataset="--folds")
    options_from_args(args)                       # bad arguments refused before the file is read
    out = output_folder(args.out)
    exp = with_gyro_range(args, io.read_experiment(path))
    grade = args.grade
    if grade is None:
        choice = choose_grade(exp, keyframe_s=args.keyframe)
        print(f"grade: {choice.reason}")
        grade = choice.grade
    options = options_from_args(args, grade=grade)
    solver = args.solver

    def fit(train):
        if args.diagnose:
            diag = diagnose(train, options=options, diagnosis=DiagnosisOptions(solvers=(solver,)))
            # what graph-calib diagnose writes: the final model solved again as calibrate solves it (variance
            # components), not the loop's own stage, which tests on the identified noise unscaled
            result = calibrate_with_effects(train, added=diag.added, options=options, solvers=(solver,)).results[
                solver] if options.variance_components else diag.after.results[solver]
            print(f"  loop added: {', '.join(diag.added) or 'nothing'}", file=sys.stderr)
        else:
            run_ = calibrate(train, options=options, solvers=(solver,))
            result = run_.results[solver]
            print(f"  {run_.verdict.text()}", file=sys.stderr)
        return Calibration.from_result(result)

    cv = cross_validate(exp, fit=fit, folds=args.folds, by=args.by,
                        progress=lambda line: print(line, file=sys.stderr))
    make_output_folder(out)
    doc = {**cv.to_json(), "source": path.name, "solver": solver, "grade": grade, "diagnose": bool(args.diagnose)}
    io.atomic_write_json(out / "crossval.json", doc)
    print(crossval_table(cv))
    pooled, folds = cv.worse_than_raw(), cv.folds_worse_than_raw()
    if pooled or folds:
        where = ([f"pooled: {', '.join(pooled)}"] if pooled else []) + \
            [f"fold {i + 1}: {', '.join(w)}" for i, w in folds]
        hint = ""
        if args.by in ("rests", "pairs") and any("static_norm_std_mps2" in w for _, w in folds):
            # a held-out face is one the accelerometer calibration never saw (docs/crossval.md)
            hint = (" (these folds hold out whole rests, so each fold's accelerometer calibration has not seen the "
                    "faces it is judged on; --by transitions keeps every rest in training and judges the motions)")
        print(f"verdict: FAIL: on the held-out poses the calibration is worse than the raw samples ("
              f"{'; '.join(where)}){hint} -> {out / 'crossval.json'}")
        return 3
    print("verdict: pass: on the held-out poses the calibration is no worse than the raw samples in any figure "
          f"(within 2 %) -> {out / 'crossval.json'}")
    return 0
