"""``graph-calib design --out DIR [--spec SPEC.toml] [--baseline PROGRAM.toml]``.

The shortest bench program whose predicted accuracy meets the targets (:mod:`graph_calib.design.program_search`:
CasADi/IPOPT on a reduced model, every candidate verified with the full prediction).  Writes
``program.toml``, ``prediction.json``, ``design.json`` and ``report.html``.
"""

from __future__ import annotations

import sys

import numpy as np

from graph_calib import io
from graph_calib.constants import RS_TO_DH
from graph_calib.commands.paths import make_output_folder
from graph_calib.design.prediction import prediction_result
from graph_calib.design.program_search import DesignSpec, design, design_document, read_spec
from graph_calib.reports.design_report import design_report_html
from graph_calib.simulation import simulate
from graph_calib.simulation.program import program_text, read_program, scenario_program


def add_arguments(p):
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--spec", default=None, metavar="SPEC.toml",
                   help="targets and bench limits (docs/design.md; default: navigation grade, 0.01 deg/h and "
                        "2e-4 m/s^2 at 2 sigma over an 8 degC subrange)")
    p.add_argument("--baseline", default=None, metavar="PROGRAM.toml",
                   help="program to compare with (default: the nav-subrange scenario's experiment at seed 7, "
                        "data/programs/nav-subrange.toml)")


def run(args):
    spec = read_spec(args.spec) if args.spec else DesignSpec()
    if args.baseline:
        baseline = read_program(args.baseline)
    else:
        baseline = scenario_program(simulate("nav-subrange", rng=np.random.default_rng(7)), name="nav-subrange")

    def progress(msg):
        print(msg, file=sys.stderr, flush=True)

    with io.no_empty_folder_if_refused(args.out):
        out = make_output_folder(args.out)
        result = design(spec, baseline=baseline, progress=progress)
    doc = design_document(result, spec)
    best = result.best
    io.atomic_write_text(out / "program.toml", program_text(best.program))
    io.write_result(prediction_result(best.problem, best.prediction), out / "prediction.json")
    io.atomic_write_json(out / "design.json", doc)
    io.atomic_write_text(out / "report.html", design_report_html(doc, designed=best.program, baseline=baseline))
    g = max(doc["predicted_bound"]["gyro_radps"]["bound"]) * RS_TO_DH
    a = max(doc["predicted_bound"]["accel_mps2"]["bound"])
    print(f"designed: {doc['duration_s'] / 60:.1f} min, {best.n_stations} static stations; predicted gyro "
          f"{g:.4f} deg/h, accel {a:.2e} m/s^2 at {spec.confidence_sigma:g} sigma: "
          f"{'targets met' if doc['targets_met'] else 'targets NOT met'}")
    if "baseline" in doc:
        print(f"baseline {doc['baseline']['name']}: {doc['baseline']['duration_s'] / 60:.1f} min; "
              f"designed/baseline {doc['duration_ratio_to_baseline']:.2f}")
    print(f"  -> {out / 'program.toml'}, prediction.json, design.json, report.html")
    return 0 if doc["targets_met"] else 3
