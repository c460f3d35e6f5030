r"""Stitching per-subrange calibrations into one model of every parameter over the whole temperature range.

Each experiment of a campaign calibrates one temperature subrange: for a
temperature-dependent parameter ``p`` it gives the value at its reference
temperature and the coefficient(s) of the declared model,

.. math::

    p(T) = p + p_\mathrm{tc}\,(T - T_\mathrm{ref}) \;[+\; p_\mathrm{tc2}\,(T - T_\mathrm{ref})^2],

with their covariance, where ``T`` is the temperature of the sensor the element
belongs to (``gyro.bias.y`` follows the gyro y channel; misalignment ``xy``
follows its row, gyro x).  Read as data, a subrange ``i`` measures the
derivatives of the unknown curve ``f`` at ``T_ref,i``,

.. math::

    y_i = \bigl[f(T_{\mathrm{ref},i}),\ f'(T_{\mathrm{ref},i}),\ f''(T_{\mathrm{ref},i})/2\bigr] + e_i,
    \qquad e_i \sim N(0, \Sigma_i),

(``Sigma_i`` the marginal block of the subrange's covariance; subranges are
independent experiments).  Every stitched model is the generalised
least-squares fit of a curve family to all these measurements together:

``linear``
    a continuous piecewise-linear curve; its unknowns are its values at knots
    placed at the ends of the covered range and at every boundary between
    consecutive subranges (see :func:`boundary_temperature`).  Inside a segment
    a subrange measures the value and the slope of the segment.
``cubic``
    one cubic polynomial over the whole range (degree lowered when there are
    fewer measurements than four).
``constant``
    for parameters the model holds constant over temperature (misalignments,
    further effects without a temperature coefficient): the weighted mean.
    Their ``linear`` model interpolates the subrange values (knots at the
    reference temperatures).

Each fit reports its chi-square and degrees of freedom.  When ``chi2/dof > 1``
the covariance of the fit is multiplied by ``chi2/dof`` (Birge ratio), so that
a family that cannot follow the data shows it in wider bands instead of false
confidence; the unscaled value is kept.

Boundary check: consecutive subranges (ordered by reference temperature) each
predict the parameter at their common boundary with their own linear model;
the difference divided by the combined sigma is ``z``; ``|z| > 3`` is flagged
per element, and the campaign counts as consistent when the largest ``|z|``
stays below the limit that the largest of that many N(0,1) values exceeds with
1 % probability (:func:`family_z_limit`).

Correlations between different elements are ignored (each element is stitched
on its own); correlations between an element's value and its temperature
coefficients are kept.

Examples
--------
>>> import numpy as np
>>> from graph_calib.experiment import Result
>>> def sub(t_ref, a, b):
...     names = ("gyro.bias.x", "gyro.bias_tc.x")
...     return Result(source="s", solver="factor-graph", t_ref_degC=t_ref,
...                   temperature_range_degC=(t_ref - 4, t_ref + 4), effects=("gyro.bias", "gyro.bias_tc"),
...                   values=dict(zip(names, (a, b))), sigmas=dict(zip(names, (1e-8, 1e-9))),
...                   covariance_names=names, covariance=np.diag([1e-16, 1e-18]))
>>> st = stitch([sub(5.0, 1e-7, 2e-9), sub(15.0, 1.2e-7, 2e-9)], names=["warm", "hot"])
>>> v, s = st.curves["gyro.bias.x"].evaluate([10.0])
>>> round(float(v[0]) * 1e9, 3)
110.0
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import comb

import numpy as np

from graph_calib import params
from graph_calib.effects import REGISTRY, temperature_family

#: The six sensors whose temperatures the model uses, in ``temperature_map`` order.
SENSORS = ("gyro.x", "gyro.y", "gyro.z", "accel.x", "accel.y", "accel.z")

#: Models that :func:`stitch` fits.
MODELS = ("linear", "cubic", "constant")

#: Largest |z| of the boundary check that counts as consistent.
BOUNDARY_Z_LIMIT = 3.0

#: Family-wise false-alarm probability of the boundary verdict (see :func:`family_z_limit`).
FAMILY_FALSE_ALARM = 0.01

#: Two subranges closer than this (degC, reference temperatures) share a segment of the linear model.
MIN_KNOT_SPACING_DEGC = 1.0

#: Suffixes of temperature coefficients, by polynomial order.


def sensor_of(element):
    """Index (0..5, :data:`SENSORS`) of the sensor whose temperature an element follows, or None.

    ``gyro.*`` and ``accel.*`` elements belong to the axis their element name
    starts with (``gyro.misalignment.zx`` -> gyro z); other parameters (mount,
    lever arm, time lags) have no sensor.

    >>> sensor_of("accel.bias.y"), sensor_of("gyro.misalignment.zx"), sensor_of("mount.x")
    (4, 2, None)
    """
    name, el = params.split_element_name(element)
    triad = name.split(".", 1)[0]
    if triad not in ("gyro", "accel") or not el:
        return None
    return (0 if triad == "gyro" else 3) + "xyz".index(el[0])


def family(parameter):
    """``(base, {order: coefficient name})`` of a parameter: ``gyro.bias_tc`` -> ``('gyro.bias', ...)``.

    The temperature coefficients of each parameter come from the effect registry
    (:func:`graph_calib.effects.temperature_family`).
    """
    return temperature_family(parameter)


def is_stitched(parameter):
    """Whether a parameter gets its own curve: an IMU parameter (gyro.*, accel.*) that is not a coefficient."""
    triad = parameter.split(".", 1)[0]
    return triad in ("gyro", "accel") and family(parameter)[0] == parameter


# ---------------------------------------------------------------------------
# the pieces
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class SubrangePoint:
    """What one subrange says about one element.

    Attributes
    ----------
    name : str
        Experiment name.
    t_ref_degC : float
    coef : ndarray, shape (d+1,)
        ``[p, p_tc, (p_tc2)]``, SI: the value and its temperature coefficients at ``t_ref_degC``.
    cov : ndarray, shape (d+1, d+1)
    t_range : (float, float)
        Temperature range of the element's sensor during the experiment, degC.
    """

    name: str
    t_ref_degC: float
    coef: np.ndarray
    cov: np.ndarray
    t_range: tuple

    @property
    def value(self):
        return float(self.coef[0])

    @property
    def sigma(self):
        return float(np.sqrt(max(self.cov[0, 0], 0.0)))

    def predict(self, T):
        """The subrange's own model at temperatures ``T``: ``(value, sigma)`` arrays."""
        dT = np.atleast_1d(np.asarray(T, dtype=float)) - self.t_ref_degC
        J = np.stack([dT**k for k in range(self.coef.size)], axis=1)
        v = J @ self.coef
        s = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", J, self.cov, J), 0.0, None))
        return v, s


@dataclass(frozen=True)
class Fit:
    """One stitched model of one element: a linear family ``f(T) = basis(T) @ theta`` fitted by GLS.

    Attributes
    ----------
    kind : str
        ``"linear"``, ``"cubic"`` or ``"constant"``.
    theta : ndarray
        Knot values (``linear``) or polynomial coefficients in ``u = (T - center) / scale``.
    cov : ndarray
        Covariance of ``theta`` (Birge-scaled when ``chi2/dof > 1``).
    chi2 : float
    dof : int
    knots : ndarray or None
        Knot temperatures of the ``linear`` model, degC.
    center, scale : float
        Of the polynomial variable.
    clamp : bool
        Hold the end values outside the knots (models without temperature coefficients).
    """

    kind: str
    theta: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    knots: np.ndarray | None = None
    center: float = 0.0
    scale: float = 1.0
    clamp: bool = False

    @property
    def birge(self):
        """``sqrt(chi2 / dof)`` (1 without degrees of freedom)."""
        return float(np.sqrt(self.chi2 / self.dof)) if self.dof > 0 else 1.0

    def rows(self, T, order=0):
        """Rows of the ``order``-th Taylor coefficient ``f^(order)(T) / order!`` in ``theta``, shape (N, P)."""
        T = np.atleast_1d(np.asarray(T, dtype=float))
        P = self.theta.size
        A = np.zeros((T.size, P))
        if self.kind == "linear":
            tk = self.knots
            if tk.size == 1:
                if order == 0:
                    A[:, 0] = 1.0
                return A
            Tc = np.clip(T, tk[0], tk[-1]) if self.clamp else T
            j = np.clip(np.searchsorted(tk, Tc, side="right") - 1, 0, tk.size - 2)
            h = tk[j + 1] - tk[j]
            idx = np.arange(T.size)
            if order == 0:
                w = (Tc - tk[j]) / h
                A[idx, j] = 1.0 - w
                A[idx, j + 1] = w
            elif order == 1:
                inside = ~self.clamp | ((T >= tk[0]) & (T <= tk[-1]))
                A[idx, j] = np.where(inside, -1.0 / h, 0.0)
                A[idx, j + 1] = np.where(inside, 1.0 / h, 0.0)
            return A
        u = (T - self.center) / self.scale
        for p in range(order, P):
            A[:, p] = comb(p, order) * u ** (p - order) / self.scale**order
        return A

    def evaluate(self, T):
        """``(value, sigma)`` arrays at temperatures ``T``."""
        A = self.rows(T)
        v = A @ self.theta
        s = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", A, self.cov, A), 0.0, None))
        return v, s

    def to_dict(self):
        out = {"kind": self.kind, "theta": self.theta, "covariance": self.cov, "chi2": self.chi2, "dof": self.dof,
               "birge_ratio": self.birge}
        if self.kind == "linear":
            out["knots_degC"] = self.knots
        else:
            out["center_degC"] = self.center
            out["scale_degC"] = self.scale
        return out


@dataclass(frozen=True)
class BoundaryCheck:
    """Two consecutive subranges' own predictions of one element at their common boundary.

    ``z = (upper_value - lower_value) / sqrt(lower_sigma^2 + upper_sigma^2)``.
    """

    element: str
    lower: str
    upper: str
    t_degC: float
    lower_value: float
    lower_sigma: float
    upper_value: float
    upper_sigma: float

    @property
    def difference(self):
        return self.upper_value - self.lower_value

    @property
    def sigma(self):
        return float(np.hypot(self.lower_sigma, self.upper_sigma))

    @property
    def z(self):
        s = self.sigma
        return self.difference / s if s > 0 else 0.0

    def to_dict(self):
        return {"element": self.element, "t_degC": self.t_degC,
                "lower": self.lower, "lower_value": self.lower_value, "lower_sigma": self.lower_sigma,
                "upper": self.upper, "upper_value": self.upper_value, "upper_sigma": self.upper_sigma,
                "difference": self.difference, "z": self.z}


@dataclass(frozen=True)
class ElementCurve:
    """One element over the whole range: the subrange points, the fits, the boundary checks."""

    element: str
    parameter: str
    sensor: int | None
    temperature_dependent: bool
    points: tuple
    fits: dict
    boundaries: tuple

    @property
    def default_model(self):
        return "cubic" if self.temperature_dependent else "constant"

    def fit(self, model=None):
        """The :class:`Fit` called ``model`` (the default model when None; ``cubic`` and ``constant``
        stand for each other, so one name serves every element)."""
        m = model or self.default_model
        if m not in self.fits:
            m = {"cubic": "constant", "constant": "cubic"}.get(m, m)
        return self.fits[m]

    def evaluate(self, T, model=None):
        """``(value, sigma)`` of the stitched ``model`` at temperatures ``T`` (degC), SI."""
        return self.fit(model).evaluate(T)

    @property
    def t_span(self):
        """Lowest and highest sensor temperature over the subranges, degC."""
        return (min(p.t_range[0] for p in self.points), max(p.t_range[1] for p in self.points))

    def to_dict(self):
        return {
            "element": self.element, "parameter": self.parameter,
            "sensor": None if self.sensor is None else SENSORS[self.sensor],
            "temperature_dependent": self.temperature_dependent,
            "points": [{"name": p.name, "t_ref_degC": p.t_ref_degC, "coefficients": p.coef, "covariance": p.cov,
                        "t_range_degC": list(p.t_range)} for p in self.points],
            "fits": {k: f.to_dict() for k, f in self.fits.items()},
            "boundaries": [b.to_dict() for b in self.boundaries],
        }


@dataclass(frozen=True)
class Stitched:
    """Every stitched element of one solver's campaign results.

    Attributes
    ----------
    solver : str
    subranges : tuple of str
        Experiment names, ordered by reference temperature.
    curves : dict
        ``{flat element name: ElementCurve}``.
    """

    solver: str
    subranges: tuple
    curves: dict = field(default_factory=dict)

    def parameters(self):
        """Stitched parameter names, catalogue order."""
        names = {c.parameter for c in self.curves.values()}
        return [p.name for p in REGISTRY if p.name in names]

    def elements(self, parameter):
        return [c for c in self.curves.values() if c.parameter == parameter]

    def evaluate(self, T_sensors, model=None):
        """Every stitched element at the sensor temperatures of each row.

        Parameters
        ----------
        T_sensors : array_like, shape (N, 6)
            Temperatures of gyro x, y, z and accel x, y, z, degC.
        model : str, optional
            ``"linear"`` or ``"cubic"`` (elements without temperature
            coefficients use ``"linear"`` or ``"constant"`` respectively); the
            default model when None.

        Returns
        -------
        dict
            ``{flat element name: values (N,)}``, SI.
        """
        return {name: c.evaluate(sensor_columns(T_sensors, c.sensor), model)[0] for name, c in self.curves.items()}

    def element_sigmas(self, T_sensors, model=None):
        """One sigma of every stitched element at the sensor temperatures, ``{flat element name: (N,)}``."""
        return {name: c.evaluate(sensor_columns(T_sensors, c.sensor), model)[1] for name, c in self.curves.items()}

    def boundary_checks(self):
        return [b for c in self.curves.values() for b in c.boundaries]

    def boundary_summary(self, *, limit=BOUNDARY_Z_LIMIT):
        """Summary of the boundary check: per boundary and overall, ``max |z|`` and the elements beyond ``limit``."""
        checks = self.boundary_checks()
        per = {}
        for b in checks:
            key = f"{b.lower} | {b.upper}"
            e = per.setdefault(key, {"lower": b.lower, "upper": b.upper, "checks": 0, "max_abs_z": 0.0,
                                     "worst": None, "beyond_limit": []})
            e["checks"] += 1
            if abs(b.z) >= e["max_abs_z"]:
                e["max_abs_z"], e["worst"] = abs(b.z), b.element
            if abs(b.z) > limit:
                e["beyond_limit"].append(b.element)
        zs = np.array([abs(b.z) for b in checks]) if checks else np.zeros(0)
        family_limit = family_z_limit(zs.size)
        return {
            "limit": limit, "checks": int(zs.size), "max_abs_z": float(zs.max()) if zs.size else 0.0,
            "rms_z": float(np.sqrt(np.mean(zs**2))) if zs.size else 0.0,
            "beyond_limit": int(np.count_nonzero(zs > limit)),
            "family_limit": family_limit,
            "consistent": bool(zs.size == 0 or zs.max() <= family_limit),
            "boundaries": list(per.values()),
        }

    def to_dict(self):
        return {"solver": self.solver, "subranges": list(self.subranges),
                "boundary_check": self.boundary_summary(),
                "elements": {k: c.to_dict() for k, c in self.curves.items()}}


# ---------------------------------------------------------------------------
# fitting
# ---------------------------------------------------------------------------


def family_z_limit(n_checks, *, false_alarm=FAMILY_FALSE_ALARM):
    """|z| that the largest of ``n_checks`` independent N(0,1) values exceeds with probability ``false_alarm``.

    With many checks a few beyond 3 sigma are expected by chance (105 checks: 0.3 on
    average); the campaign's verdict uses this limit (about 3.9 for 105 checks at 1 %).
    """
    from scipy.stats import norm

    if n_checks <= 0:
        return BOUNDARY_Z_LIMIT
    return float(max(BOUNDARY_Z_LIMIT, norm.isf(0.5 * (1.0 - (1.0 - false_alarm) ** (1.0 / n_checks)))))


def _gls(kind, points, *, knots=None, center=0.0, scale=1.0, degree=3, clamp=False, orders=None):
    """Generalised least squares of one family to the points' Taylor coefficients."""
    if kind == "linear":
        n_theta = knots.size
        proto = Fit(kind, np.zeros(n_theta), np.zeros((n_theta, n_theta)), 0.0, 0, knots=knots, clamp=clamp)
    else:
        n_theta = degree + 1
        proto = Fit(kind, np.zeros(n_theta), np.zeros((n_theta, n_theta)), 0.0, 0, center=center, scale=scale)
    A_rows, y_rows = [], []
    for p in points:
        d = p.coef.size if orders is None else min(orders, p.coef.size)
        A = np.vstack([proto.rows([p.t_ref_degC], k) for k in range(d)])
        y = p.coef[:d]
        S = p.cov[:d, :d]
        # whiten with the Cholesky factor (a tiny jitter guards exactly singular blocks)
        jitter = 1e-12 * np.max(np.diag(S)) if np.max(np.diag(S)) > 0 else 1e-300
        L = np.linalg.cholesky(S + jitter * np.eye(d))
        keep = np.any(A != 0.0, axis=1)  # a family without that derivative (linear: curvature) ignores it
        Aw = np.linalg.solve(L, A)
        yw = np.linalg.solve(L, y)
        if not np.all(keep):
            idx = np.flatnonzero(keep)
            S2 = S[np.ix_(idx, idx)] + jitter * np.eye(idx.size)
            L2 = np.linalg.cholesky(S2)
            Aw, yw = np.linalg.solve(L2, A[idx]), np.linalg.solve(L2, y[idx])
        A_rows.append(Aw)
        y_rows.append(yw)
    A = np.vstack(A_rows)
    y = np.concatenate(y_rows)
    theta, *_ = np.linalg.lstsq(A, y, rcond=None)
    N = A.T @ A
    cov = np.linalg.pinv(N)
    r = y - A @ theta
    chi2 = float(r @ r)
    dof = int(A.shape[0] - np.linalg.matrix_rank(A))
    if dof > 0 and chi2 / dof > 1.0:
        cov = cov * (chi2 / dof)
    return Fit(kind, theta, cov, chi2, dof, knots=proto.knots, center=center, scale=scale, clamp=clamp)


def boundary_temperature(lower, upper):
    """Common boundary of two consecutive subranges on one sensor's temperature axis, degC.

    The middle between the top of the lower subrange's coverage and the bottom of
    the upper one's (the middle of their overlap when they overlap), kept
    strictly between the two reference temperatures.
    """
    tb = 0.5 * (lower.t_range[1] + upper.t_range[0])
    lo, hi = lower.t_ref_degC, upper.t_ref_degC
    if hi > lo:
        tb = min(max(tb, lo + 0.05 * (hi - lo)), hi - 0.05 * (hi - lo))
    return float(tb)


def _merged_knots(temps):
    knots = np.array(sorted({round(float(t), 9) for t in temps}))
    merged = []
    for t in knots:  # knots closer than the spacing merge
        if not merged or t - merged[-1] >= MIN_KNOT_SPACING_DEGC:
            merged.append(t)
    return np.array(merged)


def fit_element(element, points):
    """Fit every model of one element and check its boundaries; an :class:`ElementCurve`.

    An element is temperature dependent when its parameter has temperature
    coefficients in the catalogue (``gyro.bias`` has ``gyro.bias_tc``), even if
    the results hold only its values (a calibration at constant temperature):
    then the ``linear`` model interpolates the values (knots at the reference
    temperatures, continued linearly outside) and the ``cubic`` fits the values
    alone; the boundary check needs the subranges' slopes and is skipped.
    """
    parameter = params.split_element_name(element)[0]
    points = tuple(sorted(points, key=lambda p: p.t_ref_degC))
    tdep = bool(family(parameter)[1]) or any(p.coef.size > 1 for p in points)
    slopes = all(p.coef.size > 1 for p in points)
    fits = {}
    lo = min(min(p.t_range[0] for p in points), points[0].t_ref_degC)
    hi = max(max(p.t_range[1] for p in points), points[-1].t_ref_degC)
    if tdep:
        if slopes:
            inner = []
            for a, b in zip(points[:-1], points[1:]):
                if b.t_ref_degC - a.t_ref_degC >= MIN_KNOT_SPACING_DEGC:
                    inner.append(boundary_temperature(a, b))
            knots = np.array([lo] + inner + [hi])
            if hi - lo < 1e-6:
                knots = np.array([lo, lo + 1.0])
        else:
            knots = _merged_knots([p.t_ref_degC for p in points])
        fits["linear"] = _gls("linear", points, knots=knots, orders=2)
        n_meas = sum(min(p.coef.size, 4) for p in points)
        center = 0.5 * (lo + hi)
        scale = max(0.5 * (hi - lo), 1.0)
        fits["cubic"] = _gls("cubic", points, center=center, scale=scale, degree=min(3, n_meas - 1))
    else:
        knots = _merged_knots([p.t_ref_degC for p in points])
        fits["linear"] = _gls("linear", points, knots=knots, clamp=True, orders=1)
        fits["constant"] = _gls("constant", points, center=0.0, scale=1.0, degree=0, orders=1)
    boundaries = []
    for a, b in zip(points[:-1], points[1:]):
        if tdep and not (a.coef.size > 1 and b.coef.size > 1):
            continue
        tb = boundary_temperature(a, b)
        va, sa = a.predict([tb])
        vb, sb = b.predict([tb])
        boundaries.append(BoundaryCheck(element, a.name, b.name, tb, float(va[0]), float(sa[0]),
                                        float(vb[0]), float(sb[0])))
    return ElementCurve(element=element, parameter=parameter, sensor=sensor_of(element), temperature_dependent=tdep,
                        points=points, fits=fits, boundaries=tuple(boundaries))


def _cov_block(result, names):
    """Covariance of ``names`` from a result (its full matrix, else its sigmas)."""
    if result.covariance is not None and result.covariance_names is not None:
        idx = {n: i for i, n in enumerate(result.covariance_names)}
        if all(n in idx for n in names):
            ii = [idx[n] for n in names]
            return np.asarray(result.covariance, dtype=float)[np.ix_(ii, ii)]
    return np.diag([float(result.sigmas[n]) ** 2 for n in names])


def result_points(result, *, name=None, sensor_ranges=None, values=None):
    """Every stitched element of one result as a :class:`SubrangePoint`, ``{flat element: point}``.

    Parameters
    ----------
    result : graph_calib.experiment.Result
    name : str, optional
        Label of the points (default: the result's source).
    sensor_ranges : array_like (6, 2), optional
        Temperature range of each sensor (default: the result's range for all).
    values : dict, optional
        Values to use instead of ``result.values`` (e.g. with a truth's curvature remainder added).
        Coefficients are taken in order (value, ``_tc``, ``_tc2``) up to the first one absent; the
        covariance comes from the result (zero without sigmas: a truth).
    """
    values = result.values if values is None else values
    rg = (np.tile(np.asarray(result.temperature_range_degC, dtype=float), (6, 1)) if sensor_ranges is None
          else np.asarray(sensor_ranges, dtype=float).reshape(6, 2))
    out = {}
    for flat in values:
        try:
            parameter, el = params.split_element_name(flat)
        except KeyError:
            continue
        if not is_stitched(parameter):
            continue
        coef_names = [flat]
        for _, cn in sorted(family(parameter)[1].items()):
            cn = cn if el is None else f"{cn}.{el}"
            if cn not in values:
                break
            coef_names.append(cn)
        coef = np.array([float(values[n]) for n in coef_names])
        cov = _cov_block(result, coef_names) if result.sigmas is not None else np.zeros((coef.size, coef.size))
        s = sensor_of(flat)
        t_range = tuple(float(v) for v in (rg[s] if s is not None else rg.mean(axis=0)))
        out[flat] = SubrangePoint(name or result.source, float(result.t_ref_degC), coef, cov, t_range)
    return out


def sensor_columns(T_sensors, sensor):
    """The temperature an element follows: its sensor's column of ``T_sensors`` (N, 6), else their mean."""
    T = np.atleast_2d(np.asarray(T_sensors, dtype=float))
    return T[:, sensor] if sensor is not None else T.mean(axis=1)


def stitch(results, *, names=None, sensor_ranges=None, solver=None):
    """Stitch per-subrange results of one IMU into a model of every IMU parameter over temperature.

    Parameters
    ----------
    results : sequence of graph_calib.experiment.Result
        One per subrange (same solver), each with sigmas and preferably its covariance.
    names : sequence of str, optional
        Experiment names (default: the results' sources).
    sensor_ranges : sequence of array_like (6, 2), optional
        Per result, the lowest and highest temperature of each sensor (:data:`SENSORS`),
        degC.  Default: the result's ``temperature_range_degC`` for every sensor.
    solver : str, optional
        Label (default: the first result's solver).

    Returns
    -------
    Stitched
    """
    results = list(results)
    if not results:
        raise ValueError("nothing to stitch: no results")
    names = list(names) if names is not None else [r.source for r in results]
    if len(set(names)) != len(names):
        raise ValueError(f"experiment names must be unique, got {names}")
    ranges = []
    for i, r in enumerate(results):
        if sensor_ranges is not None and sensor_ranges[i] is not None:
            ranges.append(np.asarray(sensor_ranges[i], dtype=float).reshape(6, 2))
        else:
            ranges.append(np.tile(np.asarray(r.temperature_range_degC, dtype=float), (6, 1)))
    points = {}
    for r, nm, rg in zip(results, names, ranges):
        if r.sigmas is None:
            raise ValueError(f"{nm}: a result without sigmas (truth?) cannot be stitched")
        for flat, pt in result_points(r, name=nm, sensor_ranges=rg).items():
            points.setdefault(flat, []).append(pt)
    curves = {}
    order = {n: i for i, n in enumerate(p.name for p in REGISTRY)}
    for flat in sorted(points, key=lambda f: (order[params.split_element_name(f)[0]], f)):
        curves[flat] = fit_element(flat, points[flat])
    ordered = [nm for _, nm in sorted(zip([r.t_ref_degC for r in results], names))]
    return Stitched(solver=solver or results[0].solver, subranges=tuple(ordered), curves=curves)


__all__ = ["SENSORS", "MODELS", "BOUNDARY_Z_LIMIT", "sensor_of", "family", "is_stitched", "SubrangePoint", "Fit", "family_z_limit",
           "BoundaryCheck", "ElementCurve", "Stitched", "boundary_temperature", "fit_element", "stitch",
           "result_points", "sensor_columns"]
