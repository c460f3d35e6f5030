r"""White rate noise beside a quantization: the Whittle likelihood of the rests' increments.

A ring-laser gyro's angle carries a white error ``Q`` at every sample end (IEEE Std 952 quantization), so
each increment of a rest is ``N w_j sqrt(tau0) + e_{j+1} - e_j``: white rate noise ``N`` plus the difference
of two quantization errors.  Its spectrum, per sample and at angular frequency ``omega`` (rad per sample), is

.. math::  S(\omega) = N^2 \tau_0 + 2 Q^2 (1 - \cos\omega),

flat for the white noise and vanishing at low frequency for the quantization.  At 100 Hz a navigation-grade
ring-laser gyro's per-sample scatter is some 1700 times ``N^2 tau0`` in variance: ``N`` shows only where
``2 Q^2 (1 - cos omega) < N^2 tau0``, below about 0.4 Hz, and in the Allan variance only beyond
``tau = sqrt(3) Q / N`` (about 50 s), longer than most rests.  A least-squares fit of the Allan terms
there leaves ``N`` to the curvature of a quantization-dominated curve (measured on the 6-min
``nav-subrange-short`` at 0.5 arcsec: ``N`` 0.93 of the simulated on average, 31 % of records more than 10 %
off).  The Whittle likelihood of the rests' periodograms uses every frequency with its own weight,
``-sum_k [log S(omega_k) + I_k / S(omega_k)]``, and is the efficient estimate of the two terms: its
information on ``N^2 tau0`` is ``L / (8 a^{3/2} b^{1/2})`` for ``L`` samples, ``a = N^2 tau0``,
``b = Q^2``, a relative sigma of ``sqrt(8 sqrt(b / a) / L)`` (6 % in ``N^2`` for the record above).

Each rest's increments lose their mean (its rate: the Earth's and the biases) and are tapered
(:func:`split_cosine_taper`): untapered, the quantization errors at a rest's two ends reach every ordinate
with ``2 Q^2 / n``, more than the white noise at a 20-s rest.  The periodogram is taken at the Fourier
frequencies ``0 < k < n / 2``, with the exact expectation the taper gives (:func:`rest_periodograms`), and
its ordinates taken as independent exponentials, the covariance widened by the taper's variance inflation.  Slower terms (bias instability, rate random walk) are below the white noise over
a rest of minutes on a gyro that quantizes (a navigation-grade one); the Allan fit keeps reporting them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

#: The share of each rest's samples in each of the taper's two cosine ramps (:func:`split_cosine_taper`).
TAPER_FRACTION = 0.1
#: Fisher-scoring iterations at most.
MAX_ITERATIONS = 60
#: The iteration stops when no parameter moves by more than this fraction of its own sigma.
STEP_TOLERANCE = 1e-6
#: A rest whose score for the white noise exceeds this many of its sigmas at the others' fit is left out.
REST_SCORE_LIMIT = 5.0
#: Neither parameter below this fraction of the per-sample variance (a term the data do not show stays
#: positive, so that its information is finite; its value is then a bound, not an estimate).
FLOOR_FRACTION = 1e-9


@dataclass(frozen=True)
class WhiteQuantization:
    """The Whittle estimate of one channel's white rate noise and quantization.

    Attributes
    ----------
    white_var : float
        ``N^2``, (rad/s)^2 s or (m/s^2)^2 s.
    quantization_var : float
        ``Q^2``, rad^2 or (m/s)^2.
    cov : ndarray, shape (2, 2)
        Covariance of ``(N^2, Q^2)`` (the inverse Fisher information).
    frequencies : int
        The number of periodogram ordinates used.
    converged : bool
    rests_left_out : tuple of int
        The rests (rows of ``rests``) left out for a low-frequency power the others do not explain.
    """

    white_var: float
    quantization_var: float
    cov: np.ndarray
    frequencies: int
    converged: bool
    rests_left_out: tuple = ()


@dataclass(frozen=True)
class Periodograms:
    """The rests' pooled periodogram ordinates of one channel and what their expectation is made of.

    Attributes
    ----------
    I : ndarray, shape (M,)
        The ordinates at ``0 < k < n_rest / 2`` of every rest.
    v, u : ndarray, shape (M,)
        ``E[I] = N^2 tau0 v + Q^2 u``: ``u`` is ``rho u_k + c``, ``v`` is 1, each less the share the rest's mean
        took out (its increments' mean holds ``(e_n - e_0) / n`` of the quantization, and the taper's transform
        ``H_k`` at ``k > 0`` is not zero).
    rest : ndarray of int, shape (M,)
        The rest (its row in ``rests``) of each ordinate.
    inflation : float
        The taper's variance inflation ``n sum h^4 / (sum h^2)^2``, averaged over the ordinates (the tapered
        ordinates are that much less informative than independent ones).
    """

    I: np.ndarray
    v: np.ndarray
    u: np.ndarray
    rest: np.ndarray
    inflation: float


def split_cosine_taper(n, *, fraction=TAPER_FRACTION):
    """The split cosine bell of ``n`` points: a half-cosine ramp over ``fraction`` of them at each end, 1 between."""
    m = max(1, int(round(fraction * n)))
    h = np.ones(n)
    ramp = 0.5 * (1.0 - np.cos(np.pi * (np.arange(m) + 0.5) / m))
    h[:m] = ramp
    h[n - m:] = ramp[::-1]
    return h


def rest_periodograms(increments, rests):
    """Every rest's tapered periodogram of one channel's increments, pooled, with what the model needs of each.

    For a taper ``h`` (:func:`split_cosine_taper`), ``I_k = |sum_j h_j x_j exp(-i omega_k j)|^2 / sum h^2`` has the
    expectation ``N^2 tau0 + Q^2 (rho u_k + c)`` exactly: ``u_k = 2 (1 - cos omega_k)``, ``rho = sum h_j h_{j-1} /
    sum h^2`` and ``c = sum_{j=0}^{n} (h_j - h_{j-1})^2 / sum h^2`` (``h_{-1} = h_n = 0``), the quantization errors at
    the rest's ends and along the taper's slopes (less the mean's share, below).  Untapered, ``c = 2 / n``: the two end errors reach every
    ordinate, which at a 20-s rest of a ring-laser gyro is more than its white noise.

    Parameters
    ----------
    increments : ndarray, shape (n,)
        One channel's increments (rad or m/s).
    rests : ndarray of int, shape (P, 2)
        Sample ranges ``[start, stop)``.

    Returns
    -------
    Periodograms
    """
    I_parts, v_parts, u_parts, infl, which = [], [], [], [], []
    for i, (a, b) in enumerate(np.asarray(rests, dtype=np.int64).reshape(-1, 2)):
        x = np.asarray(increments[a:b], dtype=float)
        n = x.size
        if n < 8:
            continue
        h = split_cosine_taper(n)
        h2 = float(h @ h)
        F = np.fft.rfft((x - x.mean()) * h)
        k = np.arange(1, (n - 1) // 2 + 1)
        rho = float(h[1:] @ h[:-1]) / h2
        c = float(np.sum(np.diff(np.concatenate(([0.0], h, [0.0]))) ** 2)) / h2
        # the mean taken out leaves the taper's own transform H_k times it in every ordinate: its share of both
        # terms (the mean of the increments holds (e_n - e_0) / n of the quantization)
        H = np.fft.rfft(h)[k]
        z_end = np.exp(-2j * np.pi * k * (n - 1) / n)
        ends = (h[0] + h[-1] * z_end)
        I_parts.append(np.abs(F[k]) ** 2 / h2)
        v_parts.append(1.0 - np.abs(H) ** 2 / (n * h2))
        u_parts.append(rho * 2.0 * (1.0 - np.cos(2.0 * np.pi * k / n)) + c
                       + (2.0 * np.abs(H) ** 2 / n**2 - 2.0 * np.real(np.conj(H) * ends) / n) / h2)
        infl.append(np.full(k.size, n * float(np.sum(h**4)) / h2**2))
        which.append(np.full(k.size, i, dtype=np.int64))
    if not I_parts:
        return Periodograms(I=np.zeros(0), v=np.zeros(0), u=np.zeros(0), rest=np.zeros(0, dtype=np.int64),
                            inflation=1.0)
    return Periodograms(I=np.concatenate(I_parts), v=np.concatenate(v_parts), u=np.concatenate(u_parts),
                        rest=np.concatenate(which), inflation=float(np.mean(np.concatenate(infl))))


def whittle_white_quantization(increments, rests, *, tau0, start=None):
    """``N^2`` and ``Q^2`` of one channel from its rests (module doc).

    A rest whose low-frequency power the others' fit does not explain (its score for ``N^2`` above
    :data:`REST_SCORE_LIMIT` sigmas: a slow turn or a table settling that the rest detection let through) is
    left out and the fit made again, until none is.

    Parameters
    ----------
    increments : ndarray, shape (n,)
    rests : ndarray of int, shape (P, 2)
    tau0 : float
        The sample interval, s.
    start : tuple (N^2, Q^2), optional
        Where Fisher scoring starts (default: from the periodogram's low and high ends).

    Returns
    -------
    WhiteQuantization or None
        None when the rests hold fewer than a handful of ordinates.
    """
    pg = rest_periodograms(increments, rests)
    if pg.I.size < 8 or not np.all(np.isfinite(pg.I)) or not np.any(pg.I > 0):
        return None
    keep = np.ones(pg.I.size, dtype=bool)
    dropped = []
    while True:
        fit = _fit(pg.I[keep], pg.v[keep], pg.u[keep], inflation=pg.inflation, tau0=tau0, start=start)
        theta = np.array([fit.white_var * tau0, fit.quantization_var])
        S = theta[0] * pg.v + theta[1] * pg.u
        score = np.bincount(pg.rest, weights=keep * pg.v * (pg.I - S) / S**2, minlength=int(pg.rest.max()) + 1)
        info = np.bincount(pg.rest, weights=keep * pg.v**2 / S**2, minlength=score.size) * pg.inflation
        z = np.where(info > 0, score / np.sqrt(np.where(info > 0, info, 1.0)), 0.0)
        worst = int(np.argmax(z))
        if z[worst] <= REST_SCORE_LIMIT or np.count_nonzero(keep & (pg.rest != worst)) < 8:
            return replace(fit, rests_left_out=tuple(dropped))
        keep &= pg.rest != worst
        dropped.append(worst)


def _fit(I, v, u, *, inflation, tau0, start):
    """Fisher scoring of the Whittle likelihood of ``E[I] = a v + b u`` (``a = N^2 tau0``, ``b = Q^2``)."""
    floor = FLOOR_FRACTION * float(np.mean(I))
    if start is None:
        low = u <= np.quantile(u, 0.05)
        a = float(np.mean(I[low]))
        b = max(float(np.mean(I[u > 2.0]) - a) / 3.0, floor) if np.any(u > 2.0) else floor
    else:
        a, b = float(start[0]) * tau0, float(start[1])
    theta = np.array([max(a, floor), max(b, floor)])
    converged = False
    for _ in range(MAX_ITERATIONS):
        F, score = _information(I, v, u, theta)
        step = np.linalg.solve(F, score)
        sd = np.sqrt(np.diag(np.linalg.inv(F)))
        new = theta + step
        # a parameter the step would take below its floor halves toward it instead
        new = np.where(new < floor, np.maximum(0.5 * theta, floor), new)
        moved = np.abs(new - theta) / sd
        theta = new
        if np.all(moved < STEP_TOLERANCE):
            converged = True
            break
    F, _ = _information(I, v, u, theta)
    C = np.linalg.inv(F) * inflation
    # (a, b) = (N^2 tau0, Q^2) -> (N^2, Q^2)
    J = np.diag([1.0 / tau0, 1.0])
    return WhiteQuantization(white_var=float(theta[0] / tau0), quantization_var=float(theta[1]), cov=J @ C @ J,
                             frequencies=int(I.size), converged=converged)


def _information(I, v, u, theta):
    """The Fisher information and the score of ``(a, b)`` at ``theta``."""
    S = theta[0] * v + theta[1] * u
    w = 1.0 / S**2
    F = np.array([[(w * v * v).sum(), (w * v * u).sum()], [(w * v * u).sum(), (w * u * u).sum()]])
    r = (I - S) * w
    return F, np.array([(r * v).sum(), (r * u).sum()])


__all__ = ["WhiteQuantization", "Periodograms", "rest_periodograms", "split_cosine_taper", "whittle_white_quantization",
           "TAPER_FRACTION", "REST_SCORE_LIMIT"]
