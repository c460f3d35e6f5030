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
from graph_calib import effects, io, params
from graph_calib.solvers.results import sigma_ratio_range_text
from graph_calib.reports import html as H

_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf")
_AXIS_COLORS = ("#1f77b4", "#2ca02c", "#d62728")
SOLVER_LABEL = {"factor-graph": "factor graph", "sqrt-kf": "square-root KF"}


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _fmt(v, digits=4):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if v == 0:
        return "0"
    a = abs(v)
    if 1e-3 <= a < 1e5:
        return f"{v:.{digits}g}"
    return f"{v:.{max(1, digits - 1)}e}"


def _unit(parameter):
    sp = effects.EFFECTS[parameter]
    return sp.report_unit, sp.to_report


# ---------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------


def fig_temperatures(run):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 3.6))
    for i, (name, s) in enumerate(run.summaries.items()):
        ser = s.get("series")
        if not ser:
            continue
        t = np.asarray(ser["t_s"]) / 3600.0
        T = np.asarray(ser["sensor_temperature_degC"])
        col = _COLORS[i % len(_COLORS)]
        ax.fill_between(t, T.min(axis=1), T.max(axis=1), color=col, alpha=0.25, lw=0)
        ax.plot(t, T.mean(axis=1), color=col, lw=1.5, label=f"{name} (T_ref {s['t_ref_degC']:.1f})")
    ax.set_xlabel("time in the experiment, h")
    ax.set_ylabel("sensor temperature, degC")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="best")
    ax.set_title("Sensor temperatures of each experiment (line: mean of the six sensors; band: their spread)",
                 fontsize=9)
    return fig


def _truth_curve(truth_cal, element, T):
    if truth_cal is None:
        return None
    v = truth_cal.evaluate(np.tile(np.asarray(T)[:, None], (1, 6))).get(element)
    return v


def fig_parameter(parameter, stitched, *, other=None, truth_cal=None, model="cubic"):
    """The method's figure for one parameter: per-subrange estimates, their lines, the stitched curves, the truth.

    Top row: values; bottom row: the same minus the reference curve (the truth when
    known, else the stitched curve), where the one-sigma bands can be seen.
    """
    plt = _plt()
    unit, k = _unit(parameter)
    curves = stitched.elements(parameter)
    n = len(curves)
    ncol = min(n, 3)
    nrow_blocks = math.ceil(n / ncol)
    fig, axes = plt.subplots(2 * nrow_blocks, ncol, figsize=(4.1 * ncol, 5.4 * nrow_blocks), squeeze=False,
                             gridspec_kw={"height_ratios": [1.5, 1.0] * nrow_blocks})
    other_pts = {}
    if other is not None:
        for cv in other.elements(parameter):
            other_pts[cv.element] = cv.points
    for idx, cv in enumerate(curves):
        r, col = divmod(idx, ncol)
        ax, axd = axes[2 * r, col], axes[2 * r + 1, col]
        lo, hi = cv.t_span
        pad = 0.04 * max(hi - lo, 1.0)
        T = np.linspace(lo - pad, hi + pad, 240)
        truth = _truth_curve(truth_cal, cv.element, T)
        fit = cv.fit(model)
        vs, ss = fit.evaluate(T)
        ref = truth if truth is not None else vs
        ref_of = (lambda tt: _truth_curve(truth_cal, cv.element, tt)) if truth is not None else \
            (lambda tt: fit.evaluate(tt)[0])
        for j, p in enumerate(cv.points):
            color = _COLORS[j % len(_COLORS)]
            if cv.temperature_dependent:
                tt = np.linspace(p.t_range[0], p.t_range[1], 40)
                pv, ps = p.predict(tt)
                for a, base in ((ax, 0.0), (axd, ref_of(tt))):
                    a.plot(tt, (pv - base) * k, ":", color=color, lw=1.4)
                    a.fill_between(tt, (pv - ps - base) * k, (pv + ps - base) * k, color=color, alpha=0.15, lw=0)
            for a, base in ((ax, 0.0), (axd, float(ref_of(np.array([p.t_ref_degC]))[0]))):
                a.errorbar([p.t_ref_degC], [(p.value - base) * k], yerr=[p.sigma * k], fmt="o", ms=4, color=color,
                           capsize=3, lw=1.2, label=p.name if a is ax else None)
            for q in other_pts.get(cv.element, ()):
                if q.name == p.name:
                    for a, base in ((ax, 0.0), (axd, float(ref_of(np.array([q.t_ref_degC + 0.5]))[0]))):
                        a.errorbar([q.t_ref_degC + 0.5], [(q.value - base) * k], yerr=[q.sigma * k], fmt="s",
                                   mfc="none", ms=4, color=color, capsize=2, lw=0.8)
        lin_v, lin_s = cv.fit("linear").evaluate(T)
        label_s = {"cubic": "stitched cubic", "constant": "stitched constant"}.get(fit.kind, f"stitched {fit.kind}")
        for a, base in ((ax, 0.0), (axd, ref)):
            a.plot(T, (vs - base) * k, "-", color="k", lw=1.6, label=label_s if a is ax else None)
            a.fill_between(T, (vs - ss - base) * k, (vs + ss - base) * k, color="k", alpha=0.12, lw=0)
            a.plot(T, (lin_v - base) * k, "--", color="#555", lw=1.0,
                   label="stitched piecewise linear" if a is ax else None)
            if truth is not None:
                a.plot(T, (truth - base) * k, "-", color="#e6007e", lw=1.1, label="truth" if a is ax else None)
        ax.set_title(cv.element, fontsize=9)
        ax.set_ylabel(unit, fontsize=8)
        axd.set_ylabel(f"minus {'truth' if truth is not None else 'stitched'}, {unit}", fontsize=8)
        axd.set_xlabel("sensor temperature, degC", fontsize=8)
        axd.axhline(0.0, color="#e6007e" if truth is not None else "k", lw=0.8)
        for a in (ax, axd):
            a.grid(alpha=0.3)
            a.tick_params(labelsize=7)
        if idx == 0:
            ax.legend(fontsize=6, loc="best")
    for idx in range(n, nrow_blocks * ncol):
        r, col = divmod(idx, ncol)
        axes[2 * r, col].axis("off")
        axes[2 * r + 1, col].axis("off")
    fig.tight_layout()
    return fig


def fig_solver_comparison(run):
    plt = _plt()
    names = [n for n in run.results if "sqrt-kf" in run.results[n] and "factor-graph" in run.results[n]]
    if not names:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.4))
    for i, n in enumerate(names):
        a, b = run.results[n]["sqrt-kf"], run.results[n]["factor-graph"]
        d, ratio = [], []
        for el in a.values:
            if el in b.values:
                big = max(a.sigmas[el], b.sigmas[el])
                d.append((b.values[el] - a.values[el]) / big if big > 0 else 0.0)
                ratio.append(b.sigmas[el] / a.sigmas[el] if a.sigmas[el] > 0 else np.nan)
        jit = (np.random.default_rng(i).uniform(-0.25, 0.25, len(d)))
        axes[0].plot(i + jit, d, ".", ms=4, color=_COLORS[i % len(_COLORS)])
        axes[1].plot(i + jit, ratio, ".", ms=4, color=_COLORS[i % len(_COLORS)])
    for ax, title, lines in ((axes[0], "(graph - filter) / larger sigma", (-0.1, 0.1)),
                             (axes[1], "sigma(graph) / sigma(filter)", (0.9, 1.1))):
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels(names, rotation=20, fontsize=7)
        for y in lines:
            ax.axhline(y, color="r", lw=0.8, ls="--")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle("Filter against graph, every parameter of every subrange (dashed: agreement limits)", fontsize=9)
    fig.tight_layout()
    return fig


def fig_boundaries(stitched):
    plt = _plt()
    checks = stitched.boundary_checks()
    if not checks:
        return None
    keys = []
    for b in checks:
        k = f"{b.lower} | {b.upper}"
        if k not in keys:
            keys.append(k)
    fig, ax = plt.subplots(figsize=(9, 3.4))
    rng = np.random.default_rng(0)
    for b in checks:
        i = keys.index(f"{b.lower} | {b.upper}")
        color = "#1f77b4" if b.element.startswith("gyro") else "#d62728"
        ax.plot(i + rng.uniform(-0.25, 0.25), b.z, ".", color=color, ms=5)
    for y in (-3, 3):
        ax.axhline(y, color="r", ls="--", lw=0.8)
    ax.set_xticks(range(len(keys)))
    ax.set_xticklabels(keys, rotation=15, fontsize=7)
    ax.set_ylabel("difference / combined sigma")
    ax.set_title("Consecutive subranges at their common boundary: every gyro (blue) and accelerometer (red) element",
                 fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def fig_validation(v):
    plt = _plt()
    w = v.windows
    st = w["static"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    thr_g = v.thresholds["gyro_radps"] * c.RS_TO_DH
    thr_a = v.thresholds["accel_mps2"] * c.MPS2_TO_UG
    for i, ax_name in enumerate("xyz"):
        for triad, ax, de, sig, k, sel in (
            ("gyro", axes[0], v.de_gyro, v.sigma_gyro, c.RS_TO_DH, st if np.any(st) else np.ones_like(st)),
            ("accel", axes[1], v.de_accel, v.sigma_accel, c.MPS2_TO_UG, np.ones_like(st)),
        ):
            s = i if triad == "gyro" else 3 + i
            T = w["T"][:, s]
            ins = v.inside[:, s]
            ax.plot(T[sel & ins], de[sel & ins, i] * k, ".", ms=1.5, color=_AXIS_COLORS[i], label=f"{triad} {ax_name}")
            ax.plot(T[sel & ~ins], de[sel & ~ins, i] * k, ".", ms=1.5, color="#bbbbbb",
                    label="outside the calibrated range" if i == 2 else None)
            if sig is not None and np.any(sel):
                Ts, ss = T[sel], sig[sel, i]
                o = np.argsort(Ts)
                ax.plot(Ts[o], ss[o] * k, "-", color=_AXIS_COLORS[i], lw=0.7, alpha=0.6)
                ax.plot(Ts[o], -ss[o] * k, "-", color=_AXIS_COLORS[i], lw=0.7, alpha=0.6)
    for ax, thr, unit, what in ((axes[0], thr_g, "deg/h", "gyro error, static windows"),
                                (axes[1], thr_a, "micro-g", "accelerometer error, all windows")):
        ax.axhline(thr, color="r", ls="--", lw=1)
        ax.axhline(-thr, color="r", ls="--", lw=1)
        ax.set_xlabel("sensor temperature, degC")
        ax.set_ylabel(f"remaining error, {unit}")
        ax.set_title(f"{what} (dashed: published accuracy; thin: stitched 1-sigma)", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, markerscale=5)
    fig.suptitle(f"Validation on {v.record} against {v.reference}", fontsize=9)
    fig.tight_layout()
    return fig


def _load_residuals(path):
    """``{kind: (t (F,) s, values (F, 3))}`` of a residual-series file (:func:`graph_calib.io.read_residuals`).

    Kinds sorted by name, empty kinds left out; ``{}`` when the file is missing.
    """
    if not Path(path).is_file():
        return {}
    _, series = io.read_residuals(path)
    return {kd: series[kd] for kd in sorted(series) if series[kd][1].size}


def fig_residuals(run, solver):
    plt = _plt()
    names = [n for n in run.results if solver in run.results[n]]
    data = {n: _load_residuals(run.out / n / f"{solver}.residuals.h5") for n in names}
    kinds = []
    for d in data.values():
        for k in d:
            if k not in kinds:
                kinds.append(k)
    if not kinds:
        return None
    fig, axes = plt.subplots(len(names), len(kinds), figsize=(3.7 * len(kinds), 1.7 * len(names) + 0.6),
                             squeeze=False, sharey=True)
    for i, n in enumerate(names):
        for j, kd in enumerate(kinds):
            ax = axes[i, j]
            if kd in data[n]:
                t, val = data[n][kd]
                step = max(1, t.size // 1500)
                for a in range(3):
                    ax.plot(t[::step] / 3600.0, val[::step, a], ".", ms=0.8, color=_AXIS_COLORS[a],
                            label="xyz"[a] if (i == 0 and j == 0) else None)
                rms = float(np.sqrt(np.mean(val ** 2)))
                ax.text(0.99, 0.95, f"rms {rms:.2f}", transform=ax.transAxes, ha="right", va="top", fontsize=7)
            ax.set_ylim(-5, 5)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=6)
            if i == 0:
                ax.set_title(kd, fontsize=9)
            if j == 0:
                ax.set_ylabel(n, fontsize=7)
            if i == len(names) - 1:
                ax.set_xlabel("time, h", fontsize=7)
    if axes.size:
        axes[0, 0].legend(fontsize=6, markerscale=6, loc="lower left")
    what = "whitened residuals" if solver == "factor-graph" else "normalised innovations"
    fig.suptitle(f"{SOLVER_LABEL.get(solver, solver)}: {what} per subrange (N(0,1) when the model fits)", fontsize=9)
    fig.tight_layout()
    return fig


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
        unit, k = _unit(cv.parameter)
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
        unit, k = _unit(p)
        cells = [el, unit]
        for n in names:
            r = run.results[n][solver]
            cells.append(H.Raw(f"{r.values[el] * k:.4g} &plusmn; {r.sigmas[el] * k:.2g}") if el in r.values else "-")
        rows.append(cells)
    return H.table(["bench parameter", "unit"] + names, rows, left=(0, 1))


# ---------------------------------------------------------------------------
# the page
# ---------------------------------------------------------------------------


def build_report(run, *, figures_dir=None):
    """The HTML text of a campaign's report.

    Parameters
    ----------
    run : graph_calib.campaign.CampaignRun
    figures_dir : Path, optional
        Also write every figure there as PNG.
    """
    from graph_calib.validation import ResultCalibration, validation_text

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
    truth_cal = ResultCalibration(next(iter(run.truths.values()))) if run.truths else None

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
        verdicts.append(["consecutive subranges agree at their boundaries", H.verdict(bsm["consistent"], "yes", "NO"),
                         f"largest |z| {bsm['max_abs_z']:.2f} over {bsm['checks']} checks (limit "
                         f"{bsm['family_limit']:.2f} for that many); rms z {bsm['rms_z']:.2f}; "
                         f"{bsm['beyond_limit']} beyond {bsm['limit']:g} sigma "
                         f"({0.0027 * bsm['checks']:.1f} expected by chance)"])
    tc = (doc.get("truth_check") or {}).get(primary, {}).get(model)
    if tc:
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
            unit, _ = _unit(p)
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

    nav = H.Raw("<nav><ul>" + "".join(
        f'<li><a href="#{a}">{t}</a></li>' for a, t in (
            ("summary", "Summary"), ("reading", "How to read the figures"), ("parameters", "Stitched parameters"),
            ("bench", "Bench parameters"), ("solvers", "Filter against graph"), ("boundaries", "Boundaries"),
            ("validation", "Validation"), ("residuals", "Residuals"))) + "</ul></nav>")
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


__all__ = ["build_report", "write_report", "fig_parameter", "fig_validation", "fig_boundaries", "fig_residuals",
           "fig_solver_comparison", "fig_temperatures"]
