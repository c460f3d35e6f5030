"""``graph-calib demo --out DIR``: simulate a navigation-grade campaign, then run ``campaign`` and ``diagnose`` on it.

Writes

- ``DIR/data/``: six experiment files over -10..+50 degC (``nav-campaign``, each
  ``--hours`` long), their truth files, ``campaign.toml``, and an independent
  validation record of the same IMU sweeping the whole range
  (``validation.h5`` with its truth);
- ``DIR/campaign/``: what ``graph-calib campaign`` writes (``report.html``,
  ``campaign.json``, one folder per experiment);
- ``DIR/diagnosis/``: what ``graph-calib diagnose`` writes for one experiment.

Everything already made is reused when the demo runs again into the same folder.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError

#: Default length of each subrange experiment, h: short enough for a few minutes on 2 cores.
DEMO_HOURS = 0.4
#: Default length of the validation record, h.
VALIDATION_HOURS = 2.0
#: Sample rate of the validation record, Hz (its 1 s window means are what validation uses).
VALIDATION_RATE_HZ = 50.0


def add_arguments(p):
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--hours", type=float, default=DEMO_HOURS,
                   help=f"length of each of the six subrange experiments, h (default {DEMO_HOURS})")
    p.add_argument("--seed", type=int, default=1, help="random seed of the simulation (default 1)")
    p.add_argument("--workers", type=int, default=None, help="Dask worker processes (default: one per core; "
                   "0: no Dask)")
    p.add_argument("--diagnose", default=None, metavar="NAME",
                   help="experiment to diagnose (default: the one around 20..30 degC)")
    p.add_argument("--no-diagnose", action="store_true", help="skip the diagnosis")


def _say(msg):
    print(msg, file=sys.stderr, flush=True)


def simulate_demo(out, *, hours, seed, validation_hours=VALIDATION_HOURS):
    """Write the demo's campaign and validation record into ``out`` (reused when present); manifest path.

    ``nav-campaign`` with ``hours`` per subrange, and ``validation.h5`` (with its truth): the same IMU
    sweeping -10..+50 degC for ``validation_hours`` at :data:`VALIDATION_RATE_HZ`.
    """
    from graph_calib import io
    from graph_calib.simulation import simulate, write_simulation
    from graph_calib.validation import simulate_validation_record

    out = Path(out)
    manifest = out / "campaign.toml"
    stamp = out / "demo.json"
    want = {"scenario": "nav-campaign", "hours": hours, "seed": seed, "validation_hours": validation_hours,
            "validation_rate_hz": VALIDATION_RATE_HZ}
    sim = simulate("nav-campaign", rng=np.random.default_rng(seed), hours=hours, tag=f"demo, seed {seed}")
    if stamp.is_file() and manifest.is_file() and (out / "validation.h5").is_file():
        import json

        try:
            if json.loads(stamp.read_text(encoding="utf-8")) == want:
                _say(f"reusing the simulated campaign in {out}")
                return manifest
        except ValueError:
            pass
    t0 = time.monotonic()
    write_simulation(sim, out, progress=lambda m: _say("  " + m), tag=f"demo, seed {seed}")
    _say(f"  simulating the validation record ({validation_hours:g} h sweeping -10..+50 degC)")
    se = simulate_validation_record(sim, hours=validation_hours, rate_hz=VALIDATION_RATE_HZ, seed=seed + 1000)
    io.write_experiment(se.experiment, out / "validation.h5")
    io.write_result(se.truth, out / "validation.truth.json")
    io.atomic_write_json(stamp, want)
    _say(f"simulated in {time.monotonic() - t0:.0f} s -> {out}")
    return manifest


def run_diagnosis(experiment_file, out):
    """``graph-calib diagnose EXPERIMENT --out DIR``; its exit code."""
    from graph_calib.cli import main

    return main(["diagnose", str(experiment_file), "--out", str(out)])


def run(args):
    from graph_calib.campaign import CampaignOptions, run_campaign
    from graph_calib.commands.campaign_cmd import print_summary

    if not (np.isfinite(args.hours) and 0 < args.hours <= 24):
        raise InputError(f"must be a number of hours in (0, 24], got {args.hours}", dataset="--hours")
    if args.seed < 0:
        raise InputError(f"must be a non-negative integer, got {args.seed}", dataset="--seed")
    if args.workers is not None and args.workers < 0:
        raise InputError(f"must be 0 or more, got {args.workers}", dataset="--workers")
    out = Path(args.out)
    t0 = time.monotonic()
    _say(f"graph-calib demo: a navigation-grade IMU, six subranges of {args.hours:g} h over -10..+50 degC")
    manifest = simulate_demo(out / "data", hours=args.hours, seed=args.seed)
    options = CampaignOptions(workers=args.workers, validate=(str(out / "data" / "validation.h5"),))
    result = run_campaign(manifest, out / "campaign", options=options)
    print_summary(result)
    rc = 1 if result.failed else 0
    if not args.no_diagnose:
        names = [e["name"] for e in result.document["experiments"]]
        name = args.diagnose or next((n for n in names if "20_30" in n), names[len(names) // 2])
        if name not in names:
            raise InputError(f"no experiment {name!r}; known: {', '.join(names)}", dataset="--diagnose")
        file = next(e["file"] for e in result.document["experiments"] if e["name"] == name)
        _say(f"diagnosing {name} ...")
        drc = run_diagnosis(file, out / "diagnosis")
        if drc != 0:
            print(f"  diagnose: exited with code {drc}")
            rc = rc or 1
        else:
            print(f"  diagnose: -> {out / 'diagnosis'}")
    print(f"demo finished in {time.monotonic() - t0:.0f} s; open {out / 'campaign' / 'report.html'}")
    return rc
