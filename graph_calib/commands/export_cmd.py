"""``graph-calib export CAMPAIGN_DIR --out TABLE``: a campaign's stitched calibration as the table an INS loads.

Every temperature-dependent element on a temperature grid over the calibrated range with
its one-sigma band, and the constant elements; JSON, CSV or a C header
(docs/compensation.md).  The table assumes linear interpolation between grid points, each
element at its own sensor's temperature, the end values held outside the grid; ``graph-calib
apply`` uses exactly that.
"""

from __future__ import annotations

import sys
from pathlib import Path

from graph_calib.compensation import STITCH_MODELS, SUFFIX, TABLE_FORMATS, StitchedCalibration, write_table
from graph_calib.compensation.joint import JointCalibration
from graph_calib.errors import InputError
from graph_calib.solvers.joint.solver import JOINT

#: Largest interpolation error (in sigma of the element) the export accepts without a remark.
INTERPOLATION_REMARK_SIGMA = 0.1


def add_arguments(p):
    p.add_argument("campaign", metavar="CAMPAIGN_DIR", help="folder written by graph-calib campaign")
    p.add_argument("--out", required=True, metavar="TABLE", help="table file to write")
    p.add_argument("--format", choices=TABLE_FORMATS, default=None,
                   help="json, csv or c-header (default: from the --out suffix .json, .csv, .h; else json)")
    p.add_argument("--step-degC", type=float, default=1.0, dest="step_degC",
                   help="grid step, degC (default 1)")
    p.add_argument("--solver", default=None, help="whose stitched results (default: the campaign's primary solver); "
                   "'joint': the joint campaign solver's curves")
    p.add_argument("--model", choices=STITCH_MODELS, default=None,
                   help="stitched model (default: the campaign's stitch_model)")


def _format(args, out):
    if args.format:
        return args.format
    by_suffix = {s: f for f, s in SUFFIX.items()}
    return by_suffix.get(out.suffix.lower(), "json")


def run(args):
    out = Path(args.out)
    if out.is_dir():
        raise InputError("is a folder; --out names the table file", path=out)
    fmt = _format(args, out)
    if args.solver == JOINT:       # the joint campaign solver's curves (docs/campaign.md), not a stitching
        if args.model:
            raise InputError("the joint calibration has one curve form; --model chooses among stitched models",
                             dataset="--model")
        stitched = JointCalibration.from_campaign(args.campaign)
    else:
        stitched = StitchedCalibration.from_campaign(args.campaign, solver=args.solver, model=args.model)
    table = stitched.table(step_degC=args.step_degC)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_table(table, out, fmt=fmt)
    g = table.grid_degC
    i = table.info
    print(f"{i.get('imu_id') or 'campaign'}: {i['solver']} {i['stitch_model']} over {len(i['subranges'])} subrange(s); "
          f"{len(table.curves)} temperature-dependent element(s) on {g.size} temperatures {g[0]:g}..{g[-1]:g} degC "
          f"(step {args.step_degC:g}), {len(table.constants)} constant(s)")
    if table.curves:
        name, c = max(table.curves.items(), key=lambda kv: kv[1].interpolation_error["max_in_sigma"])
        e = c.interpolation_error
        print(f"  linear interpolation against the stitched curve: largest {e['max_in_sigma']:.2g} sigma "
              f"({name} at {e['at_degC']:g} degC)")
        if e["max_in_sigma"] > INTERPOLATION_REMARK_SIGMA:
            print(f"  remark: above {INTERPOLATION_REMARK_SIGMA} sigma; a smaller --step-degC follows the curve closer",
                  file=sys.stderr)
    print(f"  -> {out} ({fmt})")
    return 0
