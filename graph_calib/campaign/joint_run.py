"""The joint campaign solver inside a campaign: run (or read from the cache), cross-checked, checked against truth.

:func:`run_joint` is the campaign's joint phase (after the per-subrange results are collected):

1. the cache: ``joint.json`` in the output folder is reused when its key (SHA-256 over every experiment
   file, the calibration options of each and the solver) matches;
2. else every experiment is read and made a problem in this process, warm-started from its result by the
   registry's primary solver when the campaign has it, and solved jointly through the solver registry; the
   result file (:mod:`graph_calib.solvers.joint.result`) is written atomically;
3. the cross-check: per subrange and element, the joint calibration at the subrange's ``T_ref`` minus
   each per-subrange solver's estimate, in units of that estimate's sigma;
4. the truth check: against a truth file's ``temperature_curves`` (``data-format.md``) over each
   element's whole calibrated range when one has them, else against each subrange's own truth inside
   that subrange's sensor temperature range only (never extrapolated);
5. validation: the joint calibration on each validation record with a reference.
"""

from __future__ import annotations

import hashlib
import sys
import time
from pathlib import Path

import numpy as np

from graph_calib import io
from graph_calib.campaign.tasks import calibration_options, file_sha256, options_sha256, task_key
from graph_calib.compensation.joint import JointCalibration
from graph_calib.errors import InputError
from graph_calib.solvers.joint.result import joint_element_at, joint_result, read_joint_result
from graph_calib.solvers.joint.solver import JOINT, WarmStart
from graph_calib.records.problem import build_problem
from graph_calib.sensors.curves import evaluate_polynomial_curve
from graph_calib.solvers.registry import PRIMARY_SOLVER, get_solver
from graph_calib.stitching import sensor_of
from graph_calib.evaluation.validation import ResultCalibration, truth_reference, validate

#: The joint result's file name in the campaign's output folder.
JOINT_FILE = "joint.json"
#: Points per element and subrange (or over the whole range) at which the truth check compares curves.
TRUTH_POINTS = 11


def _key(planned):
    parts = []
    for e in planned.campaign.experiments:
        opts = calibration_options(planned.campaign, t_ref_degC=e.t_ref_degC)
        parts.append(f"{file_sha256(e.file)}:{options_sha256(opts)}")
    combined = hashlib.sha256("|".join(parts).encode("utf-8")).hexdigest()
    return task_key(input_sha256=combined, options_sha256=JOINT, solver=JOINT)


def _sensor_ranges(exp):
    T = exp.sensor_temperatures()
    return np.column_stack([T.min(axis=0), T.max(axis=0)])


def _solve(planned, collected, key, *, progress):
    """Problems, warm start, the joint solve and its result file (with ``campaign.key`` and ``seconds``)."""
    t0 = time.perf_counter()
    problems, starts, ranges, names, t_refs = [], [], [], [], []
    opts = None
    for e in planned.campaign.experiments:
        exp = io.read_experiment(e.file)
        opts = calibration_options(planned.campaign, t_ref_degC=e.t_ref_degC)
        fg = collected.results.get(e.name, {}).get(PRIMARY_SOLVER)
        # a file whose own job gave a result passed the record's checks there (the same bytes: the task's key)
        p = build_problem(exp, options=opts, check=fg is None)
        problems.append(p)
        ranges.append(_sensor_ranges(exp))
        names.append(e.name)
        t_refs.append(p.model.t_ref_degC)
        starts.append(WarmStart.from_result(fg) if fg is not None else None)
        del exp
    show = (lambda ev: print(ev.text(), file=sys.stderr)) if progress else None
    out = get_solver(JOINT).solve_campaign(problems, options=opts, progress=show,
                                           initial=starts if any(s is not None for s in starts) else None)
    res = joint_result(out, source=Path(planned.campaign.path).name, experiments=names, t_refs=t_refs,
                       sensor_ranges=ranges)
    res.extra["campaign"] = {"key": key, "seconds": time.perf_counter() - t0,
                             "warm_start": sum(s is not None for s in starts)}
    io.write_result(res, planned.out / JOINT_FILE)
    return res


def cross_check(joint, collected, names):
    """Per subrange and element: (joint at ``T_ref`` - per-subrange estimate) / its sigma, per solver.

    Returns
    -------
    dict
        ``{solver: {"experiments": {name: {element: z}}, "max_abs_z", "rms_z", "fraction_within_0_5"}}``.
    """
    out = {}
    solvers = sorted({s for n in names for s in collected.results.get(n, {})})
    for s in solvers:
        per, zs = {}, []
        for n in names:
            r = collected.results.get(n, {}).get(s)
            if r is None:
                continue
            rows = {}
            for el, v in r.values.items():
                j = joint_element_at(joint, el, r.t_ref_degC, experiment=n)
                sig = r.sigmas[el]
                if j is None or sig <= 0:
                    continue
                rows[el] = (j[0] - v) / sig
            per[n] = rows
            zs.extend(rows.values())
        z = np.abs(np.asarray(zs, dtype=float))
        out[s] = {"experiments": per, "max_abs_z": float(z.max()) if z.size else None,
                  "rms_z": float(np.sqrt(np.mean(z**2))) if z.size else None,
                  "fraction_within_0_5": float(np.mean(z <= 0.5)) if z.size else None}
    return out


def _curve_truth(curves, name, T):
    c = curves[name]
    return evaluate_polynomial_curve(c["coefficients"], T, t0_degC=float(c["t0_degC"]))[0]


def truth_check(joint, truths, summaries):
    """The joint curves against the truth (module docstring), z = (joint - truth) / joint sigma.

    Returns
    -------
    dict
        ``mode`` (``"temperature_curves"`` or ``"per-subrange"``), ``points``, ``fraction_within_2sigma``,
        ``max_abs_z``, ``rms_z``, ``worst`` (element, z, temperature) ; ``{}`` without truth.
    """
    if not truths:
        return {}
    cal = JointCalibration.from_result(joint)
    with_curves = next((t for t in truths.values() if isinstance(t.extra.get("temperature_curves"), dict)), None)
    zs, worst = [], (None, 0.0, None)
    if with_curves is not None:
        mode = "temperature_curves"
        curves = with_curves.extra["temperature_curves"]
        for name, cv in cal.curves.items():
            if name not in curves:
                continue
            T = np.linspace(*cv.t_span, TRUTH_POINTS)
            v, s = cv.evaluate(T)
            z = (v - _curve_truth(curves, name, T)) / s
            zs.append(z)
            i = int(np.argmax(np.abs(z)))
            if abs(z[i]) > abs(worst[1]):
                worst = (name, float(z[i]), float(T[i]))
    else:
        mode = "per-subrange"
        for n, truth in truths.items():
            ref = ResultCalibration(truth)
            rg = np.asarray((summaries.get(n) or {}).get("sensor_temperature_range_degC")
                            or np.tile(truth.temperature_range_degC, (6, 1)), dtype=float).reshape(6, 2)
            for name, cv in cal.curves.items():
                if name not in ref.points:
                    continue
                sidx = sensor_of(name)
                T = np.linspace(*rg[sidx], TRUTH_POINTS)
                v, s = cv.evaluate(T)
                z = (v - ref.points[name].predict(T)[0]) / s
                zs.append(z)
                i = int(np.argmax(np.abs(z)))
                if abs(z[i]) > abs(worst[1]):
                    worst = (f"{name} ({n})", float(z[i]), float(T[i]))
    z = np.abs(np.concatenate(zs)) if zs else np.zeros(0)
    return {"mode": mode, "points": int(z.size),
            "fraction_within_2sigma": float(np.mean(z <= 2.0)) if z.size else None,
            "max_abs_z": float(z.max()) if z.size else None,
            "rms_z": float(np.sqrt(np.mean(z**2))) if z.size else None,
            "worst": {"element": worst[0], "z": worst[1], "T_degC": worst[2]}}


def _validate(joint, planned):
    cal = JointCalibration.from_result(joint)
    out = []
    for rec in planned.records:
        kind, ref_path = planned.references[rec]
        if not Path(ref_path).is_file():
            continue
        # the reference a truth file stands for: its temperature curves over the whole range when it has them
        v = validate(io.read_experiment(rec), cal, truth_reference(io.read_result(ref_path)), record_name=rec.name)
        out.append({"record": str(rec), "reference_kind": kind, "summary": v.summary()})
    return out


def solve_joint(planned, collected, *, progress=False, force=False):
    """The joint solve, or its cached result (module docstring, 1-2).

    Returns
    -------
    joint : graph_calib.records.experiment.Result or None
        None when the campaign has no joint solver or the solve failed.
    status : dict or str or None
        ``"computed"`` or ``"cached"``; for a failed solve ``campaign.json``'s ``joint`` entry saying so; None
        without the joint solver.
    """
    if JOINT not in getattr(planned, "campaign_solvers", ()):
        return None, None
    key = _key(planned)
    path = planned.out / JOINT_FILE
    if path.is_file() and not force:
        try:
            cached = read_joint_result(path)
            if (cached.extra.get("campaign") or {}).get("key") == key:
                return cached, "cached"
        except InputError:              # a damaged or older file is recomputed
            pass
    try:
        return _solve(planned, collected, key, progress=progress), "computed"
    except InputError:
        raise
    except Exception as exc:        # told like a failed task (joint_failures): campaign.json, exit code 1
        error = f"{type(exc).__name__}: {exc}"
        return None, {JOINT: {"file": None, "status": "failed", "error": error, "truth_check": {}}}


def joint_entry(planned, collected, joint, status):
    """``campaign.json``'s ``joint`` of a :func:`solve_joint` (module docstring, 3-5), against ``collected``'s
    per-subrange results (the final ones)."""
    if joint is None:
        return status if isinstance(status, dict) else {}
    names = [e.name for e in planned.campaign.experiments]
    block = joint.extra[JOINT]
    entry = {"file": JOINT_FILE, "status": status, "seconds": (joint.extra.get("campaign") or {}).get("seconds"),
             "t0_degC": block["t0_degC"], "degrees": block["degrees"], "degree_choice": block["degree_choice"],
             "verdict": joint.extra.get("verdict"),
             "cross_check": cross_check(joint, collected, names),
             "truth_check": truth_check(joint, collected.truths, collected.summaries),
             "validation": _validate(joint, planned)}
    return {JOINT: entry}


def run_joint(planned, collected, *, progress=False, force=False):
    """The campaign's joint phase (module docstring): ``(joint Result or None, campaign.json's joint entry)``."""
    joint, status = solve_joint(planned, collected, progress=progress, force=force)
    return joint, joint_entry(planned, collected, joint, status)


def joint_failures(joint_doc):
    """The failed joint solves of ``campaign.json``'s ``joint`` as entries of its ``failed`` list."""
    return [{"name": "(campaign)", "solver": s, "error": e["error"]} for s, e in joint_doc.items()
            if e.get("status") == "failed"]


__all__ = ["JOINT_FILE", "run_joint", "solve_joint", "joint_entry", "joint_failures", "cross_check", "truth_check"]
