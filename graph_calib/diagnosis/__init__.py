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

The package's names are its modules' and load with the first use of each (PEP 562's module
``__getattr__``): ``calibrate``'s structure tests (:mod:`graph_calib.diagnosis.structure`) import only
what they use, not the loop and its ``scipy.stats`` and ``scipy.interpolate``.
"""

import importlib

#: Each public name and the module that defines it.
_WHERE = {
    **dict.fromkeys(("DRIVER_GROUPS", "RATE_SIGN_DEADBAND", "REGRESSION_DRIVERS", "SENSOR_AXES", "TIME_SEGMENTS",
                     "Driver", "driver_series", "keyframe_context", "time_basis"), "drivers"),
    **dict.fromkeys(("diagnose", "diagnose_from"), "loop"),
    **dict.fromkeys(("CandidateTest", "Diagnosis", "DiagnosisOptions", "DriverTest", "Round", "Stage"), "rounds"),
    **dict.fromkeys(("ReducedSystem", "linearise"), "reduced_system"),
    **dict.fromkeys(("error_against_truth", "ljung_box", "regression_tests", "residual_rms", "residual_statistics"),
                    "residuals"),
    **dict.fromkeys(("Score", "log10_chi2_sf", "score_test"), "score"),
}


def __getattr__(name):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_WHERE))


__all__ = ["diagnose", "diagnose_from", "DiagnosisOptions", "Diagnosis", "Stage", "Round", "CandidateTest", "DriverTest",
           "Driver", "driver_series", "time_basis", "keyframe_context", "DRIVER_GROUPS", "SENSOR_AXES",
           "REGRESSION_DRIVERS", "RATE_SIGN_DEADBAND", "TIME_SEGMENTS", "ReducedSystem", "linearise", "Score",
           "score_test", "log10_chi2_sf", "ljung_box", "regression_tests", "residual_rms", "residual_statistics",
           "error_against_truth"]
