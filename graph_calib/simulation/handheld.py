r"""Hand-held motion without a table: static poses joined by smooth rotations.

Between two poses the body turns about one fixed body axis and its centre moves
along a straight line, both with the quintic smooth-step profile
``s(u) = 10u^3 - 15u^4 + 6u^5`` (``u = (t - t_0) / T``), whose rate and
acceleration vanish at both ends::

    C_nb(t)   = C_k Exp(s(u) phi_k)           omega_nb_b = s'(u) / T * phi_k
    r_n(t)    = r_k + s(u) d_k                domega_nb_b = s''(u) / T^2 * phi_k
                                              a_n = s''(u) / T^2 * d_k

so the kinematics are exact at any time.  Segment boundaries lie on the IMU
sample grid.

A hand does not hold still: :meth:`HandheldMotion.sway` adds a translation of the
rotation centre (the hand's pivot) made of sinusoids, at rest or not,
``a_n = sum_i A_i sin(w_i t + p_i)``, ``v_n = -sum_i A_i / w_i cos(w_i t + p_i)``
(exact, position bounded).  The lever arm from the pivot to the sensor is the
signal model's (:class:`graph_calib.simulation.imu.SignalModel`).
"""

from __future__ import annotations

import numpy as np

from graph_calib.navigation.rotations import exp_so3
from graph_calib.simulation.turntable import Kinematics


def _smoothstep(u):
    s = u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
    ds = 30.0 * u * u * (1.0 - u) ** 2
    dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    return s, ds, dds


class HandheldMotion:
    """Static poses and smooth rotations (with a small translation) between them.

    Build with :meth:`hold` and :meth:`turn`; times are rounded to whole sample periods.

    Parameters
    ----------
    rate_hz : float
    C_nb0 : ndarray, shape (3, 3)
        Attitude at the start.
    """

    has_table = False

    def __init__(self, rate_hz, C_nb0):
        self.rate_hz = float(rate_hz)
        self._C = np.asarray(C_nb0, dtype=float).copy()
        self._r = np.zeros(3)
        self._rows = []  # (start_tick, n_ticks, C_start, phi, r_start, d)
        self._tick = 0
        self._frozen = None
        self._sway = None

    def sway(self, *, amplitude, omega, phase):
        """Add the pivot's sway: accelerations ``amplitude`` (M, 3) m/s^2 at ``omega`` (M, 3) rad/s, ``phase`` (M, 3)."""
        self._sway = tuple(np.asarray(a, dtype=float) for a in (amplitude, omega, phase))

    @property
    def duration(self):
        return self._tick / self.rate_hz

    @property
    def attitude_now(self):
        return self._C.copy()

    def hold(self, seconds):
        """Rest for ``seconds``."""
        n = max(1, int(round(seconds * self.rate_hz)))
        self._rows.append((self._tick, n, self._C.copy(), np.zeros(3), self._r.copy(), np.zeros(3)))
        self._tick += n
        self._frozen = None

    def turn(self, phi_b, seconds, displacement_n=None):
        """Turn by the body-frame rotation vector ``phi_b`` (rad) and move by ``displacement_n`` (m)."""
        n = max(2, int(round(seconds * self.rate_hz)))
        phi = np.asarray(phi_b, dtype=float)
        d = np.zeros(3) if displacement_n is None else np.asarray(displacement_n, dtype=float)
        self._rows.append((self._tick, n, self._C.copy(), phi, self._r.copy(), d))
        self._tick += n
        self._C = self._C @ exp_so3(phi)
        self._r = self._r + d
        self._frozen = None

    def turn_ticks(self):
        """``[(first tick, number of ticks), ...]`` of every turn, in the order made."""
        return [(start, n) for start, n, _, phi, _, d in self._rows if np.any(phi) or np.any(d)]

    def _arrays(self):
        if self._frozen is None:
            start, n, C, phi, r, d = zip(*self._rows)
            self._frozen = (np.array(start, dtype=np.int64), np.array(n, dtype=np.int64), np.array(C),
                            np.array(phi), np.array(r), np.array(d))
        return self._frozen

    def _locate(self, t):
        start, n, C, phi, r, d = self._arrays()
        t = np.atleast_1d(np.asarray(t, dtype=float))
        s0 = start / self.rate_hz
        idx = np.clip(np.searchsorted(s0, t, side="right") - 1, 0, s0.size - 1)
        T = n[idx] / self.rate_hz
        u = np.clip((t - s0[idx]) / T, 0.0, 1.0)
        return idx, u, T

    def kinematics(self, t):
        """:class:`~graph_calib.simulation.turntable.Kinematics` at ``t`` (with ``acc_n``, ``vel_n``)."""
        _, _, C, phi, _, d = self._arrays()
        idx, u, T = self._locate(t)
        s, ds, dds = _smoothstep(u)
        p = phi[idx]
        C_nb = C[idx] @ exp_so3(s[:, None] * p)
        w = (ds / T)[:, None] * p
        dw = (dds / T**2)[:, None] * p
        acc = (dds / T**2)[:, None] * d[idx]
        vel = (ds / T)[:, None] * d[idx]
        if self._sway is not None:
            A, om, ph = self._sway
            arg = np.atleast_1d(np.asarray(t, dtype=float))[:, None, None] * om + ph     # (N, M, 3)
            acc = acc + np.sum(A * np.sin(arg), axis=1)
            vel = vel - np.sum(A / om * np.cos(arg), axis=1)
        return Kinematics(C_nb=C_nb, omega_nb_b=w, domega_nb_b=dw, acc_n=acc, vel_n=vel)

    def is_static(self, t, *, margin=0.0):
        """Whether the body rests at ``t`` (and ``margin`` seconds either side), shape (N,); the sway aside."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.ones(t.shape, dtype=bool)
        sway, self._sway = self._sway, None
        try:
            for dt in (-margin, 0.0, margin) if margin > 0 else (0.0,):
                k = self.kinematics(t + dt)
                out &= np.all(k.omega_nb_b == 0.0, axis=1) & np.all(k.acc_n == 0.0, axis=1)
        finally:
            self._sway = sway
        return out


__all__ = ["HandheldMotion"]
