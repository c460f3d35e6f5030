"""The study page (Markdown, docs/study.md) of ``graph-calib compare --markdown``: the comparison's numbers, its
figures as PNG files beside it, and the statements where a candidate needs at most half the reference's duration
and where not, worked out from those numbers.

It reads the comparison document and the comparison's curves; it never runs a prediction or a solver.
"""

from __future__ import annotations

from pathlib import Path

from graph_calib.design.comparison import DISPLAY, FAMILIES
from graph_calib.io import atomic_path
from graph_calib.reports.comparison_report import accuracy_figure, curves_figure, noise_text, ratio_figure
from graph_calib.reports.html import figure_png

HALF = 0.5


def _save(fig, path):
    png = figure_png(fig, dpi=100)
    with atomic_path(path) as tmp:
        tmp.write_bytes(png)


def _ratio_cell(r):
    if r["ratio"] is None:
        return "not reached"
    return {"below": "< ", "extrapolated": "~"}.get(r["status"], "") + f"{r['ratio']:.2f}"


def half_statements(doc, *, metric="largest_sigma", families=("gyro.bias", "accel.bias")):
    """Lines saying, per candidate, soak and family, for which reference lengths the ratio is at most half."""
    lines = []
    several = {p["name"] for p in doc["procedures"] if len(p["lengths_s"]) >= 2}
    for cand, by_soak in doc["equal_accuracy"].items():
        if cand not in several:
            continue            # one campaign: no curve to read a duration from (its point is in the figures)
        for soak, fams in by_soak.items():
            for f in families:
                rows = fams[f][metric]
                yes = [r for r in rows if r["ratio"] is not None and r["ratio"] <= HALF]
                no = [r for r in rows if r not in yes]
                hs = lambda rr: ", ".join(f"{r['reference_length_s'] / 3600:g} h ({_ratio_cell(r)})" for r in rr)
                where = f"{cand}, soak {float(soak) / 3600:g} h, {f}:"
                if not no:
                    lines.append(f"- {where} at most half for every step length ({hs(yes)}).")
                elif not yes:
                    lines.append(f"- {where} **never** at most half ({hs(no)}).")
                else:
                    lines.append(f"- {where} at most half for {hs(yes)}; **not** for {hs(no)}.")
    return lines


def why_lines(doc, comparison):
    """Facts behind the ratios, computed: the soaks' share, accuracy per recorded hour, where over temperature
    each procedure's sigma is largest, the model error against the noise."""
    procs = doc["procedures"]
    ref, cand = procs[0], procs[1]
    lines = []
    if ref["kind"] == "steps":
        n = ref["experiments"]
        for w in doc["soaks_s"]:
            shares = [(n - 1) * w / (n * L + (n - 1) * w) for L in ref["lengths_s"]]
            lines.append(f"- Soak {w / 3600:g} h: the soaks are {', '.join(f'{s:.0%}' for s in shares)} of the "
                         f"{ref['name']} campaigns ({', '.join(f'{L / 3600:g}' for L in ref['lengths_s'])} h per "
                         "step); the continuous procedure has none, so the saving is the soaks.")
    rp = {pt["length_s"]: pt["metrics"] for pt in doc["campaigns"][ref["name"]]}
    cp = {pt["length_s"]: pt["metrics"] for pt in doc["campaigns"][cand["name"]]}
    common = sorted(set(rp) & set(cp))
    for L in common:
        g = [rp[L]["gyro.bias"]["largest_sigma"], cp[L]["gyro.bias"]["largest_sigma"]]
        a = [rp[L]["accel.bias"]["largest_sigma"], cp[L]["accel.bias"]["largest_sigma"]]
        lines.append(f"- {L / 3600:g} h per experiment ({ref['experiments']} x against {cand['experiments']} x): "
                     f"largest gyro-bias sigma {g[0] * DISPLAY['gyro.bias'][0]:.4f} ({ref['name']}) against "
                     f"{g[1] * DISPLAY['gyro.bias'][0]:.4f} deg/h ({cand['name']}), accelerometer "
                     f"{a[0] * DISPLAY['accel.bias'][0]:.3f} against {a[1] * DISPLAY['accel.bias'][0]:.3f} micro-g: "
                     "per recorded hour the constant-temperature step is the better estimator (it need not separate "
                     "the bias from its slope).")
    T = comparison.grid_degC
    for p in comparison.procedures[:2]:
        pts = comparison.points[p.name]
        pt = min(pts, key=lambda x: abs(x.length_s - 3600.0))
        for f in ("gyro.bias", "accel.bias"):
            s = pt.sigma_curve[f]
            mid = s[(T > T[0] + 10) & (T < T[-1] - 10)].max()
            i = int(s.argmax())
            lines.append(f"- {p.name}, {pt.length_s / 3600:.3g} h: the {f} sigma is largest at {T[i]:.0f} degC, "
                         f"{s[i] / mid:.2f} times its largest 10 degC inside the ends.")
    for L in common[:1] + common[-1:]:
        lines.append(f"- Model error of the accelerometer bias, {L / 3600:g} h per experiment: {ref['name']} "
                     f"{rp[L]['accel.bias']['model_error_largest'] * DISPLAY['accel.bias'][0]:.3f} micro-g, "
                     f"{cand['name']} {cp[L]['accel.bias']['model_error_largest'] * DISPLAY['accel.bias'][0]:.3f} "
                     f"micro-g (mean over the truth draws of the largest over the range; the noise sigma "
                     f"{cp[L]['accel.bias']['largest_sigma'] * DISPLAY['accel.bias'][0]:.3f} micro-g).")
    return lines


def comparison_markdown(doc, comparison, *, path, command, intro="", closing=""):
    """Write the study page to ``path`` and its figures to ``path.parent / "figures"``; returns the text.

    ``command``: the command line that made it (quoted on the page); ``intro`` / ``closing``: Markdown the
    caller adds before the results and after them (the reading of the numbers).
    """
    path = Path(path)
    figs = path.parent / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    _save(accuracy_figure(doc, families=("gyro.bias", "accel.bias")), figs / "study_accuracy.png")
    _save(accuracy_figure(doc, metric="largest_total", families=("gyro.bias", "accel.bias")),
          figs / "study_accuracy_total.png")
    _save(ratio_figure(doc), figs / "study_ratios.png")
    _save(curves_figure(comparison), figs / "study_curves.png")
    ref = doc["procedures"][0]["name"]
    out = ["# Study: a continuous temperature profile against constant-temperature steps", "",
           f"Generated by `{command}` ({doc['seconds']:.0f} s wall, {doc.get('cpu_seconds', float('nan')):.0f} s CPU for the predicted part); do not edit by hand.", ""]
    if intro:
        out += [intro.strip(), ""]
    out += ["## The procedures", "", "| name | kind | experiments | h per experiment | soak, h | description |",
            "| --- | --- | --- | --- | --- | --- |"]
    for p in doc["procedures"]:
        soak = f"{p['soak_s'] / 3600:g}" if p["kind"] == "steps" else "-"
        out.append(f"| {p['name']} | {p['kind']} | {p['experiments']} | "
                   f"{', '.join(f'{L / 3600:.3g}' for L in p['lengths_s'])} | {soak} | {p['description']} |")
    tf = doc["truth_family"]
    out += ["", f"The IMU: {noise_text(doc['noise'])}.", "", f"Range judged: {doc['range_degC'][0]:g}..{doc['range_degC'][1]:g} degC of sensor temperature. "
            f"Truth family ({doc['truth_draws']} draws): {tf['form']}; sizes in "
            "`graph_calib/design/comparison.py` (`TruthFamily`): accelerometer bias 10-40 micro-g for each of the "
            "quadratic and cubic terms at the ends of the range, scale factors 1-8 ppm, gyro bias 0.005-0.03 deg/h, "
            "slopes the simulator's navigation ranges.", "",
            "## Accuracy against campaign duration", "",
            "![largest 1-sigma against duration](figures/study_accuracy.png)", "",
            "![largest of noise and model error against duration](figures/study_accuracy_total.png)", "",
            "| procedure | h per experiment | campaign h (per soak) | " + " | ".join(
                f"{f} 1-sigma, {DISPLAY[f][1]}" for f in FAMILIES) + " | gyro.bias model error | "
            "accel.bias model error | accel.bias expected largest |",
            "| --- " * (3 + len(FAMILIES) + 3) + "|"]
    for p in doc["procedures"]:
        for pt in doc["campaigns"][p["name"]]:
            d = pt["duration_s"]
            d = " / ".join(f"{v / 3600:.3g}" for v in d.values()) if isinstance(d, dict) else f"{d / 3600:.3g}"
            m = pt["metrics"]
            cells = [f"{m[f]['largest_sigma'] * DISPLAY[f][0]:.3g}" for f in FAMILIES]
            out.append(f"| {p['name']} | {pt['length_s'] / 3600:.3g} | {d} | " + " | ".join(cells) + " | "
                       f"{m['gyro.bias']['model_error_largest'] * DISPLAY['gyro.bias'][0]:.3g} | "
                       f"{m['accel.bias']['model_error_largest'] * DISPLAY['accel.bias'][0]:.3g} | "
                       f"{m['accel.bias']['expected_largest'] * DISPLAY['accel.bias'][0]:.3g} |")
    out += ["", "## Equal-accuracy ratios", "",
            f"The duration a candidate needs for the accuracy of each {ref} campaign, divided by that campaign's "
            "duration (`<`: the candidate's shortest campaign is already as accurate; `~`: beyond its longest "
            "campaign, on the log-log line of its last two).", "",
            "![equal-accuracy ratios](figures/study_ratios.png)", ""]
    lengths = [f"{r['reference_length_s'] / 3600:g} h" for r in next(iter(next(iter(
        doc["equal_accuracy"].values())).values()))["gyro.bias"]["largest_sigma"]]
    out += ["| candidate | soak, h | family | metric | " + " | ".join(lengths) + " |",
            "| --- " * (4 + len(lengths)) + "|"]
    several = {p["name"] for p in doc["procedures"] if len(p["lengths_s"]) >= 2}
    for cand, by_soak in doc["equal_accuracy"].items():
        if cand not in several:
            continue
        for soak, fams in by_soak.items():
            for f in ("gyro.bias", "accel.bias"):
                for m in ("largest_sigma", "rms_sigma", "largest_total", "expected_largest"):
                    out.append(f"| {cand} | {float(soak) / 3600:g} | {f} | {m} | "
                               + " | ".join(_ratio_cell(r) for r in fams[f][m]) + " |")
    out += ["", "### Where the candidate needs at most half (largest 1-sigma over the range)", ""]
    out += half_statements(doc)
    out += ["", "### The same with the model error (largest sqrt(sigma^2 + model error^2))", ""]
    out += half_statements(doc, metric="largest_total")
    out += ["", "## Over temperature", "", "![sigma and model error over temperature](figures/study_curves.png)", ""]
    out += ["## Why, in the numbers", ""] + why_lines(doc, comparison) + [""]
    sc = doc.get("simulated_check")
    if sc:
        out += ["## Simulated check", "", sc["what"], "", f"**{sc['verdict']['text']}**", "",
                "| procedure | h per experiment | family | realisations | scale of the experiments (95 % band) | "
                "scale of the stitched curve (band) | scale at the four nodes (band) | predicted largest | simulated "
                "largest (scaled) | raw largest over the range | raw / predicted | predicted RMS | raw RMS | "
                "raw / predicted |",
                "| --- " * 14 + "|"]
        for name, per in sc["campaigns"].items():
            for L, v in per.items():
                for f in ("gyro.bias", "accel.bias"):
                    k = DISPLAY[f][0]
                    x = v[f]
                    ws, es = x["whitened"], x["experiment"]
                    out.append(f"| {name} | {float(L) / 3600:g} | {f} | {x['realisations']} | "
                               f"{es['scale']:.3f} ({es['band'][0]:.2f}-{es['band'][1]:.2f}) | "
                               f"{ws['scale']:.3f} ({ws['band'][0]:.2f}-{ws['band'][1]:.2f}) | "
                               f"{', '.join(f'{n:.2f}' for n in ws['node_scale'])} "
                               f"({ws['node_band'][0]:.2f}-{ws['node_band'][1]:.2f}) | "
                               f"{x['predicted_largest_sigma'] * k:.3g} | {x['largest_sigma'] * k:.3g} | "
                               f"{x['largest_sigma_raw'] * k:.3g} | "
                               f"{x['largest_sigma_raw'] / x['predicted_largest_sigma']:.3f} | "
                               f"{x['predicted_rms_sigma'] * k:.3g} | {x['rms_sigma_raw'] * k:.3g} | "
                               f"{x['rms_sigma_raw'] / x['predicted_rms_sigma']:.3f} |")
        out += ["", "| family | metric | judged | reference h per step | predicted ratio | simulated ratio | "
                "simulated / predicted | standard error | status (predicted / simulated) |", "| --- " * 9 + "|"]
        for f, per in sc["ratios"].items():
            if f not in ("gyro.bias", "accel.bias"):
                continue
            for m, rows in per.items():
                for r in rows:
                    fmt = lambda v: "-" if v is None else f"{v:.3f}"
                    se = "-" if r.get("relative_se") is None else f"{r['relative_se']:.0%}"
                    out.append(f"| {f} | {m} | {'yes' if r.get('judged') else 'no'} | "
                               f"{r['reference_length_s'] / 3600:g} | {fmt(r['predicted'])} | "
                               f"{fmt(r['simulated'])} | {fmt(r['agreement'])} | {se} | {r['status']} |")
        out.append("")
    if closing:
        out += [closing.strip(), ""]
    text = "\n".join(out)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return text


__all__ = ["half_statements", "why_lines", "comparison_markdown"]
