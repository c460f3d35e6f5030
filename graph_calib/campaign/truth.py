"""The truth check of a campaign: the stitched curves against a simulator's truth, never extrapolated.

- :func:`truth_path`: ``<stem>.truth.json`` next to an experiment file (the simulator's convention);
- :func:`truth_check`: how the stitched curves sit against the truth (``campaign.json``'s ``truth_check``).

Which truth (data-format.md): a truth file's ``temperature_curves`` give the truth over the whole
range, so each stitched curve is checked across its covered range.  Without them a truth file holds
only inside its own temperature range (its value at ``t_ref_degC`` with its slope): each curve is then
checked against each subrange's own truth inside that subrange's sensor temperature range, never
beyond it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from graph_calib.stitching import family_z_limit, sensor_of
from graph_calib.evaluation.validation import ResultCalibration, TruthCurves


def truth_path(experiment_file):
    """``<stem>.truth.json`` next to an experiment file (the simulator's convention)."""
    p = Path(experiment_file)
    return p.with_name(p.stem + ".truth.json")


def _pieces(truth, sensor_ranges):
    """``(what, [(reference, (6, 2) ranges or None)])``: the references and where each holds."""
    if hasattr(truth, "evaluate"):
        return "reference", [(truth, None)]
    truths = dict(truth) if isinstance(truth, dict) else ({truth.source: truth} if hasattr(truth, "values")
                                                          else dict(enumerate(truth)))
    for t in truths.values():
        if (t.extra or {}).get("temperature_curves"):
            return "temperature_curves", [(TruthCurves(t), None)]
    out = []
    for name, t in truths.items():
        rg = (sensor_ranges or {}).get(name)
        rg = (np.asarray(rg, dtype=float).reshape(6, 2) if rg is not None
              else np.tile(np.asarray(t.temperature_range_degC, dtype=float), (6, 1)))
        out.append((ResultCalibration(t), rg))
    return "subrange_truths", out


def truth_check(stitched, truth, *, model=None, n=61, sensor_ranges=None):
    """How the stitched curves sit against the truth, without extrapolating a per-subrange truth.

    Parameters
    ----------
    stitched : graph_calib.stitching.Stitched
    truth : Result, sequence or dict of Result, or evaluator
        The experiments' truth files (``{experiment name: Result}`` or a list; one Result is a list
        of one); or anything with ``evaluate(T_sensors)`` giving ``{element: values}`` valid over the
        whole range (a :class:`graph_calib.evaluation.validation.TruthCurves`, another stitch).  When one truth
        file has ``temperature_curves`` those are the reference over each curve's covered range;
        otherwise each truth file is used only inside its own sensor temperature range.
    model : str, optional
        The stitched model, ``"cubic"`` or ``"linear"``; the default model when None.
    n : int
        Temperatures per element and reference piece.
    sensor_ranges : dict, optional
        ``{experiment name: (6, 2) sensor temperature ranges, degC}`` (the summaries'); default: each
        truth file's ``temperature_range_degC`` for all six sensors.

    Returns
    -------
    dict
        ``reference`` (``"temperature_curves"``, ``"subrange_truths"`` or ``"reference"``), per element
        ``{"max_abs_z", "max_abs_error"}`` (z: error over the stitched one-sigma band) and overall
        ``max_abs_z``, ``rms_z``, ``fraction_within_1sigma`` (about 0.68 for honest bands),
        ``fraction_within_2sigma``, ``points`` and ``consistent``: the largest ``|z|`` below the 1 %
        family-wise limit for four independent checks per element and piece
        (:func:`graph_calib.stitching.family_z_limit`).
    """
    what, pieces = _pieces(truth, sensor_ranges)
    per, zs, n_checks = {}, [], 0
    for name, cv in stitched.curves.items():
        lo, hi = cv.t_span
        s = sensor_of(name)
        zk, ek = [], []
        for ref, rg in pieces:
            a, b = (lo, hi) if rg is None else (max(lo, rg[s if s is not None else 0][0]),
                                                 min(hi, rg[s if s is not None else 0][1]))
            if not b > a:
                continue
            T = np.linspace(a, b, n)
            tv = ref.evaluate(np.tile(T[:, None], (1, 6))).get(name)
            if tv is None:
                continue
            v, sg = cv.evaluate(T, model)
            zk.append(np.where(sg > 0, (v - tv) / np.where(sg > 0, sg, 1.0), 0.0))
            ek.append(np.abs(v - tv))
            n_checks += 4
        if not zk:
            continue
        z = np.concatenate(zk)
        per[name] = {"max_abs_z": float(np.max(np.abs(z))), "max_abs_error": float(np.max(np.concatenate(ek)))}
        zs.append(z)
    allz = np.abs(np.concatenate(zs)) if zs else np.zeros(0)
    # the points of one curve are strongly correlated: count about four independent checks per element and piece
    limit = family_z_limit(n_checks)
    return {
        "model": model or "default", "reference": what, "elements": per,
        "max_abs_z": float(allz.max()) if allz.size else 0.0,
        "rms_z": float(np.sqrt(np.mean(allz**2))) if allz.size else 0.0,
        "fraction_within_1sigma": float(np.mean(allz <= 1.0)) if allz.size else 1.0,
        "fraction_within_2sigma": float(np.mean(allz <= 2.0)) if allz.size else 1.0,
        "points": int(allz.size), "family_limit": limit,
        "consistent": bool(allz.size == 0 or allz.max() <= limit),
    }


__all__ = ["truth_path", "truth_check"]
