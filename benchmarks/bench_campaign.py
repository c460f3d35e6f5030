"""End-to-end campaign benchmark: six subranges of 3 h at 100 Hz, both solvers, stitching, validation, report.

Run by hand::

    .venv/bin/python benchmarks/bench_campaign.py [--hours 3] [--workers 2] [--out /tmp/bench-campaign]
                                                  [--solvers both|sqrt-kf|factor-graph] [--no-report]

Simulates the ``nav-campaign`` scenario with the demo's code (once; reused from ``--out`` when present), then times
``graph_calib.campaign.run_campaign`` from a cold cache (``force``) with a local Dask cluster, and
samples the resident memory of the whole process tree (this process and the Dask workers) every
0.2 s.  Prints the wall time per stage, the per-task times and the peak memory; docs/performance.md
records what it measured.  Targets: 2 minutes, under 4 GB.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

from _memory import MemoryMonitor
from _report import report


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=3.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", default="/tmp/bench-campaign")
    ap.add_argument("--solvers", default="both", choices=("both", "sqrt-kf", "factor-graph"))
    ap.add_argument("--no-report", action="store_true", help="skip report.html (time the calibration only)")
    args = ap.parse_args(argv)

    from graph_calib.campaign import CampaignOptions, run_campaign
    from graph_calib.commands.demo_cmd import simulate_demo

    out = Path(args.out)
    data = out / "data"
    t0 = time.perf_counter()
    simulate_demo(data, hours=args.hours, seed=args.seed, validation_hours=3.0)
    print(f"simulation ready in {time.perf_counter() - t0:.0f} s")

    opts = CampaignOptions(workers=args.workers, validate=(str(data / "validation.h5"),), force=True,
                           progress=True, solvers=args.solvers, report=not args.no_report)
    t0 = time.perf_counter()
    with MemoryMonitor() as mem:
        run = run_campaign(data / "campaign.toml", out / "campaign", options=opts)
    wall = time.perf_counter() - t0
    doc = run.document
    tim = doc["timing"]
    print()
    print(f"machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}, "
          f"{__import__('os').cpu_count()} cores")
    print(f"campaign, 6 x {args.hours:g} h at 100 Hz, solvers: {args.solvers}, {args.workers} workers:")
    print(f"  end to end      {wall:7.1f} s  (target 120 s)")
    print(f"  tasks (Dask)    {tim['tasks_seconds']:7.1f} s  ({tim['tasks_computed']} computed)")
    print(f"  report          {tim.get('report_seconds', 0.0):7.1f} s")
    print(f"  rest            {wall - tim['tasks_seconds'] - tim.get('report_seconds', 0.0):7.1f} s "
          "(hashing, comparison, stitching, validation)")
    print(f"  peak memory     {mem.peak_total / 2**30:7.2f} GB total (main {mem.peak_main / 2**30:.2f} GB, "
          f"largest worker {mem.peak_child / 2**30:.2f} GB)  (target < 4 GB)")
    per = []
    for e in doc["experiments"]:
        for s, info in e["results"].items():
            per.append((e["name"], s, info.get("seconds")))
    print("  per task (build + solve, on its worker):")
    for name, s, sec in per:
        print(f"    {name:12s} {s:13s} {sec:7.1f} s" if sec is not None else f"    {name:12s} {s:13s}       -")
    report("end_to_end_s", wall, "s", f"campaign 6 x {args.hours:g} h, {args.solvers}, {args.workers} workers")
    report("tasks_s", tim["tasks_seconds"], "s", "calibration tasks (Dask)")
    if not args.no_report:
        report("report_s", tim.get("report_seconds", 0.0), "s", "report.html")
    report("peak_memory_gb", mem.peak_total / 2**30, "GB", "peak memory, all processes")
    if run.failed:
        print("FAILED:", run.failed)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
