"""One experiment's data prepared once for the factors, whatever parameters are estimated.

A :class:`PreparedRecord` holds what the factors need from the samples and does not depend on the
layout (which parameters are estimated): rates and specific forces with their slope-limited
derivatives, sensor temperatures and their rates, keyframes, the valid table readings.  The
diagnosis builds it once and reuses it for every layout it tries.
"""

from __future__ import annotations

import numpy as np

from graph_calib.constants import omega_ie_n as _omega_ie_n
from graph_calib.model.encoder_noise import dwell_scatter, noise_frame
from graph_calib.model.local_rates import READING_FIT_HALF_WINDOWS_S, boundary_rate_correction, local_rates
from graph_calib.navigation.rotations import exp_so3, quat_to_dcm


def _limited_derivative(y, t):
    """Time derivative of sample means ``y`` (N, 3) at each sample, slope-limited (minmod).

    Where the signal varies linearly both one-sided differences agree; at a jump
    (a rate step) one of them is zero and so is the estimate, instead of the
    spurious spike a central difference puts on both neighbours of the jump.
    """
    d = np.diff(y, axis=0) / np.diff(t)[:, None]
    back = np.vstack([d[:1], d])
    fwd = np.vstack([d, d[-1:]])
    same = np.sign(back) == np.sign(fwd)
    return np.where(same, np.sign(back) * np.minimum(np.abs(back), np.abs(fwd)), 0.0)


def _quadratic_slope(y, win, delta):
    """Slope of the least-squares quadratic over a centred window of ``win`` samples (odd), per row of ``y``.

    Savitzky-Golay's first derivative of order 2 with scipy's ``mode='interp'``
    (``scipy.signal.savgol_filter(y, win, 2, deriv=1, delta=delta, axis=0,
    mode='interp')``, checked in tests/records/test_record_slope.py): inside, the slope of the
    quadratic through the window, ``sum(k y_{i+k}) / (delta sum k^2)``; in the
    first and last ``win // 2`` rows, the slope at each row of the quadratic fitted
    to the first (last) ``win`` rows.  Written here so that the solvers do not
    import ``scipy.signal`` (and with it ``scipy.stats``: most of ``graph-calib
    calibrate``'s start-up, docs/performance.md).

    Parameters
    ----------
    y : ndarray, shape (M, K)
        Series, ``M >= win``.
    win : int
        Odd window length, samples (at least 3).
    delta : float
        Sample spacing, s.

    Returns
    -------
    ndarray, shape (M, K)
        Slope, unit of ``y`` per s.
    """
    m = win // 2
    k = np.arange(-m, m + 1, dtype=float)
    c = k / (delta * np.sum(k * k))
    n = y.shape[0]
    out = np.empty_like(y)
    # interior: correlation with the slope coefficients (one pass per offset, vectorised over the rows)
    inner = np.zeros((n - 2 * m,) + y.shape[1:])
    for j in range(win):
        inner += c[j] * y[j:n - 2 * m + j]
    out[m:n - m] = inner
    # edges: the quadratic through the first (last) window, its slope at each edge row
    x = np.arange(win, dtype=float)
    V = np.vander(x, 3)                                   # columns x^2, x, 1
    P = np.linalg.pinv(V)                                 # (3, win): coefficients from the window
    D = np.column_stack([2 * x[:m], np.ones(m)]) @ P[:2]  # d/dx at rows 0..m-1
    out[:m] = D @ y[:win] / delta
    Dl = np.column_stack([2 * x[win - m:], np.ones(m)]) @ P[:2]
    out[n - m:] = Dl @ y[n - win:] / delta
    return out


def _moving_slope(y, dt, window_s):
    """Least-squares slope of ``y`` (N, K) over a centred window of about ``window_s``, per sample.

    Temperature channels are slow and often quantised, so a long window is wanted.
    The series is first averaged over blocks of about 1 s, the quadratic
    Savitzky-Golay slope is taken on the block means, and it is interpolated back
    to the samples: O(N) and accurate for any smooth temperature.
    """
    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    per = max(1, int(round(1.0 / dt)))
    nb = n // per
    if nb < 7:
        if n < 2:
            return np.zeros_like(y)
        t = np.arange(n) * dt
        return np.broadcast_to(np.polyfit(t, y, 1)[0], y.shape).copy()
    yb = y[: nb * per].reshape(nb, per, -1).mean(axis=1)
    tb = (np.arange(nb) * per + 0.5 * (per - 1)) * dt
    win = int(round(window_s / (per * dt))) | 1
    win = max(5, min(win, nb if nb % 2 else nb - 1))
    sb = _quadratic_slope(yb, win, per * dt)
    t = np.arange(n) * dt
    return np.column_stack([np.interp(t, tb, sb[:, i]) for i in range(y.shape[1])])


def _grid(a, b, per):
    """Keyframe starts in ``[a, b)``: every ``per`` samples, a last piece shorter than ``per / 2`` joined to the one before."""
    k0 = np.arange(a, b, per, dtype=np.int64)
    if b - k0[-1] < max(1, per // 2) and k0.size > 1:
        k0 = k0[:-1]
    return k0


def _rest_cuts(runs, segment_bounds, per):
    """Samples where a keyframe must start: both ends of each rest that holds no whole keyframe of the grid.

    The grid starts at each segment's first sample and again at each cut; rests ``runs`` (R, 2) in order.
    """
    cuts = []
    for a, b in segment_bounds:
        origin = a
        for s, e in runs[(runs[:, 0] >= a) & (runs[:, 1] <= b)]:
            first = origin + -(-(s - origin) // per) * per        # the first grid start at or after s
            if first + per <= e:
                continue
            cuts += [int(s), int(e)]
            origin = int(e)
    return np.asarray(cuts, dtype=np.int64)


class PreparedRecord:
    """The data of one experiment cut into keyframes, ready for any layout.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    keyframe_s : float
        Keyframe interval, s.
    t_ref_degC : float, optional
        Reference temperature; default the mean of the six sensors' temperatures.
    static_mask : ndarray of bool, shape (N,), optional
        Samples known to be static; None: every keyframe counts as static.
    short_rests : array_like of int, shape (R, 2), optional
        The short rests (:func:`graph_calib.noise.rests.segment_static_parts`; static in ``static_mask``
        too).  One that holds no whole keyframe of the grid starts and ends on keyframe boundaries, so that
        it is one static keyframe of its own length (a hand holds a face 0.5-1.5 s); the grid of
        ``keyframe_s`` restarts at its end.  The other rests leave the grid as it is.

    Attributes
    ----------
    t_key : ndarray, shape (K+1,)
        Keyframe boundary times, s; ``T_key`` their intervals; ``k0`` their first samples (and N).
    w_raw, f_raw : ndarray, shape (N, 3)
        Raw interval-mean angular rate (rad/s) and specific force (m/s^2); ``dw_raw``, ``df_raw``
        their slope-limited time derivatives.
    temperatures : ndarray, shape (N, 6)
        Sensor temperatures (gyro x, y, z, accel x, y, z), degC; ``dTg``, ``dTa`` their offsets from
        ``t_ref_degC`` per triad (N, 3), ``dTdtg``, ``dTdta`` their rates, degC/s.
    reading_* : ndarray
        The valid table readings inside the record (M of them): ``reading_t`` time, ``reading_sample``
        the last sample ending before it, ``reading_interval`` the sample interval holding it,
        ``reading_key`` its keyframe, ``reading_C_nf`` the faceplate attitude, and the data-only pieces
        of the encoder factor (``reading_dt``, ``reading_tau``, ``reading_alpha``, ``reading_phi_shape``,
        ``reading_f``, ``reading_w_nb_offset``, ``reading_E``, ``reading_C_nb_nominal``, ``reading_lo``);
        ``reading_scatter`` the static dwells' scatter and ``reading_axes_b`` the table's axes when known
        (:mod:`graph_calib.model.encoder_noise`, :meth:`encoder_noise_frame`).
    static_key : ndarray of bool, shape (K,)
        Whether each keyframe is static; ``static_known`` whether a static mask said so (without one every
        keyframe counts as static).
    segment_bounds : ndarray of int, shape (S, 2)
        ``(start, stop)`` samples of each segment (``/imu/segment``; one for a record without it);
        ``segment_keys`` (S,) the first keyframe of each (keyframes never span a boundary, and the last
        keyframe of a segment ends at its last sample: its ``T_key`` is its own); ``rotation_keys``
        (K - S + 1,) the keyframes whose end is the next one's start, i.e. those with a rotation factor.
    """

    #: A valid table reading counts as taken while the table turns above this rate
    #: against the level frame, rad/s (about 0.06 deg/s, 14 times the Earth rate).
    LAG_RATE_THRESHOLD = 1e-3

    def __init__(self, experiment, *, keyframe_s, t_ref_degC=None, static_mask=None, short_rests=None):
        self.experiment = experiment
        self.keyframe_s = float(keyframe_s)
        self.omega_ie_n = _omega_ie_n(experiment.latitude_rad)
        self.t_ref_degC = float(experiment.default_t_ref() if t_ref_degC is None else t_ref_degC)
        self.gravity = float(experiment.gravity_mps2)
        self._prepare_samples()
        self._prepare_keyframes(short_rests)
        self._prepare_table()
        self._static_keyframes(static_mask)
        self._prepare_reading_noise()

    @property
    def has_valid_readings(self):
        """Whether the record holds valid table readings."""
        return self.reading_sample.size > 0

    @property
    def readings_in_motion(self):
        """Whether a valid reading was taken while the table turned (above :attr:`LAG_RATE_THRESHOLD`)."""
        if not self.has_valid_readings:
            return False
        w_nb_b = self.w_raw[self.reading_interval] + self.reading_w_nb_offset   # raw rate against the level frame
        return bool(np.any(np.linalg.norm(w_nb_b, axis=1) > self.LAG_RATE_THRESHOLD))

    def _prepare_samples(self):
        e = self.experiment
        dt = e.dt
        self.dt = dt
        self.w_raw = e.dtheta / dt[:, None]
        self.f_raw = e.dv / dt[:, None]
        h = 1.0 / e.rate_hz
        # the segments (/imu/segment): sample ranges whose attitude is continuous; no derivative,
        # keyframe or rotation factor reaches across a boundary between two of them
        self.segment_bounds = np.asarray(e.segment_bounds(), dtype=np.int64).reshape(-1, 2)
        self.dw_raw = np.empty_like(self.w_raw)
        self.df_raw = np.empty_like(self.f_raw)
        for a, b in self.segment_bounds:
            if b - a < 2:
                self.dw_raw[a:b] = 0.0
                self.df_raw[a:b] = 0.0
                continue
            self.dw_raw[a:b] = _limited_derivative(self.w_raw[a:b], e.t[a:b])
            self.df_raw[a:b] = _limited_derivative(self.f_raw[a:b], e.t[a:b])
        T = e.sensor_temperatures()     # not kept: :attr:`temperatures` reads the experiment's again
        dT = T - self.t_ref_degC
        dTdt = _moving_slope(T, h, 60.0)
        self.dTg = np.ascontiguousarray(dT[:, :3])
        self.dTa = np.ascontiguousarray(dT[:, 3:])
        self.dTdtg = np.ascontiguousarray(dTdt[:, :3])
        self.dTdta = np.ascontiguousarray(dTdt[:, 3:])

    def _prepare_keyframes(self, short_rests):
        e = self.experiment
        n = e.n_samples
        per = max(1, int(round(self.keyframe_s * e.rate_hz)))
        runs = np.zeros((0, 2), dtype=np.int64) if short_rests is None else \
            np.asarray(short_rests, dtype=np.int64).reshape(-1, 2)
        cuts = _rest_cuts(runs[np.argsort(runs[:, 0])], self.segment_bounds, per)
        starts, seg_keys = [], []
        for a, b in self.segment_bounds:          # keyframes never span a segment boundary
            edges = np.unique(np.concatenate([[a, b], cuts[(cuts > a) & (cuts < b)]]))
            k0 = np.concatenate([_grid(s, t, per) for s, t in zip(edges[:-1], edges[1:])])
            seg_keys.append(sum(s.size for s in starts))
            starts.append(k0)
        self.k0 = np.append(np.concatenate(starts), n).astype(np.int64)
        self.n_keyframes = self.k0.size - 1
        #: keyframe index of each segment's first keyframe, (S,); 0 first
        self.segment_keys = np.asarray(seg_keys, dtype=np.int64)
        #: the keyframes whose end is the next one's start (no segment boundary between them), (K - S + 1,)
        cont = np.ones(self.n_keyframes, dtype=bool)
        cont[self.segment_keys[1:] - 1] = False
        self.rotation_keys = np.flatnonzero(cont).astype(np.int64)
        t_start = e.t - self.dt
        self.t_key = np.append(t_start[self.k0[:-1]], e.t[-1])  # time of each boundary, (K+1,)
        # the last keyframe of a segment ends at its last sample, not at the next segment's start
        self.T_key = np.diff(self.t_key)
        if self.segment_keys.size > 1:
            last = self.segment_keys[1:] - 1
            self.T_key[last] = e.t[self.k0[last + 1] - 1] - t_start[self.k0[last]]
        self.w_b_fix = self._boundary_rate_fix()

    def _boundary_rate_fix(self):
        """``w_b_fix`` (K+1, 3): from the two-sample mean (one sample at the record's ends) to the rate at
        each keyframe boundary of the local fit (:func:`local_rates`); at a segment's first boundary (the two
        samples straddle the cut) the correction of :func:`boundary_rate_correction` (none)."""
        e = self.experiment
        fix = boundary_rate_correction(self.w_raw, self.k0, segment_keys=self.segment_keys)
        K = self.n_keyframes
        keys = np.arange(K + 1)
        keep = ~np.isin(keys, self.segment_keys[1:])
        keys = keys[keep]
        seg = np.searchsorted(self.segment_keys, np.minimum(keys, K - 1), side="right") - 1
        rate, _, sigma = local_rates(e.dtheta, e.t, self.dt, bounds=self.segment_bounds, t_eval=self.t_key[keys],
                                     segment=seg)
        #: the boundary rates' scatter per axis (K+1, 3), rad/s (the lever-arm term's noise in the gravity factors)
        self.w_b_sigma = np.zeros((K + 1, 3))
        self.w_b_sigma[keys] = sigma
        w = self.w_raw
        base = np.empty((keys.size, 3))
        inner = (keys > 0) & (keys < K)
        base[inner] = 0.5 * (w[self.k0[keys[inner]] - 1] + w[self.k0[keys[inner]]])
        base[keys == 0] = w[0]
        base[keys == K] = w[-1]
        fix[keys] = rate - base
        return fix

    @property
    def temperatures(self):
        """Sensor temperatures (gyro x, y, z, accel x, y, z), degC, shape (N, 6).

        Formed from the experiment's channels when asked (reports, results): the factors read only
        ``dTg``, ``dTa`` and their rates, and a stored copy would hold another 52 MB per 3-h record.
        """
        return self.experiment.sensor_temperatures()

    @property
    def n_segments(self):
        """Number of segments (``/imu/segment``; 1 without it)."""
        return int(self.segment_keys.size)

    def _prepare_table(self):
        e = self.experiment
        tab = e.table
        self.has_table = tab is not None
        empty3 = np.zeros((0, 3))
        if tab is None or not np.any(tab.valid):
            self.reading_sample = np.zeros(0, dtype=np.int64)
            self.reading_t = np.zeros(0)
            self.reading_key = np.zeros(0, dtype=np.int64)
            self.reading_dt = np.zeros(0)
            self.reading_tau = np.zeros(0)
            self.reading_C_nf = np.zeros((0, 3, 3))
            self.reading_interval = np.zeros(0, dtype=np.int64)
            self.reading_f = empty3
            self.reading_alpha = empty3
            self.reading_phi_shape = empty3
            self.reading_quantization_gain = np.zeros(0)
            self.C_fb = np.eye(3) if tab is None else quat_to_dcm(tab.q_fb_nominal)
        else:
            tm = tab.t[tab.valid]
            q = tab.q_nf[tab.valid]
            j = np.searchsorted(e.t, tm, side="right") - 1
            keep = (j >= 0) & (tm <= e.t[-1])
            tm, q, j = tm[keep], q[keep], j[keep]
            self.reading_sample = j.astype(np.int64)
            self.reading_t = tm
            self.reading_key = (np.searchsorted(self.k0, j, side="right") - 1).astype(np.int64)
            self.reading_dt = tm - e.t[j]
            self.reading_tau = tm - self.t_key[self.reading_key]
            self.reading_C_nf = quat_to_dcm(q)
            nxt = np.minimum(j + 1, e.n_samples - 1)      # the sample interval holding t_m
            self.reading_interval = nxt.astype(np.int64)
            # Inside that interval the rate is taken linear, mean w (the increment over h) and slope
            # alpha: the turn from the sample end to the reading is w dt_m + alpha dt_m (dt_m - h) / 2
            # (the mean alone is off by alpha h^2/8, 1.5 arcsec, 0.75 sigma of a navigation-grade
            # encoder, in a table ramp, when readings are valid in motion).  The rate at the reading
            # (for the lag) and alpha are those of the local fit of the angle (local_rates): a sample's
            # own mean and the slope of its neighbours scatter by sqrt(2) Q / h and more under a
            # ring-laser gyro's quantization Q (readings at rest then looked as if taken in motion,
            # and the lag, estimated from that scatter, came out 60 sigma off)
            h = self.dt[nxt]
            seg = np.searchsorted(self.segment_keys, self.reading_key, side="right") - 1
            w_at, self.reading_alpha, _ = local_rates(e.dtheta, e.t, self.dt, bounds=self.segment_bounds, t_eval=tm,
                                                      segment=seg, half_windows_s=READING_FIT_HALF_WINDOWS_S)
            self.reading_phi_shape = self.reading_alpha * (0.5 * self.reading_dt * (self.reading_dt - h))[:, None]
            self.reading_f = self.f_raw[nxt]
            #: the share of the sample ends' angle errors in the attitude interpolated to the reading
            a = self.reading_dt / h
            self.reading_quantization_gain = (1.0 - a) ** 2 + a**2
            self.C_fb = quat_to_dcm(tab.q_fb_nominal)
            # the rate against the level frame at the reading (for the lag) is the calibrated interval
            # mean plus this: the fit's rate at the reading less the raw mean, minus the Earth rate in b
            # (from the readings' attitude)
            C_bn = np.swapaxes(self.reading_C_nf @ self.C_fb, 1, 2)
            self.reading_w_nb_offset = (w_at - self.w_raw[nxt]) - C_bn @ self.omega_ie_n
        if tab is None or not np.any(tab.valid):
            self.reading_w_nb_offset = empty3
        self.reading_lo = np.searchsorted(self.reading_sample, self.k0[:-1], side="left").astype(np.int64)
        # data-only pieces of the encoder factor, formed once: the Earth turn since the keyframe start,
        # the nominal faceplate-to-level attitude
        self.reading_E = self.earth_turn(self.reading_tau)
        self.reading_C_nb_nominal = self.reading_C_nf @ self.C_fb

    def _prepare_reading_noise(self):
        """The static dwells' scatter of the valid readings (:mod:`graph_calib.model.encoder_noise`)."""
        M = self.reading_sample.size
        tab = self.experiment.table
        if M:
            w_nb_b = self.w_raw[self.reading_interval] + self.reading_w_nb_offset
            at_rest = self.static_key[self.reading_key] & (np.linalg.norm(w_nb_b, axis=1) <= self.LAG_RATE_THRESHOLD)
        else:
            at_rest = np.zeros(0, dtype=bool)
        #: the dwells' scatter (:class:`graph_calib.model.encoder_noise.DwellScatter`); a dwell never
        #: spans a segment boundary (/imu/segment)
        segment = np.searchsorted(self.segment_keys, self.reading_key, side="right") - 1
        self.reading_scatter = dwell_scatter(self.reading_t, self.reading_C_nf, at_rest, C_fb=self.C_fb,
                                             group=segment)
        #: the table's axes in body axes at each reading (M, A, 3), when the experiment carries them
        self.reading_axes_b = None
        if M and tab.axes_f is not None:
            tm = tab.t[tab.valid]
            keep = np.isin(tm, self.reading_t)
            self.reading_axes_b = tab.axes_f[tab.valid][keep] @ self.C_fb
        self._noise_frames = {}
        # the gains of graph_calib.model.shared_gyro_noise for the last preintegration and noise (they depend on
        # nothing else): (weak reference to the preintegration, noise key, gains)
        self.shared_gyro_gains = None

    def encoder_noise_frame(self, encoder_noise):
        """The readings' :class:`~graph_calib.model.encoder_noise.NoiseFrame` for a declared noise (rad), cached."""
        key = float(encoder_noise)
        if key not in self._noise_frames:
            self._noise_frames[key] = noise_frame(self.reading_scatter, self.reading_axes_b, encoder_noise=key)
        return self._noise_frames[key]

    def _static_keyframes(self, static_mask):
        self.static_known = static_mask is not None
        if static_mask is None:
            self.static_key = np.ones(self.n_keyframes, dtype=bool)
        else:
            m = np.asarray(static_mask, dtype=bool)
            self.static_key = np.logical_and.reduceat(m, self.k0[:-1])

    def earth_turn(self, T):
        """``E(T) = Exp(-omega_ie_n T)``, shape (..., 3, 3)."""
        T = np.asarray(T, dtype=float)
        return exp_so3(-T[..., None] * self.omega_ie_n)


__all__ = ["PreparedRecord"]
