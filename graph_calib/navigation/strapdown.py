r"""Strapdown attitude from angle increments, and Euler angles for reports.

Everything here works on raw increments (``dtheta``) as the experiment file
holds them; nothing is calibrated unless the caller passes calibrated increments.
Conventions follow :mod:`graph_calib`: ``n`` is East-North-Up, ``q_nb`` is scalar
first and maps ``b`` into ``n``, units are SI and radians.  The equations are
written out in ``docs/strapdown.md``.  Initial alignment lives in
:mod:`graph_calib.navigation.alignment`, static-interval detection in
:mod:`graph_calib.navigation.static_detection`.

Attitude
    :func:`integrate_attitude` (numba) propagates ``q_nb`` over the samples with a
    two-sample coning correction and the Earth rate,

    .. math::

        \phi_k = \Delta\theta_k + \tfrac{1}{12}\,\Delta\theta_{k-1} \times \Delta\theta_k,
        \qquad
        q_{nb}(t_k) = \mathrm{Exp}(-\omega_{ie}^n\,\Delta t_k) \otimes q_{nb}(t_{k-1})
                      \otimes \mathrm{Exp}(\phi_k).

    :func:`attitude_times` gives the time of each output row, :func:`slerp_attitude`
    the attitude at arbitrary times, :func:`graph_calib.navigation.rotations.quat_to_dcm`
    turns a quaternion stack into ``C_nb`` matrices.

Euler angles (reports only)
    ``C_nb = R_z(-heading) @ R_x(pitch) @ R_y(roll)`` for a body with x right, y
    forward, z up: heading is the angle from North clockwise to the body y axis,
    pitch turns y upwards, roll turns x downwards.  Levelled, ``f_b / g =
    [-cos(pitch) sin(roll), sin(pitch), cos(pitch) cos(roll)]``.  The attitude
    itself never goes through Euler angles, so any pose (any axis up) aligns.
"""

from __future__ import annotations

import numba
import numpy as np

from graph_calib.constants import OMEGA_E
from graph_calib.navigation.rotations import (
    quat_conjugate,
    quat_multiply,
    quat_to_rotvec,
    rotvec_to_quat,
)
from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

__all__ = [
    "integrate_attitude",
    "attitude_times",
    "slerp_attitude",
    "euler_from_dcm",
    "dcm_from_euler",
]

#: Number of samples between two renormalisations of the attitude quaternion.
RENORMALISE_EVERY = 64

# ---------------------------------------------------------------------------
# Attitude propagation
# ---------------------------------------------------------------------------


@numba.njit(cache=True)
def _integrate_kernel(dtheta, elapsed, q0, wx, wy, wz, coning, out):
    """Propagate ``q_nb`` (rows of ``out``, ``out[0] = q0``) over the increments.

    ``(wx, wy, wz)`` is ``omega_ie_n`` in rad/s and ``elapsed[k]`` the time from
    the start to ``t[k]``.  The body part ``P_k = q0 * Exp(phi_1) * ... * Exp(phi_k)``
    is accumulated by right products; the Earth part ``Exp(-omega_ie_n elapsed[k])``
    is evaluated in closed form at every sample, and ``q_nb(t_k) = E_k * P_k``.
    This is the recursion of :func:`integrate_attitude` exactly (the Earth-rate
    rotations share one axis, so they commute), but rounding does not pile up on
    a body at rest, where a left-and-right product would repeat the same rounding
    error at every sample.
    """
    n = dtheta.shape[0]
    pw, px_, py_, pz_ = q0[0], q0[1], q0[2], q0[3]
    nrm = np.sqrt(pw * pw + px_ * px_ + py_ * py_ + pz_ * pz_)
    pw /= nrm
    px_ /= nrm
    py_ /= nrm
    pz_ /= nrm
    out[0, 0] = pw
    out[0, 1] = px_
    out[0, 2] = py_
    out[0, 3] = pz_
    wn = np.sqrt(wx * wx + wy * wy + wz * wz)
    if wn > 0.0:
        ux = wx / wn
        uy = wy / wn
        uz = wz / wn
    else:
        ux = 0.0
        uy = 0.0
        uz = 0.0
    px = 0.0
    py = 0.0
    pz = 0.0
    for k in range(n):
        # coning-corrected rotation vector
        ax = dtheta[k, 0]
        ay = dtheta[k, 1]
        az = dtheta[k, 2]
        if coning:
            fx = ax + (py * az - pz * ay) / 12.0
            fy = ay + (pz * ax - px * az) / 12.0
            fz = az + (px * ay - py * ax) / 12.0
            px = ax
            py = ay
            pz = az
        else:
            fx = ax
            fy = ay
            fz = az
        # body quaternion Exp(phi)
        t2 = fx * fx + fy * fy + fz * fz
        if t2 < 1e-12:
            bw = 1.0 - t2 / 8.0 + t2 * t2 / 384.0
            sk = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
        else:
            t = np.sqrt(t2)
            bw = np.cos(0.5 * t)
            sk = np.sin(0.5 * t) / t
        bx = sk * fx
        by = sk * fy
        bz = sk * fz
        # P <- P * b
        rw = pw * bw - px_ * bx - py_ * by - pz_ * bz
        rx = pw * bx + px_ * bw + py_ * bz - pz_ * by
        ry = pw * by - px_ * bz + py_ * bw + pz_ * bx
        rz = pw * bz + px_ * by - py_ * bx + pz_ * bw
        pw = rw
        px_ = rx
        py_ = ry
        pz_ = rz
        if (k + 1) % RENORMALISE_EVERY == 0:
            nrm = np.sqrt(pw * pw + px_ * px_ + py_ * py_ + pz_ * pz_)
            pw /= nrm
            px_ /= nrm
            py_ /= nrm
            pz_ /= nrm
        # Earth part E = Exp(-omega_ie_n * elapsed), q = E * P
        half = 0.5 * wn * elapsed[k]
        ew = np.cos(half)
        s = -np.sin(half)
        ex = s * ux
        ey = s * uy
        ez = s * uz
        out[k + 1, 0] = ew * pw - ex * px_ - ey * py_ - ez * pz_
        out[k + 1, 1] = ew * px_ + ex * pw + ey * pz_ - ez * py_
        out[k + 1, 2] = ew * py_ - ex * pz_ + ey * pw + ez * px_
        out[k + 1, 3] = ew * pz_ + ex * py_ - ey * px_ + ez * pw


def integrate_attitude(dtheta, *, t, rate_hz, q_nb0, latitude_rad, coning=True):
    r"""Attitude ``q_nb`` from gyro angle increments, with the Earth rate.

    .. math::

        \phi_k = \Delta\theta_k + \tfrac{1}{12}\,\Delta\theta_{k-1}\times\Delta\theta_k
        \quad(\Delta\theta_{-1} = 0),

        q_{nb}(t_k) = \mathrm{Exp}(-\omega_{ie}^n\,\Delta t_k)\otimes q_{nb}(t_{k-1})
                      \otimes \mathrm{Exp}(\phi_k),

    with ``omega_ie_n = OMEGA_E * [0, cos(lat), sin(lat)]`` (the level frame turns
    against inertial space; never neglected) and ``Delta t_0 = 1/rate_hz``,
    ``Delta t_k = t[k] - t[k-1]``.  The Earth-rate factors share one axis, so the
    recursion is evaluated as ``q_nb(t_k) = Exp(-omega_ie_n T_k) * P_k`` with
    ``T_k = t[k] - (t[0] - 1/rate_hz)`` in closed form and the body product
    ``P_k = q_nb0 * Exp(phi_0) * ... * Exp(phi_k)`` accumulated (renormalised every
    :data:`RENORMALISE_EVERY` samples): the same numbers, but rounding does not
    pile up on a body at rest (4 h at rest stay within 1e-12 rad).

    Parameters
    ----------
    dtheta : array_like, shape (N, 3)
        Angle increments of ``b`` against inertial space over ``(t[k-1], t[k]]``,
        rad, in ``b`` axes (as measured, or calibrated by the caller).
    t : array_like, shape (N,)
        Sample times, s, strictly increasing.
    rate_hz : float
        Nominal sample rate, Hz; the first increment covers ``(t[0] - 1/rate_hz, t[0]]``.
    q_nb0 : array_like, shape (4,)
        Attitude at ``t[0] - 1/rate_hz``, scalar first (normalised here).
    latitude_rad : float
        Latitude of the bench, rad.
    coning : bool, optional
        Apply the two-sample coning correction (default True).

    Returns
    -------
    q_nb : ndarray, shape (N + 1, 4)
        ``q_nb[0]`` at ``t[0] - 1/rate_hz``, ``q_nb[k + 1]`` at ``t[k]``
        (see :func:`attitude_times`).

    Examples
    --------
    >>> q = integrate_attitude(np.zeros((10, 3)), t=np.arange(1, 11) / 100.0, rate_hz=100.0,
    ...                        q_nb0=[1.0, 0.0, 0.0, 0.0], latitude_rad=0.0)
    >>> q.shape
    (11, 4)
    """
    dtheta = np.ascontiguousarray(dtheta, dtype=float)
    if dtheta.ndim != 2 or dtheta.shape[1] != 3:
        raise ValueError(f"dtheta must have shape (N, 3), got {dtheta.shape}")
    t = np.asarray(t, dtype=float)
    if t.shape != (dtheta.shape[0],):
        raise ValueError(f"t must have shape ({dtheta.shape[0]},), got {t.shape}")
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    q0 = np.asarray(q_nb0, dtype=float)
    if q0.shape != (4,) or not np.all(np.isfinite(q0)) or np.linalg.norm(q0) == 0.0:
        raise ValueError(f"q_nb0 must be a non-zero quaternion of shape (4,), got {q_nb0!r}")
    if dtheta.shape[0] > 1 and not np.all(np.diff(t) > 0):
        raise ValueError("t must be strictly increasing")
    elapsed = t - (t[0] - 1.0 / float(rate_hz)) if t.shape[0] else t
    w = OMEGA_E * np.array([0.0, np.cos(latitude_rad), np.sin(latitude_rad)])
    out = np.empty((dtheta.shape[0] + 1, 4))
    _integrate_kernel(dtheta, np.ascontiguousarray(elapsed), q0, w[0], w[1], w[2], bool(coning), out)
    return out


def attitude_times(t, rate_hz):
    """Times of the rows of :func:`integrate_attitude`'s output, s, shape (N + 1,).

    ``[t[0] - 1/rate_hz, t[0], t[1], ..., t[N-1]]``.
    """
    t = np.asarray(t, dtype=float)
    return np.concatenate([[t[0] - 1.0 / float(rate_hz)], t])


def slerp_attitude(q_nb, t_q, t_query):
    """Attitude at arbitrary times by spherical linear interpolation.

    Parameters
    ----------
    q_nb : array_like, shape (M, 4)
        Attitude quaternions (scalar first) at times ``t_q``.
    t_q : array_like, shape (M,)
        Their times, s, strictly increasing.
    t_query : array_like, shape (K,) or scalar
        Times wanted, s, within ``[t_q[0], t_q[-1]]``.

    Returns
    -------
    ndarray, shape (K, 4) (or (4,) for a scalar ``t_query``)
        Unit quaternions; the shorter arc between neighbours is taken.
    """
    q_nb = np.asarray(q_nb, dtype=float)
    t_q = np.asarray(t_q, dtype=float)
    tq = np.asarray(t_query, dtype=float)
    scalar = tq.ndim == 0
    tq = np.atleast_1d(tq)
    if np.any(tq < t_q[0]) or np.any(tq > t_q[-1]):
        raise ValueError(
            f"t_query outside [{t_q[0]!r}, {t_q[-1]!r}]: min {tq.min()!r}, max {tq.max()!r}"
        )
    i = np.clip(np.searchsorted(t_q, tq, side="right") - 1, 0, t_q.shape[0] - 2)
    u = ((tq - t_q[i]) / (t_q[i + 1] - t_q[i]))[:, None]
    q0 = q_nb[i]
    q1 = q_nb[i + 1]
    q1 = q1 * np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0.0, -1.0, 1.0)
    rel = quat_to_rotvec(quat_multiply(quat_conjugate(q0), q1))
    q = quat_multiply(q0, rotvec_to_quat(u * rel))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q[0] if scalar else q


# ---------------------------------------------------------------------------
# Euler angles (for reports)
# ---------------------------------------------------------------------------


def dcm_from_euler(roll, pitch, heading):
    """``C_nb = R_z(-heading) @ R_x(pitch) @ R_y(roll)`` (module docstring), rad -> shape (..., 3, 3)."""
    roll, pitch, heading = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (roll, pitch, heading)))
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    ch, sh = np.cos(heading), np.sin(heading)
    C = np.empty(roll.shape + (3, 3))
    # R_x(pitch) @ R_y(roll)
    m = np.empty(roll.shape + (3, 3))
    m[..., 0, :] = np.stack([cr, np.zeros_like(cr), sr], axis=-1)
    m[..., 1, :] = np.stack([sp * sr, cp, -sp * cr], axis=-1)
    m[..., 2, :] = np.stack([-cp * sr, sp, cp * cr], axis=-1)
    C[..., 0, :] = ch[..., None] * m[..., 0, :] + sh[..., None] * m[..., 1, :]
    C[..., 1, :] = -sh[..., None] * m[..., 0, :] + ch[..., None] * m[..., 1, :]
    C[..., 2, :] = m[..., 2, :]
    return C


def euler_from_dcm(C_nb):
    """Roll, pitch, heading (rad) of ``C_nb`` in the convention of :func:`dcm_from_euler`.

    Parameters
    ----------
    C_nb : array_like, shape (..., 3, 3)

    Returns
    -------
    roll, pitch, heading : ndarray, shape (...)
        Roll in (-pi, pi], pitch in [-pi/2, pi/2], heading in (-pi, pi].  Near
        pitch = +-pi/2 (body y axis vertical) roll and heading are ill defined.
    """
    C = np.asarray(C_nb, dtype=float)
    pitch = np.arctan2(C[..., 2, 1], np.hypot(C[..., 2, 0], C[..., 2, 2]))
    roll = np.arctan2(-C[..., 2, 0], C[..., 2, 2])
    heading = np.arctan2(C[..., 0, 1], C[..., 1, 1])
    return roll, pitch, heading
