"""``graph-calib simulate SCENARIO --out DIR`` or ``--program P.toml``: make a synthetic experiment or campaign.

Writes one experiment file per experiment, its truth (``<stem>.truth.json``,
the result layout with ``solver = "truth"``) and a ``campaign.toml`` manifest
listing them (also for a single experiment).  ``--list`` shows the scenarios.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from graph_calib.errors import InputError


#: The scenario options a command-line flag sets (the scenarios that do not take one refuse the flag by name).
FLAG_OF = {"--cut": "cut", "--hand-accel": "hand_accel_mps2", "--pivot": "pivot_m", "--cubic-scale": "cubic_scale",
           "--effect": "effects", "--effect-scale": "effect_scale", "--hours": "hours"}


def add_arguments(parser):
    parser.add_argument("scenario", nargs="?", metavar="SCENARIO", help="scenario name (see --list)")
    parser.add_argument("--program", metavar="PROGRAM.toml",
                        help="run a bench program (docs/programs.md) instead of a scenario")
    parser.add_argument("--out", metavar="DIR", help="output folder (created if missing)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0); same seed, same files")
    parser.add_argument("--no-noise", action="store_true", help="no sensor, encoder or temperature noise")
    parser.add_argument("--no-errors", action="store_true",
                        help="an ideal IMU: every truth parameter zero (no mount, lever arm or lag either)")
    parser.add_argument("--hours", type=float, metavar="H",
                        help="length of each experiment, h (default: the scenario's)")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="switch a further effect of model.md on (repeatable)")
    parser.add_argument("--effect-scale", type=float, metavar="S",
                        help="multiply the size of every switched-on effect (default 1)")
    parser.add_argument("--cut", action="store_true",
                        help="hand-held scenarios: cut turns out and mark the pieces in /imu/segment")
    parser.add_argument("--hand-accel", type=float, metavar="A",
                        help="hand-held scenarios: the pivot's sway, m/s^2 rms (default 0)")
    parser.add_argument("--pivot", type=float, metavar="M",
                        help="hand-held scenarios: distance of the sensor from the hand's pivot, m (default 0)")
    parser.add_argument("--cubic-scale", type=float, metavar="S",
                        help="turntable scenarios: a cubic term in the bias temperature curves, as real IMUs have, "
                             "S times the grade's typical size (default 0: none; the same seed otherwise gives the "
                             "same data)")
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")


def _print_list(out):
    from graph_calib.simulation import SCENARIOS

    width = max(len(n) for n in SCENARIOS)
    print("scenarios:", file=out)
    for name, sc in SCENARIOS.items():
        print(f"  {name:<{width}}  {sc.summary}", file=out)


def run(args):
    from graph_calib.simulation import SCENARIOS, get_scenario, simulate, write_simulation
    from graph_calib.simulation.scenarios import scenario_names
    from graph_calib.simulation.program import program_simulation, read_program

    if args.list:
        _print_list(sys.stdout)
        return 0
    if args.program and args.scenario:
        raise InputError(f"give a SCENARIO or --program, not both (got {args.scenario!r} and {args.program!r})")
    if args.program and args.hours is not None:
        raise InputError("--hours does not apply to --program: the program states its length")
    if not args.scenario and not args.program:
        raise InputError(f"SCENARIO or --program is required; known scenarios: {', '.join(SCENARIOS)}")
    if args.scenario and args.scenario not in SCENARIOS:
        raise InputError(f"unknown scenario {args.scenario!r}; known: {', '.join(SCENARIOS)}")
    if not args.out:
        raise InputError("--out DIR is required")
    if args.seed < 0:
        raise InputError(f"--seed must be a non-negative integer, got {args.seed}")
    if args.hours is not None and not (np.isfinite(args.hours) and args.hours > 0):
        raise InputError(f"--hours must be a positive number, got {args.hours}")
    tag = f"seed {args.seed}"
    options = {"noise": not args.no_noise, "errors": not args.no_errors, "hours": args.hours, "tag": tag,
               "effect_scale": args.effect_scale}
    if args.effect:
        options["effects"] = tuple(args.effect)
    for key, value in (("cut", args.cut or None), ("hand_accel_mps2", args.hand_accel), ("pivot_m", args.pivot)):
        if value is not None:
            options[key] = value
    if args.cubic_scale is not None:
        options["cubic_scale"] = args.cubic_scale
    rng = np.random.default_rng(args.seed)
    t0 = time.monotonic()
    if args.program:
        program = read_program(args.program)
        options.pop("hours")
        if options["effect_scale"] is None:
            options.pop("effect_scale")
        sim = program_simulation(program, rng=rng, **options)
    else:
        known = get_scenario(args.scenario).options() if args.scenario in scenario_names() else None
        for flag, key in FLAG_OF.items():
            if known is not None and key in options and key not in known:
                takes = ", ".join(n for n in scenario_names() if key in get_scenario(n).options())
                raise InputError(f"scenario {args.scenario!r} does not take {flag} (it takes: {takes})",
                                 dataset=flag)
        sim = simulate(args.scenario, rng=rng, **options)

    def progress(msg):
        print(msg, file=sys.stderr, flush=True)

    written = write_simulation(sim, args.out, progress=progress, tag=tag)
    n_exp = len(written) - 1
    print(f"{args.scenario or sim.scenario} ({tag}, grade {sim.grade}, {'no noise' if args.no_noise else 'with noise'}, "
          f"{'no errors' if args.no_errors else 'with errors'}): {n_exp} experiment"
          f"{'s' if n_exp != 1 else ''} in {time.monotonic() - t0:.1f} s")
    for w in written[:-1]:
        lo, hi = w["temperature_range_degC"]
        table = (f", table {w['table_readings']} readings ({w['valid_readings']} valid)"
                 if w["table_readings"] else ", no table")
        print(f"  {w['file']}: {w['n_samples']} samples, {w['hours']:.2f} h at {w['rate_hz']:g} Hz, "
              f"sensors {lo:.1f}..{hi:.1f} degC{table}")
        print(f"  {w['truth']}: truth, T_ref {w['t_ref_degC']:.2f} degC, {w['n_parameters']} parameter elements")
    print(f"  {written[-1]['manifest']}: manifest")
    return 0
