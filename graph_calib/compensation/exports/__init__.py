r"""The ecosystem's own files: PX4 and ArduPilot parameters, Kalibr's and OpenVINS's IMU YAML.

Each format projects the full calibration over temperature
(:class:`~graph_calib.compensation.exports.source.ExportSource`, from a result file or a
campaign folder) onto what the format can hold, and reports what it leaves out with its
size over the calibrated range (:class:`~graph_calib.compensation.exports.projection.Loss`):
in the file's comments and, through ``graph-calib export``, on the terminal.
``docs/compensation.md`` states each consumer's equation.

:data:`EXPORT_FORMATS` maps each format to its file suffixes and its writer
``document(source, **options) -> {"loss", ...}`` and ``text(source, document) -> str``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from graph_calib.compensation.exports import autopilot, estimators
from graph_calib.compensation.exports.projection import DEFAULT_ENVELOPE_DPS, Loss
from graph_calib.compensation.exports.source import ExportSource, load_source


@dataclass(frozen=True)
class ExportFormat:
    """One ecosystem file: its name, suffixes, what it takes and how it is written."""

    name: str
    suffixes: tuple
    summary: str
    document: Callable
    text: Callable
    options: tuple = ()


def _kalibr_text(source, doc):
    return estimators.yaml_text(source, doc, title="Kalibr imu.yaml (scale-misalignment intrinsics)")


def _openvins_text(source, doc):
    return estimators.yaml_text(source, doc, title="OpenVINS kalibr_imu_chain.yaml (model kalibr)",
                                directive="%YAML:1.0")


EXPORT_FORMATS = {
    "px4": ExportFormat("px4", (".params",), "PX4 TC_* thermal-compensation parameters (QGroundControl file)",
                        autopilot.px4_document, autopilot.px4_text, ("instance", "gyro_id", "accel_id")),
    "ardupilot": ExportFormat("ardupilot", (".parm", ".param"), "ArduPilot INS_TCALn_* parameters (.parm)",
                              autopilot.ardupilot_document, autopilot.ardupilot_text, ("instance",)),
    "kalibr": ExportFormat("kalibr", (".yaml", ".yml"), "Kalibr imu.yaml: noise and scale-misalignment intrinsics",
                           estimators.kalibr_document, _kalibr_text, ("rostopic", "rate_hz")),
    "openvins": ExportFormat("openvins", (".yaml", ".yml"), "OpenVINS kalibr_imu_chain.yaml: noise and intrinsics",
                             estimators.openvins_document, _openvins_text, ("rostopic", "rate_hz")),
}

__all__ = ["EXPORT_FORMATS", "ExportFormat", "ExportSource", "load_source", "Loss", "DEFAULT_ENVELOPE_DPS"]
