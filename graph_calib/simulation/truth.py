r"""Truth parameters of a simulated IMU: drawn once per IMU, evaluated per subrange.

Each element is drawn as ``sign * U(low, high)`` (a random sign, a magnitude
uniform in the grade's range, :data:`TRUTH_RANGES`); ``time_lag.*`` are positive.

Temperature dependence over the whole campaign
----------------------------------------------
Bias and scale of both triads follow a smooth curve that is *not* linear over
the campaign's range,

.. math::

    p(T) = c_0 + c_1 (T - T_c) + c_2 (T - T_c)^2, \qquad T_c = 20\ \mathrm{degC},

(quadratic by default; the simulator must produce its errors through
:func:`graph_calib.sensors.sensor_model.measure`, whose terms go up to ``dT^2``, and
``dT^3`` for the biases).  In an experiment with reference temperature ``T_ref``
the same curve is exactly

.. math::

    p(T) = p(T_\mathrm{ref}) + p'(T_\mathrm{ref})\,dT + c_2\,dT^2,

so the truth of the declared model is ``p = p(T_ref)`` and ``p_tc = p'(T_ref)``,
and the curvature ``c_2`` is a small ``*_tc2`` remainder that the declared
(linear) model does not hold.  The data carry it (through the ``*.bias_tc2`` /
``*.scale_tc2`` terms of the simulation layout); the truth file lists it under
``simulation.unmodelled`` unless the scenario switches that effect on, when it
is part of the truth (effect value plus curvature).

A cubic term, as real IMUs show, is added to the biases with ``cubic_scale > 0``
(and to the scale factors of both triads with ``scale_cubic_scale > 0``, drawn after the biases' and
from the grade's ``*.scale_tc3`` range: a pendulous accelerometer's scale factor bends by a few ppm over
60 degC)
(:func:`draw_imu`): ``p(T) = ... + c_3 (T - T_c)^3`` with ``c_3`` drawn from the
grade's ``*.bias_tc3`` range times ``cubic_scale`` (drawn after every other
parameter, so the other draws of a seed stay the same; ``cubic_scale = 0``, the
default, draws nothing and leaves every seed's data as before).  Around ``T_ref``
it is ``p(T_ref) + p' dT + (c_2 + 3 c_3 d) dT^2 + c_3 dT^3`` with
``d = T_ref - T_c``: the local curvature grows towards the ends of the range.

The truth over the whole range is :meth:`ImuTruth.temperature_curves`, written
into each truth file as data-format.md's top-level ``temperature_curves``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graph_calib import constants as c
from graph_calib.sensors.effects import DECLARED, EFFECTS, FURTHER_EFFECTS, REGISTRY
from graph_calib.sensors.params import Layout

DH = c.DH_TO_RS
AS = c.ARCSEC_TO_RAD
AM = 60.0 * c.ARCSEC_TO_RAD
PPM = 1e-6
UG = c.UG_TO_MPS2

#: Centre of the temperature curves, degC.
T_CENTER_DEGC = 20.0

#: Temperature-dependent parameters: value, first and second temperature coefficients.
TEMPERATURE_TRIPLES = (
    ("gyro.bias", "gyro.bias_tc", "gyro.bias_tc2"),
    ("gyro.scale", "gyro.scale_tc", "gyro.scale_tc2"),
    ("accel.bias", "accel.bias_tc", "accel.bias_tc2"),
    ("accel.scale", "accel.scale_tc", "accel.scale_tc2"),
)

#: Magnitude ranges (low, high), SI, of the declared parameters and of the curvature
#: ``c_2`` (keys ``*_tc2``) per grade.  ``*.bias`` / ``*.scale`` are the values at
#: ``T_CENTER_DEGC``; ``*_tc`` the slopes there.
TRUTH_RANGES = {
    "navigation": {
        "gyro.bias": (0.01 * DH, 0.1 * DH),
        "gyro.bias_tc": (0.001 * DH, 0.005 * DH),
        "gyro.bias_tc2": (1e-5 * DH, 3e-5 * DH),
        "gyro.bias_tc3": (1e-7 * DH, 4e-7 * DH),
        "gyro.scale": (10 * PPM, 100 * PPM),
        "gyro.scale_tc": (0.3 * PPM, 1.5 * PPM),
        "gyro.scale_tc2": (0.002 * PPM, 0.01 * PPM),
        "gyro.scale_tc3": (0.5e-4 * PPM, 2e-4 * PPM),
        "gyro.misalignment": (10 * AS, 60 * AS),
        "accel.bias": (1e-4, 1e-3),
        "accel.bias_tc": (0.5e-5, 2e-5),
        "accel.bias_tc2": (2e-8, 8e-8),
        "accel.bias_tc3": (2e-9, 8e-9),
        "accel.scale": (50 * PPM, 300 * PPM),
        "accel.scale_tc": (0.5 * PPM, 2 * PPM),
        "accel.scale_tc2": (0.002 * PPM, 0.01 * PPM),
        "accel.scale_tc3": (1e-4 * PPM, 3e-4 * PPM),
        "accel.misalignment": (10 * AS, 60 * AS),
        "mount": (1 * AM, 5 * AM),
        "lever_arm": (0.05, 0.15),
        "time_lag.table": (0.002, 0.010),
    },
    "tactical": {
        "gyro.bias": (0.5 * DH, 5 * DH),
        "gyro.bias_tc": (0.02 * DH, 0.1 * DH),
        "gyro.bias_tc2": (2e-4 * DH, 6e-4 * DH),
        "gyro.bias_tc3": (2e-6 * DH, 8e-6 * DH),
        "gyro.scale": (100 * PPM, 1000 * PPM),
        "gyro.scale_tc": (3 * PPM, 15 * PPM),
        "gyro.scale_tc2": (0.02 * PPM, 0.1 * PPM),
        "gyro.scale_tc3": (0.5e-3 * PPM, 2e-3 * PPM),
        "gyro.misalignment": (20 * AS, 200 * AS),
        "accel.bias": (5e-4, 5e-3),
        "accel.bias_tc": (2e-5, 1e-4),
        "accel.bias_tc2": (2e-7, 8e-7),
        "accel.bias_tc3": (2e-8, 8e-8),
        "accel.scale": (200 * PPM, 1000 * PPM),
        "accel.scale_tc": (5 * PPM, 20 * PPM),
        "accel.scale_tc2": (0.02 * PPM, 0.1 * PPM),
        "accel.scale_tc3": (1e-3 * PPM, 3e-3 * PPM),
        "accel.misalignment": (20 * AS, 200 * AS),
        "mount": (2 * AM, 10 * AM),
        "lever_arm": (0.05, 0.15),
        "time_lag.table": (0.002, 0.010),
    },
    "consumer": {
        "gyro.bias": (0.1 * c.DEG_TO_RAD, 1.0 * c.DEG_TO_RAD),
        "gyro.bias_tc": (0.005 * c.DEG_TO_RAD, 0.03 * c.DEG_TO_RAD),
        "gyro.bias_tc2": (0.0, 0.0),
        "gyro.bias_tc3": (0.0, 0.0),
        "gyro.scale": (0.005, 0.03),
        "gyro.scale_tc": (50 * PPM, 300 * PPM),
        "gyro.scale_tc2": (0.0, 0.0),
        "gyro.scale_tc3": (0.0, 0.0),
        "gyro.misalignment": (0.2 * c.DEG_TO_RAD, 2.0 * c.DEG_TO_RAD),
        "accel.bias": (0.02, 0.2),
        "accel.bias_tc": (1e-3, 5e-3),
        "accel.bias_tc2": (0.0, 0.0),
        "accel.bias_tc3": (0.0, 0.0),
        "accel.scale": (0.005, 0.03),
        "accel.scale_tc": (50 * PPM, 300 * PPM),
        "accel.scale_tc2": (0.0, 0.0),
        "accel.scale_tc3": (0.0, 0.0),
        "accel.misalignment": (0.2 * c.DEG_TO_RAD, 2.0 * c.DEG_TO_RAD),
        "mount": (0.5 * c.DEG_TO_RAD, 3.0 * c.DEG_TO_RAD),
        "lever_arm": (0.0, 0.05),
        "time_lag.table": (0.0, 0.02),
    },
}

#: Size (low, high), SI, of each further effect when a scenario switches it on (the effect registry's
#: ``simulation_size``): chosen for the ``nav-subrange-short`` design (about 18 min, sensors drifting
#: about 5 degC) to be several times its own estimation sigma (rough estimates in ``docs/simulator.md``),
#: yet within what real navigation-grade units show.
EFFECT_SIZES = {e: EFFECTS[e].simulation_size for e in FURTHER_EFFECTS if EFFECTS[e].simulation_size is not None}

_POSITIVE = tuple(e.name for e in REGISTRY if e.positive)


def _draw(rng, lo, hi, size, positive=False):
    mag = rng.uniform(lo, hi, size=size)
    if positive:
        return mag
    return mag * np.where(rng.uniform(size=size) < 0.5, -1.0, 1.0)


def draw_rms(grade):
    """``{parameter: sigma}``: the RMS of the simulator's draw ``sign * U(low, high)`` of each parameter of ``grade``.

    ``sqrt((high^3 - low^3) / (3 (high - low)))`` from :data:`TRUTH_RANGES`.  As a calibration's prior sigmas
    (``ModelOptions(prior_sigma=draw_rms(grade))``) they give the simulated truth its prior's second moments, so
    that a linear estimator's error has exactly its reported covariance when the noise model is right: the
    Monte Carlo check of the sigmas (the grade's own priors are 2 to 38 times wider than these draws, so that an
    element tied to a direction the record does not determine looks pessimistic whatever the noise model;
    docs/model.md, "Noise from the record").
    """
    return {name: float(np.sqrt((hi**3 - lo**3) / (3.0 * (hi - lo)))) for name, (lo, hi) in TRUTH_RANGES[grade].items()}


@dataclass(frozen=True)
class ImuTruth:
    """One simulated IMU: every truth parameter, temperature curves included.

    Attributes
    ----------
    grade : str
    constants : dict
        ``{name: ndarray}`` of the parameters that do not depend on temperature
        (misalignments, mount, lever arm, time lags, further effects).
    curves : dict
        ``{"gyro.bias": (c0, c1, c2), ...}``, each an ndarray (3,): value, slope
        and curvature at ``t_center`` (see the module docstring).
    t_center : float
        degC.
    effects : tuple of str
        Further effects switched on (their values in ``constants``; for the
        ``*_tc2`` ones the value *adds* to the curvature).
    exclude : tuple of str
        Declared parameters that this set-up does not have (no table: mount,
        lever arm, table time lag).
    """

    grade: str
    constants: dict
    curves: dict
    t_center: float = T_CENTER_DEGC
    effects: tuple = ()
    exclude: tuple = ()
    curvature: bool = True
    notes: dict = field(default_factory=dict)
    cubic: dict = field(default_factory=dict)

    def temperature_curves(self):
        """The truth over the whole range, data-format.md's ``temperature_curves``.

        ``{flat element: {"t0_degC": t_center, "coefficients": [c0, c1, c2(, c3)]}}`` (SI) for every
        element of the temperature-dependent parameters, except those of a parameter whose ``*_tc2`` or
        ``*_tc3`` further effect is switched on (that effect is added around each experiment's
        ``T_ref``, so it is no single curve over the range: those elements are left out).
        """
        out = {}
        for p, ptc, ptc2 in TEMPERATURE_TRIPLES:
            if ptc2 in self.effects or f"{p}_tc3" in self.effects:
                continue
            c0, c1, c2 = self.curves[p]
            c3 = self.cubic.get(p)
            for i, ax in enumerate("xyz"):
                coef = [float(c0[i]), float(c1[i]), float(c2[i])] + ([] if c3 is None else [float(c3[i])])
                out[f"{p}.{ax}"] = {"t0_degC": float(self.t_center), "coefficients": coef}
        return out

    def truth_layout(self):
        """Layout of the truth file: the declared model (minus ``exclude``) plus ``effects``."""
        return Layout.declared(extra=self.effects, exclude=self.exclude)

    def simulation_layout(self):
        """Layout the data are made with: the truth layout plus the curvature terms."""
        extra = [t[2] for t in TEMPERATURE_TRIPLES] if self.curvature else []
        extra += [f"{p}_tc3" for p in self.cubic]
        return self.truth_layout().with_names(*[n for n in extra if n not in self.effects])

    def at(self, t_ref):
        """Truth at reference temperature ``t_ref``.

        Returns
        -------
        truth_layout : Layout
        x_truth : ndarray
            Values written to the truth file.
        sim_layout : Layout
        x_sim : ndarray
            Values the data are made with (``x_truth`` plus the curvature terms).
        unmodelled : dict
            ``{flat name: value}`` of the curvature terms that the truth layout lacks.
        """
        values = {n: np.asarray(v, dtype=float) for n, v in self.constants.items()}
        d = t_ref - self.t_center
        for p, ptc, ptc2 in TEMPERATURE_TRIPLES:
            c0, c1, c2 = self.curves[p]
            values[p] = c0 + c1 * d + c2 * d * d
            values[ptc] = c1 + 2.0 * c2 * d
            curv = c2 if self.curvature else np.zeros(3)
            c3 = self.cubic.get(p)
            if c3 is not None:   # the cubic about T_ref: value, slope and curvature grow, the dT^3 term stays
                values[p] = values[p] + c3 * d**3
                values[ptc] = values[ptc] + 3.0 * c3 * d * d
                curv = curv + 3.0 * c3 * d
                values[f"{p}_tc3"] = values.get(f"{p}_tc3", np.zeros(3)) + c3
            values[ptc2] = values.get(ptc2, np.zeros(3)) + curv
        tl = self.truth_layout()
        sl = self.simulation_layout()

        def vec(layout):
            x = layout.zeros()
            for n in layout.names:
                x[layout.slice(n)] = values[n]
            return x

        x_sim = vec(sl)
        x_truth = vec(tl)
        unmodelled = {}
        for n in sl.names:
            if n not in tl:
                unmodelled.update(dict(zip(EFFECTS[n].element_names(), values[n].tolist())))
        return tl, x_truth, sl, x_sim, unmodelled


def draw_imu(grade, *, rng, effects=(), effect_scale=1.0, errors=True, curvature=True, exclude=(), cubic_scale=0.0,
             scale_cubic_scale=0.0):
    """Draw one IMU's truth.

    Parameters
    ----------
    grade : str
        ``"navigation"``, ``"tactical"`` or ``"consumer"`` (:data:`TRUTH_RANGES`).
    rng : numpy.random.Generator
    effects : sequence of str
        Further effects (model.md) switched on, drawn from :data:`EFFECT_SIZES`.
    effect_scale : float
        Multiplies every effect size.
    errors : bool
        False: every parameter zero (an ideal IMU, exactly aligned, no lever arm or lag).
    curvature : bool
        False: temperature curves exactly linear (no unmodelled remainder).
    exclude : sequence of str
        Declared parameters absent from this set-up (kept zero, left out of the truth).
    cubic_scale : float
        Multiplies the cubic term of the bias curves (``*.bias_tc3`` of :data:`TRUTH_RANGES`); 0 (the
        default): none, and nothing drawn, so every seed's IMU stays as before.  Needs ``curvature``.
    scale_cubic_scale : float
        The same for the scale-factor curves of both triads (``*.scale_tc3`` of :data:`TRUTH_RANGES`), drawn
        after the biases' cubic terms; 0 (the default): none, nothing drawn.

    Returns
    -------
    ImuTruth
    """
    try:
        ranges = TRUTH_RANGES[grade]
    except KeyError:
        raise KeyError(f"no truth ranges for grade {grade!r}; known: {', '.join(TRUTH_RANGES)}") from None
    effects = tuple(dict.fromkeys(effects))
    for e in effects:
        if e not in FURTHER_EFFECTS:
            raise KeyError(f"unknown effect {e!r}; known: {', '.join(FURTHER_EFFECTS)}")
    consts = {}
    for name in DECLARED:
        if name in ("gyro.bias", "gyro.bias_tc", "gyro.scale", "gyro.scale_tc", "accel.bias", "accel.bias_tc",
                    "accel.scale", "accel.scale_tc"):
            continue
        lo, hi = ranges[name]
        consts[name] = _draw(rng, lo, hi, EFFECTS[name].size, positive=name in _POSITIVE)
    curves = {}
    for p, ptc, ptc2 in TEMPERATURE_TRIPLES:
        curves[p] = tuple(_draw(rng, *ranges[n], 3) for n in (p, ptc, ptc2))
    for e, (lo, hi) in EFFECT_SIZES.items():
        # the first effects are always drawn, in registry order, so switching one on shifts no other draw;
        # effects added later are drawn only when on (after those), so every existing seed's data stay
        if not (EFFECTS[e].drawn_when_off or e in effects):
            continue
        v = _draw(rng, lo * effect_scale, hi * effect_scale, EFFECTS[e].size, positive=e in _POSITIVE)
        if e in effects:
            consts[e] = v
    for name in exclude:
        consts[name] = np.zeros(EFFECTS[name].size)
    if not errors:
        consts = {n: np.zeros_like(v) for n, v in consts.items()}
        curves = {n: tuple(np.zeros(3) for _ in range(3)) for n in curves}
        curvature = False
    if not curvature:
        curves = {n: (v[0], v[1], np.zeros(3)) for n, v in curves.items()}
    cubic = {}
    if cubic_scale > 0 and errors and curvature:   # drawn last: the draws above stay those of the seed
        for p in ("gyro.bias", "accel.bias"):
            lo, hi = ranges[f"{p}_tc3"]
            cubic[p] = _draw(rng, lo * cubic_scale, hi * cubic_scale, 3)
    if scale_cubic_scale > 0 and errors and curvature:   # after the biases' cubic terms: their draws stay
        for p in ("gyro.scale", "accel.scale"):
            lo, hi = ranges[f"{p}_tc3"]
            cubic[p] = _draw(rng, lo * scale_cubic_scale, hi * scale_cubic_scale, 3)
    return ImuTruth(grade=grade, constants=consts, curves=curves, effects=effects, exclude=tuple(exclude),
                    curvature=curvature, cubic=cubic)


def curvature_fit_offsets(imu, sensor_dT, *, t_ref=None):
    """How a linear fit in ``dT`` would absorb the curvature inside one experiment.

    Least squares of ``c_2 dT_i^2`` on ``[1, dT_i]`` over the experiment's
    samples, per sensor ``i``: the declared model's estimates of ``p`` and
    ``p_tc`` are expected off the truth by these offsets (for an estimator that
    weighs the record evenly).

    Parameters
    ----------
    imu : ImuTruth
    sensor_dT : ndarray, shape (N, 6)
        ``T - T_ref`` of gyro x, y, z and accel x, y, z.
    t_ref : float, optional
        degC; with a cubic term (``imu.cubic``) its local curvature and ``dT^3`` are included.

    Returns
    -------
    dict
        ``{flat name: offset}`` for ``*.bias``, ``*.bias_tc``, ``*.scale``, ``*.scale_tc``.
    """
    out = {}
    if not imu.curvature:
        return out
    for p, ptc, _ in TEMPERATURE_TRIPLES:
        c2 = imu.curves[p][2]
        c3 = imu.cubic.get(p) if t_ref is not None else None
        if c3 is not None:
            c2 = c2 + 3.0 * c3 * (t_ref - imu.t_center)
        cols = slice(0, 3) if p.startswith("gyro") else slice(3, 6)
        dT = sensor_dT[:, cols]
        for i, ax in enumerate("xyz"):
            d = dT[:, i]
            y = c2[i] * d * d + (0.0 if c3 is None else c3[i] * d**3)
            dm, ym = d.mean(), y.mean()
            var = np.mean((d - dm) ** 2)
            slope = float(np.mean((d - dm) * (y - ym)) / var) if var > 0 else 0.0
            out[f"{p}.{ax}"] = float(ym - slope * dm)
            out[f"{ptc}.{ax}"] = slope
    return out


__all__ = ["TRUTH_RANGES", "EFFECT_SIZES", "T_CENTER_DEGC", "TEMPERATURE_TRIPLES", "ImuTruth", "draw_imu",
           "curvature_fit_offsets", "draw_rms"]
