r"""The gyro noise a keyframe's gravity and rotation factors share, made independent.

Over keyframe ``k`` (start ``R_k``, preintegrated ``dR``, ``A = E(T_k) R_k dR``) the gyros' white noise, integrated,
tilts the indicated attitude by ``xi(t)`` (level frame, covariance ``q_g^2 t I``).  The rotation factor reads its
end value and the gravity factor its mean over the keyframe (every sample's specific force ``~ g_up`` is rotated
with its own attitude): written in the level frame,

.. math::

    \phi = \operatorname{Log}(R_{k+1} A^T) = A\, r_{rot} \ni -\xi(T), \qquad
    r_{grav} \ni -[g_{up} \times]\, \bar\xi, \qquad
    \operatorname{cov}(\xi(T), \bar\xi) = q_g^2 T / 2\, I,

so ``cov(phi, r_grav) = -(q_g^2 T / 2) [g_up x]``: a correlation of ``sqrt(3) / 2`` between the rotation factor and
the gravity factor's horizontal gyro term (``g^2 q_g^2 T / 3``).  Taken as independent, the gravity factors are
over-trusted against the rotation factors wherever that term is a good part of their noise (a MEMS gyro: on the
Xsens session it is three quarters of the horizontal variance, and the gravity kind's variance factor came out 0.63
to make up for it, docs/model.md).

The residual list (:func:`graph_calib.model.residual_list.residual_list`) replaces each such rotation factor by
its part independent of the keyframe's gravity factor, in the level frame:

.. math::

    \rho = \phi - \operatorname{cov}(\phi, r_{grav}) \Sigma_{grav}^{-1} r_{grav}
         = \phi + \beta\, [g_{up} \times]\, r_{grav}, \qquad \beta = \frac{q_g^2 T}{2 h},

``Sigma_grav = diag(h, h, v)`` (level axes; ``[g_up x]`` sees the horizontal alone), with the covariance
``diag(q_g^2 T - c, q_g^2 T - c, q_g^2 T)``, ``c = q_g^4 T^2 g^2 / (4 h)``: each component independent with its
own sigma, and independent of the gravity factor, which keeps its own noise.  The pair's cost is the Mahalanobis
norm of ``(phi, r_grav)`` under their joint covariance, the same whichever of the two is conditioned on the other;
the rotation factor is (so that the gravity factor stays a measurement of ``R_k`` alone, as the filter takes it).
``rho`` is a function of ``R_k``, ``R_{k+1}`` and the calibration with exact Jacobians: with ``J = J_r^-1(phi)``,
``d phi / d R_{k+1} = J A``, ``d phi / d R_k = -J A dR^T``, ``d phi / d x = -J A J_dR``, and the gravity factor's
own through ``beta [g_up x]``.

The variance factors (:class:`graph_calib.model.factors.Noise`) scale each kind's block of the joint covariance,
``v_rot`` the rotation factor's and ``v_grav`` the gravity factor's, and the cross block by
``sqrt(v_rot v_grav)``: the pair's correlation stays the one the white noise gives (at most ``sqrt(3) / 2`` times
the square root of the gyro term's share of ``h``), whatever the factors.  With ``q^2 T`` and ``h`` the unscaled
variances, ``beta = sqrt(v_rot / v_grav) q_g^2 T / (2 h)`` and the conditioned covariance is ``v_rot`` times the
unscaled one, so ``c <= 3/4 v_rot q_g^2 T``.  (The gyro term of the gravity factor taken as the rotation kind's
alone made the pair stiffer the further the factors part: with the rotation kind's factor at 10 and the gravity
kind's at 0.7 on the Xsens session, the filter, started cold, stopped 849 sigma from the factor graph.)

Which keyframes: every one with a rotation factor and no table reading.  A keyframe with readings has its rotation
factor made independent of them (:mod:`graph_calib.model.shared_gyro_noise`) and keeps the gravity factor apart as
before: there the gyro's share of the gravity factor's noise is small (a navigation-grade gyro on a table: about
1e-10 of it).  The conditioned factors are given whitened and turned into the axes of the keyframe's end ``A``
(:mod:`graph_calib.model.heading_axes`: a heading common to every attitude then turns none of them), or in level axes
(horizontal, horizontal, up) with ``body_axes=False``.  A cold start's first solve takes the two factors independent
(``ModelOptions.gravity_gyro_shared``, :func:`graph_calib.solvers.registry.solve`).  Under a robust loss the map is the same, so a gross gravity error reaches the keyframe's
rotation factor through ``beta [g_up x]`` (``beta g`` is at most ``3 / (2 g)`` rad per m/s^2 times
``sqrt(v_rot / v_grav)``, and far less when the accelerometer's noise is a good part of ``h``).
"""

from __future__ import annotations

import numpy as np

from graph_calib.model.factors import Residuals
from graph_calib.model.heading_axes import to_body_axes
from graph_calib.navigation.rotations import log_so3, right_jacobian_inv, skew


def conditioned(record, rot):
    """Index into ``rot`` (the rotation factors) of the factors conditioned on their keyframe's gravity factor: those
    of keyframes without a table reading, with a gyro noise (bool, (F,))."""
    return ~np.isin(rot.key, record.reading_key) & (rot.sigma[:, 0] > 0.0)


def condition_on_gravity(record, preint, x, R, rot, grav, *, variance_factors, body_axes=True):
    """The rotation factors ``rot`` with those of :func:`conditioned` keyframes made independent of ``grav``.

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
    preint : graph_calib.model.preintegration.Preintegrated
    x : ndarray, shape (P,)
    R : ndarray, shape (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.
    rot : graph_calib.model.factors.Residuals
        The rotation factors as :func:`graph_calib.model.factors.rotation_factors` gives them (the rotation kind's
        variance factor applied), those of keyframes with readings possibly made independent of them already.
    grav : graph_calib.model.factors.Residuals
        Every keyframe's gravity factor (``key`` = keyframe), its variance factor applied.
    variance_factors : mapping
        ``{kind: factor}`` (``rotation`` and ``gravity``; 1 where absent): the factors ``rot`` and ``grav`` carry.
    body_axes : bool
        The conditioned factors in the axes of the keyframe's end (:mod:`graph_calib.model.heading_axes`); False:
        in level axes.

    Returns
    -------
    graph_calib.model.factors.Residuals
        ``rot`` with the conditioned factors' rows replaced (module docstring); a new object, ``rot`` untouched.
    """
    sel = np.flatnonzero(conditioned(record, rot))
    if sel.size == 0:
        return rot
    k = rot.key[sel]
    dR = preint.corrected(x).dR[k]
    A = record.earth_turn(record.T_key[k]) @ R[k] @ dR
    phi = log_so3(R[k + 1] @ np.swapaxes(A, 1, 2))
    JA = right_jacobian_inv(phi) @ A
    v_rot = float(variance_factors.get("rotation", 1.0))
    v_grav = float(variance_factors.get("gravity", 1.0))
    s2 = rot.sigma[sel, 0] ** 2 / v_rot                # q_g^2 T: the factor's own (isotropic) variance, unscaled
    h = grav.sigma[k, 0] ** 2 / v_grav                 # the gravity factor's horizontal variance, unscaled
    beta = (np.sqrt(v_rot / v_grav) * s2 / (2.0 * h))[:, None, None]
    G = skew(np.array([0.0, 0.0, record.gravity]))
    BG = beta * G                                      # (F, 3, 3)
    c = s2 * s2 * record.gravity**2 / (4.0 * h)
    r, H_R, H_N, H_x, sigma = rot.r.copy(), rot.H_R.copy(), rot.H_R_next.copy(), rot.H_x.copy(), rot.sigma.copy()
    r[sel] = phi + np.einsum("fij,fj->fi", BG, grav.r[k])
    H_R[sel] = -JA @ np.swapaxes(dR, 1, 2) + BG @ grav.H_R[k]
    H_N[sel] = JA
    H_x[sel] = -JA @ preint.J_dR[k] + BG @ grav.H_x[k]
    sigma[sel] = np.sqrt(v_rot * np.column_stack([s2 - c, s2 - c, s2]))
    # in the axes of the keyframe's end, A = E R_k dR, which a common heading does not turn
    # (graph_calib.model.heading_axes): A moves as A Exp(dR^T delta_k) and A Exp(J_dR dx)
    level = Residuals(r=r, key=rot.key, H_R=H_R, H_R_next=H_N, H_x=H_x, sigma=sigma)
    if not body_axes:
        return level
    return to_body_axes(level, A, rows=sel, C_jacobians=(("H_R", np.swapaxes(dR, 1, 2)), ("H_x", preint.J_dR[k])))


__all__ = ["conditioned", "condition_on_gravity"]
