"""The closed loop's cost in a campaign: one experiment without and with the loop, back to back, alternating.

Run by hand (minutes per run; not part of ``make bench``)::

    PYTHONPATH=. .venv/bin/python benchmarks/campaign_loop_pair.py [--data /tmp/loop-full/data]
        [--experiment sub5_30_40] [--pairs 2] [--out /tmp/loop-pair] [--loop-only] [--job-only]

``--data`` is the simulation of ``benchmarks/campaign_loop_full.py`` (6 x 3 h ``nav-campaign``, seed 11,
``cubic_scale = 2``; that script writes it).  A one-experiment manifest of ``--experiment`` (its truth file
beside it) is run through :func:`graph_calib.campaign.run_campaign` in this process (``workers=0``: no Dask,
so the ratio is the loop's, not the cluster's), from a cold result cache, without the loop
(``diagnose=False``) and with it, ``--pairs`` times, the order alternating (without-with, with-without, ...)
so that a change in the machine's load falls on both.  Per run: wall time of the whole call (tasks, joint
solve, report), CPU time of this process, the tasks' wall time (``campaign.json`` ``timing.tasks_seconds``),
the tasks' CPU time, the loop's own seconds and rounds (``diagnosis.json``), what it added, and the load averages before and
after (2 cores shared with other work: the CPU time is the steadier figure).  Issue 11's target: the campaign
with the loop within twice the time of the campaign without it.  docs/performance.md records the figures.
The same script measures another checkout with ``PYTHONPATH=OTHER``.  ``--job-only``: the per-experiment solvers
alone and no report (no joint solve, no ``report.html``), so that the process's time is mostly the experiment's
own job (with ``--loop-only --pairs 1``: the one-job benchmark of docs/performance.md).  A campaign's Dask worker
runs BLAS on one thread (Dask's nanny sets ``OPENBLAS_NUM_THREADS=1``); this process does so only when its
environment says so: set ``OPENBLAS_NUM_THREADS=1`` to time what a worker does.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import tomllib
from pathlib import Path

from _report import report

import graph_calib
from graph_calib.campaign import CampaignOptions, execution, run_campaign

_TASK_CPU = [0.0]


def _timed_run_tasks(run_tasks):
    """``run_tasks`` adding its CPU time (this process: ``workers=0``) to ``_TASK_CPU``."""
    def timed(tasks):
        c0 = time.process_time()
        try:
            return run_tasks(tasks)
        finally:
            _TASK_CPU[0] += time.process_time() - c0
    return timed


execution.run_tasks = _timed_run_tasks(execution.run_tasks)


def _manifest(data, experiment, out):
    """A manifest of ``experiment`` alone (the ``[imu]`` of ``data``'s), its files linked beside it."""
    folder = out / "data"
    folder.mkdir(parents=True, exist_ok=True)
    src = tomllib.loads((data / "campaign.toml").read_text())
    for suffix in (".h5", ".truth.json"):
        link = folder / f"{experiment}{suffix}"
        if not link.exists():
            link.symlink_to((data / f"{experiment}{suffix}").resolve())
    imu = "\n".join(f"{k} = {json.dumps(v)}" for k, v in src["imu"].items())
    toml = folder / "campaign.toml"
    toml.write_text(f"[imu]\n{imu}\n\n[[experiment]]\nfile = \"{experiment}.h5\"\n")
    return toml


def _run(toml, out, *, diagnose, job_only=False):
    load0 = os.getloadavg()
    _TASK_CPU[0] = 0.0
    w0, c0 = time.perf_counter(), time.process_time()
    extra = dict(solvers="per-subrange", report=False) if job_only else {}
    run = run_campaign(toml, out, options=CampaignOptions(workers=0, diagnose=diagnose, force=True, progress=False,
                                                          **extra))
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    row = {"loop": diagnose, "wall_s": wall, "cpu_s": cpu, "tasks_s": run.document["timing"]["tasks_seconds"],
           "tasks_cpu_s": _TASK_CPU[0],
           "load_before": load0, "load_after": os.getloadavg(), "at": time.strftime("%H:%M:%S", time.gmtime())}
    diag = next(out.glob("*/diagnosis.json"), None)
    if diagnose and diag is not None:
        d = json.loads(diag.read_text())
        row.update(loop_s=d["seconds"], rounds_s=[r.get("seconds") for r in d["rounds"]],
                   added=[a if isinstance(a, str) else a.get("effect") for a in d["added"]])
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/tmp/loop-full/data")
    ap.add_argument("--experiment", default="sub5_30_40")
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--out", default="/tmp/loop-pair")
    ap.add_argument("--loop-only", action="store_true", help="only the runs with the loop (another checkout's)")
    ap.add_argument("--job-only", action="store_true", help="per-experiment solvers only, no report")
    args = ap.parse_args(argv)
    data, out = Path(args.data), Path(args.out)
    if not (data / f"{args.experiment}.h5").is_file():
        print(f"{data / (args.experiment + '.h5')} is missing: run benchmarks/campaign_loop_full.py first "
              f"(it simulates the data)", file=sys.stderr)
        return 2
    toml = _manifest(data, args.experiment, out)
    print(f"code: {Path(graph_calib.__file__).parent}", flush=True)
    rows = []
    for i in range(args.pairs):
        order = (False, True) if i % 2 == 0 else (True, False)
        for diagnose in ((True,) if args.loop_only else order):
            row = _run(toml, out / f"run{i}-{'loop' if diagnose else 'plain'}", diagnose=diagnose,
                       job_only=args.job_only)
            rows.append(row)
            extra = (f", loop {row['loop_s']:.1f} s (rounds {', '.join(f'{s:.1f}' for s in row['rounds_s'])}), "
                     f"added {row['added']}") if diagnose and "loop_s" in row else ""
            print(f"{row['at']} {'with' if diagnose else 'without':7s} the loop: wall {row['wall_s']:.1f} s, "
                  f"cpu {row['cpu_s']:.1f} s, tasks {row['tasks_s']:.1f} s (cpu {row['tasks_cpu_s']:.1f} s){extra}; load "
                  f"{row['load_before'][0]:.1f} -> {row['load_after'][0]:.1f}", flush=True)
    (out / "pairs.json").write_text(json.dumps({"rows": rows}, indent=1))
    if args.loop_only:
        return 0
    ratios = {}
    for key in ("wall_s", "cpu_s", "tasks_s", "tasks_cpu_s"):
        plain = sum(r[key] for r in rows if not r["loop"])
        loop = sum(r[key] for r in rows if r["loop"])
        ratios[key] = loop / plain
    print(f"with / without the loop over {args.pairs} pair(s): wall x{ratios['wall_s']:.2f}, "
          f"cpu x{ratios['cpu_s']:.2f}, tasks x{ratios['tasks_s']:.2f} (cpu x{ratios['tasks_cpu_s']:.2f}) (target <= 2)")
    (out / "pairs.json").write_text(json.dumps({"rows": rows, "ratios": ratios}, indent=1))
    report("loop_ratio_wall", ratios["wall_s"], "", f"{args.experiment}: campaign wall time with / without the loop")
    report("loop_ratio_cpu", ratios["cpu_s"], "", f"{args.experiment}: campaign CPU time with / without the loop")
    return 0


if __name__ == "__main__":
    sys.exit(main())
