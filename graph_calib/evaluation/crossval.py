r"""Out-of-sample figures of a calibration: fit on some poses of a record, judge on the others.

Labs trust a calibration that predicts what it has not seen.  A multi-position record (hand-held or on a
table) is a chain of rests joined by rotations; this module cuts it into ``K`` folds of consecutive rests,
calibrates on the record without one fold (the remaining pieces marked as segments, each aligned on its
own rest), and computes IMU-TK's figures of merit (:mod:`graph_calib.evaluation.imu_tk`) on the held-out
fold, with the calibration applied and without it (the raw samples).

Folds
-----
The rests are the record's static intervals as the calibration finds them (:func:`record_rests`: segment
by segment, each with its own threshold, rests down to 0.5 s included).  They are grouped into units of consecutive rests, and
the units are dealt to the ``K`` folds:

``by="pairs"`` (default)
    units of two consecutive rests, dealt in turn (unit ``u`` to fold ``u mod K``): every fold holds
    poses from the whole record, so each training record still sees many orientations;
``by="rests"``
    ``K`` contiguous blocks of rests (fold ``j`` holds rest ``i`` when ``floor(i K / P) = j``): the
    strictest split, where a fold's poses may be absent from its training record altogether;
``by="segments"``
    a record cut together from pieces (``/imu/segment``) folded by whole segments;
``by="transitions"``
    only the rotations between consecutive rests are held out (the motion from the end of rest ``i``
    to the start of rest ``i + 1``, dealt in turn), every rest stays in the training record: the gyro
    triad is judged out of sample on the transitions while the accelerometer triad keeps every pose
    (a six-face session has no face to spare); the static figures are then not held out and are left
    out (NaN);
``by="faces"``
    :func:`face_to_face_folds`: the rotations between two faces alone, dealt in turn, the full turns of a
    Ferraris session kept for training with the rests (what imucal fits, so that on the held-out motions both
    are out of sample).

A unit's held-out span runs from the first sample of its first rest to the first sample of the rest
after its last (or the record's end), so the rotations inside a unit are held out with its rests and
the training record's pieces (marked as segments) each start at rest.  A training piece without a rest
(motion before the first rest), or one in which the calibration's own detection, with the piece's own
threshold, finds none (a short first rest after a start in motion), cannot be aligned and is left out.

Held-out figures (per fold, and pooled over the folds)
------------------------------------------------------
``static_norm_std_mps2``
    the spread (standard deviation over the held-out rests) of ``|mean f|``, m/s^2: a calibrated
    accelerometer triad reads the same ``|g|`` in every pose;
``transitions_rms_deg`` (median, max)
    the angle between the gravity direction predicted by integrating the calibrated rate over each
    held-out rotation and the one measured after it, deg (IMU-TK's check);
``static_rate_rms_dps``
    RMS over the held-out rests of ``|mean omega|``, deg/s: what a still unit appears to turn at,
    the Earth rate (at most 0.0042 deg/s) included.

A calibration whose held-out figures are worse than the raw samples' (by more than :data:`WORSE_FACTOR`) is worse
than none: the command line says so and exits 3, whether pooled over the folds or on any one fold.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from graph_calib.constants import RAD_TO_DEG
from graph_calib.errors import InputError
from graph_calib.evaluation.imu_tk import transition_figures
from graph_calib.noise.rests import record_rests
from graph_calib.records.experiment import Table

#: The figures compared between calibrated and raw, and whether smaller is better (all are).
FIGURES = ("static_norm_std_mps2", "transitions_rms_deg", "static_rate_rms_dps")

#: A held-out figure counts as worse than the raw one when it exceeds it by this factor: within 2 % the two are
#: the same figure (a navigation-grade unit's static rate is the Earth rate's, raw and calibrated, and a unit that
#: turns slowly in a quiet "rest" reads its turn in both: the last digits decided, and a good calibration failed).
WORSE_FACTOR = 1.02
#: A rotation between two rests whose raw gyro angle about one axis exceeds this is a full turn (a Ferraris
#: session's 360 deg turns), deg.
FULL_TURN_DEG = 300.0


@dataclass(frozen=True)
class Fold:
    """One held-out part of a record.

    Attributes
    ----------
    index : int
    spans : tuple of (int, int)
        The held-out samples, ``start:stop`` per span, in order.
    rests : tuple of ndarray of int, shape (K_s, 2)
        Each span's rests, ``[start, stop)`` sample indices of the whole record (for a transitions
        fold: the two rests the held-out rotation joins, which stay in the training record).
    transitions_only : bool
        Only the rotations are held out (``by="transitions"``).
    """

    index: int
    spans: tuple
    rests: tuple
    transitions_only: bool = False

    @property
    def n_rests(self):
        return int(sum(r.shape[0] for r in self.rests))


@dataclass(frozen=True)
class HeldOutFigures:
    """IMU-TK's figures on one held-out part (module docstring), SI except the named degrees."""

    n_rests: int
    static_norm_std_mps2: float
    transitions_rms_deg: float
    transitions_median_deg: float
    transitions_max_deg: float
    static_rate_rms_dps: float

    def to_json(self):
        """The figures; one not held out (NaN: the static ones of ``by="transitions"``) as None (JSON null)."""
        return {k: _json_float(v) if isinstance(v, float) else v for k, v in self.__dict__.items()}


def _json_float(v):
    return float(v) if np.isfinite(v) else None


@dataclass(frozen=True)
class FoldResult:
    """A fold's figures with the calibration fitted without it, and raw."""

    fold: Fold
    calibrated: HeldOutFigures
    raw: HeldOutFigures

    def worse_than_raw(self):
        """Names of the figures where the calibration is worse than the raw samples."""
        return tuple(k for k in FIGURES
                     if getattr(self.calibrated, k) > WORSE_FACTOR * getattr(self.raw, k))


@dataclass(frozen=True)
class CrossValidation:
    """Every fold's held-out figures.

    Attributes
    ----------
    folds : tuple of FoldResult
    by : str
        ``"pairs"``, ``"rests"`` or ``"segments"``.
    """

    folds: tuple
    by: str

    def pooled(self, which):
        """``{figure: value}`` pooled over the folds (RMS of the per-fold figures), for ``'calibrated'`` or ``'raw'``."""
        out = {}
        for k in FIGURES:
            v = np.array([getattr(getattr(f, which), k) for f in self.folds], dtype=float)
            v = v[np.isfinite(v)]
            out[k] = float(np.sqrt(np.mean(v ** 2))) if v.size else float("nan")
        return out

    def worse_than_raw(self):
        """Names of the pooled figures where the calibration is worse than the raw samples."""
        cal, raw = self.pooled("calibrated"), self.pooled("raw")
        return tuple(k for k in FIGURES if np.isfinite(cal[k]) and cal[k] > WORSE_FACTOR * raw[k])

    def folds_worse_than_raw(self):
        """``((fold index, figure names), ...)`` of the folds where the calibration is worse than the raw samples."""
        return tuple((f.fold.index, w) for f in self.folds if (w := f.worse_than_raw()))

    def to_json(self):
        return {
            "format": "imu-calibration-crossval", "version": 1, "by": self.by,
            "folds": [{"index": f.fold.index, "spans": [[int(a), int(b)] for a, b in f.fold.spans],
                       "rests": f.fold.n_rests, "calibrated": f.calibrated.to_json(),
                       "raw": f.raw.to_json(), "worse_than_raw": list(f.worse_than_raw())} for f in self.folds],
            "pooled": {w: {k: _json_float(v) for k, v in self.pooled(w).items()} for w in ("calibrated", "raw")},
            "worse_than_raw": list(self.worse_than_raw()),
        }


def make_folds(experiment, *, folds=2, by="pairs", rests=None):
    """The folds of a record (module docstring).

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    folds : int
        Number of folds, at least 2.
    by : {'pairs', 'rests', 'segments', 'transitions', 'faces'}
        ``faces``: :func:`face_to_face_folds` (the rotations between two faces alone; every rest and full turn stays).
    rests : array_like of int, shape (P, 2), optional
        ``[start, stop)`` of the rests; default :func:`record_rests`.

    Returns
    -------
    list of Fold
    """
    if folds < 2:
        raise InputError(f"needs at least 2 folds, got {folds}", dataset="--folds")
    rests = record_rests(experiment) if rests is None else np.asarray(rests, dtype=np.int64).reshape(-1, 2)
    if by == "faces":
        return face_to_face_folds(experiment, folds=folds, rests=rests)
    n, p = experiment.n_samples, rests.shape[0]
    if by == "segments":
        bounds = experiment.segment_bounds()
        if len(bounds) < folds:
            raise InputError(f"has {len(bounds)} segment(s), fewer than the {folds} folds asked for",
                             path=experiment.source or None, dataset="/imu/segment")
        out = []
        for j, g in enumerate(np.array_split(np.arange(len(bounds)), folds)):
            spans = tuple(bounds[i] for i in g)
            out.append(Fold(index=j, spans=spans, rests=tuple(
                rests[(rests[:, 0] >= a) & (rests[:, 1] <= b)] for a, b in spans)))
        return out
    if by == "transitions":
        if p - 1 < folds:
            raise InputError(f"has {p} rest(s), {max(p - 1, 0)} transition(s): fewer than the {folds} folds asked "
                             f"for", path=experiment.source or None, dataset="/imu")
        return _transition_folds(rests, np.arange(p - 1), folds)
    if by == "pairs":
        units = [np.arange(i, min(i + 2, p)) for i in range(0, p, 2)]
        owner = np.arange(len(units)) % folds
    elif by == "rests":
        units = [np.arange(p)]
        units = [idx for idx in np.array_split(np.arange(p), folds)]
        owner = np.arange(len(units))
    else:
        raise InputError(f"folds are made by 'pairs', 'rests', 'segments', 'transitions' or 'faces', not {by!r}",
                         dataset="--by")
    if p < 2 * folds or len(units) < folds:
        raise InputError(f"has {p} rest(s): {folds} folds need at least {2 * folds} (two per fold, one rotation "
                         f"between them)", path=experiment.source or None, dataset="/imu")
    out = []
    for j in range(folds):
        spans, rs = [], []
        for u in (units[k] for k in np.flatnonzero(owner == j)):
            start = int(rests[u[0], 0])
            stop = int(rests[u[-1] + 1, 0]) if u[-1] + 1 < p else n
            spans.append((start, stop))
            rs.append(rests[u])
        out.append(Fold(index=j, spans=tuple(spans), rests=tuple(rs)))
    return out


def face_to_face_folds(experiment, *, folds=2, rests=None):
    """Folds of the rotations between two faces alone, dealt in turn (a ``by="transitions"`` fold of those): every
    rest and every full turn (a raw gyro angle above :data:`FULL_TURN_DEG` about one axis) stays in the training
    record.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    folds : int
    rests : array_like of int, shape (P, 2), optional
        ``[start, stop)`` of the rests; default :func:`record_rests`.

    Returns
    -------
    list of Fold
    """
    rests = record_rests(experiment) if rests is None else np.asarray(rests, dtype=np.int64).reshape(-1, 2)
    turn = np.deg2rad(FULL_TURN_DEG)
    faces = [i for i in range(rests.shape[0] - 1)
             if np.max(np.abs(experiment.dtheta[rests[i, 1]:rests[i + 1, 0]].sum(axis=0))) < turn]
    if len(faces) < folds:
        raise InputError(f"has {len(faces)} rotation(s) between two faces: fewer than the {folds} folds asked for",
                         path=experiment.source or None, dataset="/imu")
    return _transition_folds(rests, np.asarray(faces, dtype=np.int64), folds)


def _transition_folds(rests, which, folds):
    """Folds of the rotations ``which`` (rest ``i`` to rest ``i + 1``), dealt in turn; every rest stays."""
    return [Fold(index=j, spans=tuple((int(rests[i, 1]), int(rests[i + 1, 0])) for i in which[j::folds]),
                 rests=tuple(rests[i:i + 2] for i in which[j::folds]), transitions_only=True) for j in range(folds)]


def _segments_of(experiment):
    return np.zeros(experiment.n_samples, dtype=np.int64) if experiment.segment is None else \
        np.asarray(experiment.segment, dtype=np.int64)


def _complement(spans, n):
    edges, a = [], 0
    for s, e in sorted(spans):
        if s > a:
            edges.append((a, s))
        a = max(a, e)
    if a < n:
        edges.append((a, n))
    return edges


def training_record(experiment, fold, *, rests):
    """The record without the fold's spans, its pieces marked as segments (those without a rest left out).

    A piece counts as having a rest when the calibration finds one in it: segment by segment, with the piece's
    own threshold (:func:`record_rests` of the cut record), which need not see the rest the whole record's
    detection found there (a short first rest after a start in motion); a piece where it finds none is left
    out, since the calibration could not align it.
    """
    seg = _segments_of(experiment)
    pieces = []
    for a, b in _complement(fold.spans, experiment.n_samples):
        # split further at the record's own segment boundaries
        cuts = [a] + [int(k) for k in np.flatnonzero(np.diff(seg[a:b])) + a + 1] + [b]
        for s, e in zip(cuts[:-1], cuts[1:]):
            if np.any((rests[:, 0] >= s) & (rests[:, 1] <= e)):
                pieces.append((s, e))
    while True:
        if not pieces:
            raise InputError(f"fold {fold.index + 1}: nothing with a rest is left to calibrate on",
                             path=experiment.source or None, dataset="/imu")
        cut = _cut(experiment, fold, pieces)
        if len(pieces) == 1:
            return cut
        found = record_rests(cut)
        starts = np.cumsum([0] + [e - s for s, e in pieces])
        keep = [(s, e) for (s, e), a, b in zip(pieces, starts[:-1], starts[1:])
                if np.any((found[:, 0] >= a) & (found[:, 1] <= b))]
        if len(keep) == len(pieces):
            return cut
        pieces = keep


def _cut(experiment, fold, pieces):
    """``experiment`` restricted to ``pieces`` (``[(start, stop)]``), each marked as a segment when there are several."""
    idx = np.concatenate([np.arange(s, e) for s, e in pieces])
    labels = np.concatenate([np.full(e - s, i, dtype=np.int32) for i, (s, e) in enumerate(pieces)])
    table = experiment.table
    if table is not None:
        keep = np.zeros(table.t.shape[0], dtype=bool)
        dt0 = 1.0 / experiment.rate_hz
        for s, e in pieces:
            t0 = experiment.t[s] - (experiment.t[s] - experiment.t[s - 1] if s > 0 else dt0)
            keep |= (table.t > t0) & (table.t <= experiment.t[e - 1])
        table = Table(table.t[keep], table.q_nf[keep], table.valid[keep], table.q_fb_nominal,
                      None if table.axes_f is None else table.axes_f[keep])
    return replace(experiment, t=experiment.t[idx], dtheta=experiment.dtheta[idx], dv=experiment.dv[idx],
                   temperature=experiment.temperature[idx], table=table,
                   segment=labels if len(pieces) > 1 else None,
                   description=f"{experiment.description} (cross-validation: fold {fold.index + 1} held out)".strip())


def held_out_figures(experiment, fold, calibration=None):
    """IMU-TK's figures on the fold's rests and the rotations between them (``calibration`` None: raw); a rotation
    between two rests of different segments (``/imu/segment``: attitude not continuous) is not judged."""
    norms, angles, rates = [], [], []
    for (start, stop), rests in zip(fold.spans, fold.rests):
        if not rests.shape[0]:
            continue
        if fold.transitions_only:
            start, stop = int(rests[0, 0]), int(rests[-1, 1])
        part = experiment.slice(start, stop)
        iv = rests - start
        iv = np.column_stack([iv[:, 0], iv[:, 1] - 1])               # IMU-TK's [a, e], both included
        fig = transition_figures(part, calibration, intervals=iv)
        norms.append(np.asarray(fig.static_norm, dtype=float))
        # no transition across a segment boundary: attitude is not continuous there (a cut, a saturated turn)
        seg = _segments_of(part)
        same = seg[iv[:-1, 1]] == seg[iv[1:, 0]]
        angles.append(np.asarray(fig.angles_rad, dtype=float)[same] * RAD_TO_DEG)
        omega = (part.dtheta / part.dt[:, None]) if calibration is None else calibration.correct(part)[0]
        c = np.vstack([np.zeros((1, 3)), np.cumsum(omega, axis=0)])
        mean_rate = (c[iv[:, 1] + 1] - c[iv[:, 0]]) / (iv[:, 1] + 1 - iv[:, 0])[:, None]
        rates.append(np.linalg.norm(mean_rate, axis=1) * RAD_TO_DEG)
    norm, ang, rate = (np.concatenate(v) if v else np.zeros(0) for v in (norms, angles, rates))
    nan = float("nan")
    if fold.transitions_only:
        norm, rate = np.zeros(0), np.zeros(0)
    return HeldOutFigures(
        n_rests=int(norm.size),
        static_norm_std_mps2=float(np.std(norm)) if norm.size > 1 else nan,
        transitions_rms_deg=float(np.sqrt(np.mean(ang ** 2))) if ang.size else nan,
        transitions_median_deg=float(np.median(ang)) if ang.size else nan,
        transitions_max_deg=float(np.max(ang)) if ang.size else nan,
        static_rate_rms_dps=float(np.sqrt(np.mean(rate ** 2))) if rate.size else nan,
    )


def cross_validate(experiment, *, fit, folds=2, by="pairs", progress=None, rests=None):
    """Calibrate without each fold in turn and judge on it.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    fit : callable
        ``fit(training_experiment) -> Calibration`` (anything with ``correct(experiment) -> (omega_ib_b, f_b)``).
    folds : int
    by : {'pairs', 'rests', 'segments', 'transitions'}
    progress : callable, optional
        Called with a line of text per fold.
    rests : ndarray of int, shape (P, 2), optional
        The record's rests when the caller has them (default :func:`record_rests`).

    Returns
    -------
    CrossValidation
    """
    rests = record_rests(experiment) if rests is None else rests
    out = []
    for fold in make_folds(experiment, folds=folds, by=by, rests=rests):
        if progress is not None:
            progress(f"fold {fold.index + 1}/{folds}: {len(fold.spans)} span(s), {fold.n_rests} rests held out")
        calibration = fit(training_record(experiment, fold, rests=rests))
        out.append(FoldResult(fold=fold, calibrated=held_out_figures(experiment, fold, calibration),
                              raw=held_out_figures(experiment, fold)))
    return CrossValidation(folds=tuple(out), by=by)


def crossval_table(cv):
    """The terminal table: per fold and pooled, calibrated against raw."""
    head = f"{'fold':>6} {'rests':>5} {'|f| spread [m/s^2]':>22} {'transitions rms [deg]':>24} {'static rate [deg/s]':>22}"
    lines = [head, f"{'':>6} {'':>5} {'calibrated':>11}{'raw':>11} {'calibrated':>12}{'raw':>12} {'calibrated':>11}{'raw':>11}"]

    def cell(v, width, spec):
        return f"{v:>{width}{spec}}" if np.isfinite(v) else f"{'-':>{width}}"

    def row(name, n, c, r):
        return f"{name:>6} {n:>5} " + " ".join(cell(c[k], w, spec) + cell(r[k], w, spec) for k, w, spec in (
            ("static_norm_std_mps2", 11, ".3e"), ("transitions_rms_deg", 12, ".3f"), ("static_rate_rms_dps", 11, ".4f")))

    for f in cv.folds:
        lines.append(row(str(f.fold.index + 1), f.calibrated.n_rests, f.calibrated.__dict__, f.raw.__dict__))
    lines.append(row("all", sum(f.calibrated.n_rests for f in cv.folds), cv.pooled("calibrated"), cv.pooled("raw")))
    if cv.by == "transitions":
        lines.append("(-: not held out; with folds by transitions or faces every rest stays in the training record)")
    return "\n".join(lines)
