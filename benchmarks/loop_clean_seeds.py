"""How often the campaign's loop adds an effect to clean data: 20 seeds of a short linear-truth subrange.

Run by hand::

    PYTHONPATH=. .venv/bin/python benchmarks/loop_clean_seeds.py [--seeds 20] [--hours 0.3] [--rate 100]

Each seed simulates ``nav-subrange-short`` (18 min at 100 Hz, sensors drifting 5 degC) with exactly linear
temperature curves (``curvature=False``) and no further effect, and runs the campaign's loop on it
(:func:`graph_calib.diagnosis.diagnose` with :func:`graph_calib.campaign.loop.loop_options`; its decisions use
the factor graph only, so the filter is left out).  Done means (issue 11): the loop adds nothing in at least
95 % of the subranges.  ``tests/test_loop_clean.py`` runs three seeds; docs/campaign.md records this count.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np
from _report import report

from graph_calib.campaign import CampaignOptions, calibration_options
from graph_calib.campaign.loop import loop_options
from graph_calib.diagnosis import diagnose
from graph_calib.io import Campaign
from graph_calib.simulation import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--hours", type=float, default=0.3)
    ap.add_argument("--rate", type=float, default=100.0)
    args = ap.parse_args(argv)
    campaign = Campaign(path=None, imu_id="SIM-NAV 0001", grade="navigation", experiments=())
    dopts = replace(loop_options(campaign, CampaignOptions(), ("factor-graph",)), solvers=("factor-graph",))
    copts = calibration_options(campaign)
    clean = 0
    t0 = time.perf_counter()
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        sim = simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=args.hours, rate_hz=args.rate,
                       curvature=False)
        d = diagnose(sim.plans[0].run().experiment, options=copts, diagnosis=dopts)
        clean += not d.added
        best = min((c for r in d.rounds for c in r.candidates if not c.skipped), key=lambda c: c.log10_p, default=None)
        print(f"seed {seed}: added {', '.join(d.added) or 'nothing'}"
              + (f" (most significant candidate {best.name}: {best.statistic:.1f} vs {best.threshold:.1f})"
                 if best else ""), flush=True)
    share = clean / args.seeds
    print(f"the loop added nothing in {clean} of {args.seeds} clean subranges ({100 * share:.0f} %, target >= 95 %); "
          f"{time.perf_counter() - t0:.0f} s")
    report("clean_share", share, "", "share of clean subranges where the loop adds nothing")
    return 0 if share >= 0.95 else 1


if __name__ == "__main__":
    sys.exit(main())
