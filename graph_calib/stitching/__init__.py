r"""Stitching per-subrange calibrations into one model of every parameter over the whole temperature range.

Each experiment of a campaign calibrates one temperature subrange: for a
temperature-dependent parameter ``p`` it gives the value at its reference
temperature and the coefficient(s) of the declared model,

.. math::

    p(T) = p + p_\mathrm{tc}\,(T - T_\mathrm{ref}) \;[+\; p_\mathrm{tc2}\,(T - T_\mathrm{ref})^2],

with their covariance, where ``T`` is the temperature of the sensor the element
belongs to (``gyro.bias.y`` follows the gyro y channel; misalignment ``xy``
follows its row, gyro x).  Read as data, a subrange ``i`` measures the
derivatives of the unknown curve ``f`` at ``T_ref,i``,

.. math::

    y_i = \bigl[f(T_{\mathrm{ref},i}),\ f'(T_{\mathrm{ref},i}),\ f''(T_{\mathrm{ref},i})/2\bigr] + e_i,
    \qquad e_i \sim N(0, \Sigma_i),

(``Sigma_i`` the marginal block of the subrange's covariance; subranges are
independent experiments).  A result that holds a temperature-dependent element
without its coefficients (a calibration at constant temperature) measured
``f`` at its own sensor's temperature, not at ``T_ref`` (the mean of all six
sensors, which self-heating puts tenths of a degree away): given the sensor
ranges, its point sits at the middle of that sensor's range.  Every stitched model is the generalised
least-squares fit of a curve family to all these measurements together:

``linear``
    a continuous piecewise-linear curve; its unknowns are its values at knots
    placed at the ends of the covered range and at every boundary between
    consecutive subranges (see :func:`boundary_temperature`).  Inside a segment
    a subrange measures the value and the slope of the segment.
``cubic``
    one cubic polynomial over the whole range (degree lowered when there are
    fewer measurements than four).
``constant``
    for parameters the model holds constant over temperature (misalignments,
    further effects without a temperature coefficient): the weighted mean.
    Their ``linear`` model interpolates the subrange values (knots at the
    reference temperatures).

Each fit reports its chi-square and degrees of freedom.  When ``chi2/dof > 1``
the covariance of the fit is multiplied by ``chi2/dof`` (Birge ratio), so that
a family that cannot follow the data shows it in wider bands instead of false
confidence; the unscaled value is kept.

Boundary check: consecutive subranges (ordered by reference temperature) each
predict the parameter at their common boundary with their own linear model;
the difference divided by the combined sigma is ``z``; ``|z| > 3`` is flagged
per element, and the campaign counts as consistent when the largest ``|z|``
stays below the limit that the largest of that many N(0,1) values exceeds with
1 % probability (:func:`family_z_limit`).

Correlations between different elements are ignored (each element is stitched
on its own); correlations between an element's value and its temperature
coefficients are kept.

Examples
--------
>>> import numpy as np
>>> from graph_calib.records.experiment import Result
>>> def sub(t_ref, a, b):
...     names = ("gyro.bias.x", "gyro.bias_tc.x")
...     return Result(source="s", solver="any", t_ref_degC=t_ref,
...                   temperature_range_degC=(t_ref - 4, t_ref + 4), effects=("gyro.bias", "gyro.bias_tc"),
...                   values=dict(zip(names, (a, b))), sigmas=dict(zip(names, (1e-8, 1e-9))),
...                   covariance_names=names, covariance=np.diag([1e-16, 1e-18]))
>>> st = stitch([sub(5.0, 1e-7, 2e-9), sub(15.0, 1.2e-7, 2e-9)], names=["warm", "hot"])
>>> v, s = st.curves["gyro.bias.x"].evaluate([10.0])
>>> round(float(v[0]) * 1e9, 3)
110.0
"""

from graph_calib.stitching.assemble import result_points, stitch
from graph_calib.stitching.fits import MIN_KNOT_SPACING_DEGC, boundary_temperature, fit_element
from graph_calib.stitching.pieces import (
    BOUNDARY_Z_LIMIT,
    FAMILY_FALSE_ALARM,
    MODELS,
    SENSORS,
    BoundaryCheck,
    ElementCurve,
    Fit,
    Stitched,
    SubrangePoint,
    family,
    family_z_limit,
    is_stitched,
    sensor_columns,
    sensor_of,
)

__all__ = ["SENSORS", "MODELS", "BOUNDARY_Z_LIMIT", "FAMILY_FALSE_ALARM", "MIN_KNOT_SPACING_DEGC", "sensor_of",
           "family", "is_stitched", "SubrangePoint", "Fit", "family_z_limit", "BoundaryCheck", "ElementCurve",
           "Stitched", "boundary_temperature", "fit_element", "stitch", "result_points", "sensor_columns"]
