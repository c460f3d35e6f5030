r"""The model's residual list: every factor kind, enumerated once, with its robust-loss policy; the one whitening.

A record's residuals are its factors (:mod:`graph_calib.model.factors`), one :class:`FactorKind` each in
:data:`FACTOR_KINDS`, and its priors (the attitude of each segment's first keyframe, the calibration vector:
:class:`graph_calib.model.factors.PriorResidual`).  Every solver, the diagnosis and the filter read the kinds
from here; a new kind is one entry (its residual function in ``factors`` and a method of the model).

The residual list (:func:`residual_list`) gives every kind as the solvers use it: the rotation and encoder
factors of a keyframe interval share gyro noise, which :mod:`graph_calib.model.shared_gyro_noise` makes
independent (one linear map of their residuals and Jacobians), a keyframe's rotation factor without readings
is made independent of its gravity factor, with which it shares gyro noise too
(:mod:`graph_calib.model.gravity_gyro_noise`), so that every component is then independent of every other; a rest's rotation and still factors, which tie the same two attitudes, become one process
factor and one measurement of the rest's first keyframe (:mod:`graph_calib.model.still_fusion`).

Whitening (:func:`whiten`): a factor's rows divided by its one-sigma noise (the model's
:class:`graph_calib.model.factors.Noise` gives each kind's sigma), then, under a robust loss, scaled by the
square root of the M-estimator's weight of the norm of the factor's whole whitened residual (GTSAM's
``noiseModel.Robust``), its cost the estimator's loss.  Factors of one robust group share one loss: an
encoder group holds every reading of a keyframe (GTSAM's factor of stacked readings), its threshold
``robust_k sqrt(m)`` for ``m`` readings (a group at pure noise has norm about ``sqrt(3 m)``), so that it is
down-weighted no sooner than one reading would be.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.model.factors import encoder_columns
from graph_calib.model.gravity_gyro_noise import condition_on_gravity
from graph_calib.model.guided_turns import KIND as TURN
from graph_calib.model.heading_axes import to_body_axes
from graph_calib.model.shared_gyro_noise import decorrelate
from graph_calib.model.still_fusion import fuse_still


@dataclass(frozen=True)
class FactorKind:
    """One kind of factor of the model.

    Attributes
    ----------
    name : str
        Its name in result files and residual series.
    method : str
        The :class:`graph_calib.model.CalibrationModel` method that evaluates it, ``(R, preint, x) -> Residuals``.
    robust : bool
        Whether a requested robust loss applies to it (a measurement; the rotation factors are the process).
    per_keyframe : bool
        Whether one robust loss covers every factor of a keyframe (the encoder readings), else one per factor.
    optional : bool
        Whether a model has the kind only on request or where its record shows it (the still factors, the guided
        turns): a model without any leaves it out of its residual series and statistics, where every other kind is
        listed, empty or not.
    components : str
        What the three components of a factor are, in a report's words.
    keys : str or None
        The model's attribute holding each factor's keyframe, where the kind has factors on some keyframes only (the
        still factors, the guided turns): its times are theirs.
    weightless_rows : bool
        Whether some of its factors' components are weightless (sigma infinite: a guided turn's tilt is two rows of
        three), which its series then hold as exact zeros, left out of their RMS.
    """

    name: str
    method: str
    robust: bool
    per_keyframe: bool = False
    optional: bool = False
    components: str = "xyz (body)"
    keys: str | None = None
    weightless_rows: bool = False

    def evaluate(self, model, R, preint, x):
        """The kind's :class:`graph_calib.model.factors.Residuals` at ``(R, x)``, on its own: the rotation and
        encoder kinds before their shared gyro noise is made independent (:func:`residual_list` gives every
        kind as the solvers use it)."""
        return getattr(model, self.method)(R, preint, x)

    def listed(self, res):
        """Whether the kind, its factors ``res``, is listed in the residual series and statistics: every kind, empty
        or not, but an optional one only where the model has such factors."""
        return not self.optional or res.key.size > 0

    def times(self, model):
        """Time of each factor, s: the rotation factor's end, the gravity factor's keyframe start, a reading's time."""
        if self.name == "rotation":
            return model.t_key[model.record.rotation_keys + 1]
        if self.name == "encoder":
            return model.record.reading_t
        if self.keys is not None:
            return model.t_key[getattr(model, self.keys)]
        return model.t_key[:-1]

    def robust_groups(self, res, *, robust, robust_k):
        """``(group (F,) or None, threshold per group or scalar)`` of the robust loss; ``(None, None)`` without one."""
        if robust is None or not self.robust:
            return None, None
        if not self.per_keyframe:
            return None, robust_k
        _, group, counts = np.unique(res.key, return_inverse=True, return_counts=True)
        return group, robust_k * np.sqrt(counts)


#: Every factor kind of the model, in the order solvers and files list them.
FACTOR_KINDS = (
    FactorKind("rotation", "rotation_factors", robust=False),
    FactorKind("gravity", "gravity_factors", robust=True, components="ENU"),
    FactorKind("encoder", "encoder_factors", robust=True, per_keyframe=True,
               components="noise axes nearest body xyz"),
    FactorKind("still", "still_factors", robust=True, optional=True, keys="still_keys",
               components="xyz (body), the rest's gyro integral against the Earth's turn"),
    FactorKind(TURN, "turn_factors", robust=True, optional=True, keys="turn_keys",
               components="a guided turn's closure (xyz), or its tilt (two axes normal to the vertical, a weightless "
                          "third)", weightless_rows=True),
)
#: Their names.
KIND_NAMES = tuple(k.name for k in FACTOR_KINDS)
#: The kinds that are measurements (their components count in the degrees of freedom of the verdict).
MEASUREMENT_KINDS = tuple(k.name for k in FACTOR_KINDS if k.robust)
#: The kinds whose series hold weightless components as exact zeros (:attr:`FactorKind.weightless_rows`).
WEIGHTLESS_ROW_KINDS = tuple(k.name for k in FACTOR_KINDS if k.weightless_rows)


def weighted_components(kind, values):
    """The components of a kind's series (F, 3) that are measurements: all, or for a kind with weightless rows
    (:data:`WEIGHTLESS_ROW_KINDS`) those that are not exact zeros; a boolean array of ``values``' shape."""
    values = np.asarray(values)
    return values != 0.0 if kind in WEIGHTLESS_ROW_KINDS else np.ones(values.shape, dtype=bool)


def series_rms(kind, values):
    """``(per-axis RMS (3,) list, RMS)`` of a kind's series over its weighted components (:func:`weighted_components`)."""
    v = np.asarray(values, dtype=float)
    w = weighted_components(kind, v)
    per_axis = np.sqrt(np.sum(np.where(w, v**2, 0.0), axis=0) / np.maximum(np.sum(w, axis=0), 1))
    return per_axis.tolist(), float(np.sqrt(np.sum(v[w] ** 2) / max(int(np.sum(w)), 1)))


def robust_loss(e, kind, k):
    """``(loss, weight)`` of GTSAM's M-estimator ``kind`` (``huber``, ``cauchy``) at whitened norms ``e``."""
    if kind == "huber":
        big = e > k
        loss = np.where(big, k * e - 0.5 * k * k, 0.5 * e * e)
        return loss, np.where(big, k / np.maximum(e, 1e-300), 1.0)
    if kind == "cauchy":
        q = (e / k) ** 2
        return 0.5 * k * k * np.log1p(q), 1.0 / (1.0 + q)
    raise ValueError(f"unknown robust loss {kind!r}")


def whiten(kind, res, *, robust=None, robust_k=3.0):
    """The one whitening: ``(cost, whitened (F, 3), row scale (F, 3))`` of a kind's factors.

    ``whitened = r / sigma`` (no robust weight); ``row scale`` multiplies the factor's residual and Jacobian
    rows in the normal equations: ``1 / sigma`` times the square root of the robust weight of its group;
    ``cost`` is half the squared whitened norm, or the sum of the groups' robust losses.
    """
    inv_sigma = 1.0 / res.sigma               # the one place a kind's noise enters (a variance factor: here)
    w = res.whitened()
    group, k = kind.robust_groups(res, robust=robust, robust_k=robust_k)
    if k is None:
        return 0.5 * float(np.sum(w * w)), w, inv_sigma
    g = np.arange(w.shape[0]) if group is None else group
    e = np.sqrt(np.bincount(g, weights=np.sum(w * w, axis=1)))
    loss, weight = robust_loss(e, robust, k)
    return float(np.sum(loss)), w, np.sqrt(weight)[g][:, None] / res.sigma


def cost_by_key(kind, res, n_keys, *, robust=None, robust_k=3.0):
    """A kind's cost split by keyframe, (n_keys,): each factor's (a robust group's loss) on its first keyframe."""
    out = np.zeros(n_keys)
    w = res.whitened()
    squares = np.sum(w * w, axis=1)
    group, k = kind.robust_groups(res, robust=robust, robust_k=robust_k)
    if k is None:
        np.add.at(out, res.key, 0.5 * squares)
        return out
    g = np.arange(squares.size) if group is None else group
    loss, _ = robust_loss(np.sqrt(np.bincount(g, weights=squares)), robust, k)
    first = np.zeros(loss.size, dtype=np.int64)
    first[g[::-1]] = res.key[::-1]          # the key of each group's first factor
    np.add.at(out, first, loss)
    return out


def residual_list(model, R, preint, x):
    """``{kind name: Residuals}`` of every factor kind at ``(R, x)``, in :data:`FACTOR_KINDS` order.

    The rotation and encoder factors come out with the gyro noise they share made independent
    (:func:`graph_calib.model.shared_gyro_noise.decorrelate`), a rotation factor without readings independent of its
    keyframe's gravity factor (:func:`graph_calib.model.gravity_gyro_noise.condition_on_gravity`), so that every whitened component is
    independent of every other, and a rest's rotation and still factors as one process factor and one
    measurement of a keyframe (:func:`graph_calib.model.still_fusion.fuse_still`): evaluate the kinds through
    this list, not one by one.
    """
    factors = {kind.name: kind.evaluate(model, R, preint, x) for kind in FACTOR_KINDS}
    factors["rotation"], factors["encoder"] = decorrelate(
        model.record, preint, model.noise, factors["rotation"], factors["encoder"],
        columns=encoder_columns(model.layout, preint), overwrite_input=True)
    if model.options.gravity_gyro_shared:
        factors["rotation"] = condition_on_gravity(model.record, preint, x, R, factors["rotation"], factors["gravity"],
                                                   variance_factors=model.noise.variance_factors,
                                                   body_axes=model.options.heading_axes)
    # the gravity factors in their keyframe's body axes, which a common heading does not turn (its start attitude
    # R_k moves as R_k Exp(delta_k)): graph_calib.model.heading_axes
    if model.options.heading_axes:
        grav = factors["gravity"]
        rows = np.arange(grav.key.size)
        if model.options.moving_sigma is not None:          # the moving keyframes' large residuals stay level
            rows = rows[np.asarray(model.record.static_key, dtype=bool)[grav.key]]
        factors["gravity"] = to_body_axes(grav, R[grav.key[rows]], rows=rows, C_jacobians=(("H_R", None),))
    factors["rotation"], factors["still"] = fuse_still(factors["rotation"], factors["still"])
    return factors


__all__ = ["FactorKind", "FACTOR_KINDS", "KIND_NAMES", "MEASUREMENT_KINDS", "WEIGHTLESS_ROW_KINDS", "weighted_components", "series_rms", "robust_loss", "whiten", "cost_by_key",
           "residual_list"]
