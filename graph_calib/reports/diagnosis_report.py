"""The report of ``graph-calib diagnose``: figures and one HTML page from a :class:`~graph_calib.diagnosis.Diagnosis`.

Reads what the loop concluded (the stages before and after, the rounds and
their tests); never runs a solver.  Figures use matplotlib's ``Agg`` backend.

- :func:`signature_figure`: binned whitened residuals against an effect's
  driver, before and after the effect is added;
- :func:`time_figure`: the residuals in time, before and after;
- :func:`statistics_figure`: the score statistics of a round against their thresholds;
- :func:`error_figure`: error of the declared parameters against a truth, before and after;
- :func:`write_report`: ``report.html``.
"""

from __future__ import annotations

import numpy as np

from graph_calib.sensors import effects
from graph_calib.sensors.effects import REGISTRY
from graph_calib.reports import html

#: For each further effect: the driver its signature follows, and the triad whose residuals show it.
EFFECT_VIEW = {e.name: e.report_view for e in REGISTRY if e.report_view is not None}

#: Axis labels of the drivers (SI, temperatures in degC).
DRIVER_LABEL = {
    "time": "time since start [s]",
    "temperature": "dT [degC]",
    "temperature_rate": "dT/dt [degC/s]",
    "rate": "angular rate [rad/s]",
    "rate_size": "|angular rate| [rad/s]",
    "rate_sign": "sign of the angular rate",
    "angular_acceleration": "angular acceleration [rad/s^2]",
    "specific_force": "specific force [m/s^2]",
    "specific_force_sq": "specific force squared [m^2/s^4]",
}

_BEFORE = dict(color="#c0392b", label="before")
_AFTER = dict(color="#1f5fa8", label="after")


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def residual_view(stage, triad):
    """``(name, whitened (F, 3), keyframe (F,), component labels)`` of the series where ``triad`` errors show.

    Gyro errors show in the encoder residuals when the experiment has valid table
    readings, else in the rotation residuals (body axes: in static poses gravity
    holds the attitude, so the gyro's error is left in them); accelerometer errors
    in the gravity residuals in body axes (static keyframes).
    """
    res = stage.residuals
    if triad == "gyro" and "encoder" in res and res["encoder"]["w"].shape[0] > 0:
        d = res["encoder"]
        return "encoder", d["w"], d["key"], ("x", "y", "z")
    if triad == "gyro":
        d = res["rotation"]
        return "rotation", d["w"], d["key"], ("x", "y", "z")
    d = res["gravity"]
    m = d["static"]
    return "gravity (body axes, static keyframes)", d["w_body"][m], d["key"][m], ("x", "y", "z")


def _driver_values(ctx, driver, key, comp, triad):
    v = ctx[driver][key]
    if v.ndim == 1:
        return v
    if v.shape[1] == 6:       # per sensor: the triad's three sensors
        cols = slice(0, 3) if triad == "gyro" else slice(3, 6)
        return v[:, cols][:, comp] if comp is not None else v[:, cols].mean(axis=1)
    return v[:, comp] if comp is not None else v.mean(axis=1)


def binned(x, y, bins=20):
    """Means of ``y`` in equal-width bins of ``x``: ``(x centres, means, standard errors)``.

    Bins with fewer than two values are left out.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 4 or np.ptp(x) == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    edges = np.linspace(x.min(), x.max(), bins + 1)
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, bins - 1)
    xc, ym, ys = [], [], []
    for b in np.unique(idx):
        m = idx == b
        if np.count_nonzero(m) < 2:
            continue
        xc.append(x[m].mean())
        ym.append(y[m].mean())
        ys.append(y[m].std(ddof=1) / np.sqrt(np.count_nonzero(m)))
    return np.array(xc), np.array(ym), np.array(ys)


def signature_figure(before, after, driver, triad, *, title="", component_driver=True):
    """Whitened residuals binned against ``driver``, before and after (one panel per component).

    Parameters
    ----------
    before, after : graph_calib.diagnosis.Stage
        The same object draws one series ("final model").
    driver : str
        A key of :func:`graph_calib.diagnosis.keyframe_context`.
    triad : {"gyro", "accel"}
    component_driver : bool
        Plot component ``i`` of the residual against component ``i`` of a
        three-component driver (else against its mean).
    """
    from graph_calib.diagnosis import keyframe_context

    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.2), sharey=True)
    stages = ((after, dict(color=_AFTER["color"], label="final model")),) if before is after else \
        ((before, _BEFORE), (after, _AFTER))
    for stage, style in stages:
        ctx = keyframe_context(stage.problem.model)
        name, w, key, comps = residual_view(stage, triad)
        level = False
        for i, ax in enumerate(axes):
            comp = i if (component_driver and not level) else None
            x = _driver_values(ctx, driver, key, comp, triad)
            xc, ym, ys = binned(x, w[:, i])
            if xc.size:
                ax.errorbar(xc, ym, yerr=ys, fmt="o-", ms=3, lw=1, capsize=2, **style)
            ax.set_title(f"{name}: {comps[i]}", fontsize=9)
            ax.axhline(0.0, color="0.6", lw=0.8)
            xl = DRIVER_LABEL.get(driver, driver)
            if comp is not None and ctx[driver].ndim > 1:
                xl = xl.replace("[", f"{'xyz'[i]} [", 1)
            ax.set_xlabel(xl, fontsize=8)
    axes[0].set_ylabel("mean whitened residual (bins)", fontsize=8)
    axes[0].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def time_figure(before, after, *, bin_s=30.0):
    """Whitened residuals of every factor kind in time (means over ``bin_s``), before and after."""
    plt = _plt()
    kinds = [k for k in ("gravity", "encoder", "rotation") if before.residuals.get(k, {}).get("w") is not None
             and before.residuals[k]["w"].shape[0] > 0]
    fig, axes = plt.subplots(len(kinds), 3, figsize=(11, 2.4 * len(kinds)), sharex=True, squeeze=False)
    for r, kind in enumerate(kinds):
        for stage, style in ((before, _BEFORE), (after, _AFTER)):
            d = stage.residuals[kind]
            w = d["w_body"] if kind == "gravity" else d["w"]
            t = d["t"] - stage.problem.model.t_key[0]
            sel = d["static"] if kind == "gravity" else np.ones(t.size, bool)
            edges = np.arange(0.0, t.max() + bin_s, bin_s)
            idx = np.digitize(t[sel], edges)
            for c in range(3):
                ys = np.array([w[sel][idx == b, c].mean() if np.any(idx == b) else np.nan
                               for b in range(1, edges.size)])
                axes[r, c].plot(0.5 * (edges[:-1] + edges[1:]), ys, lw=1, **style)
        for c in range(3):
            lab = "body " + "xyz"[c]
            axes[r, c].set_title(f"{kind} ({'static, ' if kind == 'gravity' else ''}{lab})", fontsize=9)
            axes[r, c].axhline(0.0, color="0.6", lw=0.8)
        axes[r, 0].set_ylabel(f"whitened, {bin_s:g} s means", fontsize=8)
    for c in range(3):
        axes[-1, c].set_xlabel("time since start [s]", fontsize=8)
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    return fig


def statistics_figure(rnd):
    """Score statistic over threshold of every tested candidate of a round (log scale)."""
    plt = _plt()
    tested = sorted((c for c in rnd.candidates if not c.skipped), key=lambda c: c.log10_p)
    fig, ax = plt.subplots(figsize=(8, 0.35 * max(len(tested), 3) + 1))
    names = [c.name for c in tested][::-1]
    ratio = [max(c.statistic, 1e-3) / c.threshold for c in tested][::-1]
    colors = ["#c0392b" if r > 1 else "#7f8c8d" for r in ratio]
    ax.barh(names, ratio, color=colors)
    ax.axvline(1.0, color="k", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("score statistic / threshold (threshold: chi-square quantile, Bonferroni)", fontsize=8)
    ax.set_title(f"round {rnd.index}: candidates", fontsize=10)
    ax.tick_params(labelsize=8)
    fig.tight_layout()
    return fig


def error_figure(before, after, solver=None):
    """RMS of ``(estimate - truth) / sigma`` per declared parameter, before and after (``solver``: the
    stages' primary solver by default)."""
    plt = _plt()
    solver = before.primary if solver is None else solver
    eb = before.error[solver]["groups"]
    ea = after.error[solver]["groups"]
    names = [n for n in eb if n in ea]
    fig, ax = plt.subplots(figsize=(9, 3.2))
    x = np.arange(len(names))
    ax.bar(x - 0.2, [eb[n]["rms_z"] for n in names], 0.4, color=_BEFORE["color"], label="before")
    ax.bar(x + 0.2, [ea[n]["rms_z"] for n in names], 0.4, color=_AFTER["color"], label="after")
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=45, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_ylabel("RMS (estimate - truth) / sigma", fontsize=8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


#: The IEEE terms of an Allan variance: name, power of tau, coefficient (graph_calib.noise.identify.TERMS).
_ALLAN_TERMS = (("quantization", -2, 3.0), ("white", -1, 1.0), ("bias_instability", 0, 2.0 * np.log(2.0) / np.pi),
                ("rate_random_walk", 1, 1.0 / 3.0), ("rate_ramp", 2, 0.5))


def allan_figure(noise):
    """Allan deviation of each gyro and accelerometer channel over the rests, with the fitted IEEE terms.

    ``noise`` is a result's ``noise`` block; its ``identified`` figures hold the curve and the terms
    (None when nothing was identified).
    """
    ident = (noise or {}).get("identified") or {}
    sensors = [s for s in ("gyro", "accel") if "allan" in ident.get(s, {})]
    if not sensors:
        return None
    plt = _plt()
    f, axes = plt.subplots(1, len(sensors), figsize=(5.2 * len(sensors), 3.8), squeeze=False)
    unit = {"gyro": "rad/s", "accel": "m/s^2"}
    for ax, s in zip(axes[0], sensors):
        d = ident[s]
        tau = np.asarray(d["allan"]["tau_s"])
        adev = np.asarray(d["allan"]["adev"])
        tt = np.geomspace(tau.min(), tau.max(), 100)
        estimators = d.get("estimator") or ["allan"] * 3
        for c, (name, color) in enumerate(zip("xyz", ("#c0392b", "#27ae60", "#1f5fa8"))):
            # a channel whose Q and N came from the rests' spectra (graph_calib.noise.spectral) says so
            spectral = " (Q, N from the spectra)" if estimators[c] == "whittle" else ""
            ax.loglog(tau, adev[:, c], "o", ms=3, color=color, label=f"{name}{spectral}")
            var = sum(k * d[t]["channels"][c] ** 2 * tt**p for t, p, k in _ALLAN_TERMS)
            ax.loglog(tt, np.sqrt(var), "-", lw=1, color=color)
        for t, p, k in _ALLAN_TERMS:
            v = d[t]["value"]
            if v > 0 and d[t]["supported"]:
                ax.loglog(tt, np.sqrt(k * v**2 * tt**p), "--", lw=0.8, color="0.4")
                ax.annotate(t.replace("_", " "), (tt[len(tt) // 2], np.sqrt(k * v**2 * tt[len(tt) // 2] ** p)),
                            fontsize=7, color="0.3")
        ax.set_xlabel("tau [s]")
        ax.set_ylabel(f"Allan deviation [{unit[s]}]")
        ax.set_title(f"{s}: density {d['density']:.3g} (keyframe {d['keyframe_s']:g} s), rests {d['rest_s']:.0f} s",
                     fontsize=8)
        ax.legend(fontsize=7)
        ax.grid(True, which="both", alpha=0.3)
    f.tight_layout()
    return f


def _noise_section(diag, fig):
    """The noise the solve used and, where identified, its Allan plot."""
    res = next(iter(diag.before.results.values()), None) if getattr(diag.before, "results", None) else None
    noise = (res.extra or {}).get("noise") if res is not None else None
    if not noise:
        return None
    src = noise.get("source", {})
    rows = [["gyro", f"{noise['gyro_rad_per_sqrt_s']:.4g} rad/sqrt(s)", src.get("gyro", "")],
            ["accelerometer", f"{noise['accel_mps_per_sqrt_s']:.4g} m/s/sqrt(s)", src.get("accel", "")],
            ["table readings", f"{noise['encoder_rad']:.4g} rad", src.get("encoder", "")]]
    items = [html.table(["sensor", "white-noise density used", "source"], rows, left=(0, 2))]
    f = allan_figure(noise)
    if f is not None:
        items.append(fig(f, "Overlapping Allan deviation of each channel over every rest (points), the fitted "
                            "IEEE 952/1293 terms per channel (lines) and each term the data support (dashed); a "
                            "channel marked 'Q, N from the spectra' has its quantization and white noise from the "
                            "Whittle likelihood of the rests' spectra, where the quantization makes most of its "
                            "per-sample scatter (docs/model.md, \"Noise from the record\").",
                         "allan"))
    return html.section("Noise identified from the record", *items, anchor="noise")


def _fmt(v, digits=3):
    if v is None:
        return ""
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if not np.isfinite(v):
        return "-"
    if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
        return f"{v:.{digits}g}"
    return f"{v:.{digits}g}" if abs(v) < 1 else f"{v:.{max(digits - 2, 1)}f}"


def _candidate_table(rnd):
    rows, classes = [], []
    for c in sorted(rnd.candidates, key=lambda c: (c.skipped is not None, c.log10_p)):
        if c.skipped:
            rows.append([c.name, "", "", "", "", "skipped: " + c.skipped])
            classes.append("")
            continue
        s = effects.effect(c.name)
        z = [abs(e) / sg for e, sg in zip(c.estimate, c.sigma) if np.isfinite(sg) and sg > 0]
        est = ", ".join(f"{e * s.to_report:.3g}" for e in c.estimate)
        rows.append([c.name, _fmt(c.statistic), c.dof, _fmt(c.threshold), _fmt(c.log10_p),
                     html.Raw(f"{'<b>significant</b>' if c.significant else 'no'}; one-step estimate "
                              f"[{html.esc(est)}] {html.esc(s.report_unit)}"
                              + (f" (largest {max(z):.1f} sigma)" if z else ""))])
        classes.append("bad" if c.significant else "")
    return html.table(["candidate", "statistic", "dof", "threshold", "log10 p", "verdict"], rows,
                      row_classes=classes, left=(0, 5))


def _driver_table(drivers, limit=12):
    rows = []
    for d in sorted(drivers, key=lambda d: d.log10_p)[:limit]:
        unit, k = d.report
        z = [abs(e) / s if np.isfinite(s) and s > 0 else 0.0 for e, s in zip(d.estimate, d.sigma)]
        best = int(np.argmax(z))
        feat = (f"{d.labels[best]}: {d.estimate[best]:.3g} +- {d.sigma[best]:.2g}" if d.group != "time"
                else f"{d.dof} B-spline directions")
        rows.append([d.group, d.axis, _fmt(d.statistic), d.dof, _fmt(d.threshold), _fmt(d.log10_p),
                     f"{d.amplitude * k:.3g} {unit}", feat, "yes" if d.significant else "no"])
    return html.table(["driver", "as a bias on", "statistic", "dof", "threshold", "log10 p",
                       "RMS of the fitted bias", "strongest feature (SI per unit)", "significant"], rows,
                      left=(0, 1, 7))


def profile_figure(stage, drivers, *, limit=4):
    """The fitted bias of the strongest driver signatures over the record (keyframe values)."""
    plt = _plt()
    t = stage.problem.model.t_key[:-1] - stage.problem.model.t_key[0]
    fig, ax = plt.subplots(figsize=(9, 3.0))
    for d in sorted(drivers, key=lambda d: d.log10_p)[:limit]:
        unit, k = d.report
        ax.plot(t, np.asarray(d.profile, dtype=float) * k, ".-", ms=2, lw=0.8,
                label=f"{d.group} on {d.axis} [{unit}]")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlabel("time since start [s]", fontsize=8)
    ax.set_ylabel("fitted bias (mean removed)", fontsize=8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


#: A residual series whose Ljung-Box p-value is below this is not called free of structure.
WHITENESS_ALPHA = 1e-3


def _whiteness_failures(stage):
    """``["solver kind", ...]`` of the stage's residual series whose Ljung-Box test rejects whiteness."""
    out = []
    for solver, series in (getattr(stage, "statistics", None) or {}).items():
        for kind, s in series.items():
            if min(s["ljung_box"]["p"], default=1.0) < WHITENESS_ALPHA:
                out.append(f"{solver} {kind}")
    return out


def _residual_table(diag):
    rows = []
    for label, st in (("before", diag.before), ("after", diag.after)):
        for solver, series in st.statistics.items():
            for kind, s in series.items():
                lb = s["ljung_box"]
                top = s["drivers"][0] if s["drivers"] else None
                rows.append([label, solver, f"{kind} ({s['components']})", s["count"],
                             " / ".join(f"{v:.3f}" for v in s["rms"]),
                             " / ".join(f"{p:.2g}" for p in lb["p"]),
                             "" if top is None else f"{top['driver']} (component {top['component']}): "
                                                    f"R^2 {top['r2']:.3f}, log10 p {top['log10_p']:.1f}"])
    return html.table(["model", "solver", "series", "count", "RMS whitened (per component)",
                       "Ljung-Box p (10 lags)", "strongest driver relation"],
                      rows, left=(0, 1, 2, 6))


def _error_table(diag):
    rows = []
    for solver in diag.before.error:
        b = diag.before.error[solver]
        a = diag.after.error.get(solver, b)
        rows.append([solver, _fmt(b["rms_z"]), _fmt(a["rms_z"]), _fmt(a.get("rms_z_fixed")),
                     f"{_fmt(b['max_abs_z'])} ({b['worst']})", f"{_fmt(a['max_abs_z'])} ({a['worst']})"])
    t1 = html.table(["solver", "RMS z before", "RMS z after", "RMS z after (before's sigmas)",
                     "max |z| before", "max |z| after"], rows, left=(0, 4, 5))
    solver = diag.before.primary
    gb, ga = diag.before.error[solver]["groups"], diag.after.error[solver]["groups"]
    rows = [[n, _fmt(gb[n]["rms_z"]), _fmt(ga[n]["rms_z"]), _fmt(gb[n]["rms_abs"]), _fmt(ga[n]["rms_abs"]),
             gb[n]["report_unit"]] for n in gb if n in ga]
    t2 = html.table(["parameter", "RMS z before", "RMS z after", "RMS error before", "RMS error after", "unit"],
                    rows, left=(0, 5))
    return t1, t2


def signature_view_of_driver(d):
    """``(driver key of keyframe_context, triad, component-wise)`` to draw a driver-test signature."""
    triad = d.axis.split(".")[0]
    key = {"rate_sign": "rate", "rate_size": "rate_size", "time": "time", "temperature": "temperature",
           "angular_acceleration": "angular_acceleration", "specific_force_sq": "specific_force_sq"}[d.group]
    return key, triad


def write_report(diag, path, *, figures_dir=None):
    """Write ``report.html`` for a :class:`~graph_calib.diagnosis.Diagnosis`.

    Parameters
    ----------
    diag : Diagnosis
    path : str or Path
    figures_dir : str or Path, optional
        Also save every figure there as PNG.
    """
    from pathlib import Path

    from graph_calib.io import atomic_write_text

    fd = None if figures_dir is None else Path(figures_dir)
    if fd is not None:
        fd.mkdir(parents=True, exist_ok=True)
    n_fig = [0]

    def fig(f, caption, stem):
        n_fig[0] += 1
        return html.figure(f, caption=caption, save_to=None if fd is None else fd / f"{stem}.png")

    ctx = diag.context
    parts = []
    verdict = (f"added {', '.join(diag.added)}" if diag.added else "nothing added")
    white = _whiteness_failures(diag.after)
    if diag.unexplained:
        verdict += "; residual structure remains that no candidate explains"
    elif white:
        verdict += (f"; no candidate or driver test finds structure, but the residuals are not white ("
                    f"Ljung-Box p below {WHITENESS_ALPHA:g}: {', '.join(white)})")
    else:
        verdict += "; no residual structure left"
    parts.append(html.section(
        "Summary",
        html.table(["", ""], [
            ["experiment", diag.source],
            ["samples, duration", f"{ctx['n_samples']}, {ctx['duration_s']:.0f} s at {ctx['rate_hz']:g} Hz"],
            ["turntable", "yes" if ctx["table"] else "no (gravity only)"],
            ["grade (priors, noise)", ctx["grade"]],
            ["keyframes", f"{ctx['keyframes']} of {ctx['keyframe_s']:g} s"],
            ["T_ref, range", f"{ctx['t_ref_degC']:.2f} degC, {ctx['temperature_range_degC'][0]:.2f} .. "
                             f"{ctx['temperature_range_degC'][1]:.2f} degC"],
            ["added (in order)", ", ".join(diag.added) or "none"],
            ["unexplained", html.verdict(not diag.unexplained, "false", "true")],
            ["run time", f"{diag.seconds:.1f} s"],
        ], left=(0, 1)),
        html.paragraph(verdict + "."),
        html.paragraph(
            f"Each candidate is tested with the score (Lagrange-multiplier) statistic of the factor graph at the "
            f"current solution: chi-square with as many degrees of freedom as the candidate has identifiable "
            f"directions when the effect is absent. Threshold: the chi-square quantile at "
            f"alpha = {diag.options.alpha:g} divided by the number of candidates tested in the round (Bonferroni), "
            f"so that a correct model gains an effect with probability at most {diag.options.alpha:g}. The same "
            f"test of generic drivers (time, temperature, its rate, rate sign and size, angular acceleration, "
            f"specific force and its square, each as a bias on each sensor axis; Bonferroni over those tests) "
            f"finds structure that no candidate explains. See docs/diagnosis.md.", cls="note"),
        anchor="summary"))
    for rnd in diag.rounds:
        items = [html.paragraph(f"Model: {', '.join(n for n in rnd.layout if not effects.EFFECTS[n].declared) or 'declared'}"
                                f"; chi^2/dof of the fit {rnd.chi2_per_dof:.3f}, variance factor "
                                f"{rnd.variance_factor:.3f}. Decision: {rnd.decision}."),
                 _candidate_table(rnd),
                 fig(statistics_figure(rnd), f"Round {rnd.index}: statistic over threshold per candidate "
                                             f"(red: significant).", f"round{rnd.index}_statistics")]
        for ch in rnd.checks:
            items.append(html.paragraph(f"Check of {ch['candidate']} against the generic drivers: {ch['verdict']}.",
                                        cls="note"))
        sig = [d for d in rnd.drivers if d.significant]
        items.append(html.paragraph(f"Driver tests: {len(sig)} of {len(rnd.drivers)} significant."))
        if sig:
            items.append(_driver_table(sig))
        parts.append(html.section(f"Round {rnd.index}", *items, anchor=f"round{rnd.index}"))
    # the added effects: residual signature before and after
    if diag.added:
        items = []
        for e in diag.added:
            driver, triad = EFFECT_VIEW[e]
            items.append(fig(signature_figure(diag.before, diag.after, driver, triad,
                                              title=f"{e}: residuals against {driver}"),
                             f"{e}: whitened residuals (binned means +- standard error) against "
                             f"{DRIVER_LABEL.get(driver, driver)}, with the declared model (red) and after the "
                             f"loop (blue).", f"signature_{e.replace('.', '_')}"))
        items.append(fig(time_figure(diag.before, diag.after), "Whitened residuals in time (30 s means), before "
                                                               "(red) and after (blue).", "residuals_time"))
        parts.append(html.section("Residual signatures before and after", *items, anchor="signatures"))
    if diag.unexplained:
        items = [html.paragraph("Structure remains that no candidate of the catalogue explains. Signature "
                                "(driver tests significant at the final model):"), _driver_table(diag.signature)]
        items.append(fig(profile_figure(diag.after, diag.signature),
                         "The bias each of the strongest signatures fits, keyframe by keyframe (its mean, "
                         "the bias itself, removed).", "unexplained_profiles"))
        d = diag.signature[0]
        key, triad = signature_view_of_driver(d)
        items.append(fig(signature_figure(diag.after, diag.after, key, triad,
                                          title=f"unexplained: {d.group} as a bias on {d.axis}"),
                         f"Residuals of the final model against {DRIVER_LABEL.get(key, key)}.", "unexplained"))
        parts.append(html.section("Unexplained residual structure", *items, anchor="unexplained"))
    noise = _noise_section(diag, fig)
    if noise is not None:
        parts.append(noise)
    parts.append(html.section("Residual statistics before and after", _residual_table(diag),
                              html.paragraph("Ljung-Box over 10 lags per component; driver relations are F-tests "
                                             "of keyframe means (descriptive: successive residuals are not "
                                             "independent).", cls="note"), anchor="statistics"))
    if diag.before.error is not None and diag.after.error is not None:
        t1, t2 = _error_table(diag)
        parts.append(html.section(
            "Error against the truth (declared parameters)", t1, t2,
            fig(error_figure(diag.before, diag.after), "RMS of (estimate - truth) / sigma per declared parameter, "
                                                       "before and after (factor graph).", "error_vs_truth"),
            anchor="truth"))
    page = html.page(f"graph-calib diagnose: {diag.source}", *parts)
    atomic_write_text(path, page)
    return path


__all__ = ["EFFECT_VIEW", "DRIVER_LABEL", "allan_figure", "residual_view", "binned", "signature_figure", "time_figure",
           "statistics_figure", "error_figure", "profile_figure", "write_report"]
