"""The truth check of a campaign: the stitched curves against a simulator's truth file.

- :func:`truth_path`: ``<stem>.truth.json`` next to an experiment file (the simulator's convention);
- :func:`truth_check`: how the stitched curves sit against the truth, inside each element's covered
  range (``campaign.json``'s ``truth_check``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from graph_calib.stitching import family_z_limit
from graph_calib.validation import ResultCalibration


def truth_path(experiment_file):
    """``<stem>.truth.json`` next to an experiment file (the simulator's convention)."""
    p = Path(experiment_file)
    return p.with_name(p.stem + ".truth.json")


def truth_check(stitched, truth, *, model=None, n=61):
    """How the stitched curves sit against the truth, inside each element's covered range.

    Parameters
    ----------
    stitched : graph_calib.stitching.Stitched
    truth : graph_calib.experiment.Result
        A truth file's result; or anything with ``evaluate(T_sensors)`` giving ``{element: values}``
        (a :class:`graph_calib.validation.ResultCalibration`, another stitch).
    model : str, optional
        The stitched model, ``"cubic"`` or ``"linear"``; the default model when None.
    n : int
        Temperatures per element.

    Returns
    -------
    dict
        Per element ``{"max_abs_z", "max_abs_error"}`` (z: error over the stitched
        one-sigma band, on ``n`` temperatures across the covered range) and overall
        ``max_abs_z``, ``fraction_within_1sigma`` (about 0.68 for honest bands),
        ``fraction_within_2sigma`` and ``consistent``: the largest ``|z|`` below the
        1 % family-wise limit for four independent checks per element
        (:func:`graph_calib.stitching.family_z_limit`).
    """
    ref = truth if hasattr(truth, "evaluate") else ResultCalibration(truth)
    per, zs = {}, []
    for name, cv in stitched.curves.items():
        lo, hi = cv.t_span
        T = np.linspace(lo, hi, n)
        tv = ref.evaluate(np.tile(T[:, None], (1, 6))).get(name)
        if tv is None:
            continue
        v, s = cv.evaluate(T, model)
        z = np.where(s > 0, (v - tv) / np.where(s > 0, s, 1.0), 0.0)
        per[name] = {"max_abs_z": float(np.max(np.abs(z))), "max_abs_error": float(np.max(np.abs(v - tv)))}
        zs.append(z)
    allz = np.abs(np.concatenate(zs)) if zs else np.zeros(0)
    # the points of one curve are strongly correlated: count about four independent checks per element
    limit = family_z_limit(4 * len(per))
    return {
        "model": model or "default", "elements": per, "max_abs_z": float(allz.max()) if allz.size else 0.0,
        "fraction_within_1sigma": float(np.mean(allz <= 1.0)) if allz.size else 1.0,
        "fraction_within_2sigma": float(np.mean(allz <= 2.0)) if allz.size else 1.0,
        "family_limit": limit,
        "consistent": bool(allz.size == 0 or allz.max() <= limit),
    }


__all__ = ["truth_path", "truth_check"]
