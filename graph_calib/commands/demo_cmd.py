"""``graph-calib demo --out DIR``: simulate a navigation-grade campaign, then run ``campaign`` and ``diagnose`` on it.

Writes

- ``DIR/data/``: six experiment files over -10..+50 degC (``nav-campaign``, each
  ``--hours`` long), their truth files, ``campaign.toml``, and an independent
  validation record of the same IMU sweeping the whole range
  (``validation.h5`` with its truth);
- ``DIR/campaign/``: what ``graph-calib campaign`` writes (``report.html``,
  ``campaign.json``, one folder per experiment);
- ``DIR/campaign/thermal.params``: the campaign's calibration as PX4 thermal-compensation
  parameters (``graph-calib export --format px4``), with what they leave out and its size
  printed;
- ``DIR/data/with_<effect>/``: one experiment of the campaign (default the one
  around 20..30 degC) simulated again, same IMU, programme and noise, with a
  further effect the declared model lacks (``--effect``, default
  ``accel.bias_dtdt``, a bias following the rate of temperature change), and its
  truth; it lasts ``--hours`` but at least :data:`DIAGNOSIS_MIN_HOURS` (a shorter
  record is then a longer run of the same subrange and IMU);
- ``DIR/diagnosis/``: what ``graph-calib diagnose`` writes for that record: the
  closed loop should find the effect and the error against the truth fall; one
  line on stdout says what it added, with its score and the error before and
  after.

Everything already made is reused when the demo runs again into the same folder.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError
from graph_calib.solvers.registry import PRIMARY_SOLVER

#: Default length of each subrange experiment, h: short enough for a few minutes on 2 cores.
DEMO_HOURS = 0.4
#: Default length of the validation record, h.
VALIDATION_HOURS = 2.0
#: Sample rate of the validation record, Hz (its 1 s window means are what validation uses).
VALIDATION_RATE_HZ = 50.0
#: Further effect planted in the record the demo diagnoses (its simulated size: graph_calib.sensors.effects).
DIAGNOSIS_EFFECT = "accel.bias_dtdt"
#: Shortest diagnosed record, h: with seed 1 accel.bias_dtdt scores 252 (threshold 17) at 0.2 h, 30 at 0.1 h
#: and is not seen at 0.05 h (too little change of the temperature rate).
DIAGNOSIS_MIN_HOURS = 0.2


def add_arguments(p):
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--hours", type=float, default=DEMO_HOURS,
                   help=f"length of each of the six subrange experiments, h (default {DEMO_HOURS})")
    p.add_argument("--seed", type=int, default=1, help="random seed of the simulation (default 1)")
    p.add_argument("--workers", type=int, default=None, help="Dask worker processes (default: one per core; "
                   "0: no Dask)")
    p.add_argument("--diagnose", default=None, metavar="NAME",
                   help="experiment to simulate again with --effect and diagnose (default: the one around "
                        "20..30 degC)")
    p.add_argument("--effect", default=DIAGNOSIS_EFFECT, metavar="EFFECT",
                   help=f"further effect of model.md planted in the diagnosed record (default {DIAGNOSIS_EFFECT}; "
                        "'none': diagnose the campaign's own record)")
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
    from graph_calib.evaluation.validation import simulate_validation_record

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


def simulate_with_effect(out, *, name, hours, seed, effect):
    """The campaign's experiment ``name`` simulated again with ``effect`` on; its file (reused when present).

    Same scenario and seed as :func:`simulate_demo`, so the same IMU (switching an effect on shifts no other
    draw, graph_calib.simulation.truth) and, with the same ``hours``, the same programme and noise, plus the
    effect; written with its truth (``<stem>.truth.json``, the effect's value in it) and a one-experiment
    ``campaign.toml`` into ``out/with_<effect>/``.
    """
    import json

    from graph_calib import io
    from graph_calib.simulation import simulate, write_simulation

    sim = simulate("nav-campaign", rng=np.random.default_rng(seed), hours=hours, effects=(effect,),
                   tag=f"demo, seed {seed}, with {effect}")
    plan = next((p for p in sim.plans if Path(p.file_name).stem == name), None)
    if plan is None:
        raise InputError(f"no experiment {name!r} in the simulated campaign", dataset="--diagnose")
    folder = Path(out) / f"with_{effect.replace('.', '_')}"
    path = folder / plan.file_name
    stamp = folder / "demo.json"
    want = {"scenario": "nav-campaign", "hours": hours, "seed": seed, "experiment": name, "effect": effect}
    try:
        if path.is_file() and json.loads(stamp.read_text(encoding="utf-8")) == want:
            return path
    except (OSError, ValueError):
        pass
    _say(f"  simulating {plan.file_name} again with {effect} (same IMU, programme and noise)")
    write_simulation(replace(sim, plans=(plan,)), folder, tag=f"demo, seed {seed}, with {effect}")
    io.atomic_write_json(stamp, want)
    return path


def run_diagnosis(experiment_file, out):
    """``graph-calib diagnose EXPERIMENT --out DIR``; its exit code."""
    from graph_calib.cli import main

    return main(["diagnose", str(experiment_file), "--out", str(out)])


def diagnosis_line(diagnosis_json, *, planted=None):
    """One line from ``diagnosis.json``: what was added (score, threshold), the error vs truth before and after.

    With ``planted`` (the simulated effect) the line says whether the loop found it.  Returns
    ``(line, found)``: ``found`` is None without ``planted``.
    """
    import json

    d = json.loads(Path(diagnosis_json).read_text(encoding="utf-8"))
    added = list(d.get("added") or [])
    parts = []
    for name in added:
        cand = next((c for r in d.get("rounds", []) if r.get("added") == name
                     for c in r.get("candidates", []) if c.get("name") == name), None)
        if cand and cand.get("statistic") is not None:
            parts.append(f"{name} (score {cand['statistic']:.1f} > {cand['threshold']:.1f}, {cand['dof']} dof)")
        else:
            parts.append(name)
    line = "diagnosis: added " + (", ".join(parts) if parts else "nothing")
    err = [((d.get(k) or {}).get("error_vs_truth") or {}).get(PRIMARY_SOLVER, {}).get("rms_z")
           for k in ("before", "after")]
    if None not in err:
        line += f", error vs truth RMS {err[0]:.2f} -> {err[1]:.2f} sigma ({PRIMARY_SOLVER})"
    found = None
    if planted:
        found = planted in added
        line += f"; simulated: {planted} ({'found' if found else 'NOT found'})"
    return line, found


def run(args):
    from graph_calib.campaign import CampaignOptions, run_campaign
    from graph_calib.commands.campaign_cmd import print_summary

    if not (np.isfinite(args.hours) and 0 < args.hours <= 24):
        raise InputError(f"must be a number of hours in (0, 24], got {args.hours}", dataset="--hours")
    if args.seed < 0:
        raise InputError(f"must be a non-negative integer, got {args.seed}", dataset="--seed")
    if args.workers is not None and args.workers < 0:
        raise InputError(f"must be 0 or more, got {args.workers}", dataset="--workers")
    if args.effect != "none":
        from graph_calib.simulation.truth import EFFECT_SIZES

        if args.effect not in EFFECT_SIZES:
            raise InputError(f"unknown effect {args.effect!r}; known: none, {', '.join(EFFECT_SIZES)}",
                             dataset="--effect")
    out = Path(args.out)
    t0 = time.monotonic()
    _say(f"graph-calib demo: a navigation-grade IMU, six subranges of {args.hours:g} h over -10..+50 degC")
    manifest = simulate_demo(out / "data", hours=args.hours, seed=args.seed)
    t_sim = time.monotonic() - t0
    options = CampaignOptions(workers=args.workers, validate=(str(out / "data" / "validation.h5"),))
    result = run_campaign(manifest, out / "campaign", options=options)
    print_summary(result)
    if not result.failed:
        # the campaign as PX4 thermal-compensation parameters: what they leave out, and its size, printed
        from graph_calib.cli import main

        main(["export", str(out / "campaign"), "--format", "px4", "--out", str(out / "campaign" / "thermal.params")])
    t_diag = time.monotonic()
    # cli.md: 1 an internal failure, 3 a failed verdict (of the campaign or the diagnosis), 0 otherwise
    rc = 1 if result.failed else (3 if result.verdict_failed else 0)
    if not args.no_diagnose:
        names = [e["name"] for e in result.document["experiments"]]
        name = args.diagnose or next((n for n in names if "20_30" in n), names[len(names) // 2])
        if name not in names:
            raise InputError(f"no experiment {name!r}; known: {', '.join(names)}", dataset="--diagnose")
        file = next(e["file"] for e in result.document["experiments"] if e["name"] == name)
        planted = None if args.effect == "none" else args.effect
        if planted:
            hours = max(args.hours, DIAGNOSIS_MIN_HOURS)
            file = simulate_with_effect(out / "data", name=name, hours=hours, seed=args.seed, effect=planted)
            _say(f"diagnosing {name} simulated again{'' if hours == args.hours else f' for {hours:g} h'} with "
                 f"{planted}, an effect the declared model lacks ...")
        else:
            _say(f"diagnosing {name} ...")
        drc = run_diagnosis(file, out / "diagnosis")
        if drc not in (0, 3):
            print(f"  diagnose: exited with code {drc}")
            rc = 1
        else:
            if drc == 3:
                print("  diagnose: its verdict failed (see diagnosis.json)")
                rc = rc if rc == 1 else 3
            line, found = diagnosis_line(out / "diagnosis" / "diagnosis.json", planted=planted)
            print(line)
            print(f"  diagnose: -> {out / 'diagnosis'}")
            if found is False:
                rc = rc or 1
    t_end = time.monotonic()
    tim = result.document["timing"]
    joint = (result.document.get("joint") or {}).get("joint") or {}
    joint_s = float(joint.get("seconds") or 0.0) if joint.get("status") == "computed" else 0.0   # cached: its old time
    waves_s = float(tim.get("pooled_seconds", 0.0))
    rest = (tim["total_seconds"] - tim["warmup_seconds"] - tim["tasks_seconds"] - tim.get("report_seconds", 0.0)
            - joint_s - waves_s)
    kernels = (f"{tim['compile_seconds']:.0f} s compiling, once per machine" if tim["compile_seconds"] >= 0.5
               else "from the cache")
    print(f"demo finished in {t_end - t0:.0f} s: simulation {t_sim:.0f} s, numba kernels {tim['warmup_seconds']:.0f} s "
          f"({kernels}), calibration {tim['tasks_seconds']:.0f} s, joint solve {joint_s:.0f} s, "
          f"the loop's pooled waves {waves_s:.0f} s, report {tim.get('report_seconds', 0.0):.0f} s, "
          f"hashing, stitching and validation {rest:.0f} s"
          + ("" if args.no_diagnose else f", diagnosis {t_end - t_diag:.0f} s")
          + f"; open {out / 'campaign' / 'report.html'}")
    return rc
