"""The shared calibration model: one place for every equation every solver uses.

Modules, from the data up:

- :mod:`graph_calib.model.options`: :class:`ModelOptions`;
- :mod:`graph_calib.model.record`: :class:`PreparedRecord`, the data of one experiment prepared once
  (rates, temperatures and their slopes, keyframes, table readings), whatever the layout;
- :mod:`graph_calib.model.local_rates`: the rate and angular acceleration at an instant (a keyframe boundary,
  a table reading) from local fits of the integrated angle, and the boundary rate's four-sample correction;
- :mod:`graph_calib.model.encoder_noise`: the table readings' noise covariance (each static dwell's
  scatter, or the declared noise about a program's axes, floored) and the principal axes that whiten it;
- :mod:`graph_calib.model.kernel`: the compiled per-sample preintegration kernel;
- :mod:`graph_calib.model.preintegration`: :class:`Preintegrated`, which owns its first-order
  correction in the calibration, and :func:`preintegrate`;
- :mod:`graph_calib.model.factors`: the rotation, gravity and encoder factors and the priors, each a
  residual with its Jacobians (equations in that module's docstring);
- :mod:`graph_calib.model.shared_gyro_noise`: the gyro noise a keyframe interval's table readings share with
  each other and with its rotation factor, made independent by one linear map;
- :mod:`graph_calib.model.residual_list`: the factor kinds enumerated once (:data:`FACTOR_KINDS`), each with
  its robust-loss policy, the residual list (the kinds with their shared noise made independent) and the one
  whitening;
- :mod:`graph_calib.model.attitude_elimination`, :mod:`graph_calib.model.normal_equations`: the one builder
  of the normal equations, the keyframe attitudes eliminated by their banded Schur complement;
- :mod:`graph_calib.model.unresolved`: the directions a record cannot resolve (a heading drift that
  looks like a g-sensitivity) and the covariance with their data information removed;
- :mod:`graph_calib.model.calibration_model`: :class:`CalibrationModel`, the thin problem object
  (layout, priors, noise) the solvers call.
"""

from graph_calib.model.calibration_model import TABLE_ALIGNMENT_SIGMA, CalibrationModel, gyrocompass_attitude_sigma
from graph_calib.model.factors import Noise, PriorResidual, Residuals
from graph_calib.model.options import ModelOptions
from graph_calib.model.preintegration import REPREINTEGRATE_TOL, Preintegrated, SensorTerms
from graph_calib.model.local_rates import boundary_rate_correction
from graph_calib.model.record import PreparedRecord

__all__ = ["CalibrationModel", "ModelOptions", "PreparedRecord", "Preintegrated", "SensorTerms", "Residuals",
           "PriorResidual", "Noise", "REPREINTEGRATE_TOL", "TABLE_ALIGNMENT_SIGMA", "gyrocompass_attitude_sigma",
           "boundary_rate_correction"]
