"""The closed loop of residual analysis: from the residuals to the missing effect.

``diagnose(experiment, options=...)`` calibrates with the declared model, tests
every further effect of ``model.md`` that the declared model lacks, adds the most
significant one, re-solves and repeats until no candidate is significant.  It
then tests the residuals against generic *drivers* (time, temperature, its rate,
the sign and size of the angular rate, angular acceleration, specific force and
its square): structure that no candidate explains is reported as
``unexplained`` with its signature.  ``docs/diagnosis.md`` gives the statistics
and their thresholds.

Modules, from the data up:

- :mod:`graph_calib.diagnosis.drivers`: the generic drivers (:class:`Driver`,
  :func:`driver_series`, :func:`time_basis`), their sums at the factors' interval boundaries
  (``DriverSums``, one per record) and their keyframe means (:func:`keyframe_context`);
- :mod:`graph_calib.diagnosis.reduced_system`: the Gauss-Newton system of the extended
  model at the current solution with the attitudes eliminated (:func:`linearise`,
  :class:`ReducedSystem`);
- :mod:`graph_calib.diagnosis.score`: the score (Lagrange-multiplier) test (:func:`score_test`,
  :class:`Score`, :func:`log10_chi2_sf`); the statistic is derived in that module's docstring;
- :mod:`graph_calib.diagnosis.residuals`: residual series of the factor graph and the filter,
  their whiteness (:func:`ljung_box`), driver regressions, :func:`residual_statistics`,
  :func:`residual_rms`, :func:`error_against_truth`;
- :mod:`graph_calib.diagnosis.rounds`: :class:`DiagnosisOptions` and what the loop records
  (:class:`CandidateTest`, :class:`DriverTest`, :class:`Round`, :class:`Stage`,
  :class:`Diagnosis` with ``to_json``);
- :mod:`graph_calib.diagnosis.loop`: :func:`diagnose`, the loop as a sequence of steps, and
  :func:`diagnose_from`, the loop continued on a model grown from outside (a campaign's pooled test).
"""

from graph_calib.diagnosis.drivers import (
    DRIVER_GROUPS,
    RATE_SIGN_DEADBAND,
    REGRESSION_DRIVERS,
    SENSOR_AXES,
    TIME_SEGMENTS,
    Driver,
    driver_series,
    keyframe_context,
    time_basis,
)
from graph_calib.diagnosis.loop import diagnose, diagnose_from
from graph_calib.diagnosis.rounds import (
    CandidateTest,
    Diagnosis,
    DiagnosisOptions,
    DriverTest,
    Round,
    Stage,
)
from graph_calib.diagnosis.reduced_system import ReducedSystem, linearise
from graph_calib.diagnosis.residuals import (
    error_against_truth,
    ljung_box,
    regression_tests,
    residual_rms,
    residual_statistics,
)
from graph_calib.diagnosis.score import Score, log10_chi2_sf, score_test

__all__ = ["diagnose", "diagnose_from", "DiagnosisOptions", "Diagnosis", "Stage", "Round", "CandidateTest", "DriverTest",
           "Driver", "driver_series", "time_basis", "keyframe_context", "DRIVER_GROUPS", "SENSOR_AXES",
           "REGRESSION_DRIVERS", "RATE_SIGN_DEADBAND", "TIME_SEGMENTS", "ReducedSystem", "linearise", "Score",
           "score_test", "log10_chi2_sf", "ljung_box", "regression_tests", "residual_statistics", "residual_rms",
           "error_against_truth"]
