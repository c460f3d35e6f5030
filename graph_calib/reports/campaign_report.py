"""``report.html`` of a campaign: summary, stitched parameters, solvers compared, boundaries, validation, residuals.

Built from a :class:`graph_calib.campaign.CampaignRun` (results, stitched
curves, validations in memory; residual series read from the experiment
folders).  Every figure is embedded as PNG, so the file stands alone.  Values
are shown in the report unit of each parameter (``effects.EFFECTS[name].report_unit``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from graph_calib import constants as c
from graph_calib.sensors import effects, params
from graph_calib import io
from graph_calib.reports.joint_report import joint_sections
from graph_calib.reports import html as H
from graph_calib.reports.campaign_figures import (
    SOLVER_LABEL,
    fig_boundaries,
    fig_parameter,
    fig_residuals,
    fig_solver_comparison,
    fig_temperatures,
    fig_validation,
    report_unit,
)
from graph_calib.solvers.results import sigma_ratio_range_text
from graph_calib.solvers.verdict import PRIOR_HELD_WORDS
from graph_calib.solvers.joint.solver import JOINT
from graph_calib.evaluation.validation import TruthCurves, validation_text


def _fmt(v, digits=4):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if v == 0:
        return "0"
    a = abs(v)
    if 1e-3 <= a < 1e5:
        return f"{v:.{digits}g}"
    return f"{v:.{max(1, digits - 1)}e}"


# ---------------------------------------------------------------------------
# tables
# ---------------------------------------------------------------------------


def _summary_table(run):
    doc = run.document
    rows = []
    for e in doc["experiments"]:
        s = run.summaries.get(e["name"], {})
        cells = [e["name"], Path(e["file"]).name, _fmt(s.get("t_ref_degC"), 4)]
        tr = s.get("temperature_range_degC")
        cells.append(f"{tr[0]:.1f} .. {tr[1]:.1f}" if tr else "-")
        cells.append(f"{s['duration_s'] / 3600.0:.2f}" if "duration_s" in s else "-")
        cells.append(str(s.get("n_samples", "-")))
        for sv in doc["solvers"]:
            info = e["results"].get(sv, {})
            st = info.get("status", "-")
            sec = info.get("seconds")
            cells.append(f"{st}" + (f", {sec:.0f} s" if isinstance(sec, (int, float)) else ""))
        rows.append(cells)
    heads = ["experiment", "file", "T_ref, degC", "sensor temperatures, degC", "hours", "samples"] + \
        [f"{SOLVER_LABEL.get(s, s)}" for s in doc["solvers"]]
    return H.table(heads, rows, left=(0, 1))


def _comparison_table(run):
    rows, classes = [], []
    for e in run.document["experiments"]:
        cmp_ = e.get("comparison")
        if not cmp_:
            continue
        rows.append([e["name"], str(cmp_["parameters"]), f"{cmp_['max_abs_difference_in_sigma']:.2g}",
                     sigma_ratio_range_text(cmp_),
                     H.verdict(cmp_["agree"], "agree", "DIFFER")])
        classes.append("" if cmp_["agree"] else "bad")
    if not rows:
        return None
    return H.table(["experiment", "parameters", "max |difference| / sigma", "sigma ratio graph/filter", "verdict"],
                   rows, row_classes=classes)


def _boundary_table(stitched):
    sm = stitched.boundary_summary()
    rows, classes = [], []
    for b in sm["boundaries"]:
        rows.append([b["lower"], b["upper"], str(b["checks"]), f"{b['max_abs_z']:.2f}", b["worst"] or "-",
                     ", ".join(b["beyond_limit"]) or "none"])
        classes.append("bad" if b["beyond_limit"] else "")
    return H.table(["lower subrange", "upper subrange", "elements", "max |z|", "worst element",
                    f"beyond {sm['limit']:g} sigma"], rows, row_classes=classes, left=(0, 1, 4, 5)), sm


def _validation_table(summary):
    rows = []
    g, a = summary["gyro_radps"], summary["accel_mps2"]
    thr_g = summary["thresholds"]["gyro_radps"] * c.RS_TO_DH
    thr_a = summary["thresholds"]["accel_mps2"]
    for label, block, k, unit, thr in (
        ("gyro, static windows", g.get("static"), c.RS_TO_DH, "deg/h", thr_g),
        ("gyro, all windows", g.get("all"), c.RS_TO_DH, "deg/h", None),
        ("gyro, moving windows", g.get("moving"), c.RS_TO_DH, "deg/h", None),
        ("accel, all windows", a.get("all"), 1.0, "m/s^2", thr_a),
        ("accel, static windows", a.get("static"), 1.0, "m/s^2", None),
        ("gyro, outside the calibrated range", g.get("outside_calibrated_range"), c.RS_TO_DH, "deg/h", None),
        ("accel, outside the calibrated range", a.get("outside_calibrated_range"), 1.0, "m/s^2", None),
    ):
        if not block:
            continue
        cells = [label, str(block["windows"])]
        cells += [_fmt(v * k, 3) for v in block["rms"]] + [_fmt(v * k, 3) for v in block["max"]]
        cells.append(f"{thr:.3g} {unit}" if thr is not None else "")
        cells.append(unit)
        rows.append(cells)
    mv = g.get("moving") or {}
    if "rms_relative_ppm" in mv:
        rows.append(["gyro, moving: rms error / rms rate", "", *[f"{v:.3g}" for v in mv["rms_relative_ppm"]],
                     "", "", "", "", "ppm"])
    return H.table(["errors", "windows", "rms x", "rms y", "rms z", "max x", "max y", "max z", "accuracy", "unit"],
                   rows, left=(0,))


def _calibration_table(stitched, model, temps):
    rows = []
    for name, cv in stitched.curves.items():
        unit, k = report_unit(cv.parameter)
        v, s = cv.evaluate(np.asarray(temps, dtype=float), model)
        rows.append([name, unit] + [f"{a * k:.4g} &plusmn; {b * k:.2g}" for a, b in zip(v, s)])
    rows = [[r[0], r[1]] + [H.Raw(x) for x in r[2:]] for r in rows]
    return H.table(["element", "unit"] + [f"{t:g} degC" for t in temps], rows, left=(0, 1))


def _bench_table(run, solver):
    names = [n for n in run.results if solver in run.results[n]]
    bench = [p for p in ("mount", "lever_arm", "time_lag.table") if any(
        any(k.startswith(p) for k in run.results[n][solver].values) for n in names)]
    els = [e for p in bench for e in effects.EFFECTS[p].element_names()]
    if not els:
        return None
    rows = []
    for el in els:
        p = params.split_element_name(el)[0]
        unit, k = report_unit(p)
        cells = [el, unit]
        for n in names:
            r = run.results[n][solver]
            cells.append(H.Raw(f"{r.values[el] * k:.4g} &plusmn; {r.sigmas[el] * k:.2g}") if el in r.values else "-")
        rows.append(cells)
    return H.table(["bench parameter", "unit"] + names, rows, left=(0, 1))


# ---------------------------------------------------------------------------
# the page
# ---------------------------------------------------------------------------


def _loop_table(doc):
    """Rows per subrange of the closed loop: effects added, residual RMS and error vs truth before -> after."""
    rows, truth = [], False
    for e in doc["experiments"]:
        lp = e.get("loop")
        if not lp:
            continue
        added = "; ".join(f"{a['effect']} (score {a['statistic']:.1f} > {a['threshold']:.1f}, log10 p "
                          f"{a['log10_p']:.1f})" for a in lp["added"]) or "nothing"
        pooled = "; ".join((f"{a['effect']} (wave {a['wave']}: carried, the curvature "
                            f"{', '.join(a.get('adopted_in') or [])} adopted"
                            + (", the joint curve's Taylor coefficient as its prior)" if a.get("kind") == "joint"
                               else ")")) if a.get("kind") in ("carried", "joint") else
                           f"{a['effect']} (wave {a['wave']}: pooled {a['kind']} score {a['statistic']:.1f} > "
                           f"{a['threshold']:.1f}, "
                           f"{a['dof']} dof, log10 p {a['log10_p']:.1f}, over {len(a['experiments'])} experiments)"
                           for a in lp.get("pooled") or []) or "-"
        rr = lp["residual_rms"]
        res = ", ".join(f"{SOLVER_LABEL.get(s, s)} {rr['before'][s]['overall']:.3f} -> {rr['after'][s]['overall']:.3f}"
                        for s in rr["after"] if s in rr["before"])
        errs = []
        for s, ev in (lp.get("error_vs_truth") or {}).items():
            b, a = ev.get("before"), ev.get("after")
            if b and a:
                truth = True
                errs.append(f"{SOLVER_LABEL.get(s, s)}: RMS {b['rms_z']:.2f} -> {a['rms_z']:.2f}, max "
                            f"{b['max_abs_z']:.1f} -> {a['max_abs_z']:.1f}, within 3 sigma "
                            f"{100 * b['fraction_within_3sigma']:.0f} -> {100 * a['fraction_within_3sigma']:.0f} %")
        rows.append([e["name"], added, pooled, res, "; ".join(errs) or "-"])
    return rows, truth


def _loop_section(doc):
    """The closed loop's section (None when the loop did not run)."""
    if not (doc.get("loop") or {}).get("enabled"):
        return None
    rows, truth = _loop_table(doc)
    text = ("Before stitching, every experiment went through the closed loop of graph-calib diagnose: calibrated "
            "with the declared model, every further effect of model.md score-tested against its residuals, the most "
            "significant one added and the model solved again, until none is significant (Bonferroni at alpha = "
            f"{doc['loop']['options']['alpha']:g}). The stitched curves come from the models the loop chose. "
            "Then the campaign's pooled score tests, over the experiments that did not adopt a candidate: 'sum', "
            "their final-round score statistics summed (chi-square with the summed degrees of freedom), and "
            "'common', the score test of one value of the effect shared by them; at the same level, Bonferroni "
            "over every pooled test; the candidate of the most significant one past its threshold is adopted in "
            "those experiments, which are solved again (an effect each subrange sees weakly, seen by the "
            "campaign). "
            "Residual RMS: overall RMS of the whitened residuals (graph) or normalised innovations (filter), about 1 "
            "for a model that explains the data.")
    waves = ((doc["loop"].get("pooled") or {}).get("waves")) or []
    if waves:
        text += " Pooled decisions: " + "; ".join(f"{w['wave']}: {w['decision']}" for w in waves) + "."
    if truth:
        text += (" Error against the truth: the declared parameters' estimates minus the truth at the subrange's "
                 "reference temperature, in their own sigmas (RMS, largest, share within 3 sigma).")
    return H.section("The closed loop", H.paragraph(text),
                     H.table(["experiment", "effects added (score, log10 p)", "adopted by the pooled test",
                              "residual RMS before -> after", "error against the truth before -> after"], rows,
                             left=(0, 1, 2, 3, 4)), anchor="loop")


def _truth_curves(truths):
    """The truth over the whole range to draw (a truth file's ``temperature_curves``), or None.

    A truth file without them holds only inside its own subrange (data-format.md); it is not drawn as a curve.
    """
    for t in (truths or {}).values():
        if (t.extra or {}).get("temperature_curves"):
            return TruthCurves(t)
    return None


def build_report(run, *, figures_dir=None):
    """The HTML text of a campaign's report.

    Parameters
    ----------
    run : graph_calib.campaign.CampaignRun
    figures_dir : Path, optional
        Also write every figure there as PNG.
    """
    doc = run.document
    model = doc.get("stitch_model", "cubic")
    primary = doc.get("primary_solver")
    other_solver = next((s for s in run.stitched if s != primary), None)
    fig_no = [0]

    def fig(f, caption):
        if f is None:
            return H.Raw("")
        fig_no[0] += 1
        save = None
        if figures_dir is not None:
            Path(figures_dir).mkdir(parents=True, exist_ok=True)
            save = Path(figures_dir) / f"figure{fig_no[0]:02d}.png"
        return H.figure(f, caption=f"Figure {fig_no[0]}. {caption}", save_to=save)

    parts = []
    n_exp = len(doc["experiments"])
    truth_cal = _truth_curves(run.truths)

    # --- summary
    verdicts = []
    cmps = [e["comparison"] for e in doc["experiments"] if e.get("comparison")]
    if cmps:
        agree = all(x["agree"] for x in cmps)
        verdicts.append(["filter and graph agree in every subrange", H.verdict(agree, "yes", "NO"),
                         f"largest difference {max(x['max_abs_difference_in_sigma'] for x in cmps):.2g} sigma"])
    st_primary = run.stitched.get(primary) if primary else None
    if st_primary is not None:
        bsm = st_primary.boundary_summary()
        if not bsm["checked"]:
            verdicts.append(["consecutive subranges agree at their boundaries", H.Raw("not checked"),
                             f"no boundary between subranges to check ({len(st_primary.subranges)} subrange(s))"])
    if st_primary is not None and bsm["checked"]:
        verdicts.append(["consecutive subranges agree at their boundaries", H.verdict(bsm["consistent"], "yes", "NO"),
                         f"largest |z| {bsm['max_abs_z']:.2f} over {bsm['checks']} checks (limit "
                         f"{bsm['family_limit']:.2f} for that many); rms z {bsm['rms_z']:.2f}; "
                         f"{bsm['beyond_limit']} beyond {bsm['limit']:g} sigma "
                         f"({0.0027 * bsm['checks']:.1f} expected by chance)"])
    tc = (doc.get("truth_check") or {}).get(primary, {}).get(model)
    if tc and not tc.get("points"):
        verdicts.append([f"stitched {model} curves match the truth within their bands", H.Raw("not checked"),
                         "no point of a curve where a truth holds"])
    elif tc:
        verdicts.append([f"stitched {model} curves match the truth within their bands",
                         H.verdict(tc["consistent"], "yes", "NO"),
                         f"within 1 sigma: {100 * tc['fraction_within_1sigma']:.0f} % of the points (68 % expected), "
                         f"within 2 sigma: {100 * tc['fraction_within_2sigma']:.0f} % (95 %); largest |error|/sigma "
                         f"{tc['max_abs_z']:.2f} (limit {tc['family_limit']:.2f})"])
    for ventry in doc.get("validation", []):
        vs = (ventry.get("results") or {}).get(primary, {}).get(model)
        if vs:
            verdicts.append([f"validation on {Path(ventry['record']).name}",
                             H.verdict(vs["pass"]["all"], "pass", "FAIL"),
                             validation_text(vs) + " (limits 0.01 deg/h, 2e-4 m/s^2)"])
        elif ventry.get("error"):
            verdicts.append([f"validation on {Path(ventry['record']).name}", H.verdict(False, "", "not done"),
                             ventry["error"]])
    for c in (doc.get("campaign_checks") or {}).get("checks", []):
        verdicts.append([f"campaign check: {c['check']}",
                         H.Raw("not checked") if not c["checked"] else H.verdict(c["passed"], "pass", "FAIL"), c["text"]])
    held = [f"{e['name']}: {n}" for e in doc["experiments"] for n in (e.get("verdict") or {}).get("notes", ())
            if PRIOR_HELD_WORDS in n]
    if held:
        verdicts.append(["elements held by their priors", H.Raw("note"), "; ".join(held)])
    if run.failed:
        verdicts.append(["tasks that failed", H.verdict(False, "", str(len(run.failed))),
                         "; ".join(f"{f['name']} {f['solver']}: {f['error']}" for f in run.failed)])
    tim = doc.get("timing", {})
    intro = (f"IMU <b>{H.esc(doc['imu_id'])}</b> ({H.esc(doc['grade'])} grade): {n_exp} experiment(s), each calibrated "
             f"by {', '.join(SOLVER_LABEL.get(s, s) for s in doc['solvers'])}. The per-subrange estimates are stitched "
             f"into a model of every parameter over the whole temperature range ({H.esc(model)} model shown; "
             f"the stitched curves come from the {SOLVER_LABEL.get(primary, primary)}). Manifest: "
             f"<code>{H.esc(doc['manifest'])}</code>. This run: {tim.get('tasks_computed', 0)} task(s) computed, "
             f"{tim.get('tasks_cached', 0)} taken from the cache, {tim.get('tasks_seconds', 0.0):.0f} s of calibration.")
    parts.append(H.section("Summary", H.Raw(f"<p>{intro}</p>"),
                           H.table(["check", "result", "detail"], verdicts, left=(0, 2)), _summary_table(run),
                           fig(fig_temperatures(run), "The temperature of the sensors during each experiment: the "
                               "temperature keeps changing, and each experiment covers one subrange."),
                           anchor="summary"))

    # --- how to read
    parts.append(H.section(
        "How to read the parameter figures",
        H.Raw("<p>One panel per element, at the temperature of the sensor it belongs to. <b>Dots with bars</b>: each "
              "subrange's estimate at its reference temperature, one sigma (" + H.esc(SOLVER_LABEL.get(primary, "")) +
              "; hollow squares, shifted by 0.5 degC: the " + H.esc(SOLVER_LABEL.get(other_solver, "other solver")) +
              "). <b>Dotted lines with bands</b>: each subrange's own linear model p + p_tc (T - T_ref) over the "
              "temperatures it saw, one sigma. <b>Black line and grey band</b>: the stitched model (cubic fit to every "
              "subrange's value and slope with their covariances), one sigma; <b>dashed</b>: the continuous piecewise "
              "linear stitch. <b>Magenta</b>: the truth, when the data are simulated. The lower row shows everything "
              "minus the truth (or minus the stitched curve without a truth), where the bands can be seen.</p>"),
        anchor="reading"))

    # --- parameters
    if st_primary is not None:
        other = run.stitched.get(other_solver) if other_solver else None
        blocks = []
        for p in st_primary.parameters():
            unit, _ = report_unit(p)
            tdep = any(cv.temperature_dependent for cv in st_primary.elements(p))
            blocks.append(H.section(f"{p} ({unit})", fig(
                fig_parameter(p, st_primary, other=other, truth_cal=truth_cal, model=model),
                f"{p}: estimates per subrange, "
                + ("each subrange's linear variation, " if tdep else "")
                + "the stitched model" + (" and the truth." if truth_cal is not None else ".")), level=3))
        temps = np.round(np.linspace(*_span(st_primary), 7), 1)
        parts.append(H.section("Stitched parameters over temperature", *blocks,
                               H.section("The stitched calibration, table", H.paragraph(
                                   f"The {model} model of every element at a few temperatures, value and one sigma, "
                                   "in report units. Elements without a temperature coefficient use the weighted "
                                   "mean of the subranges."), _calibration_table(st_primary, model, temps), level=3),
                               anchor="parameters"))
        bt = _bench_table(run, primary)
        if bt is not None:
            parts.append(H.section("Bench parameters per experiment", H.paragraph(
                "Mounting, lever arm and table time lag belong to each set-up, not to the IMU; they are not "
                "stitched."), bt, anchor="bench"))

    # --- the closed loop
    lp = _loop_section(doc)
    if lp is not None:
        parts.append(lp)

    # --- solvers
    ct = _comparison_table(run)
    if ct is not None:
        parts.append(H.section(
            "Filter against graph, subrange by subrange",
            H.paragraph("Both solvers consume the same model; they agree when every difference is below 0.1 of the "
                        "larger sigma and the sigma ratio stays within 0.9..1.1 (comparison.json of each experiment "
                        "holds every parameter)."),
            ct, fig(fig_solver_comparison(run), "Every parameter of every subrange: difference between the solvers "
                    "in sigmas (left) and ratio of their sigmas (right)."), anchor="solvers"))

    # --- boundaries
    if st_primary is not None and st_primary.boundary_checks():
        tbl, sm = _boundary_table(st_primary)
        parts.append(H.section(
            "Consecutive subranges at their common boundaries",
            H.paragraph("At the boundary between two consecutive subranges (the middle between the top of the lower "
                        "one's sensor temperatures and the bottom of the upper one's) each subrange predicts every "
                        "element with its own linear model; z is the difference divided by the combined sigma. For "
                        "consistent subranges z is about N(0,1); |z| > 3 is flagged. With many checks a few beyond 3 "
                        f"are expected by chance: the verdict uses {sm['family_limit']:.2f}, the value the largest of "
                        f"{sm['checks']} N(0,1) draws exceeds with 1 % probability. Here: largest |z| "
                        f"{sm['max_abs_z']:.2f}, rms {sm['rms_z']:.2f}."),
            tbl, fig(fig_boundaries(st_primary), "z of every element at every boundary."), anchor="boundaries"))

    # --- validation
    vparts = []
    for ventry, v in zip([e for e in doc.get("validation", []) if e.get("results")], run.validations):
        vs = ventry["results"][primary][model]
        alt = {m: r for m, r in ventry["results"][primary].items() if m != model}
        alt_txt = "; ".join(f"{m} model: {validation_text(r)}" for m, r in alt.items())
        vparts += [H.section(f"Record {Path(ventry['record']).name}", H.paragraph(
            f"Reference: {v.reference}. Record temperatures {vs['temperature_range_degC'][0]:.1f} .. "
            f"{vs['temperature_range_degC'][1]:.1f} degC; calibrated range "
            + (f"{vs['calibrated_range_degC'][0]:.1f} .. {vs['calibrated_range_degC'][1]:.1f} degC."
               if vs.get("calibrated_range_degC") else "unknown.")),
            H.Raw(f"<p>Verdict ({H.esc(model)} model): gyros {H.verdict(vs['pass']['gyro'])}, accelerometers "
                  f"{H.verdict(vs['pass']['accel'])}. Other model: {H.esc(alt_txt)}."
                  + (f" Largest error over its combined one-sigma (stitched and reference): gyros "
                     f"{vs['largest_z']['gyro']:.2f}, accelerometers {vs['largest_z']['accel']:.2f}."
                     if vs.get("largest_z") and None not in vs["largest_z"].values() else "") + "</p>"),
            _validation_table(vs), fig(fig_validation(v), "Remaining sensor error over the record against the "
                                       "sensor temperature."), level=3)]
    if vparts:
        parts.append(H.section(
            "Validation on an independent record",
            H.paragraph("The stitched calibration is applied to a record that took no part in the calibration. In "
                        "each 1 s window the declared sensor error b(T) + (diag(s(T)) + M) u, u the mean rate or "
                        "specific force, is computed with the reference calibration and with the stitched one; "
                        "their difference is the error that remains after calibration. Gyros are judged at rest "
                        "(static windows: the condition of the published 0.01 deg/h), accelerometers over the whole "
                        "record (limit 2e-4 m/s^2 = 20.4 micro-g). Under rotation the remaining gyro error is "
                        "dominated by the scale factor and is given relative to the rate, in ppm."),
            *vparts, anchor="validation"))
    elif not doc.get("validation"):
        parts.append(H.section("Validation on an independent record", H.paragraph(
            "No independent record was given (graph-calib campaign --validate RECORD.h5).")))

    # --- residuals
    rparts = []
    for s in doc["solvers"]:
        f = fig_residuals(run, s)
        if f is not None:
            rparts.append(fig(f, f"{SOLVER_LABEL.get(s, s)}: residuals of every measurement kind over time, per "
                              "subrange, colour by axis; rms in each panel."))
    if rparts:
        parts.append(H.section("Residuals", H.paragraph(
            "Whitened residuals (factor graph) and normalised innovations (filter) should look like white noise of "
            "unit variance. Structure over time or temperature points to an effect the model lacks "
            "(graph-calib diagnose looks for it)."), *rparts, anchor="residuals"))

    parts.extend(joint_sections(run, fig))

    nav = H.Raw("<nav><ul>" + "".join(
        f'<li><a href="#{a}">{t}</a></li>' for a, t in (
            ("summary", "Summary"), ("reading", "How to read the figures"), ("parameters", "Stitched parameters"),
            ("bench", "Bench parameters"), ("loop", "The closed loop"), ("solvers", "Filter against graph"), ("boundaries", "Boundaries"),
            ("validation", "Validation"), ("residuals", "Residuals"), (JOINT, "Joint solver"))) + "</ul></nav>")
    return H.page(f"Thermal calibration campaign: {doc['imu_id']}", nav, *parts,
                  H.paragraph("Written by graph-calib campaign. Units: SI in the files; here deg/h, ppm, arcsec, "
                              "micro-g (1 micro-g = 9.80665e-6 m/s^2), mm, ms.", cls="note"))


def _span(stitched):
    spans = [cv.t_span for cv in stitched.curves.values() if cv.temperature_dependent]
    if not spans:
        spans = [cv.t_span for cv in stitched.curves.values()]
    return min(s[0] for s in spans), max(s[1] for s in spans)


def write_report(run, path, *, figures_dir=None):
    """Write ``report.html`` atomically; returns its path."""
    text = build_report(run, figures_dir=figures_dir)
    io.atomic_write_text(path, text)
    return Path(path)


__all__ = ["build_report", "write_report"]
