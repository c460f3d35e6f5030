"""``graph-calib diagnose EXPERIMENT.h5 --out DIR``: the closed loop of residual analysis.

Calibrates with the declared model (both solvers), tests every further effect
of model.md against the residuals, adds the most significant one and repeats
until none is significant; reports what was added and why, the residuals
before and after and, when a simulator's truth file lies beside the experiment
(``<stem>.truth.json``) or is given with ``--truth``, the error against it.
Writes ``diagnosis.json`` and ``report.html`` (docs/diagnosis.md).
"""

from __future__ import annotations

import argparse

import sys
from dataclasses import replace
from pathlib import Path

from graph_calib.commands.model_options import (add_bench_options, bench_options, check_gyro_range, finite_float,
                                                 with_gyro_range)
from graph_calib.commands.paths import earlier_results, make_output_folder
from graph_calib.errors import InputError
from graph_calib.records.grade_choice import choose_grade, grade_warning
from graph_calib.commands.calibrate_cmd import solver_choice
from graph_calib.solvers import registry


def add_arguments(p):
    p.add_argument("experiment", help="experiment file (HDF5, data-format.md)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    add_bench_options(p)
    p.add_argument("--holdout", action=argparse.BooleanOptionalAction, default=True,
                   help="without a table, adopt an effect only when it does not make the held-out figures (two "
                        "folds of the rests) worse (default; --no-holdout adopts on the score tests alone; "
                        "docs/diagnosis.md)")
    p.add_argument("--grade", choices=("navigation", "tactical", "consumer"), default=None,
                   help="IMU grade for priors and noise (default: chosen from the static intervals, printed with "
                        "the reason)")
    p.add_argument("--keyframe", type=finite_float, default=1.0, help="keyframe interval, s (default 1.0)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME",
                   help="a further effect of model.md in the model from the start, not tested (repeatable)")
    p.add_argument("--t-ref", type=finite_float, default=None, help="reference temperature, degC")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="false-alarm probability of each decision (default 0.01, Bonferroni over the tests)")
    p.add_argument("--max-added", type=int, default=4, help="most effects added (default 4)")
    p.add_argument("--max-iterations", type=int, default=None,
                   help="Levenberg-Marquardt iterations of the factor graph (default: GraphOptions'; hand-held "
                        "sessions may need 100 or more)")
    p.add_argument("--solver", type=solver_choice, default=registry.BOTH, metavar="SOLVERS",
                   help=f"solvers run before and after: {registry.choice_help()} (default {registry.BOTH}); the "
                        f"tests use the first in the diagnosis' order ({registry.PRIMARY_SOLVER} when given)")
    p.add_argument("--truth", default=None,
                   help="truth file (result layout); default <stem>.truth.json beside the experiment if present")
    p.add_argument("--no-truth", action="store_true", help="ignore a truth file beside the experiment")


def _options(args, *, grade="navigation"):
    from graph_calib.diagnosis import DiagnosisOptions
    from graph_calib.sensors.effects import FURTHER_EFFECTS
    from graph_calib.model import ModelOptions
    from graph_calib.options import CalibrationOptions, GraphOptions

    check_gyro_range(args)
    for e in args.effect:
        if e not in FURTHER_EFFECTS:
            raise InputError(f"unknown effect {e!r}; known: {', '.join(FURTHER_EFFECTS)}", dataset="--effect")
    if not args.keyframe > 0:
        raise InputError("must be positive", dataset="--keyframe")
    if not 0.0 < args.alpha < 1.0:
        raise InputError("must be between 0 and 1", dataset="--alpha")
    if args.max_added < 0:
        raise InputError("must not be negative", dataset="--max-added")
    graph = GraphOptions()
    if args.max_iterations is not None:
        if args.max_iterations < 1:
            raise InputError("must be at least 1", dataset="--max-iterations")
        graph = GraphOptions(max_iterations=args.max_iterations)
    calibration_options = CalibrationOptions(model=ModelOptions(keyframe_s=args.keyframe, grade=args.grade or grade,
                                                 extra_effects=tuple(args.effect), **bench_options(args)),
                                             graph=graph, t_ref_degC=args.t_ref)
    solvers = registry.primary_first(registry.parse_choice(args.solver)[0])
    diagnosis_options = DiagnosisOptions(alpha=args.alpha, max_added=args.max_added, solvers=solvers,
                                         holdout=args.holdout)
    return calibration_options, diagnosis_options


def _truth(args, path):
    from graph_calib import io

    if args.no_truth:
        return None, None
    tp = Path(args.truth) if args.truth else path.with_name(path.name[:-3] + ".truth.json" if path.name.endswith(".h5")
                                                              else path.name + ".truth.json")
    if args.truth is None and not tp.exists():
        return None, None
    if not tp.exists():
        raise InputError("no such file", path=tp, dataset="--truth")
    return io.read_result(tp), tp


def run(args):
    from graph_calib import io
    from graph_calib.calibrate import calibrate_with_effects
    from graph_calib.diagnosis import diagnose, residual_rms
    from graph_calib.reports.diagnosis_report import write_report

    path = Path(args.experiment)
    if not path.exists():
        raise InputError("no such file", path=path)
    _options(args)                                # bad arguments refused before the file is read
    exp = with_gyro_range(args, io.read_experiment(path))
    choice = None
    if args.grade is None:
        choice = choose_grade(exp, keyframe_s=args.keyframe)
        print(f"grade: {choice.reason}")
    elif warning := grade_warning(exp, args.grade, keyframe_s=args.keyframe):
        print(warning, file=sys.stderr)
    calibration_options, diagnosis_options = _options(args, grade=choice.grade if choice else "navigation")
    truth, tp = _truth(args, path)
    out = Path(args.out)
    make_output_folder(out)

    def say(msg):
        print(f"  {msg}", file=sys.stderr)

    print(f"{path.name}: {exp.n_samples} samples, {exp.t[-1] - exp.t[0] + 1 / exp.rate_hz:.0f} s"
          + (f"; truth {tp.name}" if tp else ""), file=sys.stderr)
    diag = diagnose(exp, options=calibration_options, diagnosis=diagnosis_options, truth=truth, progress=say)
    # the calibration the loop ends with, as calibrate writes it: each solver's result, the comparison, the verdict
    final = dict(diag.after.results)
    comparison, verdict = diag.after.comparison, diag.after.verdict
    if calibration_options.variance_components:
        # the final model solved again with one variance factor per measurement kind (solvers/variance.py), as
        # calibrate does: the loop itself tests on the identified noise, unscaled
        say("the final model with variance components ...")
        run = calibrate_with_effects(exp, added=diag.added, options=calibration_options, solvers=tuple(final),
                                     concurrent=True)
        final = {s: run.results[s] for s in final}          # the loop's order of the files
        comparison, verdict = run.comparison, run.verdict
    extra = {"verdict": verdict.to_json(), "diagnosis": {"added": list(diag.added)}}
    if choice is not None:
        extra["grade_choice"] = choice.to_json()
    for s, res in final.items():
        io.write_result(replace(res, extra={**res.extra, **extra}), out / f"{s}.json")
    if comparison is not None:
        io.atomic_write_json(out / "comparison.json", comparison)
    js = diag.to_json()
    js["source"] = path.name
    js["verdict"] = verdict.to_json()
    js["calibration"] = {"model": list(diag.after.layout), "files": [f"{s}.json" for s in final]
                         + (["comparison.json"] if comparison is not None else [])}
    io.atomic_write_json(out / "diagnosis.json", js)
    write_report(diag, out / "report.html")
    print(f"added: {', '.join(diag.added) or 'nothing'}; unexplained: {str(diag.unexplained).lower()}")
    for d in diag.signature[:3]:
        print(f"  left: {d.group} as a bias on {d.axis} (statistic {d.statistic:.1f} > {d.threshold:.1f})")
    for label, st in (("before", diag.before), ("after", diag.after)):
        rms = residual_rms(st).get(st.primary, {})
        line = ", ".join(f"{k} {max(v):.3f}" for k, v in rms.items() if isinstance(v, list))
        err = ""
        if st.error:
            e = st.error[st.primary]
            err = f"; error vs truth RMS {e['rms_z']:.2f} sigma (max {e['max_abs_z']:.1f}, {e['worst']})"
        print(f"  {label}: largest whitened residual RMS per kind: {line}{err}")
    print(f"  -> {out / 'diagnosis.json'}, {out / 'report.html'}, the final calibration "
          f"{', '.join(js['calibration']['files'])} ({diag.seconds:.0f} s)")
    earlier = earlier_results(out, set(js["calibration"]["files"]), solver_names=registry.solver_names())
    if earlier:
        print(f"  note: {out} also holds {', '.join(earlier)} of an earlier run, not this one's", file=sys.stderr)
    for problem in verdict.problems:
        print(f"  {problem}")
    print(verdict.text())
    return 0 if verdict.passed else 3
