"""A campaign's joint calibration (:mod:`graph_calib.solvers.joint`) as a compensation, like the stitched one.

:class:`JointCalibration` evaluates every temperature-dependent element's joint curve at each sample's
own sensor temperature, with its one-sigma band straight from the joint covariance of the curve's
coefficients (no stitching step); the shared elements are constants.  It has what
:class:`graph_calib.compensation.StitchedCalibration` has: ``correct``/``corrected`` (through the one
sensor model), ``table`` (the compensation table ``graph-calib export`` writes), and ``evaluate``,
``element_sigmas`` and ``curves[...].t_span`` for :func:`graph_calib.evaluation.validation.validate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from graph_calib.compensation.elements import TABLE_PARAMETERS, ElementCompensation, element_order, parameter_of
from graph_calib.compensation.stitched import INTERPOLATION_CHECK_POINTS, read_campaign
from graph_calib.compensation.table import CompensationTable, TableCurve, interpolate
from graph_calib.errors import InputError
from graph_calib.solvers.joint.result import read_joint_result
from graph_calib.sensors.curves import evaluate_polynomial_curve
from graph_calib.solvers.joint.solver import JOINT
from graph_calib.stitching import sensor_of


@dataclass(frozen=True)
class JointCurve:
    """One element's joint curve: ``value(T) = sum c_j (T - t0)^j`` with its covariance.

    Attributes
    ----------
    coefficients : ndarray, shape (d+1,)
    covariance : ndarray, shape (d+1, d+1)
    t0_degC : float
    t_span : tuple of float
        Where the curve is calibrated (its sensor's lowest and highest temperature over the experiments), degC.
    """

    coefficients: np.ndarray
    covariance: np.ndarray
    t0_degC: float
    t_span: tuple

    def evaluate(self, T, model=None):
        """``(value, sigma)`` at temperatures ``T`` (degC), SI (``model`` ignored: one curve form)."""
        return evaluate_polynomial_curve(self.coefficients, T, t0_degC=self.t0_degC, covariance=self.covariance)


@dataclass(frozen=True, eq=False)
class JointCalibration(ElementCompensation):
    """The joint calibration of a campaign (module docstring).

    Attributes
    ----------
    curves : dict
        ``{flat element: JointCurve}`` of the temperature-dependent sensor elements.
    constants : dict
        ``{flat element: (value, sigma)}`` of the shared sensor elements.
    info : dict
        ``solver``, ``source``, ``t0_degC``, ``degrees``, ``experiments``.
    """

    curves: dict
    constants: dict
    info: dict = field(default_factory=dict)

    @classmethod
    def from_result(cls, result, *, source=""):
        """From a joint result (:func:`graph_calib.solvers.joint.result.joint_result`)."""
        block = result.extra[JOINT]
        t0 = float(block["t0_degC"])
        spans = np.asarray(block["sensor_ranges_degC"], dtype=float).reshape(6, 2)
        curves = {}
        for name, cv in block["curves"].items():
            if parameter_of(name) not in TABLE_PARAMETERS:
                continue
            s = sensor_of(name)
            span = tuple(float(v) for v in (spans[s] if s is not None else block["valid_range_degC"]))
            curves[name] = JointCurve(np.asarray(cv["coefficients"], dtype=float),
                                      np.asarray(cv["covariance"], dtype=float), t0, span)
        family_members = {n for n in result.values if parameter_of(n) not in TABLE_PARAMETERS}
        constants = {n: (float(v), float(result.sigmas[n])) for n, v in result.values.items()
                     if n not in family_members and n not in curves}
        curves = {n: curves[n] for n in element_order(list(curves))}
        constants = {n: constants[n] for n in element_order(list(constants))}
        info = {"solver": result.solver, "stitch_model": JOINT, "source": source or result.source,
                "t0_degC": t0, "degrees": dict(block.get("degrees", {})),
                "subranges": list(block.get("experiments", []))}
        return cls(curves=curves, constants=constants, info=info)

    @classmethod
    def from_file(cls, path):
        """From a joint result file (:func:`graph_calib.solvers.joint.result.read_joint_result`)."""
        return cls.from_result(read_joint_result(path), source=str(Path(path).resolve()))

    @classmethod
    def from_campaign(cls, campaign, *, solver=JOINT):
        """From a campaign folder (or its ``campaign.json``) whose joint solver ran.

        Raises
        ------
        InputError
            No campaign there, or no joint result in it.
        """
        path = Path(campaign)
        if path.is_dir():
            path = path / "campaign.json"
        doc = read_campaign(path)
        entry = (doc.get(JOINT) or {}).get(solver)
        if not isinstance(entry, dict) or "file" not in entry:
            raise InputError(f"no {solver} result in this campaign (run it with --solver {solver} or both)",
                             path=path, dataset=JOINT)
        out = cls.from_file(path.parent / entry["file"])
        out.info["imu_id"] = doc.get("imu_id", "")
        return out

    # -- ElementCompensation ---------------------------------------------------------

    def curve_elements(self):
        return list(self.curves)

    def curve_values(self, element, T):
        return self.curves[element].evaluate(T)

    def valid_range(self, element):
        return self.curves[element].t_span

    def describe(self):
        i = self.info
        return (f"corrected with the joint calibration of {i.get('imu_id') or 'an unnamed IMU'} "
                f"(degrees {i.get('degrees')}, from {i.get('source') or '?'})")

    # -- what validation reads --------------------------------------------------------

    def evaluate(self, T_sensors, model=None):
        """Every element at the sensor temperatures ``T_sensors`` (N, 6), ``{flat: (N,)}`` (``model`` ignored)."""
        return self.element_values(T_sensors)

    def element_sigmas(self, T_sensors, model=None):
        """One sigma of every element at the sensor temperatures, ``{flat: (N,)}`` (``model`` ignored)."""
        return super().element_sigmas(T_sensors)

    # -- the table ---------------------------------------------------------------------

    def table(self, step_degC=1.0):
        """The compensation table on a grid of ``step_degC`` over the calibrated range (as the stitched one's)."""
        step = float(step_degC)
        if not (math.isfinite(step) and step > 0):
            raise InputError(f"must be a positive number of degC, got {step_degC!r}", dataset="--step-degc")
        lo = min(c.t_span[0] for c in self.curves.values())
        hi = max(c.t_span[1] for c in self.curves.values())
        k0 = math.floor(lo / step + 1e-9)
        grid = np.arange(k0, max(math.ceil(hi / step - 1e-9), k0 + 1) + 1) * step
        frac = np.arange(INTERPOLATION_CHECK_POINTS) / INTERPOLATION_CHECK_POINTS
        fine = np.append((grid[:-1, None] + np.diff(grid)[:, None] * frac).ravel(), grid[-1])
        curves = {}
        for n, cv in self.curves.items():
            v, s = cv.evaluate(grid)
            vf, sf = cv.evaluate(fine)
            err = np.abs(interpolate(grid, v, fine) - vf)
            in_sigma = err / np.where(sf > 0, sf, np.inf)
            curves[n] = TableCurve(v, s, cv.t_span, {"max_abs": float(err.max()),
                                                     "max_in_sigma": float(in_sigma.max()),
                                                     "at_degC": float(fine[int(np.argmax(in_sigma))])})
        info = dict(self.info)
        info.update({"step_degC": step, "calibrated_range_degC": [float(lo), float(hi)]})
        return CompensationTable(grid, curves, dict(self.constants), info=info)


__all__ = ["JointCurve", "JointCalibration"]
