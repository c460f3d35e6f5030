"""What a compensation holds and how it applies itself: element values at each sample's own sensor temperature.

A compensation (a stitched calibration, :mod:`graph_calib.compensation.stitched`, or
a compensation table, :mod:`graph_calib.compensation.table`) states every element
of the sensor model's parameters (:data:`TABLE_PARAMETERS`) as a value over the
temperature of the sensor the element belongs to (``gyro.bias.y`` follows the gyro
y channel of the record's ``temperature_map``, ``gyro.misalignment.zx`` its row,
gyro z; :func:`graph_calib.stitching.sensor_of`), or as a constant.  Applying it
(:meth:`ElementCompensation.correct`) evaluates every element at each sample's
temperatures, which gives one calibration vector per sample, and inverts the one
sensor model with them (:func:`graph_calib.compensation.calibration.correct_record`): the
solvers' inverse, fed as the solvers feed it.

Temperature coefficients (``*_tc``, ``*_tc2``, ``*_tc3``) are never elements of a
compensation: the temperature dependence is in the values.  Bench parameters
(:data:`BENCH_PARAMETERS`: mounting on the faceplate, lever arm, table lag,
damper stiffness) act through the turntable's factors, not through the sensor
model, and belong to the set-up rather than to the IMU; a compensation leaves them out.
"""

from __future__ import annotations

import numpy as np

from graph_calib.compensation.calibration import correct_record, corrected_experiment, prepare
from graph_calib.sensors.effects import EFFECTS, REGISTRY
from graph_calib.model import ModelOptions
from graph_calib.sensors.params import Layout, split_element_name
from graph_calib.stitching import SENSORS, sensor_columns, sensor_of

#: Parameters a compensation may hold: every parameter with a sensor term that is not a temperature coefficient.
TABLE_PARAMETERS = tuple(e.name for e in REGISTRY if e.term is not None and e.temperature_of is None)
#: Parameters of the set-up, acting through the turntable factors: never in a compensation.
BENCH_PARAMETERS = tuple(e.name for e in REGISTRY if e.term is None)
#: Why a bench parameter is not in a compensation (written into every table).
BENCH_REASON = "bench set-up (acts through the turntable factors, not the sensor model): not an IMU correction"


def parameter_of(element):
    """Parameter of a flat element name (``KeyError`` for an unknown name)."""
    return split_element_name(element)[0]


def unit_of(element):
    """SI unit of an element's value (the effect registry's)."""
    return EFFECTS[parameter_of(element)].unit


def sensor_name(element):
    """``"gyro.x"`` ... ``"accel.z"``: the sensor whose temperature the element follows; None for no sensor."""
    s = sensor_of(element)
    return None if s is None else SENSORS[s]


def table_element(element):
    """Whether a flat element name may be an element of a compensation (:data:`TABLE_PARAMETERS`)."""
    try:
        return parameter_of(element) in TABLE_PARAMETERS
    except KeyError:
        return False


def element_order(names):
    """``names`` (flat elements) in calibration-vector order (the registry's, then the elements')."""
    layout = Layout(tuple({parameter_of(n) for n in names}))
    index = {n: i for i, n in enumerate(layout.element_names())}
    return sorted(names, key=index.__getitem__)


class ElementCompensation:
    """Base of the compensations: element values over sensor temperature, applied through the sensor model.

    A subclass provides :meth:`curve_values` (the temperature-dependent elements at
    temperatures), :attr:`constants` (``{element: (value, sigma)}``) and
    :meth:`valid_range` (per temperature-dependent element, the temperatures where
    its values are stated).
    """

    #: ``{flat element: (value, sigma)}`` of the elements that do not depend on temperature.
    constants: dict

    def curve_elements(self):
        """Temperature-dependent elements, calibration-vector order."""
        raise NotImplementedError

    def curve_values(self, element, T):
        """``(value, sigma)`` arrays of a temperature-dependent element at its sensor temperatures ``T`` (degC)."""
        raise NotImplementedError

    def valid_range(self, element):
        """``(low, high)``, degC: where a temperature-dependent element's values are stated."""
        raise NotImplementedError

    # -- the layout and the values ---------------------------------------------------

    def elements(self):
        """Every element, calibration-vector order."""
        return element_order(list(self.curve_elements()) + list(self.constants))

    @property
    def layout(self):
        """:class:`graph_calib.sensors.params.Layout` of every parameter the compensation holds (missing elements zero)."""
        return Layout(tuple({parameter_of(n) for n in self.elements()}))

    def element_values(self, T_sensors):
        """Every element at the sensor temperatures of each row, ``{flat element: (N,)}``, SI.

        Parameters
        ----------
        T_sensors : array_like, shape (N, 6)
            Temperatures of gyro x, y, z and accel x, y, z, degC
            (:meth:`graph_calib.records.experiment.Experiment.sensor_temperatures`).
        """
        T = np.atleast_2d(np.asarray(T_sensors, dtype=float))
        out = {n: self.curve_values(n, sensor_columns(T, sensor_of(n)))[0] for n in self.curve_elements()}
        out.update({n: np.full(T.shape[0], v) for n, (v, _) in self.constants.items()})
        return out

    def element_sigmas(self, T_sensors):
        """One sigma of every element at the sensor temperatures of each row, ``{flat element: (N,)}``."""
        T = np.atleast_2d(np.asarray(T_sensors, dtype=float))
        out = {n: self.curve_values(n, sensor_columns(T, sensor_of(n)))[1] for n in self.curve_elements()}
        out.update({n: np.full(T.shape[0], s) for n, (_, s) in self.constants.items()})
        return out

    def rows(self, T_sensors):
        """The calibration vector of each row, shape (N, layout.size): :meth:`element_values` in layout order."""
        values = self.element_values(T_sensors)
        layout = self.layout
        n = np.atleast_2d(np.asarray(T_sensors)).shape[0]
        X = np.zeros((n, layout.size))
        for i, name in enumerate(layout.element_names()):
            if name in values:
                X[:, i] = values[name]
        return X

    def outside(self, T_sensors):
        """Number of rows where some element's sensor temperature is outside that element's :meth:`valid_range`."""
        T = np.atleast_2d(np.asarray(T_sensors, dtype=float))
        bad = np.zeros(T.shape[0], dtype=bool)
        for n in self.curve_elements():
            lo, hi = self.valid_range(n)
            t = sensor_columns(T, sensor_of(n))
            bad |= (t < lo) | (t > hi)
        return int(np.count_nonzero(bad))

    # -- applying ----------------------------------------------------------------------

    def correct(self, experiment, *, n_newton=ModelOptions.n_newton):
        """Compensated angular rate and specific force of every sample of an experiment.

        Every element at each sample's own sensor temperature (:meth:`rows`), then the
        inverse sensor model with those per-sample vectors, fed as the solvers feed it
        (:func:`graph_calib.compensation.calibration.correct_record`).

        Returns
        -------
        omega_ib_b : ndarray, shape (N, 3)
            rad/s, mean over each sample interval.
        f_b : ndarray, shape (N, 3)
            m/s^2, mean over each sample interval.
        """
        X = self.rows(experiment.sensor_temperatures())
        return correct_record(self.layout, X, prepare(experiment), n_newton=n_newton)

    def corrected(self, experiment, *, n_newton=ModelOptions.n_newton, note=None):
        """The experiment with its increments corrected (:func:`graph_calib.compensation.calibration.corrected_experiment`)."""
        return corrected_experiment(experiment, *self.correct(experiment, n_newton=n_newton),
                                    note=self.describe() if note is None else note)

    def describe(self):
        """One line naming the compensation (for descriptions and summaries)."""
        return type(self).__name__


__all__ = ["TABLE_PARAMETERS", "BENCH_PARAMETERS", "BENCH_REASON", "ElementCompensation", "parameter_of", "unit_of",
           "sensor_name", "table_element", "element_order"]
