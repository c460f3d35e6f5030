"""Regenerate docs/study.md: ``graph-calib compare`` on the study's procedures, soaks and simulated check.

The study is the product's own comparison (``graph-calib compare``, docs/study.md); this script only holds its
arguments.  The predicted part takes about a minute of CPU (its wall time, with the machine's load, is on the
page); the simulated check (10 realisations of the 7 x 0.25 h steps and of the 6 x 0.5 and 1 h ramps, the
campaigns the 0.25 h steps' equal-accuracy ratio is formed from: 190 calibrations with variance components)
about 17 minutes of wall time per realisation at load 11-13 on 2 cores, cached in ``--work`` (resumable: run it in parts by raising ``--realisations`` step by
step)::

    PYTHONPATH=. .venv/bin/python scripts/study_profiles.py [--work /tmp/study-compare] [--realisations 10]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROCEDURES = ("procedure-steps.toml", "procedure-ramp.toml", "procedure-designed.toml")
SOAKS_H = ("1", "1.5", "2.5")
SIMULATE_AT = ("steps:0.25", "ramp:0.5", "ramp:1")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/study-compare", help="cache of the simulated calibrations and output")
    ap.add_argument("--realisations", type=int, default=10)
    args = ap.parse_args(argv)
    from graph_calib.cli import main as cli

    work = Path(args.work)
    return cli(["compare", *(str(Path("data/programs") / p) for p in PROCEDURES), *(a for h in SOAKS_H for a in ("--soak-h", h)),
                "--simulate", str(args.realisations), *(a for s in SIMULATE_AT for a in ("--simulate-at", s)), "--work", str(work / "simulated"),
                "--out", str(work / "out"), "--markdown", "docs/study.md", "--notes", "docs/study-notes.md"])


if __name__ == "__main__":
    sys.exit(main())
