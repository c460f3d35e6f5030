r"""Method comparison: campaign procedures on predicted accuracy against campaign duration.

For every procedure (:mod:`graph_calib.design.procedures`) and every recorded length per experiment:

1. **Noise.**  The base experiment's bench program is set up without noise or sensor errors exactly as
   for a calibration and its covariance predicted from the shared model's Fisher information
   (:func:`graph_calib.design.prediction.predict`; ``*_tc`` left out for constant-temperature steps).
   Each experiment of the campaign is that prediction at its own temperatures (one shift of the base
   program's).  The predictions are stitched as the campaign stitches its results
   (:func:`graph_calib.stitching.stitch`, the cubic over temperature, each element at its own sensor's
   temperature), and the stitched curve's one sigma evaluated over the whole range ``range_degC``.
2. **Model error.**  Truth curves are drawn from a stated family (:class:`TruthFamily`: a slope, a
   quadratic and a cubic term in every bias and scale factor of both triads, each sensor's element in
   its own sensor's temperature).  What each experiment's model makes of a curve is its least-squares
   projection over the experiment's sensor temperatures (samples weighted evenly): a constant for a step
   (its value at the sensor's mean temperature), value and slope about ``T_ref`` for a ramp.  Those
   values are stitched like the estimates and compared with the curve over the range: the error the
   procedure's temperature model leaves with no noise at all.
3. **Metrics** per family (``gyro.bias``, ``accel.bias``, ``gyro.scale``, ``accel.scale``; the largest of
   the three axes): the largest one sigma over the range (``largest_sigma``), the RMS sigma over range
   and axes (``rms_sigma``), the largest model error over the range (mean over truth draws), the largest
   of the total (``sqrt(sigma^2 + model error^2)``), and the expected largest error
   ``E max_T |noise + model error|`` (noise drawn from the stitched covariance).
4. **Equal-accuracy ratios**: for every campaign of the reference procedure (the first), the duration the
   other procedure needs for the same metric (log-log interpolation between its campaigns), divided by
   the reference campaign's duration; for every soak time asked (the soak changes the duration of a step
   campaign, not its accuracy).

Nothing here runs a solver; :mod:`graph_calib.design.comparison_check` confirms the noise part with
simulated calibrations.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from graph_calib import constants as c
from graph_calib.design.prediction import predict, prediction_result
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.simulation.program import nominal_experiment
from graph_calib.sensors.params import DEFAULT_GRADE
from graph_calib.stitching import stitch
from graph_calib.stitching.pieces import sensor_of

#: The temperature-dependent families compared, and the coefficient each experiment may estimate.
FAMILIES = ("gyro.bias", "accel.bias", "gyro.scale", "accel.scale")
_TC = {f: f"{f}_tc" for f in FAMILIES}
AXES = "xyz"

#: Metrics of a campaign (per family) and those the equal-accuracy ratios are given for.
METRICS = ("largest_sigma", "rms_sigma", "model_error_largest", "largest_total", "expected_largest")

#: IMU sample rate of the predicted records, Hz.  The information per keyframe is set by the noise densities,
#: not the sample rate: at 20 Hz every bias, scale-factor and temperature-coefficient sigma of a 30 min step
#: or ramp is within 0.02 % of its 100 Hz value (every element within 0.7 %, the lever arm the furthest),
#: for a third of the time; at 10 Hz every compared metric (largest and RMS sigma, model error) is within
#: 0.1 % of its 20 Hz value (steps 0.25 h 0.07 %, ramps 0.25 h 0.09 %, 1 h 0.03 %) for 0.7 of the time.
PREDICTION_RATE_HZ = 10.0

#: Display unit per family: (factor from SI, unit name).
DISPLAY = {"gyro.bias": (c.RS_TO_DH, "deg/h"), "accel.bias": (1.0 / c.UG_TO_MPS2, "micro-g"),
           "gyro.scale": (1e6, "ppm"), "accel.scale": (1e6, "ppm")}


@dataclass(frozen=True)
class TruthFamily:
    r"""The stated family of truth curves: per element, over the sensor's own temperature ``T``,

    .. math::

        p(T) = c_1 (T - T_c) + c_2 (T - T_c)^2 + c_3 (T - T_c)^3, \qquad
        c_2 = \pm a_2 / h^2,\ c_3 = \pm a_3 / h^3,

    ``T_c`` the middle of the range, ``h`` its half width; ``a_2`` and ``a_3`` (the quadratic and cubic
    terms' size at the ends of the range) uniform in the ranges below, ``c_1`` uniform in ``slope``,
    every sign random.  The constant does not matter (every model holds it exactly).  SI units.

    Default sizes (navigation grade; a pendulous accelerometer's bias bends by tens of micro-g and its
    scale factor by several ppm over 60 degC; the slopes are the simulator's navigation ranges):

    ============  ====================  ====================  ======================
    family        slope ``c_1``         ``a_2`` (at h)        ``a_3`` (at h)
    ============  ====================  ====================  ======================
    gyro.bias     0.001-0.005 deg/h/C   0.01-0.03 deg/h       0.005-0.02 deg/h
    accel.bias    0.5-2 micro-g/C       10-40 micro-g         10-40 micro-g
    gyro.scale    0.3-1.5 ppm/C         2-8 ppm               1-4 ppm
    accel.scale   0.5-2 ppm/C           1-4 ppm               1-4 ppm
    ============  ====================  ====================  ======================
    """

    slope: dict = field(default_factory=lambda: {
        "gyro.bias": (0.001 * c.DH_TO_RS, 0.005 * c.DH_TO_RS), "accel.bias": (0.5 * c.UG_TO_MPS2, 2 * c.UG_TO_MPS2),
        "gyro.scale": (0.3e-6, 1.5e-6), "accel.scale": (0.5e-6, 2e-6)})
    quadratic: dict = field(default_factory=lambda: {
        "gyro.bias": (0.01 * c.DH_TO_RS, 0.03 * c.DH_TO_RS), "accel.bias": (10 * c.UG_TO_MPS2, 40 * c.UG_TO_MPS2),
        "gyro.scale": (2e-6, 8e-6), "accel.scale": (1e-6, 4e-6)})
    cubic: dict = field(default_factory=lambda: {
        "gyro.bias": (0.005 * c.DH_TO_RS, 0.02 * c.DH_TO_RS), "accel.bias": (10 * c.UG_TO_MPS2, 40 * c.UG_TO_MPS2),
        "gyro.scale": (1e-6, 4e-6), "accel.scale": (1e-6, 4e-6)})

    def draw(self, rng, n, *, center_degC, half_width_degC):
        """``{flat element: ndarray (n, 3)}`` of ``(c1, c2, c3)`` about ``center_degC``."""
        h = float(half_width_degC)
        out = {}
        for fam in FAMILIES:
            for ax in AXES:
                sign = np.where(rng.uniform(size=(n, 3)) < 0.5, -1.0, 1.0)
                c1 = rng.uniform(*self.slope[fam], size=n)
                a2 = rng.uniform(*self.quadratic[fam], size=n)
                a3 = rng.uniform(*self.cubic[fam], size=n)
                out[f"{fam}.{ax}"] = sign * np.stack([c1, a2 / h**2, a3 / h**3], axis=1)
        return out

    def to_dict(self):
        return {"form": "c1 (T - Tc) + c2 (T - Tc)^2 + c3 (T - Tc)^3 in each element's own sensor temperature; "
                        "c2 = +-a2/h^2, c3 = +-a3/h^3 (h the range's half width), uniform magnitudes, random signs",
                "slope_c1": self.slope, "a2": self.quadratic, "a3": self.cubic, "units": "SI"}


@dataclass(frozen=True)
class CampaignPoint:
    """One campaign of one procedure: a recorded length per experiment, its predicted stitched accuracy.

    ``metrics``: ``{family: {metric: value}}``, SI; ``sigma_curve`` / ``model_error_curve``:
    ``{family: ndarray (G,)}`` the largest over the axes at each temperature of the grid; ``sigma_axes``:
    ``{family: ndarray (3, G)}`` per axis; ``node_covariance``: ``{family: ndarray (12, 12)}`` the
    stitched cubics' joint covariance at the four :func:`check_nodes` of the range over the three axes
    (axis-major; a cubic is fixed by its values there: what the simulated check whitens its errors with);
    ``experiment_covariance``: ``(names, matrix)`` one experiment's predicted covariance of the compared
    families' elements (every experiment of the campaign has it: one program shifted in temperature);
    ``noise``: the grade and the white-noise densities the prediction used (SI: ``gyro_noise`` rad/sqrt(s),
    ``accel_noise`` m/s/sqrt(s), ``encoder_noise`` rad).
    """

    procedure: str
    length_s: float
    metrics: dict
    sigma_curve: dict
    model_error_curve: dict
    t_ref_degC: tuple
    sigma_axes: dict
    seconds: float
    node_covariance: dict = field(default_factory=dict)
    experiment_covariance: tuple = ((), None)
    noise: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Comparison:
    """Every procedure's campaigns and the equal-accuracy ratios against the reference (the first)."""

    procedures: tuple
    points: dict
    range_degC: tuple
    grid_degC: np.ndarray
    soaks_s: tuple
    truth: TruthFamily
    draws: int
    ratios: dict
    seconds: float
    cpu_seconds: float = float("nan")
    model: ModelOptions = ModelOptions(grade=DEFAULT_GRADE)

    def durations(self, name, *, soak_s=None):
        proc = next(p for p in self.procedures if p.name == name)
        return np.array([proc.duration_s(pt.length_s, soak_s=soak_s) for pt in self.points[name]])

    def noise(self):
        """The grade and white-noise densities the predictions used (SI), and which of them were given."""
        first = next(pt for pts in self.points.values() for pt in pts)
        given = [k for k in ("gyro_noise", "accel_noise", "encoder_noise") if getattr(self.model, k) is not None]
        return {**first.noise, "given": given}

    def to_dict(self):
        def fam(d):
            return {f: {m: float(v) for m, v in d[f].items()} for f in d}

        return {
            "range_degC": list(self.range_degC), "soaks_s": list(self.soaks_s), "truth_family": self.truth.to_dict(),
            "truth_draws": self.draws, "seconds": self.seconds, "cpu_seconds": self.cpu_seconds,
            "noise": self.noise(),
            "procedures": [p.to_dict() for p in self.procedures],
            "campaigns": {name: [{"length_s": pt.length_s,
                                  "duration_s": {f"{w:g}": p.duration_s(pt.length_s, soak_s=w) for w in self.soaks_s}
                                  if p.kind == "steps" else p.duration_s(pt.length_s),
                                  "t_ref_degC": list(pt.t_ref_degC), "metrics": fam(pt.metrics)}
                                 for pt in self.points[name]]
                          for name, p in ((p.name, p) for p in self.procedures)},
            "equal_accuracy": self.ratios,
            "units": "SI: rad/s for gyro.bias, m/s^2 for accel.bias, 1 for scale factors; durations s",
        }


def _shifted(result, shift):
    return replace(result, t_ref_degC=result.t_ref_degC + shift,
                   temperature_range_degC=tuple(float(v) + shift for v in result.temperature_range_degC))


def _family_result(result):
    """The result restricted to the compared families (value and ``_tc`` elements)."""
    keep = [n for n in result.covariance_names if n.rsplit(".", 1)[0] in FAMILIES + tuple(_TC.values())]
    idx = [result.covariance_names.index(n) for n in keep]
    cov = np.asarray(result.covariance)[np.ix_(idx, idx)]
    return replace(result, values={n: 0.0 for n in keep}, sigmas={n: result.sigmas[n] for n in keep},
                   covariance_names=tuple(keep), covariance=cov, effects=tuple(dict.fromkeys(
                       n.rsplit(".", 1)[0] for n in keep)))


def _projection_rows(T_s, t_ref, center, slope_known):
    """What an experiment's model makes of a truth curve, as rows on its coefficients ``(c1, c2, c3)``.

    ``T_s`` (M,) the element's sensor temperatures over the record.  Returns shape (1, 3) (a step: the
    mean over the record) or (2, 3) (value at ``t_ref`` and slope: least squares on ``[1, T - t_ref]``);
    samples weighted evenly.
    """
    u = T_s - center
    Y = np.stack([u, u**2, u**3], axis=1)
    if not slope_known:
        return Y.mean(axis=0)[None, :]
    d = T_s - t_ref
    X = np.stack([np.ones_like(d), d], axis=1)
    B, *_ = np.linalg.lstsq(X, Y, rcond=None)
    return B


def check_nodes(range_degC):
    """The four Chebyshev nodes of ``range_degC`` (degC): a cubic over the range is fixed by its values there."""
    lo, hi = (float(v) for v in range_degC)
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.cos((2 * np.arange(4) + 1) * np.pi / 8)


def _curve_samples(curve, T, n, rng):
    """``n`` draws of the stitched curve's error at ``T`` from its fit covariance, shape (n, G)."""
    fit = curve.fit()
    A = fit.rows(T)
    cov = 0.5 * (fit.cov + fit.cov.T)
    w, V = np.linalg.eigh(cov)
    L = V * np.sqrt(np.clip(w, 0.0, None))
    z = rng.standard_normal((n, L.shape[1]))
    return (z @ L.T) @ A.T


def _model_errors(results, temps, names, ranges, truths, grid_degC, center_degC, nodes_degC):
    """Stitched minus truth over the grid for every truth draw, ``{family: ndarray (draws, 3, G)}``, and the
    stitched curves' joint covariance at ``nodes_degC`` over the axes, ``{family: ndarray (3 N, 3 N)}``
    (axis-major).

    The stitched curve is linear in the experiments' values (generalised least squares with fixed
    weights), so the campaign is stitched once per (experiment, coefficient) slot with a unit value in
    every element, and each draw's curve is the sum of those responses weighted by its projections.  The
    same responses at the nodes carry each experiment's full covariance (the axes' correlations included,
    which the per-element stitch does not keep) to the nodes.
    """
    n_coef = 2 if any(n.rsplit(".", 1)[0] in _TC.values() for n in results[0].values) else 1
    elements = [f"{f}.{ax}" for f in FAMILIES for ax in AXES]
    response = {}
    for k in range(len(results)):
        for j in range(n_coef):
            rs = []
            for i, r in enumerate(results):
                vals = {n: 0.0 for n in r.values}
                if i == k:
                    for el in elements:
                        f, ax = el.rsplit(".", 1)
                        vals[el if j == 0 else f"{_TC[f]}.{ax}"] = 1.0
                rs.append(replace(r, values=vals))
            st = stitch(rs, names=names, sensor_ranges=ranges)
            for el in elements:
                response[(el, k, j)] = st.curves[el].evaluate(np.concatenate([grid_degC, nodes_degC]))[0]
    G, N = grid_degC.size, len(nodes_degC)
    node_cov = {}
    for f in FAMILIES:
        C = np.zeros((3 * N, 3 * N))
        for k, r in enumerate(results):
            slots = [(i, j, f"{f}.{ax}" if j == 0 else f"{_TC[f]}.{ax}") for i, ax in enumerate(AXES)
                     for j in range(n_coef)]
            idx = [r.covariance_names.index(n) for _, _, n in slots]
            S = np.asarray(r.covariance)[np.ix_(idx, idx)]
            Gm = np.zeros((3 * N, len(slots)))
            for c, (i, j, _) in enumerate(slots):
                Gm[i * N:(i + 1) * N, c] = response[(f"{f}.{AXES[i]}", k, j)][G:]
            C += Gm @ S @ Gm.T
        node_cov[f] = 0.5 * (C + C.T)
    out = {f: np.zeros((len(next(iter(truths.values()))), 3, grid_degC.size)) for f in FAMILIES}
    for f in FAMILIES:
        for i, ax in enumerate(AXES):
            el = f"{f}.{ax}"
            coef = truths[el]                                            # (D, 3)
            u = grid_degC - center_degC
            for k, (r, Ts) in enumerate(zip(results, temps)):
                rows = _projection_rows(Ts[:, sensor_of(el)], r.t_ref_degC, center_degC,
                                        slope_known=f"{_TC[f]}.{ax}" in r.values)
                y = coef @ rows.T                                        # (D, n_coef)
                for j in range(rows.shape[0]):
                    out[f][:, i] += y[:, [j]] * response[(el, k, j)][None, :G]
            out[f][:, i] -= coef @ np.stack([u, u**2, u**3])
    return out, node_cov


def campaign_point(procedure, length_s, *, grid_degC, truths, center_degC, noise_draws=20, rng,
                   rate_hz=PREDICTION_RATE_HZ, model=ModelOptions(grade=DEFAULT_GRADE), progress=None):
    """The predicted stitched accuracy of one campaign of ``procedure`` (:class:`CampaignPoint`).

    ``model``: the grade and noise of the compared IMU (:class:`ModelOptions`; ``exclude`` is the procedure's).
    """
    t0 = time.perf_counter()
    program = procedure.base_program(length_s, rate_hz=rate_hz)
    exp = nominal_experiment(program)
    opts = CalibrationOptions(model=replace(model, exclude=procedure.exclude))
    problem = build_problem(exp, options=opts)
    pred = predict(problem)
    base = _family_result(prediction_result(problem, pred))
    T_sens = exp.sensor_temperatures()[:: max(int(round(exp.rate_hz)), 1)]   # 1 s samples
    mean_sensor = T_sens.mean(axis=1)
    mid = 0.5 * (float(mean_sensor.min()) + float(mean_sensor.max()))
    exps = procedure.experiments(mid)
    results, ranges, temps, names = [], [], [], []
    for e in exps:
        results.append(_shifted(base, e.shift_degC))
        Ts = T_sens + e.shift_degC
        temps.append(Ts)
        ranges.append(np.stack([Ts.min(axis=0), Ts.max(axis=0)], axis=1))
        names.append(e.label)
    st = stitch(results, names=names, sensor_ranges=ranges)
    G = grid_degC.size
    sigma = {f: np.zeros((3, G)) for f in FAMILIES}
    nodes = check_nodes((grid_degC[0], grid_degC[-1]))
    noise = {f: [] for f in FAMILIES}
    for f in FAMILIES:
        for i, ax in enumerate(AXES):
            cv = st.curves[f"{f}.{ax}"]
            sigma[f][i] = cv.evaluate(grid_degC)[1]
            noise[f].append(_curve_samples(cv, grid_degC, noise_draws * len(next(iter(truths.values()))), rng))
    n_draws = len(next(iter(truths.values())))
    merr, node_cov = _model_errors(results, temps, names, ranges, truths, grid_degC, center_degC, nodes)
    metrics, sig_curve, me_curve = {}, {}, {}
    for f in FAMILIES:
        s = sigma[f]
        me = merr[f]
        me_rms = np.sqrt(np.mean(me**2, axis=0))                 # (3, G) over the truth draws
        tot = np.sqrt(s**2 + me_rms**2)
        noise_f = np.stack(noise[f], axis=1).reshape(n_draws, noise_draws, 3, G)
        largest = np.max(np.abs(noise_f + me[:, None]), axis=(2, 3))
        metrics[f] = {"largest_sigma": float(s.max()), "rms_sigma": float(np.sqrt(np.mean(s**2))),
                      "model_error_largest": float(np.mean(np.max(np.abs(me), axis=(1, 2)))),
                      "model_error_largest_p95": float(np.percentile(np.max(np.abs(me), axis=(1, 2)), 95)),
                      "largest_total": float(tot.max()), "expected_largest": float(np.mean(largest))}
        sig_curve[f] = s.max(axis=0)
        me_curve[f] = me_rms.max(axis=0)
    noise = problem.model.noise
    pt = CampaignPoint(procedure=procedure.name, length_s=float(length_s), metrics=metrics, sigma_curve=sig_curve,
                       model_error_curve=me_curve, t_ref_degC=tuple(r.t_ref_degC for r in results), sigma_axes=sigma,
                       seconds=time.perf_counter() - t0, node_covariance=node_cov,
                       experiment_covariance=(tuple(base.covariance_names), np.asarray(base.covariance)),
                       noise={"grade": problem.model.options.grade, "gyro_noise": float(noise.gyro),
                              "accel_noise": float(noise.accel), "encoder_noise": float(noise.encoder)})
    if progress:
        progress(f"  {procedure.name}, {length_s / 3600:g} h per experiment: gyro bias largest sigma "
                 f"{metrics['gyro.bias']['largest_sigma'] * c.RS_TO_DH:.4f} deg/h, accel bias "
                 f"{metrics['accel.bias']['largest_sigma'] / c.UG_TO_MPS2:.3f} micro-g ({pt.seconds:.1f} s)")
    return pt


def equal_accuracy_duration(target, durations, values, *, extrapolate=4.0):
    """Duration at which a procedure's ``values`` (falling with ``durations``) reach ``target``.

    Log-log interpolation between consecutive campaigns.  Returns ``(duration or None, status)``: status
    ``"interpolated"``; ``"below"`` (reached already by the shortest campaign: the duration is then an upper
    bound, the shortest's); ``"extrapolated"`` (beyond the longest campaign, on the log-log line of the last
    two, at most ``extrapolate`` times the longest duration); or ``"not reached"`` (None).
    """
    d = np.asarray(durations, dtype=float)
    v = np.asarray(values, dtype=float)
    order = np.argsort(d)
    d, v = d[order], v[order]
    if target >= v[0]:
        return float(d[0]), "below"
    for i in range(d.size - 1):
        a, b = v[i], v[i + 1]
        if (a - target) * (b - target) <= 0 and a != b:
            x = (np.log(target) - np.log(a)) / (np.log(b) - np.log(a))
            return float(np.exp(np.log(d[i]) + x * (np.log(d[i + 1]) - np.log(d[i])))), "interpolated"
    if d.size >= 2 and v[-1] < v[-2] and target > 0:
        slope = (np.log(v[-1]) - np.log(v[-2])) / (np.log(d[-1]) - np.log(d[-2]))
        log_dur = np.log(d[-1]) + (np.log(target) - np.log(v[-1])) / slope
        if log_dur <= np.log(extrapolate * d[-1]):
            return float(np.exp(log_dur)), "extrapolated"
    return None, "not reached"


def equal_accuracy(procedures, points, *, soaks_s, metrics=("largest_sigma", "rms_sigma", "largest_total",
                                                             "expected_largest")):
    """``{candidate: {f"{soak:g}": {family: {metric: [rows]}}}}`` against the reference (first) procedure.

    Each row: the reference campaign's length and duration, the candidate's equal-accuracy duration,
    the ratio (None when not reached), the status of :func:`equal_accuracy_duration`.
    """
    ref = procedures[0]
    out = {}
    for cand in procedures[1:]:
        cpts = points[cand.name]
        by_soak = {}
        for w in soaks_s:
            fams = {}
            for f in FAMILIES:
                mets = {}
                for m in metrics:
                    rows = []
                    for rp in points[ref.name]:
                        d_ref = ref.duration_s(rp.length_s, soak_s=w)
                        dur, status = equal_accuracy_duration(
                            rp.metrics[f][m], [cand.duration_s(p.length_s, soak_s=w) for p in cpts],
                            [p.metrics[f][m] for p in cpts])
                        rows.append({"reference_length_s": rp.length_s, "reference_duration_s": d_ref,
                                     "duration_s": dur, "ratio": None if dur is None else dur / d_ref,
                                     "status": status})
                    mets[m] = rows
                fams[f] = mets
            by_soak[f"{w:g}"] = fams
        out[cand.name] = by_soak
    return out


def compare(procedures, *, soaks_s=None, range_degC=(-10.0, 50.0), truth=None, draws=40, seed=1, grid_points=121,
            rate_hz=PREDICTION_RATE_HZ, model=ModelOptions(grade=DEFAULT_GRADE), progress=None):
    """Compare ``procedures`` (the first is the reference) on predicted accuracy against duration.

    Parameters
    ----------
    procedures : sequence of graph_calib.design.procedures.Procedure
        At least two.
    soaks_s : sequence of float, optional
        Soak times of the step procedures to state the durations and ratios for (default: each step
        procedure's own).
    range_degC : (float, float)
        The temperature range the curves are judged over (sensor temperature).
    truth : TruthFamily, optional
    draws : int
        Truth curves drawn from the family (the model error is their mean / 95th percentile).
    seed : int
        Of the truth draws and the noise samples of the expected largest error.
    grid_points : int
    rate_hz : float
        IMU sample rate of the predicted records (:data:`PREDICTION_RATE_HZ`).
    model : ModelOptions
        The compared IMU: its grade (priors and noise) and any noise overrides (``gyro_noise``,
        ``accel_noise``, ``encoder_noise``); default the navigation grade.  ``exclude`` is each procedure's.
    progress : callable, optional

    Returns
    -------
    Comparison
    """
    t0, c0 = time.perf_counter(), time.process_time()
    procedures = tuple(procedures)
    if len(procedures) < 2:
        raise ValueError("a comparison needs at least two procedures")
    if len({p.name for p in procedures}) != len(procedures):
        raise ValueError(f"procedure names must be unique, got {[p.name for p in procedures]}")
    lo, hi = (float(v) for v in range_degC)
    if not hi > lo:
        raise ValueError(f"range_degC must be (low, high) with low < high, got {range_degC!r}")
    truth = truth or TruthFamily()
    rng = np.random.default_rng(seed)
    center, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    truths = truth.draw(rng, int(draws), center_degC=center, half_width_degC=half)
    grid = np.linspace(lo, hi, int(grid_points))
    points = {}
    for p in procedures:
        if progress:
            progress(f"{p.name} ({p.kind}, {p.n_experiments} experiments)")
        points[p.name] = tuple(campaign_point(p, L, grid_degC=grid, truths=truths, center_degC=center, rng=rng,
                                              rate_hz=rate_hz, model=model, progress=progress)
                                for L in p.lengths())
    if soaks_s is None:
        soaks_s = tuple(sorted({p.soak_s for p in procedures if p.kind == "steps"})) or (0.0,)
    soaks_s = tuple(float(w) for w in soaks_s)
    ratios = equal_accuracy(procedures, points, soaks_s=soaks_s)
    return Comparison(procedures=procedures, points=points, range_degC=(lo, hi), grid_degC=grid, soaks_s=soaks_s,
                      truth=truth, draws=int(draws), ratios=ratios, seconds=time.perf_counter() - t0,
                      cpu_seconds=time.process_time() - c0, model=model)


__all__ = ["PREDICTION_RATE_HZ", "FAMILIES", "METRICS", "DISPLAY", "TruthFamily", "CampaignPoint", "Comparison",
           "campaign_point", "check_nodes",
           "equal_accuracy_duration", "equal_accuracy", "compare"]
