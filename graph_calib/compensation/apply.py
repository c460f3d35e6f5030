"""Applying a calibration to a raw record: what ``graph-calib apply`` does, as functions.

:func:`read_compensation` reads what corrects: a result file (``data-format.md``,
one experiment's calibration: :class:`graph_calib.compensation.calibration.Calibration`), a
calibration document (:meth:`Calibration.to_dict`), a compensation table (JSON or
CSV: :class:`~graph_calib.compensation.table.CompensationTable`) or a campaign
folder or its ``campaign.json`` (the stitched calibration applied directly:
:class:`~graph_calib.compensation.stitched.StitchedCalibration`).  Each has
``correct(experiment) -> (omega_ib_b, f_b)`` through the one sensor model and
``corrected(experiment)``, the experiment with corrected increments.

:func:`verdict_failed` says whether the result or campaign read has a failed verdict (``graph-calib apply``
refuses it without ``--force``); a result's directions marked ``unresolved`` are never applied
(:func:`without_unresolved`: the calibration's component along each is removed, and the provenance says so).

:func:`apply` corrects an experiment and says how; :func:`write_corrected` writes
the corrected experiment atomically, a valid experiment file whose root attribute
:data:`PROVENANCE_ATTRIBUTE` holds the provenance (JSON) and whose description
starts with it in words; :func:`correction_of` reads that attribute back, so that a
corrected record is not corrected twice by mistake.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import h5py
import numpy as np

from graph_calib import __version__, io
from graph_calib.compensation.calibration import CALIBRATION_FORMAT, Calibration, corrected_experiment
from graph_calib.compensation.formats import read_table
from graph_calib.compensation.joint import JointCalibration
from graph_calib.compensation.stitched import CAMPAIGN_FORMAT, StitchedCalibration
from graph_calib.compensation.table import TABLE_FORMAT
from graph_calib.constants import MPS2_TO_UG, RS_TO_DH
from graph_calib.errors import InputError
from graph_calib.solvers.joint.result import read_joint_result
from graph_calib.solvers.joint.solver import JOINT
from graph_calib.solvers.registry import PREDICTION_SOLVER

#: Root attribute of a corrected experiment file: the provenance of its correction, JSON.
PROVENANCE_ATTRIBUTE = "corrected_by"


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def read_compensation(path, *, solver=None, model=None):
    """What corrects, from a file or a campaign folder, and its provenance.

    Parameters
    ----------
    path : str or Path
        A result file, a calibration document, a compensation table (JSON or CSV), a
        campaign folder or its ``campaign.json``.
    solver, model : str, optional
        For a campaign only: whose stitching and which stitched model (defaults: the
        campaign's primary solver and ``stitch_model``).

    Returns
    -------
    compensation : Calibration, CompensationTable or StitchedCalibration
    provenance : dict
        JSON-ready: ``kind`` (``result``, ``calibration``, ``table``, ``stitched``), the
        file, its SHA-256, and what the compensation says of itself.

    Raises
    ------
    graph_calib.errors.InputError
        Naming the file: missing, not one of these, a newer version, bad content.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "campaign.json"
        if not path.is_file():
            raise InputError("a folder without campaign.json: expected a result file, a compensation table or a "
                             "campaign folder", path=path.parent)
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path=path)
    kind, fmt = _kind(path)
    if kind != "stitched" and (solver or model):
        raise InputError(f"--solver and --model choose among a campaign's stitchings; {path.name} is a {kind} file",
                         dataset="--solver" if solver else "--model")
    prov = {"kind": kind, "file": str(path.resolve()), "sha256": _sha256(path)}
    if kind == "result":
        result = io.read_result(path)
        if result.solver == PREDICTION_SOLVER:
            raise InputError("is a prediction (graph-calib predict): the sigmas a calibration of the record would "
                             "reach, every value 0; apply or export a result of calibrate, diagnose or campaign",
                             path=path)
        # a joint result (docs/joint-result.md): its curves with their bands, like a stitched calibration
        comp = (JointCalibration.from_result(read_joint_result(path), source=str(path.resolve()))
                if isinstance(result.extra.get(JOINT), dict) else Calibration.from_result(result))
        prov.update(solver=result.solver, source=result.source, t_ref_degC=result.t_ref_degC,
                    temperature_range_degC=list(result.temperature_range_degC))
        if result.extra.get("imu_id"):
            prov["imu_id"] = str(result.extra["imu_id"])
        if isinstance(result.extra.get("verdict"), dict):
            prov["verdict"] = result.extra["verdict"]
        elif isinstance(result.extra.get("campaign"), dict):
            # a campaign's task file holds no verdict (the campaign judges the experiment's solvers together and
            # keeps the files as the workers wrote them): its experiment's verdict in campaign.json
            verdict, final = experiment_entry(path, str(result.extra["campaign"].get("experiment", "")),
                                              solver=result.solver)
            if verdict is not None:
                prov["verdict"] = verdict
            if final is not None and final != path.resolve():
                prov["superseded_by"] = str(final)
        if result.extra.get("unresolved") and isinstance(comp, Calibration):
            comp, removed = without_unresolved(comp, result.extra["unresolved"])
            prov["unresolved_not_applied"] = removed
    elif kind == "calibration":
        try:
            comp = Calibration.from_dict(json.loads(path.read_text(encoding="utf-8")))
        except InputError as exc:
            raise InputError(str(exc), path=path) from None
        prov.update(source=comp.source, t_ref_degC=comp.t_ref_degC)
    elif kind == "table":
        comp = read_table(path)
        prov.update(format=fmt, **{k: v for k, v in comp.info.items() if k in ("imu_id", "solver", "stitch_model",
                                                                              "source", "step_degC")})
        prov["grid_degC"] = [float(comp.grid_degC[0]), float(comp.grid_degC[-1])]
        if isinstance(comp.info.get("verdict"), dict):
            prov["verdict"] = comp.info["verdict"]
    elif solver == JOINT:
        comp = JointCalibration.from_campaign(path)
        prov.update({k: v for k, v in comp.info.items() if k in ("imu_id", "solver", "stitch_model", "subranges")})
    else:
        comp = StitchedCalibration.from_campaign(path, solver=solver, model=model)
        prov.update({k: v for k, v in comp.info.items() if k in ("imu_id", "solver", "stitch_model", "subranges")})
    if kind == "stitched":
        verdict = campaign_verdict(path)
        if verdict is not None:
            prov["verdict"] = verdict
    return comp, prov


def experiment_entry(path, name, *, solver):
    """``(verdict, final result file)`` campaign.json gives experiment ``name`` and ``solver``, for a result file
    ``path`` of that campaign (in ``OUT/<name>/``, or a re-solve's ``OUT/<name>/pooled/<wave>/``); None for what no
    campaign.json above it says.  A final file other than ``path`` means ``path`` was superseded (a re-solve wave's
    result is the campaign's)."""
    for folder in list(Path(path).resolve().parents)[:4]:
        doc_path = folder / "campaign.json"
        if not doc_path.is_file():
            continue
        try:
            doc = json.loads(doc_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None, None
        for e in doc.get("experiments") or () if isinstance(doc, dict) else ():
            if isinstance(e, dict) and e.get("name") == name:
                verdict = e.get("verdict") if isinstance(e.get("verdict"), dict) else None
                entry = (e.get("results") or {}).get(solver)
                file = entry.get("file") if isinstance(entry, dict) else None
                return verdict, ((folder / file).resolve() if isinstance(file, str) and file else None)
        return None, None
    return None, None


def campaign_verdict(path):
    """The verdict (dict) of a campaign, its folder or its ``campaign.json``; None where it holds none or cannot be
    read (its reader says what is wrong with it)."""
    path = Path(path)
    path = path / "campaign.json" if path.is_dir() else path
    try:
        verdict = json.loads(path.read_text(encoding="utf-8")).get("verdict")
    except (OSError, ValueError, AttributeError):
        return None
    return verdict if isinstance(verdict, dict) else None


def superseded(provenance):
    """The words for a campaign task file the campaign re-solved (its final result another file), or None."""
    final = provenance.get("superseded_by")
    if not final:
        return None
    return (f"a re-solve wave of its campaign superseded it: the campaign's result of this experiment is {final} "
            "(--force takes this one anyway)")


def verdict_failed(provenance):
    """The failed verdict's words (str) of what :func:`read_compensation` read, or None when it passed or has none."""
    verdict = provenance.get("verdict")
    if not isinstance(verdict, dict) or verdict.get("passed", True):
        return None
    text = verdict.get("text") or "; ".join(str(p) for p in verdict.get("problems", ()))
    if not text:
        # a campaign's (campaign.json): the experiments that failed theirs and the checks over the campaign
        parts = ([f"experiments that failed theirs: {', '.join(map(str, verdict['failed']))}"]
                 if verdict.get("failed") else [])
        parts += [" ".join(str(c).split()) for c in verdict.get("campaign_checks_failed") or ()]
        text = "; ".join(parts) or "failed"
    return str(text).splitlines()[0]


def without_unresolved(calibration, unresolved):
    """The calibration with its component along each unresolved direction removed (left at the prior's zero).

    A direction the record cannot resolve (``unresolved`` of a result, data-format.md: ``{name: {element:
    component}}``, a unit direction) carries the prior and whatever the data's noise put there, not a sensor
    error: applying it would add an error (a gyro g-sensitivity along a heading drift turns a still unit).

    Returns
    -------
    Calibration
        ``x - u (u . x)`` for each direction ``u``.
    removed : dict
        ``{name: {"component": u . x, "elements": {element: change}}}`` for the provenance and the terminal.
    """
    names = calibration.layout.element_names()
    x = np.array(calibration.x, dtype=float)
    removed = {}
    for name, direction in unresolved.items():
        u = np.array([float(direction.get(n, 0.0)) for n in names])
        norm = float(np.linalg.norm(u))
        if norm == 0.0:
            continue
        u /= norm
        a = float(u @ x)
        change = -a * u
        x = x + change
        removed[name] = {"component": a, "elements": {n: float(c) for n, c in zip(names, change) if c != 0.0}}
    cal = Calibration(layout=calibration.layout, x=x, t_ref_degC=calibration.t_ref_degC, sigma=calibration.sigma,
                      source=calibration.source)
    return cal, removed


def _kind(path):
    """``(kind, table format)`` of a file, told by its content."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096).decode("utf-8", errors="replace").lstrip()
    except OSError as exc:
        raise InputError(f"cannot read: {exc}", path=path) from None
    if head.startswith("# format"):
        return "table", "csv"
    if head.startswith("/*"):
        raise InputError("a C header table is written for an INS, not read back: apply the JSON or CSV table",
                         path=path)
    if not head.startswith("{"):
        raise InputError("not a result file, a compensation table (JSON or CSV) or a campaign.json", path=path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"not valid JSON ({str(exc).splitlines()[0]})", path=path) from None
    fmt = doc.get("format") if isinstance(doc, dict) else None
    kinds = {io.RESULT_FORMAT: "result", CALIBRATION_FORMAT: "calibration", TABLE_FORMAT: "table",
             CAMPAIGN_FORMAT: "stitched"}
    if fmt not in kinds:
        raise InputError(f"is {fmt!r}: not a result file ({io.RESULT_FORMAT!r}), a compensation table "
                         f"({TABLE_FORMAT!r}) or a campaign ({CAMPAIGN_FORMAT!r})", path=path, dataset="format")
    return kinds[fmt], "json"


def _outside(compensation, provenance, T):
    """Samples whose sensor temperatures leave where the compensation is stated."""
    if hasattr(compensation, "outside"):
        return compensation.outside(T)
    rng = provenance.get("temperature_range_degC")
    if not rng:
        return 0
    return int(np.count_nonzero(np.any((T < rng[0]) | (T > rng[1]), axis=1)))


def note_of(compensation, provenance):
    """The first line of a corrected experiment's description: what corrected it, in words."""
    p = provenance
    if p["kind"] in ("result", "calibration"):
        what = (f"the {p.get('solver', 'calibration')} calibration of {p.get('source') or '?'} "
                f"(T_ref {p['t_ref_degC']:.2f} degC)")
        text = f"corrected with {what}"
    else:
        text = compensation.describe()
    return f"{text}; graph-calib {__version__} apply, {Path(p['file']).name} sha256 {p['sha256'][:12]}"


def apply(compensation, experiment, *, provenance):
    """Correct an experiment; the corrected experiment and a summary.

    Parameters
    ----------
    compensation : Calibration, CompensationTable or StitchedCalibration
    experiment : graph_calib.records.experiment.Experiment
    provenance : dict
        From :func:`read_compensation`; completed with the input and the counts.

    Returns
    -------
    corrected : graph_calib.records.experiment.Experiment
        Increments ``omega_ib_b dt`` and ``f_b dt``; description headed by :func:`note_of`.
    provenance : dict
        With ``input`` (the experiment's source), ``samples`` and ``outside`` (samples
        whose sensor temperatures leave where the compensation is stated: a table holds
        its end values there, a curve or a single result extrapolates).
    summary : dict
        ``mean_gyro_correction_degph`` and ``mean_accel_correction_ug`` (raw minus
        corrected, per axis), for printing.
    """
    T = experiment.sensor_temperatures()
    omega, f = compensation.correct(experiment)
    corrected = corrected_experiment(experiment, omega, f, note=note_of(compensation, provenance))
    prov = dict(provenance)
    prov.update(input=experiment.source, samples=experiment.n_samples,
                outside=_outside(compensation, provenance, T), written_by=f"graph-calib {__version__}")
    dt = experiment.dt[:, None]
    summary = {"mean_gyro_correction_degph": (np.mean(experiment.dtheta / dt - omega, axis=0) * RS_TO_DH).tolist(),
               "mean_accel_correction_ug": (np.mean(experiment.dv / dt - f, axis=0) * MPS2_TO_UG).tolist()}
    return corrected, prov, summary


def write_corrected(experiment, path, provenance):
    """Write a corrected experiment atomically, the provenance as root attribute :data:`PROVENANCE_ATTRIBUTE`."""
    path = Path(path)
    with io.atomic_path(path) as tmp:
        io.write_experiment(experiment, tmp)
        with h5py.File(tmp, "a") as f:
            f.attrs[PROVENANCE_ATTRIBUTE] = json.dumps(io.to_json_builtin(provenance))
    return path


def correction_of(path):
    """The provenance of an experiment file's correction (dict), or None for a raw record."""
    try:
        with h5py.File(path, "r") as f:
            value = f.attrs.get(PROVENANCE_ATTRIBUTE)
    except OSError:
        return None
    if value is None:
        return None
    if isinstance(value, bytes):
        value = value.decode("utf-8", errors="replace")
    try:
        return json.loads(str(value))
    except ValueError:
        return {"text": str(value)}


__all__ = ["PROVENANCE_ATTRIBUTE", "read_compensation", "superseded", "verdict_failed", "without_unresolved", "apply", "note_of", "write_corrected", "correction_of"]
