"""The rate and angular acceleration of a gyro record at an instant, from local fits of its integrated angle.

What the factors need at instants that fall between samples: :func:`local_rates` fits a polynomial to the
accumulated angle around each instant (a keyframe boundary, a table reading) and chooses the window by the
intersection of confidence intervals, so that a ring-laser gyro's quantization does not reach the lever-arm
term at rest while a turn's ramps are followed; :func:`boundary_rate_correction` is the four-sample value at a
keyframe boundary from the interval means.  :class:`graph_calib.model.record.PreparedRecord` calls both once
per record.
"""

from __future__ import annotations

import numpy as np

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


__all__ = ["boundary_rate_correction", "local_rates", "RATE_FIT_HALF_WINDOWS_S", "READING_FIT_HALF_WINDOWS_S",
           "RATE_FIT_DEGREE", "RATE_FIT_ICI", "RATE_FIT_FLOOR_RAD"]
