"""``graph-calib predict INPUT --out prediction.json [--grade G] [--gyro-noise ...] [--effect ...] [--variance-components]``.

The predicted accuracy of the calibration of an experiment file or of a bench program (:mod:`graph_calib.design.prediction`): the Fisher
information of the model at the nominal calibration, no noise simulated and no solver run.  With
``--variance-components`` the kinds' variance factors calibrate would apply are estimated first (on the
record, or on one simulated noise realisation of a program, ``--seed``) and the prediction is calibrate's.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from graph_calib import io
from graph_calib.constants import RS_TO_DH
from graph_calib.sensors.effects import FURTHER_EFFECTS
from graph_calib.errors import InputError
from graph_calib.records.grade_choice import choose_grade, grade_warning
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.design.prediction import expected_variance_factors, predict, prediction_result
from graph_calib.records.problem import build_problem
from graph_calib.commands.model_options import add_noise, finite_float, noise_of
from graph_calib.simulation.program import nominal_experiment, read_program


def add_arguments(p):
    p.add_argument("input", help="experiment file (HDF5, data-format.md) or bench program (TOML, docs/programs.md)")
    p.add_argument("--out", required=True, metavar="FILE.json", help="prediction file to write (JSON, the result layout)")
    add_noise(p, grade_default="chosen from the static intervals, as calibrate",
              noise_default="identified from the record's rests, as calibrate; a program: the grade's")
    p.add_argument("--effect", action="append", default=[], metavar="NAME",
                   help="further effects of model.md to include (repeatable)")
    p.add_argument("--keyframe", type=finite_float, default=1.0, help="keyframe interval, s (default 1.0)")
    p.add_argument("--t-ref", type=finite_float, default=None, help="reference temperature, degC")
    p.add_argument("--variance-components", action="store_true",
                   help="apply the variance factors calibrate estimates (solves the record, or one simulated noise "
                        "realisation of a program): the sigmas calibrate reports (docs/design.md)")
    p.add_argument("--seed", type=int, default=1,
                   help="seed of a program's simulated realisation for --variance-components (default 1)")


def options_from_args(args, *, grade=None):
    """The :class:`CalibrationOptions` the arguments ask for (``grade``: the chosen one); bad values refused."""
    for e in args.effect:
        if e not in FURTHER_EFFECTS:
            raise InputError(f"unknown effect {e!r}; known: {', '.join(FURTHER_EFFECTS)}", dataset="--effect")
    if not (np.isfinite(args.keyframe) and args.keyframe > 0):
        raise InputError(f"must be a positive number, got {args.keyframe!r}", dataset="--keyframe")
    noise = noise_of(args)
    if getattr(args, "seed", 0) < 0:
        raise InputError(f"must be a non-negative integer, got {args.seed}", dataset="--seed")
    model = ModelOptions(keyframe_s=args.keyframe, grade=args.grade or grade or "navigation",
                         extra_effects=tuple(args.effect), **noise)
    return CalibrationOptions(model=model, t_ref_degC=args.t_ref)


def run(args):
    path = Path(args.input)
    if not path.exists():
        raise InputError("no such file", path=path)
    options_from_args(args)                       # bad arguments refused before the file is read
    choice, program = None, None
    if path.suffix.lower() == ".toml":
        program = read_program(path)
        exp = nominal_experiment(program)         # the program's motion and temperatures, no noise, no errors
        if args.grade is None:
            args.grade = program.grade
    else:
        exp = io.read_experiment(path)
        if args.grade is None:
            choice = choose_grade(exp, keyframe_s=args.keyframe)
            print(f"grade: {choice.reason}")
        elif warning := grade_warning(exp, args.grade, keyframe_s=args.keyframe):
            print(warning, file=sys.stderr)
    options = options_from_args(args, grade=choice.grade if choice else None)
    problem = build_problem(exp, options=options)
    m = problem.model
    print(f"{path.name}: {exp.n_samples} samples, {m.n_keyframes} keyframes, {m.layout.size} parameters, "
          f"T_ref {m.t_ref_degC:.2f} degC", file=sys.stderr)
    factors = None
    if args.variance_components:
        factors = expected_variance_factors(
            problem, options=options, program=program,
            rng=np.random.default_rng(args.seed) if program is not None else None)
        print("variance factors (" + ("one simulated realisation of the program" if program is not None else
                                      "estimated on the record") + "): "
              + ", ".join(f"{k} {v:.3g}" for k, v in factors.items()), file=sys.stderr)
    prediction = predict(problem, variance_factors=factors)
    extra = {"grade_choice": choice.to_json()} if choice is not None else None
    result = prediction_result(problem, prediction, extra=extra)
    out = Path(args.out)
    if out.parent != Path(""):
        out.parent.mkdir(parents=True, exist_ok=True)
    io.write_result(result, out)
    print(prediction_text(prediction))
    print(f"  -> {out}")
    return 0


def prediction_text(prediction):
    """Predicted gyro-bias sigmas and the remaining-error bound against the published accuracy, a few lines."""
    s = prediction.sigmas()
    b = prediction.bound.summary()
    gb = [s[f"gyro.bias.{a}"] * RS_TO_DH for a in "xyz"]
    ab = [s[f"accel.bias.{a}"] for a in "xyz"]
    k = b["confidence_sigma"]
    g_bound = max(b["gyro_radps"]["bound"]) * RS_TO_DH
    a_bound = max(b["accel_mps2"]["bound"])
    verdict = "meets" if b["meets"]["all"] else "does not meet"
    return (f"  predicted sigma: gyro bias [deg/h] {gb[0]:.5f} {gb[1]:.5f} {gb[2]:.5f}, "
            f"accel bias [m/s^2] {ab[0]:.2e} {ab[1]:.2e} {ab[2]:.2e} ({prediction.seconds:.1f} s)\n"
            f"  remaining errors ({k:g} sigma): gyro {g_bound:.4f} deg/h ({b['gyro_criterion']}), "
            f"accel {a_bound:.2e} m/s^2: {verdict} 0.01 deg/h and 2e-4 m/s^2")
