r"""The degree of each joint curve family, chosen by a rule that controls the error it leaves, in sigma.

The joint solve estimates every temperature family (``gyro.bias``, ``gyro.scale``, ``accel.bias``,
``accel.scale``) at the highest degree the effect registry holds (:data:`graph_calib.sensors.effects.MAX_TEMPERATURE_ORDER`,
5).  Then per family, from the highest order down to 2, the order's coefficients ``c`` (all three axes) are
tested against zero with their covariance ``Sigma`` from the joint solution:

.. math::

    W = c^T \Sigma^{-1} c \;\sim\; \chi^2_k \text{ under the null } (k = 3),

and the order is kept when ``W > chi2.isf(alpha, k)`` (``alpha`` = :data:`DEGREE_ALPHA`, 0.01, the closed
loop's level per decision; 11.3 for three coefficients).  An order that is not kept is dropped: the estimate
is conditioned on its coefficients being zero (the Gauss-Newton solution of the smaller model at the same
linearisation point) and the next lower order is tested.  The linear terms are declared and always kept.

Why not the Bayesian information criterion: its price ``k ln n`` grows with the number of measurements (41
for three coefficients at about 300,000), so on a long campaign it drops an order whose coefficients are
six or seven sigma from zero and leaves that much error in the curve.  The Wald test's threshold does not
grow with ``n``: what it drops is, jointly, within about 3.4 sigma of zero, so the error the dropped order
leaves is bounded in the sigma of the model that holds it.  In the reported (lower-degree) curve's own sigma, which
is smaller, it can be more: at the edge of the range the leftover can reach 4 of them (docs/campaign.md, "Seeds").

**The next order.**  For every family the test of the order past the chosen degree is part of the evidence
(``next_order``): below its threshold when the chosen degree is lower than the registry's highest; when the
highest order itself was needed, the curve has no capacity left to test, and ``next_order.passed`` is False
with the reason in words: the campaign's verdict fails on it
(:mod:`graph_calib.campaign.checks`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import stats
from scipy.special import gammaln

from graph_calib.sensors.params import split_element_name
from graph_calib.solvers.joint.unknowns import curve_label

#: Level of each order's Wald test (the closed loop's per-decision level).
DEGREE_ALPHA = 0.01

#: The rule in words (result file, campaign.json, report).
DEGREE_RULE = ("per family, from the highest order down to 2: the order's coefficients (three axes) tested against "
               "zero by their Wald statistic from the joint covariance, kept when above chi2.isf(alpha, 3); a dropped "
               "order conditions the estimate on its coefficients being zero")


@dataclass(frozen=True)
class DegreeEvidence:
    """The evidence for one curve family's degree.

    Attributes
    ----------
    family : str
        ``gyro.bias``, ...
    degree : int
        Degree kept.
    tests : list of dict
        Per order tested (highest first): ``order``, ``wald``, ``k`` (coefficients), ``threshold``
        (``chi2.isf(alpha, k)``), ``log10_p``, ``kept``.
    next_order : dict
        The test of order ``degree + 1``: ``order``, ``wald``, ``threshold``, ``passed`` (not significant), and
        ``text``; with ``wald`` None when ``degree`` is the highest order the curves hold (``passed`` False).
    alpha : float
    """

    family: str
    degree: int
    tests: list
    next_order: dict
    alpha: float = DEGREE_ALPHA

    def to_json(self):
        return {"family": self.family, "degree": self.degree, "rule": "wald", "alpha": self.alpha,
                "tests": list(self.tests), "next_order": dict(self.next_order)}


def log10_chi2_sf(statistic, dof):
    """``log10 P(chi2_dof > statistic)``, finite far in the tail (where ``chi2.sf`` underflows to 0)."""
    x, k = float(statistic), int(dof)
    v = float(stats.chi2.logsf(x, k))
    if np.isfinite(v):
        return v / np.log(10.0)
    # the leading term of the upper incomplete gamma function: x^(k/2-1) e^(-x/2) / (2^(k/2-1) Gamma(k/2))
    h = 0.5 * k
    return float(((h - 1.0) * np.log(x) - 0.5 * x - (h - 1.0) * np.log(2.0) - gammaln(h)) / np.log(10.0))


def _next_order(family, degree, max_degree, tests):
    if degree >= max_degree:
        return {"order": degree + 1, "wald": None, "threshold": None, "passed": False,
                "text": f"{family}: order {degree} (the highest the curves hold) is significant, so an order "
                        f"{degree + 1} cannot be ruled out: the curve may lack the capacity the data need"}
    t = next(t for t in tests if t["order"] == degree + 1)
    return {"order": degree + 1, "wald": t["wald"], "threshold": t["threshold"], "passed": not t["kept"],
            "text": f"{family}: order {degree + 1} Wald {t['wald']:.3g} <= {t['threshold']:.3g} (alpha {t['alpha']:g})"}


def choose_degrees_wald(unknowns, theta, covariance, *, n_measurements=None, alpha=DEGREE_ALPHA):
    """Each curve family's degree by the Wald test at ``alpha`` (module docstring).

    Parameters
    ----------
    unknowns : graph_calib.solvers.joint.unknowns.Unknowns
        At the full degrees.
    theta : ndarray, shape (Nt,)
    covariance : ndarray, shape (Nt, Nt)
    n_measurements : int, optional
        Not used by the rule (kept for the solver's call).
    alpha : float

    Returns
    -------
    unknowns : Unknowns
        With the degrees kept.
    keep : ndarray of bool, shape (Nt,)
        Which entries of ``theta`` remain.
    theta, covariance : ndarray
        Conditioned on the dropped coefficients being zero (full size; dropped entries zero).
    choices : tuple of DegreeEvidence
    """
    th = np.asarray(theta, dtype=float).copy()
    C = np.asarray(covariance, dtype=float).copy()
    keep = np.ones(th.size, dtype=bool)
    idx = unknowns.z_index()
    degrees, choices = dict(unknowns.degrees), []
    for base, d_max in unknowns.degrees.items():
        elements = [f for f in unknowns.curve_elements() if split_element_name(f)[0] == base]
        tests, d = [], d_max
        while d >= 2:
            D = [idx[curve_label(f, d)] for f in elements]
            cD, CD = th[D], C[np.ix_(D, D)]
            wald = float(cD @ np.linalg.lstsq(CD, cD, rcond=None)[0])
            threshold = float(stats.chi2.isf(alpha, len(D)))
            kept = wald > threshold
            tests.append({"order": d, "wald": wald, "k": len(D), "threshold": threshold, "alpha": alpha,
                          "log10_p": log10_chi2_sf(wald, len(D)), "kept": bool(kept)})
            if kept:
                break
            G = np.linalg.lstsq(CD, C[D, :], rcond=None)[0].T          # C[:, D] CD^-1
            th = th - G @ cD
            C = C - G @ C[D, :]
            C = 0.5 * (C + C.T)
            th[D] = 0.0
            C[D, :] = 0.0
            C[:, D] = 0.0
            keep[D] = False
            d -= 1
        degrees[base] = d
        choices.append(DegreeEvidence(family=base, degree=d, tests=tests, next_order=_next_order(base, d, d_max, tests),
                                      alpha=alpha))
    z_names = tuple(n for n, k in zip(unknowns.z_names, keep[:unknowns.nz]) if k)
    reduced = replace(unknowns, degrees=degrees, z_names=z_names)
    return reduced, keep, th, C, tuple(choices)


__all__ = ["DEGREE_ALPHA", "DEGREE_RULE", "DegreeEvidence", "choose_degrees_wald"]
