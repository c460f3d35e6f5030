r"""Static intervals (poses) of an experiment, from the moving-window variance.

Works on raw increments (``dtheta``, ``dv``) as the experiment file holds them;
nothing is calibrated.  Units are SI and radians.  The method, its defaults and
its results on the measured sessions are written out in ``docs/strapdown.md``.

Static intervals
    :func:`detect_static` (moving-window variance, after Tedaldi et al. 2014) and
    :func:`static_means`.
"""

from __future__ import annotations

import numba
import numpy as np

from graph_calib.errors import InputError
from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

__all__ = [
    "accelerometer_threshold",
    "detect_static",
    "static_means",
]


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
    experiment : graph_calib.records.experiment.Experiment
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


def accelerometer_threshold(experiment, *, window_s=1.0, init_static_s=10.0, threshold_mult=2.0):
    """The accelerometer threshold :func:`detect_static` sets by default, m/s^2 (None if too short).

    ``threshold_mult`` times the median moving-window scatter of ``f`` over the first
    ``init_static_s`` seconds.  A record cut into segments is detected segment by segment with one
    threshold: the smallest of the segments' own (a segment may start with a motion, which inflates
    its own median; at least one starts at rest).
    """
    rate = float(experiment.rate_hz)
    n = experiment.n_samples
    h = max(1, int(round(window_s * rate / 2.0)))
    if n < 2 * h + 1:
        return None
    n_init = min(n, max(2 * h + 1, int(round(init_static_s * rate))))
    f = experiment.dv[:n_init] / experiment.dt[:n_init, None]
    m = float(np.median(_moving_stats(f, h)[0][h:n_init - h]))
    if not np.isfinite(m):
        return None
    return threshold_mult * m if m > 0 else float(np.finfo(float).tiny)


def static_means(experiment, intervals):
    """Mean specific force and angular rate over static intervals.

    ``f_b = sum(dv) / T`` and ``omega_ib_b = sum(dtheta) / T`` with ``T`` the
    length of the interval (sum of its sample periods).

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
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
