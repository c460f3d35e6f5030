r"""Time stamps of imported logs: groups restarting their clock, rows out of order, jittered stamps.

Shared by the importers that read a time column (:mod:`graph_calib.importers.csv`,
:mod:`graph_calib.importers.rosbag`, :mod:`graph_calib.importers.ulog`).

* :func:`label_segments`: a label column (numbers or text, e.g. the face a row
  belongs to) as segment numbers: each run of equal labels is one segment,
  numbered in order of appearance.
* :func:`rebase_segments`: segments whose clock restarts (rows grouped by a label,
  each group from time 0) placed one after the other, one nominal period apart.
* :func:`regular_times`: stamps with transport jitter (a wireless link delivering
  samples in bursts) replaced by ``t0 + k / rate`` when the stamps follow the sample
  index, i.e. no sample is missing; otherwise an error that proposes the remedy.
"""

from __future__ import annotations

import numpy as np

from graph_calib.errors import InputError
from graph_calib.io import MAX_GAP_PERIODS

#: Largest departure of a stamp from ``t0 + k / rate``, in nominal periods, for which the stamps are read as
#: jitter around a regular clock with no sample missing (a missing sample shifts every later stamp by a period,
#: and several of them by more than this).
JITTER_TOLERANCE_PERIODS = 4.0
#: Largest relative difference between the rate of the stamps' end points and the nominal rate for that reading.
JITTER_RATE_TOLERANCE = 0.01
#: A spacing of stamps whose standard deviation is above this share of the median spacing is jitter to look at
#: (a sample clock's spacing varies by well under a per cent).
JITTER_SPACING = 0.05


#: What a logged rate is: the mean over the interval its stamp closes, or a sample at the stamp.
RATE_MEANINGS = ("averaged", "instantaneous")


def gap_segments(t, rate_hz):
    """Segment numbers cut where a gap exceeds the format's limit (messages missing)."""
    cut = np.zeros(t.shape[0], dtype=np.int32)
    cut[1:] = np.diff(t) > MAX_GAP_PERIODS / rate_hz
    return np.cumsum(cut, dtype=np.int32)


def increments(signal, dt, segment, rates):
    """Increments of rates over the interval each sample closes: ``averaged`` (rate x interval) or ``instantaneous``
    (the trapezoid of the rates at both ends; a segment's first sample its own rate x the nominal period)."""
    if rates == "averaged":
        return signal * dt[:, None]
    inc = signal * dt[:, None]
    trapezoid = 0.5 * (signal[1:] + signal[:-1]) * dt[1:, None]
    keep = np.ones(signal.shape[0] - 1, dtype=bool) if segment is None else np.diff(segment) == 0
    inc[1:][keep] = trapezoid[keep]
    return inc



def label_segments(labels):
    """Segment numbers from a label column: each run of equal labels one segment, numbered 0, 1, ... in order.

    Integer labels that never decrease are kept as they are (a segment column proper).
    """
    labels = np.asarray(labels)
    if labels.dtype.kind == "f" and np.all(labels == np.round(labels)):
        as_int = labels.astype(np.int64)
        if np.all(np.diff(as_int) >= 0) and np.all(np.abs(as_int) < 2**31):
            return as_int.astype(np.int32)
    change = np.ones(labels.shape[0], dtype=bool)
    change[1:] = labels[1:] != labels[:-1]
    return (np.cumsum(change) - 1).astype(np.int32)


def rebase_segments(t, segment, rate_hz):
    """Times with each segment whose clock went back placed one nominal period after the previous segment's end.

    Inside a segment the times must still increase (checked by the caller's time check).
    """
    t = np.array(t, dtype=float)
    starts = np.flatnonzero(np.diff(segment) != 0) + 1
    for s in starts:
        if t[s] <= t[s - 1]:
            t[s:][segment[s:] == segment[s]] += t[s - 1] + 1.0 / rate_hz - t[s]
            # the later segments keep their own clocks; they are rebased in their turn
    return t


def within_segment_order(t, segment):
    """Index of the first row whose time is not after the previous row's inside one segment, or None."""
    bad = ~(np.diff(t) > 0)
    if segment is not None:
        bad &= np.diff(segment) == 0
    return int(np.flatnonzero(bad)[0]) + 1 if bad.any() else None


def regular_times(t, rate_hz, *, segment=None, source="the log", given_rate=False, path=None):
    """Jittered stamps replaced by the sample index at the nominal rate when no sample is missing.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Stamps, s, increasing.
    rate_hz : float
        Nominal rate (given, or from the median spacing).
    segment : ndarray or None
        With segments the stamps are kept: a gap between segments is expected.
    source : str
        Named in messages.
    given_rate : bool
        Whether ``rate_hz`` was given by the user (then it is kept; otherwise the end points' rate is used).

    Returns
    -------
    t : ndarray
        The stamps unchanged when no gap exceeds the format's limit, else ``t0 + k / rate``.
    rate_hz : float
    note : str
        Empty, or what was done (for the description and the terminal).

    Raises
    ------
    InputError
        Gaps beyond the limit and stamps that do not follow the index (samples missing): the message proposes
        the sample index at a nominal rate, or segments.
    """
    d = np.diff(t)
    limit = MAX_GAP_PERIODS / rate_hz
    if segment is not None or t.shape[0] < 3:
        return t, rate_hz, ""
    gaps = bool(np.any(d > limit))
    # stamps taken on arrival scatter about the sample clock even where no gap shows: a spacing that varies by more
    # than JITTER_SPACING of the period is no sample clock's (each sample's increment is its rate times that
    # spacing, so the per-sample noise the record shows would be the stamps' scatter)
    scattered = float(np.std(d)) > JITTER_SPACING * float(np.median(d))
    if not gaps and not scattered:
        return t, rate_hz, ""
    k = np.arange(t.shape[0], dtype=float)
    end_rate = (t.shape[0] - 1) / (t[-1] - t[0])
    rate = rate_hz if given_rate else float(f"{end_rate:.6g}")
    departure = np.max(np.abs(t - t[0] - k / rate)) * rate
    worst = int(np.argmax(d))
    jitter = (abs(end_rate / rate - 1.0) <= JITTER_RATE_TOLERANCE
              and departure <= JITTER_TOLERANCE_PERIODS)
    if jitter:
        note = (f"time stamps of {source} jitter (largest gap {d[worst]:.4g} s, {d[worst] * rate:.3g} periods; "
                f"spacing scatter {np.std(d) * rate:.2g} periods) but follow the sample index within {departure:.2g} "
                f"periods, so no sample is missing: t = t0 + k / {rate:g} Hz")
        return t[0] + k / rate, rate, note
    if not gaps:
        return t, rate_hz, ""
    first = int(np.flatnonzero(d > limit)[0])
    where = (f"gap of {d[first]:.6g} s ({d[first] * rate_hz:.4g} nominal periods) before sample {first + 1} (at "
             f"{t[first + 1]:.6g} s; at most {MAX_GAP_PERIODS:g} periods are accepted)")
    # the span at the nominal period against the samples in it: what the gaps hold (late stamps hold none); stamps
    # that arrive in bursts have a median spacing shorter than any period, so without a given rate they cannot tell
    period = 1.0 / rate_hz if given_rate else float(np.median(d))
    told = given_rate or float(np.mean(d)) <= 2.0 * period
    missing = (t[-1] - t[0]) / period - (t.shape[0] - 1)
    if told and missing >= MISSING_SAMPLES:
        lag = (t - t[0]) / period - np.arange(t.shape[0])         # samples missing before each one
        lost = int(np.argmax(lag > 0.5 * missing))
        raise InputError(
            f"{where}: about {missing:.0f} samples are missing (the span at {1.0 / period:.6g} Hz holds that many "
            f"more than the file; half of them before sample {lost}, at {t[lost]:.6g} s). Mark where each piece "
            f"starts with a segment "
            f"column (segment=COLUMN in --columns, e.g. a counter that steps at each gap) and each piece is "
            f"integrated on its own; the sample index at one rate would close the gaps and misplace every later "
            f"sample", path=path, dataset="t", index=first + 1)
    if told:
        raise InputError(
            f"{where}, and the stamps depart from the sample index by {departure:.3g} periods while the span holds "
            f"every sample: the clock is not the sample clock. If the stamps are late (a wireless link), use the "
            f"sample index at the nominal rate (csv: leave t= out of --columns and give --rate-hz {end_rate:.6g}); "
            f"if pieces are missing, mark where each piece starts with a segment column (segment=COLUMN)",
            path=path, dataset="t", index=first + 1)
    raise InputError(
        f"{where}, and the stamps depart from the sample index by {departure:.3g} periods: samples are missing, or "
        f"the clock is not the sample clock (the stamps come in bursts: give the sensor's rate, --rate-hz, and the "
        f"import tells which). If every sample is there and only the stamps are late, use the sample index at the "
        f"nominal rate (csv: leave t= out of --columns and give --rate-hz); if pieces are missing, mark where each "
        f"piece starts with a segment column (segment=COLUMN)", path=path, dataset="t", index=first + 1)


#: Samples missing (the span at the median spacing less the samples in it) from which on a gap in the stamps is taken
#: as lost samples, not late stamps (whose span holds every sample: within a period or two of the count).
MISSING_SAMPLES = 3.0


def message_times(t, rate_hz, *, source):
    """Times of logged messages (rosbag, ulog): jitter regularised, or segments where messages are missing.

    Parameters
    ----------
    t : ndarray
        Stamps, s, from the first; increasing.
    rate_hz : float or None
        Nominal rate given by the user; None: ``1 / median`` spacing.

    Returns
    -------
    t, rate_hz, segment (ndarray or None), note (str)
    """
    given = rate_hz is not None
    rate = float(rate_hz) if given else float(f"{1.0 / float(np.median(np.diff(t))):.6g}")
    try:
        t, rate, note = regular_times(t, rate, source=source, given_rate=given)
        return t, rate, None, note
    except InputError:
        segment = gap_segments(t, rate)
        note = (f"messages missing: cut into {int(segment[-1]) + 1} segments where the stamps leave gaps of more "
                f"than {MAX_GAP_PERIODS:g} periods")
        return t, rate, segment, note


__all__ = ["message_times", "RATE_MEANINGS", "gap_segments", "increments", "label_segments", "rebase_segments", "within_segment_order", "regular_times",
           "JITTER_TOLERANCE_PERIODS", "JITTER_RATE_TOLERANCE"]
