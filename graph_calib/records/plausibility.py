r"""Is the record physically plausible?  The units of the gyro increments, judged from the motion.

The experiment file's reader (:mod:`graph_calib.io.experiment_file`) checks the format and per-sample
bounds: ``|dtheta| / dt`` at most 35 rad/s, ``|dv| / dt`` at most 16 g, and the record's median
``|dv| / dt`` within 0.5..2 x gravity (so specific force in g, or increments not in m/s, are refused
there and not again here).  What it cannot see is a gyro record in the wrong unit whose rates stay
under its bound: a turntable's 30 deg/s written in degrees is 30 "rad/s".  :func:`check_record` sees
it from the motion, with two rules, and refuses with one :class:`~graph_calib.errors.InputError`
naming the file, the dataset, the ratio found and its likely cause.

Turn rule (a table with valid readings)
    Between consecutive valid readings ``i``, ``j`` the encoders give the body's rotation against
    inertial space, ``A_e = q_nb,i^-1 Exp(omega_ie^n (t_j - t_i)) q_nb,j`` with
    ``q_nb = q_nf q_fb_nominal``, of angle ``theta_e`` about the axis ``u``.  The gyro turn is the
    sum of the increments projected on ``u``, unwrapped, so that a 90-deg turn written in degrees gives
    5157 deg and not 5157 deg modulo 360.  A bias is taken off first: the gyros' median rate (less the
    encoders' rotation, the Earth rate) over the readings where the encoders see the table at rest (a
    turn below :data:`REST_TURN_RAD`).  The ratio of the gyro turn to ``theta_e`` is near 1 for a
    right record.  A turn beyond 180 deg (seen by the encoders as the shorter rotation the other way)
    counts as ratio ``theta_g / theta_e`` when the gyros'
    rotation (:func:`graph_calib.navigation.strapdown.integrate_attitude`, the Earth rate removed) matches the
    encoders' to within :data:`MATCH_TOLERANCE` of the turn.  The record's ratio is the median over
    the :data:`N_TURNS` largest turns (at least :data:`MIN_TURN_RAD` and a quarter of the largest):
    the largest, so that encoder noise, the bias and scale errors of a consumer unit (a few %) stay
    small against them.  Outside :data:`TURN_RATIO_RANGE` the record is refused: 57.3 is degrees
    written for radians, 0.0175 the reverse, ``rate_hz`` rates written for increments, anything
    else wrong units or a wrong rate.

Static rule (a record without a table, or whose table shows no turn)
    The median over the static intervals of the mean angular rate must stay below
    :data:`STATIC_RATE_FACTOR` times the gyro bias prior of the loosest grade (consumer, 2 deg/s) plus
    the Earth rate.  The bound does not depend on the grade the
    user asked for: a consumer unit calibrated with ``--grade navigation`` is not refused here (the
    verdict judges that later), while a consumer unit whose bias (above 0.7 deg/s) is written in degrees
    is (2 deg/s becomes 2 "rad/s", 115 deg/s).  A navigation-grade unit at rest turns at the Earth
    rate only, so degrees for radians without a table stay unseen by this rule (0.24 deg/s).  The static
    intervals are those of :func:`graph_calib.navigation.static_detection.detect_static` with ``max_rate`` half the
    bound: quiet accelerometers are not enough, since a turn about the vertical at a constant rate leaves
    the specific force unchanged.  On a table with turns the turn rule decides alone.

Tilt rule (a record without a table, or whose table shows no turn)
    Between consecutive rests (:func:`graph_calib.navigation.static_detection.detect_static`, as the static rule's)
    of one segment, gravity's direction in the body turns by ``theta_f``, the angle between the rests' mean specific
    forces ``f_1`` and ``f_2``.  The gyros (their median rate over the rests taken off as a bias) say by how much:
    ``theta_g``, the angle between ``f_1`` and ``A^T f_1``, ``A = C_nb,1^T C_nb,2`` their attitude change between
    the rests' middles (:func:`graph_calib.navigation.strapdown.integrate_attitude`, the Earth rate in).  The ratio
    ``theta_g / theta_f`` is near 1 for a right record; the record's is the median over the :data:`N_TURNS` largest
    changes of at least :data:`MIN_TILT_RAD`, refused outside :data:`TURN_RATIO_RANGE` with the cause of the turn
    rule: 0.0175 is radians taken for degrees (rad/s imported as deg/s), which the static rule cannot see.

Continuity rule (every record)
    A record cut together from pieces (sections of a session with the motion between them removed)
    without ``/imu/segment`` is refused at the first cut, naming the sample
    (:func:`check_continuity`): where the :data:`JUMP_WINDOW_S` before a sample and the same length
    after it are both at rest (mean ``|f|`` within :data:`JUMP_REST_FRACTION` of gravity, scatter of
    ``f`` below :data:`JUMP_REST_SCATTER`, mean rate below :data:`JUMP_REST_RATE`) and their mean
    specific forces differ in direction by more than :data:`JUMP_ANGLE_RAD` beyond what the gyros
    turned between the two windows' middles.  A hand's acceleration tilts a window mean by a degree
    or two (0.2 m/s^2), a tap by a few: far below the bound.  A cut between two moving sections is
    not seen by this rule (nor is a saturated gyro in violent motion taken for a cut); the io reader's
    gap rule still sees a cut whose time stamps jump.

Examples
--------
>>> from graph_calib.simulation import simulate                              # doctest: +SKIP
>>> sim = simulate("nav-subrange-short", rng=np.random.default_rng(1), hours=0.05)   # doctest: +SKIP
>>> exp = sim.run()[0].experiment                                           # doctest: +SKIP
>>> round(turn_ratio(exp), 2)                                                # doctest: +SKIP
1.0
"""

from __future__ import annotations

import numpy as np

from graph_calib import constants as c
from graph_calib.errors import InputError
from graph_calib.sensors.params import GRADES
from graph_calib.navigation.rotations import (
    quat_conjugate,
    quat_multiply,
    quat_to_dcm,
    quat_to_rotvec,
    rotvec_to_quat,
)
from graph_calib.navigation.static_detection import detect_static
from graph_calib.navigation.strapdown import attitude_times, integrate_attitude, slerp_attitude

#: Accepted ratio of the gyro turns to the encoders' (median over the largest turns).
TURN_RATIO_RANGE = (0.5, 2.0)
#: Number of the largest turns whose ratios make the median.
N_TURNS = 9
#: Smallest encoder turn counted, rad; turns below a quarter of the largest are not counted either.
MIN_TURN_RAD = 1.0 * c.DEG_TO_RAD
#: A turn whose gyro rotation matches the encoders' within this fraction of the turn (or 2 deg) counts as
#: matching (ratio ``theta_g / theta_e``), whatever its projected sum: turns beyond 180 deg.
MATCH_TOLERANCE = 0.1
#: Encoder turn below which the table counts as at rest between two readings (for the gyro bias), rad.
REST_TURN_RAD = 0.2 * c.DEG_TO_RAD
#: Smallest change of gravity's direction between two rests that the tilt rule counts, rad.
MIN_TILT_RAD = 20.0 * c.DEG_TO_RAD
#: Multiple of the loosest grade's gyro bias prior above which a static rate is refused.
STATIC_RATE_FACTOR = 20.0
#: How close (as a factor) a ratio must be to a named cause to be called that cause.
CAUSE_FACTOR = 1.3

#: Length of the windows either side of a sample whose mean specific forces are compared, s.
JUMP_WINDOW_S = 0.1
#: Direction change of the mean specific force, beyond the gyros' turn, that counts as a cut, rad.
JUMP_ANGLE_RAD = 15.0 * c.DEG_TO_RAD
#: Both windows count as at rest when their mean |f| is within this fraction of gravity ...
JUMP_REST_FRACTION = 0.1
#: ... the scatter of f inside each (root of the summed per-axis variances) is below this, m/s^2 ...
JUMP_REST_SCATTER = 0.5
#: ... and the magnitude of each one's mean angular rate is below this, rad/s (about 17 deg/s).
JUMP_REST_RATE = 0.3

_DTHETA = "/imu/dtheta"
_DV = "/imu/dv"


def attitude_jumps(experiment):
    """Samples where the specific force turns more than the gyros explain (the continuity rule).

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment

    Returns
    -------
    index : ndarray of int, shape (J,)
        First sample after each jump (inside one segment; a boundary of ``/imu/segment`` is allowed).
    excess : ndarray, shape (J,)
        Angle between the windows' mean specific forces less the gyros' turn between them, rad.
    """
    n = experiment.n_samples
    W = max(3, int(round(JUMP_WINDOW_S * experiment.rate_hz)))
    empty = np.zeros(0, dtype=np.int64), np.zeros(0)
    if n < 2 * W:
        return empty
    dt = experiment.dt
    cum_v = np.vstack([np.zeros((1, 3)), np.cumsum(experiment.dv, axis=0)])
    cum_t = np.concatenate([[0.0], np.cumsum(dt)])
    cum_w = np.vstack([np.zeros((1, 3)), np.cumsum(experiment.dtheta, axis=0)])
    f = experiment.dv / dt[:, None]
    cum_f2 = np.concatenate([[0.0], np.cumsum(np.einsum("ij,ij->i", f, f))])
    # every window [s, s + W): mean specific force, its scatter, mean rate; quiet = at rest
    span = cum_t[W:] - cum_t[:-W]
    m_f = (cum_v[W:] - cum_v[:-W]) / span[:, None]
    norm_f = np.sqrt(np.einsum("ij,ij->i", m_f, m_f))
    scatter2 = (cum_f2[W:] - cum_f2[:-W]) / W - norm_f**2
    rate = np.linalg.norm(cum_w[W:] - cum_w[:-W], axis=1) / span
    g = float(experiment.gravity_mps2)
    quiet = ((np.abs(norm_f - g) < JUMP_REST_FRACTION * g) & (scatter2 < JUMP_REST_SCATTER**2)
             & (rate < JUMP_REST_RATE))
    # the jump lies between samples j - 1 and j: windows [j - W, j) and [j, j + W), both quiet
    j = W + np.flatnonzero(quiet[: n - 2 * W + 1] & quiet[W:])
    if experiment.segment is not None:
        # a window pair that touches a segment boundary is not judged
        cuts = np.concatenate([[0], np.cumsum(np.diff(np.asarray(experiment.segment)) != 0)])
        j = j[cuts[j - W] == cuts[j + W - 1]]
    if j.size == 0:
        return empty
    f0, f1 = m_f[j - W], m_f[j]
    h = W // 2                                   # the gyros' turn between the windows' middles
    turn = np.linalg.norm(cum_w[j + h] - cum_w[j - h], axis=1)
    cosang = np.einsum("ij,ij->i", f0, f1) / np.maximum(norm_f[j - W] * norm_f[j], 1e-300)
    excess = np.arccos(np.clip(cosang, -1.0, 1.0)) - turn
    bad = np.flatnonzero(excess > JUMP_ANGLE_RAD)
    if bad.size == 0:
        return empty
    # one report per jump: the sample of the largest excess in each run of consecutive flagged samples
    runs = np.split(bad, np.flatnonzero(np.diff(j[bad]) > 1) + 1)
    best = np.array([r[np.argmax(excess[r])] for r in runs])
    return j[best].astype(np.int64), excess[best]


def check_continuity(experiment):
    """Refuse a record cut together without ``/imu/segment`` (the module docstring's continuity rule).

    Raises
    ------
    InputError
        Naming the file, ``/imu/dv``, the sample after the first cut and the angles found.
    """
    index, excess = attitude_jumps(experiment)
    if index.size == 0:
        return
    k = int(index[0])
    more = f" ({index.size} such places in all)" if index.size > 1 else ""
    raise InputError(
        f"the record is discontinuous before this sample: the specific force turns "
        f"{excess[0] * c.RAD_TO_DEG:.1f} deg more than the gyros between the {JUMP_WINDOW_S:g} s before and "
        f"after it, both at rest{more}; a record cut together from pieces needs /imu/segment marking each "
        f"piece (the CSV importer's segment column)", path=experiment.source or None, dataset=_DV, index=k)


def check_record(experiment):
    """Refuse a record cut together without ``/imu/segment``, or whose gyro increments cannot be in radians.

    The module docstring's continuity rule first (:func:`check_continuity`), then its turn rule, or its static
    and tilt rules.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
        A record that the reader accepted (finite, increasing time, shapes checked).

    Raises
    ------
    InputError
        Naming the file, ``/imu/dtheta``, the ratio found and its likely cause.
    """
    check_continuity(experiment)
    ratio, n, typical = turn_ratio(experiment, details=True)
    if ratio is not None:
        _refuse_ratio(experiment, ratio, f"the gyros turn {ratio:.4g} times as far as the encoders (median over the "
                                         f"{n} largest turns between valid /table readings, "
                                         f"{typical * c.RAD_TO_DEG:.3g} deg typical")
        return
    # at rest: quiet accelerometers, and a mean rate within half the static bound of the first seconds' (a turn about
    # the vertical at a constant rate leaves the specific force unchanged); the static and tilt rules' rests
    static = detect_static(experiment, max_rate=0.5 * static_rate_bound()[0])
    _check_static_rates(experiment, static)
    ratio, n, typical = tilt_ratio(experiment, static=static)
    if ratio is not None:
        _refuse_ratio(experiment, ratio, f"the gyros turn gravity's direction {ratio:.4g} times as far as the "
                                         f"accelerometers see it turn between rests (median over the {n} largest "
                                         f"changes, {typical * c.RAD_TO_DEG:.3g} deg typical")


def _refuse_ratio(experiment, ratio, what):
    """InputError on ``/imu/dtheta`` when a turn or tilt ``ratio`` is outside :data:`TURN_RATIO_RANGE`, naming it in
    ``what`` and its likely cause."""
    lo, hi = TURN_RATIO_RANGE
    if not lo <= ratio <= hi:
        raise InputError(f"{what}; accepted {lo:g}..{hi:g}): {_cause(ratio, experiment.rate_hz)}",
                         path=experiment.source or None, dataset=_DTHETA)


def _cause(ratio, rate_hz):
    """The likely cause of a turn (or rate) ratio, in words."""
    def near(x):
        return abs(np.log(ratio / x)) < np.log(CAUSE_FACTOR)

    if near(c.RAD_TO_DEG):
        return "degrees written for radians?"
    if near(c.DEG_TO_RAD):
        return "radians taken for degrees and converted again (rad/s imported as deg/s: --gyro-units)?"
    if near(rate_hz):
        return "angular rates (rad/s) written for increments (rad)?"
    if near(c.RAD_TO_DEG * rate_hz):
        return "rates in deg/s written for increments in rad?"
    return "wrong units, or increments made with a wrong sample rate?"


def turns(experiment):
    """Encoder turns between consecutive valid table readings and the gyros' ratio to each.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment

    Returns
    -------
    theta_e : ndarray, shape (M,)
        Encoder rotation angle of each turn, rad, in [0, pi].
    ratio : ndarray, shape (M,)
        Gyro turn over encoder turn (module docstring); empty arrays without a table or with fewer
        than two valid readings inside the record.
    """
    empty = np.zeros(0), np.zeros(0)
    tab = experiment.table
    if tab is None:
        return empty
    ta = attitude_times(experiment.t, experiment.rate_hz)
    valid = np.asarray(tab.valid, dtype=bool)
    tr = np.asarray(tab.t, dtype=float)[valid]
    q_nf = np.asarray(tab.q_nf, dtype=float)[valid]
    inside = (tr >= ta[0]) & (tr <= ta[-1])
    tr, q_nf = tr[inside], q_nf[inside]
    if tr.shape[0] < 2:
        return empty
    lat = float(experiment.latitude_rad)
    w_n = c.omega_ie_n(lat)
    span = np.diff(tr)
    # the encoders: the body's rotation against inertial space, from the faceplate through the nominal mounting
    q_nb = quat_multiply(q_nf, np.asarray(tab.q_fb_nominal, dtype=float))
    earth = rotvec_to_quat(span[:, None] * w_n)
    a_e = quat_multiply(quat_multiply(quat_conjugate(q_nb[:-1]), earth), q_nb[1:])
    r_e = quat_to_rotvec(a_e)
    theta_e = np.linalg.norm(r_e, axis=1)
    # the gyros' sums between readings, less a bias: their median rate where the encoders see the table at rest
    cum = np.vstack([np.zeros((1, 3)), np.cumsum(experiment.dtheta, axis=0)])
    summed = np.diff(np.column_stack([np.interp(tr, ta, cum[:, k]) for k in range(3)]), axis=0)
    rest = theta_e < REST_TURN_RAD
    bias = np.median((summed - r_e)[rest] / span[rest, None], axis=0) if rest.sum() >= 3 else np.zeros(3)
    summed = summed - bias * span[:, None]
    # the gyros' rotation between readings (Earth part of integrate_attitude taken off), for turns beyond 180 deg
    q = integrate_attitude(experiment.dtheta - bias * experiment.dt[:, None], t=experiment.t,
                           rate_hz=experiment.rate_hz, q_nb0=[1.0, 0.0, 0.0, 0.0], latitude_rad=lat)
    body_r = slerp_attitude(quat_multiply(rotvec_to_quat((ta - ta[0])[:, None] * w_n), q), ta, tr)
    a_g = quat_multiply(quat_conjugate(body_r[:-1]), body_r[1:])
    theta_g = np.linalg.norm(quat_to_rotvec(a_g), axis=1)
    mismatch = np.linalg.norm(quat_to_rotvec(quat_multiply(quat_conjugate(a_g), a_e)), axis=1)
    # the unwrapped gyro turn: the sums projected on the encoders' axis
    axis = r_e / np.maximum(theta_e, 1e-300)[:, None]
    projected = np.abs(np.sum(summed * axis, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        matches = mismatch <= np.maximum(MATCH_TOLERANCE * theta_e, 2.0 * c.DEG_TO_RAD)
        ratio = np.where(matches, theta_g, projected) / theta_e
    if experiment.segment is not None:                # a record cut from pieces: no turn across a cut
        seg_r = np.asarray(experiment.segment)[np.clip(np.searchsorted(experiment.t, tr), 0, experiment.n_samples - 1)]
        same = seg_r[:-1] == seg_r[1:]
        theta_e, ratio = theta_e[same], ratio[same]
    return theta_e, ratio


def turn_ratio(experiment, *, details=False):
    """The record's ratio of gyro to encoder turns: the median over the largest turns (module docstring).

    Returns
    -------
    float or None
        None without a table, or without a turn of at least :data:`MIN_TURN_RAD`.  With
        ``details=True``, ``(ratio, number of turns, median encoder turn in rad)``.
    """
    theta_e, ratio = turns(experiment)
    keep = theta_e >= MIN_TURN_RAD
    if not keep.any():
        return (None, 0, 0.0) if details else None
    keep &= theta_e >= 0.25 * theta_e[keep].max()
    order = np.argsort(theta_e[keep])[::-1][:N_TURNS]
    r = float(np.median(ratio[keep][order]))
    return (r, int(order.size), float(np.median(theta_e[keep][order]))) if details else r


def tilts(experiment, *, static=None):
    """Between consecutive rests of one segment: gravity's change of direction and the gyros' ratio to it.

    ``static``: the rests, ``[start, stop)`` (P, 2); default those of the static rule (detected here).

    Returns
    -------
    theta_f : ndarray, shape (M,)
        Angle between the rests' mean specific forces, rad.
    ratio : ndarray, shape (M,)
        The gyros' change of that direction over ``theta_f`` (module docstring's tilt rule); empty arrays with
        fewer than two rests.
    """
    empty = np.zeros(0), np.zeros(0)
    if static is None:
        try:
            static = detect_static(experiment, max_rate=0.5 * static_rate_bound()[0])
        except (InputError, ValueError):
            return empty
    if static.shape[0] < 2:
        return empty
    dt = experiment.dt
    cum_v = np.vstack([np.zeros((1, 3)), np.cumsum(experiment.dv, axis=0)])
    cum_w = np.vstack([np.zeros((1, 3)), np.cumsum(experiment.dtheta, axis=0)])
    cum_t = np.concatenate([[0.0], np.cumsum(dt)])
    a, b = static[:, 0], static[:, 1]
    f = cum_v[b] - cum_v[a]
    f /= np.linalg.norm(f, axis=1)[:, None]
    bias = np.median((cum_w[b] - cum_w[a]) / (cum_t[b] - cum_t[a])[:, None], axis=0)
    q = integrate_attitude(experiment.dtheta - bias * dt[:, None], t=experiment.t, rate_hz=experiment.rate_hz,
                           q_nb0=[1.0, 0.0, 0.0, 0.0], latitude_rad=float(experiment.latitude_rad))
    mid = (a + b) // 2
    C = quat_to_dcm(q[mid])
    A = np.swapaxes(C[:-1], 1, 2) @ C[1:]                  # C_nb,1^T C_nb,2
    predicted = np.einsum("kji,kj->ki", A, f[:-1])          # A^T f_1
    theta_f = np.arccos(np.clip(np.sum(f[:-1] * f[1:], axis=1), -1.0, 1.0))
    theta_g = np.arccos(np.clip(np.sum(f[:-1] * predicted, axis=1), -1.0, 1.0))
    if experiment.segment is not None:                    # no change across a cut
        seg = np.asarray(experiment.segment)
        same = seg[a[:-1]] == seg[b[1:] - 1]
        theta_f, theta_g = theta_f[same], theta_g[same]
    with np.errstate(divide="ignore", invalid="ignore"):
        return theta_f, theta_g / theta_f


def tilt_ratio(experiment, *, static=None):
    """``(ratio, number of changes, median change in rad)`` of the tilt rule, or ``(None, 0, 0.0)`` without a change
    of gravity's direction of at least :data:`MIN_TILT_RAD` between two rests (``static``: as :func:`tilts`)."""
    theta_f, ratio = tilts(experiment, static=static)
    keep = theta_f >= MIN_TILT_RAD
    if not keep.any():
        return None, 0, 0.0
    order = np.argsort(theta_f[keep])[::-1][:N_TURNS]
    return float(np.median(ratio[keep][order])), int(order.size), float(np.median(theta_f[keep][order]))


def static_rate_bound():
    """``(bound in rad/s, grade named)``: the static-rule bound of the module docstring."""
    name, g = max(GRADES.items(), key=lambda kv: kv[1].prior_sigma["gyro.bias"])
    return STATIC_RATE_FACTOR * float(g.prior_sigma["gyro.bias"]) + c.OMEGA_E, name


def _check_static_rates(experiment, static):
    bound, name = static_rate_bound()
    if static.shape[0] == 0:
        return
    dt = experiment.dt
    cum_w = np.vstack([np.zeros((1, 3)), np.cumsum(experiment.dtheta, axis=0)])
    cum_t = np.concatenate([[0.0], np.cumsum(dt)])
    a, b = static[:, 0], static[:, 1]
    mean_rate = np.linalg.norm(cum_w[b] - cum_w[a], axis=1) / (cum_t[b] - cum_t[a])
    rate = float(np.median(mean_rate))
    if rate > bound:
        sigma = GRADES[name].prior_sigma["gyro.bias"]
        raise InputError(
            f"the median angular rate over the {static.shape[0]} static interval(s) is {rate:.4g} rad/s "
            f"({rate * c.RAD_TO_DEG:.4g} deg/s), {rate / (sigma + c.OMEGA_E):.4g} times the largest plausible "
            f"bias plus the Earth rate (the {name} grade's gyro bias prior, {sigma * c.RAD_TO_DEG:.3g} deg/s; "
            f"refused beyond {STATIC_RATE_FACTOR:g} times): {_static_cause(rate, bound, experiment.rate_hz)}",
            path=experiment.source or None, dataset=_DTHETA)


def _static_cause(rate, bound, rate_hz):
    """A static rate's likely cause: the first unit fix that brings it under the bound."""
    if rate * c.DEG_TO_RAD <= bound:
        return "degrees written for radians?"
    if rate / rate_hz <= bound:
        return "angular rates (rad/s) written for increments (rad)?"
    if rate * c.DEG_TO_RAD / rate_hz <= bound:
        return "rates in deg/s written for increments in rad?"
    return "wrong units, or increments made with a wrong sample rate?"


__all__ = [
    "MATCH_TOLERANCE",
    "MIN_TILT_RAD",
    "MIN_TURN_RAD",
    "N_TURNS",
    "REST_TURN_RAD",
    "STATIC_RATE_FACTOR",
    "TURN_RATIO_RANGE",
    "JUMP_ANGLE_RAD",
    "JUMP_REST_FRACTION",
    "JUMP_REST_RATE",
    "JUMP_REST_SCATTER",
    "JUMP_WINDOW_S",
    "attitude_jumps",
    "check_continuity",
    "check_record",
    "static_rate_bound",
    "tilt_ratio",
    "tilts",
    "turn_ratio",
    "turns",
]
