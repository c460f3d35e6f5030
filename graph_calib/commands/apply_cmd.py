"""``graph-calib apply CALIBRATION EXPERIMENT.h5 --out CORRECTED.h5``: a raw record corrected by a calibration.

A result or campaign whose verdict failed is refused (exit 2, naming the verdict) unless
``--force``; a result's directions marked ``unresolved`` are never applied (their component is
left out and the terminal says so).  CALIBRATION is a result file (one experiment's calibration), a compensation table
written by ``graph-calib export`` (JSON or CSV), or a campaign folder (its stitched
calibration applied directly).  The output is a valid experiment file whose
``dtheta``/``dv`` are the corrected increments, with the provenance in its description
and its root attribute ``corrected_by`` (docs/compensation.md).
"""

from __future__ import annotations

import sys
from pathlib import Path

from graph_calib import io
from graph_calib.commands.paths import output_file
from graph_calib.compensation import PROVENANCE_ATTRIBUTE, STITCH_MODELS, apply, correction_of, read_compensation
from graph_calib.compensation import write_corrected
from graph_calib.compensation.apply import superseded, verdict_failed
from graph_calib.constants import RAD_TO_DEG
from graph_calib.errors import InputError


def add_arguments(p):
    p.add_argument("calibration", metavar="RESULT_OR_TABLE",
                   help="result file (JSON), compensation table (JSON or CSV from graph-calib export), or a campaign "
                        "folder")
    p.add_argument("experiment", metavar="EXPERIMENT.h5", help="raw experiment file (HDF5, data-format.md)")
    p.add_argument("--out", required=True, metavar="CORRECTED.h5", help="corrected experiment file to write")
    p.add_argument("--solver", default=None, help="a campaign folder only: whose stitching (default: its primary)")
    p.add_argument("--model", choices=STITCH_MODELS, default=None,
                   help="a campaign folder only: the stitched model (default: the campaign's)")
    p.add_argument("--again", action="store_true",
                   help="correct a record that is already corrected (subtracts the sensor errors a second time)")
    p.add_argument("--force", action="store_true",
                   help="apply a result or campaign whose verdict failed, or a result of another IMU (refused "
                        "otherwise, exit 2)")


def run(args):
    src = Path(args.experiment)
    out = Path(args.out)
    if out.exists() and src.exists() and out.resolve() == src.resolve():
        raise InputError("is the input record; write the corrected record to another file", dataset="--out")
    output_file(out)
    compensation, provenance = read_compensation(args.calibration, solver=args.solver, model=args.model)
    failed = verdict_failed(provenance)
    if failed and not args.force:
        raise InputError(f"its verdict failed ({failed}); a calibration that failed its own checks is not applied "
                         "without --force", path=args.calibration, dataset="verdict")
    later = superseded(provenance)
    if later and not args.force:
        raise InputError(later, path=args.calibration, dataset="campaign")
    experiment = io.read_experiment(src)
    other = provenance.get("imu_id")     # a result's, a table's or a campaign's
    foreign = bool(other and experiment.imu_id and other != experiment.imu_id)
    if foreign and not args.force:
        raise InputError(f"is a record of IMU {experiment.imu_id!r}, the calibration is of IMU {other!r}: one unit's "
                         "errors are not another's (--force applies it anyway)", path=src, dataset="imu_id")
    before = correction_of(src)
    if before is not None and not args.again:
        what = before.get("file") or before.get("text") or "?"
        raise InputError(f"already corrected (with {what}); correcting it again subtracts the sensor errors twice "
                         "(--again does it anyway)", path=src, dataset=f'/.attrs["{PROVENANCE_ATTRIBUTE}"]')
    corrected, provenance, summary = apply(compensation, experiment, provenance=provenance)
    if before is not None:
        provenance["previously"] = before
    out.parent.mkdir(parents=True, exist_ok=True)
    write_corrected(corrected, out, provenance)
    g = summary["mean_gyro_correction_degph"]
    a = summary["mean_accel_correction_ug"]
    print(f"{src.name}: {experiment.n_samples} samples {corrected.description.splitlines()[0]}")
    print(f"  mean correction: gyro [deg/h] {g[0]:+.4f} {g[1]:+.4f} {g[2]:+.4f}, "
          f"accel [micro-g] {a[0]:+.1f} {a[1]:+.1f} {a[2]:+.1f}")
    if provenance["outside"]:
        held = "held at the table's end values" if provenance["kind"] == "table" else "extrapolated"
        print(f"  {provenance['outside']} sample(s) with a sensor temperature outside the calibrated range ({held})",
              file=sys.stderr)
    if failed:
        print(f"  warning: applied with --force although its verdict failed ({failed})", file=sys.stderr)
    if foreign:
        print(f"  warning: applied with --force to a record of IMU {experiment.imu_id!r}, the calibration is of IMU "
              f"{other!r}", file=sys.stderr)
    elif not (other and experiment.imu_id):
        unnamed = " and ".join(w for w, i in (("the calibration", other), ("the record", experiment.imu_id)) if not i)
        print(f"  note: {unnamed} name(s) no IMU (imu_id empty): whether they are of one unit was not checked "
              "(graph-calib import --imu-id names it)", file=sys.stderr)
    for name, r in provenance.get("unresolved_not_applied", {}).items():
        gs = {k: v for k, v in r["elements"].items() if k.startswith("gyro.g_sensitivity")}
        size = max((abs(v) for v in gs.values()), default=0.0)
        print(f"  not applied: the result marks the direction '{name}' unresolved; its component "
              f"{r['component']:.3g} is left out" + (f" (gyro g-sensitivity up to {size * RAD_TO_DEG * 3600:.3g} "
                                                     "deg/h per m/s^2)" if gs else ""))
    print(f"  -> {out}")
    return 0
