"""Initial alignment of an experiment: levelling, gyrocompassing, table heading.

Works on raw increments (``dtheta``, ``dv``) as the experiment file holds them;
nothing is calibrated.  Conventions follow :mod:`graph_calib`: ``n`` is
East-North-Up, ``q_nb`` is scalar first and maps ``b`` into ``n``, units are SI
and radians.  The equations are written out in ``docs/strapdown.md``.

Alignment
    :func:`level` (roll, pitch from ``f_b``), :func:`gyrocompass` and
    :func:`table_heading_dcm` (``C_nb`` from ``f_b`` and a horizontal reference),
    :func:`alignment` and :func:`align` for an experiment (static interval from
    :func:`graph_calib.navigation.static_detection.detect_static`, carried back to the start
    with :func:`graph_calib.navigation.strapdown.integrate_attitude`).

Euler angles (reports only)
    The convention of :mod:`graph_calib.navigation.strapdown`:
    ``C_nb = R_z(-heading) @ R_x(pitch) @ R_y(roll)`` for a body with x right, y
    forward, z up.  Levelled, ``f_b / g = [-cos(pitch) sin(roll), sin(pitch),
    cos(pitch) cos(roll)]``.  The attitude itself never goes through Euler angles,
    so any pose (any axis up) aligns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.constants import OMEGA_E
from graph_calib.errors import InputError
from graph_calib.navigation.rotations import (
    dcm_to_quat,
    quat_conjugate,
    quat_multiply,
    quat_to_dcm,
    rotvec_to_quat,
)
from graph_calib.navigation.static_detection import detect_static, static_means
from graph_calib.navigation.strapdown import euler_from_dcm, integrate_attitude

__all__ = [
    "level",
    "gyrocompass",
    "table_heading_dcm",
    "Alignment",
    "alignment",
    "align",
]


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
    experiment : graph_calib.records.experiment.Experiment
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
