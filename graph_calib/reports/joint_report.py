"""The joint campaign solver's part of a campaign report: its curves over the per-subrange estimates, the table.

:func:`joint_sections` returns the report's section (or nothing when the joint solver did not run): per
curve family, one figure with a panel per axis (the joint curve with its one-sigma band, straight from the
joint covariance, over each subrange's estimate at its reference temperature with one-sigma bars, and the
truth curve when a truth file gives ``temperature_curves``), the degree chosen with its evidence, and the
table of ``(joint at T_ref - per-subrange estimate) / sigma`` per subrange and element.
"""

from __future__ import annotations

import numpy as np

from graph_calib.compensation.joint import JointCalibration
from graph_calib.reports import html as H
from graph_calib.reports.campaign_figures import _plt, report_unit
from graph_calib.solvers.joint.solver import JOINT
from graph_calib.solvers.registry import PRIMARY_SOLVER, primary_first

#: Markers of the per-subrange solvers in the figures, the primary solver's first.
_MARKERS = (("o", "C0"), ("s", "C1"), ("^", "C2"), ("D", "C3"))


def fig_joint_family(run, parameter, cal):
    """One panel per axis: the joint curve of ``parameter`` with its band over the per-subrange estimates."""
    names = [n for n in cal.curves if n.rsplit(".", 1)[0] == parameter]
    if not names:
        return None
    plt = _plt()
    unit, k = report_unit(parameter)
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.2), squeeze=False)
    curves = next((t.extra["temperature_curves"] for t in run.truths.values()
                   if isinstance(t.extra.get("temperature_curves"), dict)), None)
    for ax, name in zip(axes[0], names):
        cv = cal.curves[name]
        T = np.linspace(*cv.t_span, 121)
        v, s = cv.evaluate(T)
        ax.fill_between(T, (v - s) * k, (v + s) * k, color="0.8", label="joint, 1 sigma")
        ax.plot(T, v * k, "k-", lw=1.2, label="joint curve")
        for i, solver in enumerate(primary_first(run.document.get("solvers", ()))):
            pts = [(r[solver].t_ref_degC, r[solver].values[name], r[solver].sigmas[name])
                   for r in run.results.values() if solver in r and name in r[solver].values]
            if pts:
                t, y, e = (np.array(c) for c in zip(*pts))
                m, col = _MARKERS[i % len(_MARKERS)]
                ax.errorbar(t + 0.4 * i, y * k, yerr=e * k, fmt=m, color=col, ms=4, capsize=2,
                            mfc=col if i == 0 else "none", label=f"{solver} per subrange")
        if curves is not None and name in curves:
            c = curves[name]
            d = T - float(c["t0_degC"])
            ax.plot(T, sum(float(ci) * d**j for j, ci in enumerate(c["coefficients"])) * k, "m--", lw=1,
                    label="truth")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("sensor temperature (degC)")
        ax.set_ylabel(unit)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def _cross_table(entry):
    rows = []
    for solver, cc in entry.get("cross_check", {}).items():
        for exp, z in cc["experiments"].items():
            worst = sorted(z.items(), key=lambda kv: -abs(kv[1]))[:3]
            rows.append([exp, solver, f"{max(abs(v) for v in z.values()):.2f}" if z else "-",
                         f"{np.sqrt(np.mean(np.square(list(z.values())))):.2f}" if z else "-",
                         ", ".join(f"{n} {v:+.2f}" for n, v in worst)])
    return H.table(["subrange", "solver", "max |z|", "rms z", "largest (element z)"], rows, left=(0, 1, 4))


def _full_table(entry):
    cc = entry.get("cross_check", {}).get(PRIMARY_SOLVER)
    if not cc:
        return H.Raw("")
    exps = list(cc["experiments"])
    elements = sorted({n for z in cc["experiments"].values() for n in z})
    rows = [[n] + [f"{cc['experiments'][e].get(n, float('nan')):+.2f}" for e in exps] for n in elements]
    return H.table(["element"] + exps, rows)


def joint_sections(run, fig):
    """The report's joint-solver section (a list, empty when the joint solver did not run)."""
    if run.joint is None:
        return []
    entry = (run.document.get(JOINT) or {}).get(JOINT, {})
    cal = JointCalibration.from_result(run.joint)
    blocks = []
    for p in ("gyro.bias", "gyro.scale", "accel.bias", "accel.scale"):
        f = fig_joint_family(run, p, cal)
        if f is not None:
            deg = entry.get("degrees", {}).get(p)
            blocks.append(fig(f, f"{p}: the joint curve (degree {deg}) with its one-sigma band from the joint "
                                 "covariance, over each subrange's estimate at its reference temperature."))
    choice = "; ".join(
        f"{c['family']}: degree {c['degree']}"
        + (f" (the data show {c['significant_degree']}; holding the rest widens its sigma by at most "
           f"{c.get('widening', 1.0):.2f}x)" if c.get("significant_degree") not in (None, c["degree"]) else "")
        + " (" + ", ".join(f"order {t['order']} Wald {t['wald']:.3g} vs "
                           + (f"BIC price {t['bic_price']:.3g}" if "bic_price" in t else f"threshold {t['threshold']:.3g}")
                           for t in c["tests"])
        + ")" for c in entry.get("degree_choice", []))
    tc = entry.get("truth_check") or {}
    truth = (f"Against the truth ({tc['mode']}): {100 * tc['fraction_within_2sigma']:.1f} % of {tc['points']} points "
             f"within 2 sigma, largest |z| {tc['max_abs_z']:.2f} ({tc['worst']['element']} at "
             f"{tc['worst']['T_degC']:.1f} degC)." if tc.get("points") else "No truth to check against.")
    verdict = entry.get("verdict") or {}
    return [H.section(
        "Joint solver: one model over the whole range",
        H.paragraph(f"Every experiment in one factor graph: each temperature-dependent element one polynomial in its "
                    f"sensor's temperature about t0 = {entry.get('t0_degC')} degC, the set-up (mount, lever arm, "
                    f"table lag) per experiment, the rest shared ({entry.get('status')}, "
                    f"{entry.get('seconds') or 0:.1f} s). {verdict.get('text', '')}"),
        H.paragraph("Degree by evidence: " + choice),
        H.paragraph(truth),
        *blocks,
        H.section("Joint at each T_ref minus the per-subrange estimate, in sigma of the per-subrange estimate",
                  _cross_table(entry), _full_table(entry), level=3),
        anchor=JOINT)]


__all__ = ["joint_sections", "fig_joint_family"]
