"""The closed loop inside a campaign: every experiment diagnosed, the effects its data ask for adopted.

- :func:`loop_options`: whether the loop runs (``CampaignOptions.diagnose``, else the manifest's
  ``[solver] diagnose``, else on) and its :class:`graph_calib.diagnosis.DiagnosisOptions`;
- :func:`loop_record`: what a task keeps of a :class:`graph_calib.diagnosis.Diagnosis` in its result file's
  ``campaign.loop`` (the model chosen and why: each effect added with its score and log10 p, the residual
  RMS before and after): small, so that a cached task keeps it without running again;
- :func:`declared_path`: where a task keeps the declared model's result (before the loop) when the loop
  added something (``<experiment>/declared/<solver>.json``);
- :func:`truth_errors`: a result against a truth, per element at the result's own ``T_ref`` (RMS
  normalised error, largest, share within 3 sigma);
- :func:`wave_record`: the record carried on through a wave of the campaign's pooled score test;
- :func:`loop_entry`: ``campaign.json``'s ``loop`` of one experiment, from its results and its truth.

The worker side (diagnose, write the files) is :func:`graph_calib.campaign.execution.run_tasks`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from graph_calib.sensors import effects
from graph_calib import io
from graph_calib.diagnosis import DiagnosisOptions, residual_rms
from graph_calib.errors import InputError
from graph_calib.solvers.registry import PRIMARY_SOLVER, primary_of

#: The files of the declared model's results (before the loop), beside the chosen ones.
DECLARED_FOLDER = "declared"


def loop_options(campaign, options, solvers):
    """``DiagnosisOptions`` of the loop, or None when it is off.

    Parameters
    ----------
    campaign : graph_calib.io.Campaign
    options : CampaignOptions
        ``diagnose``: True / False, or None for the manifest's ``[solver] diagnose`` (default on).
    solvers : tuple of str
        The campaign's per-experiment solvers.  The loop's tests always use the registry's primary solver
        (:data:`graph_calib.solvers.registry.PRIMARY_SOLVER`); the others are run on the declared and the
        chosen model.
    """
    on = options.diagnose if options.diagnose is not None else campaign.solver.get("diagnose", True)
    if not on:
        return None
    return DiagnosisOptions(solvers=(PRIMARY_SOLVER,) + tuple(s for s in solvers if s != PRIMARY_SOLVER))


def declared_path(task):
    """``<experiment>/declared/<solver>.json``: the task's result with the declared model."""
    return Path(task.out_dir) / DECLARED_FOLDER / f"{task.solver}.json"


def loop_record(diagnosis):
    """What a task keeps of its experiment's loop (``campaign.loop`` of its result file), JSON-ready.

    ``declared`` and ``chosen`` models (parameter names), ``added`` (per effect: ``round``, ``statistic``
    (the score), ``threshold``, ``dof``, ``log10_p``, the round's ``decision``), the last round's decision,
    ``unexplained`` (significant driver signatures left), ``residual_rms`` ``{"before", "after"}`` (per
    solver the overall RMS of the whitened residuals or normalised innovations, and per kind),
    ``seconds``, and ``final_round``: the last round's index and every candidate it tested (``effect``,
    ``statistic``, ``dof``, ``threshold``, ``log10_p``, and its ``score`` vector, ``information`` matrix
    (row-major) and the prior sigmas ``scale`` (:class:`graph_calib.diagnosis.CandidateTest`); ``dof`` 0 and
    empty lists when skipped), at the chosen model: what the
    campaign's pooled score test sums (:mod:`graph_calib.campaign.pooled`), without recomputing anything.
    """
    added = []
    for r in diagnosis.rounds:
        if r.added is None:
            continue
        t = next(c for c in r.candidates if c.name == r.added)
        added.append({"effect": t.name, "round": r.index, "statistic": float(t.statistic),
                      "threshold": float(t.threshold), "dof": int(t.dof), "log10_p": float(t.log10_p),
                      "decision": r.decision})
    last = diagnosis.rounds[-1] if diagnosis.rounds else None

    def rms(stage):
        out = {}
        for solver, d in residual_rms(stage).items():
            out[solver] = {"overall": float(d["overall"]),
                           "per_kind": {k: [float(x) for x in v] for k, v in d.items() if isinstance(v, list)}}
        return out

    return {"declared": list(diagnosis.before.layout), "chosen": list(diagnosis.after.layout), "added": added,
            "decision": last.decision if last else "", "unexplained": bool(diagnosis.unexplained),
            "signature": [f"{d.group} on {d.axis}" for d in diagnosis.signature[:5]],
            "residual_rms": {"before": rms(diagnosis.before), "after": rms(diagnosis.after)},
            "seconds": float(diagnosis.seconds),
            "final_round": {"round": last.index if last else 0,
                            "candidates": [] if last is None else [
                                {"effect": t.name, "statistic": float(t.statistic), "dof": int(t.dof),
                                 "threshold": float(t.threshold) if t.dof else None,
                                 "log10_p": float(t.log10_p), "score": list(t.score),
                                 "information": list(t.information), "scale": list(t.scale)}
                                for t in last.candidates]}}


def wave_record(previous, diagnosis, *, wave, effects):
    """The loop record after a wave of the campaign's pooled test (:mod:`graph_calib.campaign.pooled`).

    Parameters
    ----------
    previous : dict
        The record the wave started from (:func:`loop_record`, or an earlier wave's).
    diagnosis : graph_calib.diagnosis.Diagnosis
        The wave's :func:`graph_calib.diagnosis.diagnose_from` (its ``before`` the grown model).
    wave : int
    effects : tuple of str
        The effects this wave adopted (the pooled test's one, or the joint curvature's orders).

    Returns
    -------
    dict
        ``previous`` carried on: ``declared`` kept, ``chosen`` the wave's, ``added`` extended by what the wave's
        own rounds added (each with its ``wave``), ``pooled`` extended by ``{"effect", "wave"}`` per effect (the pooled
        statistics are the campaign's, in ``campaign.json``), ``residual_rms.before`` kept and ``after`` the
        wave's, ``seconds`` summed, ``decision``, ``unexplained``, ``signature`` and ``final_round`` the wave's.
    """
    new = loop_record(diagnosis)
    return {**previous, "chosen": new["chosen"],
            "added": list(previous["added"]) + [dict(a, wave=wave) for a in new["added"]],
            "pooled": list(previous.get("pooled", [])) + [{"effect": e, "wave": wave} for e in effects],
            "decision": new["decision"], "unexplained": new["unexplained"], "signature": new["signature"],
            "residual_rms": {"before": previous["residual_rms"]["before"], "after": new["residual_rms"]["after"]},
            "seconds": float(previous["seconds"]) + new["seconds"], "final_round": new["final_round"]}


def _truth_at(truth, t_ref):
    """The truth's values at ``t_ref`` (degC): its own at its ``T_ref``, else from its temperature curves.

    Each curve's value and its derivatives give the element and its ``*_tc`` (``*_tc2``, ``*_tc3``)
    coefficients at ``t_ref``.  None when neither applies (a truth is never extrapolated).
    """
    if abs(truth.t_ref_degC - t_ref) < 1e-9:
        return dict(truth.values)
    curves = (truth.extra or {}).get("temperature_curves")
    if not curves:
        return None
    P = np.polynomial.polynomial
    values = dict(truth.values)
    for flat, cv in curves.items():
        parameter, _ = flat.rsplit(".", 1)
        axis = flat.rsplit(".", 1)[1]
        coef = np.asarray(cv["coefficients"], dtype=float)
        d = t_ref - float(cv["t0_degC"])
        values[flat] = float(P.polyval(d, coef))
        fact = 1.0
        for order, name in sorted(effects.temperature_family(parameter)[1].items()):
            fact *= order
            key = f"{name}.{axis}"
            if key in values or order == 1:
                values[key] = float(P.polyval(d, P.polyder(coef, order)) / fact) if coef.size > order else 0.0
    return values


def truth_errors(result, truth):
    """``result`` against ``truth`` over the declared parameters both hold, each at the result's ``T_ref``.

    Returns
    -------
    dict or None
        ``rms_z`` (RMS normalised error), ``max_abs_z``, ``worst`` (element), ``fraction_within_3sigma``,
        ``n``; None when the truth holds no value at the result's ``T_ref`` (different ``T_ref`` and no
        temperature curves).
    """
    tv = _truth_at(truth, result.t_ref_degC)
    if tv is None or result.sigmas is None:
        return None
    names = [e for p in effects.DECLARED for e in effects.effect(p).element_names()
             if e in result.values and e in tv and result.sigmas.get(e, 0.0) > 0]
    if not names:
        return None
    z = np.array([(result.values[e] - tv[e]) / result.sigmas[e] for e in names])
    i = int(np.argmax(np.abs(z)))
    return {"rms_z": float(np.sqrt(np.mean(z**2))), "max_abs_z": float(abs(z[i])), "worst": names[i],
            "fraction_within_3sigma": float(np.mean(np.abs(z) <= 3.0)), "n": int(z.size)}


def loop_entry(folder, results, truth=None):
    """``campaign.json``'s ``loop`` of one experiment (None when its results carry no loop).

    Parameters
    ----------
    folder : Path
        The experiment's output folder.
    results : dict
        ``{solver: Result}`` of the chosen model.
    truth : graph_calib.records.experiment.Result, optional

    Returns
    -------
    dict or None
        :func:`loop_record` of its primary solver's (else first) result, with ``error_vs_truth``
        ``{solver: {"before", "after"}}`` (:func:`truth_errors`) when a truth exists.
    """
    recs = {s: (r.extra.get("campaign") or {}).get("loop") for s, r in results.items()}
    rec = recs.get(primary_of(tuple(recs))) or next((v for v in recs.values() if v), None)
    if rec is None:
        return None
    entry = dict(rec)
    if truth is not None:
        err = {}
        # the declared model's results: declared/ when the experiment's own loop added something, else the
        # experiment's own result files when a pooled wave changed them, else the results themselves
        first_wave = any("wave" not in a for a in rec["added"])
        for s, r in results.items():
            before = r
            if first_wave or rec.get("pooled"):
                p = Path(folder) / (DECLARED_FOLDER if first_wave else "") / f"{s}.json"
                try:
                    before = io.read_result(p)
                except InputError:
                    before = None
            err[s] = {"before": None if before is None else truth_errors(before, truth),
                      "after": truth_errors(r, truth)}
        entry["error_vs_truth"] = err
    return entry


__all__ = ["DECLARED_FOLDER", "loop_options", "loop_record", "wave_record", "declared_path", "truth_errors", "loop_entry"]
