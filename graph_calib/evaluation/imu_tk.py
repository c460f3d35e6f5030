r"""IMU-TK's figures of merit on a measured multi-position session, for any calibration.

The figures the users of hand-held multi-position calibration compare tools with
(Tedaldi, Pretto, Menegatti, ICRA 2014, and their IMU-TK), computed by the same
rules so that ours and theirs can be set side by side (docs/measured-data.md).
Reimplemented from the method's description and IMU-TK's documented behaviour;
no code is taken from it.

Static intervals (IMU-TK's detector)
------------------------------------
On the raw specific force ``f_k`` (any unit; the test is a ratio), with windows
of ``L = 2h + 1`` samples (101), window ``k`` covering samples ``[k - h, k + h]``:

.. math::

    s(k) = \lVert (\mathrm{var}_x, \mathrm{var}_y, \mathrm{var}_z) \rVert_2, \qquad
    \mathrm{var} \text{ with } L - 1 \text{ in the denominator},

quiet when ``s(k) < m s_0``, ``s_0`` the same statistic over the first
``n_init + 1`` samples (5,001: IMU-TK's sample program), ``m`` the threshold
multiplier.  A run of quiet windows starting at ``a`` ends at the first loud
window ``e`` (or at ``N - h - 1``); the interval is ``[a, e]`` (both ends
included) and is kept when ``e - a >= 100``.  IMU-TK tries ``m = 2 .. 10`` and
keeps the one whose accelerometer fit (below) leaves the smallest cost;
:func:`imu_tk_static_intervals` does the same when ``threshold_mult`` is None.

The two figures
---------------
- **static |f|**: the standard deviation (over the intervals) of ``|mean f|``,
  the calibrated specific force averaged over each interval ``[a, e]``, m/s^2.
- **transitions**: for each pair of consecutive intervals ``i, i + 1``, the
  calibrated angular rate integrated (IMU-TK's quaternion RK4 between
  consecutive samples, ``dt`` from the time stamps) from sample ``e_i`` to
  sample ``a_{i+1} - 1`` gives ``R`` (body at the end of the later
  interval's start to body at ``e_i``); the angle between the predicted gravity
  direction ``R^T u_i`` and the measured one ``u_{i+1}`` (``u`` the unit mean
  specific force of an interval), deg.  RMS, median and largest over the
  transitions.

The calibrated angular rate is integrated as IMU-TK integrates it: against
inertial space, the Earth rate included (at most 15 deg/h, about 0.02 deg over a
5 s transition; IMU-TK's gyro bias from the initial rest removes the Earth rate
of the first pose only).

The reference fit (:func:`imu_tk_fit`)
--------------------------------------
IMU-TK's own calibration, for comparison: accelerometers ``f = A (r - b)`` with
``A`` upper triangular (its three misalignments and three scales) fitted so
that ``|f| = g`` on the first 100 samples of every interval; gyros ``omega = M
(w - b_0)``, ``b_0`` the mean of the first ``n_init + 1`` samples, ``M`` (six
misalignments and three scales) fitted to the transitions' gravity directions
(residual ``R^T u_i - u_{i+1}``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from graph_calib.errors import InputError

WINDOW_SAMPLES = 101
N_INIT = 5000
MIN_INTERVAL = 100
THRESHOLD_MULTS = tuple(range(2, 11))


@dataclass(frozen=True)
class TransitionFigures:
    """IMU-TK's figures of one calibration on one record.

    Attributes
    ----------
    intervals : ndarray of int, shape (K, 2)
        ``[start, end]`` sample indices of the static intervals, both included.
    threshold_mult : int
        Detector threshold multiplier used.
    static_norm : ndarray, shape (K,)
        ``|mean f|`` per interval, m/s^2.
    angles_rad : ndarray, shape (K - 1,)
        Transition angles, rad (transition ``i`` from interval ``i`` to ``i + 1``).
    """

    intervals: np.ndarray
    threshold_mult: int
    static_norm: np.ndarray
    angles_rad: np.ndarray

    @property
    def static_std(self):
        """Standard deviation of ``|mean f|`` over the intervals, m/s^2."""
        return float(np.std(self.static_norm))

    def transitions_deg(self, which=None):
        """``(rms, median, max)`` of the transition angles, deg, over ``which`` (indices; default all)."""
        a = np.degrees(self.angles_rad if which is None else self.angles_rad[np.asarray(which)])
        return float(np.sqrt(np.mean(a ** 2))), float(np.median(a)), float(np.max(a))


def _moving_variance_norm(x, h):
    """``|| var ||_2`` over the windows ``[k - h, k + h]``, ``k = h .. N - h - 1`` (ddof 1), shape (N - 2h,)."""
    y = x - x[: min(len(x), 1000)].mean(axis=0)
    c1 = np.vstack([np.zeros((1, 3)), np.cumsum(y, axis=0)])
    c2 = np.vstack([np.zeros((1, 3)), np.cumsum(y * y, axis=0)])
    L = 2 * h + 1
    s1 = c1[L:] - c1[:-L]
    s2 = c2[L:] - c2[:-L]
    var = (s2 - s1 * s1 / L) / (L - 1)
    return np.linalg.norm(np.maximum(var, 0.0), axis=1)


def _detect(f, *, threshold_mult, n_init, window):
    """IMU-TK's static intervals of raw specific force ``f`` (N, 3) for one multiplier: (K, 2) ``[a, e]``."""
    n = f.shape[0]
    h = window // 2
    if n <= window or n <= n_init:
        return np.zeros((0, 2), dtype=np.int64)
    v0 = f[: n_init + 1]
    s0 = float(np.linalg.norm(np.var(v0, axis=0, ddof=1)))
    quiet = _moving_variance_norm(f, h) < threshold_mult * s0  # window centres h .. n - h - 1
    edges = np.diff(np.concatenate([[0], quiet.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)  # first loud window after the run, or len(quiet) at the end
    ends = np.where(stops < quiet.shape[0], stops, quiet.shape[0] - 1)
    iv = np.column_stack([starts + h, ends + h]).astype(np.int64)
    return iv[iv[:, 1] - iv[:, 0] >= MIN_INTERVAL]


def _rates(experiment):
    """Raw sample means ``(omega, f)`` of an experiment, rad/s and m/s^2, shape (N, 3) each."""
    dt = experiment.dt[:, None]
    return experiment.dtheta / dt, experiment.dv / dt


def _accel_fit(samples, g):
    """IMU-TK's accelerometer fit: ``A`` upper triangular, ``b``; returns (A, b, cost)."""
    iu = np.triu_indices(3)

    def unpack(p):
        A = np.zeros((3, 3))
        A[iu] = p[:6]
        return A, p[6:]

    def resid(p):
        A, b = unpack(p)
        return g - np.linalg.norm((samples - b) @ A.T, axis=1)

    def jac(p):
        A, b = unpack(p)
        d = samples - b
        c = d @ A.T
        u = c / np.linalg.norm(c, axis=1)[:, None]
        J = np.empty((samples.shape[0], 9))
        for k, (i, j) in enumerate(zip(*iu)):
            J[:, k] = -u[:, i] * d[:, j]
        J[:, 6:] = u @ A
        return J

    p0 = np.concatenate([np.eye(3)[iu], np.zeros(3)])
    sol = least_squares(resid, p0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    A, b = unpack(sol.x)
    return A, b, 0.5 * float(sol.fun @ sol.fun)


def imu_tk_static_intervals(experiment, *, threshold_mult=None, n_init=N_INIT, window=WINDOW_SAMPLES):
    """IMU-TK's static intervals of an experiment (module docstring).

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    threshold_mult : int, optional
        Detector multiplier; default IMU-TK's rule (2 to 10, smallest accelerometer fit cost).
    n_init, window : int, optional
        Initial-rest samples (``n_init + 1`` used) and window length, samples.

    Returns
    -------
    intervals : ndarray of int, shape (K, 2)
        ``[start, end]``, both included.
    threshold_mult : int
    """
    f = _rates(experiment)[1]
    g = float(experiment.gravity_mps2)
    if threshold_mult is not None:
        return _detect(f, threshold_mult=threshold_mult, n_init=n_init, window=window), int(threshold_mult)
    best = None
    for m in THRESHOLD_MULTS:
        iv = _detect(f, threshold_mult=m, n_init=n_init, window=window)
        if iv.shape[0] < 12:
            continue
        samples = np.concatenate([f[a:a + MIN_INTERVAL] for a, _ in iv])
        cost = _accel_fit(samples, g)[2]
        if best is None or cost < best[0]:
            best = (cost, iv, m)
    if best is None:
        raise InputError("IMU-TK's detector finds fewer than 12 static intervals at every threshold "
                         "multiplier from 2 to 10", path=experiment.source or None, dataset="/imu")
    return best[1], int(best[2])


def _interval_means(x, intervals):
    """Mean of ``x`` over each ``[a, e]`` (both included), shape (K, 3)."""
    c = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    a, e = intervals[:, 0], intervals[:, 1] + 1
    return (c[e] - c[a]) / (e - a)[:, None]


def _rk4_step_matrices(w0, w1, dt):
    """IMU-TK's RK4 quaternion step as a linear map: ``q_next ~ Phi q`` (before normalising), shape (..., 4, 4)."""
    def omega(w):
        x, y, z = w[..., 0], w[..., 1], w[..., 2]
        o = np.zeros(w.shape[:-1] + (4, 4))
        o[..., 0, 1], o[..., 0, 2], o[..., 0, 3] = -x, -y, -z
        o[..., 1, 0], o[..., 1, 2], o[..., 1, 3] = x, z, -y
        o[..., 2, 0], o[..., 2, 1], o[..., 2, 3] = y, -z, x
        o[..., 3, 0], o[..., 3, 1], o[..., 3, 2] = z, y, -x
        return 0.5 * o

    eye = np.broadcast_to(np.eye(4), w0.shape[:-1] + (4, 4))
    h = dt[..., None, None]
    A0, Am, A1 = omega(w0), omega(0.5 * (w0 + w1)), omega(w1)
    K1 = A0
    K2 = Am @ (eye + 0.5 * h * K1)
    K3 = Am @ (eye + 0.5 * h * K2)
    K4 = A1 @ (eye + h * K3)
    return eye + h * (K1 + 2.0 * K2 + 2.0 * K3 + K4) / 6.0


def _transition_rotations(omega, t, intervals):
    """``R`` per transition (body at the later sample to body at ``e_i``), shape (K - 1, 3, 3).

    IMU-TK normalises the quaternion after every step; the steps are linear in it,
    so the product of the step matrices, normalised once, is the same quaternion.
    The products are formed pairwise (log depth), vectorised over the transitions.
    """
    i0 = intervals[:-1, 1]
    i1 = intervals[1:, 0] - 1
    n_steps = np.maximum(i1 - i0, 0)
    L = 1 << int(max(1, n_steps.max())).bit_length() if n_steps.size else 1
    k = np.arange(L)
    idx = np.minimum(i0[:, None] + k[None, :], omega.shape[0] - 2)
    valid = k[None, :] < n_steps[:, None]
    dt = np.where(valid, t[idx + 1] - t[idx], 0.0)
    Phi = _rk4_step_matrices(omega[idx], omega[idx + 1], dt)
    Phi[~valid] = np.eye(4)
    while Phi.shape[1] > 1:
        Phi = Phi[:, 1::2] @ Phi[:, 0::2]
    q = Phi[:, 0, :, 0]  # applied to the identity quaternion
    q = q / np.linalg.norm(q, axis=1)[:, None]
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def _gravity_directions(f_cal, intervals):
    m = _interval_means(f_cal, intervals)
    return m, m / np.linalg.norm(m, axis=1)[:, None]


def _transition_angles(omega_cal, f_cal, t, intervals):
    m, u = _gravity_directions(f_cal, intervals)
    R = _transition_rotations(omega_cal, t, intervals)
    pred = np.einsum("kji,kj->ki", R, u[:-1])
    c = np.einsum("ki,ki->k", pred / np.linalg.norm(pred, axis=1)[:, None], u[1:])
    s = np.linalg.norm(np.cross(pred, u[1:]), axis=1) / np.linalg.norm(pred, axis=1)
    return np.linalg.norm(m, axis=1), np.arctan2(s, c)


def transition_figures(experiment, calibration=None, *, intervals=None, threshold_mult=None):
    """IMU-TK's static |f| and transition figures of a calibration on an experiment.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
        A multi-position record starting with at least ``N_INIT + 1`` samples at rest.
    calibration : graph_calib.compensation.calibration.Calibration or ImuTkFit or None
        Applied to the raw samples (:meth:`Calibration.correct`, the solvers' inverse
        model); None for the raw (nominal) samples.
    intervals : array_like of int, shape (K, 2), optional
        ``[start, end]`` (both included); default :func:`imu_tk_static_intervals`.
    threshold_mult : int, optional
        Passed to :func:`imu_tk_static_intervals` when ``intervals`` is None.

    Returns
    -------
    TransitionFigures
    """
    if intervals is None:
        intervals, threshold_mult = imu_tk_static_intervals(experiment, threshold_mult=threshold_mult)
    intervals = np.asarray(intervals, dtype=np.int64).reshape(-1, 2)
    if calibration is None:
        omega, f = _rates(experiment)
    else:
        omega, f = calibration.correct(experiment)
    norm, ang = _transition_angles(omega, f, experiment.t, intervals)
    return TransitionFigures(intervals=intervals, threshold_mult=int(threshold_mult or 0),
                             static_norm=norm, angles_rad=ang)


@dataclass(frozen=True)
class ImuTkFit:
    """IMU-TK's calibration (module docstring): ``f = A (r_f - b_f)``, ``omega = M (r_w - b_w)``, SI.

    ``r_f``, ``r_w`` the experiment's raw sample means (m/s^2, rad/s).
    """

    A: np.ndarray
    b_f: np.ndarray
    M: np.ndarray
    b_w: np.ndarray
    threshold_mult: int

    def correct(self, experiment):
        """Calibrated ``(omega, f)`` of every sample, shape (N, 3) each."""
        w, f = _rates(experiment)
        return (w - self.b_w) @ self.M.T, (f - self.b_f) @ self.A.T


def imu_tk_fit(experiment, *, n_init=N_INIT):
    """IMU-TK's calibration of a multi-position record (module docstring), as a reference.

    Returns
    -------
    fit : ImuTkFit
    intervals : ndarray of int, shape (K, 2)
    """
    intervals, mult = imu_tk_static_intervals(experiment, n_init=n_init)
    w, f = _rates(experiment)
    g = float(experiment.gravity_mps2)
    A, b_f, _ = _accel_fit(np.concatenate([f[a:a + MIN_INTERVAL] for a, _ in intervals]), g)
    _, u = _gravity_directions((f - b_f) @ A.T, intervals)
    b_w = w[: n_init + 1].mean(axis=0)
    w0 = w - b_w
    t = experiment.t

    def resid(p):
        R = _transition_rotations(w0 @ p.reshape(3, 3).T, t, intervals)
        return (np.einsum("kji,kj->ki", R, u[:-1]) - u[1:]).ravel()

    sol = least_squares(resid, np.eye(3).ravel(), method="lm", xtol=1e-12, ftol=1e-12)
    fit = ImuTkFit(A=A, b_f=b_f, M=sol.x.reshape(3, 3), b_w=b_w, threshold_mult=mult)
    return fit, intervals


__all__ = ["ImuTkFit", "TransitionFigures", "imu_tk_fit", "imu_tk_static_intervals", "transition_figures"]
