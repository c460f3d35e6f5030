"""Model options several commands share on the command line (one spelling, one help text, one parser)."""

from __future__ import annotations

import argparse
import math
import sys

from graph_calib.errors import InputError
from graph_calib.records.saturation import cut_at_range


def finite_float(text):
    """An option's number, refused (exit 2 naming the option) when it is not a finite one (``nan``, ``inf``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def add_sway(parser):
    """``--sway-sigma estimate|MPS2``: the bench's own acceleration at rest (a swaying hand), ``ModelOptions.sway_sigma``."""
    parser.add_argument("--sway-sigma", default=None, metavar="estimate|MPS2",
                        help="a hand holding the unit sways it: 'estimate' it from the static intervals, or give its "
                             "one sigma in m/s^2 (added to every gravity measurement; default none: a bench)")


def sway_of(args):
    """``ModelOptions.sway_sigma`` from ``--sway-sigma``: None, ``"estimate"`` or a non-negative float."""
    return _estimate_or_mps2(getattr(args, "sway_sigma", None), "--sway-sigma")


def add_still(parser):
    """``--still-rests``: a unit at rest does not turn, ``ModelOptions.still_at_rest``."""
    parser.add_argument("--still-rests", action="store_true",
                        help="the unit does not turn while it rests (it sits on a surface): each rest's gyro "
                             "integral then measures the gyro biases against the Earth's turn, as a Ferraris "
                             "calibration's rests do (default: the rests constrain the attitudes through gravity only)")


def still_of(args):
    """``ModelOptions.still_at_rest`` from ``--still-rests``."""
    return bool(getattr(args, "still_rests", False))


def add_guided_turns(parser):
    """``--guided-turns DEG|off``: a Ferraris session's full turns about the vertical, ``ModelOptions.guided_turns``."""
    parser.add_argument("--guided-turns", default=None, metavar="DEG|off",
                        help="full turns about the vertical between two rests on one face are a Ferraris session's "
                             "guided turns (slid flat, pressed against a guide before and after): they close and stay "
                             "flat within this spread, deg (default 0.5, used where such turns are found); 'off' takes "
                             "them for motion like any other (docs/model.md, \"Guided full turns\")")


def guided_turns_of(args):
    """``ModelOptions.guided_turns`` from ``--guided-turns``: True (the default spread), False (off) or a spread in
    rad."""
    text = getattr(args, "guided_turns", None)
    if text is None:
        return True
    if str(text).lower() == "off":
        return False
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"must be 'off' or a positive number of degrees, got {text!r}", dataset="--guided-turns")
    return math.radians(value)


def add_bench_options(parser):
    """The bench options every command that calibrates takes, in one order: ``--sway-sigma``, ``--gyro-range-dps``,
    ``--moving-sigma``, ``--still-rests``, ``--guided-turns`` (:func:`bench_options` reads them)."""
    add_sway(parser)
    add_gyro_range(parser)
    add_moving(parser)
    add_still(parser)
    add_guided_turns(parser)


def bench_options(args):
    """The :class:`~graph_calib.model.ModelOptions` fields of the bench options every command that calibrates takes
    (``--sway-sigma``, ``--moving-sigma``, ``--still-rests``, ``--guided-turns``), each read and checked once."""
    return {"sway_sigma": sway_of(args), "moving_sigma": moving_of(args), "still_at_rest": still_of(args),
            "guided_turns": guided_turns_of(args)}


def add_gyro_range(parser):
    """``--gyro-range-dps DPS``: the record cut after each saturated episode before the work (records/saturation)."""
    parser.add_argument("--gyro-range-dps", type=finite_float, default=None, metavar="DPS",
                        help="the gyros' full-scale range, deg/s: the record is cut after each run of samples at it "
                             "that a rest follows, so that no rotation factor spans the angle a saturated turn lost "
                             "(as import --gyro-range-dps does; docs/model.md, \"A saturated gyro\")")


def check_gyro_range(args):
    """Refuse a ``--gyro-range-dps`` that is not a positive finite number (exit 2 naming the option)."""
    value = getattr(args, "gyro_range_dps", None)
    if value is not None and not (math.isfinite(value) and value > 0.0):
        raise InputError(f"must be a positive number of deg/s, got {value!r}", dataset="--gyro-range-dps")


def with_gyro_range(args, experiment):
    """``experiment`` cut after its saturated episodes when ``--gyro-range-dps`` is given (printing where), else as
    is."""
    check_gyro_range(args)
    value = getattr(args, "gyro_range_dps", None)
    if value is None:
        return experiment
    cuts = cut_at_range(experiment, gyro_range_rps=math.radians(value))
    print(f"note: {cuts.describe() or f'no gyro sample reaches {value:g} deg/s: the record is not cut.'}",
          file=sys.stderr)
    return cuts.experiment


def add_moving(parser):
    """``--moving-sigma estimate|MPS2``: the gravity sigma of keyframes in motion, ``ModelOptions.moving_sigma``."""
    parser.add_argument("--moving-sigma", default=None, metavar="estimate|MPS2",
                        help="without a table, the gravity measurement of a keyframe in motion carries the hand's own "
                             "acceleration: 'estimate' its sigma with the variance components, or give it in m/s^2 "
                             "(default 1 m/s^2)")


def moving_of(args):
    """``ModelOptions.moving_sigma`` from ``--moving-sigma``: None, ``"estimate"`` or a non-negative float."""
    return _estimate_or_mps2(getattr(args, "moving_sigma", None), "--moving-sigma")


def _estimate_or_mps2(text, option):
    if text is None or text == "estimate":
        return text
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value >= 0):
        raise InputError(f"must be 'estimate' or a non-negative number of m/s^2, got {text!r}", dataset=option)
    return value


GRADE_CHOICES = ("navigation", "tactical", "consumer")

#: The white-noise options: (flag, ``ModelOptions`` field, metavar, what).
_NOISE = (("--gyro-noise", "gyro_noise", "RAD_PER_SQRT_S", "gyro angle random walk, rad/sqrt(s)"),
          ("--accel-noise", "accel_noise", "MPS2_PER_SQRT_HZ", "accelerometer velocity random walk, m/s^2/sqrt(Hz)"),
          ("--encoder-noise", "encoder_noise", "RAD", "encoder reading noise, rad"))


def add_noise(parser, *, grade_default, noise_default):
    """``--grade`` and the white-noise overrides ``--gyro-noise``, ``--accel-noise``, ``--encoder-noise`` (SI).

    ``grade_default`` / ``noise_default``: what the command does without them, for the help text.
    """
    parser.add_argument("--grade", choices=GRADE_CHOICES, default=None,
                        help=f"IMU grade for priors and noise (default: {grade_default})")
    for flag, _, metavar, what in _NOISE:
        parser.add_argument(flag, type=float, default=None, metavar=metavar,
                            help=f"{what} (default: {noise_default})")


def noise_of(args):
    """``{ModelOptions field: value}`` of the noise overrides given; each must be a positive finite number."""
    out = {}
    for flag, field, _, _ in _NOISE:
        v = getattr(args, field, None)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise InputError(f"must be a positive number, got {v!r}", dataset=flag)
        out[field] = v
    return out


__all__ = ["finite_float", "add_sway", "sway_of", "add_still", "still_of", "add_moving", "moving_of", "GRADE_CHOICES", "add_noise",
           "noise_of", "add_gyro_range", "check_gyro_range", "with_gyro_range", "add_guided_turns", "guided_turns_of",
           "bench_options", "add_bench_options"]
