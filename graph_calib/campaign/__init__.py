r"""A calibration campaign: every experiment with both solvers, in parallel, cached, stitched, validated.

This is the public Python API behind ``graph-calib campaign``::

    from graph_calib.campaign import CampaignOptions, run_campaign
    run = run_campaign("campaign.toml", "out", options=CampaignOptions(workers=2))
    run.stitched["factor-graph"].curves["gyro.bias.x"].evaluate([25.0])

Work and files
--------------
One *task* is one experiment calibrated by one solver; the tasks of one
experiment run together as one job (the problem is set up once for both
solvers).  Jobs run on Dask
workers (a local cluster of processes with one thread each, sized for the
machine, or an existing cluster given by its scheduler address; workers must
see the output folder) or, with ``workers=0``, one after the other in this
process.  A task writes, into ``OUT/<experiment name>/``, each file atomically:

- ``summary.json``: the experiment's length, reference temperature, sensor
  temperature ranges and a thinned temperature series;
- ``<solver>.residuals.h5``: the solver's whitened residuals (factor graph) or
  normalised innovations (filter) per measurement kind, for the residual plots:
  the residual-series file of ``docs/data-format.md``, the one ``graph-calib
  calibrate --residuals`` writes (:func:`graph_calib.io.write_residuals`);
- ``<solver>.json``: the result (``data-format.md``), written last; its
  top-level ``campaign`` object holds the task's cache key.

The main process then writes ``comparison.json`` per experiment, stitches every
solver's results over temperature (:mod:`graph_calib.stitching`), validates the
stitched calibration on independent records (:mod:`graph_calib.validation`), and
writes ``campaign.json`` and ``report.html``.

Caching and resuming
--------------------
The cache key of a task is a SHA-256 over the experiment file's content, the
calibration options (repr of :class:`graph_calib.calibrate.CalibrationOptions`,
reference temperature included), the solver and :data:`CACHE_VERSION`.  A task
whose result file carries the same key (and whose residual and summary files
exist) is not run again.  So an interrupted campaign resumes where it stopped
(finished tasks are on disk, a task cut short left nothing, thanks to the
atomic writes) and a rerun does only what changed.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from graph_calib import io
from graph_calib.campaign.execution import execute, experiment_summary, run_tasks
from graph_calib.campaign.planning import check_experiment_header, plan, plan_campaign
from graph_calib.campaign.tasks import (
    CACHE_VERSION, CampaignOptions, Task, cached, calibration_options, file_sha256, options_sha256,
    task_key,
)
from graph_calib.campaign.truth import truth_check, truth_path
from graph_calib.errors import InputError
from graph_calib.solvers.results import compare

#: Format name of ``campaign.json``.
CAMPAIGN_FORMAT = "imu-calibration-campaign"
CAMPAIGN_VERSION = 1


@dataclass
class CampaignRun:
    """What :func:`run_campaign` produced (files on disk, the main objects in memory).

    Attributes
    ----------
    out : Path
    document : dict
        The content of ``campaign.json``.
    results : dict
        ``{experiment name: {solver: Result}}``.
    summaries : dict
        ``{experiment name: summary dict}``.
    truths : dict
        ``{experiment name: truth Result}`` where a truth file exists.
    stitched : dict
        ``{solver: graph_calib.stitching.Stitched}``.
    validations : list
        :class:`graph_calib.validation.Validation` objects (default model, primary solver first).
    failed : list of dict
        Tasks that raised: ``{"name", "solver", "error"}``.
    """

    out: Path
    document: dict
    results: dict = field(default_factory=dict)
    summaries: dict = field(default_factory=dict)
    truths: dict = field(default_factory=dict)
    stitched: dict = field(default_factory=dict)
    validations: list = field(default_factory=list)
    failed: list = field(default_factory=list)
    report_path: Path | None = None


def run_campaign(manifest, out, *, options=CampaignOptions(), on_done=None):
    """Run (or resume) a campaign: calibrate, compare, stitch, validate, write every file.

    Parameters
    ----------
    manifest : str, Path or graph_calib.io.Campaign
    out : str or Path
        Output folder (created).
    options : CampaignOptions
    on_done : callable, optional
        Called with each finished task's outcome dict (in the main process).

    Returns
    -------
    CampaignRun

    Raises
    ------
    InputError
        A bad manifest, a missing experiment or validation file, a bad option.
    """
    from graph_calib.stitching import stitch

    t_start = time.perf_counter()
    campaign = manifest if isinstance(manifest, io.Campaign) else io.read_manifest(manifest)
    planned = plan_campaign(campaign, out, options=options)
    out, records, refs, solvers = planned.out, planned.records, planned.references, planned.solvers
    todo, done, vtodo, vdone = planned.todo, planned.done, planned.validation_todo, planned.validation_done
    if options.progress:
        print(f"campaign {campaign.imu_id}: {len(campaign.experiments)} experiment(s) x {len(solvers)} solver(s); "
              f"{len(done) + len(vdone)} cached, {len(todo) + len(vtodo)} to compute", file=sys.stderr)
    t_tasks = time.perf_counter()
    outcomes = execute(planned.to_compute, options=options, on_done=on_done)
    tasks_seconds = time.perf_counter() - t_tasks
    for t in planned.from_cache:
        outcomes[(t.name, t.solver)] = {"name": t.name, "solver": t.solver, "status": "cached"}
    bad = [o for o in outcomes.values() if o.get("input_error")]
    if bad:  # bad input found by a worker: one clear message, exit code 2 (finished tasks stay cached)
        raise InputError(bad[0]["input_error"])

    run = CampaignRun(out=out, document={})
    experiments_doc = []
    for e in campaign.experiments:
        folder = out / e.name
        entry = {"name": e.name, "file": str(e.file), "folder": e.name, "t_ref_degC": e.t_ref_degC, "results": {}}
        summary_file = folder / "summary.json"
        if summary_file.is_file():
            summ = json.loads(summary_file.read_text(encoding="utf-8"))
            run.summaries[e.name] = summ
            entry.update({k: summ[k] for k in ("t_ref_degC", "duration_s", "n_samples", "rate_hz",
                                               "temperature_range_degC", "sensor_temperature_range_degC")})
        res = {}
        for s in solvers:
            oc = outcomes.get((e.name, s), {"status": "missing"})
            info = {"status": oc["status"], "file": f"{e.name}/{s}.json"}
            if oc["status"] == "failed":
                info["error"] = oc["error"]
                run.failed.append({"name": e.name, "solver": s, "error": oc["error"]})
            p = folder / f"{s}.json"
            if oc["status"] in ("computed", "cached") and p.is_file():
                r = io.read_result(p)
                res[s] = r
                info["seconds"] = (r.extra.get("campaign") or {}).get("seconds")
            entry["results"][s] = info
        run.results[e.name] = res
        if "sqrt-kf" in res and "factor-graph" in res:
            cmp_ = compare(res["sqrt-kf"], res["factor-graph"])
            io.atomic_write_json(folder / "comparison.json", cmp_)
            entry["comparison"] = cmp_["summary"]
        tp = truth_path(e.file)
        if tp.is_file():
            try:
                run.truths[e.name] = io.read_result(tp)
                entry["truth"] = str(tp)
            except InputError as exc:
                entry["truth_error"] = str(exc)
        experiments_doc.append(entry)

    # stitching, per solver
    stitch_doc = {}
    for s in solvers:
        names = [e.name for e in campaign.experiments if s in run.results[e.name]]
        if not names:
            continue
        ranges = [run.summaries.get(n, {}).get("sensor_temperature_range_degC") for n in names]
        st = stitch([run.results[n][s] for n in names], names=names, sensor_ranges=ranges, solver=s)
        run.stitched[s] = st
        stitch_doc[s] = st.to_dict()
    truth_any = next(iter(run.truths.values()), None)
    truth_doc = {}
    if truth_any is not None:
        for s, st in run.stitched.items():
            truth_doc[s] = {m: truth_check(st, truth_any, model=m) for m in ("cubic", "linear")}

    # validation
    validation_doc = []
    primary = "factor-graph" if "factor-graph" in run.stitched else next(iter(run.stitched), None)
    if records and primary is not None:
        from graph_calib.validation import ResultCalibration, validate, window_means

        order = [primary] + [s for s in run.stitched if s != primary]
        for rec in records:
            kind, ref_path = refs[rec]
            entry = {"record": str(rec), "reference_kind": kind, "reference": str(ref_path)}
            if not Path(ref_path).is_file():
                oc = outcomes.get((f"validation/{rec.stem}", "factor-graph"), {})
                entry["error"] = oc.get("error", "the record's own calibration is missing")
                validation_doc.append(entry)
                continue
            reference = ResultCalibration(io.read_result(ref_path))
            exp = io.read_experiment(rec)
            w = window_means(exp)
            entry["results"] = {}
            for s in order:
                entry["results"][s] = {}
                for m in (options.stitch_model, "cubic" if options.stitch_model == "linear" else "linear"):
                    v = validate(exp, run.stitched[s], reference, model=m, windows=w, record_name=rec.name)
                    entry["results"][s][m] = v.summary()
                    if m == options.stitch_model:
                        run.validations.append(v)
            validation_doc.append(entry)
            del exp

    n_computed = sum(1 for o in outcomes.values() if o["status"] == "computed")
    doc = {
        "format": CAMPAIGN_FORMAT, "version": CAMPAIGN_VERSION,
        "manifest": str(campaign.path), "imu_id": campaign.imu_id, "grade": campaign.grade,
        "solvers": list(solvers), "primary_solver": primary, "stitch_model": options.stitch_model,
        "model": {"effects": list(campaign.effects), "exclude": list(campaign.exclude), "priors": campaign.priors,
                  "solver_options": campaign.solver},
        "experiments": experiments_doc,
        "stitching": stitch_doc,
        "truth_check": truth_doc,
        "validation": validation_doc,
        "failed": run.failed,
        "timing": {"tasks_computed": n_computed, "tasks_cached": len(outcomes) - n_computed
                   - len(run.failed), "tasks_failed": len(run.failed), "tasks_seconds": tasks_seconds},
    }
    run.document = doc
    if options.report:
        from graph_calib.reports.campaign_report import write_report

        t_rep = time.perf_counter()
        run.report_path = write_report(run, out / "report.html")
        doc["timing"]["report_seconds"] = time.perf_counter() - t_rep
    doc["timing"]["total_seconds"] = time.perf_counter() - t_start
    io.atomic_write_json(out / "campaign.json", doc)
    return run


__all__ = ["CAMPAIGN_FORMAT", "CACHE_VERSION", "CampaignOptions", "CampaignRun", "Task", "calibration_options",
           "file_sha256", "options_sha256", "task_key", "cached", "plan", "run_tasks", "execute", "run_campaign",
           "truth_check", "truth_path", "experiment_summary", "check_experiment_header"]
