"""``graph-calib calibrate EXPERIMENT.h5 --out DIR [--solver sqrt-kf|factor-graph|both]``."""

from __future__ import annotations

import sys
from pathlib import Path

from graph_calib.constants import RS_TO_DH
from graph_calib.errors import InputError


def add_arguments(p):
    p.add_argument("experiment", help="experiment file (HDF5, data-format.md)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--solver", choices=("sqrt-kf", "factor-graph", "both"), default="both")
    p.add_argument("--grade", choices=("navigation", "tactical", "consumer"), default=None,
                   help="IMU grade for priors and noise (default: navigation)")
    p.add_argument("--keyframe", type=float, default=1.0, help="keyframe interval, s (default 1.0)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME",
                   help="model a further effect of model.md (repeatable)")
    p.add_argument("--t-ref", type=float, default=None, help="reference temperature, degC")
    p.add_argument("--robust", choices=("huber", "cauchy"), default=None, help="robust loss (factor graph)")
    p.add_argument("--residuals", action="store_true",
                   help="also write each solver's residual time series, SOLVER.residuals.h5 (docs/data-format.md)")


def options_from_args(args):
    from graph_calib.calibrate import CalibrationOptions
    from graph_calib.factor_graph import GraphOptions
    from graph_calib.model import ModelOptions
    from graph_calib.params import FURTHER_EFFECTS

    for e in args.effect:
        if e not in FURTHER_EFFECTS:
            raise InputError(f"unknown effect {e!r}; known: {', '.join(FURTHER_EFFECTS)}", dataset="--effect")
    if args.keyframe <= 0:
        raise InputError("must be positive", dataset="--keyframe")
    mopt = ModelOptions(keyframe_s=args.keyframe, grade=args.grade or "navigation",
                        extra_effects=tuple(args.effect))
    return CalibrationOptions(model=mopt, graph=GraphOptions(robust=args.robust), t_ref_degC=args.t_ref)


def run(args):
    from graph_calib import io
    from graph_calib.calibrate import build_problem, compare, run_factor_graph, run_sqrt_kf, sigma_ratio_range_text

    path = Path(args.experiment)
    if not path.exists():
        raise InputError("no such file", path=path)
    options = options_from_args(args)
    exp = io.read_experiment(path)
    out = Path(args.out)
    solvers = ("sqrt-kf", "factor-graph") if args.solver == "both" else (args.solver,)
    problem = build_problem(exp, options=options)
    out.mkdir(parents=True, exist_ok=True)
    m = problem.model
    print(f"{path.name}: {exp.n_samples} samples, {exp.t[-1] - exp.t[0] + 1 / exp.rate_hz:.0f} s, "
          f"{m.n_keyframes} keyframes, {m.layout.size} parameters, T_ref {m.t_ref_degC:.2f} degC", file=sys.stderr)
    results = {}
    for s in solvers:
        def progress(i, info, _s=s):
            what = f"cost {info:.6g}" if isinstance(info, float) else (
                f"calibration moved {info.max_dx_sigma:.3g} sigma, chi2/dof {info.chi2_per_dof:.3g}")
            print(f"  {_s}: pass {i}, {what}", file=sys.stderr)

        res, raw = (run_factor_graph if s == "factor-graph" else run_sqrt_kf)(problem, options=options,
                                                                              progress=progress)
        io.write_result(res, out / f"{s}.json")
        if args.residuals:
            if s == "factor-graph":
                series, quantity = raw.residuals, "whitened residual"
            else:
                series, quantity = raw.innovation_series(), "normalised innovation"
            io.write_residuals(out / f"{s}.residuals.h5", series, solver=s, source=path.name, kind=quantity)
        results[s] = res
        b = [res.values[f"gyro.bias.{a}"] * RS_TO_DH for a in "xyz"]
        print(f"  {s}: gyro bias [deg/h] {b[0]:+.4f} {b[1]:+.4f} {b[2]:+.4f} -> {out / (s + '.json')}")
    if len(results) == 2:
        cmp_ = compare(results["sqrt-kf"], results["factor-graph"])
        io.atomic_write_json(out / "comparison.json", cmp_)
        sm = cmp_["summary"]
        print(f"  comparison: max |difference| {sm['max_abs_difference_in_sigma']:.3f} sigma, sigma ratio "
              f"{sigma_ratio_range_text(sm)} -> {out / 'comparison.json'}")
    return 0
