r"""Scenarios: complete synthetic experiments and campaigns with their truth.

A scenario is a function ``build(*, rng, **options) -> Simulation``; the
registry :data:`SCENARIOS` maps its name to it.  A :class:`Simulation` holds
the campaign information (IMU id, grade) and one :class:`ExperimentPlan` per
experiment; a plan makes its experiment on demand (so a long campaign is written
one experiment at a time) and always makes the same one: each plan owns a seed
drawn from ``rng`` when the scenario is built.

Randomness comes only from the ``numpy.random.Generator`` passed in.  Inside an
experiment, independent generators (drawn from the plan's seed) serve the table
programme, the thermal set-up and the noise, so switching the noise off changes
nothing else, bit for bit.

Use :func:`simulate` to build a scenario by name and :func:`write_simulation`
to write the experiment files, ``*.truth.json`` and ``campaign.toml``.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from graph_calib import effects, params
from graph_calib.errors import InputError
from graph_calib.experiment import Experiment, Result, Table
from graph_calib.rotations import exp_so3, log_so3, quat_to_dcm
from graph_calib.simulation.handheld import HandheldMotion
from graph_calib.simulation.imu import SignalModel, simulate_increments
from graph_calib.simulation.thermal import ThermalModel, ramp_chamber
from graph_calib.simulation.truth import (
    TEMPERATURE_TRIPLES,
    ImuTruth,
    curvature_fit_offsets,
    draw_imu,
)
from graph_calib.simulation.turntable import (
    INNER,
    OUTER,
    ProgramBuilder,
    TurntableMotion,
    encoder_readings,
    rot_z,
)

#: Default bench: latitude (deg) and local gravity (m/s^2) of Moscow.
DEFAULT_LATITUDE_DEG = 55.7
DEFAULT_GRAVITY_MPS2 = 9.8155

#: Temperature channels of the navigation-grade IMU: name, time constant (min),
#: offset above the chamber (degC, self-heating).  ``chamber`` is the chamber's own
#: sensor (no lag).  The six sensors map to channels 0, 1, 2, 3, 3, 3.
NAV_CHANNELS = (
    ("gyro_x", 20.0, 0.8),
    ("gyro_y", 28.0, 0.6),
    ("gyro_z", 35.0, 1.0),
    ("accel", 15.0, 0.4),
    ("chamber", 0.0, 0.0),
)
NAV_TEMPERATURE_MAP = (0, 1, 2, 3, 3, 3)

#: One-sigma noise of a recorded temperature, degC (when noise is on).
TEMPERATURE_NOISE = {"navigation": 0.005, "tactical": 0.01, "consumer": 0.02}

#: The six subranges of the navigation campaign, degC.
CAMPAIGN_SUBRANGES = ((-10.0, 0.0), (0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, 40.0), (40.0, 50.0))


@dataclass(frozen=True)
class Design:
    """The rotation design of a table experiment.

    Attributes
    ----------
    alignment_s : float
        Initial static alignment, s (capped at ``alignment_fraction`` of the experiment).
    alignment_fraction : float
    dwell_s : (float, float)
        Range of the static positions between rotations, s.
    rate_dps : (float, float)
        Range of the peak rotation rate, deg/s.
    ramp_s : float
        Length of each rate ramp, s.
    full_turns : bool
        Add a full turn each way about every axis.
    """

    alignment_s: float = 900.0
    alignment_fraction: float = 0.2
    dwell_s: tuple = (20.0, 40.0)
    rate_dps: tuple = (10.0, 30.0)
    ramp_s: float = 1.0
    full_turns: bool = True


NAV_DESIGN = Design()
SHORT_DESIGN = Design(alignment_s=180.0, dwell_s=(15.0, 25.0))


def _wrap_quarters(q):
    """A quarter-turn count reduced to -1, 0, 1, 2."""
    q = q % 4
    return q - 4 if q == 3 else q


def rotation_program(rate_hz, duration_s, *, rng, design=NAV_DESIGN):
    """Turntable programme: alignment, then rotations about each instrument axis held horizontal.

    After the static alignment the programme cycles through the instrument axes
    x, y, z.  For each it first brings the axis onto a horizontal table axis (a
    90-deg move of the other table axis when needed; see
    :mod:`graph_calib.simulation.turntable`), then turns about it four times by
    90 deg one way and four times back, and (``design.full_turns``) a full turn
    each way; a static position of random length in ``design.dwell_s`` follows
    every move.  Rates are drawn in ``design.rate_dps``.  Moves are added while
    they fit; a final dwell fills the programme to exactly ``duration_s``.

    Parameters
    ----------
    rate_hz : float
    duration_s : float
    rng : numpy.random.Generator
    design : Design

    Returns
    -------
    TableProgram
    """
    n_total = int(round(duration_s * rate_hz))
    b = ProgramBuilder(rate_hz)
    b.dwell(min(design.alignment_s, design.alignment_fraction * duration_s))
    quarters = [0, 0]  # (alpha, beta) in quarter turns
    dwell_lo = int(round(design.dwell_s[0] * rate_hz))

    def steps():
        while True:
            for axis_name in ("x", "y", "z"):
                if axis_name in ("x", "y"):
                    want_odd = axis_name == "y"
                    if (quarters[1] % 2 == 1) != want_odd:
                        yield INNER, (1 if rng.uniform() < 0.5 else -1)
                    turn_axis = OUTER
                else:
                    if quarters[0] % 2 == 0:
                        yield OUTER, (1 if rng.uniform() < 0.5 else -1)
                    turn_axis = INNER
                s = 1 if rng.uniform() < 0.5 else -1
                seq = [s] * 4 + [-s] * 4
                if design.full_turns:
                    seq += [4 * s, -4 * s]
                for q in seq:
                    yield turn_axis, q

    for axis, q in steps():
        rate = np.radians(rng.uniform(*design.rate_dps))
        dwell = rng.uniform(*design.dwell_s)
        angle = q * np.pi / 2.0
        need = b.move_ticks(angle, rate=rate, ramp=design.ramp_s) + int(round(dwell * rate_hz))
        if b.ticks + need > n_total - dwell_lo:
            break
        b.move(axis, angle, rate=rate, ramp=design.ramp_s)
        quarters[axis] += q
        b.dwell(dwell)
    rest = n_total - b.ticks
    if rest > 0:
        b.dwell(rest / rate_hz)
    return b.build()


# ---------------------------------------------------------------------------
# simulated experiments
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class SimulatedExperiment:
    """One simulated experiment with everything needed to check a solver against it.

    Attributes
    ----------
    file_name : str
        Experiment file name (``<stem>.h5``); the truth goes to ``<stem>.truth.json``.
    experiment : Experiment
    truth : Result
        ``solver = "truth"``; what the truth file holds.
    signals : SignalModel
        The true motion and signals at any time (``signals.attitude(t)`` is the
        true ``C_nb``; ``signals.motion`` the table or hand motion).
    thermal : ThermalModel
        The true (noise-free) temperatures at any time.
    layout : Layout
        Every parameter the data were made with (the truth layout plus the curvature terms).
    x : ndarray
        Their values at ``truth.t_ref_degC``.
    """

    file_name: str
    experiment: Experiment
    truth: Result
    signals: SignalModel
    thermal: ThermalModel
    layout: params.Layout
    x: np.ndarray

    @property
    def stem(self):
        return self.file_name[:-3] if self.file_name.endswith(".h5") else self.file_name

    @property
    def truth_name(self):
        return f"{self.stem}.truth.json"

    @property
    def motion(self):
        return self.signals.motion

    def attitude(self, t):
        """True ``C_nb`` at times ``t``, shape (N, 3, 3)."""
        return self.signals.attitude(t)


@dataclass(frozen=True)
class ExperimentPlan:
    """An experiment of a scenario, made on demand by :meth:`run` (always the same one)."""

    file_name: str
    make: Callable = field(repr=False)
    summary: str = ""

    def run(self):
        """Make the experiment: a :class:`SimulatedExperiment`."""
        return self.make()


@dataclass(frozen=True)
class Simulation:
    """A built scenario: campaign information and one plan per experiment.

    Attributes
    ----------
    scenario : str
    imu_id : str
    grade : str
    plans : tuple of ExperimentPlan
    imu : ImuTruth
        The simulated IMU (truth over the whole temperature range).
    exclude : tuple of str
        Declared parameters the set-up does not have (written to the manifest's ``[model] exclude``).
    info : dict
        Options the scenario was built with (for summaries).
    """

    scenario: str
    imu_id: str
    grade: str
    plans: tuple
    imu: ImuTruth
    exclude: tuple = ()
    info: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.plans)

    def run(self):
        """Every experiment, as a list of :class:`SimulatedExperiment`."""
        return [p.run() for p in self.plans]

    def pairs(self):
        """Every experiment as ``(Experiment, truth Result)`` pairs."""
        return [(s.experiment, s.truth) for s in self.run()]

    def temperature_range(self):
        """``(lowest, highest)`` chamber set-point of the scenario's turntable experiments, degC."""
        subs = self.info.get("subranges")
        if subs:
            return float(min(a for a, _ in subs)), float(max(b for _, b in subs))
        kw = self._table_keywords()
        return float(kw["start_degC"]), float(kw["start_degC"] + kw["span_degC"])

    def further_experiment(self, *, file_name, seed, hours, start_degC, span_degC, rate_hz=None,
                           description="", tag=""):
        """Another turntable experiment of the same IMU, bench and rotation design.

        Its own programme and noise (``seed``), ``hours`` long, the chamber taking the
        sensors from ``start_degC`` through ``span_degC`` (degC); used for independent
        validation records.  Returns a :class:`SimulatedExperiment`; ``ValueError`` for
        a scenario without a turntable (hand-held).
        """
        make = self.plans[0].make
        kw = dict(self._table_keywords())
        kw.update(file_name=file_name, seed=int(seed), duration_s=float(hours) * 3600.0,
                  start_degC=float(start_degC), span_degC=float(span_degC), description=description, tag=tag)
        if rate_hz is not None:
            kw["rate_hz"] = float(rate_hz)
        return make.func(*make.args, **kw)

    def _table_keywords(self):
        make = self.plans[0].make if self.plans else None
        if not (isinstance(make, partial) and make.func is _make_table_experiment):
            raise ValueError(f"scenario {self.scenario!r} has no turntable experiment to extend")
        return make.keywords


def _child_rngs(seed, k):
    rng = np.random.default_rng(seed)
    return [np.random.default_rng(int(s)) for s in rng.integers(0, 2**62, size=k)]


def _label(v):
    s = f"{v:g}"
    return s.replace("-", "m").replace(".", "p")


def _as_list(a):
    return [float(v) for v in np.ravel(a)]


def _truth_result(*, file_name, imu, t_ref, T_rec_sensors, tl, x_truth, unmodelled, info):
    sensor_dT = T_rec_sensors - t_ref
    curves = {"t_center_degC": imu.t_center}
    for p, _, _ in TEMPERATURE_TRIPLES:
        c0, c1, c2 = imu.curves[p]
        for i, ax in enumerate("xyz"):
            curves[f"{p}.{ax}"] = [float(c0[i]), float(c1[i]), float(c2[i])]
    sim = dict(info)
    sim["unmodelled"] = unmodelled
    sim["curvature_fit_offsets"] = curvature_fit_offsets(imu, sensor_dT)
    sim["temperature_curves"] = curves
    return Result(
        source=file_name, solver="truth", t_ref_degC=float(t_ref),
        temperature_range_degC=(float(T_rec_sensors.min()), float(T_rec_sensors.max())),
        effects=tuple(tl.names), values=tl.to_dict(x_truth), sigmas=None, extra={"simulation": sim},
    )


def _make_table_experiment(*, file_name, scenario, imu, imu_id, seed, rate_hz, duration_s, start_degC, span_degC,
                           design, latitude_rad, gravity_mps2, noise, valid, encoder_rate_hz, azimuth_rad,
                           description, tag):
    g = params.grade(imu.grade)
    r_prog, r_therm, r_noise = _child_rngs(seed, 3)
    program = rotation_program(rate_hz, duration_s, rng=r_prog, design=design)

    names = tuple(c[0] for c in NAV_CHANNELS)
    tau = np.array([c[1] for c in NAV_CHANNELS]) * 60.0 * r_therm.uniform(0.9, 1.1, len(names))
    offset = np.array([c[2] for c in NAV_CHANNELS]) + np.where(tau > 0, r_therm.normal(0.0, 0.1, len(names)), 0.0)
    pattern = np.array([1.0, 0.55, 1.4]) * r_therm.uniform(0.85, 1.15, 3)
    thermal = ramp_chamber(duration=program.duration, start_degC=start_degC, span_degC=span_degC, names=names,
                           tau=tau, offset=offset, temperature_map=NAV_TEMPERATURE_MAP, pattern=tuple(pattern))

    n = program.n_ticks
    t = np.arange(1, n + 1) / rate_hz
    tmap = np.array(NAV_TEMPERATURE_MAP)
    sig_T = TEMPERATURE_NOISE[imu.grade] if noise else 0.0
    T_rec = thermal.temperature(t)
    if sig_T > 0:
        T_rec = T_rec + sig_T * r_noise.standard_normal(T_rec.shape)
    t_ref = float(np.mean(T_rec[:, tmap]))
    tl, x_truth, sl, x_sim, unmodelled = imu.at(t_ref)

    mount = sl.get(x_sim, "mount", np.zeros(3))
    q_fb_nominal = np.array([1.0, 0.0, 0.0, 0.0])
    C_fb = quat_to_dcm(q_fb_nominal) @ exp_so3(mount)
    motion = TurntableMotion(program, C_n0=rot_z(azimuth_rad), C_fb=C_fb)
    K = sl.get(x_sim, "damping.stiffness")
    signals = SignalModel(motion, latitude_rad=latitude_rad, gravity_mps2=gravity_mps2,
                          lever_arm=sl.get(x_sim, "lever_arm"), stiffness=None if K is None else K.reshape(3, 3),
                          rate_hz=rate_hz)
    t, dtheta, dv = simulate_increments(signals, thermal, rate_hz=rate_hz, n_samples=n, layout=sl, x=x_sim,
                                        t_ref=t_ref, temperature_map=tmap)
    dt = 1.0 / rate_hz
    if noise:
        dtheta += g.gyro_noise * np.sqrt(dt) * r_noise.standard_normal(dtheta.shape)
        dv += g.accel_noise * np.sqrt(dt) * r_noise.standard_normal(dv.shape)
    lag = float(sl.get(x_sim, "time_lag.table", np.zeros(1))[0])
    tt, q_nf, ok = encoder_readings(motion, t_end=t[-1], rate_hz=encoder_rate_hz, time_lag=lag,
                                    noise_rad=g.encoder_noise if noise else 0.0, rng=r_noise, valid=valid)
    experiment = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=T_rec, temperature_names=names,
        temperature_map=tmap.copy(), rate_hz=float(rate_hz), latitude_rad=float(latitude_rad),
        gravity_mps2=float(gravity_mps2), imu_id=imu_id, description=description,
        table=Table(t=tt, q_nf=q_nf, valid=ok, q_fb_nominal=q_fb_nominal), source=file_name,
    )
    info = {
        "scenario": scenario, "tag": tag, "grade": imu.grade, "effects_on": list(imu.effects),
        "noise": {"gyro_noise": g.gyro_noise if noise else 0.0, "accel_noise": g.accel_noise if noise else 0.0,
                  "encoder_noise_rad": g.encoder_noise if noise else 0.0, "temperature_noise_degC": sig_T},
        "table": {"outer_axis": "horizontal, base x (azimuth from East)", "azimuth_rad": float(azimuth_rad),
                  "encoder_rate_hz": float(encoder_rate_hz), "valid": valid},
        "chamber": {"t_s": _as_list(thermal.chamber_t), "T_degC": _as_list(thermal.chamber_T)},
        "channels": {"names": list(names), "tau_s": _as_list(tau), "offset_degC": _as_list(offset)},
    }
    truth = _truth_result(file_name=file_name, imu=imu, t_ref=t_ref, T_rec_sensors=T_rec[:, tmap], tl=tl,
                          x_truth=x_truth, unmodelled=unmodelled, info=info)
    return SimulatedExperiment(file_name=file_name, experiment=experiment, truth=truth, signals=signals,
                               thermal=thermal, layout=sl, x=x_sim)


def _random_rotation(rng):
    q = rng.standard_normal(4)
    return quat_to_dcm(q / np.linalg.norm(q))


def _make_handheld_experiment(*, file_name, scenario, imu, imu_id, seed, rate_hz, duration_s, n_poses,
                              initial_static_s, hold_s, turn_s, translation_m, latitude_rad, gravity_mps2,
                              noise, description, tag):
    g = params.grade(imu.grade)
    r_prog, r_therm, r_noise = _child_rngs(seed, 3)
    motion = HandheldMotion(rate_hz, rot_z(r_prog.uniform(0.0, 2.0 * np.pi)))
    motion.hold(initial_static_s)
    k = 0
    while True:
        C_now = motion.attitude_now
        for _ in range(100):
            phi = log_so3(C_now.T @ _random_rotation(r_prog))
            if np.linalg.norm(phi) > np.radians(40.0):
                break
        T_turn = r_prog.uniform(*turn_s)
        hold = r_prog.uniform(*hold_s)
        d = r_prog.normal(0.0, translation_m, 3) if translation_m > 0 else np.zeros(3)
        if duration_s is None:
            if k >= n_poses:
                break
        elif motion.duration + T_turn + hold > duration_s and k > 0:
            break
        motion.turn(phi, T_turn, d)
        motion.hold(hold)
        k += 1
    if duration_s is not None:
        rest = int(round(duration_s * rate_hz)) - int(round(motion.duration * rate_hz))
        if rest > 0:
            motion.hold(rest / rate_hz)
    n = int(round(motion.duration * rate_hz))

    room0 = r_therm.uniform(21.0, 25.0)
    drift = r_therm.uniform(-1.0, 1.0) / 3600.0
    dur = n / rate_hz
    thermal = ThermalModel(chamber_t=np.array([0.0, dur]), chamber_T=np.array([room0, room0 + drift * dur]),
                           names=("imu",), tau=np.array([r_therm.uniform(180.0, 420.0)]),
                           offset=np.array([r_therm.uniform(2.0, 4.0)]), initial=np.array([room0]))
    t = np.arange(1, n + 1) / rate_hz
    tmap = np.zeros(6, dtype=np.int64)
    sig_T = TEMPERATURE_NOISE[imu.grade] if noise else 0.0
    T_rec = thermal.temperature(t)
    if sig_T > 0:
        T_rec = T_rec + sig_T * r_noise.standard_normal(T_rec.shape)
    t_ref = float(np.mean(T_rec[:, tmap]))
    tl, x_truth, sl, x_sim, unmodelled = imu.at(t_ref)
    signals = SignalModel(motion, latitude_rad=latitude_rad, gravity_mps2=gravity_mps2, rate_hz=rate_hz)
    t, dtheta, dv = simulate_increments(signals, thermal, rate_hz=rate_hz, n_samples=n, layout=sl, x=x_sim,
                                        t_ref=t_ref, temperature_map=tmap)
    dt = 1.0 / rate_hz
    if noise:
        dtheta += g.gyro_noise * np.sqrt(dt) * r_noise.standard_normal(dtheta.shape)
        dv += g.accel_noise * np.sqrt(dt) * r_noise.standard_normal(dv.shape)
    experiment = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=T_rec, temperature_names=("imu",), temperature_map=tmap,
        rate_hz=float(rate_hz), latitude_rad=float(latitude_rad), gravity_mps2=float(gravity_mps2),
        imu_id=imu_id, description=description, table=None, source=file_name,
    )
    info = {
        "scenario": scenario, "tag": tag, "grade": imu.grade, "effects_on": list(imu.effects),
        "noise": {"gyro_noise": g.gyro_noise if noise else 0.0, "accel_noise": g.accel_noise if noise else 0.0,
                  "temperature_noise_degC": sig_T},
        "poses": k, "translation_m": float(translation_m),
        "chamber": {"t_s": _as_list(thermal.chamber_t), "T_degC": _as_list(thermal.chamber_T)},
        "channels": {"names": ["imu"], "tau_s": _as_list(thermal.tau), "offset_degC": _as_list(thermal.offset)},
    }
    truth = _truth_result(file_name=file_name, imu=imu, t_ref=t_ref, T_rec_sensors=T_rec[:, tmap], tl=tl,
                          x_truth=x_truth, unmodelled=unmodelled, info=info)
    return SimulatedExperiment(file_name=file_name, experiment=experiment, truth=truth, signals=signals,
                               thermal=thermal, layout=sl, x=x_sim)


# ---------------------------------------------------------------------------
# scenarios
# ---------------------------------------------------------------------------


def _check_common(hours, rate_hz, effect_scale, effect_names):
    if hours is not None and not (np.isfinite(hours) and hours > 0):
        raise InputError(f"--hours must be a positive number, got {hours!r}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"rate_hz must be positive, got {rate_hz!r}")
    if not (np.isfinite(effect_scale) and effect_scale >= 0):
        raise InputError(f"--effect-scale must be a non-negative number, got {effect_scale!r}")
    for e in effect_names:
        if e not in effects.FURTHER_EFFECTS:
            raise InputError(f"unknown effect {e!r}; known: {', '.join(effects.FURTHER_EFFECTS)}")


def _table_scenario(name, *, rng, subranges, hours, span_degC, design, imu_id, noise, errors, rate_hz, effects,
                    effect_scale, curvature, latitude_deg, gravity_mps2, table_valid, encoder_rate_hz, tag,
                    file_stem):
    _check_common(hours, rate_hz, effect_scale, effects)
    if table_valid not in ("static", "all"):
        raise InputError(f"table_valid must be 'static' or 'all', got {table_valid!r}")
    imu_seed, *seeds = (int(s) for s in rng.integers(0, 2**62, size=1 + len(subranges)))
    imu = draw_imu("navigation", rng=np.random.default_rng(imu_seed), effects=effects, effect_scale=effect_scale,
                   errors=errors, curvature=curvature)
    azimuth = 0.0
    plans = []
    for i, ((lo, hi), seed) in enumerate(zip(subranges, seeds)):
        if file_stem is None:
            stem = f"sub{i + 1}_{_label(lo)}_{_label(hi)}"
        else:
            stem = file_stem
        width = hi - lo
        span = min(span_degC, width)
        start = lo + 0.5 * (width - span)
        desc = (f"graph-calib simulate {name}: navigation-grade IMU on a two-axis turntable, "
                f"subrange {lo:g}..{hi:g} degC, {hours:g} h at {rate_hz:g} Hz"
                + (f", effects {', '.join(effects)}" if effects else "") + ("" if noise else ", no noise")
                + ("" if errors else ", no errors") + (f"; {tag}" if tag else ""))
        make = partial(
            _make_table_experiment, file_name=f"{stem}.h5", scenario=name, imu=imu, imu_id=imu_id, seed=seed,
            rate_hz=float(rate_hz), duration_s=float(hours) * 3600.0, start_degC=start, span_degC=span,
            design=design, latitude_rad=np.radians(latitude_deg), gravity_mps2=float(gravity_mps2), noise=noise,
            valid=table_valid, encoder_rate_hz=float(encoder_rate_hz), azimuth_rad=azimuth, description=desc,
            tag=tag,
        )
        plans.append(ExperimentPlan(file_name=f"{stem}.h5", make=make,
                                    summary=f"subrange {lo:g}..{hi:g} degC, {hours:g} h"))
    info = {"hours": hours, "rate_hz": rate_hz, "noise": noise, "errors": errors, "effects": list(effects),
            "subranges": [list(s) for s in subranges]}
    return Simulation(scenario=name, imu_id=imu_id, grade="navigation", plans=tuple(plans), imu=imu, info=info)


_COMMON_DOC = """
    Common options: ``noise`` (False: no sensor, encoder or temperature noise),
    ``errors`` (False: every truth parameter zero), ``hours`` (length of each
    experiment), ``rate_hz``, ``effects`` (further effects of model.md switched
    on), ``effect_scale`` (multiplies their sizes), ``curvature`` (False: exactly
    linear temperature curves), ``latitude_deg``, ``gravity_mps2``,
    ``table_valid`` (``"static"`` or ``"all"``), ``encoder_rate_hz``, ``tag``
    (free text for the description and the truth file).
"""


def nav_subrange(*, rng, hours=1.5, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                 curvature=True, subrange=(20.0, 30.0), span_degC=8.0, latitude_deg=DEFAULT_LATITUDE_DEG,
                 gravity_mps2=DEFAULT_GRAVITY_MPS2, table_valid="static", encoder_rate_hz=10.0, tag=""):
    """One navigation-grade experiment: 1.5 h at 100 Hz, sensors drifting 8 degC through 20..30 degC.

    15 min static alignment, then rotations at 10-30 deg/s about each instrument
    axis held horizontal, both ways, with 20-40 s static positions between.
    """
    return _table_scenario("nav-subrange", rng=rng, subranges=(tuple(subrange),), hours=hours,
                           span_degC=span_degC, design=NAV_DESIGN, imu_id="SIM-NAV 0001", noise=noise,
                           errors=errors, rate_hz=rate_hz, effects=tuple(effects), effect_scale=effect_scale,
                           curvature=curvature, latitude_deg=latitude_deg, gravity_mps2=gravity_mps2,
                           table_valid=table_valid, encoder_rate_hz=encoder_rate_hz, tag=tag, file_stem=None)


def nav_subrange_short(*, rng, hours=0.3, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                       curvature=True, subrange=(20.0, 25.0), span_degC=5.0, latitude_deg=DEFAULT_LATITUDE_DEG,
                       gravity_mps2=DEFAULT_GRAVITY_MPS2, table_valid="static", encoder_rate_hz=10.0, tag="",
                       _name="nav-subrange-short", _stem=None):
    """The nav-subrange design in 18 min (3 min alignment, 15-25 s static positions), sensors drifting 5 degC."""
    return _table_scenario(_name, rng=rng, subranges=(tuple(subrange),), hours=hours, span_degC=span_degC,
                           design=SHORT_DESIGN, imu_id="SIM-NAV 0001", noise=noise, errors=errors,
                           rate_hz=rate_hz, effects=tuple(effects), effect_scale=effect_scale, curvature=curvature,
                           latitude_deg=latitude_deg, gravity_mps2=gravity_mps2, table_valid=table_valid,
                           encoder_rate_hz=encoder_rate_hz, tag=tag, file_stem=_stem)


def nav_campaign(*, rng, hours=1.5, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                 curvature=True, span_degC=8.0, latitude_deg=DEFAULT_LATITUDE_DEG, gravity_mps2=DEFAULT_GRAVITY_MPS2,
                 table_valid="static", encoder_rate_hz=10.0, tag=""):
    """Six navigation-grade experiments covering -10..+50 degC (one IMU), the nav-subrange design each."""
    return _table_scenario("nav-campaign", rng=rng, subranges=CAMPAIGN_SUBRANGES, hours=hours, span_degC=span_degC,
                           design=NAV_DESIGN, imu_id="SIM-NAV 0001", noise=noise, errors=errors, rate_hz=rate_hz,
                           effects=tuple(effects), effect_scale=effect_scale, curvature=curvature,
                           latitude_deg=latitude_deg, gravity_mps2=gravity_mps2, table_valid=table_valid,
                           encoder_rate_hz=encoder_rate_hz, tag=tag, file_stem=None)


def effect_scenario(effect, *, rng, hours=0.3, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                    curvature=True, latitude_deg=DEFAULT_LATITUDE_DEG, gravity_mps2=DEFAULT_GRAVITY_MPS2,
                    table_valid="static", encoder_rate_hz=10.0, tag=""):
    """nav-subrange-short with the further effect ``effect`` switched on (size from ``EFFECT_SIZES``)."""
    return nav_subrange_short(rng=rng, hours=hours, noise=noise, errors=errors, rate_hz=rate_hz,
                              effects=(effect,) + tuple(e for e in effects if e != effect),
                              effect_scale=effect_scale, curvature=curvature, latitude_deg=latitude_deg,
                              gravity_mps2=gravity_mps2, table_valid=table_valid, encoder_rate_hz=encoder_rate_hz,
                              tag=tag, _name=f"effect-{effect}", _stem=f"effect_{effect.replace('.', '_')}")


def consumer_handheld(*, rng, hours=None, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                      n_poses=30, initial_static_s=20.0, hold_s=(3.0, 10.0), turn_s=(1.0, 2.5), translation_m=0.05,
                      latitude_deg=DEFAULT_LATITUDE_DEG, gravity_mps2=DEFAULT_GRAVITY_MPS2, tag=""):
    """A consumer MEMS IMU turned by hand, no table: 20 s static, then 30 poses of 3-10 s.

    Between poses the hand turns the unit smoothly (1-2.5 s, to a random
    orientation at least 40 deg away) and moves it by a few cm.  The unit warms
    by 2-4 degC after power-on in a room drifting by up to 1 degC/h.  With
    ``hours`` the poses fill that length instead of ``n_poses``.
    """
    _check_common(hours, rate_hz, effect_scale, effects)
    if hours is None and not (isinstance(n_poses, (int, np.integer)) and n_poses >= 1):
        raise InputError(f"n_poses must be a positive integer, got {n_poses!r}")
    exclude = ("mount", "lever_arm", "time_lag.table")
    imu_seed, seed = (int(s) for s in rng.integers(0, 2**62, size=2))
    imu = draw_imu("consumer", rng=np.random.default_rng(imu_seed), effects=effects, effect_scale=effect_scale,
                   errors=errors, curvature=False, exclude=exclude)
    desc = ("graph-calib simulate consumer-handheld: consumer MEMS IMU turned by hand, no table"
            + ("" if noise else ", no noise") + ("" if errors else ", no errors") + (f"; {tag}" if tag else ""))
    make = partial(
        _make_handheld_experiment, file_name="handheld.h5", scenario="consumer-handheld", imu=imu,
        imu_id="SIM-MEMS 0001", seed=seed, rate_hz=float(rate_hz),
        duration_s=None if hours is None else float(hours) * 3600.0, n_poses=int(n_poses),
        initial_static_s=float(initial_static_s), hold_s=tuple(hold_s), turn_s=tuple(turn_s),
        translation_m=float(translation_m), latitude_rad=np.radians(latitude_deg),
        gravity_mps2=float(gravity_mps2), noise=noise, description=desc, tag=tag,
    )
    plan = ExperimentPlan(file_name="handheld.h5", make=make, summary="hand-held poses, no table")
    info = {"hours": hours, "rate_hz": rate_hz, "noise": noise, "errors": errors, "effects": list(effects)}
    return Simulation(scenario="consumer-handheld", imu_id="SIM-MEMS 0001", grade="consumer", plans=(plan,),
                      imu=imu, exclude=exclude, info=info)


@dataclass(frozen=True)
class Scenario:
    """A registry entry: name, one-line summary, ``build(*, rng, **options) -> Simulation``."""

    name: str
    summary: str
    build: Callable

    def options(self):
        """Keyword options the scenario accepts (name -> default)."""
        sig = inspect.signature(self.build)
        return {k: p.default for k, p in sig.parameters.items()
                if p.kind is p.KEYWORD_ONLY and k != "rng" and not k.startswith("_")}


def _registry():
    reg = {
        "nav-subrange": Scenario("nav-subrange", "navigation grade, one 1.5 h experiment at 100 Hz, 20..30 degC",
                                 nav_subrange),
        "nav-subrange-short": Scenario("nav-subrange-short", "the nav-subrange design shortened to 18 min, 5 degC",
                                       nav_subrange_short),
        "nav-campaign": Scenario("nav-campaign", "navigation grade, six 1.5 h experiments over -10..+50 degC",
                                 nav_campaign),
        "consumer-handheld": Scenario("consumer-handheld", "consumer MEMS turned by hand, no table, ~5 min",
                                      consumer_handheld),
    }
    for e in effects.FURTHER_EFFECTS:
        name = f"effect-{e}"
        build = partial(effect_scenario, e)
        build.__doc__ = effect_scenario.__doc__
        reg[name] = Scenario(name, f"nav-subrange-short with {e} switched on", build)
    return reg


#: Every scenario by name.
SCENARIOS = _registry()


def scenario_names():
    """Names of the known scenarios, in registry order."""
    return list(SCENARIOS)


def get_scenario(name):
    """The :class:`Scenario` called ``name``; :class:`InputError` listing the known ones."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise InputError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}") from None


def simulate(name, *, rng, **options):
    """Build scenario ``name`` with ``options`` (see each scenario's keyword arguments).

    Parameters
    ----------
    name : str
    rng : numpy.random.Generator
        The only source of randomness.
    **options
        Options of the scenario; ``None`` values take the scenario's default.

    Returns
    -------
    Simulation

    Raises
    ------
    InputError
        Unknown scenario, unknown option, or a bad option value.
    """
    sc = get_scenario(name)
    known = sc.options()
    unknown = [k for k in options if k not in known]
    if unknown:
        raise InputError(f"scenario {name!r} has no option {unknown[0]!r}; options: {', '.join(known)}")
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    opts = {k: v for k, v in options.items() if v is not None}
    return sc.build(rng=rng, **opts)


# ---------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------


def _toml_str(s):
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def manifest_text(simulation, *, tag=""):
    """The ``campaign.toml`` of a simulation (data-format.md; ``[model] exclude`` without a table)."""
    lines = [f"# written by graph-calib simulate {simulation.scenario}" + (f" ({tag})" if tag else ""),
             "# truth of each experiment: <file stem>.truth.json next to it", "",
             "[imu]", f"id = {_toml_str(simulation.imu_id)}", f"grade = {_toml_str(simulation.grade)}", ""]
    if simulation.exclude:
        lines += ["[model]", "exclude = [" + ", ".join(_toml_str(n) for n in simulation.exclude) + "]", ""]
    for p in simulation.plans:
        lines += ["[[experiment]]", f"file = {_toml_str(p.file_name)}", ""]
    return "\n".join(lines)


def write_simulation(simulation, out_dir, *, progress=None, tag=""):
    """Make every experiment of a simulation and write it, one at a time.

    Writes ``<stem>.h5`` (:func:`graph_calib.io.write_experiment`),
    ``<stem>.truth.json`` (:func:`graph_calib.io.write_result`) per experiment,
    then ``campaign.toml``; every file atomically.

    Parameters
    ----------
    simulation : Simulation
    out_dir : str or Path
        Created if missing.
    progress : callable, optional
        Called with a short message before each experiment.
    tag : str
        Written in the manifest's header comment.

    Returns
    -------
    list of dict
        Per experiment: ``file``, ``truth`` (paths), ``n_samples``, ``hours``,
        ``temperature_range_degC``, ``t_ref_degC``, ``table_readings``,
        ``valid_readings``, ``n_parameters``; and a last entry ``{"manifest": path}``.
    """
    from graph_calib import io

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc}", path=out) from None
    if not out.is_dir():
        raise InputError("is not a folder", path=out)
    summary = []
    for i, plan in enumerate(simulation.plans):
        if progress is not None:
            progress(f"[{i + 1}/{len(simulation.plans)}] simulating {plan.file_name} ({plan.summary})")
        se = plan.run()
        io.write_experiment(se.experiment, out / se.file_name)
        io.write_result(se.truth, out / se.truth_name)
        e = se.experiment
        summary.append({
            "file": out / se.file_name, "truth": out / se.truth_name, "n_samples": e.n_samples,
            "hours": e.n_samples / e.rate_hz / 3600.0, "rate_hz": e.rate_hz,
            "temperature_range_degC": se.truth.temperature_range_degC, "t_ref_degC": se.truth.t_ref_degC,
            "table_readings": 0 if e.table is None else int(e.table.t.size),
            "valid_readings": 0 if e.table is None else int(np.count_nonzero(e.table.valid)),
            "n_parameters": len(se.truth.values),
        })
        del se
    manifest = out / "campaign.toml"
    io.atomic_write_text(manifest, manifest_text(simulation, tag=tag))
    summary.append({"manifest": manifest})
    return summary


__all__ = [
    "Design", "NAV_DESIGN", "SHORT_DESIGN", "rotation_program", "SimulatedExperiment", "ExperimentPlan",
    "Simulation", "Scenario", "SCENARIOS", "scenario_names", "get_scenario", "simulate", "manifest_text",
    "write_simulation", "nav_subrange", "nav_subrange_short", "nav_campaign", "consumer_handheld",
    "effect_scenario", "CAMPAIGN_SUBRANGES", "NAV_CHANNELS", "NAV_TEMPERATURE_MAP", "DEFAULT_LATITUDE_DEG",
    "DEFAULT_GRAVITY_MPS2",
]
