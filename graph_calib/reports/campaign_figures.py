"""The figures of a campaign's ``report.html``: temperatures, parameters over temperature, solvers, boundaries,
validation, residuals.

Each ``fig_*`` function returns a matplotlib figure (None when there is nothing
to draw); :mod:`graph_calib.reports.campaign_report` places them on the page.
Values are shown in the report unit of each parameter (:func:`report_unit`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from graph_calib import constants as c
from graph_calib.sensors import effects
from graph_calib import io
from graph_calib.solvers.registry import SOLVER_LABELS, comparison_order

_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf")
_AXIS_COLORS = ("#1f77b4", "#2ca02c", "#d62728")
SOLVER_LABEL = SOLVER_LABELS


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def report_unit(parameter):
    """``(report unit, factor from SI)`` of a parameter (``effects.EFFECTS[name].report_unit``)."""
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
    if ax.get_legend_handles_labels()[1]:          # no experiment's summary: no series (the joint solver alone)
        ax.legend(fontsize=7, ncol=2, loc="best")
    ax.set_title("Sensor temperatures of each experiment (line: mean of the six sensors; band: their spread)",
                 fontsize=9)
    return fig


#: How far right of its own reference temperature the other solver's point is drawn, degC (drawing only).
PLOT_OFFSET_DEGC = 0.5


def point_minus_reference(point, reference):
    """A subrange point's value minus the reference curve at the point's own reference temperature, SI.

    ``reference(T) -> values`` (the truth curve or the stitched one); the offset a figure draws a point at
    never enters the difference.
    """
    return float(point.value - np.asarray(reference(np.array([point.t_ref_degC])), dtype=float).reshape(-1)[0])


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
    unit, k = report_unit(parameter)
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
            for a, base in ((ax, 0.0), (axd, p.value - point_minus_reference(p, ref_of))):
                a.errorbar([p.t_ref_degC], [(p.value - base) * k], yerr=[p.sigma * k], fmt="o", ms=4, color=color,
                           capsize=3, lw=1.2, label=p.name if a is ax else None)
            for q in other_pts.get(cv.element, ()):
                if q.name == p.name:
                    # drawn PLOT_OFFSET_DEGC to the right so that both markers show; the reference is
                    # subtracted at the point's own temperature
                    for a, base in ((ax, 0.0), (axd, q.value - point_minus_reference(q, ref_of))):
                        a.errorbar([q.t_ref_degC + PLOT_OFFSET_DEGC], [(q.value - base) * k], yerr=[q.sigma * k], fmt="s",
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
    pair = comparison_order(run.document.get("solvers", ()))[:2]
    names = [n for n in run.results if len(pair) == 2 and all(s in run.results[n] for s in pair)]
    if not names:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.4))
    for i, n in enumerate(names):
        a, b = run.results[n][pair[0]], run.results[n][pair[1]]
        d, ratio = [], []
        for el in a.values:
            if el in b.values:
                big = max(a.sigmas[el], b.sigmas[el])
                d.append((b.values[el] - a.values[el]) / big if big > 0 else 0.0)
                ratio.append(b.sigmas[el] / a.sigmas[el] if a.sigmas[el] > 0 else np.nan)
        jit = (np.random.default_rng(i).uniform(-0.25, 0.25, len(d)))
        axes[0].plot(i + jit, d, ".", ms=4, color=_COLORS[i % len(_COLORS)])
        axes[1].plot(i + jit, ratio, ".", ms=4, color=_COLORS[i % len(_COLORS)])
    la, lb = (SOLVER_LABELS.get(s, s) for s in pair)
    for ax, title, lines in ((axes[0], f"({lb} - {la}) / larger sigma", (-0.1, 0.1)),
                             (axes[1], f"sigma({lb}) / sigma({la})", (0.9, 1.1))):
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels(names, rotation=20, fontsize=7)
        for y in lines:
            ax.axhline(y, color="r", lw=0.8, ls="--")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{la} against {lb}, every parameter of every subrange (dashed: agreement limits)", fontsize=9)
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


def _load_residuals(path, quantities=None):
    """``{kind: (t (F,) s, values (F, 3))}`` of a residual-series file (:func:`graph_calib.io.read_residuals`).

    Kinds sorted by name, empty kinds left out; ``{}`` when the file is missing.  ``quantities``, a list,
    receives the file's residual quantity (whitened residual or normalised innovation).
    """
    if not Path(path).is_file():
        return {}
    attrs, series = io.read_residuals(path)
    if quantities is not None and attrs.get("quantity"):
        quantities.append(str(attrs["quantity"]))
    return {kd: series[kd] for kd in sorted(series) if series[kd][1].size}


def fig_residuals(run, solver):
    plt = _plt()
    names = [n for n in run.results if solver in run.results[n]]
    # beside each experiment's result file (its own folder, or a pooled wave's, campaign.json's results.file)
    files = {e["name"]: ((e.get("results") or {}).get(solver) or {}).get("file") for e in run.document["experiments"]}
    quantities = []
    data = {n: _load_residuals(run.out / Path(files.get(n) or f"{n}/{solver}.json").parent / f"{solver}.residuals.h5",
                               quantities) for n in names}
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
    what = f"{quantities[0]}s" if quantities else "residuals"
    fig.suptitle(f"{SOLVER_LABEL.get(solver, solver)}: {what} per subrange (N(0,1) when the model fits)", fontsize=9)
    fig.tight_layout()
    return fig


__all__ = ["SOLVER_LABEL", "PLOT_OFFSET_DEGC", "point_minus_reference", "report_unit", "fig_parameter", "fig_validation", "fig_boundaries", "fig_residuals",
           "fig_solver_comparison", "fig_temperatures"]
