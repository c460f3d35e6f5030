"""Calibrating one experiment: the model set up once, either solver, results and comparison.

This is the public Python API behind ``graph-calib calibrate``::

    from graph_calib.calibrate import CalibrationOptions, calibrate
    results = calibrate(experiment, options=CalibrationOptions(grade="navigation"))
    results["factor-graph"].values["gyro.bias.x"]
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from graph_calib.alignment import alignment
from graph_calib.experiment import Result
from graph_calib.factor_graph import GraphOptions
from graph_calib.model import CalibrationModel, ModelOptions, gyrocompass_attitude_sigma
from graph_calib.params import grade
from graph_calib.static_detection import detect_static

SOLVERS = ("sqrt-kf", "factor-graph")


@dataclass(frozen=True)
class CalibrationOptions:
    """Everything that decides a calibration besides the data.

    Attributes
    ----------
    model : ModelOptions
        Keyframes, grade, effects, priors, noise.
    graph : GraphOptions
        Levenberg-Marquardt options of the factor graph.
    kf_max_passes : int
        Passes of the iterated square-root filter.
    t_ref_degC : float or None
        Reference temperature; None for the mean sensor temperature.
    """

    model: ModelOptions = field(default_factory=ModelOptions)
    graph: GraphOptions = field(default_factory=GraphOptions)
    kf_max_passes: int = 500
    t_ref_degC: float | None = None


@dataclass(frozen=True)
class Problem:
    """A calibration model with its initial attitude, ready for either solver."""

    model: CalibrationModel
    q_nb0: np.ndarray
    alignment: object


def build_problem(experiment, *, options=CalibrationOptions()):
    """Set up the shared model of ``experiment`` and align it.

    Without a table, gravity measurements count only where the IMU is static
    (``ModelOptions.moving_sigma`` then defaults to 1 m/s^2 for moving keyframes).
    """
    mopt = options.model
    static = detect_static(experiment)
    static_mask = None
    if experiment.table is None:
        static_mask = np.zeros(experiment.n_samples, dtype=bool)
        for a, b in static:
            static_mask[a:b] = True
        if mopt.moving_sigma is None:
            mopt = replace(mopt, moving_sigma=1.0)
    interval = tuple(static[0]) if len(static) else None
    if interval is not None:
        mopt = _noise_from_static(experiment, interval, mopt)
    method = "table" if (experiment.table is not None and np.any(experiment.table.valid)) else "gyrocompass"
    try:
        al = alignment(experiment, interval=interval, method=method)
    except Exception:
        if method != "table":
            raise
        al = alignment(experiment, interval=interval, method="gyrocompass")
        if mopt.initial_attitude_sigma is None:
            # the table could not give the attitude: the prior is as loose as gyrocompassing is
            mopt = replace(mopt, initial_attitude_sigma=gyrocompass_attitude_sigma(
                mopt, latitude_rad=experiment.latitude_rad))
    model = CalibrationModel(experiment, options=mopt, t_ref_degC=options.t_ref_degC, static_mask=static_mask)
    return Problem(model=model, q_nb0=al.q_nb0, alignment=al)


def _noise_from_static(experiment, interval, mopt):
    """White-noise densities: the grade's, raised to what the first static interval shows.

    The density is the per-sample standard deviation of the rate (force) times
    ``sqrt(dt)``, averaged over the axes.  Options set explicitly are kept.  The
    grade's value is a floor, so noise-free data keep a sensible weighting.
    """
    a, b = int(interval[0]), int(interval[1])
    if b - a < 50:
        return mopt
    g = grade(mopt.grade)
    dt = experiment.dt[a:b, None]
    w = experiment.dtheta[a:b] / dt
    f = experiment.dv[a:b] / dt
    h = float(np.median(dt))
    est_g = float(np.sqrt(np.mean(np.var(w, axis=0)) * h))
    est_a = float(np.sqrt(np.mean(np.var(f, axis=0)) * h))
    return replace(
        mopt,
        gyro_noise=mopt.gyro_noise if mopt.gyro_noise is not None else max(g.gyro_noise, est_g),
        accel_noise=mopt.accel_noise if mopt.accel_noise is not None else max(g.accel_noise, est_a),
    )


def to_result(*, model, x, covariance, solver, residuals, extra=None):
    """A :class:`graph_calib.experiment.Result` from an estimate and its covariance."""
    names = model.layout.element_names()
    sig = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    T = model.temperatures
    ex = {"priors": model.priors_used(), "keyframe_s": model.options.keyframe_s, "grade": model.options.grade,
          "noise": {"gyro_rad_per_sqrt_s": model.gyro_noise, "accel_mps_per_sqrt_s": model.accel_noise,
                    "encoder_rad": model.encoder_noise}}
    ex.update(extra or {})
    return Result(
        source=model.experiment.source.rsplit("/", 1)[-1] if model.experiment.source else "",
        solver=solver, t_ref_degC=model.t_ref_degC,
        temperature_range_degC=(float(T.min()), float(T.max())),
        effects=tuple(model.layout.names),
        values=dict(zip(names, np.asarray(x, dtype=float).tolist())),
        sigmas=dict(zip(names, sig.tolist())),
        covariance_names=tuple(names), covariance=np.asarray(covariance, dtype=float),
        residuals=residuals, extra=ex,
    )


def _residual_stats(series):
    out = {}
    for kind, (t, w) in series.items():
        w = np.asarray(w)
        if w.size == 0:
            continue
        out[kind] = {"count": int(w.shape[0]), "rms_whitened": np.sqrt(np.mean(w**2, axis=0)).tolist(),
                     "chi2_per_dof": float(np.mean(w**2))}
    return out


def run_factor_graph(problem, *, options=CalibrationOptions(), progress=None):
    """Solve ``problem`` with the factor graph; returns ``(Result, GraphResult)``."""
    from graph_calib import factor_graph

    gr = factor_graph.solve(problem.model, q_nb0=problem.q_nb0, options=options.graph, progress=progress)
    stats = _residual_stats(gr.residuals)
    stats.update({"iterations": gr.iterations, "converged": bool(gr.converged),
                  "final_cost": float(gr.cost_history[-1]), "seconds": gr.seconds})
    res = to_result(model=problem.model, x=gr.x, covariance=gr.covariance, solver="factor-graph", residuals=stats)
    return res, gr


def run_sqrt_kf(problem, *, options=CalibrationOptions(), progress=None):
    """Solve ``problem`` with the reference square-root filter; returns ``(Result, FilterResult)``."""
    import kf_reference

    fr = kf_reference.calibrate(problem.model, q_nb0=problem.q_nb0, max_passes=options.kf_max_passes,
                                progress=progress)
    return kf_reference.to_result(fr, problem.model), fr


def calibrate(experiment, *, options=CalibrationOptions(), solvers=SOLVERS):
    """Calibrate ``experiment`` with each of ``solvers``; ``{solver: Result}``."""
    problem = build_problem(experiment, options=options)
    out = {}
    for s in solvers:
        if s == "factor-graph":
            out[s] = run_factor_graph(problem, options=options)[0]
        elif s == "sqrt-kf":
            out[s] = run_sqrt_kf(problem, options=options)[0]
        else:
            raise ValueError(f"unknown solver {s!r}; known: {', '.join(SOLVERS)}")
    return out


def sigma_ratio_range_text(summary):
    """``"lo..hi"`` of a comparison summary's sigma-ratio range (``inf`` where a ratio has no value)."""
    lo, hi = summary["sigma_ratio_range"]
    return f"{lo:.3f}..{'inf' if hi is None else f'{hi:.3f}'}"


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
            "agree": bool(diffs.size == 0 or (diffs.max() <= 0.1 and ratios.min() >= 0.9 and ratios.max() <= 1.1)),
        },
        "parameters": rows,
    }
