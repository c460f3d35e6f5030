r"""The checks over the whole campaign: what its verdict needs beyond each experiment's own.

Each experiment's verdict (converged, its solvers agree, residuals consistent) says nothing about the
campaign as a whole.  :func:`campaign_checks` adds, from what the campaign has written (``campaign.json``'s
document, the per-subrange results and the joint result):

- **validation**: every validation record named on the command line is met, by the stitched calibration of
  the primary solver (the campaign's stitch model) and by the joint calibration; a record that could not be
  validated fails too (it was asked for);
- **boundaries**: consecutive subranges of the primary solver's stitching agree where they meet, the largest
  ``|z|`` of every element at every boundary within the 1 % family-wise limit for that many checks
  (docs/campaign.md, "The boundary check"; records of two units, or a subrange gone wrong, fail it);
- **joint against subranges**: per subrange, solver and element, the joint calibration at the subrange's
  ``T_ref`` against that subrange's estimate, ``z = (joint - subrange) / sqrt(sigma_sub^2 + sigma_joint^2)``
  (their two covariances; the joint uses the subrange's data too, so the positive correlation only makes
  the true spread smaller and the check conservative), the largest ``|z|`` against the 1 % family-wise
  limit for that many checks (:func:`graph_calib.stitching.family_z_limit`);
- **curvature carried**: where the campaign adopted curvature of a family (the joint's degree of it above 1;
  a loop's or the pooled test's ``*_tc2`` and up in any experiment), every subrange whose own model lacks
  an order of that curve is biased by it: the joint curve's Taylor expansion at the subrange's ``T_ref``, its
  orders beyond the subrange's own fitted by least squares onto the orders the subrange holds over its
  sensor's temperature range, gives the offsets its estimates absorb.  They are written per experiment as
  ``curvature_bias`` (element: offset in the estimate's sigma), flagged from :data:`CURVATURE_FLAG_SIGMA`, and
  fail the check from :data:`CURVATURE_FAIL_SIGMA`: such a result is known to be that far off;
- **next order**: for every joint curve family, the test of the order past the chosen degree
  (:mod:`graph_calib.solvers.joint.degrees`); a family that needed the highest order the curves hold fails;
- **joint verdict**: the joint solve converged and its residuals are consistent;
- **truth** (simulated campaigns, with a truth file): the joint curves against the truth curves, at least
  :data:`TRUTH_FRACTION_2SIGMA` of the points within 2 sigma and none beyond :data:`TRUTH_MAX_SIGMA`; every
  per-subrange final result against its truth (the loop's ``error_vs_truth.after``), per solver over every
  element of every result: the largest |z| within the Bonferroni limit and the sum of z^2 within its
  chi-square quantile, so that a right model fails with probability :data:`TRUTH_ALPHA` (the issue's own bar,
  99 % within 3 sigma per result, is a Monte Carlo acceptance figure: over 12 results of 39 elements a right
  model would miss it more often than not).

Before any work, :func:`check_inputs` reads every input file still to be read in full, so that a bad file is
refused before the first experiment starts.

A check with nothing to check says ``not checked`` and neither passes nor fails.  :func:`apply_to_verdict`
folds the failures into ``campaign.json``'s ``verdict`` (``passed`` false, ``campaign_checks_failed`` the
words), so that the campaign exits 3 (cli.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import stats

from graph_calib.solvers.joint.solver import JOINT
from graph_calib import io
from graph_calib.evaluation.validation import validation_text
from graph_calib.sensors.curves import taylor_at
from graph_calib.sensors.effects import EFFECTS, temperature_family
from graph_calib.sensors.params import split_element_name
from graph_calib.solvers.joint.result import joint_element_at
from graph_calib.stitching import family_z_limit, sensor_of

#: A subrange estimate that the curvature its model lacks shifts by this many of its sigmas is flagged.
CURVATURE_FLAG_SIGMA = 1.0
#: ... and fails the campaign's check from this many.
CURVATURE_FAIL_SIGMA = 3.0
#: The truth checks of a simulated campaign (issue "Done means").
TRUTH_FRACTION_2SIGMA = 0.90
TRUTH_MAX_SIGMA = 4.0
#: False-alarm probability of the per-subrange truth check of a right model (the loop's alpha).
TRUTH_ALPHA = 0.01
#: Points over a subrange's sensor range where the curvature's offsets are fitted.
CURVATURE_POINTS = 41

FAMILIES = ("gyro.bias", "gyro.scale", "accel.bias", "accel.scale")


def _check(name, passed, text, *, checked=True, details=None):
    return {"check": name, "checked": bool(checked), "passed": None if not checked else bool(passed),
            "text": text if checked else f"not checked: {text}", "details": details or {}}


# ---------------------------------------------------------------------------
# boundaries
# ---------------------------------------------------------------------------


def _boundary_check(document):
    """The primary solver's stitching: consecutive subranges agree at their boundaries (module docstring)."""
    primary = document.get("primary_solver")
    bc = ((document.get("stitching") or {}).get(primary) or {}).get("boundary_check")
    if not bc or not bc.get("checked"):
        return [_check("boundaries", None, "no boundary between two subranges", checked=False)]
    text = (f"{primary}: largest |z| {bc['max_abs_z']:.2f} over {bc['checks']} element(s) at the boundaries between "
            f"subranges (1 % family-wise limit {bc['family_limit']:.2f}); {bc['beyond_limit']} beyond "
            f"{bc['limit']:g} sigma")
    return [_check("boundaries", bc["consistent"], text)]


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------


def _validation_checks(document):
    primary, model = document.get("primary_solver"), document.get("stitch_model", "cubic")
    out = []
    for entry in document.get("validation") or []:
        name = str(entry.get("record", "?")).rsplit("/", 1)[-1]
        summ = ((entry.get("results") or {}).get(primary) or {}).get(model)
        if summ is None:
            out.append(_check(f"validation {name} (stitched)", False,
                              f"validation on {name} was asked for and could not be done: "
                              f"{entry.get('error', 'no result')}"))
            continue
        ok = summ["pass"]["all"]
        out.append(_check(f"validation {name} (stitched)", ok,
                          f"validation on {name} of the stitched {model} calibration ({primary}): "
                          f"{validation_text(summ)} -> {'met' if ok else 'NOT met'}{_own_reference(entry, ok)}"))
    joint = (document.get(JOINT) or {}).get(JOINT) or {}
    for val in joint.get("validation") or []:
        name = str(val.get("record", "?")).rsplit("/", 1)[-1]
        summ = val["summary"]
        ok = summ["pass"]["all"]
        out.append(_check(f"validation {name} (joint)", ok,
                          f"validation on {name} of the joint calibration: {validation_text(summ)} -> "
                          f"{'met' if ok else 'NOT met'}"))
    return out


def _own_reference(entry, ok):
    """What a validation against the record's own calibration (no truth file beside it) cannot tell, when it fails."""
    if ok or entry.get("reference_kind") != "estimate":
        return ""
    return (" (the reference is the record's own factor-graph calibration, no truth: its own errors count in these "
            "figures, and a record shorter than the campaign's subranges calibrates itself no better than they do)")


# ---------------------------------------------------------------------------
# the joint model against the subranges
# ---------------------------------------------------------------------------


def joint_against_subranges(joint, results):
    """Per solver, experiment and element ``z = (joint at T_ref - estimate) / sqrt(s_sub^2 + s_joint^2)``.

    Returns
    -------
    dict
        ``{solver: {experiment: {element: z}}}``.
    """
    out = {}
    for name, per in results.items():
        for solver, r in per.items():
            rows = {}
            for el, v in r.values.items():
                sig = (r.sigmas or {}).get(el)
                j = joint_element_at(joint, el, r.t_ref_degC, experiment=name)
                if j is None or sig is None or sig <= 0:
                    continue
                rows[el] = float((j[0] - v) / np.hypot(sig, j[1]))
            out.setdefault(solver, {})[name] = rows
    return out


def _joint_check(joint, results):
    if joint is None:
        return _check("joint against subranges", None, "no joint result", checked=False), {}
    zmap = joint_against_subranges(joint, results)
    items = [(abs(z), s, n, el, z) for s, per in zmap.items() for n, rows in per.items() for el, z in rows.items()]
    if not items:
        return _check("joint against subranges", None, "no per-subrange result to compare", checked=False), zmap
    limit = family_z_limit(len(items))
    worst = max(items)
    beyond = sorted((it for it in items if it[0] > limit), reverse=True)
    ok = not beyond
    text = (f"the joint model at each subrange's T_ref and the per-subrange results agree within their two "
            f"covariances: largest |z| {worst[0]:.2f} ({worst[3]} of {worst[2]}, {worst[1]}) over {len(items)} "
            f"checks, limit {limit:.2f}" if ok else
            "the joint model and the per-subrange results DISAGREE beyond their two covariances: "
            + "; ".join(f"{el} of {n} ({s}) {z:+.2f} sigma" for _, s, n, el, z in beyond[:6])
            + (f" and {len(beyond) - 6} more" if len(beyond) > 6 else "") + f" (limit {limit:.2f} for {len(items)} checks)")
    return _check("joint against subranges", ok, text, details={"limit": limit, "checks": len(items),
                                                                  "max_abs_z": worst[0]}), zmap


# ---------------------------------------------------------------------------
# curvature the subranges lack
# ---------------------------------------------------------------------------


def orders_held(result, base):
    """Highest temperature order of ``base`` a result holds (its effects), 0 without the parameter."""
    orders = temperature_family(base)[1]
    held = [k for k, n in orders.items() if n in result.effects or any(v.startswith(n + ".") for v in result.values)]
    return max(held, default=0)


def curvature_offsets(coefficients, t0_degC, t_ref_degC, t_range_degC, held):
    """What a subrange model holding orders ``0..held`` absorbs of a curve's higher orders around ``T_ref``.

    The curve's Taylor coefficients at ``T_ref`` (:func:`graph_calib.sensors.curves.taylor_at`); its orders above
    ``held`` over the sensor's range (evenly spread temperatures) fitted by least squares on ``dT^0..dT^held``.

    Returns
    -------
    ndarray, shape (held + 1,)
        Offsets of the subrange's ``p, p_tc, ...`` (SI): its estimates are expected this far from the curve's.
    """
    a, _ = taylor_at(coefficients, t_ref_degC, t0_degC=t0_degC)
    if a.size <= held + 1:
        return np.zeros(held + 1)
    dT = np.linspace(t_range_degC[0], t_range_degC[1], CURVATURE_POINTS) - t_ref_degC
    rest = sum(a[k] * dT**k for k in range(held + 1, a.size))
    V = dT[:, None] ** np.arange(held + 1)[None, :]
    return np.linalg.lstsq(V, rest, rcond=None)[0]


def curvature_bias(joint, results, sensor_ranges):
    """Per experiment and solver, the offsets (in the estimate's sigma) the joint curves' orders its model lacks
    cause: ``{experiment: {solver: {element: z}}}`` (only elements with a lacking order)."""
    if joint is None:
        return {}
    block = joint.extra[JOINT]
    t0 = float(block["t0_degC"])
    out = {}
    for name, per in results.items():
        rg = sensor_ranges.get(name)
        for solver, r in per.items():
            rows = {}
            for flat, cv in block["curves"].items():
                base, el = split_element_name(flat)
                held = orders_held(r, base)
                if len(cv["coefficients"]) - 1 <= held or flat not in r.values:
                    continue
                s = sensor_of(flat)
                t_range = (np.asarray(rg, dtype=float).reshape(6, 2)[s] if rg is not None
                           else np.asarray(r.temperature_range_degC, dtype=float))
                off = curvature_offsets(cv["coefficients"], t0, r.t_ref_degC, t_range, held)
                orders = temperature_family(base)[1]
                for k in range(held + 1):
                    n = flat if k == 0 else f"{orders[k]}.{el}"
                    sig = (r.sigmas or {}).get(n)
                    if sig and sig > 0:
                        rows[n] = float(off[k] / sig)
            if rows:
                out.setdefault(name, {})[solver] = rows
    return out


def _curvature_adopted(document, joint):
    """``{family: [(effect, where)]}``: where the campaign adopted curvature of each family (``effect`` None for
    the joint's degree, ``where`` then its words; else the experiment's name)."""
    out = {}
    if joint is not None:
        for f, d in joint.extra[JOINT]["degrees"].items():
            if d >= 2:
                out.setdefault(f, []).append((None, f"the joint's degree {d}"))
    for e in document.get("experiments", []):
        loop = e.get("loop") or {}
        for a in list(loop.get("added") or []) + list(loop.get("pooled") or []):
            eff = EFFECTS.get(a.get("effect"))
            if eff is not None and eff.temperature_of and eff.temperature_order >= 2:
                out.setdefault(eff.temperature_of, []).append((a["effect"], e["name"]))
    return out


def _adopted_json(adopted):
    """``campaign.json``'s ``details.adopted`` of :func:`_curvature_adopted`: ``{family: ["EFFECT in NAME", ...]}``."""
    return {f: [w if e is None else f"{e} in {w}" for e, w in where] for f, where in adopted.items()}


def _adopted_text(adopted, n_experiments):
    """``adopted`` in words, each effect once with where it was adopted (a count past three experiments)."""
    parts = []
    for family, where in adopted.items():
        joint = [w for e, w in where if e is None]
        per = {}
        for e, name in where:
            if e is not None:
                per.setdefault(e, {})[name] = None
        items = joint + [f"{e} in " + (", ".join(names) if len(names) <= 3 else
                                       "every experiment" if len(names) == n_experiments else
                                       f"{len(names)} experiments") for e, names in per.items()]
        parts.append(f"{family}: {', '.join(items)}")
    return "; ".join(parts)


def _curvature_check(document, joint, results):
    adopted = _curvature_adopted(document, joint)
    ranges = {e["name"]: e.get("sensor_temperature_range_degC") for e in document.get("experiments", [])}
    bias = curvature_bias(joint, results, ranges)
    if not adopted:
        return _check("curvature carried", None, "no curvature adopted anywhere", checked=False), bias
    if joint is None:
        return _check("curvature carried", None, "curvature adopted ("
                      + _adopted_text(adopted, len(document.get("experiments", [])))
                      + ") but no joint curve to bound what the subranges without it lack", checked=False), bias
    if "solvers" in document and not document["solvers"]:
        return _check("curvature carried", None, "no per-subrange result to carry it into (the joint solver alone)",
                      checked=False), bias
    flagged = sorted(((abs(z), n, s, el, z) for n, per in bias.items() for s, rows in per.items()
                      for el, z in rows.items() if abs(z) >= CURVATURE_FLAG_SIGMA), reverse=True)
    failing = [f for f in flagged if f[0] >= CURVATURE_FAIL_SIGMA]
    where = _adopted_text(adopted, len(document.get("experiments", [])))
    if not flagged:
        text = (f"curvature adopted ({where}); every subrange holds it or lacks less than "
                f"{CURVATURE_FLAG_SIGMA:g} sigma of it")
    else:
        text = (f"curvature adopted ({where}); subranges whose model lacks it are biased by it: "
                + "; ".join(f"{el} of {n} ({s}) {z:+.1f} sigma" for _, n, s, el, z in flagged[:6])
                + (f" and {len(flagged) - 6} more" if len(flagged) > 6 else "")
                + (f" ({len(failing)} beyond {CURVATURE_FAIL_SIGMA:g} sigma: those results are known to be off)"
                   if failing else f" (flagged; none beyond {CURVATURE_FAIL_SIGMA:g} sigma)"))
    return _check("curvature carried", not failing, text,
                  details={"adopted": _adopted_json(adopted), "flagged": len(flagged)}), bias


# ---------------------------------------------------------------------------
# the joint's own evidence and verdict, the truth
# ---------------------------------------------------------------------------


def _next_order_checks(joint):
    if joint is None:
        return []
    out = []
    for c in joint.extra[JOINT].get("degree_choice") or []:
        nxt = c.get("next_order")
        if nxt is None:             # an older joint result (degrees by BIC): no next-order test recorded
            out.append(_check(f"next order {c['family']}", None, f"{c['family']}: no test of the next order recorded",
                              checked=False))
            continue
        out.append(_check(f"next order {c['family']}", nxt["passed"], nxt["text"]))
    return out


def _joint_verdict_check(document, joint):
    entry = (document.get(JOINT) or {}).get(JOINT) or {}
    if entry.get("status") == "failed":
        return [_check("joint verdict", False, f"the joint solve failed: {entry.get('error')}")]
    if joint is None:
        return []
    v = joint.extra.get("verdict") or {}
    if not v:
        return []
    return [_check("joint verdict", v.get("passed", True), f"joint solver: {v.get('text', '')}")]


def _truth_checks(document):
    out = []
    tc = (((document.get(JOINT) or {}).get(JOINT) or {}).get("truth_check")) or {}
    if tc.get("points"):
        ok = tc["fraction_within_2sigma"] >= TRUTH_FRACTION_2SIGMA and tc["max_abs_z"] <= TRUTH_MAX_SIGMA
        w = tc.get("worst") or {}
        out.append(_check("joint against truth", ok,
                          f"joint curves against the truth ({tc['mode']}): {100 * tc['fraction_within_2sigma']:.0f} % "
                          f"of {tc['points']} points within 2 sigma (at least {100 * TRUTH_FRACTION_2SIGMA:.0f} %), "
                          f"largest {tc['max_abs_z']:.2f} sigma ({w.get('element')}; at most {TRUTH_MAX_SIGMA:g})"))
    # per solver, every final per-subrange result's elements together: a right model fails this with
    # probability TRUTH_ALPHA (the largest |z| against the Bonferroni limit over all elements, the sum of z^2
    # against its chi-square quantile), not with the near certainty of "none beyond 3 sigma" over hundreds
    per_solver = {}
    for e in document.get("experiments", []):
        for solver, err in ((e.get("loop") or {}).get("error_vs_truth") or {}).items():
            a = (err or {}).get("after")
            if a and a.get("n"):
                per_solver.setdefault(solver, []).append((e["name"], a))
    for solver, rows in per_solver.items():
        n = sum(int(a["n"]) for _, a in rows)
        z_limit = float(stats.norm.isf(TRUTH_ALPHA / (4.0 * n)))          # two-sided, the two tests Bonferroni
        ss = sum(int(a["n"]) * float(a["rms_z"]) ** 2 for _, a in rows)
        ss_limit = float(stats.chi2.isf(TRUTH_ALPHA / 2.0, n))
        beyond = [(name, a) for name, a in rows if a["max_abs_z"] > z_limit]
        ok = not beyond and ss <= ss_limit
        worst_name, worst = max(rows, key=lambda r: r[1]["max_abs_z"])
        text = (f"every final per-subrange result against its truth ({solver}, {len(rows)} results, {n} elements): "
                f"RMS normalised error {np.sqrt(ss / n):.2f} (limit {np.sqrt(ss_limit / n):.2f}), largest "
                f"{worst['max_abs_z']:.2f} sigma ({worst_name} {worst.get('worst')}; limit {z_limit:.2f})")
        if beyond:
            text += "; beyond it: " + "; ".join(f"{name} {a.get('worst')} {a['max_abs_z']:.1f} sigma" for name, a in beyond[:4])
        out.append(_check(f"subranges against truth ({solver})", ok, text))
    return out


# ---------------------------------------------------------------------------
# together
# ---------------------------------------------------------------------------


def campaign_checks(document, *, results, joint=None):
    """Every check over the whole campaign (module docstring): ``campaign.json``'s ``campaign_checks``.

    Parameters
    ----------
    document : dict
        ``campaign.json``'s content so far (experiments, validation, joint).
    results : dict
        ``{experiment: {solver: Result}}``, the final per-subrange results.
    joint : graph_calib.records.experiment.Result, optional
        The joint result.

    Returns
    -------
    dict
        ``checks`` (each ``check``, ``checked``, ``passed``, ``text``, ``details``), ``passed``, ``failed`` (the
        texts of the failed ones), ``joint_against_subranges`` (z per solver, experiment, element) and
        ``curvature_bias`` (per experiment and solver, element: offset in sigma).
    """
    checks = _validation_checks(document) + _boundary_check(document)
    jc, zmap = _joint_check(joint, results)
    cc, bias = _curvature_check(document, joint, results)
    checks += [jc, cc] + _next_order_checks(joint) + _joint_verdict_check(document, joint) + _truth_checks(document)
    failed = [c["text"] for c in checks if c["checked"] and not c["passed"]]
    return {"checks": checks, "passed": not failed, "failed": failed, "joint_against_subranges": zmap,
            "curvature_bias": bias}


def apply_to_verdict(document, checks):
    """``campaign.json``'s ``verdict`` with the campaign checks folded in (``campaign_checks_failed``); in place."""
    v = document.setdefault("verdict", {"passed": True, "failed": []})
    v["campaign_checks_failed"] = list(checks["failed"])
    v["passed"] = bool(v.get("passed", True) and checks["passed"])
    for e in document.get("experiments", []):
        per = checks["curvature_bias"].get(e["name"])
        if per:
            e["curvature_bias"] = {s: {el: z for el, z in rows.items() if abs(z) >= CURVATURE_FLAG_SIGMA}
                                   for s, rows in per.items()}
    return v


def check_inputs(planned):
    """Every input still to be read, checked against every rule of data-format.md before any work starts.

    Each experiment file a task still has to compute and each validation record is read in full
    (:func:`graph_calib.io.read_experiment`, one at a time, then dropped): a file that breaks a rule (a
    missing ``/imu/dv``, time not increasing, an unmarked cut) stops the campaign here, with one error naming
    the file and the dataset, instead of after the experiments before it were calibrated.  Cached tasks'
    files were read when they were computed (their content is in the cache key).

    Raises
    ------
    InputError
    """
    files = dict.fromkeys([Path(t.file) for t in planned.to_compute] + [Path(r) for r in planned.records])
    for f in files:
        io.read_experiment(f)


def judge_campaign(document, *, results, joint=None):
    """:func:`campaign_checks` written into ``document`` (``campaign_checks``) and folded into its verdict."""
    checks = campaign_checks(document, results=results, joint=joint)
    document["campaign_checks"] = checks
    apply_to_verdict(document, checks)
    return checks


def check_lines(checks):
    """The checks in words, one line each (the command's summary)."""
    out = []
    for c in checks["checks"]:
        if not c["checked"]:
            out.append(f"{c['check']}: {c['text']}")      # the text says "not checked: ..."
            continue
        out.append(f"{c['check']}: {'pass' if c['passed'] else 'FAIL'}: {c['text']}")
    return out


__all__ = ["CURVATURE_FLAG_SIGMA", "CURVATURE_FAIL_SIGMA", "check_inputs", "campaign_checks", "apply_to_verdict", "judge_campaign",
           "check_lines",
           "joint_against_subranges", "curvature_bias", "curvature_offsets"]
