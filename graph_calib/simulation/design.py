r"""The rotation design of a table experiment and the turntable programme made from it.

:class:`Design` holds the numbers of a design (alignment, static positions,
rates, ramps, full turns); :data:`NAV_DESIGN` is the navigation-grade one and
:data:`SHORT_DESIGN` its shortened variant.  :func:`rotation_program` turns a
design into a :class:`~graph_calib.simulation.turntable.TableProgram` of the
length asked for, drawing the random choices from the generator passed in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.simulation.turntable import INNER, OUTER, ProgramBuilder


@dataclass(frozen=True)
class Design:
    """The rotation design of a table experiment.

    Attributes
    ----------
    alignment_s : float
        Initial static alignment, s (capped at ``alignment_fraction`` of the experiment).
    alignment_fraction : float
    dwell_s : (float, float)
        Range of the static positions between rotations, s.
    rate_dps : (float, float)
        Range of the peak rotation rate, deg/s.
    ramp_s : float
        Length of each rate ramp, s.
    full_turns : bool
        Add a full turn each way about every axis.
    """

    alignment_s: float = 900.0
    alignment_fraction: float = 0.2
    dwell_s: tuple = (20.0, 40.0)
    rate_dps: tuple = (10.0, 30.0)
    ramp_s: float = 1.0
    full_turns: bool = True


NAV_DESIGN = Design()
SHORT_DESIGN = Design(alignment_s=180.0, dwell_s=(15.0, 25.0))


def rotation_program(rate_hz, duration_s, *, rng, design=NAV_DESIGN):
    """Turntable programme: alignment, then rotations about each instrument axis held horizontal.

    After the static alignment the programme cycles through the instrument axes
    x, y, z.  For each it first brings the axis onto a horizontal table axis (a
    90-deg move of the other table axis when needed; see
    :mod:`graph_calib.simulation.turntable`), then turns about it four times by
    90 deg one way and four times back, and (``design.full_turns``) a full turn
    each way; a static position of random length in ``design.dwell_s`` follows
    every move.  Rates are drawn in ``design.rate_dps``.  Moves are added while
    they fit; a final dwell fills the programme to exactly ``duration_s``.

    Parameters
    ----------
    rate_hz : float
    duration_s : float
    rng : numpy.random.Generator
    design : Design

    Returns
    -------
    TableProgram
    """
    n_total = int(round(duration_s * rate_hz))
    b = ProgramBuilder(rate_hz)
    b.dwell(min(design.alignment_s, design.alignment_fraction * duration_s))
    quarters = [0, 0]  # (alpha, beta) in quarter turns
    dwell_lo = int(round(design.dwell_s[0] * rate_hz))

    def steps():
        while True:
            for axis_name in ("x", "y", "z"):
                if axis_name in ("x", "y"):
                    want_odd = axis_name == "y"
                    if (quarters[1] % 2 == 1) != want_odd:
                        yield INNER, (1 if rng.uniform() < 0.5 else -1)
                    turn_axis = OUTER
                else:
                    if quarters[0] % 2 == 0:
                        yield OUTER, (1 if rng.uniform() < 0.5 else -1)
                    turn_axis = INNER
                s = 1 if rng.uniform() < 0.5 else -1
                seq = [s] * 4 + [-s] * 4
                if design.full_turns:
                    seq += [4 * s, -4 * s]
                for q in seq:
                    yield turn_axis, q

    for axis, q in steps():
        rate = np.radians(rng.uniform(*design.rate_dps))
        dwell = rng.uniform(*design.dwell_s)
        angle = q * np.pi / 2.0
        need = b.move_ticks(angle, rate=rate, ramp=design.ramp_s) + int(round(dwell * rate_hz))
        if b.ticks + need > n_total - dwell_lo:
            break
        b.move(axis, angle, rate=rate, ramp=design.ramp_s)
        quarters[axis] += q
        b.dwell(dwell)
    rest = n_total - b.ticks
    if rest > 0:
        b.dwell(rest / rate_hz)
    return b.build()


__all__ = ["Design", "NAV_DESIGN", "SHORT_DESIGN", "rotation_program"]
