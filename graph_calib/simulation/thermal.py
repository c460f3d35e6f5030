r"""Thermal chamber and sensor temperature channels, in closed form.

The chamber follows a piecewise-linear profile ``u(t)`` (ramps of different
rates that never stop: the temperature keeps drifting).  Channel ``i`` is a
first-order lag of the chamber with time constant ``tau_i`` and a steady offset
``c_i`` (self-heating):

.. math::

    \tau_i \dot y_i = u(t) + c_i - y_i .

On a chamber segment ``u = u_j + b_j (t - t_j)`` the solution is exact,

.. math::

    y_i(t) = u(t) + c_i - b_j\tau_i + (y_i(t_j) - u_j - c_i + b_j\tau_i)\,e^{-(t - t_j)/\tau_i},

so temperatures and their rates ``dy/dt = (u + c - y) / tau`` are analytic at
any time (C1 in time even where the chamber ramp changes rate).  A channel
with ``tau = 0`` is the chamber itself plus its offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ThermalModel:
    """Chamber profile and the temperature channels that lag it.

    Attributes
    ----------
    chamber_t : ndarray, shape (P,)
        Breakpoints of the chamber profile, s, increasing; constant before the
        first and after the last.
    chamber_T : ndarray, shape (P,)
        Chamber temperature at the breakpoints, degC.
    names : tuple of str
        Channel names (K).
    tau : ndarray, shape (K,)
        Time constants, s (0: follows the chamber at once).
    offset : ndarray, shape (K,)
        Steady offset above the chamber, degC.
    initial : ndarray, shape (K,)
        Channel temperatures at ``chamber_t[0]``, degC.
    """

    chamber_t: np.ndarray
    chamber_T: np.ndarray
    names: tuple
    tau: np.ndarray
    offset: np.ndarray
    initial: np.ndarray

    def __post_init__(self):
        tb = np.asarray(self.chamber_t, dtype=float)
        Tb = np.asarray(self.chamber_T, dtype=float)
        slope = np.zeros(tb.size)
        slope[:-1] = np.diff(Tb) / np.diff(tb)
        # channel states at the breakpoints (a loop over the few breakpoints only)
        y = np.empty((tb.size, len(self.names)))
        y[0] = np.where(self.tau > 0, self.initial, Tb[0] + self.offset)
        for j in range(tb.size - 1):
            y[j + 1] = self._evolve(y[j], Tb[j], slope[j], tb[j + 1] - tb[j])
        object.__setattr__(self, "_slope", slope)
        object.__setattr__(self, "_ybreak", y)

    def _evolve(self, y0, u0, b, dt, channels=None):
        """Channel states (broadcast) after ``dt`` from ``y0`` on a ramp ``u0 + b t``."""
        sel = slice(None) if channels is None else channels
        tau = np.asarray(self.tau, dtype=float)[sel]
        c = np.asarray(self.offset, dtype=float)[sel]
        u = u0 + b * dt
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.where(tau > 0, np.exp(-dt / np.where(tau > 0, tau, 1.0)), 0.0)
        return u + c - b * tau + (y0 - u0 - c + b * tau) * e

    def _segment(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        tb = np.asarray(self.chamber_t, dtype=float)
        j = np.clip(np.searchsorted(tb, t, side="right") - 1, 0, tb.size - 1)
        dt = t - tb[j]
        b = self._slope[j]
        before = t < tb[0]
        # before the first breakpoint everything rests at the initial state
        dt = np.where(before, 0.0, dt)
        return j, dt, b

    def chamber(self, t):
        """Chamber temperature at ``t``, degC, shape (N,)."""
        j, dt, b = self._segment(t)
        return np.asarray(self.chamber_T, dtype=float)[j] + b * dt

    def temperature(self, t, channels=None):
        """Channel temperatures at ``t``, degC, shape (N, K) (or (N, len(channels)))."""
        j, dt, b = self._segment(t)
        u0 = np.asarray(self.chamber_T, dtype=float)[j]
        sel = slice(None) if channels is None else np.asarray(channels, dtype=int)
        return self._evolve(self._ybreak[j][:, sel], u0[:, None], b[:, None], dt[:, None],
                            None if channels is None else sel)

    def rate(self, t, channels=None):
        """Channel temperature rates at ``t``, degC/s, shape (N, K) (or (N, len(channels)))."""
        j, dt, b = self._segment(t)
        y = self.temperature(t, channels)
        u = (np.asarray(self.chamber_T, dtype=float)[j] + b * dt)[:, None]
        sel = slice(None) if channels is None else np.asarray(channels, dtype=int)
        tau = np.asarray(self.tau, dtype=float)[sel]
        c = np.asarray(self.offset, dtype=float)[sel]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(tau > 0, (u + c - y) / np.where(tau > 0, tau, 1.0), b[:, None])
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.where((t < self.chamber_t[0])[:, None], 0.0, r)


def ramp_chamber(*, duration, start_degC, span_degC, names, tau, offset, temperature_map,
                 pattern=(1.0, 0.55, 1.4), max_rate=1.5 / 60.0):
    """A chamber that ramps (never settling) so that the sensors drift by ``span_degC``.

    The chamber ramps through ``len(pattern)`` equal parts of the experiment with
    rates proportional to ``pattern``, starting in equilibrium with the sensors
    (channels at chamber + offset).  The rate is chosen so that the mean of the
    six sensors' temperatures rises by ``span_degC`` over the experiment (the
    response is linear in the rate), but the chamber never ramps faster than
    ``max_rate`` degC/s (then the span comes out smaller).

    Parameters
    ----------
    duration : float
        s.
    start_degC : float
        Mean sensor temperature at the start.
    span_degC : float
        Wanted rise of the mean sensor temperature (negative: cooling).
    names, tau, offset : see :class:`ThermalModel`.
    temperature_map : array_like of int, shape (6,)
        Channel of each sensor (the span refers to their mean).
    pattern : tuple of float
        Relative ramp rates of the parts.
    max_rate : float
        Largest chamber rate, degC/s.

    Returns
    -------
    ThermalModel
    """
    tmap = np.asarray(temperature_map, dtype=int)
    tau = np.asarray(tau, dtype=float)
    offset = np.asarray(offset, dtype=float)
    pattern = np.asarray(pattern, dtype=float)
    k = pattern.size
    tb = np.linspace(0.0, duration, k + 1)

    def build(rate, T0, c):
        Tb = T0 + np.concatenate([[0.0], np.cumsum(rate * pattern * np.diff(tb))])
        return ThermalModel(chamber_t=tb, chamber_T=Tb, names=tuple(names), tau=tau, offset=c, initial=T0 + c)

    unit = build(1.0, 0.0, np.zeros_like(offset))
    ends = unit.temperature([0.0, duration])[:, tmap].mean(axis=1)
    response = ends[1] - ends[0]
    rate = span_degC / response if response != 0 else 0.0
    peak = np.max(np.abs(pattern)) * abs(rate)
    if peak > max_rate:
        rate *= max_rate / peak
    T0 = start_degC - float(np.mean(offset[tmap]))
    return build(rate, T0, offset)


__all__ = ["ThermalModel", "ramp_chamber"]
