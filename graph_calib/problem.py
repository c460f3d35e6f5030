"""One experiment made ready for any solver: the shared model, its static intervals and its alignment.

>>> problem = build_problem(experiment, options=CalibrationOptions())      # doctest: +SKIP
>>> problem.model.layout.size, problem.q_nb0                                # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from graph_calib.model import CalibrationModel, gyrocompass_attitude_sigma
from graph_calib.options import CalibrationOptions
from graph_calib.params import grade
from graph_calib.alignment import Alignment, alignment
from graph_calib.errors import InputError
from graph_calib.plausibility import check_record
from graph_calib.static_detection import detect_static


@dataclass(frozen=True)
class Problem:
    """A calibration model with its initial attitude, ready for any solver.

    Attributes
    ----------
    model : graph_calib.model.CalibrationModel
    q_nb0 : ndarray, shape (4,)
        Attitude ``q_nb`` (scalar first) at the start of the record, from the alignment.
    alignment : graph_calib.alignment.Alignment
        How ``q_nb0`` was found.
    """

    model: CalibrationModel
    q_nb0: np.ndarray
    alignment: Alignment

    def with_effects(self, extra_effects):
        """The same record, static intervals and alignment, with ``extra_effects`` as the further effects."""
        return replace(self, model=self.model.with_effects(extra_effects))


def build_problem(experiment, *, options=CalibrationOptions()):
    """Set up the shared model of ``experiment`` and align it.

    Without a table, gravity measurements count only where the IMU is static
    (``ModelOptions.moving_sigma`` then defaults to 1 m/s^2 for moving keyframes).
    A record whose gyro increments cannot be in radians (degrees written for radians, rates for
    increments: :func:`graph_calib.plausibility.check_record`) is refused first, with an
    :class:`~graph_calib.errors.InputError` (exit 2 on the command line, nothing written).

    Parameters
    ----------
    experiment : graph_calib.experiment.Experiment
    options : CalibrationOptions

    Returns
    -------
    Problem
    """
    if experiment.n_segments > 1:
        raise InputError(f"the record is cut into {experiment.n_segments} segments (/imu/segment); calibrating a "
                         f"record cut together is not supported yet: calibrate each piece on its own "
                         f"(Experiment.segment_bounds gives them)", path=experiment.source or None,
                         dataset="/imu/segment")
    check_record(experiment)
    model_options = options.model
    static = detect_static(experiment)
    static_mask = None
    if experiment.table is None:
        static_mask = np.zeros(experiment.n_samples, dtype=bool)
        for a, b in static:
            static_mask[a:b] = True
        if model_options.moving_sigma is None:
            model_options = replace(model_options, moving_sigma=1.0)
    interval = tuple(static[0]) if len(static) else None
    if interval is not None:
        model_options = _noise_from_static(experiment, interval, model_options)
    method = "table" if (experiment.table is not None and np.any(experiment.table.valid)) else "gyrocompass"
    try:
        al = alignment(experiment, interval=interval, method=method)
    except Exception:
        if method != "table":
            raise
        al = alignment(experiment, interval=interval, method="gyrocompass")
        if model_options.initial_attitude_sigma is None:
            # the table could not give the attitude: the prior is as loose as gyrocompassing is
            model_options = replace(model_options, initial_attitude_sigma=gyrocompass_attitude_sigma(
                model_options, latitude_rad=experiment.latitude_rad))
    model = CalibrationModel(experiment, options=model_options, t_ref_degC=options.t_ref_degC, static_mask=static_mask)
    return Problem(model=model, q_nb0=al.q_nb0, alignment=al)


def _noise_from_static(experiment, interval, model_options):
    """White-noise densities: the grade's, raised to what the first static interval shows.

    The density is the per-sample standard deviation of the rate (force) times
    ``sqrt(dt)``, averaged over the axes.  Options set explicitly are kept.  The
    grade's value is a floor, so noise-free data keep a sensible weighting.
    """
    a, b = int(interval[0]), int(interval[1])
    if b - a < 50:
        return model_options
    g = grade(model_options.grade)
    dt = experiment.dt[a:b, None]
    w = experiment.dtheta[a:b] / dt
    f = experiment.dv[a:b] / dt
    h = float(np.median(dt))
    est_g = float(np.sqrt(np.mean(np.var(w, axis=0)) * h))
    est_a = float(np.sqrt(np.mean(np.var(f, axis=0)) * h))
    return replace(
        model_options,
        gyro_noise=model_options.gyro_noise if model_options.gyro_noise is not None else max(g.gyro_noise, est_g),
        accel_noise=model_options.accel_noise if model_options.accel_noise is not None else max(g.accel_noise, est_a),
    )


__all__ = ["Problem", "build_problem"]
