r"""Validation: a stitched calibration applied to an independent record, the sensor errors that remain.

Definition (``docs/campaign.md`` explains it with the numbers)
-------------------------------------------------------------
The record is an experiment file that took no part in the calibration and
whose sensor temperatures cover the campaign's range.  It is cut into windows of
``window_s`` (1 s); in each window ``w`` the mean angular rate
``omega_w = sum(dtheta) / sum(dt)``, the mean specific force ``f_w = sum(dv) / sum(dt)``
and the mean temperature of each of the six sensors are formed.  A calibration
``c`` evaluated at those temperatures gives the declared sensor error

.. math::

    e^c_{g,w} = b_g(T_w) + \mathrm{diag}(s_g(T_w))\,\omega_w + M_g\,\omega_w, \qquad
    e^c_{a,w} = b_a(T_w) + \mathrm{diag}(s_a(T_w))\,f_w + M_a\,f_w,

(model.md's sensor equations; each element at its own sensor's temperature),
computed through the one sensor model (:mod:`graph_calib.compensation.calibration`): a
single result by :meth:`graph_calib.compensation.calibration.Calibration.sensor_errors` with
``dT = T_w - T_ref``, a stitched calibration by the same model terms fed with
its element values at ``T_w`` (:func:`sensor_errors`).  Further effects are not
compared.
The *remaining error* is the difference between the reference calibration's
error and the stitched one's, ``de_w = e^ref_w - e^stitched_w``: what a navigation
system would still see after correcting its sensors with the stitched
calibration.  The reference is the truth for simulated data (its
``temperature_curves``, the truth over the whole range, :class:`TruthCurves`; a
truth file without them holds only inside its own temperature range, and windows
outside it are left out, never extrapolated), or, for a real record, the record's own
calibration (then ``de`` is a consistency check limited by that calibration's
own uncertainty).  Measured rates and forces stand in for the true ones (the
difference changes ``de`` by a product of two small errors).

Per axis, RMS and largest ``|de|`` are reported

- for the gyros over the **static windows** (the IMU at rest, turning with the
  Earth only: the condition under which the method's accuracy of 0.01 deg/h is
  stated), over all windows, and over the moving windows also as a fraction of
  the rate (``ppm``: a residual scale-factor error);
- for the accelerometers over all windows (specific force stays near ``g``
  while the table turns) and over the static ones.

The record passes when the largest static gyro error is below
:data:`GYRO_ACCURACY_RADPS` and the largest accelerometer error below
:data:`ACCEL_ACCURACY_MPS2` on every axis.  ``largest_z`` divides the
errors by the combined one-sigma of the stitched and the reference calibrations'
sensor errors (the check that matters when the reference is an estimate: about
3 or less when they agree).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graph_calib import constants as c
from graph_calib.compensation.calibration import Calibration, triad_errors
from graph_calib.sensors.curves import evaluate_polynomial_curve
from graph_calib.sensors.effects import EFFECTS
from graph_calib.sensors.params import Layout, split_element_name
from graph_calib.stitching import family, result_points, sensor_columns, sensor_of

#: The method's published accuracy: gyro drift, rad/s (0.01 deg/h).
GYRO_ACCURACY_RADPS = 0.01 * c.DH_TO_RS
#: The method's published accuracy: accelerometer bias, m/s^2.
ACCEL_ACCURACY_MPS2 = 2e-4

#: The parameters whose sensor errors validation compares, at the window temperatures (module docstring).
ERROR_LAYOUT = Layout(("gyro.bias", "gyro.scale", "gyro.misalignment", "accel.bias", "accel.scale",
                       "accel.misalignment"))
#: The same with their temperature coefficients: what a single result contributes.
RESULT_PARAMETERS = tuple(n for n in EFFECTS if family(n)[0] in ERROR_LAYOUT.names)


def _parameter_of(element):
    """Parameter name of a flat element name, None when the catalogue does not know it."""
    try:
        return split_element_name(element)[0]
    except KeyError:
        return None


class ResultCalibration:
    """A single result (truth or estimate) as a calibration over temperature.

    Every gyro/accel element follows ``p + p_tc dT + p_tc2 dT^2 + p_tc3 dT^3 + ...``, every temperature
    coefficient the result holds (the registry's, up to ``*_tc5``), with ``dT = T_sensor - T_ref``,
    one :class:`graph_calib.stitching.SubrangePoint` per element (evaluated by
    :func:`graph_calib.sensors.curves.evaluate_polynomial_curve`); :meth:`sensor_errors` applies the same
    coefficients through the one sensor model.  For a truth file of the simulator the curvature remainder
    ``extra.simulation.unmodelled`` supplies the coefficients the truth layout lacks.

    Parameters
    ----------
    result : graph_calib.records.experiment.Result

    Attributes
    ----------
    result : graph_calib.records.experiment.Result
    points : dict
        ``{flat element: SubrangePoint}``, for :meth:`evaluate` and :meth:`element_sigmas`.
    calibration : graph_calib.compensation.calibration.Calibration
        The result's :data:`RESULT_PARAMETERS` (with the truth remainder), for :meth:`sensor_errors`.
    label : str
    """

    def __init__(self, result):
        self.result = result
        values = dict(result.values)
        sim = (result.extra or {}).get("simulation", {}) if isinstance(result.extra, dict) else {}
        for k, v in (sim.get("unmodelled") or {}).items():
            values.setdefault(k, float(v))
        self.points = result_points(result, values=values)
        own = {k: v for k, v in values.items() if _parameter_of(k) in RESULT_PARAMETERS}
        self.calibration = Calibration.from_values(own, t_ref_degC=result.t_ref_degC, sigmas=result.sigmas,
                                                   source=result.source)
        self.label = "truth" if result.solver == "truth" else f"{result.solver} estimate of {result.source}"
        #: Where this result holds: a truth without ``temperature_curves`` only inside its own range
        #: (data-format.md: never extrapolate it); None for an estimate (its record's own range).
        self.valid_range_degC = (tuple(float(v) for v in result.temperature_range_degC)
                                 if result.solver == "truth" else None)

    def evaluate(self, T_sensors, model=None):
        """``{flat element: values (N,)}`` at the sensor temperatures ``T_sensors`` (N, 6), SI."""
        return {k: p.predict(sensor_columns(T_sensors, sensor_of(k)))[0] for k, p in self.points.items()}

    def element_sigmas(self, T_sensors, model=None):
        """One sigma of every element at the sensor temperatures, ``{flat: (N,)}`` (empty for a truth).

        From the result's covariance of each element and its temperature coefficients.
        """
        if self.result.sigmas is None:
            return {}
        return {k: p.predict(sensor_columns(T_sensors, sensor_of(k)))[1] for k, p in self.points.items()}

    def sensor_errors(self, T_sensors, omega_b, f_b):
        """The result's declared sensor errors at the sensor temperatures ``T_sensors`` (N, 6), shape (N, 3) each.

        :meth:`graph_calib.compensation.calibration.Calibration.sensor_errors` of :attr:`calibration`
        with ``dT = T_sensors - t_ref_degC``; rad/s and m/s^2.
        """
        cal = self.calibration
        return cal.sensor_errors(omega_b, f_b, dT=np.asarray(T_sensors, dtype=float) - cal.t_ref_degC)


class TruthCurves:
    """A truth file's ``temperature_curves``: the truth of each element over the whole temperature range.

    ``value(T) = sum_i c_i (T - t0)^i`` (SI) with ``T`` the element's own sensor temperature
    (data-format.md).  Elements without a curve take the truth file's own value (with its temperature
    coefficients, :class:`ResultCalibration`): for the simulator these are the elements that do not
    depend on temperature (misalignments, mount, lever arm).

    Parameters
    ----------
    result : graph_calib.records.experiment.Result
        A truth file with ``extra["temperature_curves"]`` (validated by :func:`graph_calib.io.read_result`).

    Attributes
    ----------
    result : graph_calib.records.experiment.Result
    curves : dict
        ``{flat element: (t0_degC, coefficients ndarray)}``.
    label : str
        ``"truth (temperature curves)"``.
    """

    def __init__(self, result):
        self.result = result
        raw = (result.extra or {}).get("temperature_curves") or {}
        self.curves = {k: (float(v["t0_degC"]), np.asarray(v["coefficients"], dtype=float)) for k, v in raw.items()}
        self._own = ResultCalibration(result)
        self.label = "truth (temperature curves)"

    def evaluate(self, T_sensors, model=None):
        """``{flat element: values (N,)}`` at the sensor temperatures ``T_sensors`` (N, 6), SI."""
        T_sensors = np.atleast_2d(np.asarray(T_sensors, dtype=float))
        out = self._own.evaluate(T_sensors)
        for k, (t0, coef) in self.curves.items():
            T = sensor_columns(T_sensors, sensor_of(k))
            out[k] = evaluate_polynomial_curve(coef, T, t0_degC=t0)[0]
        return out

    def element_sigmas(self, T_sensors, model=None):
        """A truth has no uncertainty: ``{}``."""
        return {}

    def sensor_errors(self, T_sensors, omega_b, f_b):
        """The truth's declared sensor errors at the sensor temperatures, rad/s and m/s^2, (N, 3) each."""
        return sensor_errors(self.evaluate(T_sensors), omega_b, f_b)


def truth_reference(result):
    """The reference a truth (or estimate) result stands for over temperature.

    A truth file with ``temperature_curves`` gives :class:`TruthCurves` (valid over the whole range);
    any other result gives :class:`ResultCalibration`, valid only inside the result's own
    ``temperature_range_degC`` (its :attr:`ResultCalibration.valid_range_degC`).
    """
    if result.solver == "truth" and (result.extra or {}).get("temperature_curves"):
        return TruthCurves(result)
    return ResultCalibration(result)


def _element_rows(values, n):
    """``values`` (``{flat element: value or (N,)}``) as rows of :data:`ERROR_LAYOUT`, shape (N, P); missing zero."""
    X = np.zeros((n, ERROR_LAYOUT.size))
    for i, name in enumerate(ERROR_LAYOUT.element_names()):
        if name in values:
            X[:, i] = np.broadcast_to(np.asarray(values[name], dtype=float), (n,))
    return X


def sensor_error_sigmas(sigmas, omega_b, f_b):
    """One sigma of the declared sensor errors from independent element sigmas, shape (N, 3) per triad.

    ``sqrt(sum_r (s_r phi_r)^2)`` over the model's terms (:func:`graph_calib.compensation.calibration.triad_errors`
    with ``power=2``): ``sqrt(s_b^2 + (s_s u_i)^2 + sum_j (s_M,ij u_j)^2)``; correlations between
    elements are ignored.
    """
    omega_b = np.atleast_2d(np.asarray(omega_b, dtype=float))
    f_b = np.atleast_2d(np.asarray(f_b, dtype=float))
    X = np.square(_element_rows(sigmas, omega_b.shape[0]))
    vg = triad_errors(ERROR_LAYOUT, X, "gyro", omega_b, other=f_b, power=2)
    va = triad_errors(ERROR_LAYOUT, X, "accel", f_b, other=omega_b, power=2)
    return np.sqrt(np.clip(vg, 0.0, None)), np.sqrt(np.clip(va, 0.0, None))


def sensor_errors(values, omega_b, f_b):
    """The declared sensor errors of a calibration evaluated at each window's temperatures.

    The sensor model's terms of :data:`ERROR_LAYOUT` (bias, scale, misalignment) with
    the element values of each row (:func:`graph_calib.compensation.calibration.triad_errors`).

    Parameters
    ----------
    values : dict
        ``{flat element: value or values (N,)}``, SI; missing elements count as zero,
        elements outside :data:`ERROR_LAYOUT` are not used.
    omega_b, f_b : ndarray, shape (N, 3)
        Angular rate (rad/s) and specific force (m/s^2).

    Returns
    -------
    e_gyro, e_accel : ndarray, shape (N, 3)
        ``b + diag(s) u + M u`` for each triad, rad/s and m/s^2.
    """
    omega_b = np.atleast_2d(np.asarray(omega_b, dtype=float))
    f_b = np.atleast_2d(np.asarray(f_b, dtype=float))
    X = _element_rows(values, omega_b.shape[0])
    return (triad_errors(ERROR_LAYOUT, X, "gyro", omega_b, other=f_b),
            triad_errors(ERROR_LAYOUT, X, "accel", f_b, other=omega_b))


def _errors_of(calibration, T_sensors, omega_b, f_b, model=None):
    """Declared sensor errors of a calibration: its own :meth:`ResultCalibration.sensor_errors`, or
    :func:`sensor_errors` of its element values (a stitched calibration)."""
    if hasattr(calibration, "sensor_errors"):
        return calibration.sensor_errors(T_sensors, omega_b, f_b)
    return sensor_errors(calibration.evaluate(T_sensors, model), omega_b, f_b)


def static_pose_consistency(experiment, *, poses, layout=None, x=None):
    """How well a calibration makes a hand-held session's static poses agree with each other.

    Two checks that need no reference: the magnitude of the mean specific force in
    each static pose (all equal to local gravity for a calibrated triad), and, for
    consecutive poses ``i`` and ``i+1``, the rotation ``C`` integrated from the gyro
    increments between the pose centres (:func:`graph_calib.navigation.strapdown.integrate_attitude`,
    coning and Earth rate included) must carry the mean specific force of one pose
    into the other, ``f_(i+1) = C^T f_i``; the angle between the two is the
    gyro-against-accelerometer attitude mismatch.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    poses : sequence of (start, stop)
        Sample ranges of the static poses, in time order (e.g. from
        :func:`graph_calib.navigation.static_detection.detect_static`).
    layout : graph_calib.sensors.params.Layout, optional
    x : ndarray, optional
        Calibration to apply (with ``layout``); None: the raw (nominally scaled) data.

    Returns
    -------
    f_norm : ndarray, shape (n_poses,)
        ``|mean f_b|`` per pose, m/s^2.
    mismatch : ndarray, shape (n_poses - 1,)
        Attitude mismatch between consecutive poses, rad.
    """
    from graph_calib.sensors import sensor_model as sm
    from graph_calib.navigation.rotations import quat_to_dcm
    from graph_calib.navigation.strapdown import integrate_attitude

    e = experiment
    dt = e.dt[:, None]
    w = e.dtheta / dt
    f = e.dv / dt
    if x is not None:
        w, f = sm.correct_pair(layout, x, w, f)       # the gyros' g-sensitivity sees the calibrated f
    means = np.array([f[a:b].mean(axis=0) for a, b in poses])
    centres = [(a + b) // 2 for a, b in poses]
    q0 = np.array([1.0, 0.0, 0.0, 0.0])
    mismatch = np.empty(max(0, len(poses) - 1))
    for i, (i0, i1) in enumerate(zip(centres[:-1], centres[1:])):
        span = slice(i0 + 1, i1 + 1)
        q = integrate_attitude(w[span] * dt[span], t=e.t[span], rate_hz=e.rate_hz, q_nb0=q0,
                               latitude_rad=e.latitude_rad)[-1]
        pred = quat_to_dcm(q).T @ means[i]
        cosang = pred @ means[i + 1] / (np.linalg.norm(pred) * np.linalg.norm(means[i + 1]))
        mismatch[i] = np.arccos(np.clip(cosang, -1.0, 1.0))
    return np.linalg.norm(means, axis=1), mismatch


#: A window is static when its mean rate stays within this of the Earth rate, rad/s (about 10 deg/h).
STATIC_RATE_TOLERANCE_RADPS = 5e-5


def window_means(experiment, *, window_s=1.0, static_intervals=None):
    """Mean rate, force and sensor temperatures over consecutive windows of an experiment.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    window_s : float
    static_intervals : sequence of (start, stop), optional
        Sample index ranges known to be static; when given, a window must also lie
        wholly inside one of them to count as static.

    Returns
    -------
    dict
        ``t`` (W,) window centre, s; ``omega`` (W, 3) rad/s; ``f`` (W, 3) m/s^2;
        ``T`` (W, 6) degC; ``static`` (W,) bool: the window and both neighbours turn
        at the Earth rate only (``| |omega| - OMEGA_E | <`` :data:`STATIC_RATE_TOLERANCE_RADPS`).
        The rate, not the accelerometers, decides: a turn about the vertical leaves
        the specific force unchanged.
    """
    n = experiment.n_samples
    m = max(1, int(round(window_s * experiment.rate_hz)))
    W = n // m
    if W == 0:
        raise ValueError(f"record shorter than one {window_s} s window")
    sl = slice(0, W * m)
    dt = experiment.dt[sl].reshape(W, m)
    dur = dt.sum(axis=1)
    omega = experiment.dtheta[sl].reshape(W, m, 3).sum(axis=1) / dur[:, None]
    f = experiment.dv[sl].reshape(W, m, 3).sum(axis=1) / dur[:, None]
    T = experiment.sensor_temperatures()[sl].reshape(W, m, 6).mean(axis=1)
    t = experiment.t[sl].reshape(W, m).mean(axis=1)
    quiet = np.abs(np.linalg.norm(omega, axis=1) - c.OMEGA_E) < STATIC_RATE_TOLERANCE_RADPS
    static = quiet.copy()
    static[1:] &= quiet[:-1]
    static[:-1] &= quiet[1:]
    if static_intervals is not None:
        mask = np.zeros(n, dtype=bool)
        for a, b in static_intervals:
            mask[a:b] = True
        static &= mask[sl].reshape(W, m).all(axis=1)
    return {"t": t, "omega": omega, "f": f, "T": T, "static": static}


def _stats(e, sel):
    """Per-axis RMS and largest |e| over the windows selected per axis (``sel`` (W,) or (W, 3))."""
    sel = np.broadcast_to(np.asarray(sel, dtype=bool).reshape(e.shape[0], -1), e.shape)
    if not np.any(sel):
        return None
    rms, mx, cnt = [], [], []
    for i in range(e.shape[1]):
        x = e[sel[:, i], i]
        cnt.append(int(x.size))
        rms.append(float(np.sqrt(np.mean(x**2))) if x.size else 0.0)
        mx.append(float(np.max(np.abs(x))) if x.size else 0.0)
    return {"windows": int(max(cnt)), "windows_per_axis": cnt, "rms": rms, "max": mx}


@dataclass(frozen=True)
class Validation:
    """Remaining sensor errors of a calibration on a record (see the module docstring).

    Attributes
    ----------
    record : str
    reference : str
        What the errors are measured against (``"truth"`` or an estimate).
    model : str
        Stitched model evaluated.
    windows : dict
        :func:`window_means` of the record.
    de_gyro, de_accel : ndarray, shape (W, 3)
        Remaining errors, rad/s and m/s^2.
    inside : ndarray of bool, shape (W, 6)
        Whether each sensor's temperature lies in the range its bias was calibrated
        over (the verdict counts only these windows; outside is extrapolation,
        reported apart).
    sigma_gyro, sigma_accel : ndarray, shape (W, 3) or None
        One sigma of the stitched calibration's sensor error in each window (its
        elements' bands, correlations between elements ignored).
    coverage_degC : ndarray (6, 2) or None
        Calibrated temperature range of each sensor's bias.
    sigma_ref_gyro, sigma_ref_accel : ndarray, shape (W, 3) or None
        The same for the reference (zero for a truth; the record's own calibration
        otherwise).
    """

    record: str
    reference: str
    model: str
    windows: dict
    de_gyro: np.ndarray
    de_accel: np.ndarray
    inside: np.ndarray
    sigma_gyro: np.ndarray | None = None
    sigma_accel: np.ndarray | None = None
    coverage_degC: np.ndarray | None = None
    sigma_ref_gyro: np.ndarray | None = None
    sigma_ref_accel: np.ndarray | None = None
    thresholds: dict = field(default_factory=lambda: {"gyro_radps": GYRO_ACCURACY_RADPS,
                                                      "accel_mps2": ACCEL_ACCURACY_MPS2})

    def summary(self):
        """JSON-ready statistics per axis (SI) and the verdict against the published accuracy."""
        st = self.windows["static"][:, None]
        ig, ia = self.inside[:, :3], self.inside[:, 3:]
        moving = ~st
        g = {"static": _stats(self.de_gyro, st & ig), "all": _stats(self.de_gyro, ig),
             "moving": _stats(self.de_gyro, moving & ig),
             "outside_calibrated_range": _stats(self.de_gyro, ~ig)}
        if g["moving"] is not None:
            rate = np.abs(self.windows["omega"])
            ppm = []
            for i in range(3):
                s = moving[:, 0] & ig[:, i] & (rate[:, i] > 1e-3)  # turning about this axis, not Earth rate
                ppm.append(float(np.sqrt(np.mean(self.de_gyro[s, i] ** 2) / np.mean(rate[s, i] ** 2)) * 1e6)
                           if np.any(s) else 0.0)
            g["moving"]["rms_relative_ppm"] = ppm
        a = {"all": _stats(self.de_accel, ia), "static": _stats(self.de_accel, st & ia),
             "outside_calibrated_range": _stats(self.de_accel, ~ia)}
        gyro_basis = g["static"] or g["all"]
        gyro_ok = gyro_basis is not None and bool(np.max(gyro_basis["max"]) < self.thresholds["gyro_radps"])
        accel_ok = a["all"] is not None and bool(np.max(a["all"]["max"]) < self.thresholds["accel_mps2"])
        T = self.windows["T"]
        cov = self.coverage_degC
        z = None
        if self.sigma_gyro is not None:
            zero = np.zeros_like(self.de_gyro)
            sg = np.hypot(self.sigma_gyro, self.sigma_ref_gyro if self.sigma_ref_gyro is not None else zero)
            sa = np.hypot(self.sigma_accel, self.sigma_ref_accel if self.sigma_ref_accel is not None else zero)
            zg = np.where(sg > 0, np.abs(self.de_gyro) / np.where(sg > 0, sg, 1.0), 0.0)
            za = np.where(sa > 0, np.abs(self.de_accel) / np.where(sa > 0, sa, 1.0), 0.0)
            selg = np.broadcast_to(st, ig.shape) & ig
            selg = selg if np.any(selg) else ig
            z = {"gyro": float(np.max(zg[selg])) if np.any(selg) else None,
                 "accel": float(np.max(za[ia])) if np.any(ia) else None}
        return {
            "record": self.record, "reference": self.reference, "model": self.model,
            "largest": {"gyro_radps": None if gyro_basis is None else float(np.max(gyro_basis["max"])),
                        "accel_mps2": None if a["all"] is None else float(np.max(a["all"]["max"]))},
            "window_s": float(np.median(np.diff(self.windows["t"]))) if self.windows["t"].size > 1 else None,
            "temperature_range_degC": [float(T.min()), float(T.max())],
            "calibrated_range_degC": None if cov is None else [float(cov[:, 0].min()), float(cov[:, 1].max())],
            "sensor_calibrated_range_degC": None if cov is None else np.asarray(cov).tolist(),
            "fraction_inside": [float(v) for v in self.inside.mean(axis=0)],
            "gyro_radps": g, "accel_mps2": a,
            "thresholds": dict(self.thresholds),
            "gyro_criterion": "static windows" if g["static"] is not None else "all windows",
            "pass": {"gyro": gyro_ok, "accel": accel_ok, "all": gyro_ok and accel_ok},
            "largest_z": z,
        }


def validate(record, calibration, reference, *, model=None, window_s=1.0, windows=None, record_name=None):
    """Remaining sensor errors of ``calibration`` on ``record`` against ``reference``.

    Parameters
    ----------
    record : graph_calib.records.experiment.Experiment
        An independent record (not used in the calibration).
    calibration : graph_calib.stitching.Stitched or ResultCalibration or graph_calib.compensation.CompensationTable
        Anything with ``sensor_errors(T_sensors, omega_b, f_b)`` (:class:`ResultCalibration`) or
        ``evaluate(T_sensors, model) -> {element: values}``.  A compensation table is evaluated as
        ``graph-calib apply`` interpolates it, and its elements' ``calibrated_range_degC`` select the
        windows inside, so an exported table reproduces the campaign's figures of its stitched
        calibration (``docs/compensation.md``).
    reference : ResultCalibration or graph_calib.records.experiment.Result
        The truth (simulated data) or the record's own calibration.
    model : str, optional
        Stitched model to evaluate (its default when None).
    window_s : float
    windows : dict, optional
        Precomputed :func:`window_means` of the record.
    record_name : str, optional

    Returns
    -------
    Validation
    """
    if not hasattr(reference, "evaluate"):
        reference = truth_reference(reference)
    w = windows if windows is not None else window_means(record, window_s=window_s)
    T = w["T"]
    eg_c, ea_c = _errors_of(calibration, T, w["omega"], w["f"], model)
    eg_r, ea_r = _errors_of(reference, T, w["omega"], w["f"])
    sig_g = sig_a = coverage = None
    inside = np.ones(T.shape, dtype=bool)
    valid = getattr(reference, "valid_range_degC", None)
    if valid is not None:   # a truth without curves: only inside its own range (never extrapolated)
        inside &= (T >= valid[0]) & (T <= valid[1])
    curves = getattr(calibration, "curves", None)
    if curves:
        sig_g, sig_a = sensor_error_sigmas(calibration.element_sigmas(T, model), w["omega"], w["f"])
        coverage = np.tile([-np.inf, np.inf], (6, 1))
        for i, ax in enumerate("xyz"):
            for triad, s in (("gyro", i), ("accel", 3 + i)):
                cv = curves.get(f"{triad}.bias.{ax}")
                if cv is not None:
                    coverage[s] = cv.t_span
                    inside[:, s] &= (T[:, s] >= cv.t_span[0]) & (T[:, s] <= cv.t_span[1])
    ref_g = ref_a = None
    if hasattr(reference, "element_sigmas"):
        ref_sig = reference.element_sigmas(T)
        if ref_sig:
            ref_g, ref_a = sensor_error_sigmas(ref_sig, w["omega"], w["f"])
    return Validation(
        record=record_name or (record.source.rsplit("/", 1)[-1] if record.source else "record"),
        reference=getattr(reference, "label", "reference"), model=model or "default",
        windows=w, de_gyro=eg_r - eg_c, de_accel=ea_r - ea_c, inside=inside, sigma_gyro=sig_g,
        sigma_accel=sig_a, coverage_degC=coverage, sigma_ref_gyro=ref_g, sigma_ref_accel=ref_a,
    )


def validation_text(summary):
    """``gyro max X deg/h (static), accel max Y m/s^2`` of a validation summary ("-" where nothing was inside)."""
    g, a = summary["largest"]["gyro_radps"], summary["largest"]["accel_mps2"]
    gt = "-" if g is None else f"{g * c.RS_TO_DH:.4f}"
    at = "-" if a is None else f"{a:.2e}"
    return f"gyro max {gt} deg/h ({summary['gyro_criterion'].replace(' windows', '')}), accel max {at} m/s^2"


def simulate_validation_record(simulation, *, hours=2.0, start_degC=None, span_degC=None, rate_hz=None, seed=12345,
                               file_name="validation.h5"):
    """A further simulated experiment of the same IMU, sweeping the whole temperature range.

    Built from a turntable scenario of :mod:`graph_calib.simulation` (``nav-campaign``,
    ``nav-subrange``...): same IMU (``simulation.imu``), same bench and rotation
    design, its own programme and noise (``seed``), the chamber ramping so that the
    sensors drift from ``start_degC`` by ``span_degC`` (default: across every
    subrange of the scenario).

    Parameters
    ----------
    simulation : graph_calib.simulation.Simulation
    hours : float
    start_degC, span_degC : float, optional
    rate_hz : float, optional
        Sample rate (default: the scenario's).
    seed : int
    file_name : str

    Returns
    -------
    graph_calib.simulation.SimulatedExperiment
    """
    lo, hi = simulation.temperature_range()
    start = float(lo if start_degC is None else start_degC)
    span = float((hi - lo) if span_degC is None else span_degC)
    return simulation.further_experiment(
        file_name=file_name, seed=seed, hours=hours, start_degC=start, span_degC=span, rate_hz=rate_hz,
        description=f"graph-calib validation record: the {simulation.scenario} IMU sweeping "
                    f"{start:g}..{start + span:g} degC, {hours:g} h", tag="validation")


__all__ = ["GYRO_ACCURACY_RADPS", "ACCEL_ACCURACY_MPS2", "ResultCalibration", "TruthCurves", "truth_reference", "sensor_errors", "sensor_error_sigmas", "window_means",
           "Validation", "validate", "validation_text", "simulate_validation_record", "STATIC_RATE_TOLERANCE_RADPS",
           "ERROR_LAYOUT", "RESULT_PARAMETERS"]
