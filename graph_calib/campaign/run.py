"""A whole campaign, :func:`run_campaign`, as a sequence of phases, one job each.

1. read and plan: the manifest read, the inputs checked, every task listed as to compute or cached
   (:func:`graph_calib.campaign.planning.plan_campaign`);
2. compute: the numba kernels warmed in this process, the tasks run
   (:func:`graph_calib.campaign.execution.execute`), the cached ones counted;
3. collect: the tasks' files read back per experiment, ``comparison.json`` written where both solvers
   finished, each experiment's verdict (converged, solvers agree, residuals consistent) in
   ``campaign.json`` and its ``comparison.json``, the truth files read; with the closed loop (default,
   :mod:`graph_calib.campaign.loop`) the results are those of the model the loop chose, and each
   experiment's ``loop`` records the effects added and why, residuals and errors before and after;
   the joint campaign solver (:func:`graph_calib.campaign.joint_run.solve_joint`) right after the first wave,
   so that every re-solve of the pooled waves carries the joint curves' orders its model lacks, and, where
   a final model still lacks some, the wave carrying them into those subranges with the joint's curvature as
   their prior (:mod:`graph_calib.campaign.curvature_wave`), whose results are then final;
4. stitch: every solver's results over temperature (:func:`graph_calib.stitching.stitch`);
5. truth check: the stitched curves against the truth files' ``temperature_curves``, or else against each
   subrange's own truth inside its range (:func:`graph_calib.campaign.truth.truth_check`); the joint
   campaign solver's cross-check and truth check against the final results
   (:func:`graph_calib.campaign.joint_run.joint_entry`, ``campaign.json``'s ``joint``);
6. validate: the stitched calibration on each independent record (:func:`graph_calib.evaluation.validation.validate`);
7. document and report: ``campaign.json`` (:class:`CampaignRun.document`) and ``report.html``.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from graph_calib import io
from graph_calib.campaign.checks import check_inputs, judge_campaign
from graph_calib.campaign.execution import Pool, execute
from graph_calib.campaign.curvature_wave import joint_carry, run_curvature_wave
from graph_calib.campaign.joint_run import joint_entry, joint_failures, solve_joint
from graph_calib.campaign.loop import loop_entry
from graph_calib.campaign.planning import plan_campaign
from graph_calib.campaign.tasks import CampaignOptions
from graph_calib.campaign.truth import truth_check, truth_path
from graph_calib.campaign.waves import run_waves
from graph_calib.errors import InputError
from graph_calib.records.experiment import Result
from graph_calib.reports.campaign_report import write_report
from graph_calib.solvers.joint import JOINT
from graph_calib.solvers.orchestration import judge
from graph_calib.solvers.registry import PRIMARY_SOLVER, comparison_order, primary_of
from graph_calib.stitching import Stitched, stitch
from graph_calib.evaluation.validation import Validation, truth_reference, validate, window_means

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
        :class:`graph_calib.evaluation.validation.Validation` objects (default model, primary solver first).
    failed : list of dict
        Tasks that raised: ``{"name", "solver", "error"}``.
    report_path : Path or None
        ``report.html``, when written.
    joint : graph_calib.records.experiment.Result or None
        The joint campaign solver's result (``joint.json``), when it ran.
    """

    @property
    def verdict_failed(self):
        """Names of the experiments whose verdict failed (cli.md: the campaign then exits 3)."""
        return [e["name"] for e in self.document["experiments"] if not e.get("verdict", {}).get("passed", True)]

    out: Path
    document: dict
    results: dict[str, dict[str, Result]] = field(default_factory=dict)
    summaries: dict[str, dict] = field(default_factory=dict)
    truths: dict[str, Result] = field(default_factory=dict)
    stitched: dict[str, Stitched] = field(default_factory=dict)
    validations: list[Validation] = field(default_factory=list)
    failed: list[dict] = field(default_factory=list)
    report_path: Path | None = None
    joint: Result | None = None


@dataclass(frozen=True)
class _Collected:
    """What the tasks left on disk, read back (phase 3).

    Attributes
    ----------
    experiments : list of dict
        ``campaign.json``'s ``experiments``.
    results, summaries, truths, failed
        As in :class:`CampaignRun`.
    """

    experiments: list[dict]
    results: dict[str, dict[str, Result]]
    summaries: dict[str, dict]
    truths: dict[str, Result]
    failed: list[dict]


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
    t_start = time.perf_counter()
    pool = Pool(options)        # one cluster for the first wave, the pooled test's waves and the joint's
    with io.no_empty_folder_if_refused(out):
        planned = _read_and_plan(manifest, out, options=options)
        check_inputs(planned)       # every input file read and checked before the first experiment starts
        if options.scheduler:
            pool.connect()          # a cluster that cannot be reached is refused before any work too
    try:
        outcomes, compute_timing = _compute(planned, options=options, on_done=on_done, pool=pool)
        # the joint curves before the pooled waves: a wave that solves an experiment again carries them too
        joint, joint_status = solve_joint(planned, _collect_final(planned, outcomes, None),
                                          progress=options.progress, force=options.force)
        pooled = run_waves(planned, outcomes, options=options, on_done=on_done, pool=pool, carry=joint_carry(joint))
        collected = _collect_final(planned, outcomes, pooled)
        carried = run_curvature_wave(planned, pooled, joint, options=options, on_done=on_done, pool=pool,
                                     sensor_ranges={n: s.get("sensor_temperature_range_degC")
                                                    for n, s in collected.summaries.items()})
        if carried is not pooled:       # the joint curves' missing orders carried: the subranges' new results
            pooled = carried
            collected = _collect_final(planned, outcomes, pooled)
    finally:
        pool.close()
    loop_doc = _loop(planned, collected, pooled)
    stitched = _stitch(planned, collected)
    truth_doc = _check_truth(stitched, collected.truths, collected.summaries)
    joint_doc = joint_entry(planned, collected, joint, joint_status)
    truth_doc.update({s: {JOINT: e["truth_check"]} for s, e in joint_doc.items() if e["truth_check"]})
    primary = primary_of(tuple(stitched))
    validations, validation_doc = _validate(planned, stitched, outcomes, primary=primary,
                                            stitch_model=options.stitch_model)
    document = _document(planned, collected, stitched, outcomes, primary=primary, stitch_model=options.stitch_model,
                         truth_doc=truth_doc, validation_doc=validation_doc, compute_timing=compute_timing)
    document[JOINT] = joint_doc
    collected.failed.extend(joint_failures(joint_doc))     # after the timing counted the tasks
    document["loop"] = loop_doc
    if pooled is not None:
        document["timing"]["pooled_seconds"] = pooled.document["seconds"]
    judge_campaign(document, results=collected.results, joint=joint)     # checks over the whole campaign
    run = CampaignRun(out=planned.out, document=document, results=collected.results, summaries=collected.summaries,
                      truths=collected.truths, stitched=stitched, validations=validations, failed=collected.failed,
                      joint=joint)
    _write_report_and_document(run, report=options.report, t_start=t_start)
    return run


def _read_and_plan(manifest, out, *, options):
    """Phase 1: the manifest read, the inputs checked, the tasks listed; one line on stderr with ``progress``."""
    campaign = manifest if isinstance(manifest, io.Campaign) else io.read_manifest(manifest)
    planned = plan_campaign(campaign, out, options=options)
    if options.progress:
        print(f"campaign {campaign.imu_id}: {len(campaign.experiments)} experiment(s) x {len(planned.solvers)} "
              f"solver(s); {len(planned.from_cache)} cached, {len(planned.to_compute)} to compute", file=sys.stderr)
    return planned


def _compute(planned, *, options, on_done, pool=None):
    """Phase 2: the tasks run; ``({(name, solver): outcome dict}, timing dict)`` with the cached tasks' outcomes.

    The timing holds ``tasks_seconds`` (wall time of the tasks, the warm-up left out), ``warmup_seconds``,
    ``compile_seconds`` and ``compiled_signatures`` of the warm-up, and ``tasks_compile_seconds`` (numba
    compiling inside the tasks, already left out of their seconds; 0 when the warm-up covered them).

    Raises
    ------
    InputError
        A worker found an experiment file breaking a rule of the format (finished tasks stay cached).
    """
    t_tasks = time.perf_counter()
    timing = {}
    outcomes = execute(planned.to_compute, options=options, on_done=on_done, timing=timing, pool=pool)
    timing["tasks_seconds"] = time.perf_counter() - t_tasks - timing["warmup_seconds"]
    timing["tasks_compile_seconds"] = sum(o.get("compile_seconds", 0.0) for o in outcomes.values())
    for t in planned.from_cache:
        outcomes[(t.name, t.solver)] = {"name": t.name, "solver": t.solver, "status": "cached"}
    bad = [o for o in outcomes.values() if o.get("input_error")]
    if bad:  # bad input found by a worker: one clear message, exit code 2 (finished tasks stay cached)
        raise InputError(bad[0]["input_error"])
    return outcomes, timing


def _collect_final(planned, outcomes, pooled):
    """Phase 3 over the final results: the first wave's, or a later wave's where one re-solved an experiment."""
    return _collect(planned, {**outcomes, **(pooled.outcomes if pooled else {})},
                    folders=pooled.folders if pooled else {})


def _collect(planned, outcomes, *, folders):
    """Phase 3: every experiment's summary and results read back, ``comparison.json`` written, its truth read.

    ``folders``: ``{experiment: folder relative to the output}`` of those whose final results a pooled wave
    wrote (:func:`graph_calib.campaign.waves.run_waves`); the others' are in their own folder.
    """
    out = planned.out
    experiments_doc, results, summaries, truths, failed = [], {}, {}, {}, []
    for e in planned.campaign.experiments:
        folder = out / e.name
        rfolder = Path(folders.get(e.name, e.name))
        entry = {"name": e.name, "file": str(e.file), "folder": e.name, "t_ref_degC": e.t_ref_degC, "results": {}}
        summary_file = folder / "summary.json"
        if summary_file.is_file():
            summ = json.loads(summary_file.read_text(encoding="utf-8"))
            summaries[e.name] = summ
            entry.update({k: summ[k] for k in ("t_ref_degC", "duration_s", "n_samples", "rate_hz",
                                               "temperature_range_degC", "sensor_temperature_range_degC")})
        res = {}
        for s in planned.solvers:
            oc = outcomes.get((e.name, s), {"status": "missing"})
            info = {"status": oc["status"], "file": (rfolder / f"{s}.json").as_posix()}
            if oc["status"] == "failed":
                info["error"] = oc["error"]
                failed.append({"name": e.name, "solver": s, "error": oc["error"]})
            p = out / rfolder / f"{s}.json"
            if oc["status"] in ("computed", "cached") and p.is_file():
                r = io.read_result(p)
                res[s] = r
                info["seconds"] = (r.extra.get("campaign") or {}).get("seconds")
                if "compile_seconds" in (r.extra.get("campaign") or {}):
                    info["compile_seconds"] = r.extra["campaign"]["compile_seconds"]
            entry["results"][s] = info
        if res:
            # the verdict of the experiment's solvers together: in campaign.json and comparison.json (the
            # tasks' result files stay as their workers wrote them, so that cached work is kept byte for byte)
            _, cmp_, verdict = judge(res, order=comparison_order(res), stamp=False)
            entry["verdict"] = verdict.to_json()
        else:
            cmp_ = None
        results[e.name] = res
        if cmp_ is not None:
            io.atomic_write_json(folder / "comparison.json", cmp_)
            entry["comparison"] = cmp_["summary"]
        tp = truth_path(e.file)
        if tp.is_file():
            try:
                truths[e.name] = io.read_result(tp)
                entry["truth"] = str(tp)
            except InputError as exc:
                entry["truth_error"] = str(exc)
        experiments_doc.append(entry)
    return _Collected(experiments=experiments_doc, results=results, summaries=summaries, truths=truths,
                      failed=failed)


def _loop(planned, collected, pooled):
    """Phase 3b: the closed loop's record per experiment (``experiments[i].loop``) and its summary.

    Per experiment :func:`graph_calib.campaign.loop.loop_entry` (the model chosen and why, residual RMS
    before and after, the error against its truth before and after) and ``pooled``, what the campaign's
    pooled score test adopted there (per adoption its wave, pooled statistic, dof, threshold, log10 p and the
    experiments pooled; :mod:`graph_calib.campaign.pooled`); the summary (``campaign.json``'s ``loop``) says
    whether the loop ran, its options, which experiments it changed (``added``: their own loop's effects,
    ``pooled``: the pooled test's) and ``pooled``, the pooled test's waves (:func:`run_waves`).
    """
    dopts = planned.todo[0].diagnosis if planned.todo else (planned.done[0].diagnosis if planned.done else None)
    adopted = pooled.adopted if pooled else {}
    changed = []
    for entry in collected.experiments:
        le = loop_entry(planned.out / entry["name"], collected.results.get(entry["name"], {}),
                        collected.truths.get(entry["name"]))
        if le is not None:
            le["pooled"] = adopted.get(entry["name"], [])
            entry["loop"] = le
            if le["added"] or le["pooled"]:
                changed.append({"name": entry["name"], "added": [a["effect"] for a in le["added"]],
                                "pooled": [a["effect"] for a in le["pooled"]]})
    return {"enabled": dopts is not None,
            "options": None if dopts is None else {"alpha": dopts.alpha, "max_added": dopts.max_added,
                                                   "solvers": list(dopts.solvers)},
            "changed": changed, "pooled": pooled.document if pooled else None}


def _stitch(planned, collected):
    """Phase 4: ``{solver: Stitched}`` over the experiments that solver finished."""
    stitched = {}
    for s in planned.solvers:
        names = [e.name for e in planned.campaign.experiments if s in collected.results[e.name]]
        if not names:
            continue
        ranges = [collected.summaries.get(n, {}).get("sensor_temperature_range_degC") for n in names]
        stitched[s] = stitch([collected.results[n][s] for n in names], names=names, sensor_ranges=ranges, solver=s)
    return stitched


def _check_truth(stitched, truths, summaries):
    """Phase 5: ``{solver: {model: truth_check}}``, ``{}`` without a truth file.

    Against the truth files' ``temperature_curves`` when they have them; otherwise each curve against each
    subrange's own truth inside that subrange's sensor temperature range (never extrapolated).
    """
    truth_doc = {}
    if truths:
        ranges = {n: summaries.get(n, {}).get("sensor_temperature_range_degC") for n in truths}
        for s, st in stitched.items():
            truth_doc[s] = {m: truth_check(st, truths, model=m, sensor_ranges=ranges) for m in ("cubic", "linear")}
    return truth_doc


def _validate(planned, stitched, outcomes, *, primary, stitch_model):
    """Phase 6: the stitched calibrations on each validation record, both models, primary solver first.

    Returns
    -------
    validations : list of graph_calib.evaluation.validation.Validation
        Those of ``stitch_model``.
    validation_doc : list of dict
        ``campaign.json``'s ``validation``.
    """
    validations, validation_doc = [], []
    if not planned.records or primary is None:
        return validations, validation_doc
    order = [primary] + [s for s in stitched if s != primary]
    for rec in planned.records:
        kind, ref_path = planned.references[rec]
        entry = {"record": str(rec), "reference_kind": kind, "reference": str(ref_path)}
        if not Path(ref_path).is_file():
            oc = outcomes.get((f"validation/{rec.stem}", PRIMARY_SOLVER), {})
            entry["error"] = oc.get("error", "the record's own calibration is missing")
            validation_doc.append(entry)
            continue
        reference = truth_reference(io.read_result(ref_path))
        exp = io.read_experiment(rec)
        w = window_means(exp)
        entry["results"] = {}
        for s in order:
            entry["results"][s] = {}
            for m in (stitch_model, "cubic" if stitch_model == "linear" else "linear"):
                v = validate(exp, stitched[s], reference, model=m, windows=w, record_name=rec.name)
                entry["results"][s][m] = v.summary()
                if m == stitch_model:
                    validations.append(v)
        validation_doc.append(entry)
        del exp
    return validations, validation_doc


def _document(planned, collected, stitched, outcomes, *, primary, stitch_model, truth_doc, validation_doc,
              compute_timing):
    """Phase 7a: the content of ``campaign.json`` (its timing completed by :func:`_write_report_and_document`)."""
    campaign, failed = planned.campaign, collected.failed
    n_computed = sum(1 for o in outcomes.values() if o["status"] == "computed")
    return {
        "format": CAMPAIGN_FORMAT, "version": CAMPAIGN_VERSION,
        "manifest": str(campaign.path), "imu_id": campaign.imu_id, "grade": campaign.grade,
        "solvers": list(planned.solvers), "primary_solver": primary, "stitch_model": stitch_model,
        "model": {"effects": list(campaign.effects), "exclude": list(campaign.exclude), "priors": campaign.priors,
                  "solver_options": campaign.solver},
        "experiments": collected.experiments,
        "verdict": {"passed": all(e.get("verdict", {}).get("passed", True) for e in collected.experiments),
                    "failed": [e["name"] for e in collected.experiments
                               if not e.get("verdict", {}).get("passed", True)]},
        "stitching": {s: st.to_dict() for s, st in stitched.items()},
        "truth_check": truth_doc,
        "validation": validation_doc,
        "failed": failed,
        "timing": {"tasks_computed": n_computed, "tasks_cached": len(outcomes) - n_computed
                   - len(failed), "tasks_failed": len(failed), **compute_timing},
    }


def _write_report_and_document(run, *, report, t_start):
    """Phase 7b: ``report.html`` (with ``report``) and then ``campaign.json``, their timings in the document."""
    doc = run.document
    if report:
        t_rep = time.perf_counter()
        run.report_path = write_report(run, run.out / "report.html")
        doc["timing"]["report_seconds"] = time.perf_counter() - t_rep
    doc["timing"]["total_seconds"] = time.perf_counter() - t_start
    io.atomic_write_json(run.out / "campaign.json", doc)


__all__ = ["CAMPAIGN_FORMAT", "CAMPAIGN_VERSION", "CampaignRun", "run_campaign"]
