"""``graph-calib campaign MANIFEST.toml --out DIR``: every experiment, both solvers, stitched, validated, reported."""

from __future__ import annotations

import functools
import sys
from pathlib import Path

from graph_calib.campaign.checks import check_lines
from graph_calib.commands.calibrate_cmd import solver_choice
from graph_calib.errors import InputError
from graph_calib.solvers import registry
from graph_calib.solvers.verdict import PRIOR_HELD_WORDS
from graph_calib.evaluation.validation import validation_text


def add_arguments(p):
    p.add_argument("manifest", help="campaign manifest (TOML, data-format.md)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (one sub-folder per experiment)")
    p.add_argument("--workers", type=int, default=None,
                   help="Dask worker processes of the local cluster, one thread each (default: one per CPU core; "
                        "never more than one per experiment); 0: no Dask, one task after the other in this "
                        "process")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="use an existing Dask cluster (e.g. tcp://host:8786); its workers must see --out")
    p.add_argument("--solver", type=functools.partial(solver_choice, campaign=True), default=None,
                   metavar="SOLVERS",
                   help=f"override the manifest's [solver] solvers: {registry.choice_help(campaign=True)} "
                        f"(default {registry.BOTH})")
    p.add_argument("--validate", action="append", default=[], metavar="RECORD.h5",
                   help="independent record to validate the stitched calibration on (repeatable); a "
                        "RECORD.truth.json next to it is the reference, else its own calibration")
    p.add_argument("--stitch", choices=("cubic", "linear"), default="cubic",
                   help="stitched model used for validation and the calibration table (default cubic)")
    p.add_argument("--no-diagnose", action="store_true",
                   help="skip the closed loop (by default every experiment is diagnosed and the effects its data "
                        "ask for are adopted before stitching; the manifest's [solver] diagnose = false does the "
                        "same)")
    p.add_argument("--force", action="store_true", help="recompute every experiment, ignoring cached results")
    p.add_argument("--no-report", action="store_true", help="do not write report.html")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def options_from_args(args):
    from graph_calib.campaign import CampaignOptions

    if args.workers is not None and args.workers < 0:
        raise InputError(f"must be 0 or more, got {args.workers}", dataset="--workers")
    if args.workers == 0 and args.scheduler:
        raise InputError("--workers 0 runs without Dask, --scheduler on a Dask cluster: give one of them",
                         dataset="--workers")
    return CampaignOptions(workers=args.workers, scheduler=args.scheduler, solvers=args.solver,
                           stitch_model=args.stitch, validate=tuple(args.validate),
                           diagnose=False if args.no_diagnose else None, force=args.force,
                           report=not args.no_report, progress=not args.quiet)


def print_summary(run, out=None):
    """The short human summary of a finished campaign (stdout by default)."""

    out = out if out is not None else sys.stdout
    doc = run.document
    tim = doc["timing"]
    print(f"campaign {doc['imu_id']}: {len(doc['experiments'])} experiment(s), {tim['tasks_computed']} task(s) "
          f"computed, {tim['tasks_cached']} cached, {tim['tasks_failed']} failed, {tim['total_seconds']:.0f} s",
          file=out)
    for e in doc["experiments"]:
        cmp_ = e.get("comparison")
        t_ref = e.get("t_ref_degC")
        line = f"  {e['name']}: " + (f"T_ref {t_ref:.2f} degC" if t_ref is not None else "no per-subrange result")
        if cmp_:
            line += (f", filter vs graph max {cmp_['max_abs_difference_in_sigma']:.2g} sigma "
                     f"({'agree' if cmp_['agree'] else 'DIFFER'})")
        verdict = e.get("verdict")
        if verdict:
            chi = ", ".join(f"{v:.2f}" for v in verdict["fit_chi2_per_dof"].values())
            line += f", chi2/dof {chi}: {'pass' if verdict['passed'] else 'VERDICT FAILED'}"
        print(line, file=out)
        _print_loop(e.get("loop"), out)
        for problem in (verdict or {}).get("problems", []):
            print(f"    {problem}", file=out)
        for note in (verdict or {}).get("notes", []):
            if PRIOR_HELD_WORDS in note:      # what a pass does not say: the record informs little of the model
                print(f"    note: {note}", file=out)
    primary = doc.get("primary_solver")
    st = run.stitched.get(primary)
    if st is not None:
        b = st.boundary_summary()
        print(f"  boundaries: max |z| {b['max_abs_z']:.2f} over {b['checks']} checks, "
              f"{b['beyond_limit']} beyond {b['limit']:g} sigma" if b["checked"] else
              "  boundaries: not checked (no boundary between subranges)", file=out)
    tc = (doc.get("truth_check") or {}).get(primary, {}).get(doc["stitch_model"])
    if tc:
        print(f"  stitched vs truth: max |error| / sigma {tc['max_abs_z']:.2f}, "
              f"{100 * tc['fraction_within_1sigma']:.0f} % within 1 sigma", file=out)
    for v in doc.get("validation", []):
        r = (v.get("results") or {}).get(primary, {}).get(doc["stitch_model"])
        if not r:
            print(f"  validation {Path(v['record']).name}: {v.get('error', 'not done')}", file=out)
            continue
        print(f"  validation {Path(v['record']).name}: {validation_text(r)} -> "
              f"{'pass' if r['pass']['all'] else 'FAIL'}", file=out)
    _print_joint(doc, out)
    outdir = Path(run.out)
    print(f"  -> {outdir / 'campaign.json'}" + (f", {run.report_path}" if run.report_path else ""), file=out)
    checks = doc.get("campaign_checks")
    for line in check_lines(checks) if checks else []:
        print(f"  check {line}", file=out)
    if run.failed:
        names = sorted({f"{f['name']} {f['solver']}" for f in run.failed})
        print(f"verdict: FAIL: {len(run.failed)} task(s) did not finish ({', '.join(names)}): their errors follow",
              file=out)
    failed = run.verdict_failed
    if failed:
        print(f"verdict: FAIL: {len(failed)} of {len(doc['experiments'])} experiment(s) failed theirs "
              f"({', '.join(failed)}); converged, solvers agree and residuals consistent are required", file=out)
    if checks and not checks["passed"]:
        print(f"verdict: FAIL: {len(checks['failed'])} check(s) over the whole campaign failed: "
              + " | ".join(checks["failed"]), file=out)
    if not run.failed and not failed and not (checks and not checks["passed"]):
        if not any(e.get("verdict") for e in doc["experiments"]):
            print("verdict: pass: the campaign's checks pass (no per-subrange solver ran)", file=out)
        else:
            agree = ", its solvers agree" if len(doc.get("solvers") or ()) > 1 else ""
            print(f"verdict: pass: every experiment converged{agree} and its residuals are consistent", file=out)


def _print_joint(doc, out):
    """The joint campaign solver's lines of the summary (docs/campaign.md)."""
    from graph_calib.solvers.joint import JOINT

    for name, j in (doc.get(JOINT) or {}).items():
        _print_joint_one(name, j, out)


def _print_joint_one(name, j, out):
    if not j:
        return
    if j.get("status") == "failed":
        print(f"  {name}: FAILED: {j['error']}", file=out)
        return
    v = j.get("verdict") or {}
    print(f"  {name} ({j['status']}): degrees {', '.join(f'{k} {d}' for k, d in j['degrees'].items())}; "
          f"{v.get('text', '')}", file=out)
    for solver, cc in (j.get("cross_check") or {}).items():
        if cc.get("rms_z") is not None:
            print(f"    {name} at T_ref - {solver}: rms {cc['rms_z']:.2f}, max {cc['max_abs_z']:.2f} in the subrange's "
                  "sigma alone (the check below divides by both)", file=out)
    tc = j.get("truth_check") or {}
    if tc.get("points"):
        print(f"    {name} vs truth ({tc['mode']}): {100 * tc['fraction_within_2sigma']:.0f} % within 2 sigma, "
              f"max |z| {tc['max_abs_z']:.2f}", file=out)
    for val in j.get("validation", []):
        print(f"    {name} validation {Path(val['record']).name}: {validation_text(val['summary'])} -> "
              f"{'pass' if val['summary']['pass']['all'] else 'FAIL'}", file=out)


def _print_loop(loop, out):
    """One line of an experiment's closed loop: effects added (score, log10 p), error vs truth before -> after."""
    if not loop:
        return
    added = ", ".join(f"{a['effect']} (score {a['statistic']:.1f}, log10 p {a['log10_p']:.1f})"
                      for a in loop["added"]) or "nothing"
    line = f"    loop: added {added}"
    for a in loop.get("pooled") or []:
        if a.get("kind") == "joint":
            line += f"; carried {a['effect']} ({', '.join(a.get('adopted_in') or [])}, its prior the joint curve's)"
            continue
        if a.get("kind") == "carried":
            line += f"; carried {a['effect']} (adopted in {', '.join(a.get('adopted_in') or [])})"
            continue
        line += (f"; pooled test adopted {a['effect']} ({a['kind']} score {a['statistic']:.1f} > {a['threshold']:.1f} over "
                 f"{len(a['experiments'])} experiments, log10 p {a['log10_p']:.1f})")
    err = (loop.get("error_vs_truth") or {}).get(registry.PRIMARY_SOLVER) or {}
    if err.get("before") and err.get("after"):
        b, a = err["before"], err["after"]
        line += (f"; graph vs truth RMS {b['rms_z']:.2f} -> {a['rms_z']:.2f} sigma, max {b['max_abs_z']:.1f} -> "
                 f"{a['max_abs_z']:.1f}")
    print(line, file=out)


def run(args):
    from graph_calib.campaign import run_campaign

    options = options_from_args(args)
    result = run_campaign(args.manifest, args.out, options=options)
    print_summary(result)
    if result.failed:
        for f in result.failed:
            print(f"graph-calib campaign: {f['name']} {f['solver']} failed: {f['error']}", file=sys.stderr)
        return 1
    return 0 if result.document["verdict"]["passed"] and not result.verdict_failed else 3
