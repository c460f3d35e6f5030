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
that does start at rest is cut into the same static intervals as before.
"""

from __future__ import annotations

import numpy as np

from graph_calib.navigation.static_detection import _moving_stats, accelerometer_threshold, detect_static

#: The quantile of the moving-window scatter taken as a segment's resting noise level.
QUIET_QUANTILE = 0.05
#: A window is at rest below this multiple of the resting level.
THRESHOLD_MULT = 2.0
#: The first seconds' threshold is kept unless it is this much above the quiet windows' one.
START_LOUDER = 1.5
#: Moving window, s (detect_static's default).
WINDOW_S = 1.0


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


def find_rests(experiment, *, min_duration_s=2.0, use_gyro=True):
    """Every rest of ``experiment``, segment by segment, each with its own thresholds.

    The specific force's window scatter must lie below :func:`segment_threshold` and (``use_gyro``)
    the rate's below :data:`THRESHOLD_MULT` times its own quiet level.

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
    for a, b in experiment.segment_bounds():
        piece = experiment.slice(a, b) if (a, b) != (0, experiment.n_samples) else experiment
        th = segment_threshold(piece)
        if th is None:
            continue
        th_g = None
        if use_gyro:
            th_g = quiet_threshold(piece.dtheta / piece.dt[:, None], rate_hz=piece.rate_hz)
        st = detect_static(piece, threshold=th, use_gyro=use_gyro and th_g is not None,
                           gyro_threshold=th_g, min_duration_s=min_duration_s)
        out.append(np.asarray(st, dtype=np.int64).reshape(-1, 2) + a)
    return np.concatenate(out) if out else np.zeros((0, 2), dtype=np.int64)


__all__ = ["find_rests", "quiet_threshold", "segment_threshold", "QUIET_QUANTILE", "THRESHOLD_MULT",
           "START_LOUDER"]
