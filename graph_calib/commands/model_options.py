"""Model options several commands share on the command line (one spelling, one help text, one parser)."""

from __future__ import annotations

import math

from graph_calib.errors import InputError


def add_sway(parser):
    """``--sway-sigma estimate|MPS2``: the bench's own acceleration at rest (a swaying hand), ``ModelOptions.sway_sigma``."""
    parser.add_argument("--sway-sigma", default=None, metavar="estimate|MPS2",
                        help="a hand holding the unit sways it: 'estimate' it from the static intervals, or give its "
                             "one sigma in m/s^2 (added to every gravity measurement; default none: a bench)")


def sway_of(args):
    """``ModelOptions.sway_sigma`` from ``--sway-sigma``: None, ``"estimate"`` or a non-negative float."""
    return _estimate_or_mps2(getattr(args, "sway_sigma", None), "--sway-sigma")


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


__all__ = ["add_sway", "sway_of", "add_moving", "moving_of"]
