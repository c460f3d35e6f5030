"""A campaign's options and its tasks: what one task is, its cache key, whether it is cached.

- :class:`CampaignOptions`: how a campaign runs (what it computes comes from the manifest);
- :class:`Task`: one experiment calibrated by one solver, and the files it writes;
- :func:`calibration_options`: the :class:`graph_calib.options.CalibrationOptions` a manifest asks for;
- :func:`file_sha256`, :func:`options_sha256`, :func:`task_key`: a task's cache key (SHA-256 over the
  experiment file's content, the calibration options, the solver, the package version and
  :data:`CACHE_VERSION`);
- :func:`cached`: whether a task's files are on disk with its key.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from graph_calib import __version__
from graph_calib.diagnosis import DiagnosisOptions
from graph_calib.errors import InputError
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions, FilterOptions, GraphOptions
from graph_calib.solvers import registry

#: Bumped when a change of the code invalidates cached results (2: the loop's record holds its final round's
#: candidate statistics, which the pooled score test sums; 3: a model holding a curve's order holds the orders
#: below it, ``sensors.effects.with_lower_orders``).
CACHE_VERSION = 3


def solver_choice(choice):
    """``(per-experiment solvers, campaign solvers)`` a :attr:`CampaignOptions.solvers` (or ``[solver] solvers``)
    value stands for (:func:`graph_calib.solvers.registry.parse_choice`): by default ("both") the registry's
    default solvers and every campaign solver (the joint one); "per-subrange" leaves the campaign solvers out.

    Raises
    ------
    InputError
        Naming ``--solver`` when the value is not one the registry accepts.
    """
    try:
        return registry.parse_choice(choice, campaign=True)
    except ValueError as exc:
        raise InputError(str(exc), dataset="--solver") from None


@dataclass(frozen=True)
class CampaignOptions:
    """How a campaign runs (what it computes comes from the manifest).

    Attributes
    ----------
    workers : int or None
        Dask worker processes of the local cluster (one thread each); None: as many
        as CPU cores, at most the number of tasks; 0: no Dask, tasks run one after
        the other in this process.
    scheduler : str or None
        Address of an existing Dask scheduler (``tcp://host:8786``); its workers must
        see the output folder.  Overrides ``workers``.
    solvers : str or None
        ``"both"`` (the default per-experiment solvers and every campaign solver), ``"per-subrange"`` (the
        default solvers alone), or registered solver names joined by ``+`` (:func:`solver_choice`); None: the
        manifest's ``[solver] solvers``, else both.
    stitch_model : str
        ``"cubic"`` or ``"linear"``: the stitched model that validation uses.
    validate : tuple of str
        Independent experiment files for validation.  A ``<stem>.truth.json`` next
        to one is its reference; otherwise it is calibrated (the primary solver) as an
        extra task and its own estimate is the reference.
    diagnose : bool or None
        The closed loop on every experiment (:mod:`graph_calib.campaign.loop`): True, False, or None for
        the manifest's ``[solver] diagnose`` (default on).
    force : bool
        Ignore cached results.
    report : bool
        Write ``report.html``.
    progress : bool
        Show a progress bar (stderr).
    """

    workers: int | None = None
    scheduler: str | None = None
    solvers: str | None = None
    stitch_model: str = "cubic"
    validate: tuple[str, ...] = ()
    diagnose: bool | None = None
    force: bool = False
    report: bool = True
    progress: bool = True


@dataclass(frozen=True)
class Task:
    """One experiment, one solver (picklable; run on a worker with its experiment's other solvers).

    Attributes
    ----------
    name : str
        The experiment's name (its folder under the output folder), or ``validation/<stem>``.
    file : str
        The experiment file.
    solver : str
    options : CalibrationOptions
    out_dir : str
        Where its files go (``result_path``, ``residuals_path``, ``summary_path``).
    key : str
        Its cache key (:func:`task_key`), stored in its result file.
    input_sha256, options_sha256 : str
        The two hashes the key is made of.
    numba_threads : int
        Threads for numba's parallel kernels on the worker; 0: leave numba's default.
    diagnosis : graph_calib.diagnosis.DiagnosisOptions or None
        The closed loop's options (its repr is part of ``options_sha256``); None: the declared model only.
    wave : int
        0 for the experiment's own loop; ``k >= 1`` for the ``k``-th wave of the campaign's pooled score test
        (:mod:`graph_calib.campaign.waves`): the experiment solved again with the effects pooled so far
        (``options`` hold them), warm-started from the results in ``start_dir``; its files go to
        ``<experiment>/pooled/<k>/`` and its key covers the starting results' key.
    start_dir : str or None
        Where the results a wave starts from are (the previous wave's folder, or the experiment's).
    pooled : tuple of str
        The effects the campaign's waves adopted in this experiment so far, in order (the last ones this wave's).
    wave_effects : tuple of str
        The effects this wave adds (empty: the last of ``pooled``, one effect a wave as the pooled test adopts);
        a wave carrying the joint curve's curvature adds several at once
        (:mod:`graph_calib.campaign.curvature_wave`).
    """

    name: str
    file: str
    solver: str
    options: CalibrationOptions
    out_dir: str
    key: str
    input_sha256: str
    options_sha256: str
    numba_threads: int = 0
    diagnosis: DiagnosisOptions | None = None
    wave: int = 0
    start_dir: str | None = None
    pooled: tuple[str, ...] = ()
    wave_effects: tuple[str, ...] = ()

    @property
    def added_by_wave(self):
        """The effects this wave adds (``wave_effects``, else the last one of ``pooled``)."""
        return tuple(self.wave_effects) or tuple(self.pooled[-1:])

    @property
    def result_path(self):
        return Path(self.out_dir) / f"{self.solver}.json"

    @property
    def residuals_path(self):
        return Path(self.out_dir) / f"{self.solver}.residuals.h5"

    @property
    def summary_path(self):
        return Path(self.out_dir) / "summary.json"


def calibration_options(campaign, *, t_ref_degC=None):
    """The :class:`graph_calib.options.CalibrationOptions` a manifest asks for.

    ``[imu] grade``, ``[priors]``, ``[model] effects / exclude``,
    ``[solver] keyframe_s / max_iterations`` (the latter for both solvers: LM
    iterations and filter passes), and the experiment's ``t_ref_degC``.  (``[solver] diagnose``
    is the loop's switch, :func:`graph_calib.campaign.loop.loop_options`.)
    """
    s = campaign.solver
    mopt = ModelOptions(
        keyframe_s=float(s.get("keyframe_s", ModelOptions.keyframe_s)), grade=campaign.grade,
        extra_effects=tuple(campaign.effects), exclude=tuple(campaign.exclude),
        prior_sigma=dict(sorted(campaign.priors.items())) or None,
    )
    gopt = GraphOptions(max_iterations=int(s["max_iterations"])) if "max_iterations" in s else GraphOptions()
    kw = {"filter": FilterOptions(max_passes=int(s["max_iterations"]))} if "max_iterations" in s else {}
    return CalibrationOptions(model=mopt, graph=gopt, t_ref_degC=t_ref_degC, **kw)


def file_sha256(path, *, chunk=1 << 22):
    """SHA-256 (hex) of a file's content."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(chunk), b""):
            h.update(block)
    return h.hexdigest()


def options_sha256(options, diagnosis=None):
    """SHA-256 (hex) of calibration options and, with the loop, its options (reprs of frozen dataclasses)."""
    text = repr(options) if diagnosis is None else f"{options!r}|loop|{diagnosis!r}"
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def task_key(*, input_sha256, options_sha256, solver):
    """The cache key of one task."""
    text = f"graph-calib {__version__} cache {CACHE_VERSION}|{solver}|{input_sha256}|{options_sha256}"
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def cached(task):
    """Whether ``task``'s files are on disk with its key."""
    if not (task.result_path.is_file() and task.residuals_path.is_file() and task.summary_path.is_file()):
        return False
    try:
        doc = json.loads(task.result_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and isinstance(doc.get("campaign"), dict) and doc["campaign"].get("key") == task.key


__all__ = ["CACHE_VERSION", "solver_choice", "CampaignOptions", "Task", "calibration_options", "file_sha256",
           "options_sha256", "task_key", "cached"]
