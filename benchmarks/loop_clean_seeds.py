"""How often the campaign's loop adds an effect to clean data: 20 seeds of linear-truth subranges or campaigns.

Run by hand::

    PYTHONPATH=. .venv/bin/python benchmarks/loop_clean_seeds.py [--seeds 20] [--hours 0.3] [--rate 100]
    PYTHONPATH=. .venv/bin/python benchmarks/loop_clean_seeds.py --campaigns [--seeds 20] [--hours 0.2] [--rate 50]

Without ``--campaigns`` each seed simulates ``nav-subrange-short`` (18 min at 100 Hz, sensors drifting 5 degC)
with exactly linear temperature curves (``curvature=False``) and no further effect, and runs the campaign's loop
on it (:func:`graph_calib.diagnosis.diagnose` with :func:`graph_calib.campaign.loop.loop_options`; its decisions
use the factor graph only, so the filter is left out).

With ``--campaigns`` each seed simulates a whole linear-truth ``nav-campaign`` (six subranges over -10..50 degC,
``--hours`` each) and runs it through :func:`graph_calib.campaign.run_campaign` with the loop (factor graph only,
in this process): every experiment's own loop, then the campaign's pooled score tests
(:mod:`graph_calib.campaign.pooled`) and any wave they start.  A subrange counts as clean when neither its own
loop nor the pooled test added anything to it.

Done means (issue 11): the loop adds nothing in at least 95 % of the subranges.  ``tests/diagnosis/test_loop_clean.py``
runs three single subranges, ``tests/campaign/test_campaign_pooled.py`` one clean campaign; docs/campaign.md records the
counts.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from _report import report

from graph_calib import io
from graph_calib.campaign import CampaignOptions, calibration_options, run_campaign
from graph_calib.campaign.loop import loop_options
from graph_calib.diagnosis import diagnose
from graph_calib.io import Campaign
from graph_calib.simulation import simulate


def _subranges(args):
    """``(clean subranges, subranges)`` of single linear-truth subranges, one per seed."""
    campaign = Campaign(path=None, imu_id="SIM-NAV 0001", grade="navigation", experiments=())
    dopts = replace(loop_options(campaign, CampaignOptions(), ("factor-graph",)), solvers=("factor-graph",))
    copts = calibration_options(campaign)
    clean = 0
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        sim = simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=args.hours, rate_hz=args.rate,
                       curvature=False)
        d = diagnose(sim.plans[0].run().experiment, options=copts, diagnosis=dopts)
        clean += not d.added
        best = min((c for r in d.rounds for c in r.candidates if not c.skipped), key=lambda c: c.log10_p, default=None)
        print(f"seed {seed}: added {', '.join(d.added) or 'nothing'}"
              + (f" (most significant candidate {best.name}: {best.statistic:.1f} vs {best.threshold:.1f})"
                 if best else ""), flush=True)
    return clean, args.seeds


def _campaigns(args):
    """``(clean subranges, subranges)`` of whole linear-truth campaigns through the loop and the pooled test."""
    clean = total = pooled_adoptions = 0
    margins = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        with tempfile.TemporaryDirectory(prefix="clean-campaign-") as tmp:
            tmp = Path(tmp)
            sim = simulate("nav-campaign", rng=np.random.default_rng(seed), hours=args.hours, rate_hz=args.rate,
                           curvature=False)
            files = []
            for plan in sim.plans:
                se = plan.run()
                io.write_experiment(se.experiment, tmp / se.file_name)
                files.append(se.file_name)
            (tmp / "c.toml").write_text('[imu]\nid = "SIM-NAV 0001"\ngrade = "navigation"\n'
                                        + "".join(f'\n[[experiment]]\nfile = "{f}"\n' for f in files))
            run = run_campaign(tmp / "c.toml", tmp / "out", options=CampaignOptions(
                workers=0, progress=False, report=False, solvers="factor-graph"))
        doc = run.document
        changed = {c["name"]: c["added"] + c["pooled"] for c in doc["loop"]["changed"]}
        n = len(doc["experiments"])
        total += n
        clean += n - len(changed)
        waves = doc["loop"]["pooled"]["waves"]
        pooled_adoptions += sum(w["adopted"] is not None for w in waves)
        best = waves[0]["tests"][0] if waves[0]["tests"] else None
        if best:
            margins.append(best["threshold"] / max(best["statistic"], 1e-9))
        print(f"seed {seed}: {n - len(changed)} of {n} subranges clean"
              + (f"; changed {changed}" if changed else "")
              + (f"; pooled: {waves[0]['decision']}" if best else ""), flush=True)
    print(f"pooled adoptions: {pooled_adoptions} in {args.seeds} campaigns; the most significant pooled test's "
          f"threshold over its statistic: {min(margins):.2f}..{max(margins):.2f}" if margins else "")
    return clean, total


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--campaigns", action="store_true", help="whole six-subrange campaigns with the pooled test")
    ap.add_argument("--hours", type=float, default=None, help="per subrange (default 0.3; 0.2 with --campaigns)")
    ap.add_argument("--rate", type=float, default=None, help="Hz (default 100; 50 with --campaigns)")
    args = ap.parse_args(argv)
    if args.hours is None:
        args.hours = 0.2 if args.campaigns else 0.3
    if args.rate is None:
        args.rate = 50.0 if args.campaigns else 100.0
    t0 = time.perf_counter()
    clean, total = (_campaigns if args.campaigns else _subranges)(args)
    share = clean / total
    print(f"the loop added nothing in {clean} of {total} clean subranges ({100 * share:.1f} %, target >= 95 %); "
          f"{time.perf_counter() - t0:.0f} s")
    report("clean_share_campaigns" if args.campaigns else "clean_share", share, "",
           "share of clean subranges where the loop adds nothing" + (" (campaigns, pooled test)" if args.campaigns else ""))
    return 0 if share >= 0.95 else 1


if __name__ == "__main__":
    sys.exit(main())
