r"""A campaign's stitched calibration as a compensation, and its table.

:class:`StitchedCalibration` is one solver's stitched curves (:mod:`graph_calib.stitching`)
in one stitched model (``cubic`` or ``linear``), applied directly: every element at
each sample's own sensor temperature, through the one sensor model.  An element whose
stitched fit is ``constant`` (the misalignments and the further effects without a
temperature coefficient, under the cubic model) is a constant; under the linear model
those interpolate their subrange values and depend on temperature.  Sensor-term
parameters that the stitching leaves out (``time_lag.accel``: not a gyro or accel
parameter) are constants, the stitching's weighted mean over the subranges
(:func:`graph_calib.stitching.fit_element`, its ``constant`` fit).

Where the curves come from (:meth:`StitchedCalibration.from_campaign`)
    ``campaign.json`` stores each solver's stitching (``stitching.<solver>``: the
    subranges and every element's fits), but not everything needed to evaluate a fit
    (whether a linear fit holds its end values is implied, not stored).  The curves
    are therefore recomputed through :func:`graph_calib.stitching.stitch` from the
    per-experiment result files the campaign lists (``experiments[i].results.<solver>.file``),
    with the subranges and sensor temperature ranges it recorded, exactly as the
    campaign stitched them; every recomputed fit is then checked against the stored
    one, and a difference (result files changed after the campaign ran) is refused.

The table (:meth:`StitchedCalibration.table`)
    A regular grid of ``step_degC`` over the elements' calibrated range (the lowest
    and highest sensor temperature over the subranges), widened outwards to
    multiples of the step (so by less than one step); each temperature-dependent
    element's stitched value and one-sigma band at every grid temperature; the
    constants.  At the grid temperatures the table's values are the stitched values
    (the same numbers); between them the table's linear interpolation departs from a
    curved (cubic) fit by at most ``h^2/8 max|p''|``, which the table states per
    element (``interpolation_error``: largest absolute difference, and the same in
    units of the element's sigma, over 16 points per grid interval and, for a
    piecewise-linear fit, at its knots, where it departs most).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from graph_calib import io
from graph_calib.compensation.elements import TABLE_PARAMETERS, ElementCompensation, element_order, parameter_of
from graph_calib.compensation.table import CompensationTable, TableCurve, interpolate
from graph_calib.errors import InputError
from graph_calib.stitching import Stitched, SubrangePoint, family, fit_element, is_stitched, stitch

#: ``format`` of the campaign summary this module reads, and the newest version it knows.
CAMPAIGN_FORMAT = "imu-calibration-campaign"
CAMPAIGN_VERSION = 1
#: Stitched models a compensation can use.
STITCH_MODELS = ("cubic", "linear")
#: Relative difference between a recomputed fit and the one campaign.json stores that counts as the same.
REFIT_TOLERANCE = 1e-9
#: Points per grid interval at which the interpolation error is measured.
INTERPOLATION_CHECK_POINTS = 16


@dataclass(frozen=True, eq=False)
class StitchedCalibration(ElementCompensation):
    """One solver's stitched calibration in one stitched model, applied directly (module docstring).

    Attributes
    ----------
    stitched : graph_calib.stitching.Stitched
    model : str
        ``"cubic"`` or ``"linear"``.
    constants : dict
        ``{flat element: (value, sigma)}`` of the elements that do not depend on
        temperature (filled from ``stitched`` and ``extra_constants``).
    extra_constants : dict
        Sensor-term elements the stitching leaves out, ``{flat element: (value, sigma)}``.
    info : dict
        ``imu_id``, ``solver``, ``stitch_model``, ``source``, ``subranges`` (JSON-ready).
    """

    stitched: Stitched
    model: str = "cubic"
    extra_constants: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    constants: dict = field(init=False)

    def __post_init__(self):
        if self.model not in STITCH_MODELS:
            raise ValueError(f"model must be one of {STITCH_MODELS}, got {self.model!r}")
        curves, constants = [], {}
        for name, cv in self.stitched.curves.items():
            if parameter_of(name) not in TABLE_PARAMETERS:
                continue
            fit = cv.fit(self.model)
            if fit.kind == "constant":
                v, s = fit.evaluate([0.0])
                constants[name] = (float(v[0]), float(s[0]))
            else:
                curves.append(name)
        constants.update({n: (float(v), float(s)) for n, (v, s) in self.extra_constants.items()})
        object.__setattr__(self, "_curves", tuple(element_order(curves)))
        object.__setattr__(self, "constants", {n: constants[n] for n in element_order(list(constants))})
        info = {"solver": self.stitched.solver, "stitch_model": self.model,
                "subranges": list(self.stitched.subranges)}
        info.update(self.info)
        object.__setattr__(self, "info", info)

    # -- ElementCompensation -----------------------------------------------------------

    def curve_elements(self):
        return list(self._curves)

    def curve_values(self, element, T):
        return self.stitched.curves[element].evaluate(T, self.model)

    def valid_range(self, element):
        return tuple(float(t) for t in self.stitched.curves[element].t_span)

    def describe(self):
        i = self.info
        return (f"corrected with the stitched calibration of {i.get('imu_id') or 'an unnamed IMU'} "
                f"({i['solver']} {self.model}, from {i.get('source') or '?'})")

    # -- the table -----------------------------------------------------------------------

    def grid(self, step_degC=1.0):
        """The table's grid: multiples of ``step_degC`` from below the lowest calibrated sensor temperature to
        above the highest (at least two points), degC."""
        step = float(step_degC)
        if not (math.isfinite(step) and step > 0):
            raise InputError(f"must be a positive number of degC, got {step_degC!r}", dataset="--step-degc")
        spans = [self.valid_range(n) for n in self.curve_elements()]
        if not spans:
            spans = [p.t_range for cv in self.stitched.curves.values() for p in cv.points]
        lo = min(s[0] for s in spans)
        hi = max(s[1] for s in spans)
        k0 = math.floor(lo / step + 1e-9)
        k1 = max(math.ceil(hi / step - 1e-9), k0 + 1)
        return np.arange(k0, k1 + 1) * step

    def table(self, step_degC=1.0):
        """The compensation table of this calibration on :meth:`grid` (module docstring).

        Returns
        -------
        CompensationTable
            With ``info`` holding this calibration's provenance, the step, the calibrated
            range and, per element, the interpolation error.
        """
        grid = self.grid(step_degC)
        frac = np.arange(INTERPOLATION_CHECK_POINTS) / INTERPOLATION_CHECK_POINTS
        fine = np.append((grid[:-1, None] + np.diff(grid)[:, None] * frac).ravel(), grid[-1])
        curves = {}
        for n in self.curve_elements():
            knots = self.stitched.curves[n].fit(self.model).knots   # a linear fit departs most at its knots
            fine_n = fine if knots is None else np.union1d(fine, knots[(knots > grid[0]) & (knots < grid[-1])])
            v, s = self.curve_values(n, grid)
            vf, sf = self.curve_values(n, fine_n)
            err = np.abs(interpolate(grid, v, fine_n) - vf)
            in_sigma = err / np.where(sf > 0, sf, np.inf)
            curves[n] = TableCurve(v, s, self.valid_range(n), {
                "max_abs": float(err.max()), "max_in_sigma": float(in_sigma.max()),
                "at_degC": float(fine_n[int(np.argmax(in_sigma))])})
        spans = [c.calibrated_range_degC for c in curves.values()]
        info = dict(self.info)
        info.update({"step_degC": float(step_degC),
                     "calibrated_range_degC": [min(s[0] for s in spans), max(s[1] for s in spans)] if spans else None})
        return CompensationTable(grid, curves, dict(self.constants), info=info)

    # -- from a campaign -------------------------------------------------------------------

    @classmethod
    def from_campaign(cls, campaign, *, solver=None, model=None):
        """The stitched calibration of a campaign folder (or its ``campaign.json``), recomputed and checked.

        Parameters
        ----------
        campaign : str or Path
            The folder ``graph-calib campaign`` wrote, or its ``campaign.json``.
        solver : str, optional
            Whose results (default: the campaign's primary solver).
        model : str, optional
            ``"cubic"`` or ``"linear"`` (default: the campaign's ``stitch_model``).

        Raises
        ------
        graph_calib.errors.InputError
            No campaign there, a newer campaign version, a solver or model the campaign
            did not stitch, a missing or bad result file, or stored curves that the
            result files no longer give.
        """
        path = Path(campaign)
        if path.is_dir():
            path = path / "campaign.json"
        doc = read_campaign(path)
        folder = path.parent
        for key, kind in (("stitching", dict), ("experiments", list)):
            if not isinstance(doc.get(key), kind):
                raise InputError(f"missing or not a JSON {'object' if kind is dict else 'list'}", path=path,
                                 dataset=key)
        stitching = doc["stitching"]
        if not stitching:
            joint = " (its joint calibration: --solver joint)" if isinstance(doc.get("joint"), dict) and doc["joint"] \
                else ""
            raise InputError(f"the campaign stitched nothing (no per-subrange solver finished an experiment){joint}",
                             path=path, dataset="stitching")
        solver = solver or doc.get("primary_solver") or next(iter(stitching))
        if solver not in stitching:
            raise InputError(f"no stitching of solver {solver!r}; the campaign stitched {', '.join(stitching)}",
                             path=path, dataset="stitching")
        model = model or doc.get("stitch_model") or "cubic"
        if model not in STITCH_MODELS:
            raise InputError(f"stitched model {model!r} is not one of {', '.join(STITCH_MODELS)}", path=path,
                             dataset="stitch_model")
        stored = stitching[solver]
        if not isinstance(stored, dict) or not isinstance(stored.get("elements"), dict):
            raise InputError("not a stitching (an object with subranges and elements)", path=path,
                             dataset=f"stitching.{solver}")
        names = list(stored.get("subranges") or [])
        entries = {e.get("name"): e for e in doc.get("experiments") or [] if isinstance(e, dict)}
        missing = [n for n in names if n not in entries]
        if missing or not names:
            raise InputError(f"subranges {missing or names} are not among the experiments", path=path,
                             dataset=f"stitching.{solver}.subranges")
        order = [n for n in entries if n in set(names)]          # the campaign's order, as it stitched them
        results, ranges = [], []
        for n in order:
            e = entries[n]
            rel = ((e.get("results") or {}).get(solver) or {}).get("file") or f"{e.get('folder', n)}/{solver}.json"
            results.append(io.read_result(folder / rel))
            ranges.append(e.get("sensor_temperature_range_degC"))
        try:
            st = stitch(results, names=order, sensor_ranges=ranges, solver=solver)
        except ValueError as exc:      # e.g. a result without sigmas, or bad sensor ranges
            raise InputError(f"cannot stitch the results it lists: {exc}", path=path,
                             dataset=f"stitching.{solver}") from None
        _check_refit(st, stored, path=path, solver=solver)
        extra = _unstitched_constants(results, order, ranges)
        return cls(st, model=model, extra_constants=extra,
                   info={"imu_id": doc.get("imu_id", ""), "source": str(path.resolve()),
                         "source_sha256": hashlib.sha256(path.read_bytes()).hexdigest()})


def read_campaign(path):
    """The campaign summary ``campaign.json`` as a dict, its format and version checked (:class:`InputError`)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("no campaign here (campaign.json not found: run graph-calib campaign first)"
                         if not path.exists() else "not a file", path=path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"not a readable JSON file ({str(exc).splitlines()[0]})", path=path) from None
    if not isinstance(doc, dict) or doc.get("format") != CAMPAIGN_FORMAT:
        fmt = doc.get("format") if isinstance(doc, dict) else None
        raise InputError(f"format is {fmt!r}, expected {CAMPAIGN_FORMAT!r}", path=path, dataset="format")
    v = doc.get("version")
    if isinstance(v, bool) or not isinstance(v, int) or v < 1 or v > CAMPAIGN_VERSION:
        raise InputError(f"version {v!r} is not one this graph-calib reads (up to {CAMPAIGN_VERSION})", path=path,
                         dataset="version")
    return doc


def _check_refit(st, stored, *, path, solver):
    """Refuse when the recomputed stitching differs from the one ``campaign.json`` stores."""
    elements = stored.get("elements") or {}
    if set(elements) != set(st.curves):
        diff = sorted(set(elements) ^ set(st.curves))
        raise InputError(f"the result files give other elements than the campaign stitched ({', '.join(diff[:4])}"
                         f"{' ...' if len(diff) > 4 else ''}): the results changed after the campaign ran; run it "
                         "again", path=path, dataset=f"stitching.{solver}.elements")
    for name, cv in st.curves.items():
        for kind, fit in cv.fits.items():
            entry = elements[name] if isinstance(elements[name], dict) else {}
            try:
                old = np.asarray(((entry.get("fits") or {}).get(kind) or {}).get("theta", []), dtype=float)
            except (TypeError, ValueError, AttributeError):
                old = np.zeros(0)
            new = fit.theta
            scale = max(float(np.max(np.abs(new))) if new.size else 0.0, 1e-300)
            if old.shape != new.shape or float(np.max(np.abs(old - new))) > REFIT_TOLERANCE * scale:
                raise InputError(f"the {kind} fit recomputed from the result files differs from the stored one: the "
                                 "results changed after the campaign ran; run it again", path=path,
                                 dataset=f"stitching.{solver}.elements.{name}")


def _unstitched_constants(results, names, ranges):
    """Sensor-term elements the stitching leaves out, as the stitching's constant fit over the subranges."""
    out = {}
    params = [p for p in TABLE_PARAMETERS if not is_stitched(p) and family(p)[0] == p]
    for p in params:
        for el in element_order(list({n for r in results for n in r.values if _is(n, p)})):
            pts = []
            for r, nm, rg in zip(results, names, ranges):
                if el not in r.values:
                    continue
                s = (r.sigmas or {}).get(el, 0.0)
                t_range = tuple(np.asarray(rg, dtype=float).reshape(6, 2).mean(axis=0)) if rg is not None \
                    else tuple(r.temperature_range_degC)
                pts.append(SubrangePoint(nm, float(r.t_ref_degC), np.array([r.values[el]]), np.array([[s * s]]),
                                         t_range))
            fit = fit_element(el, pts).fit("constant")
            v, s = fit.evaluate([0.0])
            out[el] = (float(v[0]), float(s[0]))
    return out


def _is(element, parameter):
    try:
        return parameter_of(element) == parameter
    except KeyError:
        return False


__all__ = ["StitchedCalibration", "read_campaign", "CAMPAIGN_FORMAT", "CAMPAIGN_VERSION", "STITCH_MODELS",
           "REFIT_TOLERANCE", "INTERPOLATION_CHECK_POINTS"]
