"""Planning a campaign: the checks before any work starts and every task with its cache key.

- :func:`plan_campaign`: the whole plan of a read manifest (a :class:`CampaignPlan`): the output folder
  checked and created, the validation records and the experiment headers checked, stale temporary files
  of killed workers removed, every task listed as to compute or cached;
- :func:`plan`: the experiments' tasks, ``(to compute, cached)``;
- :func:`check_experiment_header`: the cheap check that a file is an experiment file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from graph_calib import io
from graph_calib.campaign.tasks import (
    Task, cached, calibration_options, file_sha256, options_sha256, solver_choice, task_key,
)
from graph_calib.campaign.loop import loop_options
from graph_calib.campaign.truth import truth_path
from graph_calib.errors import InputError
from graph_calib.solvers import registry


@dataclass(frozen=True)
class CampaignPlan:
    """What a campaign will do, checked before any work starts (:func:`plan_campaign`).

    Attributes
    ----------
    campaign : graph_calib.io.Campaign
        The manifest.
    out : Path
        The output folder (it exists).
    solvers : tuple of str
    records : tuple of Path
        The validation records (resolved).
    todo, done : tuple of Task
        The experiments' tasks to compute and those cached.
    validation_todo, validation_done : tuple of Task
        The same for the validation records without a truth file (factor graph only).
    references : dict
        ``{record: (kind, path)}``: ``("truth", its truth file)`` or ``("estimate", its factor-graph result)``.
    campaign_solvers : tuple of str
        The campaign solvers that run (:func:`graph_calib.campaign.tasks.solver_choice`).
    """

    campaign: io.Campaign
    out: Path
    solvers: tuple[str, ...]
    records: tuple[Path, ...]
    todo: tuple[Task, ...]
    done: tuple[Task, ...]
    validation_todo: tuple[Task, ...]
    validation_done: tuple[Task, ...]
    references: dict[Path, tuple[str, Path]]
    campaign_solvers: tuple[str, ...] = ()

    @property
    def to_compute(self):
        """Every task to compute: the experiments', then the validation records'."""
        return list(self.todo + self.validation_todo)

    @property
    def from_cache(self):
        """Every cached task: the experiments', then the validation records'."""
        return list(self.done + self.validation_done)


def plan_campaign(campaign, out, *, options):
    """Check a campaign's inputs and list its tasks, before any work starts.

    Parameters
    ----------
    campaign : graph_calib.io.Campaign
    out : str or Path
        Output folder (created).
    options : CampaignOptions

    Returns
    -------
    CampaignPlan

    Raises
    ------
    InputError
        A bad option, an output path that is not a folder, a missing or wrong experiment or validation file.
    """
    if options.stitch_model not in ("cubic", "linear"):
        raise InputError(f"must be 'cubic' or 'linear', got {options.stitch_model!r}", dataset="--stitch")
    out = _check_out(out)
    records = _check_records(options.validate, imu_id=campaign.imu_id,
                             experiments=[e.file for e in campaign.experiments])
    todo, done = plan(campaign, out, options=options)
    vtodo, vdone, refs = _validation_tasks(campaign, out, records, options=options)
    _make_out(out)              # only once every file has passed its check: a refusal leaves no empty folder
    return CampaignPlan(campaign=campaign, out=out, solvers=_solvers(campaign, options), records=tuple(records),
                        todo=tuple(todo), done=tuple(done), validation_todo=tuple(vtodo),
                        validation_done=tuple(vdone), references=refs,
                        campaign_solvers=_choice(campaign, options)[1])


def _choice(campaign, options):
    """``(per-experiment solvers, campaign solvers)`` of the option, else the manifest's, else the default."""
    return solver_choice(options.solvers or campaign.solver.get("solvers", registry.BOTH))


def _solvers(campaign, options):
    return _choice(campaign, options)[0]


def _remove_stale_temporaries(folder):
    """Temporary files of writes cut short by a killed worker (``.<name>.*.tmp``)."""
    if not folder.is_dir():
        return
    for p in folder.glob(".*.tmp"):
        try:
            p.unlink()
        except OSError:
            pass


def plan(campaign, out, *, options):
    """Every task of a campaign with its cache key: ``(tasks to run, cached tasks)``."""
    solvers = _solvers(campaign, options)
    loop = loop_options(campaign, options, solvers)
    threads = 1 if (options.scheduler or options.workers != 0) else 0
    todo, done = [], []
    for e in campaign.experiments:
        check_experiment_header(e.file, imu_id=campaign.imu_id)
        copts = calibration_options(campaign, t_ref_degC=e.t_ref_degC)
        osha = options_sha256(copts, loop)
        fsha = file_sha256(e.file)
        folder = Path(out) / e.name
        _remove_stale_temporaries(folder)
        for s in solvers:
            t = Task(name=e.name, file=str(e.file), solver=s, options=copts, out_dir=str(folder),
                     key=task_key(input_sha256=fsha, options_sha256=osha, solver=s), input_sha256=fsha,
                     options_sha256=osha, numba_threads=threads, diagnosis=loop)
            (done if (not options.force and cached(t)) else todo).append(t)
    return todo, done


def _validation_tasks(campaign, out, records, *, options):
    """Tasks calibrating validation records that have no truth file (the registry's primary solver only)."""
    todo, done, refs = [], [], {}
    threads = 1 if (options.scheduler or options.workers != 0) else 0
    for rec in records:
        truth = truth_path(rec)
        if truth.is_file():
            refs[rec] = ("truth", truth)
            continue
        copts = calibration_options(campaign)
        osha = options_sha256(copts)
        fsha = file_sha256(rec)
        folder = Path(out) / "validation" / rec.stem
        _remove_stale_temporaries(folder)
        solver = registry.PRIMARY_SOLVER
        t = Task(name=f"validation/{rec.stem}", file=str(rec), solver=solver, options=copts,
                 out_dir=str(folder), key=task_key(input_sha256=fsha, options_sha256=osha, solver=solver),
                 input_sha256=fsha, options_sha256=osha, numba_threads=threads)
        refs[rec] = ("estimate", t.result_path)
        (done if (not options.force and cached(t)) else todo).append(t)
    return todo, done, refs


def _check_out(out):
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", path=out, dataset="--out")
    return out


def _make_out(out):
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc}", path=out, dataset="--out") from None


def check_experiment_header(path, *, dataset=None, imu_id=None):
    """Cheap check that ``path`` is an experiment file (HDF5 with the right ``format``) of the IMU ``imu_id`` (when
    given, and when the file names its IMU); InputError if not.

    The full validation (every rule of data-format.md) runs where the file is
    read, on the worker; this catches a wrong file before any work starts.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path=path, dataset=dataset)
    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format")
            own = f.attrs.get("imu_id")
    except OSError:
        raise InputError("not an HDF5 file (an experiment file is HDF5, data-format.md)", path=path,
                         dataset=dataset) from None
    if isinstance(fmt, bytes):
        fmt = fmt.decode("utf-8", "replace")
    if isinstance(fmt, np.ndarray) and fmt.size == 1:
        fmt = fmt.item()
    if fmt != io.EXPERIMENT_FORMAT:
        raise InputError(f"not an experiment file: format attribute is {fmt!r}, expected {io.EXPERIMENT_FORMAT!r}",
                         path=path, dataset=dataset)
    own = own.decode("utf-8", "replace") if isinstance(own, bytes) else own
    if imu_id and isinstance(own, str) and own and own != imu_id:
        raise InputError(f"a record of IMU {own!r}; the manifest's [imu].id is {imu_id!r}: a campaign calibrates one "
                         "IMU", path=path, dataset=dataset or "imu_id")


def _check_records(records, *, imu_id, experiments=()):
    paths = []
    own = {Path(e).resolve() for e in experiments}
    for r in records:
        p = Path(r).resolve()
        if not p.is_file():
            raise InputError("validation record not found" if not p.exists() else "not a file", path=p,
                             dataset="--validate")
        if p in own:
            raise InputError("is one of the campaign's experiments: a validation record is one the calibration did "
                             "not use", path=p, dataset="--validate")
        check_experiment_header(p, dataset="--validate", imu_id=imu_id)
        paths.append(p)
    return paths


__all__ = ["CampaignPlan", "plan_campaign", "plan", "check_experiment_header"]
