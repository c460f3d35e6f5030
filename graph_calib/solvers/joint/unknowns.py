r"""The joint campaign's unknowns and each experiment's calibration vector as an exact affine map of them.

Every temperature-dependent element (a parameter of the registry with temperature coefficients:
``gyro.bias``, ``gyro.scale``, ``accel.bias``, ``accel.scale``) is one polynomial in its own
sensor's temperature over the whole campaign,

.. math::

    p(T) = \sum_{j=0}^{d} c_j\,(T - t_0)^j ,

with ``d`` its family's degree (at most the highest ``*_tc<k>`` the registry has: 3 for the biases, 2 for
the scales) and ``t_0`` one centre for the campaign.  An experiment with reference temperature
``T_ref`` models the same element as ``x_0 + x_1 dT + x_2 dT^2 + x_3 dT^3`` (``dT = T - T_ref``,
:mod:`graph_calib.sensors.sensor_model`); the Taylor expansion of the polynomial at ``T_ref`` is exact,

.. math::

    x_k = \sum_{j \ge k} \binom{j}{k} c_j\,(T_\mathrm{ref} - t_0)^{j-k},

so each experiment's calibration vector is ``x_e = A_e z + B_e s_e`` exactly, with ``z`` the curve
coefficients and the shared elements (misalignments, further sensor effects) and ``s_e`` the
experiment's set-up parameters (:data:`SETUP_PARAMETERS`: those without a sensor term, which belong to
how the unit sits on the table, not to the sensor).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

from graph_calib.sensors.effects import EFFECTS, REGISTRY
from graph_calib.sensors.params import split_element_name

#: Parameters of one set-up (one mounting on the table): the registry's parameters without a sensor term.
SETUP_PARAMETERS = tuple(e.name for e in REGISTRY if e.term is None)

#: Highest temperature order of each temperature family in the registry: ``{base: degree}``.
MAX_DEGREE = {}
for _e in REGISTRY:
    if _e.temperature_of is not None:
        MAX_DEGREE[_e.temperature_of] = max(MAX_DEGREE.get(_e.temperature_of, 0), _e.temperature_order)
del _e


def family_member(base, order):
    """The registry parameter of ``base`` with temperature order ``order`` (``base`` itself for 0)."""
    if order == 0:
        return base
    for e in REGISTRY:
        if e.temperature_of == base and e.temperature_order == order:
            return e.name
    raise KeyError(f"{base} has no temperature coefficient of order {order}")


def coefficient_terms(degrees):
    """The further effects an experiment's layout needs to hold curves of ``degrees`` (``{base: degree}``)."""
    return tuple(family_member(b, k) for b, d in degrees.items() for k in range(2, d + 1)
                 if not EFFECTS[family_member(b, k)].declared)


def curve_label(flat, order):
    """The name of a curve coefficient: ``gyro.bias.x:c2``."""
    return f"{flat}:c{order}"


@dataclass(frozen=True)
class Unknowns:
    """The joint unknowns: ``z`` (curves and shared elements) and each experiment's set-up ``s_e``.

    Attributes
    ----------
    t0_degC : float
        Centre of every curve, degC.
    degrees : dict
        ``{base parameter: degree}`` of the curve families estimated.
    z_names : tuple of str
        Names of ``z``: curve coefficients (:func:`curve_label`) and shared elements (flat names).
    setup_names : tuple of tuple of str
        Per experiment, the flat element names of ``s_e``.
    """

    t0_degC: float
    degrees: dict
    z_names: tuple
    setup_names: tuple

    @property
    def nz(self):
        return len(self.z_names)

    def z_index(self):
        return {n: i for i, n in enumerate(self.z_names)}

    def curve_columns(self, flat):
        """Columns of ``z`` holding the coefficients ``c_0..c_d`` of the element ``flat`` (``gyro.bias.x``)."""
        idx = self.z_index()
        cols = []
        j = 0
        while curve_label(flat, j) in idx:
            cols.append(idx[curve_label(flat, j)])
            j += 1
        return cols

    def curve_elements(self):
        """Flat names of the elements held as curves, in ``z`` order."""
        return [n.split(":")[0] for n in self.z_names if n.endswith(":c0")]

    def experiment_map(self, e, layout, t_ref_degC):
        """``(A, B)``: ``x_e = A z + B s_e`` for experiment ``e`` with ``layout`` and ``t_ref_degC``.

        Returns
        -------
        A : ndarray, shape (P, nz)
        B : ndarray, shape (P, len(setup_names[e]))
        """
        names = layout.element_names()
        A = np.zeros((len(names), self.nz))
        setup = {n: i for i, n in enumerate(self.setup_names[e])}
        B = np.zeros((len(names), len(setup)))
        idx = self.z_index()
        d = float(t_ref_degC) - self.t0_degC
        for i, flat in enumerate(names):
            if flat in setup:
                B[i, setup[flat]] = 1.0
                continue
            p, el = split_element_name(flat)
            eff = EFFECTS[p]
            base = eff.temperature_of or p
            if base in self.degrees:
                k = eff.temperature_order
                bflat = base if el is None else f"{base}.{el}"
                for j in range(k, self.degrees[base] + 1):
                    A[i, idx[curve_label(bflat, j)]] = comb(j, k) * d ** (j - k)
            else:
                A[i, idx[flat]] = 1.0
        return A, B


def plan_unknowns(layouts, t_refs, *, degrees=None):
    """The unknowns of a campaign whose experiments have ``layouts`` (extended to the curves' degrees).

    Parameters
    ----------
    layouts : sequence of graph_calib.sensors.params.Layout
    t_refs : sequence of float
        Reference temperatures, degC; ``t0`` is their mean rounded to 0.1 degC.
    degrees : dict, optional
        ``{base: degree}``; default :data:`MAX_DEGREE` for every family held by the first layout,
        lowered to the orders every layout holds.

    Returns
    -------
    Unknowns
    """
    first = layouts[0]
    if degrees is None:
        degrees = {}
        for base, dmax in MAX_DEGREE.items():
            if base not in first:
                continue
            d = 0
            while d < dmax and all(family_member(base, d + 1) in lay for lay in layouts):
                d += 1
            degrees[base] = d
    z, seen = [], set()
    for lay in layouts:
        for flat in lay.element_names():
            p, el = split_element_name(flat)
            if p in SETUP_PARAMETERS:
                continue
            eff = EFFECTS[p]
            base = eff.temperature_of or p
            if base in degrees:
                bflat = base if el is None else f"{base}.{el}"
                names = [curve_label(bflat, j) for j in range(degrees[base] + 1)]
            else:
                names = [flat]
            for n in names:
                if n not in seen:
                    seen.add(n)
                    z.append(n)
    setup = tuple(tuple(f for f in lay.element_names() if split_element_name(f)[0] in SETUP_PARAMETERS)
                  for lay in layouts)
    t0 = round(float(np.mean(t_refs)), 1)
    return Unknowns(t0_degC=t0, degrees=dict(degrees), z_names=tuple(z), setup_names=setup)


def curve_row(T, t0_degC, degree):
    """``(T - t0)^j`` for ``j = 0..degree``, shape (N, degree+1)."""
    d = np.asarray(T, dtype=float).reshape(-1) - t0_degC
    return d[:, None] ** np.arange(degree + 1)[None, :]


def evaluate_curve(coefficients, covariance, T, t0_degC):
    """Value and one sigma of a polynomial curve at temperatures ``T`` (degC).

    Parameters
    ----------
    coefficients : ndarray, shape (d+1,)
    covariance : ndarray, shape (d+1, d+1)
    T : array_like, shape (N,)
    t0_degC : float

    Returns
    -------
    value, sigma : ndarray, shape (N,)
    """
    c = np.asarray(coefficients, dtype=float)
    V = curve_row(T, t0_degC, c.size - 1)
    var = np.einsum("ni,ij,nj->n", V, np.asarray(covariance, dtype=float), V)
    return V @ c, np.sqrt(np.clip(var, 0.0, None))


__all__ = ["SETUP_PARAMETERS", "MAX_DEGREE", "Unknowns", "plan_unknowns", "family_member", "coefficient_terms",
           "curve_label", "curve_row", "evaluate_curve"]
