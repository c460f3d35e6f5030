"""``graph-calib import FORMAT INPUT... --out FILE.h5``: convert a log into an experiment file.

The formats come from the importer registry (:mod:`graph_calib.importers.registry`):
each registered format brings its inputs, its own options and an example; this
module adds the options every format shares (the bench: latitude, gravity, an
assumed temperature; the IMU's identity) and has no branch of its own per format.
Latitude is given in degrees here, at the edge, and stored in radians.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from graph_calib import constants as c
from graph_calib.commands.paths import output_file
from graph_calib.errors import InputError
from graph_calib.importers.registry import formats
from graph_calib.io import write_experiment
from graph_calib.commands.model_options import check_gyro_range
from graph_calib.records.saturation import cut_at_range, flat_top_text, flat_tops, saturation_note


def _format_options():
    """``{flag: (Option, [format names])}`` over every registered format, in first-declared order."""
    out = {}
    for name, fmt in formats().items():
        for opt in fmt.options:
            out.setdefault(opt.flag, (opt, []))[1].append(name)
    return out


def add_arguments(parser):
    """Options of ``graph-calib import``: the common ones and each registered format's own."""
    fmts = formats()
    parser.add_argument("format", choices=tuple(fmts), metavar="FORMAT",
                        help="; ".join(f"{n}: {f.summary}" for n, f in fmts.items()))
    parser.add_argument("inputs", nargs="+", metavar="INPUT",
                        help="; ".join(f"{n}: {' '.join(f.inputs)}" for n, f in fmts.items()))
    parser.add_argument("--out", required=True, metavar="FILE.h5", help="experiment file to write (atomically)")
    site = parser.add_argument_group("bench (every format)")
    site.add_argument("--latitude-deg", type=float, metavar="DEG",
                      help="bench latitude, degrees (the Earth rate needs it; default: xsens Padova 45.41, mpu6050 "
                           "Mendoza -32.89; required for csv, rosbag and ulog)")
    site.add_argument("--gravity", type=float, metavar="MPS2",
                      help="local gravity, m/s^2 (default: xsens 9.81744, mpu6050 9.7933; otherwise WGS-84 normal "
                           "gravity at --latitude-deg, at sea level)")
    site.add_argument("--temperature", type=float, metavar="DEGC",
                      help="assumed constant temperature, degC, for logs without one (default 20 for xsens and "
                           "mpu6050)")
    site.add_argument("--gyro-range-dps", type=float, metavar="DPS",
                      help="the gyros' full-scale range, deg/s: the record is cut (/imu/segment) after each run of "
                           "samples at it that has a rest after it, so that no rotation factor spans the angle a "
                           "saturated turn lost (mpu6050 finds its runs from the counts without it)")
    site.add_argument("--imu-id", help="IMU model and serial number")
    site.add_argument("--description", help="free text (default: provenance and conversion)")
    own = parser.add_argument_group("options of some formats (each says which)")
    for flag, (opt, names) in _format_options().items():
        helps = {}
        for n in names:
            helps.setdefault(next(o.help for o in fmts[n].options if o.flag == flag), []).append(n)
        text = "; ".join(f"{'/'.join(ns)}: {h}" for h, ns in helps.items())
        kwargs = dict(opt.kwargs)
        kwargs.setdefault("default", None)
        own.add_argument(flag, help=text, **kwargs)


def _latitude_rad(args):
    if args.latitude_deg is None:
        return None
    if not math.isfinite(args.latitude_deg) or abs(args.latitude_deg) > 90.0:
        raise InputError(f"latitude must be within [-90, 90] degrees, got {args.latitude_deg!r}",
                         dataset="--latitude-deg")
    return args.latitude_deg * c.DEG_TO_RAD


def _options(args, fmt):
    """The options given, by dest (the format's own and the common ones in SI); refuses another format's."""
    own = {o.dest for o in fmt.options}
    options = {}
    for flag, (opt, names) in _format_options().items():
        value = getattr(args, opt.dest)
        if value is None:
            continue
        if opt.dest not in own:
            raise InputError(f"does not apply to format {fmt.name} (only {', '.join(names)})", dataset=flag)
        options[opt.dest] = value
    common = {"latitude_rad": _latitude_rad(args), "gravity_mps2": args.gravity,
              "temperature_degC": args.temperature, "imu_id": args.imu_id, "description": args.description}
    options.update({k: v for k, v in common.items() if v is not None})
    return options


def summary(experiment):
    """Short human summary lines of an imported experiment."""
    e = experiment
    dt = e.dt
    f = np.linalg.norm(e.dv, axis=1) / dt
    w = np.linalg.norm(e.dtheta, axis=1) / dt
    temp = e.temperature
    segments = f" in {e.n_segments} segments" if e.n_segments > 1 else ""
    return [
        f"{e.n_samples} samples{segments}, {e.t[-1] - e.t[0] + 1.0 / e.rate_hz:.2f} s at {e.rate_hz:g} Hz",
        f"mean |f| = {f.mean():.4f} m/s^2 ({f.mean() / e.gravity_mps2:.4f} x local gravity {e.gravity_mps2:g}), "
        f"largest |omega| = {w.max() * c.RAD_TO_DEG:.1f} deg/s",
        f"temperature: {temp.shape[1]} channel(s) ({', '.join(e.temperature_names)}), "
        f"{temp.min():.2f} to {temp.max():.2f} degC",
        f"latitude {e.latitude_rad * c.RAD_TO_DEG:.4f} deg, no turntable reference",
    ]


def run(args):
    """Import, write, print a summary; InputError on bad input (exit 2)."""
    fmt = formats()[args.format]
    out = output_file(args.out)
    options = _options(args, fmt)
    if len(args.inputs) != len(fmt.inputs):
        raise InputError(f"format {fmt.name} takes {' '.join(fmt.inputs)}, got {len(args.inputs)} input(s)",
                         dataset="INPUT")
    for p in args.inputs:            # before what the format asks of its options (a latitude): the first to fix
        if not Path(p).exists():
            raise InputError("file not found", path=p)
    check_gyro_range(args)
    if args.gyro_range_dps is not None:
        options["keep_saturated"] = True      # the declared range, not a format's own limits, says where to cut
    experiment = fmt.read([Path(p) for p in args.inputs], options)
    if args.gyro_range_dps is not None:
        experiment = cut_at_range(experiment, gyro_range_rps=args.gyro_range_dps * c.DEG_TO_RAD).experiment
    write_experiment(experiment, out)
    print(f"graph-calib import {args.format}: " + ", ".join(str(p) for p in args.inputs))
    for line in summary(experiment):
        print("  " + line)
    for line in (fmt.notes(experiment, options) if fmt.notes else ()):
        print(f"note: {line}")
    note = saturation_note(experiment.description)
    if note:
        print(f"note: {note}")
    elif (tops := flat_tops(experiment)) is not None:
        print(f"note: the gyros sit at their largest output {flat_top_text(tops)}, as a saturated gyro does: "
              "--gyro-range-dps with the gyros' range cuts the record after each saturated turn, so that no rotation "
              "factor spans the angle it lost (docs/model.md, \"A saturated gyro\")")
    print(f"wrote {out}")
    return 0
