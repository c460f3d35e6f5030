r"""The IMU's noise identified from its own record: Allan slope terms, and the density the solvers use.

Per channel the overlapping Allan variance over the rests (:mod:`graph_calib.noise.allan`) is fitted
with the IEEE Std 952 / 1293 terms, each a power of ``tau``:

.. math::

    \sigma^2(\tau) = \frac{3 Q^2}{\tau^2} + \frac{N^2}{\tau} + \frac{2 \ln 2}{\pi} B^2
                     + \frac{K^2 \tau}{3} + \frac{R^2 \tau^2}{2}

``Q`` quantization (a white error of the angle or velocity itself, rad or m/s), ``N`` white rate
noise (angle / velocity random walk, rad/sqrt(s) or m/s/sqrt(s)), ``B`` bias instability (rad/s,
m/s^2; the flat floor), ``K`` rate random walk (rad/s/sqrt(s), m/s^2/sqrt(s)), ``R`` rate ramp
(rad/s^2, m/s^3: a drift over the rest, or a hand's slow sway).  The fit is a weighted non-negative
least squares on the variance, each point weighted by its confidence; a term is *supported* when its
coefficient is at least :data:`SUPPORT_SIGMAS` of its own standard deviations (the others are reported
as upper bounds: value plus two sigma).  The standard deviations treat the ``tau`` points as
independent, which the overlapping estimator's neighbours are not: read them as indicative.

Where a channel's Allan fit supports a quantization that makes most of its per-sample scatter (``2 Q^2 > N^2 tau0``:
a ring-laser gyro's) and no slower term, ``Q`` and ``N`` are taken instead from the Whittle likelihood of the rests' spectra (:mod:`graph_calib.noise.spectral`): the Allan
variance shows ``N`` only beyond ``sqrt(3) Q / N``, longer than most rests, where the fit reads it from the
curvature of a quantization-dominated curve and came out 7 % low on average.

The density the solvers use (``Noise.gyro``, ``Noise.accel``: the covariance of a keyframe interval of
length ``T`` is ``q^2 T``) is the one that governs a keyframe: over ``T`` white rate noise gives an
angle variance ``N^2 T`` and quantization ``2 Q^2`` (the error at each end), so

.. math::  q_{eff}^2 = N^2 + 2 Q^2 / T,

averaged over the three channels.  A ring-laser gyro's per-sample scatter at 100 Hz is mostly ``Q``:
taken as white rate noise it would overstate ``q`` by ``sqrt(2 / tau_0) Q / N`` at one keyframe.

The table readings' noise is the pooled scatter of the static dwells
(:class:`graph_calib.model.encoder_noise.DwellScatter`): a two-axis table's encoders turn the faceplate
about two axes, so the scatter's trace is twice the per-axis variance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graph_calib.noise.allan import AllanDeviation, overlapping_allan
from graph_calib.noise.rests import find_rests
from graph_calib.noise.spectral import whittle_white_quantization

#: The IEEE terms: name, power of tau in the Allan variance, coefficient of the squared term.
TERMS = (
    ("quantization", -2, 3.0),
    ("white", -1, 1.0),
    ("bias_instability", 0, 2.0 * np.log(2.0) / np.pi),
    ("rate_random_walk", 1, 1.0 / 3.0),
    ("rate_ramp", 2, 0.5),
)
#: The terms slower than white noise: a channel that supports one keeps the Allan fit's ``Q`` and ``N`` (the
#: spectral estimate models white noise and quantization alone).
SLOW_TERMS = ("bias_instability", "rate_random_walk", "rate_ramp")
#: A term is supported when its squared coefficient is at least this many of its standard deviations.
SUPPORT_SIGMAS = 2.0
#: Least pooled rest time for an identification, s (the white term needs some hundred averages).
MIN_REST_S = 2.0
#: Smallest table-reading noise identified, rad (0.1 arcsec): readings that scatter less (noise-free simulated
#: ones, encoders quantised coarser than their noise) say nothing of the noise, and none is identified.
ENCODER_NOISE_FLOOR = 0.1 * np.pi / 180.0 / 3600.0
#: Fewest dwells' readings (summed degrees of freedom) for the table noise to count as identified.
MIN_DWELL_DOF = 20


@dataclass(frozen=True)
class ChannelTerms:
    """The fitted terms of one channel: ``{term: (value, sigma)}``, which the data support, and how ``Q`` and ``N``
    were estimated: ``"allan"`` (the fit of the Allan variance) or ``"whittle"`` (where the channel shows a
    quantization: the rests' spectra, :mod:`graph_calib.noise.spectral`)."""

    values: dict
    sigmas: dict
    supported: tuple
    estimator: str = "allan"

    def to_json(self):
        return {t: {"value": self.values[t], "sigma": self.sigmas[t], "supported": t in self.supported}
                for t in self.values}


@dataclass(frozen=True)
class SensorNoise:
    """A triad's identified noise.

    Attributes
    ----------
    sensor : str
        ``"gyro"`` or ``"accel"``.
    density : float
        White-noise density that governs a keyframe (module doc), rad/sqrt(s) or m/s/sqrt(s).
    density_sigma : float
        Its one-sigma confidence (same unit).
    keyframe_s : float
        The keyframe length it is for, s.
    channels : tuple of ChannelTerms
        x, y, z.
    allan : AllanDeviation
    """

    sensor: str
    density: float
    density_sigma: float
    keyframe_s: float
    channels: tuple
    allan: AllanDeviation

    def term(self, name):
        """The mean over the channels of term ``name``'s value."""
        return float(np.sqrt(np.mean([c.values[name] ** 2 for c in self.channels])))

    def to_json(self):
        return {"density": self.density, "density_sigma": self.density_sigma, "keyframe_s": self.keyframe_s,
                "channels": {ax: c.to_json() for ax, c in zip("xyz", self.channels)},
                "allan": {"tau_s": self.allan.tau.tolist(), "adev": self.allan.adev.tolist(),
                          "rel_sigma": self.allan.rel_sigma.tolist(), "rest_s": self.allan.rest_s}}


@dataclass(frozen=True)
class NoiseIdentification:
    """What a record shows of its noise.

    Attributes
    ----------
    rests : ndarray of int, shape (P, 2)
        The rests used (sample ranges).
    gyro, accel : SensorNoise or None
        None when the rests are too short (:data:`MIN_REST_S`).
    encoder : float or None
        Table-reading noise per axis, rad (None without dwells).
    encoder_dof : int
        Degrees of freedom of the dwells' scatter behind it.
    """

    rests: np.ndarray
    gyro: SensorNoise | None
    accel: SensorNoise | None
    encoder: float | None = None
    encoder_dof: int = 0
    notes: tuple = field(default=())

    @property
    def rest_s(self):
        return 0.0 if self.gyro is None else self.gyro.allan.rest_s

    def to_json(self):
        out = {"rests": int(self.rests.shape[0]), "rest_s": self.rest_s}
        for s in ("gyro", "accel"):
            v = getattr(self, s)
            if v is not None:
                out[s] = v.to_json()
        if self.encoder is not None:
            out["encoder"] = {"sigma_rad": self.encoder, "dof": self.encoder_dof}
        return out


def nonnegative_least_squares(A, b):
    """``argmin |A c - b|`` over ``c >= 0`` for a few columns (``scipy.optimize.nnls``'s answer).

    Every subset of the columns is solved by least squares unconstrained; the solution is the one of least
    residual among those whose coefficients are all positive (the constrained minimum is the unconstrained
    one on its own support), zero where none is.  ``2^n`` small solves: meant for the :data:`TERMS`'
    five columns, where it spares ``calibrate`` the import of ``scipy.optimize`` (and with it
    ``scipy.sparse``: about 0.3 s).

    Parameters
    ----------
    A : ndarray, shape (M, n)
        ``n`` at most 10.
    b : ndarray, shape (M,)

    Returns
    -------
    ndarray, shape (n,)
    """
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    n = A.shape[1]
    if n > 10:
        raise ValueError(f"{n} columns: meant for a few (2^n subsets)")
    best, best_cost = np.zeros(n), float(b @ b)
    for mask in range(1, 2**n):
        cols = [j for j in range(n) if mask >> j & 1]
        c, *_ = np.linalg.lstsq(A[:, cols], b, rcond=None)
        if np.all(c > 0):
            cost = float(np.sum((A[:, cols] @ c - b) ** 2))
            if cost < best_cost:
                best, best_cost = np.zeros(n), cost
                best[cols] = c
    return best


def fit_terms(allan, channel):
    """Weighted non-negative fit of the IEEE terms to one channel's Allan variance.

    Returns
    -------
    ChannelTerms
        Values and sigmas of ``Q, N, B, K, R`` (module doc), SI.
    cov : ndarray, shape (5, 5)
        Covariance of the squared-coefficient fit (zero rows for terms the fit set to zero).
    coef : ndarray, shape (5,)
        The squared coefficients ``(3 Q^2, N^2, ...)`` divided by their ``TERMS`` factor, i.e. ``Q^2, N^2...``.
    """
    tau = allan.tau
    y = allan.adev[:, channel] ** 2
    powers = np.array([p for _, p, _ in TERMS])
    factor = np.array([f for _, _, f in TERMS])
    A = factor[None, :] * tau[:, None] ** powers[None, :]
    if not (np.all(np.isfinite(y)) and np.max(y, initial=0.0) > 0):          # a noise-free record shows nothing
        zero = {name: 0.0 for name, _, _ in TERMS}
        return (ChannelTerms(values=dict(zero), sigmas=dict(zero), supported=()),
                np.zeros((len(TERMS), len(TERMS))), np.zeros(len(TERMS)))
    w = 1.0 / (2.0 * allan.rel_sigma * np.maximum(y, 1e-12 * np.max(y)))     # 1 / sd(sigma^2)
    scale = np.max(np.abs(A * w[:, None]), axis=0)
    scale[scale == 0] = 1.0
    c_s = nonnegative_least_squares(A * w[:, None] / scale, y * w)
    c = c_s / scale
    active = c > 0
    cov = np.zeros((len(TERMS), len(TERMS)))
    if np.any(active):
        Aw = (A * w[:, None])[:, active]
        chi2 = float(np.sum((A @ c - y) ** 2 * w**2))
        dof = max(1, tau.size - int(active.sum()))
        try:
            ca = np.linalg.pinv(Aw.T @ Aw) * max(1.0, chi2 / dof)
        except np.linalg.LinAlgError:
            ca = np.zeros((int(active.sum()),) * 2)
        cov[np.ix_(active, active)] = ca
    return _channel_terms(c, cov), cov, c


def _channel_terms(c, cov, *, estimator="allan"):
    """The :class:`ChannelTerms` of squared coefficients ``c`` (``Q^2, N^2, ...``) with covariance ``cov``."""
    sd2 = np.sqrt(np.diag(cov))
    values, sigmas, supported = {}, {}, []
    for i, (name, _, _) in enumerate(TERMS):
        v = float(np.sqrt(c[i]))
        values[name] = v
        # sd of sqrt(c) from sd(c); a term at zero reports the sqrt of its two-sigma bound
        sigmas[name] = float(sd2[i] / (2.0 * v)) if v > 0 else float(np.sqrt(2.0 * sd2[i]))
        if c[i] > 0 and c[i] >= SUPPORT_SIGMAS * sd2[i]:
            supported.append(name)
    return ChannelTerms(values=values, sigmas=sigmas, supported=tuple(supported), estimator=estimator)


def sensor_noise(increments, rests, *, tau0, keyframe_s, sensor):
    """:class:`SensorNoise` of a triad's increments over ``rests`` (None when they are too short)."""
    rests = np.asarray(rests, dtype=np.int64).reshape(-1, 2)
    if rests.shape[0] == 0 or float((rests[:, 1] - rests[:, 0]).sum()) * tau0 < MIN_REST_S:
        return None
    allan = overlapping_allan(increments, rests, tau0=tau0)
    if allan.tau.size < 3:
        return None
    channels, var, var_sd2 = [], [], []
    T = float(keyframe_s)
    for ch in range(allan.adev.shape[1]):
        terms, cov, c = fit_terms(allan, ch)
        if ("quantization" in terms.supported and not set(terms.supported) & set(SLOW_TERMS)
                and 2.0 * c[0] > tau0 * c[1]):
            # the per-sample scatter is mostly quantization (2 Q^2 > N^2 tau0): the white noise from the rests'
            # spectra instead of the Allan curve's curvature (graph_calib.noise.spectral, whose model has no slower
            # term)
            terms, cov, c = _with_spectral_white(terms, cov, c, increments[:, ch], rests, tau0=tau0)
        channels.append(terms)
        g = np.zeros(len(TERMS))
        g[0], g[1] = 2.0 / T, 1.0                  # q_eff^2 = N^2 + 2 Q^2 / T
        var.append(float(g @ c))
        var_sd2.append(float(g @ cov @ g))
    q2 = float(np.mean(var))
    q2_sd = float(np.sqrt(np.sum(var_sd2))) / len(var)
    q = float(np.sqrt(q2))
    return SensorNoise(sensor=sensor, density=q, density_sigma=q2_sd / (2.0 * q) if q > 0 else 0.0,
                       keyframe_s=T, channels=tuple(channels), allan=allan)


def _with_spectral_white(terms, cov, c, increments, rests, *, tau0):
    """A channel's ``(terms, cov, c)`` of :func:`fit_terms` with ``Q`` and ``N`` from the Whittle likelihood of its
    rests (:func:`graph_calib.noise.spectral.whittle_white_quantization`); unchanged when that has no estimate."""
    w = whittle_white_quantization(increments, rests, tau0=tau0, start=(c[1], c[0]))
    if w is None or not w.converged:
        return terms, cov, c
    c = c.copy()
    cov = cov.copy()
    c[0], c[1] = w.quantization_var, w.white_var
    cov[:2, :] = 0.0
    cov[:, :2] = 0.0
    cov[0, 0], cov[1, 1] = w.cov[1, 1], w.cov[0, 0]
    cov[0, 1] = cov[1, 0] = w.cov[0, 1]
    return _channel_terms(c, cov, estimator="whittle"), cov, c


def table_noise(scatter):
    """Per-axis table-reading noise from the dwells' scatter: ``(sigma rad or None, degrees of freedom)``.

    ``scatter`` is a :class:`graph_calib.model.encoder_noise.DwellScatter`; its covariances carry the
    factor ``(n - 1) / (n - 5)`` that unbiases their inverse, taken off here.  The pooled trace over
    twice the pooled degrees of freedom (two encoder axes); None below :data:`ENCODER_NOISE_FLOOR`.
    """
    n = np.asarray(scatter.size, dtype=float)
    if n.size == 0:
        return None, 0
    dof = n - 1.0
    tr = np.trace(scatter.cov_b, axis1=1, axis2=2) * (n - 5.0) / (n - 1.0)
    total = float(dof.sum())
    if total < MIN_DWELL_DOF:
        return None, int(total)
    var = float(np.sum(dof * tr)) / (2.0 * total)
    if not var >= ENCODER_NOISE_FLOOR**2:          # readings that do not scatter say nothing of their noise
        return None, int(total)
    return float(np.sqrt(var)), int(total)


def identify_noise(experiment, *, keyframe_s, rests=None):
    """The gyro and accelerometer noise of ``experiment``, from every rest.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    keyframe_s : float
        The keyframe length the densities are for (module doc).
    rests : array_like of int, shape (P, 2), optional
        Default :func:`graph_calib.noise.rests.find_rests`.

    Returns
    -------
    NoiseIdentification
        Without the table noise (:func:`table_noise` needs the prepared record's dwells).
    """
    rests = find_rests(experiment) if rests is None else np.asarray(rests, dtype=np.int64).reshape(-1, 2)
    tau0 = 1.0 / float(experiment.rate_hz)
    g = sensor_noise(experiment.dtheta, rests, tau0=tau0, keyframe_s=keyframe_s, sensor="gyro")
    a = sensor_noise(experiment.dv, rests, tau0=tau0, keyframe_s=keyframe_s, sensor="accel")
    return NoiseIdentification(rests=rests, gyro=g, accel=a)


__all__ = ["ChannelTerms", "SensorNoise", "NoiseIdentification", "identify_noise", "fit_terms", "sensor_noise",
           "nonnegative_least_squares", "table_noise", "TERMS", "SUPPORT_SIGMAS", "MIN_REST_S", "ENCODER_NOISE_FLOOR"]
