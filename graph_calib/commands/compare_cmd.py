"""``graph-calib compare PROCEDURE.toml PROCEDURE.toml [...] --out DIR [--soak-h H]... [--grade G] [--gyro-noise ...] [--simulate N --simulate-at NAME:HOURS]...``.

Campaign procedures compared on predicted accuracy against campaign duration, for the IMU the grade and
the noise options describe (default: the navigation grade)
(:mod:`graph_calib.design.comparison`; the procedures: :mod:`graph_calib.design.procedures`), optionally
confirmed by simulated calibrations (:mod:`graph_calib.design.comparison_check`).  Writes
``comparison.json`` and ``report.html``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from graph_calib import io
from graph_calib.design.comparison import compare
from graph_calib.design.comparison_check import simulated_check
from graph_calib.design.procedures import read_procedure
from graph_calib.commands.model_options import add_noise, noise_of
from graph_calib.commands.paths import make_output_folder
from graph_calib.model import ModelOptions
from graph_calib.errors import InputError
from graph_calib.reports.comparison_report import comparison_report_html, noise_text
from graph_calib.reports.comparison_study import comparison_markdown


def add_arguments(p):
    p.add_argument("procedures", nargs="+", metavar="PROCEDURE.toml",
                   help="two or more campaign procedures (docs/study.md, data/programs/procedure-*.toml); the "
                        "first is the reference of the equal-accuracy ratios")
    p.add_argument("--out", required=True, help="output folder (comparison.json, report.html)")
    p.add_argument("--soak-h", type=float, action="append", default=None, metavar="H",
                   help="a soak time of the step procedures, h (repeatable; default: each procedure's own)")
    p.add_argument("--range-degc", type=float, nargs=2, default=(-10.0, 50.0), metavar=("LOW", "HIGH"),
                   help="temperature range the stitched curves are judged over, degC (default -10 50)")
    add_noise(p, grade_default="navigation", noise_default="the grade's")
    p.add_argument("--draws", type=int, default=40, help="truth curves drawn from the family (default 40)")
    p.add_argument("--seed", type=int, default=1, help="seed of the truth draws and of the simulations (default 1)")
    p.add_argument("--simulate", type=int, default=0, metavar="N",
                   help="also simulate and calibrate N realisations of the campaigns named by --simulate-at")
    p.add_argument("--simulate-at", action="append", default=[], metavar="NAME:HOURS",
                   help="a campaign to simulate, NAME:HOURS (hours recorded per experiment; repeatable), e.g. steps:0.25")
    p.add_argument("--markdown", default=None, metavar="PAGE.md",
                   help="also write the study page (Markdown; its figures in figures/ beside it), e.g. docs/study.md")
    p.add_argument("--notes", default=None, metavar="NOTES.md",
                   help="Markdown appended to the study page (the reading of the numbers)")
    p.add_argument("--work", default=None, help="cache of the simulated calibrations (default OUT/simulated)")


def _check(args):
    """Bad arguments refused (InputError naming the option); the simulated campaigns asked ``{name: [seconds]}`` and
    the noise options given ``{ModelOptions field: value or None}``."""
    if len(args.procedures) < 2:
        raise InputError("a comparison needs at least two procedures", dataset="PROCEDURE.toml")
    if args.soak_h is not None and not all(math.isfinite(w) and w >= 0 for w in args.soak_h):
        raise InputError(f"soak times must be non-negative hours, got {args.soak_h}", dataset="--soak-h")
    lo, hi = args.range_degc
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise InputError(f"must be LOW HIGH with LOW < HIGH, got {lo:g} {hi:g}", dataset="--range-degc")
    if args.notes is not None and not Path(args.notes).is_file():
        raise InputError("no such file", path=args.notes, dataset="--notes")
    if args.notes is not None and args.markdown is None:
        raise InputError("notes go on the study page: give --markdown too", dataset="--notes")
    if args.draws < 1:
        raise InputError(f"must be at least 1, got {args.draws}", dataset="--draws")
    if args.simulate < 0:
        raise InputError(f"must not be negative, got {args.simulate}", dataset="--simulate")
    noise = noise_of(args)
    if args.simulate and ((args.grade or "navigation") != "navigation" or any(v is not None for v in noise.values())):
        raise InputError("the simulated check simulates the navigation grade's noise: drop --simulate, or --grade and "
                         "the noise options (they set the predicted part only)", dataset="--simulate")
    if args.simulate and not args.simulate_at:
        raise InputError("name the campaigns to simulate (--simulate-at NAME:HOURS, repeatable)", dataset="--simulate-at")
    at = {}
    for item in args.simulate_at:
        name, _, hours = item.partition(":")
        try:
            h = float(hours)
        except ValueError:
            h = float("nan")
        if not name or not (math.isfinite(h) and h > 0):
            raise InputError(f"must be NAME:HOURS, got {item!r}", dataset="--simulate-at")
        at.setdefault(name, []).append(h * 3600.0)
    return at, noise


def run(args):
    at, noise = _check(args)
    procs = [read_procedure(p) for p in args.procedures]
    names = [p.name for p in procs]
    if len(set(names)) != len(names):
        raise InputError(f"procedure names must be unique, got {', '.join(names)}", dataset="PROCEDURE.toml")
    for name, Ls in at.items():
        proc = next((p for p in procs if p.name == name), None)
        if proc is None:
            raise InputError(f"no procedure named {name!r}; given: {', '.join(names)}", dataset="--simulate-at")
        for L in Ls:
            if not any(abs(L - k) < 1e-6 for k in proc.lengths()):
                raise InputError(f"{name}: {L / 3600:g} h is not one of its lengths "
                                 f"({', '.join(f'{k / 3600:g}' for k in proc.lengths())} h)", dataset="--simulate-at")
    out = make_output_folder(args.out)

    def progress(msg):
        print(msg, file=sys.stderr, flush=True)

    soaks = None if args.soak_h is None else [w * 3600.0 for w in args.soak_h]
    model = ModelOptions(grade=args.grade or "navigation", **noise)
    comparison = compare(procs, soaks_s=soaks, range_degC=tuple(args.range_degc), draws=args.draws, seed=args.seed,
                         model=model, progress=progress)
    doc = comparison.to_dict()
    if args.simulate:
        doc["simulated_check"] = simulated_check(comparison, lengths=at, realisations=args.simulate,
                                                 work=args.work or out / "simulated", seed=args.seed,
                                                 progress=progress)
    io.atomic_write_json(out / "comparison.json", doc)
    io.atomic_write_text(out / "report.html", comparison_report_html(doc, comparison))
    if args.markdown:
        comparison_markdown(doc, comparison, path=args.markdown, command=_command_line(args),
                            closing=Path(args.notes).read_text() if args.notes else "")
    print(comparison_text(doc))
    print(f"  -> {out / 'comparison.json'}, {out / 'report.html'}")
    if doc.get("simulated_check"):
        v = doc["simulated_check"]["verdict"]
        print(f"simulated check {v['text']}")
        return 0 if v["passed"] else 3
    return 0


def _command_line(args):
    """The command line that reproduces this comparison (quoted on the study page)."""
    parts = ["graph-calib compare", *args.procedures]
    if args.soak_h is not None:
        parts += [a for w in args.soak_h for a in ("--soak-h", f"{w:g}")]
    if tuple(args.range_degc) != (-10.0, 50.0):
        parts += ["--range-degc", *(f"{v:g}" for v in args.range_degc)]
    if args.grade:
        parts += ["--grade", args.grade]
    for flag, v in (("--gyro-noise", args.gyro_noise), ("--accel-noise", args.accel_noise),
                    ("--encoder-noise", args.encoder_noise)):
        if v is not None:
            parts += [flag, f"{v:g}"]
    if args.draws != 40:
        parts += ["--draws", str(args.draws)]
    if args.seed != 1:
        parts += ["--seed", str(args.seed)]
    if args.simulate:
        parts += ["--simulate", str(args.simulate), *(a for s in args.simulate_at for a in ("--simulate-at", s))]
    parts += ["--out", str(args.out), "--markdown", str(args.markdown)]
    if args.notes:
        parts += ["--notes", str(args.notes)]
    return " ".join(parts)


def comparison_text(doc):
    """The equal-accuracy ratios on the largest 1-sigma, a few lines."""
    ref = doc["procedures"][0]["name"]
    lines = [f"predicted part: {doc['seconds']:.0f} s wall, {doc['cpu_seconds']:.0f} s CPU; reference {ref}",
             f"  noise: {noise_text(doc['noise'])}"]
    several = {p["name"] for p in doc["procedures"] if len(p["lengths_s"]) >= 2}
    for cand, by_soak in doc["equal_accuracy"].items():
        if cand not in several:
            continue
        for soak, fams in by_soak.items():
            for f in ("gyro.bias", "accel.bias"):
                rows = fams[f]["largest_sigma"]
                cells = ", ".join(f"{r['reference_length_s'] / 3600:g} h: "
                                  + ("not reached" if r["ratio"] is None else f"{r['ratio']:.2f}")
                                  for r in rows)
                lines.append(f"  {cand} / {ref}, soak {float(soak) / 3600:g} h, {f} largest 1-sigma: {cells}")
    sc = doc.get("simulated_check")
    if sc:
        for f, per in sc["ratios"].items():
            for m, rows in per.items():
                for r in rows:
                    if r["agreement"] is not None and f in ("gyro.bias", "accel.bias"):
                        lines.append(f"  simulated/predicted ratio, {f} {m} at {r['reference_length_s'] / 3600:g} h: "
                                     f"{r['agreement']:.3f}")
    return "\n".join(lines)
