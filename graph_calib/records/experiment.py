"""In-memory experiment and result containers shared by I/O, simulator and solvers.

:class:`Experiment` mirrors the experiment file of ``data-format.md`` one to one;
:class:`Result` mirrors the result file.  Reading, writing and validation live in
:mod:`graph_calib.io`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Table:
    """Turntable encoder readings.

    Attributes
    ----------
    t : ndarray, shape (M,)
        Reading time on the IMU clock, s, strictly increasing.
    q_nf : ndarray, shape (M, 4)
        Faceplate attitude, scalar-first unit quaternions.
    valid : ndarray of bool, shape (M,)
        Whether the reading may be used.
    q_fb_nominal : ndarray, shape (4,)
        Nominal mounting of the IMU on the faceplate.
    axes_f : ndarray, shape (M, A, 3), or None
        The table's axes (unit vectors in ``f``) at each reading, when known: set only for a bench
        program simulated without noise (``predict`` on a program), never read from or written to a
        file; the model takes the reading noise about them (:mod:`graph_calib.model.encoder_noise`).
    """

    t: np.ndarray
    q_nf: np.ndarray
    valid: np.ndarray
    q_fb_nominal: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    axes_f: np.ndarray | None = None


@dataclass(frozen=True)
class Experiment:
    """One experiment (one temperature subrange) as the bench recorded it.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample time, s, strictly increasing.
    dtheta : ndarray, shape (N, 3)
        Raw gyro angle increments over ``(t[k-1], t[k]]``, rad, in ``b`` axes.
    dv : ndarray, shape (N, 3)
        Raw accelerometer velocity increments over the same intervals, m/s.
    temperature : ndarray, shape (N, K)
        Temperature channels, degC.
    temperature_names : tuple of str
        Names of the K channels.
    temperature_map : ndarray of int, shape (6,)
        Channel of gyro x, y, z and accel x, y, z.
    rate_hz : float
        Nominal sample rate; the first sample covers ``(t[0] - 1/rate_hz, t[0]]``.
    latitude_rad, gravity_mps2 : float
        Bench latitude and local gravity magnitude.
    imu_id, description : str
    table : Table or None
        Encoder readings, absent for hand-held sessions.
    source : str
        Where the experiment came from (file path), for messages.
    segment : ndarray of int, shape (N,), or None
        Segment of each sample, non-decreasing (``/imu/segment``): a record cut
        together from separate pieces has one segment per piece, and attitude is
        never assumed continuous across a segment boundary.  None: one segment.
    """

    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    temperature: np.ndarray
    temperature_names: tuple
    temperature_map: np.ndarray
    rate_hz: float
    latitude_rad: float
    gravity_mps2: float
    imu_id: str = ""
    description: str = ""
    table: Table | None = None
    source: str = ""
    segment: np.ndarray | None = None

    @property
    def n_samples(self):
        return int(self.t.shape[0])

    @property
    def n_segments(self):
        """Number of segments (1 without ``segment``).

        Each segment gets its own initial attitude in the model (docs/model.md, "Segments").
        """
        if self.segment is None:
            return 1
        return 1 + int(np.count_nonzero(np.diff(self.segment)))

    def segment_bounds(self):
        """``[(start, stop), ...]``: the sample ranges ``start:stop`` of the segments, in order."""
        if self.segment is None:
            return [(0, self.n_samples)]
        cuts = (np.flatnonzero(np.diff(self.segment)) + 1).tolist()
        return list(zip([0] + cuts, cuts + [self.n_samples]))

    @property
    def dt(self):
        """Length of each sample interval, s, shape (N,).

        ``t[k] - t[k-1]``, and the nominal period ``1 / rate_hz`` at the first
        sample and at the first sample of each segment (a piece's first sample
        covers one period, not the gap before it).
        """
        dt = np.empty_like(self.t)
        dt[0] = 1.0 / self.rate_hz
        dt[1:] = np.diff(self.t)
        if self.segment is not None:
            dt[1:][np.diff(self.segment) != 0] = 1.0 / self.rate_hz
        return dt

    def sensor_temperatures(self):
        """Temperature of each of the six sensors (gyro x y z, accel x y z), degC, shape (N, 6)."""
        return self.temperature[:, np.asarray(self.temperature_map, dtype=int)]

    def default_t_ref(self):
        """Mean over the experiment of the six sensors' temperatures, degC (model.md)."""
        return float(np.mean(self.sensor_temperatures()))

    def slice(self, start, stop):
        """The samples ``start:stop`` (and the table readings in their time span) as a new experiment."""
        from dataclasses import replace

        table = self.table
        if table is not None:
            t0 = self.t[start] - (self.t[start] - self.t[start - 1] if start > 0 else 1.0 / self.rate_hz)
            t1 = self.t[stop - 1]
            m = (table.t > t0) & (table.t <= t1)
            table = Table(table.t[m], table.q_nf[m], table.valid[m], table.q_fb_nominal,
                          None if table.axes_f is None else table.axes_f[m])
        return replace(
            self, t=self.t[start:stop], dtheta=self.dtheta[start:stop], dv=self.dv[start:stop],
            temperature=self.temperature[start:stop], table=table,
            segment=None if self.segment is None else self.segment[start:stop],
        )


@dataclass(frozen=True)
class Result:
    """A solver's (or a simulator's truth) conclusion about one experiment.

    Attributes
    ----------
    source : str
        Experiment file name.
    solver : str
        a registered solver's name (:mod:`graph_calib.solvers.registry`) or ``"truth"``.
    t_ref_degC : float
        Reference temperature of the temperature-dependent parameters.
    temperature_range_degC : tuple of float
        Lowest and highest sensor temperature of the experiment.
    effects : tuple of str
        Parameter names modelled.
    values : dict
        ``{flat element name: value}``, SI.
    sigmas : dict or None
        ``{flat element name: one sigma}``; None for truth.
    covariance_names : tuple of str or None
    covariance : ndarray or None, shape (P, P)
    residuals : dict
        The solver's own fit statistics (free form, JSON-serialisable).
    extra : dict
        Further top-level keys (priors used, options), JSON-serialisable.
    """

    source: str
    solver: str
    t_ref_degC: float
    temperature_range_degC: tuple
    effects: tuple
    values: dict
    sigmas: dict | None = None
    covariance_names: tuple | None = None
    covariance: np.ndarray | None = None
    residuals: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
