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

import numpy as np

from graph_calib import io
from graph_calib.campaign.execution import execute, experiment_summary, run_tasks
from graph_calib.campaign.tasks import (
    CACHE_VERSION, SOLVER_CHOICES, CampaignOptions, Task, cached, calibration_options, file_sha256, options_sha256,
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


# ---------------------------------------------------------------------------
# the campaign
# ---------------------------------------------------------------------------


def _solvers(campaign, options):
    choice = options.solvers or campaign.solver.get("solvers", "both")
    if choice not in SOLVER_CHOICES:
        raise InputError(f"unknown solver choice {choice!r}; known: {', '.join(SOLVER_CHOICES)}", dataset="--solver")
    return SOLVER_CHOICES[choice]


def _remove_stale_temporaries(folder):
    """Temporary files of writes cut short by a killed worker (``.<name>.*.tmp``)."""
    if not folder.is_dir():
        return
    for p in folder.glob(".*.tmp"):
        try:
            p.unlink()
        except OSError:
            pass


def plan(campaign, out, *, options):
    """Every task of a campaign with its cache key: ``(tasks to run, cached tasks)``."""
    solvers = _solvers(campaign, options)
    threads = 1 if (options.scheduler or options.workers != 0) else 0
    todo, done = [], []
    for e in campaign.experiments:
        check_experiment_header(e.file)
        copts = calibration_options(campaign, t_ref_degC=e.t_ref_degC)
        osha = options_sha256(copts)
        fsha = file_sha256(e.file)
        folder = Path(out) / e.name
        _remove_stale_temporaries(folder)
        for s in solvers:
            t = Task(name=e.name, file=str(e.file), solver=s, options=copts, out_dir=str(folder),
                     key=task_key(input_sha256=fsha, options_sha256=osha, solver=s), input_sha256=fsha,
                     options_sha256=osha, numba_threads=threads)
            (done if (not options.force and cached(t)) else todo).append(t)
    return todo, done


def _validation_tasks(campaign, out, records, *, options):
    """Tasks calibrating validation records that have no truth file (factor graph only)."""
    todo, done, refs = [], [], {}
    threads = 1 if (options.scheduler or options.workers != 0) else 0
    for rec in records:
        truth = truth_path(rec)
        if truth.is_file():
            refs[rec] = ("truth", truth)
            continue
        copts = calibration_options(campaign)
        osha = options_sha256(copts)
        fsha = file_sha256(rec)
        folder = Path(out) / "validation" / rec.stem
        _remove_stale_temporaries(folder)
        t = Task(name=f"validation/{rec.stem}", file=str(rec), solver="factor-graph", options=copts,
                 out_dir=str(folder), key=task_key(input_sha256=fsha, options_sha256=osha, solver="factor-graph"),
                 input_sha256=fsha, options_sha256=osha, numba_threads=threads)
        refs[rec] = ("estimate", t.result_path)
        (done if (not options.force and cached(t)) else todo).append(t)
    return todo, done, refs


def _check_out(out):
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", path=out, dataset="--out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc}", path=out, dataset="--out") from None
    return out


def check_experiment_header(path, *, dataset=None):
    """Cheap check that ``path`` is an experiment file (HDF5 with the right ``format``); InputError if not.

    The full validation (every rule of data-format.md) runs where the file is
    read, on the worker; this catches a wrong file before any work starts.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path=path, dataset=dataset)
    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format")
    except OSError:
        raise InputError("not an HDF5 file (an experiment file is HDF5, data-format.md)", path=path,
                         dataset=dataset) from None
    if isinstance(fmt, bytes):
        fmt = fmt.decode("utf-8", "replace")
    if isinstance(fmt, np.ndarray) and fmt.size == 1:
        fmt = fmt.item()
    if fmt != io.EXPERIMENT_FORMAT:
        raise InputError(f"not an experiment file: format attribute is {fmt!r}, expected {io.EXPERIMENT_FORMAT!r}",
                         path=path, dataset=dataset)


def _check_records(records):
    paths = []
    for r in records:
        p = Path(r).resolve()
        if not p.is_file():
            raise InputError("validation record not found" if not p.exists() else "not a file", path=p,
                             dataset="--validate")
        check_experiment_header(p, dataset="--validate")
        paths.append(p)
    return paths


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
    if options.stitch_model not in ("cubic", "linear"):
        raise InputError(f"must be 'cubic' or 'linear', got {options.stitch_model!r}", dataset="--stitch")
    out = _check_out(out)
    records = _check_records(options.validate)
    todo, done = plan(campaign, out, options=options)
    vtodo, vdone, refs = _validation_tasks(campaign, out, records, options=options)
    solvers = _solvers(campaign, options)
    if options.progress:
        print(f"campaign {campaign.imu_id}: {len(campaign.experiments)} experiment(s) x {len(solvers)} solver(s); "
              f"{len(done) + len(vdone)} cached, {len(todo) + len(vtodo)} to compute", file=sys.stderr)
    t_tasks = time.perf_counter()
    outcomes = execute(todo + vtodo, options=options, on_done=on_done)
    tasks_seconds = time.perf_counter() - t_tasks
    for t in done + vdone:
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
