"""Run every ``benchmarks/bench_*.py`` and print a table of their headline figures (``make bench``).

    .venv/bin/python benchmarks/run_all.py [--quick] [--only NAME]... [--list]

Each benchmark runs in its own process with this interpreter, from the repository root and with
the repository root first on ``PYTHONPATH`` (so the checkout this script is in is measured, not
another editable install), at its documented sizes; ``--quick`` passes the small sizes of
:data:`QUICK` instead (about a minute, figures not comparable with docs/performance.md).  A
benchmark's human output is passed through; its headline figures are its ``BENCH {...}`` lines
(``benchmarks/_report.py``), gathered into one table: benchmark, what, figure, unit, and the
benchmark's wall time in seconds.  Exit code 0 when every benchmark ran, 1 when one failed.
"""

from __future__ import annotations

import argparse
import ast
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from _report import parse

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

#: Small sizes for ``--quick`` (benchmarks not listed have no size option and run as documented).
QUICK = {
    "campaign": ["--hours", "0.1", "--out", "/tmp/bench-campaign-quick"],
    "experiment": ["--hours", "0.25"],
    "factor_graph": ["--static-s", "600"],
    "kf": ["--hours", "0.25"],
    "preintegration": ["--static-s", "600", "--repeat", "2"],
    "strapdown": ["--samples", "650000", "--repeat", "2"],
}
#: Environment a benchmark is documented with (docs/performance.md).
ENV = {"kf": {"NUMBA_NUM_THREADS": "1"}}


def benchmarks():
    """``{name: path}`` of every ``bench_NAME.py`` beside this script, by name."""
    return {p.stem[len("bench_"):]: p for p in sorted(HERE.glob("bench_*.py"))}


def summary_line(path):
    """First line of a benchmark's docstring (read, not imported)."""
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def _name(text, known):
    name = Path(text).stem if text.endswith(".py") else text
    name = name[len("bench_"):] if name.startswith("bench_") else name
    if name not in known:
        raise ValueError(f"unknown benchmark {text!r}; known: {', '.join(known)}")
    return name


def run_one(name, path, quick):
    """Run one benchmark; (figures, exit code, seconds)."""
    cmd = [sys.executable, str(path), *(QUICK.get(name, []) if quick else [])]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.update(ENV.get(name, {}))
    shown = [f"{k}={v}" for k, v in ENV.get(name, {}).items()] + [os.path.relpath(path, ROOT), *cmd[2:]]
    print(f"== {name}: {' '.join(shown)}", flush=True)
    figures = []
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True, bufsize=1)
    try:
        for line in proc.stdout:
            fig = parse(line)
            if fig is None:
                sys.stdout.write("   " + line)
                sys.stdout.flush()
            else:
                figures.append(fig)
        rc = proc.wait()
    except KeyboardInterrupt:
        proc.terminate()
        proc.wait()
        raise
    return figures, rc, time.perf_counter() - t0


def _value(v):
    if v is None:
        return "-"
    return f"{v:.4g}" if abs(v) < 1e5 else f"{v:.0f}"


def table(rows):
    """Markdown table of ``(benchmark, what, figure, unit, seconds)`` rows."""
    head = ("benchmark", "what", "figure", "unit", "seconds")
    width = [max(len(str(r[i])) for r in (head, *rows)) for i in range(len(head))]
    right = (False, False, True, False, True)

    def line(cells):
        return "| " + " | ".join(str(c).rjust(w) if r else str(c).ljust(w)
                                 for c, w, r in zip(cells, width, right)) + " |"

    sep = "| " + " | ".join("-" * (w - 1) + (":" if r else "-") for w, r in zip(width, right)) + " |"
    return "\n".join([line(head), sep, *(line(r) for r in rows)])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (see QUICK in this file) instead of the "
                    "documented ones")
    ap.add_argument("--only", action="append", default=[], metavar="NAME",
                    help="run only this benchmark (repeatable; NAME as in --list, bench_NAME or bench_NAME.py)")
    ap.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    args = ap.parse_args(argv)

    known = benchmarks()
    if args.list:
        width = max(len(n) for n in known)
        for name, path in known.items():
            quick = " ".join(QUICK.get(name, [])) or "(no size option)"
            print(f"{name:<{width}}  {summary_line(path)}\n{'':<{width}}  --quick: {quick}")
        return 0
    try:
        names = list(dict.fromkeys(_name(n, known) for n in args.only)) if args.only else list(known)
    except ValueError as exc:
        ap.error(str(exc))

    print(f"{len(names)} benchmark(s), {'quick' if args.quick else 'documented'} sizes; "
          f"{platform.machine()} {platform.processor() or ''}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, load average {os.getloadavg()[0]:.1f}", flush=True)
    rows, failed = [], []
    t0 = time.perf_counter()
    try:
        for name in names:
            figures, rc, seconds = run_one(name, known[name], args.quick)
            for i, f in enumerate(figures):
                rows.append((name, f.get("what", f["key"]), _value(f.get("value")), f.get("unit", ""),
                             f"{seconds:.1f}" if i == 0 else ""))
            if rc != 0 or not figures:
                failed.append(name)
                rows.append((name, f"FAILED (exit code {rc})" if rc else "no figures reported", "-", "",
                             "" if figures else f"{seconds:.1f}"))
    except KeyboardInterrupt:
        print("\ninterrupted; figures so far:", file=sys.stderr)
        print(table(rows) if rows else "(none)")
        return 130
    print()
    print(f"summary ({'quick' if args.quick else 'documented'} sizes, {time.perf_counter() - t0:.0f} s in all):")
    print(table(rows))
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
