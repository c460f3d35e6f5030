r"""What an export projects: the full calibration over temperature, its range, its noise, read from a file.

:func:`load_source` reads a result file (one experiment's calibration with its
temperature coefficients about its reference) or a campaign folder (its stitched
curves, or the joint solver's with ``solver=JOINT``) through
:func:`graph_calib.compensation.apply.read_compensation`, and gives an
:class:`ExportSource`: :meth:`ExportSource.errors` is the full model's sensor error
``measure(signal) - signal`` at a temperature (every sensor at that temperature),
through the one sensor model (:func:`graph_calib.compensation.calibration.triad_errors`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from graph_calib import io
from graph_calib.compensation.apply import read_compensation, superseded, verdict_failed
from graph_calib.compensation.calibration import Calibration, triad_errors
from graph_calib.errors import InputError
from graph_calib.solvers.joint.solver import JOINT


@dataclass(frozen=True)
class ExportSource:
    """The calibration an export projects.

    Attributes
    ----------
    compensation : Calibration or ElementCompensation
    range_degC : tuple of float
        The calibrated temperature range (the export's domain).
    t_ref_degC : float
        Reference temperature: the result's, or the middle of a campaign's range.
    noise : dict or None
        The result's ``noise`` block (data-format.md), or for a campaign the median of its results' figures.
    grade : str or None
    rate_hz : float or None
        Sample rate of the calibrated record, when it can be found.
    imu_id, label : str
        Identity and a one-line description of where it came from.
    provenance : dict
    prior_held : tuple of str
        The elements a result marks held by their priors (``prior_dominated``), sorted; empty for a campaign.
    """

    compensation: object
    range_degC: tuple
    t_ref_degC: float
    noise: dict | None = None
    grade: str | None = None
    rate_hz: float | None = None
    imu_id: str = ""
    label: str = ""
    provenance: dict = field(default_factory=dict)
    prior_held: tuple = ()

    def errors(self, T_degC, omega_b, f_b):
        """Sensor errors of the full model, ``(e_gyro, e_accel)`` (N, 3), rad/s and m/s^2.

        Parameters
        ----------
        T_degC : array_like, shape (N,)
            Temperature of every sensor, degC.
        omega_b, f_b : array_like, shape (N, 3)
            True angular rate (rad/s) and specific force (m/s^2).
        """
        T = np.asarray(T_degC, dtype=float)
        omega_b = np.atleast_2d(np.asarray(omega_b, dtype=float))
        f_b = np.atleast_2d(np.asarray(f_b, dtype=float))
        comp = self.compensation
        if isinstance(comp, Calibration):
            dT = np.repeat((T - comp.t_ref_degC)[:, None], 6, axis=1)
            return comp.sensor_errors(omega_b, f_b, dT=dT)
        X = comp.rows(np.repeat(T[:, None], 6, axis=1))
        e_g = triad_errors(comp.layout, X, "gyro", omega_b, other=f_b)
        e_a = triad_errors(comp.layout, X, "accel", f_b, other=omega_b)
        return e_g, e_a

    def parameters(self):
        """Names of the parameters the calibration holds (``gyro.scale``, ``accel.bias_tc``, ...)."""
        return tuple(self.compensation.layout.names)


def _median_noise(blocks):
    keys = {k for b in blocks for k, v in b.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    out = {k: float(np.median([b[k] for b in blocks if isinstance(b.get(k), (int, float))])) for k in sorted(keys)}
    sources = [b.get("source") for b in blocks if isinstance(b.get("source"), dict)]
    if sources:
        out["source"] = sources[0]
    return out


def _summary_rate(folder):
    """The rate a campaign's ``summary.json`` beside a task's result gives (its record may live elsewhere)."""
    try:
        rate = json.loads((Path(folder) / "summary.json").read_text(encoding="utf-8")).get("rate_hz")
    except (OSError, ValueError, AttributeError):
        return None
    return float(rate) if isinstance(rate, (int, float)) and rate > 0 else None


def _experiment_rate(candidates):
    for p in candidates:
        if p is not None and Path(p).is_file():
            try:
                return float(io.read_experiment(p).rate_hz)
            except Exception:  # noqa: BLE001 - a rate is a convenience: any unreadable candidate is skipped
                continue
    return None


def load_source(path, *, solver=None, model=None, force=False):
    """The :class:`ExportSource` of a result file or a campaign folder; a failed verdict exported with ``force`` says
    so in its label (the first line of every exported file and of the command's summary).

    Raises
    ------
    InputError
        Not a result or campaign; a compensation table (it has lost the model: export from its campaign); a failed
        verdict without ``force``.
    """
    comp, prov = read_compensation(path, solver=solver, model=model)
    failed = verdict_failed(prov)
    if failed and not force:
        raise InputError(f"its verdict failed ({failed}); export it anyway with --force", path=path,
                         dataset="verdict")
    later = superseded(prov)
    if later and not force:
        raise InputError(later, path=path, dataset="campaign")
    path = Path(path)
    if prov["kind"] == "result" and not isinstance(comp, Calibration):
        # a joint result (docs/joint-result.md): curves over temperature, exported as its campaign's joint calibration
        if not (path.parent / "campaign.json").is_file():
            raise InputError("a joint result exports from its campaign: graph-calib export CAMPAIGN --solver joint "
                             f"(no campaign.json beside it in {path.parent})", path=path)
        return load_source(path.parent, solver=JOINT, force=force)
    source = _source(comp, prov, path)
    if failed:
        source = replace(source, label=f"{source.label}, WHOSE VERDICT FAILED ({failed}), exported with --force")
    return source


def _source(comp, prov, path):
    """:func:`load_source`'s source of a result, calibration or campaign, before its label says a failed verdict."""
    kind = prov["kind"]
    if kind == "table":
        raise InputError("a compensation table holds values on a grid, not the model: export from the campaign "
                         "folder or the result file it came from", path=path)
    if kind in ("result", "calibration"):
        doc = json.loads(path.read_text(encoding="utf-8"))
        rng = tuple(doc.get("temperature_range_degC") or (comp.t_ref_degC, comp.t_ref_degC))
        folder = path.parent
        src = doc.get("source") or ""
        rate = _experiment_rate([folder / src, folder.parent / src] if src else []) or _summary_rate(folder)
        return ExportSource(compensation=comp, range_degC=(float(rng[0]), float(rng[1])),
                            t_ref_degC=float(comp.t_ref_degC), noise=doc.get("noise"), grade=doc.get("grade"),
                            rate_hz=rate, imu_id=str(doc.get("imu_id", "")),
                            label=f"{prov.get('solver', 'result')} result of {src or path.name}", provenance=prov,
                            prior_held=tuple(sorted(doc.get("prior_dominated") or ())))
    # a campaign: its curves' common range, its results' noise
    ranges = [comp.valid_range(n) for n in comp.curve_elements()]
    if not ranges:
        raise InputError("the campaign's calibration has no temperature-dependent element", path=path)
    lo, hi = max(r[0] for r in ranges), min(r[1] for r in ranges)
    campaign_json = path / "campaign.json" if path.is_dir() else path
    doc = json.loads(campaign_json.read_text(encoding="utf-8"))
    blocks, grade, rate = [], None, None
    for e in doc.get("experiments") or []:
        for res in (e.get("results") or {}).values():
            f = campaign_json.parent / res.get("file", "") if isinstance(res, dict) else None
            if f is not None and f.is_file():
                r = json.loads(f.read_text(encoding="utf-8"))
                if isinstance(r.get("noise"), dict):
                    blocks.append(r["noise"])
                grade = grade or r.get("grade")
        if rate is None and e.get("file"):
            rate = _experiment_rate([campaign_json.parent / e["file"], Path(e["file"])])
    return ExportSource(compensation=comp, range_degC=(float(lo), float(hi)), t_ref_degC=0.5 * (lo + hi),
                        noise=_median_noise(blocks) if blocks else None, grade=grade, rate_hz=rate,
                        imu_id=str(doc.get("imu_id", "")), provenance=prov,
                        label=f"{comp.info.get('stitch_model', '')} calibration over temperature of the campaign "
                              f"{campaign_json.parent.name} ({comp.info.get('solver', '')})")


__all__ = ["ExportSource", "load_source"]
