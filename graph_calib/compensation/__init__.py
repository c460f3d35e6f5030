r"""Compensation: a calibration applied to raw records, and the table an INS loads.

Three things correct a raw record, all through the one sensor model
(:func:`graph_calib.compensation.calibration.correct_record`, the solvers' inverse fed as the
solvers feed it; no second copy of the sensor equations):

:class:`graph_calib.compensation.calibration.Calibration`
    One experiment's result: its parameters with their temperature coefficients about
    its reference temperature (``Calibration.from_result``, ``Calibration.correct``).
:class:`StitchedCalibration`
    A campaign's stitched curves (one solver, one stitched model), every element at
    each sample's own sensor temperature (``StitchedCalibration.from_campaign``).
:class:`CompensationTable`
    The same on a temperature grid, with one-sigma bands and the constant elements:
    what ``graph-calib export`` writes (JSON, CSV, C header) and ``graph-calib apply``
    reads back.  **Interpolation**: linear between grid points, each element at its own
    sensor's temperature, end values held outside the grid (:func:`interpolate`).

Each has ``correct(experiment) -> (omega_ib_b, f_b)`` and ``corrected(experiment)``
(the experiment with corrected increments ``omega_ib_b dt`` and ``f_b dt``).

What "equal" means between a table and its stitched calibration
    At the grid temperatures the table holds the stitched values themselves (written so
    that they read back bit for bit), so a record whose sensor temperatures sit on grid
    temperatures is corrected identically by both.  Between grid points the table's
    straight line departs from a curved (cubic) stitched fit by at most
    ``h^2/8 max|p''|`` for a step ``h``; every table states that difference per element
    (``interpolation_error``, absolute and in units of the element's sigma), and
    ``graph-calib export`` prints the largest.  A piecewise-linear stitched fit is
    reproduced between grid points only where no knot falls inside a grid interval.

Examples
--------
>>> from graph_calib.compensation import StitchedCalibration, write_table, read_table
>>> st = StitchedCalibration.from_campaign("camp")                      # doctest: +SKIP
>>> write_table(st.table(step_degC=1.0), "camp.table.json")             # doctest: +SKIP
>>> omega_ib_b, f_b = read_table("camp.table.json").correct(experiment)  # doctest: +SKIP
"""

from graph_calib.compensation.apply import (
    PROVENANCE_ATTRIBUTE, apply, correction_of, note_of, read_compensation, write_corrected,
)
from graph_calib.compensation.elements import (
    BENCH_PARAMETERS, TABLE_PARAMETERS, ElementCompensation, parameter_of, sensor_name, table_element, unit_of,
)
from graph_calib.compensation.formats import (
    SUFFIX, TABLE_FORMATS, element_identifier, read_table, table_c_header, table_csv, table_json, write_table,
)
from graph_calib.compensation.stitched import (
    CAMPAIGN_FORMAT, CAMPAIGN_VERSION, STITCH_MODELS, StitchedCalibration, read_campaign,
)
from graph_calib.compensation.joint import JointCalibration, JointCurve
from graph_calib.compensation.table import (
    INTERPOLATION, TABLE_FORMAT, TABLE_VERSION, CompensationTable, TableCurve, interpolate,
)

__all__ = [
    "TABLE_PARAMETERS", "BENCH_PARAMETERS", "ElementCompensation", "parameter_of", "sensor_name", "table_element",
    "unit_of",
    "TABLE_FORMAT", "TABLE_VERSION", "INTERPOLATION", "interpolate", "TableCurve", "CompensationTable",
    "CAMPAIGN_FORMAT", "CAMPAIGN_VERSION", "STITCH_MODELS", "StitchedCalibration", "read_campaign",
    "JointCalibration", "JointCurve",
    "TABLE_FORMATS", "SUFFIX", "table_json", "table_csv", "table_c_header", "write_table", "read_table",
    "element_identifier",
    "PROVENANCE_ATTRIBUTE", "read_compensation", "apply", "note_of", "write_corrected", "correction_of",
]
