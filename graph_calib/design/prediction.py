r"""Predicted accuracy of a record before any solver runs: the Fisher information of the shared model.

For an experiment (recorded, or simulated from a bench program) the calibration's covariance is
predicted from the *motion*, the temperatures and the valid table readings alone:

1. :func:`graph_calib.records.problem.build_problem` sets the model up exactly as for the solvers (static
   detection, alignment, noise densities, layout, priors, keyframes).
2. The factors are linearised at the **nominal calibration** ``x = 0`` and the keyframe attitudes
   dead-reckoned from the alignment with it (:meth:`CalibrationModel.propagate`).  Nothing is
   estimated: no noise is simulated and no solver runs.
3. :func:`graph_calib.model.normal_equations.linearise` (the one builder of the Gauss-Newton system, the
   solvers' and the score tests') forms ``H = J^T J + priors`` of every factor kind and eliminates the
   attitudes by their Schur complement, as the solvers' covariance does.  The reduced
   information ``A`` in the calibration columns gives the predicted covariance ``Sigma = A^{-1}``.

Only the Jacobians enter ``A``.  They depend on the calibration and the attitudes only to first order
of small quantities (a navigation-grade unit's errors are parts per million and its dead-reckoned
attitude drifts by hundredths of a degree), so the prediction equals the factor graph's reported
covariance to a fraction of a percent (tests/design/test_prediction.py).  A unit whose raw errors are large
(consumer MEMS: degrees per minute of drift) is predicted less well: its attitudes at ``x = 0`` are
far from the solution's.

The **remaining sensor errors** are stated as :mod:`graph_calib.evaluation.validation` states them: over 1 s
windows of the record, the declared gyro and accelerometer errors (bias, scale factor, misalignment and
their temperature coefficients, each at its own sensor's temperature) of a calibration error ``dx``
are linear, ``de_w = Phi_w dx``; their predicted one sigma is ``sqrt(diag(Phi_w Sigma Phi_w^T))``
(correlations included).  The bound is :data:`CONFIDENCE_SIGMA` times the largest sigma over the
static windows (gyros: the condition of the 0.01 deg/h figure) and over all windows (accelerometers),
compared with :data:`graph_calib.evaluation.validation.GYRO_ACCURACY_RADPS` and
:data:`graph_calib.evaluation.validation.ACCEL_ACCURACY_MPS2`.  Model error (a temperature curve that is not
linear over the subrange) is not part of it.

**Variance components.**  ``calibrate`` rescales each part of the noise by a variance factor estimated from the
residuals (:mod:`graph_calib.solvers.variance`).  On the project's simulated table records with the noise
identified correctly the gyro's, the gravity's and the readings' own factors are near 1 (1.00, 0.98, 0.985 on the
15 min navigation subrange), but the floor of the table's unread direction is not: the simulated table has none of
the axis errors the floor stands for, and its factor goes to its bound of 1e-6.  A prediction with the identified
noise alone keeps the floor, and is up to 9 % above calibrate's sigmas (``gyro.misalignment.yz``).  The factors
are a property of the design and the noise, not of one realisation (their relative scatter is about
``sqrt(2 / redundancy)``, a few per cent), so :func:`expected_variance_factors` estimates them as calibrate does,
on the record itself or on one simulated noise realisation of a bench program, and
``predict(problem, variance_factors=...)`` then gives calibrate's sigmas (tests/design/test_prediction.py:
within 10 % of both solvers'; measured 0.983-1.000).  Without factors the prediction is that of the identified
noise alone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from graph_calib.compensation.calibration import triad_errors
from graph_calib.records.problem import build_problem
from graph_calib.solvers.registry import PREDICTION_SOLVER, PRIMARY_SOLVER
from graph_calib.solvers.variance import estimate_variance_components, with_variance_factors
from graph_calib.model.normal_equations import linearise
from graph_calib.records.experiment import Result
from graph_calib.sensors.params import split_element_name
from graph_calib.navigation.rotations import quat_to_dcm
from graph_calib.evaluation.validation import ACCEL_ACCURACY_MPS2, GYRO_ACCURACY_RADPS, RESULT_PARAMETERS, window_means

#: The bound on the remaining errors is this many predicted sigmas: 95.4 % of a Gaussian error, in each
#: window and on each axis (docs/design.md: the 1.5 h ``nav-subrange`` is at 0.0081 deg/h there, 0.0122 at 3 sigma).
CONFIDENCE_SIGMA = 2.0


@dataclass(frozen=True)
class ErrorBound:
    """Predicted remaining sensor errors over the record's windows (module docstring).

    Attributes
    ----------
    window_s : float
    gyro_sigma_radps, accel_sigma_mps2 : ndarray (W, 3)
        One sigma of the remaining gyro (rad/s) and accelerometer (m/s^2) error in every window.
    static : ndarray of bool (W,)
        Static windows (:func:`graph_calib.evaluation.validation.window_means`).
    confidence_sigma : float
    gyro_target_radps, accel_target_mps2 : float
        What the bound is compared with (default the published accuracy of :mod:`graph_calib.evaluation.validation`).
    """

    window_s: float
    gyro_sigma_radps: np.ndarray
    accel_sigma_mps2: np.ndarray
    static: np.ndarray
    confidence_sigma: float = CONFIDENCE_SIGMA
    gyro_target_radps: float = GYRO_ACCURACY_RADPS
    accel_target_mps2: float = ACCEL_ACCURACY_MPS2

    @property
    def gyro_criterion(self):
        """``"static windows"`` when the record has any, else ``"all windows"`` (as validation)."""
        return "static windows" if np.any(self.static) else "all windows"

    def largest_sigma(self):
        """``(gyro rad/s (3,), accel m/s^2 (3,))``: the largest one sigma per axis over the criterion's windows."""
        sel = self.static if np.any(self.static) else np.ones_like(self.static)
        return self.gyro_sigma_radps[sel].max(axis=0), self.accel_sigma_mps2.max(axis=0)

    def summary(self):
        """JSON-ready: largest sigma and bound per axis, thresholds, whether the bound meets them."""
        g, a = self.largest_sigma()
        k = self.confidence_sigma
        gyro_ok = bool(np.all(k * g < self.gyro_target_radps))
        accel_ok = bool(np.all(k * a < self.accel_target_mps2))
        return {
            "confidence_sigma": k,
            "window_s": self.window_s,
            "gyro_criterion": self.gyro_criterion,
            "gyro_radps": {"largest_sigma": g.tolist(), "bound": (k * g).tolist()},
            "accel_mps2": {"largest_sigma": a.tolist(), "bound": (k * a).tolist()},
            "thresholds": {"gyro_radps": self.gyro_target_radps, "accel_mps2": self.accel_target_mps2},
            "meets": {"gyro": gyro_ok, "accel": accel_ok, "all": gyro_ok and accel_ok},
        }


@dataclass(frozen=True)
class Prediction:
    """The predicted accuracy of one record.

    Attributes
    ----------
    names : list of str
        Flat element names (the model's layout), length P.
    covariance : ndarray (P, P)
        Predicted covariance ``A^{-1}``, SI.
    information : ndarray (P, P)
        Reduced Fisher information ``A`` (attitudes eliminated, priors included).
    bound : ErrorBound
    seconds : float
        Wall time of the prediction (model set-up excluded).
    variance_factors : dict
        The variance factors the information was formed with (empty: none, every kind 1).
    """

    names: list
    covariance: np.ndarray
    information: np.ndarray
    bound: ErrorBound
    seconds: float
    variance_factors: dict = field(default_factory=dict)

    @property
    def sigma(self):
        """Predicted one sigma of every element, shape (P,)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def sigmas(self):
        """``{flat element: predicted sigma}``."""
        return dict(zip(self.names, self.sigma.tolist()))


def reduced_information(problem):
    """Reduced Fisher information of ``problem``'s model at the nominal calibration, shape (P, P).

    The attitudes are dead-reckoned from the alignment with ``x = 0`` and eliminated (Schur
    complement); the calibration priors and the alignment prior are included.
    """
    model = problem.model
    x0 = model.layout.zeros()
    pre = model.preintegrate(x0)
    R = model.propagate(quat_to_dcm(problem.q_nb0), pre, x0)
    system = linearise(model, pre, R, x0, R_prior=model.segment_priors(problem.q_nb0),
                       prior=(model.calibration_prior(x0), np.arange(x0.size)), touched_columns=True)
    return system.reduce(0.0, definite=False)[0]


def error_jacobians(layout, windows, t_ref_degC):
    """``Phi`` of the remaining sensor errors: d e / d x per window, axis and element.

    Parameters
    ----------
    layout : graph_calib.sensors.params.Layout
    windows : dict
        :func:`graph_calib.evaluation.validation.window_means` of the record.
    t_ref_degC : float

    Returns
    -------
    Phi_gyro, Phi_accel : ndarray (W, 3, P)
        rad/s and m/s^2 per unit of each element; zero for the elements validation does not compare.
    """
    omega, f = windows["omega"], windows["f"]
    dT = windows["T"] - t_ref_degC
    W, P = omega.shape[0], layout.size
    Pg = np.zeros((W, 3, P))
    Pa = np.zeros((W, 3, P))
    for i, name in enumerate(layout.element_names()):
        if split_element_name(name)[0] not in RESULT_PARAMETERS:
            continue
        X = np.zeros((1, P))
        X[0, i] = 1.0
        Pg[:, :, i] = triad_errors(layout, X, "gyro", omega, dT=dT[:, :3], other=f)
        Pa[:, :, i] = triad_errors(layout, X, "accel", f, dT=dT[:, 3:], other=omega)
    return Pg, Pa


def error_bound(layout, covariance, experiment, *, t_ref_degC, window_s=1.0, confidence_sigma=CONFIDENCE_SIGMA,
                targets=None):
    """Predicted one sigma of the remaining sensor errors in every window of ``experiment`` (:class:`ErrorBound`).

    ``targets``: ``(gyro rad/s, accel m/s^2)`` to compare with; default the published accuracy.
    """
    tg, ta = targets if targets is not None else (GYRO_ACCURACY_RADPS, ACCEL_ACCURACY_MPS2)
    w = window_means(experiment, window_s=window_s)
    Pg, Pa = error_jacobians(layout, w, t_ref_degC)
    sg = np.sqrt(np.clip(np.einsum("wip,pq,wiq->wi", Pg, covariance, Pg), 0.0, None))
    sa = np.sqrt(np.clip(np.einsum("wip,pq,wiq->wi", Pa, covariance, Pa), 0.0, None))
    return ErrorBound(window_s=float(window_s), gyro_sigma_radps=sg, accel_sigma_mps2=sa, static=w["static"],
                      confidence_sigma=float(confidence_sigma), gyro_target_radps=float(tg),
                      accel_target_mps2=float(ta))


def predict(problem, *, variance_factors=None, window_s=1.0, confidence_sigma=CONFIDENCE_SIGMA, targets=None):
    """Predicted covariance of the calibration of ``problem`` and the bound on the remaining errors.

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
        Built by :func:`graph_calib.records.problem.build_problem` as for a calibration.
    variance_factors : dict, optional
        ``{kind: factor}`` each kind's covariance is multiplied by, as calibrate's variance components
        (:func:`expected_variance_factors`); default: those the problem's model carries (none: 1).
    window_s : float
        Window of the remaining-error statement, s.
    confidence_sigma : float
    targets : (float, float), optional
        Gyro (rad/s) and accelerometer (m/s^2) targets of the bound; default the published accuracy.

    Returns
    -------
    Prediction
    """
    t0 = time.perf_counter()
    if variance_factors is not None:
        problem = with_variance_factors(problem, variance_factors)
    model = problem.model
    A = reduced_information(problem)
    cov = np.linalg.inv(A)
    cov = 0.5 * (cov + cov.T)
    bound = error_bound(model.layout, cov, model.experiment, t_ref_degC=model.t_ref_degC, window_s=window_s,
                        confidence_sigma=confidence_sigma, targets=targets)
    return Prediction(names=model.layout.element_names(), covariance=cov, information=A, bound=bound,
                      seconds=time.perf_counter() - t0,
                      variance_factors=dict(model.options.variance_factors or {}))


def expected_variance_factors(problem, *, options, program=None, rng=None, solver=PRIMARY_SOLVER):
    """The variance factors calibrate would estimate (module docstring), ``{kind: factor}``.

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
        The record's problem: the factors are estimated on it, as calibrate does (solves of ``solver``).
    options : graph_calib.options.CalibrationOptions
        The calibration's options (its model; ``variance_components`` is not read).
    program : graph_calib.simulation.program.BenchProgram, optional
        A bench program whose record does not exist yet: the factors are estimated on one simulated
        realisation of it instead (noise at the grade's densities, an ideal IMU), with ``rng``.
    rng : numpy.random.Generator, optional
        Required with ``program``.
    solver : str

    Returns
    -------
    dict
    """
    if program is not None:
        if rng is None:
            raise ValueError("a program's variance factors need a seeded numpy.random.Generator (rng)")
        from graph_calib.simulation.program import program_simulation

        se = program_simulation(program, rng=rng, noise=True, errors=False).run()[0]
        problem = build_problem(se.experiment, options=options)
    vc = estimate_variance_components(problem, options=options, solver=solver)
    return dict(vc.factors)


def prediction_result(problem, prediction, *, extra=None):
    """The result file of a prediction: ``"solver": "prediction"``, every value 0, ``sigma`` predicted.

    ``extra`` adds top-level keys; the result always holds ``remaining_error_bound``
    (:meth:`ErrorBound.summary`), the noise densities, grade and priors used.
    """
    model = problem.model
    T = model.temperatures
    ex = {"priors": model.priors_used(), "keyframe_s": model.options.keyframe_s, "grade": model.options.grade,
          "noise": {"gyro_rad_per_sqrt_s": model.gyro_noise, "accel_mps_per_sqrt_s": model.accel_noise,
                    "encoder_rad": model.encoder_noise},
          "remaining_error_bound": prediction.bound.summary(),
          "prediction": {"linearised_at": "nominal calibration (x = 0), attitudes dead-reckoned from the alignment",
                         "seconds": prediction.seconds,
                         "variance_factors": {k: float(v) for k, v in prediction.variance_factors.items()}}}
    ex.update(extra or {})
    names = prediction.names
    return Result(
        source=model.experiment.source.rsplit("/", 1)[-1] if model.experiment.source else "",
        solver=PREDICTION_SOLVER, t_ref_degC=model.t_ref_degC,
        temperature_range_degC=(float(T.min()), float(T.max())), effects=tuple(model.layout.names),
        values={n: 0.0 for n in names}, sigmas=prediction.sigmas(), covariance_names=tuple(names),
        covariance=prediction.covariance, residuals={}, extra=ex,
    )


__all__ = ["CONFIDENCE_SIGMA", "PREDICTION_SOLVER", "ErrorBound", "Prediction", "reduced_information",
           "error_jacobians", "error_bound", "predict", "expected_variance_factors", "prediction_result"]
