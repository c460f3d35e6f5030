"""Result assembly, the same for every solver: the result file, its ``residuals`` block, comparisons.

:func:`to_result` turns a :class:`graph_calib.solvers.interface.SolverOutput` into the result layout of
``data-format.md`` (:class:`graph_calib.records.experiment.Result`); :func:`residual_block` is its
``residuals`` block, one layout for every solver; :func:`compare` is ``comparison.json``.
"""

from __future__ import annotations

import numpy as np

from graph_calib.model.residual_list import MEASUREMENT_KINDS, series_rms, weighted_components
from graph_calib.model.redundancy import FLOORED, MOVING, PSEUDO_KINDS, fit_statistics, static_gravity
from graph_calib.records.experiment import Result


def residual_block(output, *, statistics=None):
    """The ``residuals`` block of a result file: the fit statistics, one layout for all solvers.

    Parameters
    ----------
    output : graph_calib.solvers.interface.SolverOutput
    statistics : graph_calib.model.redundancy.FitStatistics, optional
        The model's statistics at the solution (:func:`graph_calib.model.redundancy.fit_statistics`).

    Returns
    -------
    dict
        ``quantity`` (whitened residual or normalised innovation); per kind in ``kinds`` (data-format.md):
        ``count``, ``chi2``, ``redundancy``, ``chi2_per_redundancy`` (from ``statistics``: the same figure
        for every solver at the same solution), the variance factor the solve used
        (``variance_factor``, 1 unless estimated or set), and the solver's own ``rms_axis`` (rms of each
        normalised component of its series) and ``rms``; ``counts`` (factors per kind);
        ``chi2_per_dof`` over every measurement component of the solver's series (kept for old readers);
        ``n_unknowns`` and ``hat_trace``; ``iterations``, ``converged``, ``final_cost``, ``seconds``; and
        the solver's own ``figures``.
    """
    kinds = {}
    measured = []
    for kind, series in output.residuals.items():
        v = np.asarray(series.values, dtype=float)
        if v.size == 0:
            continue
        # a kind's weightless components (exact zeros in its series) are no measurement: left out of its RMS
        per_axis, rms = series_rms(kind, v)
        kinds[kind] = {"count": int(v.shape[0]), "rms_axis": per_axis, "rms": rms}
        if kind in MEASUREMENT_KINDS:
            measured.append(v[weighted_components(kind, v)])
    if statistics is not None:
        for kind, fit in statistics.kinds.items():
            if kind in PSEUDO_KINDS:            # a part of a kind: inside it (below)
                continue
            kinds[kind] = {**kinds.get(kind, {}), **fit.to_json()}
        if MOVING in statistics.kinds and "gravity" in kinds:
            kinds["gravity"]["moving"] = statistics.kinds[MOVING].to_json()
            kinds["gravity"]["static"] = static_gravity(statistics.kinds).to_json()
        if FLOORED in statistics.kinds and "encoder" in kinds:
            kinds["encoder"]["floored"] = statistics.kinds[FLOORED].to_json()
    all_measured = np.concatenate(measured) if measured else np.zeros(0)
    block = {
        "quantity": output.residual_quantity,
        "kinds": kinds,
        "counts": {k: v["count"] for k, v in kinds.items()},
        "chi2_per_dof": float(np.mean(all_measured**2)) if all_measured.size else 0.0,
        "iterations": int(output.iterations),
        "converged": bool(output.converged),
        "final_cost": float(output.final_cost),
        "seconds": float(output.seconds),
    }
    if statistics is not None:
        block["n_unknowns"] = int(statistics.n_unknowns)
        block["hat_trace"] = float(statistics.trace)
    block.update({k: float(v) for k, v in output.figures.items()})
    return block


def noise_block(model):
    """The result's ``noise`` block (data-format.md): the densities the solve used and where each came from.

    ``gyro_rad_per_sqrt_s``, ``accel_mps_per_sqrt_s``, ``encoder_rad``, ``sway_mps2``; ``guided_turns`` (count and
    protocol sigma, rad) where the record's full turns are the Ferraris protocol's; the rate random walks
    ``gyro_random_walk_rad_per_s_per_sqrt_s`` and ``accel_random_walk_mps2_per_sqrt_s`` where the rests support
    them; ``source`` per sensor
    (``identified`` from the record, ``declared`` by the user, or the ``grade``'s); and, where the record
    showed them, ``identified``: per sensor the IEEE terms with their sigmas and the channels that support
    them, the keyframe density with its sigma and the rest time behind it (docs/model.md, "Noise from the
    record").
    """
    o = model.options
    sway = o.sway_sigma
    src = {"gyro": "grade", "accel": "grade", "encoder": "grade"}
    for k in src:
        if getattr(o, f"{k}_noise") is not None:
            src[k] = "declared"
    src.update(o.noise_source or {})
    out = {"gyro_rad_per_sqrt_s": model.gyro_noise, "accel_mps_per_sqrt_s": model.accel_noise,
           "encoder_rad": model.encoder_noise, "sway_mps2": float(sway) if isinstance(sway, (int, float)) else 0.0,
           "source": src}
    if model.turns.size:
        # the guided full turns used as the Ferraris protocol's (graph_calib.model.guided_turns): their count and the
        # protocol's sigma before the turn kind's variance factor
        out["guided_turns"] = {"count": int(model.turns.shape[0]), "sigma_rad": float(model.turn_sigma)}
    if model.gyro_quantization:
        # the gyros' angle quantization (IEEE Q) the encoder and gravity factors carry (docs/model.md)
        out["gyro_quantization_rad"] = model.gyro_quantization
    if o.noise_identified:
        out["identified"] = o.noise_identified
        # the rate random walks where the rests support them (the bias's random walk of Kalibr's and OpenVINS's
        # files): the IEEE term's RMS over the channels, rad/s/sqrt(s) and m/s^2/sqrt(s)
        for sensor, key in (("gyro", "gyro_random_walk_rad_per_s_per_sqrt_s"),
                            ("accel", "accel_random_walk_mps2_per_sqrt_s")):
            term = (o.noise_identified.get(sensor) or {}).get("rate_random_walk")
            if term and term.get("supported"):
                out[key] = float(term["value"])
    return out


#: An element whose posterior sigma is above this fraction of its prior sigma is prior-dominated: the data
#: bring less than half its information (``(sigma / prior)^2 > 1/2``), so its estimate is mostly the prior's.
PRIOR_DOMINATED_RATIO = 0.7


def prior_dominated(model, output):
    """``{element: posterior sigma / prior sigma}`` of the elements the data barely inform.

    Those above :data:`PRIOR_DOMINATED_RATIO`, in layout order: a result lists them (``prior_dominated``)
    so that a sigma that is the prior's is not read as a measured one.
    """
    _, prior = model.prior()
    sig = np.asarray(output.sigma, dtype=float)
    ratio = sig / prior
    names = output.layout.element_names()
    return {n: float(r) for n, r in zip(names, ratio) if r > PRIOR_DOMINATED_RATIO}


def to_result(model, output, *, extra=None):
    """The :class:`graph_calib.records.experiment.Result` of a solver's output.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
        The model the solver calibrated (data, layout, priors, noise).
    output : graph_calib.solvers.interface.SolverOutput
    extra : dict, optional
        Further top-level keys for the result file.
    """
    names = output.layout.element_names()
    sig = output.sigma
    T = model.temperatures
    ex = {"priors": model.priors_used(), "keyframe_s": model.options.keyframe_s, "grade": model.options.grade,
          "prior_dominated": prior_dominated(model, output),
          "imu_id": model.experiment.imu_id,
          "noise": noise_block(model)}
    if model.options.grade_choice:     # chosen from the record's rests (no grade given)
        ex["grade_choice"] = dict(model.options.grade_choice)
    if model.options.prior_mean:    # only then (a prior mean other than zero: the campaign's joint curvature)
        ex["prior_means"] = {n: np.atleast_1d(np.asarray(v, dtype=float)).tolist()
                             for n, v in model.options.prior_mean.items() if n in model.layout}
    unresolved, U = model.unresolved_directions(output.x)
    if unresolved:      # only then, so that every other result file stays as it was
        ex["unresolved"] = {name: {n: float(v) for n, v in zip(names, u) if v != 0.0}
                            for name, u in zip(unresolved, U)}
    ex.update(extra or {})
    statistics = fit_statistics(model, output.attitudes, output.x)
    factors = dict(model.options.variance_factors or {})
    residuals = residual_block(output, statistics=statistics)
    for kind, entry in residuals["kinds"].items():
        if kind in statistics.kinds:
            entry["variance_factor"] = float(factors.get(kind, 1.0))
    if "floored" in residuals["kinds"].get("encoder", {}):
        residuals["kinds"]["encoder"]["floored"]["variance_factor"] = float(factors.get(FLOORED, 1.0))
    residuals["variance_components"] = bool(factors)
    if model.options.moving_sigma is not None and "gravity" in residuals["kinds"]:
        residuals["kinds"]["gravity"]["moving_sigma_mps2"] = float(model.options.moving_sigma)
    return Result(
        source=model.experiment.source.rsplit("/", 1)[-1] if model.experiment.source else "",
        solver=output.solver, t_ref_degC=model.t_ref_degC,
        temperature_range_degC=(float(T.min()), float(T.max())),
        effects=tuple(output.layout.names),
        values=dict(zip(names, np.asarray(output.x, dtype=float).tolist())),
        sigmas=dict(zip(names, sig.tolist())),
        covariance_names=tuple(names), covariance=np.asarray(output.covariance, dtype=float),
        residuals=residuals, extra=ex,
    )


def sigma_ratio_range_text(summary):
    """``"lo..hi"`` of a comparison summary's sigma-ratio range (``inf`` where a ratio has no value)."""
    lo, hi = summary["sigma_ratio_range"]
    return f"{lo:.3f}..{'inf' if hi is None else f'{hi:.3f}'}"


def comparison_text(summary):
    """One line of a comparison summary: largest difference and sigma-ratio range."""
    return (f"max |difference| {summary['max_abs_difference_in_sigma']:.3f} sigma, sigma ratio "
            f"{sigma_ratio_range_text(summary)}")


#: Two solvers agree when no estimate differs by more than this many sigmas ...
AGREE_DIFFERENCE_SIGMA = 0.1
#: ... and every sigma ratio lies within these bounds.
AGREE_SIGMA_RATIO = (0.9, 1.1)


def compare(a, b):
    """Parameter-by-parameter comparison of two results (``comparison.json``).

    For every element both estimate: the two values and sigmas, the difference
    in units of the larger sigma and the sigma ratio ``sigma_b / sigma_a``.
    """
    rows = {}
    for name in a.values:
        if name not in b.values:
            continue
        sa, sb = a.sigmas[name], b.sigmas[name]
        big = max(sa, sb)
        rows[name] = {
            a.solver: {"value": a.values[name], "sigma": sa},
            b.solver: {"value": b.values[name], "sigma": sb},
            "difference_in_sigma": (b.values[name] - a.values[name]) / big if big > 0 else 0.0,
            # None (JSON null) where the first solver reports a zero sigma and the second does not
            "sigma_ratio": sb / sa if sa > 0 else (1.0 if sb == 0 else None),
        }
    diffs = np.array([abs(r["difference_in_sigma"]) for r in rows.values()]) if rows else np.zeros(0)
    ratios = np.array([np.inf if r["sigma_ratio"] is None else r["sigma_ratio"] for r in rows.values()])
    lo, hi = AGREE_SIGMA_RATIO
    return {
        "format": "imu-calibration-comparison",
        "version": 1,
        "source": a.source,
        "solvers": [a.solver, b.solver],
        "summary": {
            "parameters": len(rows),
            "max_abs_difference_in_sigma": float(diffs.max()) if diffs.size else 0.0,
            "sigma_ratio_range": ([float(ratios.min()), float(ratios.max()) if np.isfinite(ratios.max()) else None]
                                  if ratios.size else [1.0, 1.0]),
            "agree": bool(diffs.size == 0 or (diffs.max() <= AGREE_DIFFERENCE_SIGMA and ratios.min() >= lo
                                              and ratios.max() <= hi)),
        },
        "parameters": rows,
    }


__all__ = ["residual_block", "noise_block", "to_result", "compare", "sigma_ratio_range_text", "comparison_text",
           "AGREE_DIFFERENCE_SIGMA", "AGREE_SIGMA_RATIO"]
