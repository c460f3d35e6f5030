r"""Two-axis turntable: a programme of segments with exact kinematics, and its encoders.

The table (documented in ``docs/simulator.md``)
-----------------------------------------------
The *outer* axis is horizontal and fixed to the base; the *inner* axis is
carried by the outer gimbal, perpendicular to the outer axis (vertical when the
outer angle is zero); the faceplate ``f`` turns on the inner axis.  With ``alpha``
the outer and ``beta`` the inner angle,

.. math::

    C_{nf} = C_{n0}\, R_x(\alpha)\, R_z(\beta),

where ``C_n0`` is the (fixed) base: ``R_z(azimuth)``, so that at
``alpha = beta = 0`` the faceplate axes are ``x`` along the outer axis (East for
azimuth 0), ``z`` Up.  Then, exactly,

.. math::

    \omega_{nf}^f = [\dot\alpha\cos\beta,\; -\dot\alpha\sin\beta,\; \dot\beta],

    \dot\omega_{nf}^f = [\ddot\alpha\cos\beta - \dot\alpha\dot\beta\sin\beta,\;
                         -\ddot\alpha\sin\beta - \dot\alpha\dot\beta\cos\beta,\;
                         \ddot\beta].

Why this geometry: it can hold *any* instrument axis horizontal and turn about
it.  With the IMU bolted with ``C_fb = I``: ``beta = 0`` puts ``x`` on the outer
axis (turn ``alpha`` = turn about ``x``); ``beta = 90 deg`` puts ``-y`` on it
(turn about ``y``); ``alpha = 90 deg`` lays the inner axis, which is ``z``,
horizontal (turn ``beta`` = turn about ``z``).

Programme
---------
A programme is a sequence of segments on the IMU sample grid (every boundary is
an integer number of sample periods from the start, so no quadrature interval
straddles a boundary): a *dwell*, or a *move* of one axis by a given angle with
cosine ramps,

.. math::

    \dot\theta(u) = \tfrac{w}{2}(1 - \cos(\pi u / T_r)) \;(0 \le u < T_r),\quad
    w \;(\text{cruise, } T_c),\quad
    \tfrac{w}{2}(1 + \cos(\pi u' / T_r)) \;(\text{ramp down}),

so the rate is continuous with a continuous angular acceleration
(``w pi / (2 T_r) sin(pi u / T_r)``), and the angle, rate and acceleration are
analytic at any time.  ``w = angle / (T_r + T_c)`` with ``T_r`` and ``T_c``
rounded to whole sample periods, so the move turns exactly by ``angle``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from graph_calib.navigation.rotations import dcm_to_quat
from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

OUTER, INNER = 0, 1
_DWELL = -1


def rot_z(a):
    """``R_z(a)``, shape (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0] = c
    R[..., 0, 1] = -s
    R[..., 1, 0] = s
    R[..., 1, 1] = c
    R[..., 2, 2] = 1.0
    return R


@dataclass(frozen=True)
class TableProgram:
    """A compiled turntable programme (build it with :class:`ProgramBuilder`).

    Attributes
    ----------
    rate_hz : float
        IMU sample rate; every segment boundary is ``tick / rate_hz``.
    axis : ndarray of int, shape (S,)
        ``OUTER`` (0), ``INNER`` (1) or -1 for a dwell.
    start_tick, ramp_ticks, cruise_ticks : ndarray of int, shape (S,)
    angle : ndarray, shape (S,)
        Signed angle of each move, rad (0 for a dwell).
    angles0 : ndarray, shape (S, 2)
        ``(alpha, beta)`` at the start of each segment, rad.
    n_ticks : int
        Length of the programme in sample periods.
    """

    rate_hz: float
    axis: np.ndarray
    start_tick: np.ndarray
    ramp_ticks: np.ndarray
    cruise_ticks: np.ndarray
    angle: np.ndarray
    angles0: np.ndarray
    n_ticks: int

    @property
    def duration(self):
        """Length of the programme, s."""
        return self.n_ticks / self.rate_hz

    @property
    def final_angles(self):
        """``(alpha, beta)`` at the end, rad, shape (2,)."""
        a = self.angles0[-1].copy()
        if self.axis[-1] >= 0:
            a[self.axis[-1]] += self.angle[-1]
        return a

    def _locate(self, t):
        t = np.asarray(t, dtype=float)
        start = self.start_tick / self.rate_hz
        idx = np.clip(np.searchsorted(start, t, side="right") - 1, 0, start.size - 1)
        u = t - start[idx]
        return idx, u

    def angles(self, t):
        """Table angles and their first two derivatives at times ``t``.

        Before the programme the table rests at its first angles, after it at its last.

        Parameters
        ----------
        t : array_like, shape (N,)
            Time, s.

        Returns
        -------
        ang, rate, acc : ndarray, shape (N, 2)
            ``(alpha, beta)`` in rad, rad/s, rad/s^2.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        idx, u = self._locate(t)
        ax = self.axis[idx]
        moving = ax >= 0
        Tr = np.where(moving, self.ramp_ticks[idx], 1) / self.rate_hz
        Tc = np.where(moving, self.cruise_ticks[idx], 0) / self.rate_hz
        D = 2.0 * Tr + Tc
        w = np.where(moving, self.angle[idx] / (Tr + Tc), 0.0)
        u = np.clip(u, 0.0, D)
        k = np.pi / Tr
        up = u < Tr
        down = u > Tr + Tc
        ud = u - Tr - Tc
        th = np.where(up, 0.5 * w * (u - np.sin(k * u) / k),
                      np.where(down, 0.5 * w * Tr + w * Tc + 0.5 * w * (ud + np.sin(k * ud) / k),
                               0.5 * w * Tr + w * (u - Tr)))
        rt = np.where(up, 0.5 * w * (1.0 - np.cos(k * u)),
                      np.where(down, 0.5 * w * (1.0 + np.cos(k * ud)), w))
        ac = np.where(up, 0.5 * w * k * np.sin(k * u),
                      np.where(down, -0.5 * w * k * np.sin(k * ud), 0.0))
        # outside a move's span (before the programme, after it) nothing moves
        inside = (t - self.start_tick[idx] / self.rate_hz >= 0.0) & (u < D)
        rt = np.where(inside, rt, 0.0)
        ac = np.where(inside, ac, 0.0)
        ang = self.angles0[idx].copy()
        rate = np.zeros_like(ang)
        acc = np.zeros_like(ang)
        rows = np.flatnonzero(moving)
        ang[rows, ax[rows]] += th[rows]
        rate[rows, ax[rows]] = rt[rows]
        acc[rows, ax[rows]] = ac[rows]
        return ang, rate, acc

    def is_static(self, t, *, margin=0.0):
        """Whether the table rests at ``t`` and during ``margin`` seconds either side, shape (N,)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.ones(t.shape, dtype=bool)
        for dt in (-margin, 0.0, margin) if margin > 0 else (0.0,):
            _, rate, _ = self.angles(t + dt)
            out &= np.all(rate == 0.0, axis=1)
        return out

    def segments(self):
        """Human-readable list of the segments (for summaries and docs)."""
        out = []
        for i in range(self.axis.size):
            start = self.start_tick[i] / self.rate_hz
            if self.axis[i] < 0:
                out.append(("dwell", start, self.cruise_ticks[i] / self.rate_hz, 0.0))
            else:
                dur = (2 * self.ramp_ticks[i] + self.cruise_ticks[i]) / self.rate_hz
                out.append(("outer" if self.axis[i] == OUTER else "inner", start, dur, float(self.angle[i])))
        return out


class ProgramBuilder:
    """Build a :class:`TableProgram` segment by segment.

    Parameters
    ----------
    rate_hz : float
        IMU sample rate: segment lengths are rounded to whole sample periods.
    alpha0, beta0 : float
        Initial outer and inner angles, rad.

    Examples
    --------
    >>> b = ProgramBuilder(100.0)
    >>> b.dwell(10.0); b.move(OUTER, np.pi / 2, rate=np.radians(20)); b.dwell(30.0)
    >>> p = b.build()
    >>> round(p.duration, 2), np.degrees(p.final_angles).round(6).tolist()
    (45.5, [90.0, 0.0])
    """

    def __init__(self, rate_hz, *, alpha0=0.0, beta0=0.0):
        self.rate_hz = float(rate_hz)
        self._segs = []
        self._tick = 0
        self._angles = np.array([float(alpha0), float(beta0)])

    @property
    def ticks(self):
        """Current length in sample periods."""
        return self._tick

    @property
    def time(self):
        """Current length, s."""
        return self._tick / self.rate_hz

    def dwell(self, seconds):
        """Rest for ``seconds`` (rounded to whole sample periods, at least one)."""
        n = max(1, int(round(seconds * self.rate_hz)))
        self._segs.append((_DWELL, self._tick, 0, n, 0.0, self._angles.copy()))
        self._tick += n

    def move_ticks(self, angle, *, rate, ramp=1.0):
        """Length in sample periods that :meth:`move` would take."""
        nr, nc = self._ramp_cruise(angle, rate, ramp)
        return 2 * nr + nc

    def _ramp_cruise(self, angle, rate, ramp):
        if not rate > 0:
            raise ValueError(f"rate must be positive, got {rate}")
        nominal = abs(angle) / rate  # = T_r + T_c
        nr = max(1, int(round(ramp * self.rate_hz)))
        total = max(1, int(round(nominal * self.rate_hz)))
        if total < nr:
            nr = total
        return nr, total - nr

    def move(self, axis, angle, *, rate, ramp=1.0):
        """Turn ``axis`` (``OUTER`` or ``INNER``) by ``angle`` rad at peak ``rate`` rad/s.

        ``ramp`` is the length of each cosine ramp, s.  The peak rate is adjusted
        (by less than one sample period's worth) so that the move turns exactly by
        ``angle`` on the sample grid.
        """
        if axis not in (OUTER, INNER):
            raise ValueError(f"axis must be OUTER (0) or INNER (1), got {axis!r}")
        if angle == 0.0:
            return
        nr, nc = self._ramp_cruise(angle, rate, ramp)
        self._segs.append((axis, self._tick, nr, nc, float(angle), self._angles.copy()))
        self._tick += 2 * nr + nc
        self._angles[axis] += angle

    def build(self):
        """The compiled :class:`TableProgram` (at least one segment)."""
        if not self._segs:
            self.dwell(1.0 / self.rate_hz)
        axis, start, ramp, cruise, angle, a0 = zip(*self._segs)
        return TableProgram(
            rate_hz=self.rate_hz, axis=np.array(axis, dtype=np.int64), start_tick=np.array(start, dtype=np.int64),
            ramp_ticks=np.array(ramp, dtype=np.int64), cruise_ticks=np.array(cruise, dtype=np.int64),
            angle=np.array(angle, dtype=float), angles0=np.array(a0, dtype=float), n_ticks=int(self._tick),
        )


@numba.njit(cache=True, parallel=True)
def _table_kernel_nb(ang, rate, acc, A, B, C_out, w_out, dw_out):
    for k in numba.prange(ang.shape[0]):
        ca, sa = np.cos(ang[k, 0]), np.sin(ang[k, 0])
        cb, sb = np.cos(ang[k, 1]), np.sin(ang[k, 1])
        M = np.empty((3, 3))
        M[0, 0] = cb
        M[0, 1] = -sb
        M[0, 2] = 0.0
        M[1, 0] = ca * sb
        M[1, 1] = ca * cb
        M[1, 2] = -sa
        M[2, 0] = sa * sb
        M[2, 1] = sa * cb
        M[2, 2] = ca
        AM = np.zeros((3, 3))
        for i in range(3):
            for j in range(3):
                acc_ij = 0.0
                for m in range(3):
                    acc_ij += A[i, m] * M[m, j]
                AM[i, j] = acc_ij
        for i in range(3):
            for j in range(3):
                acc_ij = 0.0
                for m in range(3):
                    acc_ij += AM[i, m] * B[m, j]
                C_out[k, i, j] = acc_ij
        da, db = rate[k, 0], rate[k, 1]
        dda, ddb = acc[k, 0], acc[k, 1]
        wf0 = da * cb
        wf1 = -da * sb
        wf2 = db
        dwf0 = dda * cb - da * db * sb
        dwf1 = -dda * sb - da * db * cb
        dwf2 = ddb
        # omega_nb_b = B^T omega_nf_f
        for j in range(3):
            w_out[k, j] = B[0, j] * wf0 + B[1, j] * wf1 + B[2, j] * wf2
            dw_out[k, j] = B[0, j] * dwf0 + B[1, j] * dwf1 + B[2, j] * dwf2


def _table_kernel(ang, rate, acc, A, B):
    """``C = A R_x(alpha) R_z(beta) B``, ``B^T omega_nf_f`` and ``B^T domega_nf_f`` for every row."""
    n = ang.shape[0]
    C = np.empty((n, 3, 3))
    w = np.empty((n, 3))
    dw = np.empty((n, 3))
    _table_kernel_nb(np.ascontiguousarray(ang), np.ascontiguousarray(rate), np.ascontiguousarray(acc),
                     np.ascontiguousarray(A, dtype=float), np.ascontiguousarray(B, dtype=float), C, w, dw)
    return C, w, dw


@dataclass(frozen=True)
class Kinematics:
    """Exact motion of the body ``b`` at some times (all rows per time).

    Attributes
    ----------
    C_nb : ndarray, shape (N, 3, 3)
    omega_nb_b : ndarray, shape (N, 3)
        Angular rate of ``b`` against ``n``, rad/s.
    domega_nb_b : ndarray, shape (N, 3)
        Its time derivative, rad/s^2 (in ``b``).
    acc_n, vel_n : ndarray, shape (N, 3), or None
        Acceleration and velocity of the rotation centre in ``n`` (None: at rest,
        as on a turntable).
    """

    C_nb: np.ndarray
    omega_nb_b: np.ndarray
    domega_nb_b: np.ndarray
    acc_n: np.ndarray | None = None
    vel_n: np.ndarray | None = None


class TurntableMotion:
    """The IMU on a two-axis turntable: ``C_nb = C_n0 R_x(alpha) R_z(beta) @ C_fb``.

    Parameters
    ----------
    program : TableProgram
    C_n0 : ndarray, shape (3, 3)
        Base of the table in ``n``.
    C_fb : ndarray, shape (3, 3)
        True mounting, ``C_fb_nominal @ Exp(mount)``.
    """

    has_table = True

    def __init__(self, program, *, C_n0=None, C_fb=None):
        self.program = program
        self.C_n0 = np.eye(3) if C_n0 is None else np.asarray(C_n0, dtype=float)
        self.C_fb = np.eye(3) if C_fb is None else np.asarray(C_fb, dtype=float)

    @property
    def duration(self):
        return self.program.duration

    def C_nf(self, t):
        """Faceplate attitude at ``t``, shape (N, 3, 3)."""
        ang, _, _ = self.program.angles(t)
        return _table_kernel(ang, np.zeros_like(ang), np.zeros_like(ang), self.C_n0, np.eye(3))[0]

    def table(self, t):
        """``C_nf`` (N, 3, 3), ``omega_nf_f`` (N, 3) and its derivative (N, 3) at ``t``."""
        ang, rate, acc = self.program.angles(t)
        return _table_kernel(ang, rate, acc, self.C_n0, np.eye(3))

    def kinematics(self, t):
        """:class:`Kinematics` of the body at ``t`` (the rotation centre rests)."""
        ang, rate, acc = self.program.angles(t)
        C_nb, w, dw = _table_kernel(ang, rate, acc, self.C_n0, self.C_fb)
        return Kinematics(C_nb=C_nb, omega_nb_b=w, domega_nb_b=dw)

    def is_static(self, t, *, margin=0.0):
        return self.program.is_static(t, margin=margin)


def encoder_readings(motion, *, t_end, rate_hz=10.0, time_lag=0.0, noise_rad=0.0, rng=None,
                     valid="static", settle_s=0.2):
    """Turntable encoder readings stamped on the IMU clock.

    A reading stamped ``t`` shows the faceplate at ``t - time_lag`` (the truth
    ``time_lag.table``).  The encoder noise (``noise_rad``, one sigma) is added
    to the two axis angles, which is what encoders read.

    Parameters
    ----------
    motion : TurntableMotion
    t_end : float
        Last IMU sample time, s; readings at ``j / rate_hz`` for ``j = 1, 2, ...`` up to it.
    rate_hz : float
    time_lag : float
        s.
    noise_rad : float
    rng : numpy.random.Generator
        Needed when ``noise_rad > 0``.
    valid : {"static", "all"}
        ``"static"``: a reading is valid when the table rests at ``t - time_lag``
        and ``settle_s`` either side (as on the BINS-RT bench); ``"all"``: every reading.
    settle_s : float

    Returns
    -------
    t : ndarray, shape (M,)
    q_nf : ndarray, shape (M, 4)
    valid : ndarray of bool, shape (M,)
    """
    m = int(np.floor(t_end * rate_hz + 1e-9))
    t = np.arange(1, m + 1) / rate_hz
    ts = t - time_lag
    ang, _, _ = motion.program.angles(ts)
    if noise_rad > 0:
        ang = ang + noise_rad * rng.standard_normal(ang.shape)
    q = dcm_to_quat(_table_kernel(ang, np.zeros_like(ang), np.zeros_like(ang), motion.C_n0, np.eye(3))[0])
    if valid == "all":
        ok = np.ones(m, dtype=bool)
    elif valid == "static":
        ok = motion.program.is_static(ts, margin=settle_s)
    else:
        raise ValueError(f"valid must be 'static' or 'all', not {valid!r}")
    return t, q, ok


def encoder_axes_f(motion, t, *, time_lag=0.0):
    """The two axes the encoders read, as unit vectors in the faceplate frame, at reading times ``t``.

    With ``C_nf = C_n0 R_x(alpha) R_z(beta)`` an outer-angle error turns the faceplate about
    ``R_z(beta)^T e_x = [cos beta, -sin beta, 0]`` and an inner-angle error about ``e_z``; nothing turns
    it about their cross product.

    Returns
    -------
    ndarray, shape (M, 2, 3)
        Outer axis, inner axis.
    """
    ang, _, _ = motion.program.angles(np.asarray(t, dtype=float) - time_lag)
    b = ang[:, 1]
    axes = np.zeros((b.size, 2, 3))
    axes[:, 0, 0] = np.cos(b)
    axes[:, 0, 1] = -np.sin(b)
    axes[:, 1, 2] = 1.0
    return axes


__all__ = ["OUTER", "INNER", "rot_z", "TableProgram", "ProgramBuilder", "Kinematics",
           "TurntableMotion", "encoder_readings", "encoder_axes_f"]
