"""``graph-calib export CAMPAIGN_DIR_OR_RESULT --format F --out FILE``: the calibration in a navigation system's file.

``json``, ``csv``, ``c-header``: a campaign's stitched calibration as a compensation
table (every temperature-dependent element on a temperature grid with its one-sigma
band, and the constant elements; docs/compensation.md), linear interpolation between
grid points, each element at its own sensor's temperature, the end values held outside
the grid; ``graph-calib apply`` uses exactly that.

``px4``, ``ardupilot``, ``kalibr``, ``openvins``: the ecosystem's own files, from a
campaign or a single result (:mod:`graph_calib.compensation.exports`).  Each says, in
the file and here, what it cannot hold and how large that is over the calibrated range.

The format is ``--format``, or told by the ``--out`` suffix when that names one format;
a suffix that belongs to another format is refused (never JSON under a YAML name).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from graph_calib.commands.paths import output_file
from graph_calib.compensation import STITCH_MODELS, SUFFIX, TABLE_FORMATS, StitchedCalibration, write_table
from graph_calib.compensation.apply import campaign_verdict, verdict_failed
from graph_calib.compensation.exports import DEFAULT_ENVELOPE_DPS, EXPORT_FORMATS, load_source
from graph_calib.compensation.joint import JointCalibration
from graph_calib.errors import InputError
from graph_calib.io import atomic_write_text
from graph_calib.solvers.joint.solver import JOINT

#: Largest interpolation error (in sigma of the element) the export accepts without a remark.
INTERPOLATION_REMARK_SIGMA = 0.1
#: Largest interpolation error (in sigma) of a table written at all: beyond it the table does not follow the
#: calibration it comes from, and a smaller ``--step-degc`` is what fixes it.
INTERPOLATION_LIMIT_SIGMA = 1.0
FORMATS = tuple(TABLE_FORMATS) + tuple(EXPORT_FORMATS)


def add_arguments(p):
    p.add_argument("source", metavar="CAMPAIGN_DIR_OR_RESULT",
                   help="folder written by graph-calib campaign, or (px4, ardupilot, kalibr, openvins) a result file")
    p.add_argument("--out", required=True, metavar="FILE", help="file to write")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="json, csv, c-header (tables of a campaign); px4, ardupilot, kalibr, openvins (the "
                        "ecosystem's files). Default: from the --out suffix (.json .csv .h .params .parm), else json")
    p.add_argument("--step-degc", type=float, default=1.0, dest="step_degC", metavar="DEGC",
                   help="tables: grid step, degC (default 1)")
    p.add_argument("--solver", default=None, help="whose stitched results (default: the campaign's primary solver); "
                   "'joint': the joint campaign solver's curves")
    p.add_argument("--model", choices=STITCH_MODELS, default=None,
                   help="stitched model (default: the campaign's stitch_model)")
    p.add_argument("--envelope-dps", type=float, default=DEFAULT_ENVELOPE_DPS, metavar="DPS",
                   help=f"px4, ardupilot, kalibr, openvins: largest rate over which the loss is reported, deg/s "
                        f"(default {DEFAULT_ENVELOPE_DPS:g}; the specific force is 1 g in any direction)")
    p.add_argument("--instance", type=int, default=None, metavar="N",
                   help="px4: TC_G{N}/TC_A{N}, 0-3 (default 0); ardupilot: INS_TCAL{N}, 1-3 (default 1)")
    p.add_argument("--gyro-id", type=int, default=0, metavar="ID",
                   help="px4: TC_G{N}_ID, the gyro's device id (default 0: set it before loading)")
    p.add_argument("--accel-id", type=int, default=0, metavar="ID",
                   help="px4: TC_A{N}_ID, the accelerometer's device id (default 0: set it before loading)")
    p.add_argument("--rostopic", default="/imu0", metavar="TOPIC", help="kalibr, openvins: the IMU topic (/imu0)")
    p.add_argument("--rate-hz", type=float, default=None, metavar="HZ",
                   help="kalibr, openvins: update_rate (default: the calibrated record's rate, when found)")
    p.add_argument("--force", action="store_true", help="export a result or campaign whose verdict failed")


def _format(args, out):
    by_suffix = {}
    for f, s in SUFFIX.items():
        by_suffix.setdefault(s, []).append(f)
    for f, e in EXPORT_FORMATS.items():
        for s in e.suffixes:
            by_suffix.setdefault(s, []).append(f)
    owners = by_suffix.get(out.suffix.lower(), [])
    if args.format:
        if owners and args.format not in owners:
            raise InputError(f"ends in {out.suffix!r}, the suffix of {' or '.join(owners)}, but the format is "
                             f"{args.format}: name the file for its format (or choose --format {owners[0]})",
                             path=out, dataset="--out")
        return args.format
    if len(owners) > 1:
        raise InputError(f"a {out.suffix} file is written by {' or '.join(owners)}: give --format", path=out,
                         dataset="--format")
    return owners[0] if owners else "json"


def _table(args, out, fmt):
    source = Path(args.source)
    if source.is_file() and source.name != "campaign.json":
        raise InputError(f"--format {fmt} writes a compensation table over temperature, made from a campaign (its "
                         f"folder or campaign.json); a single result exports as "
                         f"{', '.join(EXPORT_FORMATS)}", path=source, dataset="--format")
    verdict = campaign_verdict(source)
    failed = verdict_failed({"verdict": verdict})
    if failed and not args.force:
        raise InputError(f"its verdict failed ({failed}); a table of a campaign that failed its own checks is "
                         "not written without --force", path=source, dataset="verdict")
    if args.solver == JOINT:       # the joint campaign solver's curves (docs/campaign.md), not a stitching
        if args.model:
            raise InputError("the joint calibration has one curve form; --model chooses among stitched models",
                             dataset="--model")
        stitched = JointCalibration.from_campaign(args.source)
    else:
        stitched = StitchedCalibration.from_campaign(args.source, solver=args.solver, model=args.model)
    table = stitched.table(step_degC=args.step_degC)
    if table.curves:
        name, c = max(table.curves.items(), key=lambda kv: kv[1].interpolation_error["max_in_sigma"])
        e = c.interpolation_error["max_in_sigma"]
        if e > INTERPOLATION_LIMIT_SIGMA:
            # linear interpolation's error goes with the step squared
            suggest = args.step_degC * math.sqrt(INTERPOLATION_REMARK_SIGMA / e)
            raise InputError(f"linear interpolation on a {args.step_degC:g} degC grid departs from the calibration by "
                             f"{e:.3g} sigma ({name} at {c.interpolation_error['at_degC']:g} degC; at most "
                             f"{INTERPOLATION_LIMIT_SIGMA:g}): a step of {suggest:.2g} degC or less keeps it under "
                             f"{INTERPOLATION_REMARK_SIGMA:g} sigma", dataset="--step-degc")
    if verdict is not None:
        # the campaign's verdict travels with its table: apply refuses a failed one without --force, as it does the
        # campaign itself
        table.info["verdict"] = verdict
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
            print(f"  remark: above {INTERPOLATION_REMARK_SIGMA} sigma; a smaller --step-degc follows the curve closer",
                  file=sys.stderr)
    print(f"  -> {out} ({fmt})")
    return 0


#: The instance numbers each autopilot's parameters take (PX4 ``TC_G{N}``, ArduPilot ``INS_TCAL{N}``), first and last.
INSTANCES = {"px4": (0, 3), "ardupilot": (1, 3)}


def export_document(args, fmt):
    """The source and the format's document (loss included) for ``args``: what ``run`` writes."""
    spec = EXPORT_FORMATS[fmt]
    if args.envelope_dps is None or not args.envelope_dps >= 0:
        raise InputError(f"must be a non-negative rate in deg/s, got {args.envelope_dps!r}", dataset="--envelope-dps")
    source = load_source(args.source, solver=args.solver, model=args.model, force=args.force)
    options = {"envelope_dps": args.envelope_dps}
    if "instance" in spec.options:
        first, last = INSTANCES[fmt]
        instance = first if args.instance is None else args.instance
        if not first <= instance <= last:
            raise InputError(f"{fmt} numbers its instances {first} to {last}, got {instance}", dataset="--instance")
        options["instance"] = instance
    if "gyro_id" in spec.options:
        options.update(gyro_id=args.gyro_id, accel_id=args.accel_id)
    if "rate_hz" in spec.options:
        if args.rate_hz is not None and not (math.isfinite(args.rate_hz) and args.rate_hz > 0):
            raise InputError(f"must be a positive sample rate in Hz, got {args.rate_hz!r}", dataset="--rate-hz")
        rate = args.rate_hz or source.rate_hz
        if not rate:
            raise InputError("the calibrated record's rate was not found beside the result: give it "
                             "(update_rate of the file)", dataset="--rate-hz")
        options.update(rostopic=args.rostopic, rate_hz=rate)
    return source, spec.document(source, **options)


def _not_the_source(out, source):
    """Refuse an ``--out`` that is the file exported from (a result, or a campaign's ``campaign.json``)."""
    src = Path(source)
    read = {src.resolve(), (src / "campaign.json").resolve()} if src.is_dir() else {src.resolve()}
    if out.resolve() in read:
        raise InputError(f"is the file being exported from ({source}); name another file", path=out, dataset="--out")


def run(args):
    out = output_file(args.out)
    _not_the_source(out, args.source)
    fmt = _format(args, out)
    if fmt in TABLE_FORMATS:
        return _table(args, out, fmt)
    source, doc = export_document(args, fmt)
    failed = verdict_failed(source.provenance)
    if failed:
        print(f"warning: exporting {args.source} whose verdict failed ({failed}), as --force asks; the file's first "
              "line says so", file=sys.stderr)
    text = EXPORT_FORMATS[fmt].text(source, doc)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, text)
    print(f"{source.imu_id or Path(args.source).name}: {EXPORT_FORMATS[fmt].summary}, from the {source.label}")
    for line in doc["loss"].lines():
        print(f"  {line}")
    for note in doc.get("notes", ()):
        print(f"  note: {note}")
    held = source.prior_held
    if held:
        print(f"  note: {len(held)} element(s) of the result are held by their priors (the record informs little of "
              f"them; their values are the priors'): {', '.join(held[:8])}{', ...' if len(held) > 8 else ''}",
              file=sys.stderr)
    print(f"  -> {out} ({fmt})")
    return 0

