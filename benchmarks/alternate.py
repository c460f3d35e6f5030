"""Two whole commands timed in turn (A B A B ...), their medians and the ratio A/B pair by pair.

    .venv/bin/python benchmarks/alternate.py --runs 5 --a 'CMD_A ...' --b 'CMD_B ...'

The machine's speed drifts between sittings (the same command has taken 2.6 s and 3.9 s within an hour here), so a
before/after claim is the ratio of runs taken in turn, not two figures from different times. Each run is one child
process started by this script; its wall time is a monotonic clock around it, its CPU time the operating system's
account of the reaped child and its descendants (``resource.RUSAGE_CHILDREN``: a forked worker or a Dask worker
process included once it has been waited for). Output is discarded; a command that needs a pipe or a redirection is
given as ``sh -c '...'``. The figures in docs/performance.md that compare two checkouts were taken this way, each
command run with ``env PYTHONPATH=CHECKOUT``.

Run it from outside any checkout (``cd /tmp``): ``python -m graph_calib.cli`` puts the working folder first on the
module path, ahead of ``PYTHONPATH``, so from a checkout's own folder both commands run that checkout's code and the
ratio compares it with itself.  The script refuses to start there when a command sets ``PYTHONPATH``.
"""

import argparse
import os
import resource
import shlex
import statistics
import subprocess
import time
from pathlib import Path


def _run(argv):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    rc = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL).returncode
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return rc, wall, cpu


def _line(name, values):
    return f"{name:10s} median {statistics.median(values):9.3f}   min {min(values):9.3f}   max {max(values):9.3f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", required=True, help="command A (one string, split as a shell splits words)")
    ap.add_argument("--b", required=True, help="command B, the baseline")
    ap.add_argument("--runs", type=int, default=5, help="pairs counted (default 5)")
    ap.add_argument("--warmup", type=int, default=1, help="pairs run first and not counted (default 1)")
    args = ap.parse_args(argv)
    a, b = shlex.split(args.a), shlex.split(args.b)
    if (Path(os.getcwd()) / "graph_calib").is_dir() and "PYTHONPATH=" in f"{args.a} {args.b}":
        ap.error("run from outside the checkout (cd /tmp): here `python -m` imports this folder's graph_calib "
                 "whatever PYTHONPATH names, and both commands would run the same code")
    for _ in range(args.warmup):
        _run(a), _run(b)
    rows = {"A": [], "B": []}
    for _ in range(args.runs):
        rows["A"].append(_run(a))
        rows["B"].append(_run(b))
    for name, runs in rows.items():
        print(f"{name}: exit codes {sorted({r[0] for r in runs})}")
        print(_line(f"{name} wall s", [r[1] for r in runs]))
        print(_line(f"{name} cpu s", [r[2] for r in runs]))
    print(_line("A/B wall", [x[1] / y[1] for x, y in zip(rows["A"], rows["B"])]))
    print(_line("A/B cpu", [x[2] / y[2] for x, y in zip(rows["A"], rows["B"])]))


if __name__ == "__main__":
    main()
