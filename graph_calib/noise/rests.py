"""Every rest of a record, wherever it lies: per-segment thresholds from the record's quietest windows.

:func:`graph_calib.navigation.static_detection.detect_static` sets its threshold from the first
``init_static_s`` seconds, which must be at rest.  A record need not start at rest (a session whose
first seconds are the unit being put down, a section cut out of a longer one), and then that
threshold is the motion's: motion is taken for rest, and the noise measured on it is the motion's.

Here each segment's own noise level is the low quantile :data:`QUIET_QUANTILE` of its moving-window
scatter (of the specific force, and of the rate): the quietest windows of a record are its rests,
wherever they lie, as long as rests make up more than that fraction of it.  A segment's threshold
is :data:`THRESHOLD_MULT` times that level; the one the first seconds set (``detect_static``'s
default) is kept when it is not above :data:`START_LOUDER` times the quiet one, so that a record
that does start at rest is cut into the same static intervals as before.  No segment's threshold
exceeds :data:`SEGMENT_CAP` times the whole record's quiet one: a segment with no rest at all (a
piece that only turns) has no quiet windows of its own to set it.

A record that never rests (a hand that sways the unit throughout) has quiet windows too, its least
swaying ones.  A rest is therefore also required to be *white*: over each window the scatter of
``f`` (and of the rate) may be at most :data:`WHITE_RATIO` times what its sample-to-sample differences
show (``var(f) ~ var(diff f) / 2`` for white noise; a motion of a few hertz or slower raises the first
and barely the second).  That test needs no threshold from the record.

Short rests (:func:`segment_static`).  A hand holds a face for 0.5-1.5 s (the Ferraris protocol as labs do
it), too short for the 1 s window and the 2 s minimum of ``detect_static``'s defaults.  The static
intervals the calibration uses as gravity factors and rotation anchors are therefore detected twice: as
before, and with a short window (:func:`short_window_s`) whose length follows from the noise statistics of
the scatter it estimates; the short pass adds the rests the first left out, at least two short windows
long.  The noise identification (:func:`find_rests`, Allan variances) keeps its 2 s rests: a record with
only short rests has no identified noise and falls back to its grade's (said in the result).

A rest does not turn (:func:`_not_turning`).  The first pass judges the specific force alone, and a turn about
the vertical leaves it as it was where the sensor sits near the axis: the slow start and end of a Ferraris
session's guided turn (and a turntable's) passed for rest, their gravity factors and the transitions measured
from them tilted by the turn.  Its rests therefore lose the samples whose window-mean rate departs from the
rests' median (the gyro bias and the Earth rate) by more than :data:`TURNING_RATE`, 3 deg/s: on the simulated
guided sessions 0.8-1.0 s of each turn's rests; on the Xsens session, the imucal session and the simulated
sessions whose turns are about a horizontal axis nothing, on the MPU-6050 session two samples, on hand-held
sessions a few (a hand's slow drift).
"""

from __future__ import annotations

import numpy as np

from graph_calib.errors import InputError
from graph_calib.navigation.static_detection import _moving_stats, _runs, accelerometer_threshold, detect_static

#: The quantile of the moving-window scatter taken as a segment's resting noise level.
QUIET_QUANTILE = 0.05
#: A window is at rest below this multiple of the resting level.
THRESHOLD_MULT = 2.0
#: The first seconds' threshold is kept unless it is this much above the quiet windows' one.
START_LOUDER = 1.5
#: A segment's threshold is at most this multiple of the whole record's quiet threshold.
SEGMENT_CAP = 2.0
#: A window is white when its scatter is at most this multiple of what its first differences show.
WHITE_RATIO = 2.0
#: Moving window, s (detect_static's default).
WINDOW_S = 1.0
#: The short pass's window holds enough samples that white noise's window scatter is known to this
#: relative standard deviation, ``1 / sqrt(6 (L - 1))`` for three axes of ``L`` samples (:func:`short_window_s`).
SHORT_SCATTER_REL_SD = 0.085
#: The short pass's window is never shorter than this, s (a hand's tremor, 8-12 Hz, spans it).
SHORT_WINDOW_MIN_S = 0.2
#: A short rest is kept when it spans at least this many short windows.
SHORT_REST_WINDOWS = 2.0


def short_window_s(rate_hz):
    """Window of the short pass, s: the fewest samples ``L`` with ``1 / sqrt(6 (L - 1)) <= SHORT_SCATTER_REL_SD``.

    With a threshold of :data:`THRESHOLD_MULT` times the resting scatter, a white rest's window scatter
    then lies about 12 of its standard deviations below it (``(2 - 1) / 0.085``): the short window misses no
    rest for its noise.  At least :data:`SHORT_WINDOW_MIN_S` (at 100 Hz: 25 samples, 0.25 s, so that the
    shortest rest kept is 0.5 s).
    """
    L = int(np.ceil(1.0 + 1.0 / (6.0 * SHORT_SCATTER_REL_SD**2)))
    return max(SHORT_WINDOW_MIN_S, L / float(rate_hz))


def segment_static(piece, *, threshold):
    """The static intervals of one segment: ``detect_static``'s, and the short rests between them (module doc).

    :func:`segment_static_parts` gives the two apart.

    Parameters
    ----------
    piece : graph_calib.records.experiment.Experiment
        One segment.
    threshold : float
        Its accelerometer threshold (:func:`segment_threshold`), m/s^2.

    Returns
    -------
    ndarray of int, shape (P, 2)
        ``(start, stop)`` of the piece, stop exclusive, in time order.
    """
    long, short = segment_static_parts(piece, threshold=threshold)
    out = np.concatenate([long, short])
    return out[np.argsort(out[:, 0], kind="stable")]


def segment_static_parts(piece, *, threshold):
    """``(detect_static's intervals, the short rests the short pass adds)`` of one segment, each shape (P, 2)."""
    rates = piece.dtheta / piece.dt[:, None]
    long = np.asarray(detect_static(piece, threshold=threshold), dtype=np.int64).reshape(-1, 2)
    long = _not_turning(piece, rates, long)
    w = short_window_s(piece.rate_hz)
    th_g = quiet_threshold(rates, rate_hz=piece.rate_hz, window_s=w)
    short = np.asarray(detect_static(piece, threshold=threshold, window_s=w, min_duration_s=SHORT_REST_WINDOWS * w,
                                     use_gyro=th_g is not None, gyro_threshold=th_g), dtype=np.int64).reshape(-1, 2)
    if not short.shape[0]:
        return long, short
    # a short rest counts only where the long pass found none: the long pass's extent (its core and a
    # half window each side) is taken
    h = max(1, int(round(WINDOW_S * piece.rate_hz / 2.0)))
    covered = np.zeros(piece.n_samples + 1, dtype=np.int64)
    for a, b in long:
        covered[max(a - h, 0)] += 1
        covered[min(b + h, piece.n_samples)] -= 1
    inside = np.cumsum(covered)[:-1] > 0
    c = np.concatenate([[0], np.cumsum(inside)])
    free = (c[short[:, 1]] - c[short[:, 0]]) == 0
    return long, short[free]


#: A rest's window-mean rate departs from the rests' own (the gyro bias and the Earth rate) by less than this, rad/s
#: (module docstring).
TURNING_RATE = np.radians(3.0)


def _not_turning(piece, rates, long):
    """The rests ``long`` (P, 2) of ``piece`` (its rates ``rates``, (N, 3) rad/s) less their samples whose window-mean
    rate departs from the rests' median by more than :data:`TURNING_RATE`: a smooth turn about the vertical leaves the
    specific force as it was where the sensor sits near the axis, so its slow start and end pass the accelerometer's
    test; runs shorter than a window are dropped."""
    if not long.shape[0]:
        return long
    h = max(1, int(round(WINDOW_S * piece.rate_hz / 2.0)))
    if rates.shape[0] < 2 * h + 1:
        return long
    mean = _moving_stats(rates, h)[1]
    inside = np.zeros(piece.n_samples, dtype=bool)
    for a, b in long:
        inside[a:b] = True
    ok = inside & np.all(np.isfinite(mean), axis=1)
    if not ok.any():
        return long
    ref = np.median(mean[ok], axis=0)
    still = inside & ~(np.linalg.norm(mean - ref, axis=1) > TURNING_RATE)
    runs = _runs(still)
    return runs[runs[:, 1] - runs[:, 0] >= 2 * h + 1].astype(np.int64)


def quiet_threshold(f, *, rate_hz, window_s=WINDOW_S, quantile=QUIET_QUANTILE, mult=THRESHOLD_MULT):
    """``mult`` times the ``quantile`` of the moving-window scatter of ``f`` (N, 3); None when too short."""
    h = max(1, int(round(window_s * float(rate_hz) / 2.0)))
    if f.shape[0] < 2 * h + 1:
        return None
    s = _moving_stats(f, h)[0]
    s = s[np.isfinite(s)]
    if not s.size:
        return None
    level = float(np.quantile(s, quantile))
    return mult * level if level > 0 else float(np.finfo(float).tiny)


def segment_threshold(piece):
    """The accelerometer threshold of one segment: its first seconds' unless they are loud (module doc)."""
    quiet = quiet_threshold(piece.dv / piece.dt[:, None], rate_hz=piece.rate_hz)
    start = accelerometer_threshold(piece)
    if start is None:
        return quiet
    if quiet is None:
        return start
    return start if start <= START_LOUDER * quiet else quiet


def segment_thresholds(experiment):
    """``[(start, stop, piece, accelerometer threshold or None)]`` of each segment (module doc)."""
    bounds = experiment.segment_bounds()
    pieces = [experiment.slice(a, b) if len(bounds) > 1 else experiment for a, b in bounds]
    th = [segment_threshold(p) for p in pieces]
    if len(bounds) > 1:
        cap = quiet_threshold(experiment.dv / experiment.dt[:, None], rate_hz=experiment.rate_hz)
        if cap is not None:
            th = [None if v is None else min(v, SEGMENT_CAP * cap) for v in th]
    return [(a, b, p, v) for (a, b), p, v in zip(bounds, pieces, th)]


def segment_rests(experiment):
    """The static intervals the calibration takes, segment by segment (:func:`segment_thresholds`).

    Returns
    -------
    list of tuple
        ``(start, stop, piece, long, short)`` per segment: its samples ``start:stop``, the segment as an
        experiment, and, in the piece's own sample indices, ``detect_static``'s intervals with its threshold and
        the short rests the short pass adds (:func:`segment_static_parts`; a segment without a threshold:
        ``detect_static``'s defaults, no short rests), each shape (P, 2).
    """
    out = []
    for a, b, piece, th in segment_thresholds(experiment):
        if th is None:
            long, short = np.asarray(detect_static(piece), dtype=np.int64).reshape(-1, 2), np.zeros((0, 2), np.int64)
        else:
            long, short = segment_static_parts(piece, threshold=th)
        out.append((a, b, piece, long, short))
    return out


def record_rests(experiment):
    """The rests of a record, ``[start, stop)`` sample indices, shape (P, 2): the calibration's static intervals.

    Segment by segment, each with its own threshold (:func:`segment_thresholds`), the short rests of a hand-held
    session included (:func:`segment_static`); a segment whose detection refuses it (``InputError``) has none.
    """
    out = []
    for a, _, piece, th in segment_thresholds(experiment):
        try:
            st = segment_static(piece, threshold=th) if th is not None else detect_static(piece)
        except InputError:
            continue
        out.extend((int(s) + a, int(e) + a) for s, e in np.asarray(st, dtype=np.int64).reshape(-1, 2))
    return np.array(out, dtype=np.int64).reshape(-1, 2)


def white_windows(x, *, rate_hz, window_s=WINDOW_S, ratio=WHITE_RATIO):
    """Sample centres whose window scatter of ``x`` (N, 3) is at most ``ratio`` times the white level (module doc)."""
    h = max(1, int(round(window_s * float(rate_hz) / 2.0)))
    n = x.shape[0]
    if n < 2 * h + 2:
        return np.zeros(n, dtype=bool)
    s = _moving_stats(x, h)[0]
    d = np.empty_like(x)
    d[1:] = np.diff(x, axis=0)
    d[0] = d[1]
    sd = _moving_stats(d, h)[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = (s**2 <= ratio * 0.5 * sd**2) & np.isfinite(s) & np.isfinite(sd)
    ok[:h] = ok[h]                       # the record's edges: their first (last) window covers them
    ok[n - h:] = ok[n - h - 1]
    return ok


def find_rests(experiment, *, min_duration_s=2.0, use_gyro=True):
    """Every rest of ``experiment``, segment by segment, each with its own thresholds.

    The specific force's window scatter must lie below :func:`segment_threshold` and (``use_gyro``)
    the rate's below :data:`THRESHOLD_MULT` times its own quiet level, and both must be white
    (:func:`white_windows`).

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    min_duration_s : float
        Shortest rest kept, s.
    use_gyro : bool
        Also require a quiet gyro.

    Returns
    -------
    ndarray of int, shape (P, 2)
        ``(start, stop)`` sample indices of the whole record, stop exclusive, in time order.
    """
    out = []
    for a, b, piece, th in segment_thresholds(experiment):
        if th is None:
            continue
        th_g = None
        if use_gyro:
            th_g = quiet_threshold(piece.dtheta / piece.dt[:, None], rate_hz=piece.rate_hz)
        st = detect_static(piece, threshold=th, use_gyro=use_gyro and th_g is not None,
                           gyro_threshold=th_g, min_duration_s=min_duration_s)
        mask = np.zeros(piece.n_samples, dtype=bool)
        for s0, s1 in np.asarray(st, dtype=np.int64).reshape(-1, 2):
            mask[s0:s1] = True
        mask &= white_windows(piece.dv / piece.dt[:, None], rate_hz=piece.rate_hz)
        if use_gyro:
            mask &= white_windows(piece.dtheta / piece.dt[:, None], rate_hz=piece.rate_hz)
        runs = _runs(mask)
        keep = (runs[:, 1] - runs[:, 0]) >= int(round(min_duration_s * piece.rate_hz))
        out.append(runs[keep].astype(np.int64) + a)
    return np.concatenate(out) if out else np.zeros((0, 2), dtype=np.int64)


__all__ = ["find_rests", "record_rests", "segment_rests", "segment_static", "segment_static_parts", "short_window_s", "SHORT_REST_WINDOWS", "quiet_threshold", "segment_threshold", "segment_thresholds", "SEGMENT_CAP", "white_windows", "WHITE_RATIO", "QUIET_QUANTILE", "THRESHOLD_MULT",
           "START_LOUDER"]
