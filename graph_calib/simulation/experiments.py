r"""Simulated experiments: the turntable and hand-held builders and their truth.

:func:`_make_table_experiment` makes a navigation-grade experiment on the
two-axis table (rotation programme, chamber and temperature lags, increments,
encoder readings); :func:`_make_handheld_experiment` a consumer IMU turned by
hand (no table).  Each returns a :class:`SimulatedExperiment`: the
:class:`~graph_calib.records.experiment.Experiment`, its truth
:class:`~graph_calib.records.experiment.Result` (``solver = "truth"``) and the true
signals, temperatures and parameters behind them.

Both builders draw everything from the ``seed`` they are given: independent
generators (drawn from it) serve the programme, the thermal set-up and the
noise, so switching the noise off changes nothing else, bit for bit.  The
scenarios (:mod:`graph_calib.simulation.scenarios`) bind their arguments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.sensors import params
from graph_calib.records.experiment import Experiment, Result, Table
from graph_calib.navigation.rotations import exp_so3, log_so3, quat_to_dcm
from graph_calib.simulation.design import rotation_program
from graph_calib.simulation.ferraris import ferraris_motion
from graph_calib.simulation.handheld import HandheldMotion
from graph_calib.simulation.imu import SensorNoiseSpec, SignalModel, add_sensor_noise, simulate_increments
from graph_calib.simulation.thermal import ThermalModel, ramp_chamber
from graph_calib.simulation.truth import curvature_fit_offsets
from graph_calib.simulation.turntable import TurntableMotion, encoder_readings, rot_z

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
#: Channels of a unit with a temperature sensor at each of the six sensors, each lagging the chamber with its own
#: time constant (name, minutes, self-heating offset degC); the chamber last.
SENSOR_CHANNELS = (
    ("gyro_x", 20.0, 0.8),
    ("gyro_y", 28.0, 0.6),
    ("gyro_z", 35.0, 1.0),
    ("accel_x", 12.0, 0.4),
    ("accel_y", 16.0, 0.5),
    ("accel_z", 22.0, 0.3),
    ("chamber", 0.0, 0.0),
)
SENSOR_TEMPERATURE_MAP = (0, 1, 2, 3, 4, 5)

#: Sinusoids per axis of a hand's sway (:meth:`HandheldMotion.sway`).
HAND_SWAY_TERMS = 4

#: One-sigma noise of a recorded temperature, degC (when noise is on).
TEMPERATURE_NOISE = {"navigation": 0.005, "tactical": 0.01, "consumer": 0.02}


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


def _child_rngs(seed, k):
    rng = np.random.default_rng(seed)
    return [np.random.default_rng(int(s)) for s in rng.integers(0, 2**62, size=k)]


def _as_list(a):
    return [float(v) for v in np.ravel(a)]


def _truth_result(*, file_name, imu, t_ref, T_rec_sensors, tl, x_truth, unmodelled, info):
    sensor_dT = T_rec_sensors - t_ref
    sim = dict(info)
    sim["unmodelled"] = unmodelled
    sim["curvature_fit_offsets"] = curvature_fit_offsets(imu, sensor_dT, t_ref=t_ref)
    if imu.cubic:
        sim["cubic"] = {p: [float(v) for v in c3] for p, c3 in imu.cubic.items()}
    # the truth over the whole range (data-format.md), beside the values at this experiment's T_ref
    return Result(
        source=file_name, solver="truth", t_ref_degC=float(t_ref),
        temperature_range_degC=(float(T_rec_sensors.min()), float(T_rec_sensors.max())),
        effects=tuple(tl.names), values=tl.to_dict(x_truth), sigmas=None,
        extra={"temperature_curves": imu.temperature_curves(), "simulation": sim},
    )


def _make_table_experiment(*, file_name, scenario, imu, imu_id, seed, rate_hz, duration_s, start_degC, span_degC,
                           design, latitude_rad, gravity_mps2, noise, valid, encoder_rate_hz, azimuth_rad,
                           description, tag, program=None, thermal=None, channels=NAV_CHANNELS,
                           temperature_map=NAV_TEMPERATURE_MAP, noise_factor=1.0, encoder_noise_rad=None,
                           gyro_quantization_rad=0.0, start_in_motion=False):
    """``program`` and ``thermal`` (a bench program's, :mod:`graph_calib.simulation.program`) replace the
    rotation design's programme and the ramped chamber; ``design``, ``duration_s``, ``start_degC`` and
    ``span_degC`` are then unused.

    ``noise_factor`` multiplies the grade's gyro and accelerometer densities, ``encoder_noise_rad`` replaces
    its table-reading noise, ``gyro_quantization_rad`` adds a ring-laser gyro's angle quantization
    (:class:`graph_calib.simulation.imu.SensorNoiseSpec`), and ``start_in_motion`` cuts the record so that it
    begins one second into the first motion (its initial rest gone)."""
    g = params.grade(imu.grade)
    r_prog, r_therm, r_noise = _child_rngs(seed, 3)
    spec = SensorNoiseSpec(gyro=g.gyro_noise * noise_factor, accel=g.accel_noise * noise_factor,
                           gyro_quantization=float(gyro_quantization_rad))
    enc_sigma = g.encoder_noise if encoder_noise_rad is None else float(encoder_noise_rad)
    if program is None:
        program = rotation_program(rate_hz, duration_s, rng=r_prog, design=design)

    if thermal is None:
        names = tuple(c[0] for c in channels)
        tau = np.array([c[1] for c in channels]) * 60.0 * r_therm.uniform(0.9, 1.1, len(names))
        offset = np.array([c[2] for c in channels]) + np.where(tau > 0, r_therm.normal(0.0, 0.1, len(names)),
                                                               0.0)
        pattern = np.array([1.0, 0.55, 1.4]) * r_therm.uniform(0.85, 1.15, 3)
        thermal = ramp_chamber(duration=program.duration, start_degC=start_degC, span_degC=span_degC, names=names,
                               tau=tau, offset=offset, temperature_map=temperature_map, pattern=tuple(pattern))
    names = tuple(thermal.names)
    tau, offset = np.asarray(thermal.tau), np.asarray(thermal.offset)

    n = program.n_ticks
    t = np.arange(1, n + 1) / rate_hz
    tmap = np.array(temperature_map)
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
        add_sensor_noise(dtheta, dv, spec, dt=dt, rng=r_noise, rng_quantization=np.random.default_rng([seed, 2]))
    lag = float(sl.get(x_sim, "time_lag.table", np.zeros(1))[0])
    tt, q_nf, ok = encoder_readings(motion, t_end=t[-1], rate_hz=encoder_rate_hz, time_lag=lag,
                                    noise_rad=enc_sigma if noise else 0.0, rng=r_noise, valid=valid)
    if start_in_motion:
        k0 = _first_motion_sample(motion, t) + int(round(rate_hz))
        t, dtheta, dv, T_rec = t[k0:], dtheta[k0:], dv[k0:], T_rec[k0:]
        keep_r = tt > t[0] - dt
        tt, q_nf, ok = tt[keep_r], q_nf[keep_r], ok[keep_r]
    experiment = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=T_rec, temperature_names=names,
        temperature_map=tmap.copy(), rate_hz=float(rate_hz), latitude_rad=float(latitude_rad),
        gravity_mps2=float(gravity_mps2), imu_id=imu_id, description=description,
        table=Table(t=tt, q_nf=q_nf, valid=ok, q_fb_nominal=q_fb_nominal), source=file_name,
    )
    info = {
        "scenario": scenario, "tag": tag, "grade": imu.grade, "effects_on": list(imu.effects),
        "noise": {"gyro_noise": spec.gyro if noise else 0.0, "accel_noise": spec.accel if noise else 0.0,
                  "encoder_noise_rad": enc_sigma if noise else 0.0, "temperature_noise_degC": sig_T,
                  "gyro_quantization_rad": spec.gyro_quantization if noise else 0.0},
        "start_in_motion": bool(start_in_motion),
        "table": {"outer_axis": "horizontal, base x (azimuth from East)", "azimuth_rad": float(azimuth_rad),
                  "encoder_rate_hz": float(encoder_rate_hz), "valid": valid},
        "chamber": {"t_s": _as_list(thermal.chamber_t), "T_degC": _as_list(thermal.chamber_T)},
        "channels": {"names": list(names), "tau_s": _as_list(tau), "offset_degC": _as_list(offset)},
    }
    truth = _truth_result(file_name=file_name, imu=imu, t_ref=t_ref, T_rec_sensors=T_rec[:, tmap], tl=tl,
                          x_truth=x_truth, unmodelled=unmodelled, info=info)
    return SimulatedExperiment(file_name=file_name, experiment=experiment, truth=truth, signals=signals,
                               thermal=thermal, layout=sl, x=x_sim)


def _first_motion_sample(motion, t):
    """The first sample whose true rate against the level frame is not zero (0 when none is)."""
    for a in range(0, t.size, 65536):
        w = np.linalg.norm(motion.kinematics(t[a:a + 65536]).omega_nb_b, axis=1)
        hit = np.flatnonzero(w > 1e-9)
        if hit.size:
            return a + int(hit[0])
    return 0


def _random_rotation(rng):
    q = rng.standard_normal(4)
    return quat_to_dcm(q / np.linalg.norm(q))


def cut_out(motion, drop):
    """Sample selection and ``/imu/segment`` of a session with the turns ``drop`` cut out.

    Parameters
    ----------
    motion : graph_calib.simulation.handheld.HandheldMotion
    drop : iterable of int
        Turns (counted from 0 in the order made) whose samples are removed.

    Returns
    -------
    keep : ndarray of bool, shape (N,)
        Samples kept (sample ``i`` covers tick ``i``).
    segment : ndarray of int32, shape (N_kept,)
        Segment of each kept sample: a new one after each removed turn.
    """
    n = int(round(motion.duration * motion.rate_hz))
    keep = np.ones(n, dtype=bool)
    seg = np.zeros(n, dtype=np.int32)
    drop = set(drop)
    for i, (start, count) in enumerate(motion.turn_ticks()):
        if i in drop:
            keep[start:start + count] = False
            seg[start + count:] += 1
    return keep, seg[keep]


def _random_poses(r_prog, *, rate_hz, duration_s, n_poses, initial_static_s, hold_s, turn_s, translation_m):
    """Random poses joined by hand turns: ``(motion, number of turns)``."""
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
    return motion, k


def _make_handheld_experiment(*, file_name, scenario, imu, imu_id, seed, rate_hz, duration_s, n_poses,
                              initial_static_s, hold_s, turn_s, translation_m, latitude_rad, gravity_mps2,
                              noise, description, tag, cut=False, pivot_m=0.0, hand_accel_mps2=0.0,
                              program="poses", noise_factor=1.0, face_s=10.0, rest_s=5.0, gyro_noise_factor=1.0,
                              guided=False):
    g = params.grade(imu.grade)
    spec = SensorNoiseSpec(gyro=g.gyro_noise * noise_factor * gyro_noise_factor, accel=g.accel_noise * noise_factor)
    r_prog, r_therm, r_noise = _child_rngs(seed, 3)
    if program == "ferraris":
        motion, full_turns = ferraris_motion(rate_hz, rng=r_prog, initial_static_s=initial_static_s,
                                              face_s=face_s, rest_s=rest_s, guided=guided)
        k = len(motion.turn_ticks())
    else:
        motion, k = _random_poses(r_prog, rate_hz=rate_hz, duration_s=duration_s, n_poses=n_poses,
                                  initial_static_s=initial_static_s, hold_s=hold_s, turn_s=turn_s,
                                  translation_m=translation_m)
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
    segment = None
    if cut:
        # every second turn cut out, the time stamps left continuous (no gap to see): one segment per piece
        # (the Ferraris programme: the turns between faces, each face and each full turn a piece); T_ref is
        # the mean over the samples kept, as a calibration of the cut record takes it
        drop = [i for i in range(k) if i not in full_turns] if program == "ferraris" else range(1, k, 2)
        keep, segment = cut_out(motion, drop)
    t_ref = float(np.mean((T_rec[keep] if cut else T_rec)[:, tmap]))
    tl, x_truth, sl, x_sim, unmodelled = imu.at(t_ref)
    # the hand: its pivot sways (HAND_SWAY_TERMS sinusoids per axis, 0.3-3 Hz, hand_accel_mps2 rms of |a|) and
    # the sensor sits pivot_m from it in a random body direction; drawn from a generator of their own, so
    # that every other draw of the seed stays what it was
    lever = None
    if pivot_m > 0 or hand_accel_mps2 > 0:
        r_hand = np.random.default_rng([seed, 1])
        u = r_hand.normal(size=3)
        lever = float(pivot_m) * u / np.linalg.norm(u)
        m = HAND_SWAY_TERMS
        amp = float(hand_accel_mps2) / np.sqrt(1.5 * m) * np.ones((m, 3))
        motion.sway(amplitude=amp, omega=2.0 * np.pi * r_hand.uniform(0.3, 3.0, (m, 3)),
                    phase=r_hand.uniform(0.0, 2.0 * np.pi, (m, 3)))
    signals = SignalModel(motion, latitude_rad=latitude_rad, gravity_mps2=gravity_mps2, rate_hz=rate_hz,
                          lever_arm=lever)
    t, dtheta, dv = simulate_increments(signals, thermal, rate_hz=rate_hz, n_samples=n, layout=sl, x=x_sim,
                                        t_ref=t_ref, temperature_map=tmap)
    dt = 1.0 / rate_hz
    if noise:
        add_sensor_noise(dtheta, dv, spec, dt=dt, rng=r_noise)
    if cut:
        t, dtheta, dv, T_rec = t[: keep.sum()], dtheta[keep], dv[keep], T_rec[keep]
    experiment = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=T_rec, temperature_names=("imu",), temperature_map=tmap,
        rate_hz=float(rate_hz), latitude_rad=float(latitude_rad), gravity_mps2=float(gravity_mps2),
        imu_id=imu_id, description=description, table=None, source=file_name, segment=segment,
    )
    info = {
        "scenario": scenario, "tag": tag, "grade": imu.grade, "effects_on": list(imu.effects),
        "noise": {"gyro_noise": spec.gyro if noise else 0.0, "accel_noise": spec.accel if noise else 0.0,
                  "temperature_noise_degC": sig_T},
        "poses": k, "translation_m": float(translation_m),
        "segments": 1 if segment is None else int(segment[-1]) + 1,
        "hand": {"pivot_to_sensor_b_m": [] if lever is None else _as_list(lever),
                 "sway_rms_mps2": float(hand_accel_mps2)},
        "chamber": {"t_s": _as_list(thermal.chamber_t), "T_degC": _as_list(thermal.chamber_T)},
        "channels": {"names": ["imu"], "tau_s": _as_list(thermal.tau), "offset_degC": _as_list(thermal.offset)},
    }
    truth = _truth_result(file_name=file_name, imu=imu, t_ref=t_ref, T_rec_sensors=T_rec[:, tmap], tl=tl,
                          x_truth=x_truth, unmodelled=unmodelled, info=info)
    return SimulatedExperiment(file_name=file_name, experiment=experiment, truth=truth, signals=signals,
                               thermal=thermal, layout=sl, x=x_sim)


__all__ = ["SimulatedExperiment", "cut_out", "NAV_CHANNELS", "NAV_TEMPERATURE_MAP", "SENSOR_CHANNELS",
           "SENSOR_TEMPERATURE_MAP", "TEMPERATURE_NOISE"]
