"""``graph-calib calibrate EXPERIMENT.h5 --out DIR [--solver both|NAME[+NAME...]]``: the registered solvers."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from graph_calib import io
from graph_calib.calibrate import build_problem, solve_problem
from graph_calib.constants import RS_TO_DH
from graph_calib.commands.paths import earlier_results
from graph_calib.commands.model_options import (add_bench_options, bench_options, check_gyro_range, finite_float,
                                                 with_gyro_range)
from graph_calib.errors import InputError
from graph_calib.records.grade_choice import choose_grade, grade_warning
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions, GraphOptions
from graph_calib.sensors.effects import FURTHER_EFFECTS
from graph_calib.solvers import registry
from graph_calib.solvers.results import comparison_text


def add_arguments(p):
    p.add_argument("experiment", help="experiment file (HDF5, data-format.md)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--solver", type=solver_choice, default=registry.BOTH, metavar="SOLVERS",
                   help=f"the solvers to run: {registry.choice_help()} (default {registry.BOTH})")
    p.add_argument("--grade", choices=("navigation", "tactical", "consumer"), default=None,
                   help="IMU grade for priors and noise (default: chosen from the static intervals' noise and "
                        "offsets, printed with the reason)")
    p.add_argument("--keyframe", type=finite_float, default=1.0, help="keyframe interval, s (default 1.0)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME",
                   help="model a further effect of model.md (repeatable)")
    p.add_argument("--t-ref", type=finite_float, default=None, help="reference temperature, degC")
    p.add_argument("--robust", choices=("huber", "cauchy"), default=None, help="robust loss (factor graph)")
    add_bench_options(p)
    p.add_argument("--residuals", action="store_true",
                   help="also write each solver's residual time series, SOLVER.residuals.h5 (docs/data-format.md)")


def solver_choice(value, *, campaign=False):
    """An argparse ``type`` for ``--solver``: the value, checked against the registry (exit 2 naming it)."""
    try:
        registry.parse_choice(value, campaign=campaign)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


def options_from_args(args, *, grade=None):
    """The :class:`graph_calib.options.CalibrationOptions` the arguments ask for (``grade``: the chosen one)."""
    for e in args.effect:
        if e not in FURTHER_EFFECTS:
            raise InputError(f"unknown effect {e!r}; known: {', '.join(FURTHER_EFFECTS)}", dataset="--effect")
    if args.keyframe <= 0:
        raise InputError("must be positive", dataset="--keyframe")
    check_gyro_range(args)
    model = ModelOptions(keyframe_s=args.keyframe, grade=args.grade or grade or "navigation",
                         extra_effects=tuple(args.effect), **bench_options(args))
    return CalibrationOptions(model=model, graph=GraphOptions(robust=args.robust), t_ref_degC=args.t_ref)


def _print_progress(event):
    print(f"  {event.text()}", file=sys.stderr)


def run(args):
    path = Path(args.experiment)
    if not path.exists():
        raise InputError("no such file", path=path)
    options_from_args(args)                       # bad arguments refused before the file is read
    exp = with_gyro_range(args, io.read_experiment(path))
    choice = None
    if args.grade is None:
        choice = choose_grade(exp, keyframe_s=args.keyframe)
        print(f"grade: {choice.reason}")
    elif warning := grade_warning(exp, args.grade, keyframe_s=args.keyframe):
        print(warning, file=sys.stderr)
    options = options_from_args(args, grade=choice.grade if choice else None)
    out = Path(args.out)
    solvers, _ = registry.parse_choice(args.solver)
    problem = build_problem(exp, options=options)
    out.mkdir(parents=True, exist_ok=True)
    m = problem.model
    print(f"{path.name}: {exp.n_samples} samples, {exp.t[-1] - exp.t[0] + 1 / exp.rate_hz:.0f} s, "
          f"{m.n_keyframes} keyframes, {m.layout.size} parameters, T_ref {m.t_ref_degC:.2f} degC", file=sys.stderr)
    calibration = solve_problem(problem, options=options, solvers=solvers, progress=_print_progress,
                                concurrent=True)
    for s, res in calibration.results.items():
        if choice is not None:
            res = replace(res, extra={**res.extra, "grade_choice": choice.to_json()})
        io.write_result(res, out / f"{s}.json")
        output = calibration.outputs[s]
        if args.residuals:
            io.write_residuals(out / f"{s}.residuals.h5", output.residual_arrays(), solver=s, source=path.name,
                               kind=output.residual_quantity)
        b = [res.values[f"gyro.bias.{a}"] * RS_TO_DH for a in "xyz"]
        print(f"  {s}: gyro bias [deg/h] {b[0]:+.4f} {b[1]:+.4f} {b[2]:+.4f} -> {out / (s + '.json')}")
    if calibration.comparison is not None:
        io.atomic_write_json(out / "comparison.json", calibration.comparison)
        print(f"  comparison: {comparison_text(calibration.comparison['summary'])} -> {out / 'comparison.json'}")
    written = {f"{s}.json" for s in calibration.results} | ({"comparison.json"} if calibration.comparison else set())
    earlier = earlier_results(out, written, solver_names=registry.solver_names())
    if earlier:
        print(f"  note: {out} also holds {', '.join(earlier)} of an earlier run, not this one's", file=sys.stderr)
    verdict = calibration.verdict
    for problem in verdict.problems:
        print(f"  {problem}")
    if any(t["significant"] for t in verdict.structure):
        print("  graph-calib diagnose adds the most significant of these effects and tests the others again")
    print(verdict.text())
    return 0 if verdict.passed else 3
