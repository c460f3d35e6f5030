r"""Strapdown attitude, initial alignment and static-interval detection.

Everything here works on raw increments (``dtheta``, ``dv``) as the experiment file
holds them; nothing is calibrated.  Conventions follow :mod:`graph_calib`:
``n`` is East-North-Up, ``q_nb`` is scalar first and maps ``b`` into ``n``,
units are SI and radians.  The equations are written out in ``docs/strapdown.md``.

Attitude
    :func:`integrate_attitude` (numba) propagates ``q_nb`` over the samples with a
    two-sample coning correction and the Earth rate,

    .. math::

        \phi_k = \Delta\theta_k + \tfrac{1}{12}\,\Delta\theta_{k-1} \times \Delta\theta_k,
        \qquad
        q_{nb}(t_k) = \mathrm{Exp}(-\omega_{ie}^n\,\Delta t_k) \otimes q_{nb}(t_{k-1})
                      \otimes \mathrm{Exp}(\phi_k).

    :func:`attitude_times` gives the time of each output row, :func:`slerp_attitude`
    the attitude at arbitrary times, :func:`graph_calib.rotations.quat_to_dcm`
    turns a quaternion stack into ``C_nb`` matrices.

Alignment
    :func:`level` (roll, pitch from ``f_b``), :func:`gyrocompass` and
    :func:`table_heading_dcm` (``C_nb`` from ``f_b`` and a horizontal reference),
    :func:`alignment` and :func:`align` for an experiment.

Static intervals
    :func:`detect_static` (moving-window variance, after Tedaldi et al. 2014) and
    :func:`static_means`.

Euler angles (reports only)
    ``C_nb = R_z(-heading) @ R_x(pitch) @ R_y(roll)`` for a body with x right, y
    forward, z up: heading is the angle from North clockwise to the body y axis,
    pitch turns y upwards, roll turns x downwards.  Levelled, ``f_b / g =
    [-cos(pitch) sin(roll), sin(pitch), cos(pitch) cos(roll)]``.  The attitude
    itself never goes through Euler angles, so any pose (any axis up) aligns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from graph_calib.constants import OMEGA_E
from graph_calib.errors import InputError
from graph_calib.rotations import (
    dcm_to_quat,
    quat_conjugate,
    quat_multiply,
    quat_to_dcm,
    quat_to_rotvec,
    rotvec_to_quat,
)

__all__ = [
    "integrate_attitude",
    "attitude_times",
    "slerp_attitude",
    "euler_from_dcm",
    "dcm_from_euler",
    "level",
    "gyrocompass",
    "table_heading_dcm",
    "Alignment",
    "alignment",
    "align",
    "detect_static",
    "static_means",
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
# Euler angles (for reports) and alignment
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


def level(f_b):
    """Roll and pitch from the specific force of a body at rest.

    For a body at rest ``f_b = C_nb.T @ [0, 0, g]``; with the Euler convention of
    the module docstring ``roll = atan2(-f_x, f_z)``,
    ``pitch = atan2(f_y, hypot(f_x, f_z))``.

    Parameters
    ----------
    f_b : array_like, shape (..., 3)
        Mean specific force, m/s^2 (any positive scale works).

    Returns
    -------
    roll, pitch : ndarray, shape (...)
        rad.
    """
    f = np.asarray(f_b, dtype=float)
    roll = np.arctan2(-f[..., 0], f[..., 2])
    pitch = np.arctan2(f[..., 1], np.hypot(f[..., 0], f[..., 2]))
    return roll, pitch


def _dcm_from_up_north(up_b, north_b, what):
    """``C_nb`` with rows East, North, Up (in ``b``) from Up and a not-vertical North reference."""
    up_b = np.asarray(up_b, dtype=float)
    nu = np.linalg.norm(up_b)
    if not nu > 0:
        raise ValueError("specific force is zero: cannot level")
    u = up_b / nu
    north_b = np.asarray(north_b, dtype=float)
    h = north_b - np.dot(north_b, u) * u
    nh = np.linalg.norm(h)
    if not nh > 1e-9 * np.linalg.norm(north_b):
        raise ValueError(f"{what} has no horizontal component: cannot find heading")
    nvec = h / nh
    e = np.cross(nvec, u)
    return np.vstack([e, nvec, u])


def gyrocompass(f_b, omega_ib_b):
    """``C_nb`` of a body at rest from its specific force and its angular rate.

    Up in ``b`` is ``f_b / |f_b|``; North in ``b`` is the component of
    ``omega_ib_b`` normal to Up (the horizontal Earth rate, ``OMEGA_E cos(lat)``,
    points North); East = North x Up.  ``C_nb`` has the rows East, North, Up.

    Parameters
    ----------
    f_b : array_like, shape (3,)
        Mean specific force, m/s^2.
    omega_ib_b : array_like, shape (3,)
        Mean angular rate against inertial space, rad/s (bias removed as well as
        known: a gyro bias ``b`` turns North by about ``b / (OMEGA_E cos(lat))`` rad).

    Returns
    -------
    C_nb : ndarray, shape (3, 3)
    """
    return _dcm_from_up_north(f_b, omega_ib_b, "omega_ib_b")


def table_heading_dcm(f_b, C_nb_table):
    """``C_nb`` levelled from ``f_b`` with the heading of a reference attitude.

    Up in ``b`` comes from ``f_b``; North in ``b`` is the North axis of the
    reference (``C_nb_table.T @ [0, 1, 0]``, from the turntable) made normal to Up.

    Parameters
    ----------
    f_b : array_like, shape (3,)
        Mean specific force, m/s^2.
    C_nb_table : array_like, shape (3, 3)
        Reference attitude, e.g. ``C_nf @ C_fb_nominal``.

    Returns
    -------
    C_nb : ndarray, shape (3, 3)
    """
    C = np.asarray(C_nb_table, dtype=float)
    return _dcm_from_up_north(f_b, C[1, :], "the table's North axis")


@dataclass(frozen=True)
class Alignment:
    """Initial attitude of an experiment and how it was found.

    Attributes
    ----------
    q_nb0 : ndarray, shape (4,)
        Attitude at the start of the experiment, ``t[0] - 1/rate_hz``.
    q_nb_interval : ndarray, shape (4,)
        Attitude during the static interval used (at its start).
    roll, pitch, heading : float
        Euler angles of ``q_nb_interval`` (module docstring), rad; for reports.
    sigma_tilt : float
        Rough one-sigma of the levelling, rad, from the accelerometer noise over
        the interval only (accelerometer bias and misalignment not included).
    sigma_heading : float
        Rough one-sigma of the heading, rad: gyrocompassing from the gyro noise
        over the interval only (gyro bias not included); NaN for ``'table'``.
    method : str
        ``'gyrocompass'`` or ``'table'``.
    interval : tuple of int
        ``(start, stop)`` sample indices of the static interval, stop exclusive.
    """

    q_nb0: np.ndarray
    q_nb_interval: np.ndarray
    roll: float
    pitch: float
    heading: float
    sigma_tilt: float
    sigma_heading: float
    method: str
    interval: tuple


def _mean_quaternion(q):
    """Chordal mean of nearby unit quaternions, shape (M, 4) -> (4,)."""
    q = np.asarray(q, dtype=float)
    q = q * np.where(np.sum(q * q[0], axis=1, keepdims=True) < 0.0, -1.0, 1.0)
    m = q.mean(axis=0)
    return m / np.linalg.norm(m)


def alignment(experiment, *, interval=None, method="gyrocompass"):
    """Initial attitude from a static interval: levelling plus gyrocompass or table.

    Up in ``b`` is the mean specific force over the interval
    (``sum(dv) / sum(dt)``); North comes from the mean gyro rate
    (``method='gyrocompass'``, :func:`gyrocompass`) or from the turntable
    (``method='table'``: ``C_nb = C_nf @ C_fb_nominal`` averaged over the valid
    readings in the interval, only its heading is used, :func:`table_heading_dcm`).
    The body is taken at rest over the interval, so the attitude found holds at
    its start.  When the interval starts after sample 0 the attitude is carried
    back to ``t[0] - 1/rate_hz`` with the raw gyro increments of the gap
    (:func:`integrate_attitude`); on a gyro with a large bias that adds about
    ``bias * gap`` of error, so prefer an interval that starts at 0.

    Parameters
    ----------
    experiment : graph_calib.experiment.Experiment
    interval : tuple of int, optional
        ``(start, stop)`` sample indices of a static interval, stop exclusive.
        Default: the first interval of :func:`detect_static` with its defaults.
    method : {'gyrocompass', 'table'}

    Returns
    -------
    Alignment
    """
    if method not in ("gyrocompass", "table"):
        raise ValueError(f"method must be 'gyrocompass' or 'table', got {method!r}")
    n = experiment.n_samples
    if interval is None:
        found = detect_static(experiment)
        if found.shape[0] == 0:
            raise InputError("no static interval found for the initial alignment",
                             path=experiment.source or None, dataset="/imu")
        interval = found[0]
    start, stop = (int(i) for i in interval)
    if not 0 <= start < stop <= n:
        raise ValueError(f"interval must satisfy 0 <= start < stop <= {n}, got {(start, stop)}")
    f_b, omega_b, dur = static_means(experiment, [(start, stop)])
    f_b, omega_b, dur = f_b[0], omega_b[0], float(dur[0])
    dt = experiment.dt[start:stop]
    g = float(np.linalg.norm(f_b))
    # rough statistical sigmas: sample scatter of the per-sample rates / sqrt(n)
    m = stop - start
    f_s = experiment.dv[start:stop] / dt[:, None]
    w_s = experiment.dtheta[start:stop] / dt[:, None]
    sf = float(np.sqrt(np.mean(np.var(f_s, axis=0)) / m)) if m > 1 else np.inf
    sw = float(np.sqrt(np.mean(np.var(w_s, axis=0)) / m)) if m > 1 else np.inf
    sigma_tilt = sf / g
    if method == "gyrocompass":
        C = gyrocompass(f_b, omega_b)
        w_h = OMEGA_E * np.cos(experiment.latitude_rad)
        sigma_heading = float(np.hypot(sw / w_h, sigma_tilt * np.tan(experiment.latitude_rad)))
    else:
        table = experiment.table
        if table is None:
            raise InputError("method='table' needs a /table group", path=experiment.source or None,
                             dataset="/table")
        t0 = experiment.t[start] - dt[0]
        t1 = experiment.t[stop - 1]
        sel = (table.t >= t0) & (table.t <= t1) & np.asarray(table.valid, dtype=bool)
        if not np.any(sel):
            raise InputError(f"no valid table reading in the static interval ({start}, {stop})",
                             path=experiment.source or None, dataset="/table")
        q_nb_tab = quat_multiply(_mean_quaternion(table.q_nf[sel]), np.asarray(table.q_fb_nominal, float))
        C = table_heading_dcm(f_b, quat_to_dcm(q_nb_tab))
        sigma_heading = float("nan")
    q_int = dcm_to_quat(C)
    roll, pitch, heading = (float(a) for a in euler_from_dcm(C))
    q0 = q_int
    if start > 0:
        q_rel = integrate_attitude(
            experiment.dtheta[:start], t=experiment.t[:start], rate_hz=experiment.rate_hz,
            q_nb0=np.array([1.0, 0.0, 0.0, 0.0]), latitude_rad=experiment.latitude_rad,
        )[-1]
        # q_rel = Q_E * Q_B with Q_E = Exp(-omega_ie_n T); q(start) = Q_E * q_nb0 * Q_B
        T = float(np.sum(experiment.dt[:start]))
        w = OMEGA_E * np.array([0.0, np.cos(experiment.latitude_rad), np.sin(experiment.latitude_rad)])
        q_E = rotvec_to_quat(-w * T)
        q_B = quat_multiply(quat_conjugate(q_E), q_rel)
        q0 = quat_multiply(quat_multiply(quat_conjugate(q_E), q_int), quat_conjugate(q_B))
        q0 = q0 / np.linalg.norm(q0)
        q0 = q0 * (1.0 if q0[0] >= 0 else -1.0)
    return Alignment(q_nb0=q0, q_nb_interval=q_int, roll=roll, pitch=pitch, heading=heading,
                     sigma_tilt=sigma_tilt, sigma_heading=sigma_heading, method=method,
                     interval=(start, stop))


def align(experiment, *, interval=None, method="gyrocompass"):
    """Attitude ``q_nb`` at the start of the experiment (``t[0] - 1/rate_hz``), shape (4,).

    Shorthand for ``alignment(experiment, interval=..., method=...).q_nb0``; see
    :func:`alignment` for the method, its parameters and its limits.
    """
    return alignment(experiment, interval=interval, method=method).q_nb0


# ---------------------------------------------------------------------------
# Static intervals
# ---------------------------------------------------------------------------


@numba.njit(cache=True)
def _window_stats(x, h, reseed, std_out, mean_out):
    """Centred moving-window statistics of ``x`` (N, 3) over ``[k - h, k + h]``.

    ``std_out[k] = sqrt(sum over axes of the window variance)``, ``mean_out[k]``
    the window mean; NaN where the window does not fit.  Sums are kept relative to
    a reference value that is reset (and the sums recomputed) every ``reseed``
    centres, so a long record loses no precision to cancellation.
    """
    n = x.shape[0]
    L = 2 * h + 1
    for k in range(n):
        std_out[k] = np.nan
        mean_out[k, 0] = np.nan
        mean_out[k, 1] = np.nan
        mean_out[k, 2] = np.nan
    if L > n:
        return
    s1 = np.zeros(3)
    s2 = np.zeros(3)
    r = np.zeros(3)
    since = reseed
    for k in range(h, n - h):
        if since >= reseed:
            for a in range(3):
                r[a] = x[k, a]
                s1[a] = 0.0
                s2[a] = 0.0
            for j in range(k - h, k + h + 1):
                for a in range(3):
                    d = x[j, a] - r[a]
                    s1[a] += d
                    s2[a] += d * d
            since = 0
        else:
            for a in range(3):
                d_in = x[k + h, a] - r[a]
                d_out = x[k - h - 1, a] - r[a]
                s1[a] += d_in - d_out
                s2[a] += d_in * d_in - d_out * d_out
        since += 1
        v = 0.0
        for a in range(3):
            m = s1[a] / L
            va = s2[a] / L - m * m
            if va > 0.0:
                v += va
            mean_out[k, a] = r[a] + m
        std_out[k] = np.sqrt(v)


def _moving_stats(x, h):
    x = np.ascontiguousarray(x, dtype=float)
    std = np.empty(x.shape[0])
    mean = np.empty((x.shape[0], 3))
    _window_stats(x, int(h), max(1024, 4 * (2 * int(h) + 1)), std, mean)
    return std, mean


def _runs(mask):
    """``(start, stop)`` pairs of the runs of True in a boolean array, shape (R, 2)."""
    padded = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    change = np.flatnonzero(padded[1:] != padded[:-1])
    return np.column_stack([change[0::2], change[1::2]])


#: Half window of the start window of :func:`detect_static` (``edges='pose'``), in detection half windows.
_START_WINDOW_FACTOR = 1.5


def _settled_starts(quiet_e, starts, lower, h_e):
    """Pose starts moved back over a settling tail, vectorised over the poses.

    ``quiet_e[c]``: the start window centred at ``c`` (``2 h_e + 1`` samples) is
    quiet.  For each pose, the earliest ``k`` in ``[lower, start]`` such that every
    start window that begins in ``[k, start]`` is quiet; ``start`` itself when the
    start window that begins there is not quiet (or does not fit in the record).
    """
    n = quiet_e.shape[0]
    last_loud = np.maximum.accumulate(np.where(quiet_e, -1, np.arange(n)))  # last loud centre up to each centre
    c = starts + h_e  # centre of the start window that begins at the detected start
    inside = c < n
    c = np.minimum(c, n - 1)
    earliest = np.maximum(last_loud[c] + 1 - h_e, lower)
    return np.where(inside & quiet_e[c], np.minimum(earliest, starts), starts)


def detect_static(experiment, *, window_s=1.0, min_duration_s=2.0, threshold=None, threshold_mult=2.0,
                  init_static_s=10.0, use_gyro=False, gyro_threshold=None, max_rate=None, edges="core"):
    r"""Static intervals (poses) of an experiment, from the moving-window variance.

    After Tedaldi et al. (ICRA 2014, IMU-TK).  With ``f_k = dv_k / dt_k`` and a
    centred window of ``L = 2h + 1`` samples (``h = round(window_s * rate_hz / 2)``),

    .. math::

        s_a(k) = \sqrt{\textstyle\sum_{axes} \mathrm{var}(f_{k-h}, \dots, f_{k+h})}
        \quad [\mathrm{m/s^2}].

    A window is quiet when ``s_a < threshold``; by default
    ``threshold = threshold_mult * median(s_a)`` over the windows that lie in the
    first ``init_static_s`` seconds, which must be static (the median tolerates a
    disturbance there).  Optionally (``use_gyro``) the same test on
    ``omega = dtheta / dt`` (threshold ``gyro_threshold`` rad/s, default the same
    multiple of its initial median), and (``max_rate``, rad/s) a bound on the
    window-mean rate minus the mean rate of the first ``init_static_s`` seconds,
    which catches a constant-rate rotation about the vertical that leaves ``f``
    unchanged.

    A run of quiet window centres ``[a, b)`` is one pose.  Its extent, the union
    of its quiet windows, is ``[a - h, b + h)``; a pose whose extent is shorter than
    ``min_duration_s`` is dropped.  What is returned for a pose depends on ``edges``:

    ``'core'`` (default, Tedaldi's and IMU-TK's convention)
        the quiet centres ``[a, b)``: every sample is the centre of a quiet window,
        so the interval stays about ``window_s / 2`` clear of the motion on each
        side.  Use it for means (levelling, calibration).  A pose that touches the
        start (end) of the record is extended to sample 0 (``N``): the record's
        edge is no motion, and its first (last) window covers those samples.
    ``'pose'``
        the extent ``[s, b + h)``, its start ``s <= a - h`` placed by the start
        window (below).  A window may hold a few samples of a slow motion onset
        below the threshold, so the extent can reach about 0.1 s into the motion.

    Start window (``'pose'`` only).  A pose ends with a pick-up, abrupt, but begins
    with the settling of the placement (rocking, creep), a tail that decays through
    the threshold.  At an edge a quiet window holds transient energy (sum of squared
    deviations) of up to about ``L (threshold^2 - s_pose^2)``: one or two samples of a
    pick-up whatever ``L``, but of a settling tail a part that grows with ``L``, so
    the start found with one window length is late against a longer one.  Each pose
    start is moved back to the earliest ``s`` (not before the end of the previous
    pose) such that every window of ``2 h_e + 1`` samples, ``h_e = round(1.5 h)``,
    that begins in ``[s, a - h]`` passes the same tests with the same thresholds: a
    tail that a window half as long again finds quiet belongs to the pose.  The
    count, the ends and the cores do not change.

    Parameters
    ----------
    experiment : graph_calib.experiment.Experiment
    window_s : float, optional
        Window length, s (default 1.0, IMU-TK's 101 samples at 100 Hz).
    min_duration_s : float, optional
        Shortest pose kept, s (default 2.0).
    threshold : float, optional
        Accelerometer threshold on ``s_a``, m/s^2; default from the initial static.
    threshold_mult : float, optional
        Multiple of the initial noise level used when a threshold is not given
        (default 2.0: a window whose scatter is twice the resting noise is moving).
    init_static_s : float, optional
        Length of the initial static period that sets the noise level, s (default 10).
    use_gyro : bool, optional
        Also require a quiet gyro window (default False).
    gyro_threshold : float, optional
        Gyro threshold on the window scatter, rad/s; default from the initial static.
    max_rate : float, optional
        Bound on ``|mean window rate - mean initial rate|``, rad/s (default: no bound).
    edges : {'core', 'pose'}, optional
        What to return for each pose (above).

    Returns
    -------
    ndarray of int, shape (P, 2)
        ``(start, stop)`` sample indices of each pose, stop exclusive, in time order.
    """
    if edges not in ("core", "pose"):
        raise ValueError(f"edges must be 'core' or 'pose', got {edges!r}")
    rate = float(experiment.rate_hz)
    n = experiment.n_samples
    h = max(1, int(round(window_s * rate / 2.0)))
    dt = experiment.dt
    if np.any(dt <= 0):
        raise InputError("sample times are not strictly increasing", path=experiment.source or None,
                         dataset="/imu/t", index=int(np.flatnonzero(dt <= 0)[0]))
    empty = np.zeros((0, 2), dtype=np.int64)
    if n < 2 * h + 1:
        return empty
    n_init = min(n, max(2 * h + 1, int(round(init_static_s * rate))))
    f = experiment.dv / dt[:, None]
    w = experiment.dtheta / dt[:, None] if (use_gyro or max_rate is not None) else None

    def _stats(half):
        """Scatter of ``f``, and scatter and mean of ``omega`` (when needed), windows of ``2 half + 1``."""
        s_w, m_w = _moving_stats(w, half) if w is not None else (None, None)
        return _moving_stats(f, half)[0], s_w, m_w

    stats = _stats(h)
    init_slice = slice(h, n_init - h)

    def _floor(s, what):
        m = np.median(s[init_slice])
        if not np.isfinite(m):
            raise InputError(f"cannot set the {what} threshold: initial static too short",
                             path=experiment.source or None, dataset="/imu")
        return threshold_mult * m if m > 0 else np.finfo(float).tiny

    th_a = float(threshold) if threshold is not None else _floor(stats[0], "accelerometer")
    th_g = None
    if use_gyro:
        th_g = float(gyro_threshold) if gyro_threshold is not None else _floor(stats[1], "gyro")
    w0 = w[:n_init].mean(axis=0) if max_rate is not None else None

    def _quiet(s_f, s_w, m_w):
        """Windows that pass every active test, with the thresholds set above."""
        q = s_f < th_a
        if use_gyro:
            q &= s_w < th_g
        if max_rate is not None:
            q &= np.linalg.norm(m_w - w0, axis=1) < float(max_rate)
        return q

    quiet = _quiet(*stats)
    runs = _runs(quiet)
    if runs.shape[0] == 0:
        return empty
    poses = np.column_stack([runs[:, 0] - h, runs[:, 1] + h])
    poses = np.clip(poses, 0, n)
    t_start = np.where(poses[:, 0] > 0, experiment.t[np.maximum(poses[:, 0] - 1, 0)],
                       experiment.t[0] - 1.0 / rate)
    length = experiment.t[poses[:, 1] - 1] - t_start
    keep = length >= min_duration_s - 0.5 / rate
    if edges == "core":
        core = runs.copy()
        core[core[:, 0] == h, 0] = 0
        core[core[:, 1] == n - h, 1] = n
        return core[keep].astype(np.int64)
    poses = poses[keep]
    # Start window: a placement ends in a settling tail that decays through the threshold;
    # the starts are judged with windows half as long again (same tests, same thresholds).
    h_e = int(round(_START_WINDOW_FACTOR * h))
    if h_e > h and np.any(poses[:, 0] > 0):
        lower = np.concatenate([[0], poses[:-1, 1]])
        poses[:, 0] = _settled_starts(_quiet(*_stats(h_e)), poses[:, 0], lower, h_e)
    return poses.astype(np.int64)


def static_means(experiment, intervals):
    """Mean specific force and angular rate over static intervals.

    ``f_b = sum(dv) / T`` and ``omega_ib_b = sum(dtheta) / T`` with ``T`` the
    length of the interval (sum of its sample periods).

    Parameters
    ----------
    experiment : graph_calib.experiment.Experiment
    intervals : array_like of int, shape (P, 2)
        ``(start, stop)`` sample indices, stop exclusive.

    Returns
    -------
    f_b : ndarray, shape (P, 3)
        Mean raw specific force, m/s^2.
    omega_ib_b : ndarray, shape (P, 3)
        Mean raw angular rate, rad/s.
    durations : ndarray, shape (P,)
        Length of each interval, s.
    """
    iv = np.asarray(intervals, dtype=np.int64).reshape(-1, 2)
    n = experiment.n_samples
    if np.any(iv[:, 0] < 0) or np.any(iv[:, 1] > n) or np.any(iv[:, 1] <= iv[:, 0]):
        raise ValueError(f"intervals must satisfy 0 <= start < stop <= {n}")
    dt = experiment.dt
    T = np.array([dt[a:b].sum() for a, b in iv])
    dv = np.array([experiment.dv[a:b].sum(axis=0) for a, b in iv]).reshape(-1, 3)
    dth = np.array([experiment.dtheta[a:b].sum(axis=0) for a, b in iv]).reshape(-1, 3)
    return dv / T[:, None], dth / T[:, None], T
