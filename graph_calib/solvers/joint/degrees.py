r"""The degree of each joint curve family, chosen by a rule that controls the error it leaves, in sigma.

The joint solve estimates every temperature family (``gyro.bias``, ``gyro.scale``, ``accel.bias``,
``accel.scale``) at the highest degree the effect registry holds (:data:`graph_calib.sensors.effects.MAX_TEMPERATURE_ORDER`,
5).  Two questions are then answered per family, from the highest order down.

**Which orders the data show** (the evidence).  The order's coefficients ``c`` (all three axes) are tested
against zero with their covariance ``Sigma`` from the joint solution:

.. math::

    W = c^T \Sigma^{-1} c \;\sim\; \chi^2_k \text{ under the null } (k = 3),

significant when ``W > chi2.isf(alpha, k)`` (``alpha`` = :data:`DEGREE_ALPHA`, 0.01, the closed loop's level
per decision; 11.3 for three coefficients).  An order that is not significant is conditioned to zero
(the Gauss-Newton solution of the smaller model at the same linearisation point) and the next lower order
is tested.  The highest significant order is the family's ``significant_degree`` (1 when none is: the linear
terms are declared).

**Which orders the reported curve holds** (the error it leaves).  Dropping an order the test did not see
is not free: a real order a test of limited power misses stays in the curve as an error its sigma does not
cover (model selection makes the reported sigma optimistic).  On ten simulated six-subrange campaigns with
cubic truths, curves cut back to the significant degree left two campaigns with points 3.7-4.0 sigma off and
86-89 % within 2 sigma, where the curves holding every order stayed within 3.84 sigma and 91.7 % (docs/
campaign.md, "Curve degree").  So an order that is not significant is dropped only when holding it costs
much: when it widens the family's curve sigma by more than :data:`RHO_MAX` (1.5) somewhere over its
sensor's temperature span,

.. math::

    \rho = \max_T \frac{\sigma_{d}(T)}{\sigma_{d-1}(T)} > \rho_{max},

(``sigma_d`` the curve's sigma holding orders up to ``d``, ``sigma_{d-1}`` with order ``d`` conditioned to
zero, both with every higher order conditioned out).  The curve holds every order up to its ``degree``, never
fewer than the significant ones: from the significant degree up, each order whose step costs at most
``RHO_MAX``, up to the first that costs more, which goes with every order above it (a top order the priors
hold cheaply does not keep a loose one below it).  Where the data (or, over a short record's narrow span, the priors)
constrain every order, the curve keeps the registry's full degree: on the six-subrange campaigns each step's
``rho`` was 1.25-1.37, and the total price, the curve's sigma over the significant curve's (``widening``,
recorded), 1.27-2.27 at the range's edges.  An order whose step costs more than ``RHO_MAX`` goes, and so the
curve never holds an order the data and priors leave loose.

**The next order.**  For every family the test of the order past the significant degree is part of the
evidence (``next_order``): below its threshold when the significant degree is lower than the registry's
highest; when the highest order itself is significant, the curve has no capacity left to test, and
``next_order.passed`` is False with the reason in words: the campaign's verdict fails on it
(:mod:`graph_calib.campaign.checks`).

Why not the Bayesian information criterion: its price ``k ln n`` grows with the number of measurements (41
for three coefficients at about 300,000), so on a long campaign it drops an order whose coefficients are
six or seven sigma from zero and leaves that much error in the curve.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import stats
from scipy.special import gammaln

from graph_calib.sensors.params import sensor_of, split_element_name
from graph_calib.solvers.joint.unknowns import curve_label, curve_row

#: Level of each order's Wald test (the closed loop's per-decision level).
DEGREE_ALPHA = 0.01
#: An order the Wald test did not see is dropped from the curve only when holding it widens the curve's
#: sigma by more than this factor somewhere over the sensor's span.
RHO_MAX = 1.5
#: Temperatures per sensor span at which ``rho`` is evaluated.
RHO_POINTS = 21

#: The rule in words (result file, campaign.json, report).
DEGREE_RULE = ("per family, from the highest order down: the order's coefficients (three axes) tested against zero "
               "by their Wald statistic from the joint covariance (significant above chi2.isf(alpha, 3)); from the "
               "significant degree up, the curve holds each order not significant while holding it widens the "
               f"curve's sigma by at most {RHO_MAX:g} everywhere over the sensor's span, up to the first that widens "
               "it more, which is dropped with every order above it; a dropped order conditions the estimate on its "
               "coefficients being zero")


@dataclass(frozen=True)
class DegreeEvidence:
    """The evidence for one curve family's degree.

    Attributes
    ----------
    family : str
        ``gyro.bias``, ...
    degree : int
        Degree the reported curve holds.
    significant_degree : int
        Highest order the Wald tests find significant (1 when none is).
    widening : float
        The price of the orders the curve holds beyond the significant ones: ``max_T`` of the reported curve's
        sigma over the significant curve's, over the sensors' spans (1 when it holds none).
    tests : list of dict
        Per order tested (highest first): ``order``, ``wald``, ``k`` (coefficients), ``threshold``
        (``chi2.isf(alpha, k)``), ``log10_p``, ``significant``, ``rho`` (the widening holding it causes; None
        at or below the significant degree), ``kept`` (in the reported curve).
    next_order : dict
        The test of order ``significant_degree + 1``: ``order``, ``wald``, ``threshold``, ``passed`` (not
        significant), and ``text``; with ``wald`` None when the significant degree is the highest order the
        curves hold (``passed`` False).
    alpha : float
    """

    family: str
    degree: int
    significant_degree: int
    widening: float
    tests: list
    next_order: dict
    alpha: float = DEGREE_ALPHA

    def to_json(self):
        return {"family": self.family, "degree": self.degree, "significant_degree": self.significant_degree,
                "widening": self.widening,
                "rule": "wald+rho", "alpha": self.alpha, "rho_max": RHO_MAX, "tests": list(self.tests),
                "next_order": dict(self.next_order)}


def log10_chi2_sf(statistic, dof):
    """``log10 P(chi2_dof > statistic)``, finite far in the tail (where ``chi2.sf`` underflows to 0)."""
    x, k = float(statistic), int(dof)
    v = float(stats.chi2.logsf(x, k))
    if np.isfinite(v):
        return v / np.log(10.0)
    # the leading term of the upper incomplete gamma function: x^(k/2-1) e^(-x/2) / (2^(k/2-1) Gamma(k/2))
    h = 0.5 * k
    return float(((h - 1.0) * np.log(x) - 0.5 * x - (h - 1.0) * np.log(2.0) - gammaln(h)) / np.log(10.0))


def _next_order(family, significant, max_degree, tests):
    if significant >= max_degree:
        return {"order": significant + 1, "wald": None, "threshold": None, "passed": False,
                "text": f"{family}: order {significant} (the highest the curves hold) is significant, so an order "
                        f"{significant + 1} cannot be ruled out: the curve may lack the capacity the data need"}
    t = next(t for t in tests if t["order"] == significant + 1)
    return {"order": significant + 1, "wald": t["wald"], "threshold": t["threshold"], "passed": not t["significant"],
            "text": f"{family}: order {significant + 1} Wald {t['wald']:.3g} <= {t['threshold']:.3g} (alpha {t['alpha']:g})"}


def _condition(th, C, D):
    """``(th, C)`` conditioned on ``th[D] = 0`` (dropped entries zero)."""
    cD = th[D]
    G = np.linalg.lstsq(C[np.ix_(D, D)], C[D, :], rcond=None)[0].T          # C[:, D] C_DD^-1
    th = th - G @ cD
    C = C - G @ C[D, :]
    C = 0.5 * (C + C.T)
    th[D] = 0.0
    C[D, :] = 0.0
    C[:, D] = 0.0
    return th, C


def _curve_sigma(C, cols, V):
    return np.sqrt(np.clip(np.einsum("ij,jk,ik->i", V, C[np.ix_(cols, cols)], V), 0.0, None))


def _widening(unknowns, elements, spans, *, high, low):
    """``max_T sigma_high(T) / sigma_low(T)`` over the family's elements and their sensors' spans: ``high`` and
    ``low`` are ``(covariance, degree)`` of the same curve holding more and fewer orders."""
    idx = unknowns.z_index()
    (C_hi, d_hi), (C_lo, d_lo) = high, low
    rho = 1.0
    for f in elements:
        T = np.linspace(*spans[sensor_of(f)], RHO_POINTS)
        V = curve_row(T, unknowns.t0_degC, d_hi)
        cols = [idx[curve_label(f, k)] for k in range(d_hi + 1)]
        s_hi = _curve_sigma(C_hi, cols, V)
        s_lo = _curve_sigma(C_lo, cols[:d_lo + 1], V[:, :d_lo + 1])
        ok = s_lo > 0
        if np.any(ok):
            rho = max(rho, float(np.max(s_hi[ok] / s_lo[ok])))
    return rho


def choose_degrees(unknowns, theta, covariance, *, sensor_spans, alpha=DEGREE_ALPHA, rho_max=RHO_MAX):
    """Each curve family's significant degree and the degree its reported curve holds (module docstring).

    Parameters
    ----------
    unknowns : graph_calib.solvers.joint.unknowns.Unknowns
        At the full degrees.
    theta : ndarray, shape (Nt,)
    covariance : ndarray, shape (Nt, Nt)
    sensor_spans : array_like, shape (6, 2)
        Each sensor's temperature span over the campaign (gyro x, y, z, accel x, y, z), degC: where the curve's
        widening is judged.
    alpha : float
    rho_max : float

    Returns
    -------
    unknowns : Unknowns
        With the degrees the reported curves hold.
    keep : ndarray of bool, shape (Nt,)
        Which entries of ``theta`` remain.
    theta, covariance : ndarray
        Conditioned on the dropped coefficients being zero (full size; dropped entries zero).
    choices : tuple of DegreeEvidence
    """
    spans = np.asarray(sensor_spans, dtype=float).reshape(6, 2)
    th = np.asarray(theta, dtype=float).copy()
    C = np.asarray(covariance, dtype=float).copy()
    keep = np.ones(th.size, dtype=bool)
    idx = unknowns.z_index()
    degrees, choices = dict(unknowns.degrees), []
    for base, d_max in unknowns.degrees.items():
        elements = [f for f in unknowns.curve_elements() if split_element_name(f)[0] == base]
        tests, significant = [], 1
        th_e, C_e = th, C                    # the evidence's descent: every order not significant conditioned out
        held = {d_max: (th, C)}              # the estimate holding the orders up to each degree
        for d in range(d_max, 1, -1):
            D = [idx[curve_label(f, d)] for f in elements]
            cD, CD = th_e[D], C_e[np.ix_(D, D)]
            wald = float(cD @ np.linalg.lstsq(CD, cD, rcond=None)[0])
            threshold = float(stats.chi2.isf(alpha, len(D)))
            test = {"order": d, "wald": wald, "k": len(D), "threshold": threshold, "alpha": alpha,
                    "log10_p": log10_chi2_sf(wald, len(D)), "significant": bool(wald > threshold), "rho": None}
            tests.append(test)
            if test["significant"]:
                significant = d
                break
            th_next, C_next = _condition(th_e, C_e, D)
            test["rho"] = _widening(unknowns, elements, spans, high=(C_e, d), low=(C_next, d - 1))
            th_e, C_e = th_next, C_next
            held[d - 1] = (th_e, C_e)
        # from the significant degree up, each order while holding it costs at most rho_max: an order that costs
        # more goes, and every order above it (a cheap top order does not keep a dear one below it)
        rho = {t["order"]: t["rho"] for t in tests}
        degree = significant
        while degree < d_max and rho.get(degree + 1) is not None and rho[degree + 1] <= rho_max:
            degree += 1
        if degree < d_max:
            th, C = held[degree]
            for d in range(degree + 1, d_max + 1):
                keep[[idx[curve_label(f, d)] for f in elements]] = False
        for t in tests:
            t["kept"] = t["order"] <= degree
        widening = (_widening(unknowns, elements, spans, high=(C, degree), low=(C_e, significant))
                    if degree > significant else 1.0)
        degrees[base] = degree
        choices.append(DegreeEvidence(family=base, degree=degree, significant_degree=significant, widening=widening,
                                      tests=tests,
                                      next_order=_next_order(base, significant, d_max, tests), alpha=alpha))
    z_names = tuple(n for n, k in zip(unknowns.z_names, keep[:unknowns.nz]) if k)
    reduced = replace(unknowns, degrees=degrees, z_names=z_names)
    return reduced, keep, th, C, tuple(choices)


__all__ = ["DEGREE_ALPHA", "DEGREE_RULE", "RHO_MAX", "DegreeEvidence", "choose_degrees"]
