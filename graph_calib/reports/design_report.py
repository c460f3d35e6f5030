"""The HTML report of ``graph-calib design``: the designed program over time, predicted bounds against the targets,
designed against baseline.  It reads the programs and the design document; it never runs the design."""

from __future__ import annotations

import numpy as np

from graph_calib import constants as c
from graph_calib.reports.campaign_figures import _plt
from graph_calib.reports.html import figure, page, paragraph, section, table, verdict


def _program_figure(programs):
    """Axis angles and chamber / sensor temperatures over time of each ``(label, BenchProgram)``."""
    fig, axes = _plt().subplots(2, len(programs), figsize=(5.5 * len(programs), 5.5), squeeze=False, sharey="row")
    for j, (label, prog) in enumerate(programs):
        tp = prog.table_program()
        t = np.arange(0.0, tp.duration, 1.0)
        ang, _, _ = tp.angles(t)
        ax = axes[0, j]
        ax.plot(t / 60, np.degrees(ang[:, 0]), label="outer axis")
        ax.plot(t / 60, np.degrees(ang[:, 1]), label="inner axis")
        ax.set_title(f"{label}: {tp.duration / 60:.1f} min")
        ax.set_ylabel("angle, deg")
        ax.legend(loc="upper right", fontsize=8)
        th = prog.thermal()
        T = th.temperature(t)
        ax = axes[1, j]
        ax.plot(t / 60, th.chamber(t), "k--", label="chamber")
        for i, name in enumerate(th.names[:4]):
            ax.plot(t / 60, T[:, i], label=name)
        ax.set_xlabel("time, min")
        ax.set_ylabel("temperature, degC")
        ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return fig


def _bound_figure(doc):
    """Predicted largest remaining errors (at the stated confidence) against the targets, designed and baseline."""
    rows = [("designed", doc["predicted_bound"])]
    if doc.get("baseline"):
        rows.append(("baseline", doc["baseline"]["predicted_bound"]))
    fig, axes = _plt().subplots(1, 2, figsize=(10, 3.2))
    w = 0.8 / len(rows)
    for i, (label, b) in enumerate(rows):
        x = np.arange(3) + i * w
        axes[0].bar(x, np.array(b["gyro_radps"]["bound"]) * c.RS_TO_DH, w, label=label)
        axes[1].bar(x, b["accel_mps2"]["bound"], w, label=label)
    axes[0].axhline(doc["targets"]["gyro_radps"] * c.RS_TO_DH, color="r", ls="--", label="target")
    axes[1].axhline(doc["targets"]["accel_mps2"], color="r", ls="--", label="target")
    axes[1].set_yscale("log")
    for ax, title in zip(axes, ("gyro, deg/h (static windows)", "accelerometer, m/s^2 (all windows)")):
        ax.set_xticks(np.arange(3) + 0.4 - w / 2)
        ax.set_xticklabels(["x", "y", "z"])
        ax.set_title(title)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def design_report_html(doc, *, designed, baseline=None):
    """The report page: ``doc`` is design.json's content; ``designed``/``baseline`` the programs."""
    k = doc["targets"]["confidence_sigma"]
    parts = [paragraph(f"Shortest program meeting the targets: {doc['duration_s'] / 60:.1f} min "
                       f"({doc['structure']['stations']} static stations). Targets: static gyro error "
                       f"{doc['targets']['gyro_radps'] * c.RS_TO_DH:g} deg/h and accelerometer error "
                       f"{doc['targets']['accel_mps2']:g} m/s^2 at {k:g} sigma over the record's temperatures.")]
    if doc.get("baseline"):
        b = doc["baseline"]
        parts.append(paragraph(f"Baseline {b['name']}: {b['duration_s'] / 60:.1f} min; designed / baseline duration "
                               f"{doc['duration_ratio_to_baseline']:.2f}."))
    progs = [("designed", designed)] + ([("baseline", baseline)] if baseline is not None else [])
    parts.append(section("The programs over time", figure(_program_figure(progs),
                                                          caption="table axis angles; chamber and sensor temperatures")))
    rows = []
    for label, b in [("designed", doc["predicted_bound"])] + (
            [("baseline", doc["baseline"]["predicted_bound"])] if doc.get("baseline") else []):
        rows.append([label, *[f"{v * c.RS_TO_DH:.4f}" for v in b["gyro_radps"]["bound"]],
                     *[f"{v:.2e}" for v in b["accel_mps2"]["bound"]], verdict(b["meets"]["all"], "met", "not met")])
    parts.append(section("Predicted remaining errors against the targets",
                         figure(_bound_figure(doc), caption=f"largest predicted error at {k:g} sigma"),
                         table(["program", "gyro x deg/h", "gyro y", "gyro z", "accel x m/s^2", "accel y", "accel z",
                                "targets"], rows)))
    crow = [[cd["stations"], f"{cd['duration_s'] / 60:.1f}", f"{cd['gyro_bound_radps'] * c.RS_TO_DH:.4f}",
             f"{cd['eta']:.3f}", verdict(cd["meets"], "met", "not met")] for cd in doc["candidates"]]
    parts.append(section("Structures tried (CasADi/IPOPT on the reduced model, each verified by the full prediction)",
                         table(["stations", "minutes", "full gyro bound deg/h", "eta", "targets"], crow)))
    return page("graph-calib design", *parts)


__all__ = ["design_report_html"]
