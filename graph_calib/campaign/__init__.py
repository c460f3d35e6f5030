r"""A calibration campaign: every experiment with both solvers, in parallel, cached, stitched, validated.

This is the public Python API behind ``graph-calib campaign``::

    from graph_calib.campaign import CampaignOptions, run_campaign
    run = run_campaign("campaign.toml", "out", options=CampaignOptions(workers=2))
    run.stitched[run.document["primary_solver"]].curves["gyro.bias.x"].evaluate([25.0])

Work and files
--------------
One *task* is one experiment calibrated by one solver; the tasks of one
experiment run together as one job (the problem is set up once for both
solvers).  Jobs run on Dask
workers (a local cluster of processes with one thread each, sized for the
machine, or an existing cluster given by its scheduler address; workers must
see the output folder) or, with ``workers=0``, one after the other in this
process.  A task writes, into ``OUT/<experiment name>/``, each file atomically:

- ``summary.json``: the experiment's length, reference temperature, sensor
  temperature ranges and a thinned temperature series;
- ``<solver>.residuals.h5``: the solver's whitened residuals (factor graph) or
  normalised innovations (filter) per measurement kind, for the residual plots:
  the residual-series file of ``docs/data-format.md``, the one ``graph-calib
  calibrate --residuals`` writes (:func:`graph_calib.io.write_residuals`);
- ``<solver>.json``: the result (``data-format.md``), written last; its
  top-level ``campaign`` object holds the task's cache key.

The main process then writes ``comparison.json`` per experiment, stitches every
solver's results over temperature (:mod:`graph_calib.stitching`), validates the
stitched calibration on independent records (:mod:`graph_calib.evaluation.validation`), and
writes ``campaign.json`` and ``report.html``.

Caching and resuming
--------------------
The cache key of a task is a SHA-256 over the experiment file's content, the
calibration options (repr of :class:`graph_calib.options.CalibrationOptions`,
reference temperature included), the solver, the package version and
:data:`CACHE_VERSION`.  A task
whose result file carries the same key (and whose residual and summary files
exist) is not run again.  So an interrupted campaign resumes where it stopped
(finished tasks are on disk, a task cut short left nothing, thanks to the
atomic writes) and a rerun does only what changed.

Modules, one job each
---------------------
- :mod:`graph_calib.campaign.tasks`: :class:`CampaignOptions`, :class:`Task`,
  :func:`calibration_options`, the hashes and the cache key, :func:`cached`;
- :mod:`graph_calib.campaign.planning`: the checks before any work starts (output
  folder, validation records, experiment headers) and :func:`plan`, every task
  to compute or cached (:func:`~graph_calib.campaign.planning.plan_campaign`);
- :mod:`graph_calib.campaign.execution`: :func:`run_tasks` (one job, what a worker
  runs) and :func:`execute` (in this process, on a local Dask cluster or on an
  existing scheduler; the progress display);
- :mod:`graph_calib.campaign.truth`: :func:`truth_path`, :func:`truth_check`;
- :mod:`graph_calib.campaign.loop`: the closed loop's options and record per experiment;
  :mod:`graph_calib.campaign.pooled`: the pooled score tests across the experiments (the rule);
  :mod:`graph_calib.campaign.waves`: their waves of re-solves (cached like the first);
- :mod:`graph_calib.campaign.run`: :func:`run_campaign`, a short sequence of
  phases (read and plan, compute, collect, stitch, truth check, validate,
  document and report), and :class:`CampaignRun`.

Their public names are re-exported here.
"""

from graph_calib.campaign.execution import execute, experiment_summary, run_tasks
from graph_calib.campaign.planning import check_experiment_header, plan
from graph_calib.campaign.run import CAMPAIGN_FORMAT, CAMPAIGN_VERSION, CampaignRun, run_campaign
from graph_calib.campaign.tasks import (
    CACHE_VERSION, CampaignOptions, Task, cached, calibration_options, file_sha256, options_sha256, task_key,
)
from graph_calib.campaign.truth import truth_check, truth_path

__all__ = ["CAMPAIGN_FORMAT", "CAMPAIGN_VERSION", "CACHE_VERSION", "CampaignOptions", "CampaignRun", "Task",
           "calibration_options", "file_sha256", "options_sha256", "task_key", "cached", "plan", "run_tasks",
           "execute", "run_campaign", "truth_check", "truth_path", "experiment_summary", "check_experiment_header"]
