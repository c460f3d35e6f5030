"""The IMU grade chosen from the data, with its reason, when the user does not name one.

A grade is about **priors**, not noise: the noise the solvers use is identified from the record itself
(:mod:`graph_calib.noise`), and the grade sets how far the calibration may lie from nominal before the
data say so.  Running a consumer MEMS unit with navigation-grade priors makes the solvers fight priors a
hundred times too tight (on the measured Xsens session: 500 iterations, no convergence, 12 deg transition
errors); running a navigation-grade unit with consumer priors throws its accuracy away.  So when no grade
is given, every rest of the record (:func:`graph_calib.noise.find_rests`) decides, from what any grade's
priors must be able to explain:

- how far the rest rate's magnitude lies from the Earth rate (a lower bound of the gyro biases);
- how far the rest specific force's magnitude lies from local gravity (a lower bound of the accelerometer
  biases and scale errors);

and, only as evidence of a different class of sensor, the identified white-noise densities: a grade is
ruled out by noise only when **both** the gyro's and the accelerometer's exceed :data:`NOISE_FACTOR`
times the grade's own (a navigation-grade unit whose accelerometers are ten times noisier than the
table's density is still a navigation-grade unit).  The most precise grade that is not ruled out is
chosen.  A record without a rest of :data:`MIN_STATIC_S` cannot tell: it is refused
(:class:`~graph_calib.errors.InputError`, exit 2 naming ``--grade``), never given the tightest priors by
default.  The reason is printed by the commands and stored in the result's ``grade_choice``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib import constants as c
from graph_calib.errors import InputError
from graph_calib.noise import identify_noise
from graph_calib.sensors.params import GRADES

#: A grade is ruled out by noise only when both densities exceed its own by this factor.
NOISE_FACTOR = 30.0
#: A grade's priors must cover the static offsets within this many sigmas.
PRIOR_FACTOR = 5.0
#: Grades from the most precise to the least.
ORDER = ("navigation", "tactical", "consumer")
#: Shortest static interval used, s.
MIN_STATIC_S = 2.0
#: A rest whose mean rate exceeds the quietest rest's by more than this is a turn at a constant rate, rad/s.
MAX_RATE_CHANGE = np.deg2rad(0.5)


@dataclass(frozen=True)
class GradeChoice:
    """The grade the data ask for.

    Attributes
    ----------
    grade : str
    reason : str
        In words, with the measured figures against the chosen grade's (and the next better grade's).
    gyro_noise : float
        Identified gyro noise density (the keyframe's), rad/sqrt(s).
    accel_noise : float
        Identified accelerometer noise density, m/s/sqrt(s).
    rate_offset : float
        Largest ``| |omega| - OMEGA_E |`` over the static intervals, rad/s.
    force_offset : float
        Largest ``| |f| - g |`` over the static intervals, m/s^2.
    """

    grade: str
    reason: str
    gyro_noise: float
    accel_noise: float
    rate_offset: float
    force_offset: float

    def to_json(self):
        return {"grade": self.grade, "reason": self.reason, "gyro_noise_rad_per_sqrt_s": self.gyro_noise,
                "accel_noise_mps_per_sqrt_s": self.accel_noise, "static_rate_offset_radps": self.rate_offset,
                "static_force_offset_mps2": self.force_offset}


def _misfit(name, *, gyro_noise, accel_noise, rate_offset, force_offset, gravity):
    """Why grade ``name`` cannot explain the figures (empty when it can)."""
    g = GRADES[name]
    p = g.prior_sigma
    why = []
    if gyro_noise > NOISE_FACTOR * g.gyro_noise and accel_noise > NOISE_FACTOR * g.accel_noise:
        why.append(f"gyro noise {gyro_noise / c.DSH_TO_RSS:.3g} deg/sqrt(h) > {NOISE_FACTOR:g} x "
                   f"{g.gyro_noise / c.DSH_TO_RSS:.3g} and accelerometer noise {accel_noise:.3g} m/s/sqrt(s) > "
                   f"{NOISE_FACTOR:g} x {g.accel_noise:.3g}")
    rate_bound = PRIOR_FACTOR * float(np.max(p["gyro.bias"]))
    if rate_offset > rate_bound:
        why.append(f"static rate {rate_offset * c.RS_TO_DH:.3g} deg/h off the Earth rate > {PRIOR_FACTOR:g} x "
                   f"the gyro-bias prior {float(np.max(p['gyro.bias'])) * c.RS_TO_DH:.3g} deg/h")
    force_bound = PRIOR_FACTOR * float(np.hypot(np.max(p["accel.bias"]), np.max(p["accel.scale"]) * gravity))
    if force_offset > force_bound:
        why.append(f"static |f| {force_offset:.3g} m/s^2 off gravity > {PRIOR_FACTOR:g} x the accelerometer "
                   f"bias and scale priors ({force_bound / PRIOR_FACTOR:.3g} m/s^2)")
    return why


def choose_grade(experiment, *, identification=None, keyframe_s=1.0):
    """The grade of ``experiment``'s IMU as its rests show it.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    identification : graph_calib.noise.NoiseIdentification, optional
        Default :func:`graph_calib.noise.identify_noise` of the record.
    keyframe_s : float
        The keyframe the identified densities are for.

    Returns
    -------
    GradeChoice

    Raises
    ------
    InputError
        The record has no rest of :data:`MIN_STATIC_S` to judge from (``--grade`` named).
    """
    ni = identify_noise(experiment, keyframe_s=keyframe_s) if identification is None else identification
    n_min = max(10, int(MIN_STATIC_S * experiment.rate_hz))
    intervals = [(int(a), int(b)) for a, b in ni.rests if b - a >= n_min]
    if not intervals or ni.gyro is None or ni.accel is None:
        raise InputError(f"cannot choose the IMU grade: no rest of at least {MIN_STATIC_S:g} s to judge the priors "
                         f"from; name the grade (navigation, tactical or consumer)",
                         path=experiment.source or None, dataset="--grade")
    dt = experiment.dt
    w = experiment.dtheta / dt[:, None]
    f = experiment.dv / dt[:, None]
    # a turn at a constant rate about the vertical leaves the specific force quiet: not a rest for the offsets
    mag = np.array([np.linalg.norm(w[a:b].mean(axis=0)) for a, b in intervals])
    intervals = [iv for iv, m in zip(intervals, mag) if m <= mag.min() + MAX_RATE_CHANGE]
    rate_offset = max(abs(float(np.linalg.norm(w[a:b].mean(axis=0))) - c.OMEGA_E) for a, b in intervals)
    gravity = float(experiment.gravity_mps2)
    force_offset = max(abs(float(np.linalg.norm(f[a:b].mean(axis=0))) - gravity) for a, b in intervals)
    figures = dict(gyro_noise=ni.gyro.density, accel_noise=ni.accel.density, rate_offset=rate_offset,
                   force_offset=force_offset)
    rejected = []
    for name in ORDER:
        why = _misfit(name, gravity=gravity, **figures)
        if not why:
            reason = f"{name}: the rests fit its priors"
            if rejected:
                reason += f" (not {rejected[-1][0]}: {'; '.join(rejected[-1][1])})"
            return GradeChoice(name, reason, **figures)
        rejected.append((name, why))
    return GradeChoice("consumer", f"consumer, the loosest grade, although {'; '.join(rejected[-1][1])}",
                       **figures)


def named_grade_misfit(experiment, name, *, keyframe_s=1.0):
    """Why the rests of ``experiment`` contradict the grade ``name`` a user named (``--grade``), in words: the checks
    :func:`choose_grade` makes of each grade; ``""`` when they fit, or when the record has no rest to tell."""
    try:
        choice = choose_grade(experiment, keyframe_s=keyframe_s)
    except InputError:
        return ""
    return "; ".join(_misfit(name, gravity=float(experiment.gravity_mps2), gyro_noise=choice.gyro_noise,
                             accel_noise=choice.accel_noise, rate_offset=choice.rate_offset,
                             force_offset=choice.force_offset))


def grade_warning(experiment, name, *, keyframe_s=1.0):
    """The warning line of a command given ``--grade name`` that the record's rests contradict (``""`` when not)."""
    why = named_grade_misfit(experiment, name, keyframe_s=keyframe_s)
    if not why:
        return ""
    return (f"warning: --grade {name}: the record's rests do not fit its priors ({why}): the sigmas, and the "
            "verdict's words on what the residuals lack, rest on priors the data contradict (without --grade the "
            "grade is chosen from the rests)")


__all__ = ["GradeChoice", "choose_grade", "named_grade_misfit", "grade_warning", "NOISE_FACTOR", "PRIOR_FACTOR"]
