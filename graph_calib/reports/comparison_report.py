"""The HTML report of ``graph-calib compare``: accuracy against campaign duration, the equal-accuracy ratios,
the stitched sigma and model error over temperature, and the simulated check when there is one.

It reads the comparison document (``comparison.json``'s content) and the comparison's curves; it never runs
a prediction or a solver.
"""

from __future__ import annotations

import numpy as np

from graph_calib import constants as c
from graph_calib.design.comparison import DISPLAY, FAMILIES
from graph_calib.reports.campaign_figures import _plt
from graph_calib.reports.html import figure, page, paragraph, section, table

_LABEL = {"largest_sigma": "largest 1-sigma over the range", "rms_sigma": "RMS sigma over the range",
          "largest_total": "largest sqrt(sigma^2 + model error^2)", "expected_largest": "expected largest error",
          "model_error_largest": "largest model error (mean over truths)"}


def _durations(proc, length_s, soaks):
    if proc["kind"] == "steps":
        n = proc["experiments"]
        return [(f"soak {w / 3600:g} h", n * length_s + (n - 1) * w) for w in soaks]
    return [("", proc["experiments"] * length_s)]


def accuracy_figure(doc, *, metric="largest_sigma", families=FAMILIES):
    """Accuracy (``metric``) against campaign duration, one panel per family, one line per procedure and soak."""
    fig, axes = _plt().subplots(1, len(families), figsize=(4.2 * len(families), 3.8), squeeze=False)
    for ax, f in zip(axes[0], families):
        k, unit = DISPLAY[f]
        for proc in doc["procedures"]:
            pts = doc["campaigns"][proc["name"]]
            for j, (lab, _) in enumerate(_durations(proc, 0.0, doc["soaks_s"])):
                d = [(_durations(proc, p["length_s"], doc["soaks_s"])[j][1]) / 3600 for p in pts]
                v = [p["metrics"][f][metric] * k for p in pts]
                ls = "-" if j == 0 else ("--", ":", "-.")[(j - 1) % 3]
                ax.plot(d, v, marker="o", ls=ls, ms=4, label=f"{proc['name']} {lab}".strip())
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_major_formatter(_plt().matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(_plt().matplotlib.ticker.NullFormatter())
        ax.set_xticks([1, 2, 5, 10, 20, 50])
        ax.set_xlabel("campaign duration, h")
        ax.set_title(f"{f}, {unit}", fontsize=9)
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].set_ylabel(_LABEL[metric])
    axes[0, -1].legend(fontsize=7)
    fig.tight_layout()
    return fig


def ratio_figure(doc, *, metrics=("largest_sigma", "rms_sigma", "largest_total"), families=("gyro.bias",
                                                                                               "accel.bias")):
    """Equal-accuracy ratio (candidate's duration / reference's) against the reference's length per experiment.

    Colour: the soak; line style: the metric; one figure row per candidate with at least two campaigns.
    """
    cands = [p["name"] for p in doc["procedures"][1:] if len(p["lengths_s"]) >= 2]
    plt = _plt()
    fig, axes = plt.subplots(max(len(cands), 1), len(families), figsize=(5.5 * len(families), 3.6 * max(len(cands), 1)),
                             squeeze=False)
    styles = dict(zip(metrics, ("-", "--", ":", "-.")))
    for row, cand in enumerate(cands):
        for ax, f in zip(axes[row], families):
            for j, (soak, fams) in enumerate(doc["equal_accuracy"][cand].items()):
                for m in metrics:
                    rows = [r for r in fams[f][m] if r["ratio"] is not None]
                    ax.plot([r["reference_length_s"] / 3600 for r in rows], [r["ratio"] for r in rows], marker="o",
                            ms=4, ls=styles[m], color=f"C{j}", label=f"soak {float(soak) / 3600:g} h, {m}")
            ax.axhline(0.5, color="k", ls="--", lw=0.8)
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(plt.matplotlib.ticker.ScalarFormatter())
            ax.xaxis.set_minor_formatter(plt.matplotlib.ticker.NullFormatter())
            ax.set_xticks([r["reference_length_s"] / 3600 for r in fams[f][metrics[0]]])
            ax.set_xlabel(f"{doc['procedures'][0]['name']}: hours recorded per experiment")
            ax.set_ylabel("duration ratio")
            ax.set_title(f"{cand} / {doc['procedures'][0]['name']}: {f} (dashed black: half)", fontsize=9)
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=6)
    fig.tight_layout()
    return fig


def curves_figure(comparison, *, families=("gyro.bias", "accel.bias"), length_s=3600.0):
    """Stitched one sigma and RMS model error over temperature of each procedure's campaign nearest ``length_s``."""
    fig, axes = _plt().subplots(1, len(families), figsize=(5.5 * len(families), 3.6), squeeze=False)
    T = comparison.grid_degC
    for ax, f in zip(axes[0], families):
        k, unit = DISPLAY[f]
        for proc in comparison.procedures:
            pts = comparison.points[proc.name]
            pt = min(pts, key=lambda p: abs(np.log(p.length_s / length_s)))
            line, = ax.plot(T, pt.sigma_curve[f] * k, label=f"{proc.name} {pt.length_s / 3600:.3g} h: 1 sigma")
            ax.plot(T, pt.model_error_curve[f] * k, ls="--", color=line.get_color(), label=f"{proc.name}: model error")
        ax.set_ylim(bottom=0.0)
        ax.set_xlabel("sensor temperature, degC")
        ax.set_ylabel(unit)
        ax.set_title(f"{f}: largest over the axes", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _fmt(v, f):
    return f"{v * DISPLAY[f][0]:.3g}"


def noise_text(noise):
    """The grade and densities of a comparison's ``noise`` block, in the units labs quote."""
    given = noise.get("given") or []
    return (f"{noise['grade']} grade; gyro {noise['gyro_noise'] / c.DSH_TO_RSS:.3g} deg/sqrt(h), accelerometer "
            f"{noise['accel_noise'] / c.UG_TO_MPS2:.3g} micro-g/sqrt(Hz), table readings "
            f"{noise['encoder_noise'] * c.RAD_TO_ARCSEC:.3g} arcsec"
            + (f" ({', '.join(given)} given, the rest the grade's)" if given else " (the grade's)"))


def comparison_report_html(doc, comparison):
    """The report page: ``doc`` is comparison.json's content, ``comparison`` the :class:`Comparison`."""
    ref = doc["procedures"][0]["name"]
    parts = [paragraph(
        f"Procedures compared on the predicted accuracy of their stitched curves over "
        f"{doc['range_degC'][0]:g}..{doc['range_degC'][1]:g} degC (sensor temperature) against campaign duration. "
        f"Noise: the shared model's Fisher information of each experiment (graph-calib predict), stitched as the "
        f"campaign stitches (cubic over temperature). Model error: each procedure's temperature model against "
        f"{doc['truth_draws']} truth curves of the stated family (cubic in every bias and scale factor). Reference "
        f"procedure: {ref}. The IMU: {noise_text(doc['noise'])}. Predicted part: {doc['seconds']:.0f} s wall, {doc.get('cpu_seconds', float('nan')):.0f} s CPU.")]
    rows = []
    for p in doc["procedures"]:
        rows.append([p["name"], p["kind"], p["experiments"], ", ".join(f"{L / 3600:.3g}" for L in p["lengths_s"]),
                     f"{p['soak_s'] / 3600:g}" if p["kind"] == "steps" else "-", p["description"]])
    parts.append(section("Procedures", table(["name", "kind", "experiments", "h per experiment", "soak, h",
                                              "description"], rows, left=(0, 1, 5))))
    parts.append(section("Accuracy against campaign duration",
                         figure(accuracy_figure(doc), caption="largest predicted 1-sigma of the stitched curve over "
                                                                "the range (noise only)"),
                         figure(accuracy_figure(doc, metric="largest_total"),
                                caption="largest sqrt(sigma^2 + model error^2): noise and the procedure's "
                                        "temperature model against the truth family")))
    parts.append(section("Equal-accuracy ratios", figure(ratio_figure(doc), caption=(
        "duration of the candidate campaign with the reference campaign's accuracy, divided by the reference "
        "campaign's duration; below the dashed line the candidate needs at most half"))))
    rrows = []
    several = {p["name"] for p in doc["procedures"] if len(p["lengths_s"]) >= 2}
    for cand, by_soak in doc["equal_accuracy"].items():
        if cand not in several:
            continue                # one campaign: no curve to read a duration from
        for soak, fams in by_soak.items():
            for f in ("gyro.bias", "accel.bias"):
                for m in ("largest_sigma", "rms_sigma", "largest_total", "expected_largest"):
                    cells = []
                    for r in fams[f][m]:
                        if r["ratio"] is None:
                            cells.append("not reached")
                        else:
                            mark = {"below": "< ", "extrapolated": "~"}.get(r["status"], "")
                            cells.append(f"{mark}{r['ratio']:.2f}")
                    rrows.append([cand, f"{float(soak) / 3600:g}", f, m, *cells])
    lengths = [f"{r['reference_length_s'] / 3600:g} h" for r in
               next(iter(next(iter(doc["equal_accuracy"].values())).values()))["gyro.bias"]["largest_sigma"]]
    parts.append(table(["candidate", "soak, h", "family", "metric", *[f"{ref} {x}" for x in lengths]], rrows,
                       left=(0, 2, 3)))
    parts.append(paragraph("< : the candidate's shortest campaign is already as accurate (an upper bound); "
                           "~ : beyond its longest campaign, on the log-log line of its last two."))
    parts.append(section("Over temperature", figure(curves_figure(comparison), caption=(
        "the stitched curve's predicted 1-sigma (solid) and the RMS model error over the truth draws (dashed), "
        "largest over the three axes"))))
    mrows = []
    for p in doc["procedures"]:
        for pt in doc["campaigns"][p["name"]]:
            dur = pt["duration_s"]
            dur = ", ".join(f"{v / 3600:.3g}" for v in dur.values()) if isinstance(dur, dict) else f"{dur / 3600:.3g}"
            m = pt["metrics"]
            mrows.append([p["name"], f"{pt['length_s'] / 3600:.3g}", dur,
                          *[_fmt(m[f]["largest_sigma"], f) for f in FAMILIES],
                          *[_fmt(m[f]["model_error_largest"], f) for f in FAMILIES],
                          _fmt(m["gyro.bias"]["expected_largest"], "gyro.bias"),
                          _fmt(m["accel.bias"]["expected_largest"], "accel.bias")])
    units = [f"{f} {DISPLAY[f][1]}" for f in FAMILIES]
    parts.append(section("Every campaign", table(
        ["procedure", "h per experiment", "duration, h (per soak)", *[f"1-sigma {u}" for u in units],
         *[f"model error {u}" for u in units], "expected largest gyro.bias", "expected largest accel.bias"],
        mrows)))
    if doc.get("simulated_check"):
        sc = doc["simulated_check"]
        srows = []
        for name, per in sc["campaigns"].items():
            for L, v in per.items():
                for f in ("gyro.bias", "accel.bias"):
                    ws, es = v[f]["whitened"], v[f]["experiment"]
                    srows.append([name, f"{float(L) / 3600:g}", f, v[f]["realisations"],
                                  f"{es['scale']:.3f} ({es['band'][0]:.2f}-{es['band'][1]:.2f})",
                                  f"{ws['scale']:.3f} ({ws['band'][0]:.2f}-{ws['band'][1]:.2f})",
                                  ", ".join(f"{n:.2f}" for n in ws["node_scale"])
                                  + f" ({ws['node_band'][0]:.2f}-{ws['node_band'][1]:.2f})",
                                  _fmt(v[f]["predicted_largest_sigma"], f), _fmt(v[f]["largest_sigma"], f),
                                  _fmt(v[f]["largest_sigma_raw"], f),
                                  _fmt(v[f]["predicted_rms_sigma"], f), _fmt(v[f]["rms_sigma_raw"], f)])
        crow = []
        for f, rows in sc["ratios"].items():
            for m, rr in rows.items():
                for r in rr:
                    crow.append([f, m, "yes" if r.get("judged") else "no", f"{r['reference_length_s'] / 3600:g}",
                                 "-" if r["predicted"] is None else f"{r['predicted']:.3f}",
                                 "-" if r["simulated"] is None else f"{r['simulated']:.3f}",
                                 "-" if r["agreement"] is None else f"{r['agreement']:.3f}",
                                 "-" if r.get("relative_se") is None else f"{r['relative_se']:.0%}", r["status"]])
        parts.append(section("Simulated check", paragraph(sc["what"]), paragraph(sc["verdict"]["text"]),
                             table(["procedure", "h per experiment", "family", "realisations",
                                    "scale of the experiments (95 % band)", "scale of the stitched curve (band)",
                                    "scale at the nodes (band)", "predicted largest", "simulated largest (scaled)",
                                    "raw largest", "predicted RMS", "raw RMS"], srows),
                             table(["family", "metric", "judged", "reference h", "predicted ratio", "simulated ratio",
                                    "simulated / predicted", "standard error", "status"], crow)))
    return page("graph-calib compare", *parts)


__all__ = ["accuracy_figure", "ratio_figure", "curves_figure", "noise_text", "comparison_report_html"]
