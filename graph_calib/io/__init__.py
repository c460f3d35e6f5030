r"""Reading, writing and validating the files of ``data-format.md``, and atomic writing.

Modules, one per job:

* :mod:`graph_calib.io.experiment_file`: the experiment file (HDF5),
  :func:`read_experiment`, :func:`write_experiment`, :func:`validate_experiment`;
* :mod:`graph_calib.io.result_file`: the result file (JSON), :func:`read_result`,
  :func:`write_result`, :func:`validate_result`, :func:`result_to_dict`;
* :mod:`graph_calib.io.residual_file`: the residual-series file (HDF5),
  :func:`write_residuals`, :func:`read_residuals`;
* :mod:`graph_calib.io.manifest`: the campaign manifest (TOML), :func:`read_manifest`
  giving a :class:`Campaign`;
* :mod:`graph_calib.io.atomic`: :func:`atomic_path`, :func:`atomic_write_text`,
  :func:`atomic_write_json`, :func:`dumps_json`, for every module that writes files;
* :mod:`graph_calib.io.checks`: small checks shared by the readers.

Readers check every rule of the format (``docs/data-format.md`` lists them with
their thresholds) and refuse a file that breaks one with a single
:class:`~graph_calib.errors.InputError` naming the file, the dataset or key, the
sample index where it applies, and what is wrong.  They never guess and never
drop samples.  The writers run the same checks before writing, and write
atomically, so that an error or an interruption never leaves a half-written file.

The public names of these modules are re-exported here: ``from graph_calib import
io; io.read_experiment(path)``.
"""

from graph_calib.errors import InputError
from graph_calib.io.atomic import (atomic_path, atomic_write_json, atomic_write_text, dumps_json,
                                   no_empty_folder_if_refused, to_json_builtin)
from graph_calib.io.experiment_file import (
    EXPERIMENT_FORMAT, EXPERIMENT_VERSION, GRAVITY_RANGE_MPS2, MAX_ANGULAR_RATE_RADPS, MAX_GAP_PERIODS,
    MAX_SPECIFIC_FORCE_MPS2, MEDIAN_SPECIFIC_FORCE_RANGE_G, QUATERNION_NORM_TOL, RATE_TOLERANCE,
    TEMPERATURE_RANGE_DEGC, read_experiment, validate_experiment, write_experiment,
)
from graph_calib.io.manifest import SOLVER_OPTIONS, Campaign, CampaignExperiment, read_manifest
from graph_calib.io.residual_file import RESIDUALS_FORMAT, read_residuals, write_residuals
from graph_calib.io.result_file import (
    COVARIANCE_SYMMETRY_TOL, RESULT_FORMAT, RESULT_VERSION, read_result, result_to_dict, validate_result,
    write_result,
)

__all__ = [
    # atomic writing
    "atomic_path", "atomic_write_text", "atomic_write_json", "dumps_json", "to_json_builtin",
    "no_empty_folder_if_refused",
    # experiment file
    "read_experiment", "write_experiment", "validate_experiment", "EXPERIMENT_FORMAT", "EXPERIMENT_VERSION",
    "GRAVITY_RANGE_MPS2", "MAX_GAP_PERIODS", "RATE_TOLERANCE", "MAX_ANGULAR_RATE_RADPS", "MAX_SPECIFIC_FORCE_MPS2",
    "MEDIAN_SPECIFIC_FORCE_RANGE_G", "TEMPERATURE_RANGE_DEGC", "QUATERNION_NORM_TOL",
    # result file
    "read_result", "write_result", "validate_result", "result_to_dict", "RESULT_FORMAT", "RESULT_VERSION",
    "COVARIANCE_SYMMETRY_TOL",
    # residual-series file
    "write_residuals", "read_residuals", "RESIDUALS_FORMAT",
    # campaign manifest
    "read_manifest", "Campaign", "CampaignExperiment", "SOLVER_OPTIONS",
    # the error every reader raises
    "InputError",
]
