"""Behaviour check for reshaping the code: a fixed set of runs, recorded once and compared after a change.

Usage (from the project root, with the project's virtual environment)::

    .venv/bin/python scripts/behaviour_check.py record --out /tmp/before [--code DIR]
    .venv/bin/python scripts/behaviour_check.py record --out /tmp/after
    .venv/bin/python scripts/behaviour_check.py compare /tmp/before /tmp/after

``record`` runs the command line (``python -m graph_calib.cli``) of the checkout at ``--code`` (default:
this one) on:

1. ``calibrate`` of the 1.5 h ``nav-subrange`` (seed 1), both solvers;
2. ``calibrate`` of the measured MPU-6050 session (``../shared/data/real``), consumer grade, both solvers;
3. ``diagnose`` of ``effect-accel.bias_dtdt`` (seed 2), a record with a further effect the declared model lacks;
4. ``campaign`` of a short ``nav-campaign`` (six 0.3 h subranges, seed 3), in-process (``--workers 0``).

``compare`` checks every result file (``estimates``: value and sigma) to 1e-9 relative, and the effects the
diagnosis added, and exits 1 on any difference, listing it.  Whatever the check finds is printed; nothing
is loosened by it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real"
RTOL = 1e-9


def _runs(out):
    mpu_csv = REAL / "mpu6050_uncuyo" / "example_data_calibration.csv"
    return [
        ("simulate nav-subrange", ["simulate", "nav-subrange", "--seed", "1", "--out", f"{out}/sim_nav"]),
        ("calibrate nav-subrange", ["calibrate", f"{out}/sim_nav/sub1_20_30.h5", "--out", f"{out}/cal_nav"]),
        ("import mpu6050", ["import", "mpu6050", str(mpu_csv), "--out", f"{out}/mpu6050.h5"]),
        ("calibrate mpu6050", ["calibrate", f"{out}/mpu6050.h5", "--grade", "consumer", "--out", f"{out}/cal_mpu"]),
        ("simulate effect", ["simulate", "effect-accel.bias_dtdt", "--seed", "2", "--out", f"{out}/sim_eff"]),
        ("diagnose effect", ["diagnose", f"{out}/sim_eff/sub1_20_25.h5", "--out", f"{out}/diag"]),
        ("simulate campaign", ["simulate", "nav-campaign", "--hours", "0.3", "--seed", "3", "--out",
                               f"{out}/sim_camp"]),
        ("campaign", ["campaign", f"{out}/sim_camp/campaign.toml", "--out", f"{out}/camp", "--workers", "0",
                      "--quiet"]),
    ]


def record(out, code):
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(Path(code).resolve()))
    timings = {}
    for label, argv in _runs(out):
        if label.startswith("calibrate nav") or label.startswith("diagnose"):
            # the simulated file names depend on the scenario; take the one experiment written
            folder = Path(argv[1]).parent
            h5 = sorted(folder.glob("*.h5"))
            argv = [argv[0], str(h5[0]), *argv[2:]]
        t0 = time.monotonic()
        proc = subprocess.run([sys.executable, "-m", "graph_calib.cli", *argv], env=env, cwd=out,
                              capture_output=True, text=True)
        timings[label] = time.monotonic() - t0
        (out / f"{label.replace(' ', '_')}.log").write_text(proc.stdout + proc.stderr)
        print(f"{label}: exit {proc.returncode}, {timings[label]:.1f} s", flush=True)
        if proc.returncode not in (0, 3):
            print(proc.stdout[-2000:], proc.stderr[-4000:], sep="\n")
            return 1
    (out / "timings.json").write_text(json.dumps(timings, indent=1))
    return 0


def _results(folder):
    found = {}
    for p in sorted(Path(folder).rglob("*.json")):
        rel = p.relative_to(folder).as_posix()
        if rel.startswith("sim_"):
            continue                        # simulated truths are inputs, not outputs
        try:
            doc = json.loads(p.read_text())
        except (OSError, ValueError):
            continue
        found[rel] = doc
    return found


def _close(a, b):
    if a is None or b is None:
        return a is None and b is None
    return abs(a - b) <= RTOL * max(abs(a), abs(b)) or a == b


def compare(before, after):
    old, new = _results(before), _results(after)
    problems, checked = [], 0
    for rel, doc in old.items():
        if "estimates" not in doc and "added" not in doc:
            continue
        if rel not in new:
            problems.append(f"{rel}: missing after the change")
            continue
        other = new[rel]
        if "added" in doc and doc.get("added") != other.get("added"):
            problems.append(f"{rel}: added {doc.get('added')} before, {other.get('added')} after")
        est_a, est_b = doc.get("estimates", {}), other.get("estimates", {})
        if set(est_a) != set(est_b):
            problems.append(f"{rel}: parameters differ: {sorted(set(est_a) ^ set(est_b))}")
        for name in sorted(set(est_a) & set(est_b)):
            for key in ("value", "sigma"):
                va, vb = est_a[name].get(key), est_b[name].get(key)
                checked += 1
                if not _close(va, vb):
                    problems.append(f"{rel}: {name}.{key} {va!r} -> {vb!r}")
    print(f"{len(old)} files, {checked} numbers compared at {RTOL:g} relative")
    for p in problems[:200]:
        print("  DIFFERENT", p)
    if problems:
        print(f"{len(problems)} difference(s)")
        return 1
    print("same behaviour")
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("--out", required=True)
    r.add_argument("--code", default=str(ROOT), help="checkout whose graph_calib is run (default: this one)")
    c = sub.add_parser("compare")
    c.add_argument("before")
    c.add_argument("after")
    args = parser.parse_args(argv)
    if args.cmd == "record":
        return record(args.out, args.code)
    return compare(args.before, args.after)


if __name__ == "__main__":
    sys.exit(main())
