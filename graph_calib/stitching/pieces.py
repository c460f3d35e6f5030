"""The pieces of a stitched calibration: subrange points, fits, boundary checks, element curves, the whole.

Also the small rules they share: which sensor's temperature an element follows
(:func:`sensor_of`, :func:`sensor_columns`), which parameters get a curve
(:func:`family`, :func:`is_stitched`) and the limit of the boundary verdict
(:func:`family_z_limit`).  The method is described in :mod:`graph_calib.stitching`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import comb

import numpy as np
from scipy.stats import norm

from graph_calib.sensors import params
from graph_calib.sensors.params import SENSORS, sensor_of
from graph_calib.sensors.curves import evaluate_polynomial_curve
from graph_calib.sensors.effects import REGISTRY, temperature_family

#: Models that :func:`graph_calib.stitching.stitch` fits.
MODELS = ("linear", "cubic", "constant")

#: Largest |z| of the boundary check that counts as consistent.
BOUNDARY_Z_LIMIT = 3.0

#: Family-wise false-alarm probability of the boundary verdict (see :func:`family_z_limit`).
FAMILY_FALSE_ALARM = 0.01


def family(parameter):
    """``(base, {order: coefficient name})`` of a parameter: ``gyro.bias_tc`` -> ``('gyro.bias', ...)``.

    The temperature coefficients of each parameter come from the effect registry
    (:func:`graph_calib.sensors.effects.temperature_family`).
    """
    return temperature_family(parameter)


def is_stitched(parameter):
    """Whether a parameter gets its own curve: an IMU parameter (gyro.*, accel.*) that is not a coefficient."""
    triad = parameter.split(".", 1)[0]
    return triad in ("gyro", "accel") and family(parameter)[0] == parameter


def sensor_columns(T_sensors, sensor):
    """The temperature an element follows: its sensor's column of ``T_sensors`` (N, 6), else their mean."""
    T = np.atleast_2d(np.asarray(T_sensors, dtype=float))
    return T[:, sensor] if sensor is not None else T.mean(axis=1)


def family_z_limit(n_checks, *, false_alarm=FAMILY_FALSE_ALARM):
    """|z| that the largest of ``n_checks`` independent N(0,1) values exceeds with probability ``false_alarm``.

    With many checks a few beyond 3 sigma are expected by chance (105 checks: 0.3 on
    average); the campaign's verdict uses this limit (about 3.9 for 105 checks at 1 %).
    """
    if n_checks <= 0:
        return BOUNDARY_Z_LIMIT
    return float(max(BOUNDARY_Z_LIMIT, norm.isf(0.5 * (1.0 - (1.0 - false_alarm) ** (1.0 / n_checks)))))


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
        ``[p, p_tc, p_tc2, ...]``, SI: the value and its temperature coefficients at ``t_ref_degC``, as
        many as the result holds (:func:`graph_calib.sensors.curves.evaluate_polynomial_curve` evaluates them).
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
        return evaluate_polynomial_curve(self.coef, T, t0_degC=self.t_ref_degC, covariance=self.cov)


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
            "checked": bool(zs.size > 0),     # nothing to check (one subrange) is "not checked", never "consistent"
            "consistent": bool(zs.size == 0 or zs.max() <= family_limit),
            "boundaries": list(per.values()),
        }

    def to_dict(self):
        return {"solver": self.solver, "subranges": list(self.subranges),
                "boundary_check": self.boundary_summary(),
                "elements": {k: c.to_dict() for k, c in self.curves.items()}}


__all__ = ["SENSORS", "MODELS", "BOUNDARY_Z_LIMIT", "FAMILY_FALSE_ALARM", "sensor_of", "family", "is_stitched",
           "sensor_columns", "family_z_limit", "SubrangePoint", "Fit", "BoundaryCheck", "ElementCurve", "Stitched"]
