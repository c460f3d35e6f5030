"""What the residuals of a calibrated stage say: their series, whiteness, relation to the drivers, size.

- :func:`factor_residuals`: the factor graph's residual series per factor kind, from the factors;
- :func:`filter_innovations`: the square-root filter's normalised innovations per kind;
- :func:`ljung_box`, :func:`regression_tests`: whiteness, and the (descriptive) relation of
  each component to the drivers' keyframe means (:func:`~graph_calib.diagnosis.drivers.keyframe_context`);
- :func:`residual_statistics`, :func:`residual_rms`: the figures of a
  :class:`~graph_calib.diagnosis.rounds.Stage` that ``diagnosis.json`` holds;
- :func:`error_against_truth`: the error of a result against a simulator's truth.
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtrc

from graph_calib.sensors import effects
from graph_calib.diagnosis.drivers import keyframe_context
from graph_calib.model.residual_list import FACTOR_KINDS, residual_list, series_rms, weighted_components


def factor_residuals(model, R, x, *, pre=None, factors=None):
    """Per kind: time, keyframe, SI and whitened residuals at ``(R, x)``; gravity also in body axes.

    Parameters
    ----------
    model : graph_calib.model.CalibrationModel
    R : ndarray (K+1, 3, 3)
        Attitudes ``C_nb`` at the keyframe boundaries.
    x : ndarray (P,)
        Calibration in ``model.layout``.
    pre : graph_calib.model.preintegration.Preintegrated, optional
        ``model.preintegrate(x)`` when the caller has it already.
    factors : dict, optional
        ``{kind: Residuals}`` at ``(R, x)`` when the caller has them already (their Jacobians are
        not used; :attr:`graph_calib.diagnosis.reduced_system.ReducedSystem.factors`).

    Returns
    -------
    dict
        ``{kind: {"t", "key", "r", "w"}}`` with ``r``, ``w`` of shape (F, 3); gravity also
        ``"r_body"``, ``"w_body"`` and the keyframes' ``"static"`` flags.
    """
    if factors is None:
        if pre is None:
            pre = model.preintegrate(x)
        factors = residual_list(model, R, pre, x)
    out = {}
    for k in FACTOR_KINDS:
        kind, res, t = k.name, factors[k.name], k.times(model)
        if not k.listed(res):
            continue                     # a kind this model does not have (no still factors asked for)
        w = res.whitened()
        d = {"t": np.asarray(t, dtype=float), "key": res.key.copy(), "r": res.r.copy(), "w": w}
        if kind == "gravity":
            Rk = R[: model.n_keyframes]
            r_b = np.einsum("kji,kj->ki", Rk, res.r)
            sig_v = res.sigma[:, 2]
            d["r_body"] = r_b
            d["w_body"] = r_b / sig_v[:, None]
            d["static"] = model.record.static_key.copy()
        out[kind] = d
    return out


def filter_innovations(output, model):
    """Filter innovations per kind as ``{"t", "key", "w" (F, 3)}`` from the filter's output.

    Parameters
    ----------
    output : graph_calib.solvers.interface.SolverOutput
        The square-root filter's output (normalised innovations).
    model : graph_calib.model.CalibrationModel
        Its keyframes give each innovation's ``key``.
    """
    out = {}
    for name, series in output.residuals.items():
        tt = np.asarray(series.t, dtype=float)
        key = np.clip(np.searchsorted(model.t_key, tt, side="right") - 1, 0, model.n_keyframes - 1)
        out[name] = {"t": tt, "key": key, "w": np.asarray(series.values)}
    return out


def ljung_box(y, lags=10):
    """Ljung-Box statistic of ``y`` (columns separately) and its chi-square p-values."""
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    n = y.shape[0]
    h = int(min(lags, max(1, n // 5)))
    if n < 10:
        return np.zeros(y.shape[1]), np.ones(y.shape[1]), h
    yc = y - y.mean(axis=0)
    den = np.sum(yc**2, axis=0)
    den = np.where(den > 0, den, 1.0)
    Q = np.zeros(y.shape[1])
    for k in range(1, h + 1):
        rho = np.sum(yc[k:] * yc[:-k], axis=0) / den
        Q += rho**2 / (n - k)
    Q *= n * (n + 2)
    return Q, chdtrc(h, Q), h                # scipy.stats.chi2.sf



def _regressors(ctx, group, key):
    c = ctx[group][key]
    if group == "time":
        u = c / max(float(np.max(ctx["time"])), 1e-9)
        return np.column_stack([u, u**2, u**3])
    if group == "temperature":
        m = c.mean(axis=1)
        return np.column_stack([m, m**2])
    if group == "temperature_rate":
        return c.mean(axis=1)[:, None]
    return c.reshape(c.shape[0], -1)


def regression_tests(series, ctx, *, key, static=None):
    """F-tests of each component of ``series`` (F, 3) on each driver group's keyframe means.

    Descriptive: successive residuals are not independent, so the p-values are
    optimistic; the loop decides with the score tests, not with these.

    Returns
    -------
    list of dict
        ``{"driver", "component", "F", "df", "log10_p", "r2"}`` sorted by ``log10_p``.
    """
    out = []
    y_all = np.asarray(series, dtype=float)
    sel = np.ones(y_all.shape[0], dtype=bool) if static is None else np.asarray(static, dtype=bool)
    y_all = y_all[sel]
    key = np.asarray(key)[sel]
    n = y_all.shape[0]
    if n < 20:
        return out
    from scipy import stats        # loaded when used (calibrate's structure tests need none of it)

    for group in ctx:
        X = _regressors(ctx, group, key)
        X = X[:, np.std(X, axis=0) > 0]
        if X.shape[1] == 0:
            continue
        Xc = np.column_stack([np.ones(n), X])
        q = X.shape[1]
        for comp in range(y_all.shape[1]):
            y = y_all[:, comp]
            coef, *_ = np.linalg.lstsq(Xc, y, rcond=None)
            rss1 = float(np.sum((y - Xc @ coef) ** 2))
            rss0 = float(np.sum((y - y.mean()) ** 2))
            if rss0 <= 0 or n - q - 1 <= 0:
                continue
            F = ((rss0 - rss1) / q) / max(rss1 / (n - q - 1), 1e-300)
            lp = stats.f.logsf(F, q, n - q - 1) / np.log(10.0)
            out.append({"driver": group, "component": comp, "F": float(F), "df": [q, n - q - 1],
                        "log10_p": float(lp) if np.isfinite(lp) else -300.0, "r2": 1.0 - rss1 / rss0})
    out.sort(key=lambda d: d["log10_p"])
    return out


#: What the three components of each series are.  An encoder residual is turned into the principal axes of its
#: reading's noise (graph_calib.model.encoder_noise): body x, y, z where the declared isotropic noise holds
#: (readings in motion), the scatter's axes ordered and signed nearest them in a static dwell.
_COMPONENTS = {**{k.name: k.components for k in FACTOR_KINDS}, "gravity_body": "xyz (body)"}


def residual_statistics(stage, *, top=5, lags=10, context=None):
    """Whiteness and driver relations of the residuals of every solver of the stage.

    Parameters
    ----------
    stage : graph_calib.diagnosis.rounds.Stage
        Its ``residuals`` and ``innovations`` (and its problem's model, for the drivers).
    top : int
        Driver regressions kept per series (the most significant).
    lags : int
        Lags of the Ljung-Box statistic.
    context : dict, optional
        :func:`~graph_calib.diagnosis.drivers.keyframe_context` of the stage's record when the caller has
        it already (it depends on the record only).

    Returns
    -------
    dict
        ``{solver: {series: {"count", "components", "rms", "ljung_box": {"lags", "Q", "p"},
        "drivers": [top driver regressions]}}}``.
    """
    model = stage.problem.model
    ctx = keyframe_context(model) if context is None else context
    out = {}

    def one(w, key, components, static=None):
        Q, p, h = ljung_box(w, lags)
        return {"count": int(w.shape[0]), "components": components,
                "rms": np.sqrt(np.mean(w**2, axis=0)).tolist(),
                "ljung_box": {"lags": h, "Q": Q.tolist(), "p": p.tolist()},
                "drivers": regression_tests(w, ctx, key=key, static=static)[:top]}

    fg = {}
    for kind, d in stage.residuals.items():
        if d["w"].shape[0] == 0:
            continue
        fg[kind] = one(d["w"], d["key"], _COMPONENTS[kind])
        if kind == "gravity":
            fg["gravity_body"] = one(d["w_body"], d["key"], _COMPONENTS["gravity_body"], static=d["static"])
    out[stage.primary] = fg
    for solver, series in stage.innovations.items():
        out[solver] = {kind: one(d["w"], d["key"], _COMPONENTS[kind]) for kind, d in series.items()}
    return out


def residual_rms(stage):
    """``{solver: {kind: [rms of the whitened residuals per component]}}`` plus SI figures.

    ``stage`` is a :class:`~graph_calib.diagnosis.rounds.Stage`; the primary solver's entry also has
    ``"overall"`` and ``"si"`` (RMS in SI per kind; gravity over the static keyframes only).
    """
    out = {}
    if stage.residuals:
        fg = {k: series_rms(k, v["w"])[0] for k, v in stage.residuals.items() if v["w"].size}
        fg["overall"] = float(np.sqrt(np.mean(np.concatenate([v["w"][weighted_components(k, v["w"])]
                                                              for k, v in stage.residuals.items()]) ** 2)))
        si = {}
        for k, v in stage.residuals.items():
            if v["r"].size:
                unit = "m/s^2" if k == "gravity" else "rad"
                sel = v.get("static")
                r = v["r"] if sel is None else v["r"][sel]
                si[k] = {"rms": np.sqrt(np.mean(r**2, axis=0)).tolist(), "unit": unit}
        fg["si"] = si
        out[stage.primary] = fg
    for solver, series in stage.innovations.items():
        if not series:
            continue
        kf = {k: series_rms(k, v["w"])[0] for k, v in series.items()}
        kf["overall"] = float(np.sqrt(np.mean(np.concatenate([v["w"][weighted_components(k, v["w"])]
                                                              for k, v in series.items()]) ** 2)))
        out[solver] = kf
    return out


def error_against_truth(result, truth, *, names=None, sigmas=None):
    """Error of ``result`` against a truth :class:`~graph_calib.records.experiment.Result`.

    Over the declared parameters both hold (or ``names``): per element
    ``z = (estimate - truth) / sigma`` (the result's own sigma, or ``sigmas``: e.g. the
    declared model's, to compare two results on one scale) and the error in prior
    sigmas of the result's grade.

    Returns
    -------
    dict
        ``rms_z``, ``max_abs_z`` and ``worst`` (element), ``rms_prior`` (error in prior
        sigmas, RMS), ``groups`` ``{parameter: {"rms_z", "rms_abs", "report_unit"}}``.
    """
    names = effects.DECLARED if names is None else names
    sigmas = result.sigmas if sigmas is None else sigmas
    priors = result.extra.get("priors", {}) if result.extra else {}
    z, zp, groups = [], [], {}
    worst, wz = None, 0.0
    for n in names:
        spec = effects.effect(n)
        els = [e for e in spec.element_names() if e in result.values and e in truth.values]
        if not els:
            continue
        err = np.array([result.values[e] - truth.values[e] for e in els])
        sig = np.array([sigmas[e] for e in els])
        zz = err / np.where(sig > 0, sig, np.inf)
        z.extend(zz.tolist())
        if n in priors:
            ps = np.atleast_1d(np.asarray(priors[n], dtype=float))
            ps = np.broadcast_to(ps, err.shape) if ps.size in (1, err.size) else np.full(err.shape, np.nan)
            zp.extend((err / ps).tolist())
        groups[n] = {"rms_z": float(np.sqrt(np.mean(zz**2))),
                     "rms_abs": float(np.sqrt(np.mean(err**2)) * spec.to_report),
                     "report_unit": spec.report_unit}
        i = int(np.argmax(np.abs(zz)))
        if abs(zz[i]) > wz:
            wz, worst = float(abs(zz[i])), els[i]
    z = np.asarray(z)
    zp = np.asarray(zp)
    return {"rms_z": float(np.sqrt(np.mean(z**2))) if z.size else 0.0, "max_abs_z": wz, "worst": worst,
            "rms_prior": float(np.sqrt(np.nanmean(zp**2))) if zp.size else None, "n": int(z.size),
            "groups": groups}

