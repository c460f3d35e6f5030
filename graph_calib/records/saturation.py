r"""A saturated gyro: the record is cut after each run of samples at the range, so no rotation factor spans it.

A gyro whose true rate exceeds its range outputs the range, and the angle beyond it is lost: a rotation
factor over such samples measures a rotation the unit did not make. No calibration element explains that
error, so a model fitted across it bends whatever elements come closest. On the UNCuyo MPU-6050 session
(range +-250 deg/s; 18 samples at the limit in three fast turns, 10 of them in one turn) the rotation
residuals needed a variance factor of 31 and the closed loop adopted `gyro.g_sensitivity`,
`gyro.scale_asym` and `accel.nonlinearity`; cut at the three runs, the declared model fits (variance
factors 1.0 for both kinds, no effect's score significant) and the static |f| spread falls twentyfold
(docs/measured-data.md).

Runs less than :data:`EPISODE_GAP_S` apart (a turn whose rate swings about the range) make one episode.
The cut is a segment boundary (``/imu/segment``, data-format.md: attitude is never assumed continuous
across one) placed on the first sample after each episode. A segment's last keyframe holds at least its
last half keyframe (:func:`graph_calib.model.record._grid`), so an episode shorter than that (0.5 s at the
default 1 s keyframes; the MPU-6050's last 0.02-0.1 s) lies inside it, and that keyframe has no rotation
factor; the next segment has its own initial attitude. That attitude comes from a rest in the piece
(:mod:`graph_calib.records.problem`), so an episode with no rest after it before the next cut (or the
record's end) is not cut but kept, and reported: its turn's lost angle stays in the record. The
accelerometers are not cut: a saturated accelerometer can only be in motion, where the gravity factors
are loose.

A sample is saturated when any gyro axis's rate reaches the range. An importer that reads raw counts knows
which samples sit at the counts' limits (``graph-calib import mpu6050``); for other formats the range is
declared (``graph-calib import ... --gyro-range-dps``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from graph_calib.errors import InputError
from graph_calib.navigation.static_detection import _runs
from graph_calib.noise.rests import record_rests, segment_rests
from graph_calib.records.experiment import Experiment

#: A rate within this fraction of the declared range counts as at the range (a few counts below the limit of an
#: integer output, or a range declared in round figures: 2e-4 of 32767 counts is 6.6 counts).
RANGE_TOLERANCE = 2e-4


#: Saturated runs closer than this, s, make one episode (one cut after its last run); no rest is that short.
EPISODE_GAP_S = 0.5
#: An episode longer than this, s, is said to reach beyond its segment's last keyframe (half the default 1 s).
EPISODE_INSIDE_S = 0.5
#: How the sentence :meth:`SaturationCuts.describe` adds to a record's description begins.
NOTE_START = "The gyros are saturated in "


@dataclass(frozen=True)
class SaturationCuts:
    """The record cut after its saturated episodes.

    Attributes
    ----------
    experiment : Experiment
        The record with a segment boundary after each episode in ``episodes[cut]`` (its description says so).
    episodes : ndarray of int, shape (E, 2)
        ``[start, stop)`` samples of each episode: the first saturated sample of its first run, one past the
        last of its last run.
    samples : int
        Saturated samples in all.
    cut : ndarray of bool, shape (E,)
        Whether a boundary follows the episode (False: no rest in the piece after it; it stays inside).
    rate_hz : float
        The record's sample rate (for the episodes' durations).
    """

    experiment: Experiment
    episodes: np.ndarray
    samples: int
    cut: np.ndarray
    rate_hz: float

    def describe(self):
        """One sentence for the record's description and the import summary ('' without saturated samples)."""
        if not self.episodes.shape[0]:
            return ""
        e = self.episodes.shape[0]
        text = (f"{NOTE_START}{self.samples} samples ({e} episode{'s' if e > 1 else ''}, first sample"
                f"{'s' if e > 1 else ''} {', '.join(str(int(a)) for a in self.episodes[:, 0])}): ")
        k = int(np.count_nonzero(self.cut))
        if k:
            text += (f"the record is cut after {'it' if e == 1 else f'{k} of them'} (/imu/segment), so that no "
                     "rotation factor spans the angle they lost")
            long = self.episodes[self.cut & ((self.episodes[:, 1] - self.episodes[:, 0]) / self.rate_hz
                                             > EPISODE_INSIDE_S), 0]
            if long.size:
                text += (f" (those starting at {', '.join(str(int(a)) for a in long)} last more than "
                         f"{EPISODE_INSIDE_S:g} s: with 1 s keyframes a rotation factor still spans their start)")
        if k < self.cut.size:
            kept = ", ".join(str(int(a)) for a in self.episodes[~self.cut, 0])
            text += ("; " if k else "") + (f"those starting at {kept} are kept inside their piece (no rest after "
                                           "them to align a new segment): the angle they lost stays in the record")
        return text + "."


def saturation_note(description):
    """The sentence :func:`cut_at_saturation` added to a record's description, or None."""
    text = description or ""
    i = text.find(NOTE_START)
    if i < 0:
        return None
    return text[i:]                          # the last sentence: cut_at_saturation appends it


def saturated_rates(experiment, *, gyro_range_rps):
    """Samples at which any gyro axis's rate reaches the range, (N,) bool.

    Parameters
    ----------
    experiment : Experiment
    gyro_range_rps : float
        The gyros' full-scale range, rad/s (positive).
    """
    r = float(gyro_range_rps)
    if not np.isfinite(r) or r <= 0.0:
        raise InputError(f"the gyro range must be a positive number, got {gyro_range_rps!r}", dataset="gyro_range")
    w = np.abs(experiment.dtheta / experiment.dt[:, None])
    return np.any(w >= r * (1.0 - RANGE_TOLERANCE), axis=1)


#: A flat top below this rate, rad/s (57 deg/s), is not taken for saturation: no gyro's range is that small.
FLAT_TOP_MIN_RPS = 1.0
#: A flat top holding more than this fraction of the samples, in more than FLAT_TOP_MAX_RUNS runs, or in a run longer
#: than FLAT_TOP_MAX_RUN_S, s, is a plateau (a table turning at a constant rate), not a saturated turn.
FLAT_TOP_MAX_FRACTION = 0.05
FLAT_TOP_MAX_RUNS = 20
FLAT_TOP_MAX_RUN_S = 2.0


def flat_tops(experiment, *, rests=None):
    """Where a gyro sits at its largest output in runs, as a saturated gyro does, and no boundary follows.

    For each gyro axis and sign, the samples whose rate equals the record's extreme to the last bits
    (``1e-9`` relative) when that extreme exceeds :data:`FLAT_TOP_MIN_RPS`, some of them consecutive, in at
    most :data:`FLAT_TOP_MAX_RUNS` runs none longer than :data:`FLAT_TOP_MAX_RUN_S`, and at most
    :data:`FLAT_TOP_MAX_FRACTION` of the record (else a plateau: a table turning at a constant rate). An episode
    (:data:`EPISODE_GAP_S`) that a segment boundary follows before the next rest is not counted (the record was cut there), nor one after its
    segment's last rest (no rotation factor ties it to a later attitude that gravity fixes).

    Parameters
    ----------
    experiment : Experiment
    rests : array_like of int, shape (P, 2), optional
        The static intervals the calibration takes, ``[start, stop)`` samples of the record; default
        :func:`graph_calib.noise.rests.record_rests`'s, found only when a flat top is seen.

    Returns
    -------
    dict or None
        ``{"samples": int, "episodes": int, "axes": {"x": [extreme rate, rad/s, per sign seen], ...}}``, or None.
    """
    w = experiment.dtheta / experiment.dt[:, None]
    n = w.shape[0]
    mask = np.zeros(n, dtype=bool)
    axes = {}
    for j, ax in enumerate("xyz"):
        for v in (w[:, j], -w[:, j]):
            top = float(np.max(v))
            if top <= FLAT_TOP_MIN_RPS:
                continue
            at = v >= top * (1.0 - 1e-9)
            runs = _episodes(at, 1)
            length = runs[:, 1] - runs[:, 0]
            if (at.sum() > FLAT_TOP_MAX_FRACTION * n or length.max() < 2 or runs.shape[0] > FLAT_TOP_MAX_RUNS
                    or length.max() > FLAT_TOP_MAX_RUN_S * experiment.rate_hz):
                continue
            mask |= at
            axes.setdefault(ax, []).append(float(w[np.flatnonzero(at)[0], j]))
    if not mask.any():
        return None
    seg = np.zeros(n, dtype=np.int64) if experiment.segment is None else np.asarray(experiment.segment)
    starts = set((np.flatnonzero(np.diff(seg)) + 1).tolist())
    rests = record_rests(experiment) if rests is None else rests
    rest_starts = np.sort(np.asarray(rests, dtype=np.int64).reshape(-1, 2)[:, 0])

    def tied(b):                 # a rest of the same segment after it, and no boundary right after it
        later = rest_starts[rest_starts >= b]
        return b not in starts and later.size > 0 and seg[later[0]] == seg[b - 1]

    open_ = [(a, b) for a, b in _episodes(mask, max(1, int(round(EPISODE_GAP_S * experiment.rate_hz))))
             if b < n and tied(b)]
    if not open_:
        return None
    return {"samples": int(sum(int(mask[a:b].sum()) for a, b in open_)), "episodes": len(open_), "axes": axes}


def flat_top_text(tops):
    """``tops`` (:func:`flat_tops`) in words: the axes, their extremes (deg/s), the samples and episodes."""
    where = ", ".join(f"{ax} at {' and '.join(f'{np.degrees(v):+.5g}' for v in vs)} deg/s"
                      for ax, vs in tops["axes"].items())
    e = tops["episodes"]
    return f"({where}) in {tops['samples']} samples ({e} episode{'s' if e > 1 else ''})"


def cut_at_range(experiment, *, gyro_range_rps):
    """:func:`cut_at_saturation` at the samples whose rate reaches ``gyro_range_rps`` (:func:`saturated_rates`)."""
    return cut_at_saturation(experiment, saturated_rates(experiment, gyro_range_rps=gyro_range_rps))


def _episodes(mask, gap):
    """``[start, stop)`` of the runs of ``mask``, runs fewer than ``gap`` samples apart joined."""
    runs = _runs(mask).astype(np.int64).reshape(-1, 2)
    if runs.shape[0] < 2:
        return runs
    new = np.concatenate([[True], runs[1:, 0] - runs[:-1, 1] >= gap])
    first = np.flatnonzero(new)
    last = np.concatenate([first[1:] - 1, [runs.shape[0] - 1]])
    return np.column_stack([runs[first, 0], runs[last, 1]])


def cut_at_saturation(experiment, saturated):
    """Cut ``experiment`` after each episode of ``saturated`` samples that has a rest after it (module doc).

    Parameters
    ----------
    experiment : Experiment
    saturated : array_like of bool, shape (N,)

    Returns
    -------
    SaturationCuts
        With ``experiment`` cut (its description saying where); the record unchanged without saturated samples.
    """
    sat = np.asarray(saturated, dtype=bool).reshape(-1)
    n = experiment.n_samples
    if sat.size != n:
        raise InputError(f"the saturation mask has {sat.size} samples, the record {n}", dataset="saturated")
    episodes = _episodes(sat, max(1, int(round(EPISODE_GAP_S * experiment.rate_hz))))
    own = np.zeros(n, dtype=np.int64) if experiment.segment is None else np.asarray(experiment.segment, np.int64)
    starts = set((np.flatnonzero(np.diff(own)) + 1).tolist())
    # a cut on the first sample after an episode, not on the record's end nor on a boundary the record has already
    at = {int(b): i for i, (_, b) in enumerate(episodes) if b < n and b not in starts}
    # an episode the record's end or one of its own boundaries follows needs no cut: nothing spans it already
    cut = np.array([b >= n or b in starts for _, b in episodes], dtype=bool)
    while at:
        trial = replace(experiment, segment=_labels(own, sorted(at), n))
        # a piece without a rest cannot be aligned: the cut at its start goes (at its end, for the first piece)
        drop = [a if a in at else b for a, b, _, long, short in segment_rests(trial)
                if not (long.shape[0] or short.shape[0]) and (a in at or b in at)]
        if not drop:
            cut[list(at.values())] = True
            break
        for s in drop:
            at.pop(s, None)
    out = SaturationCuts(experiment=experiment, episodes=episodes, samples=int(sat.sum()), cut=cut,
                         rate_hz=float(experiment.rate_hz))
    if not episodes.shape[0]:
        return out
    added = [b for b in episodes[cut, 1] if b < n and b not in starts]
    segment = _labels(own, added, n) if added else experiment.segment
    earlier = saturation_note(experiment.description)          # a record cut before: its sentence replaced
    base = (experiment.description or "").replace(earlier, "").strip() if earlier else experiment.description or ""
    desc = " ".join(s for s in (base, out.describe()) if s)
    return replace(out, experiment=replace(experiment, segment=segment, description=desc))


def _labels(own, cuts, n):
    """Segment labels 0, 1, 2 ... of a record with segments ``own`` (N,) and boundaries added at ``cuts``."""
    mark = np.zeros(n, dtype=np.int64)
    mark[np.asarray(cuts, dtype=np.int64)] = 1
    mark[1:] |= (np.diff(own) != 0)
    return np.cumsum(mark).astype(np.int32)


__all__ = ["SaturationCuts", "saturated_rates", "cut_at_saturation", "cut_at_range", "saturation_note", "flat_tops", "flat_top_text", "RANGE_TOLERANCE",
           "EPISODE_GAP_S", "EPISODE_INSIDE_S", "NOTE_START", "FLAT_TOP_MIN_RPS", "FLAT_TOP_MAX_FRACTION",
           "FLAT_TOP_MAX_RUNS", "FLAT_TOP_MAX_RUN_S"]
