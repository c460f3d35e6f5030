"""The IMU grade chosen from the data, with its reason, when the user does not name one.

A grade sets the priors and the noise floor (:data:`graph_calib.sensors.params.GRADES`).  Running a consumer
MEMS unit with navigation-grade priors makes the solvers fight priors a hundred times too tight
(on the measured Xsens session: 500 iterations, no convergence, 12 deg transition errors); running a
navigation-grade unit with consumer priors throws its accuracy away.  So when no grade is given,
the record's static intervals decide, from what any grade must be able to explain:

- the white-noise densities of the rates and specific forces at rest (the per-sample standard
  deviation times ``sqrt(dt)``, as :func:`graph_calib.records.problem.build_problem` measures them);
- how far the static rate's magnitude lies from the Earth rate (a lower bound of the gyro biases);
- how far the static specific force's magnitude lies from local gravity (a lower bound of the
  accelerometer biases and scale errors).

The most precise grade whose noise floor is within :data:`NOISE_FACTOR` of the measured densities
and whose priors cover the static offsets within :data:`PRIOR_FACTOR` sigmas is chosen; consumer
otherwise.  The reason is printed by the commands and stored in the result's ``grade_choice``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib import constants as c
from graph_calib.sensors.params import GRADES
from graph_calib.navigation.static_detection import detect_static

#: A grade's noise floor may be at most this much below the measured noise density.
NOISE_FACTOR = 3.0
#: A grade's priors must cover the static offsets within this many sigmas.
PRIOR_FACTOR = 5.0
#: Grades from the most precise to the least.
ORDER = ("navigation", "tactical", "consumer")
#: Shortest static interval used, s.
MIN_STATIC_S = 2.0
#: A window whose mean rate differs from the start's by more than this is motion (a turntable turning at a
#: constant rate about the vertical leaves the specific force unchanged), rad/s.
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
        Measured gyro noise density at rest, rad/sqrt(s).
    accel_noise : float
        Measured accelerometer noise density at rest, m/s/sqrt(s).
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
    if gyro_noise > NOISE_FACTOR * g.gyro_noise:
        why.append(f"gyro noise {gyro_noise / c.DSH_TO_RSS:.3g} deg/sqrt(h) > {NOISE_FACTOR:g} x "
                   f"{g.gyro_noise / c.DSH_TO_RSS:.3g}")
    if accel_noise > NOISE_FACTOR * g.accel_noise:
        why.append(f"accelerometer noise {accel_noise:.3g} m/s/sqrt(s) > {NOISE_FACTOR:g} x {g.accel_noise:.3g}")
    rate_bound = PRIOR_FACTOR * float(np.max(p["gyro.bias"]))
    if rate_offset > rate_bound:
        why.append(f"static rate {rate_offset * c.RS_TO_DH:.3g} deg/h off the Earth rate > {PRIOR_FACTOR:g} x "
                   f"the gyro-bias prior {float(np.max(p['gyro.bias'])) * c.RS_TO_DH:.3g} deg/h")
    force_bound = PRIOR_FACTOR * float(np.hypot(np.max(p["accel.bias"]), np.max(p["accel.scale"]) * gravity))
    if force_offset > force_bound:
        why.append(f"static |f| {force_offset:.3g} m/s^2 off gravity > {PRIOR_FACTOR:g} x the accelerometer "
                   f"bias and scale priors ({force_bound / PRIOR_FACTOR:.3g} m/s^2)")
    return why


def choose_grade(experiment, *, static=None):
    """The grade of ``experiment``'s IMU as its static intervals show it.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    static : sequence of (int, int), optional
        Static intervals (sample ranges); default :func:`graph_calib.navigation.static_detection.detect_static` with
        windows whose mean rate moved by more than :data:`MAX_RATE_CHANGE` from the start's left out.

    Returns
    -------
    GradeChoice
    """
    intervals = detect_static(experiment, max_rate=MAX_RATE_CHANGE) if static is None else static
    n_min = max(10, int(MIN_STATIC_S * experiment.rate_hz))
    intervals = [(int(a), int(b)) for a, b in intervals if b - a >= n_min]
    if not intervals:
        return GradeChoice("navigation", "no static interval of at least 2 s to judge from: navigation (the "
                           "default); name the grade with --grade", float("nan"), float("nan"), float("nan"),
                           float("nan"))
    dt = experiment.dt
    w = experiment.dtheta / dt[:, None]
    f = experiment.dv / dt[:, None]
    h = float(np.median(dt))
    a, b = intervals[0]
    gyro_noise = float(np.sqrt(np.mean(np.var(w[a:b], axis=0)) * h))
    accel_noise = float(np.sqrt(np.mean(np.var(f[a:b], axis=0)) * h))
    rate_offset = max(abs(float(np.linalg.norm(w[a:b].mean(axis=0))) - c.OMEGA_E) for a, b in intervals)
    gravity = float(experiment.gravity_mps2)
    force_offset = max(abs(float(np.linalg.norm(f[a:b].mean(axis=0))) - gravity) for a, b in intervals)
    figures = dict(gyro_noise=gyro_noise, accel_noise=accel_noise, rate_offset=rate_offset,
                   force_offset=force_offset)
    rejected = []
    for name in ORDER:
        why = _misfit(name, gravity=gravity, **figures)
        if not why:
            reason = f"{name}: the static intervals fit its noise and priors"
            if rejected:
                reason += f" (not {rejected[-1][0]}: {'; '.join(rejected[-1][1])})"
            return GradeChoice(name, reason, **figures)
        rejected.append((name, why))
    return GradeChoice("consumer", f"consumer, the loosest grade, although {'; '.join(rejected[-1][1])}",
                       **figures)


__all__ = ["GradeChoice", "choose_grade", "NOISE_FACTOR", "PRIOR_FACTOR"]
