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
    mode='interp')``, checked in tests/model/test_model.py): inside, the slope of the
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


def boundary_rate_correction(w_mean, k0, *, segment_keys=None):
    """Correction from the two-sample mean to the angular rate at each keyframe boundary.

    The lever-arm term needs the rate at a boundary instant, but the data are
    interval means.  The mean of the two adjacent samples is off by ``h^2/6``
    times the rate's second derivative (at a turn's cosine ramp 3e-5 rad/s, i.e.
    0.3 sigma of a navigation-grade gravity factor with a 0.15 m lever arm); the
    four-sample value ``(-m[-2] + 7 m[-1] + 7 m[0] - m[1]) / 12`` is exact for
    cubics and also where a ramp starts exactly at the boundary.  At the ends of
    the record the first (last) sample is extrapolated linearly.  The correction
    is a property of the data: its dependence on the calibration is of the order
    of a scale error times itself and is left out.

    Parameters
    ----------
    w_mean : ndarray, shape (N, 3)
        Interval-mean rates of equally spaced samples, rad/s.
    k0 : ndarray of int, shape (K+1,)
        First sample of each keyframe, and N.
    segment_keys : ndarray of int, optional
        Keyframes that start a segment (``/imu/segment``): no correction there (the four samples
        would straddle the cut).

    Returns
    -------
    ndarray, shape (K+1, 3)
        Add to ``[m[0] of keyframe 0, (m[-1] + m[0]) / 2 at inner boundaries, m[-1] of the last]``.
    """
    w = np.asarray(w_mean, dtype=float)
    b = np.asarray(k0)
    n = w.shape[0]
    fix = np.zeros((b.size, 3))
    inner = np.arange(1, b.size - 1)
    ok = (b[inner] >= 2) & (b[inner] + 1 < n)
    if segment_keys is not None:
        ok &= ~np.isin(inner, np.asarray(segment_keys))
    ok = inner[ok]
    j = b[ok]
    fix[ok] = (-w[j - 2] + w[j - 1] + w[j] - w[j + 1]) / 12.0
    if n >= 2:
        fix[0] = 0.5 * (w[0] - w[1])
        fix[-1] = 0.5 * (w[n - 1] - w[n - 2])
    return fix


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


#: Half-widths of the local fits that give the rate and angular acceleration at an instant (a keyframe
#: boundary, a table reading), s, shortest first (:func:`local_rates`).
RATE_FIT_HALF_WINDOWS_S = (0.05, 0.1, 0.2, 0.4, 0.8, 1.6)
#: The same at a table reading: its rate tells readings at rest from readings in motion and turns the lag,
#: neither of which needs the long windows (a 3-h record's 10 Hz readings: 0.1 million instants).
READING_FIT_HALF_WINDOWS_S = (0.05, 0.1)
#: Degree of those fits' polynomial in the angle (exact for a cubic rate).
RATE_FIT_DEGREE = 4
#: Half-width of the confidence intervals of the window choice, in standard deviations.
RATE_FIT_ICI = 3.0
#: Smallest angle scatter the window choice assumes, rad (noise-free data: only exact agreement counts).
RATE_FIT_FLOOR_RAD = 1e-11


def local_rates(dtheta, t, dt, *, bounds, t_eval, segment, half_windows_s=RATE_FIT_HALF_WINDOWS_S,
                degree=RATE_FIT_DEGREE, ici=RATE_FIT_ICI):
    r"""Angular rate and acceleration at the instants ``t_eval`` from a local fit of the integrated angle.

    A gyro's increments are exact integrals of the rate plus the sensor's errors.  The accumulated angle
    ``Theta`` at the sample ends is fitted, per axis, by least squares with a polynomial of ``degree``
    in time over the ``2 m + 1`` sample ends nearest each instant (the window moved inside the segment
    at its ends); the fit's first and second derivatives at the instant are the rate and the angular
    acceleration.  The window is chosen per instant among ``half_windows_s`` by the intersection of
    confidence intervals (Katkovnik's ICI rule), axis by axis: the longest whose rate lies, with every shorter one's,
    within ``ici`` standard deviations of a common value, the standard deviations those of the fits'
    rate for the angle scatter of the segment (the median of the shortest fits' residual variance).
    At rest and at a constant rate every window agrees and the longest is taken; near a ramp the
    longer fits' bias shows and a short one is kept.

    Why not the raw samples: a ring-laser gyro's angle carries a white quantization error ``Q`` (rad)
    at every sample end, so a sample's mean rate scatters by ``sqrt(2) Q / h`` (3.4e-4 rad/s for 0.5
    arcsec at 100 Hz) and the four-sample boundary value of :func:`boundary_rate_correction` by
    ``0.95 Q / h``; a quartic fit over +-0.1 s scatters by ``0.09 Q / h``, over +-0.8 s by ``0.004 Q / h``.
    That scatter is not only noise: the lever-arm term's Jacobian is the rate itself, and a rate that
    scatters at rest (where the true lever-arm term is zero) gives the lever arm information the record
    does not hold (errors in the variables: with the +-0.1 s fit alone, 0.5 arcsec made ``lever_arm.x``'s
    sigma 0.02 m against 0.16 m without quantization, and the estimate 5.7 of those sigmas off).  The
    quartic +-0.1 s fit's bias on the simulated table's 1-s cosine ramps is at most 4.4e-6 rad/s at a
    keyframe boundary (a quadratic fit of the same width: 2e-3 rad/s).  The fit is of the raw rate; its
    calibration dependence (a scale error times the fit's correction) is left out.

    Parameters
    ----------
    dtheta : ndarray, shape (N, 3)
        Gyro increments, rad.
    t, dt : ndarray, shape (N,)
        Sample end times and lengths, s.
    bounds : ndarray of int, shape (S, 2)
        ``(start, stop)`` samples of the segments; no window crosses a boundary.
    t_eval : ndarray, shape (B,)
        Instants, s.
    segment : ndarray of int, shape (B,)
        The segment of each instant.
    half_windows_s : sequence of float
        Candidate half-widths, s, increasing.
    degree : int
    ici : float

    Returns
    -------
    rate : ndarray, shape (B, 3)
        rad/s.
    accel : ndarray, shape (B, 3)
        rad/s^2.
    sigma : ndarray, shape (B, 3)
        The chosen fits' rate scatter for the segment's angle scatter, rad/s.
    """
    t_eval = np.asarray(t_eval, dtype=float)
    segment = np.asarray(segment, dtype=np.int64)
    B = t_eval.size
    rate, accel, sigma = np.zeros((B, 3)), np.zeros((B, 3)), np.zeros((B, 3))
    for s, (a, b) in enumerate(np.asarray(bounds).reshape(-1, 2)):
        sel = np.flatnonzero(segment == s)
        if sel.size == 0:
            continue
        nodes_t = np.concatenate([[t[a] - dt[a]], t[a:b]])               # the segment's sample ends
        theta = np.vstack([np.zeros(3), np.cumsum(dtheta[a:b], axis=0)])
        n = nodes_t.size
        h = float(np.median(dt[a:b]))
        ms = sorted({min(max(1, int(round(w / h))), (n - 1) // 2) for w in half_windows_s})
        if ms[-1] < 1:                                                    # one sample: its mean, no slope
            rate[sel] = dtheta[a] / dt[a]
            continue
        te = t_eval[sel]
        centre = np.clip(np.searchsorted(nodes_t, te), 0, n - 1)
        before = np.clip(centre - 1, 0, n - 1)
        centre = np.where(np.abs(nodes_t[before] - te) < np.abs(nodes_t[centre] - te), before, centre)
        uniform = bool(np.ptp(dt[a:b]) <= 1e-9 * h)
        # the segment's angle scatter, from the residuals of the shortest fit with some degrees of freedom
        # left (median: ramps and steps aside)
        dof = [2 * m + 1 - min(int(degree), 2 * m) - 1 for m in ms]
        judge = next((i for i, d in enumerate(dof) if d >= _SCATTER_DOF), len(ms) - 1)
        fits = [_poly_fit(nodes_t, theta, te, centre, m, min(int(degree), 2 * m), h, uniform=uniform,
                          want_resid=(i == judge)) for i, m in enumerate(ms)]
        scatter = float(np.sqrt(max(np.median(fits[judge][3]) if dof[judge] > 0 else 0.0, RATE_FIT_FLOOR_RAD**2)))
        # axis by axis: during a turn about one axis the other two keep the long windows
        r_out, a_out = fits[0][0].copy(), fits[0][1].copy()
        g_out = np.repeat(fits[0][2][:, None], 3, axis=1)
        lo = fits[0][0] - ici * scatter * fits[0][2][:, None]
        hi = fits[0][0] + ici * scatter * fits[0][2][:, None]
        alive = np.ones((sel.size, 3), dtype=bool)
        for r_j, a_j, g_j, _ in fits[1:]:
            lo = np.maximum(lo, r_j - ici * scatter * g_j[:, None])
            hi = np.minimum(hi, r_j + ici * scatter * g_j[:, None])
            alive &= lo <= hi
            r_out[alive], a_out[alive] = r_j[alive], a_j[alive]
            g_out[alive] = np.broadcast_to(g_j[:, None], alive.shape)[alive]
        rate[sel], accel[sel], sigma[sel] = r_out, a_out, scatter * g_out
    return rate, accel, sigma


def _poly_fit(nodes_t, theta, te, centre, m, p, h, *, uniform, want_resid):
    """One window of :func:`local_rates`: rate (b, 3), acceleration (b, 3), the rate's standard deviation
    per unit angle scatter (b,), and the residual variance per axis-mean (b,) of the fit (zeros unless
    ``want_resid``).  On equally spaced samples (``uniform``) the fit is a fixed linear filter of the window
    (its polynomial in the window's own coordinate, evaluated at the instant); otherwise each instant's
    normal equations are solved."""
    n = nodes_t.size
    width = 2 * m + 1
    lo = np.clip(centre - m, 0, n - width)
    scale = m * h
    b = te.size
    rate, accel = np.zeros((b, 3)), np.zeros((b, 3))
    gain, resid = np.zeros(b), np.zeros(b)
    powers = np.arange(p + 1)
    if uniform:
        V = ((np.arange(width) - m) / m)[:, None] ** powers                # (W, p+1), window-centred
        N_inv = np.linalg.inv(V.T @ V)
        P = N_inv @ V.T                                                    # (p+1, W)
    for c0 in range(0, b, _FIT_BLOCK):
        blk = slice(c0, c0 + _FIT_BLOCK)
        idx = lo[blk, None] + np.arange(width)                            # (b, W)
        y = theta[idx] - theta[idx[:, m]][:, None, :]                       # (b, W, 3)
        if uniform:
            v = (te[blk] - nodes_t[lo[blk] + m]) / scale                   # the instant in window units
            coef = np.einsum("pw,bwc->bpc", P, y)                          # (b, p+1, 3)
            d1 = powers[None, :] * v[:, None] ** np.maximum(powers - 1, 0)[None, :]
            d2 = (powers * (powers - 1))[None, :] * v[:, None] ** np.maximum(powers - 2, 0)[None, :]
            rate[blk] = np.einsum("bp,bpc->bc", d1, coef) / scale
            accel[blk] = np.einsum("bp,bpc->bc", d2, coef) / scale**2
            gain[blk] = np.sqrt(np.einsum("bp,pq,bq->b", d1, N_inv, d1)) / scale
            if want_resid:
                res = y - np.einsum("wp,bpc->bwc", V, coef)
                resid[blk] = np.mean(res**2, axis=(1, 2)) * width / max(width - p - 1, 1)
            continue
        u = (nodes_t[idx] - te[blk, None]) / scale                         # instant at u = 0
        Vb = u[..., None] ** powers                                        # (b, W, p+1)
        Nb = np.linalg.inv(np.swapaxes(Vb, 1, 2) @ Vb)                     # (b, p+1, p+1)
        coef = Nb @ (np.swapaxes(Vb, 1, 2) @ y)                            # (b, p+1, 3)
        rate[blk] = coef[:, 1] / scale
        if p >= 2:
            accel[blk] = 2.0 * coef[:, 2] / scale**2
        gain[blk] = np.sqrt(Nb[:, 1, 1]) / scale
        if want_resid:
            res = y - Vb @ coef
            resid[blk] = np.mean(res**2, axis=(1, 2)) * width / max(width - p - 1, 1)
    return rate, accel, gain, resid


#: Least residual degrees of freedom of the fit whose residuals give the angle scatter in :func:`local_rates`.
_SCATTER_DOF = 10
#: Instants fitted at a time in :func:`local_rates` (bounds its (b, W, 3) temporaries).
_FIT_BLOCK = 2048


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
        Whether each keyframe is static.
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

    def encoder_noise_frame(self, encoder_noise):
        """The readings' :class:`~graph_calib.model.encoder_noise.NoiseFrame` for a declared noise (rad), cached."""
        key = float(encoder_noise)
        if key not in self._noise_frames:
            self._noise_frames[key] = noise_frame(self.reading_scatter, self.reading_axes_b, encoder_noise=key)
        return self._noise_frames[key]

    def _static_keyframes(self, static_mask):
        if static_mask is None:
            self.static_key = np.ones(self.n_keyframes, dtype=bool)
        else:
            m = np.asarray(static_mask, dtype=bool)
            self.static_key = np.logical_and.reduceat(m, self.k0[:-1])

    def earth_turn(self, T):
        """``E(T) = Exp(-omega_ie_n T)``, shape (..., 3, 3)."""
        T = np.asarray(T, dtype=float)
        return exp_so3(-T[..., None] * self.omega_ie_n)


__all__ = ["PreparedRecord", "boundary_rate_correction", "local_rates", "RATE_FIT_HALF_WINDOWS_S", "RATE_FIT_DEGREE"]
