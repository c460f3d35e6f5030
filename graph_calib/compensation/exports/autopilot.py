r"""PX4 and ArduPilot temperature-calibration parameters: a bias-only cubic per axis over temperature.

PX4 (``TC_G{n}_*``, ``TC_A{n}_*``, a QGroundControl parameter file)
    As PX4's thermal compensation evaluates them: with ``T`` clamped to
    ``[TMIN, TMAX]``, ``offset = X0 + X1 dT + X2 dT^2 + X3 dT^3`` per axis, ``dT = T -
    TREF``, and ``corrected = raw - offset`` (rad/s, m/s^2); the table is used only when
    ``TC_G_ENABLE``/``TC_A_ENABLE`` is 1 and ``TC_G{n}_ID``/``TC_A{n}_ID`` is the
    sensor's device id.  Coefficients are float32 on the vehicle; they are written
    (and the loss is computed) rounded to float32.
ArduPilot (``INS_TCAL{n}_*``, a ``.parm`` file)
    As ``AP_InertialSensor`` temperature calibration evaluates them: ``p(d) = (c1 d +
    c2 d^2 + c3 d^3) 1e-6`` with ``d`` the temperature minus the reference 35 degC
    (``ACC1``/``GYR1`` first order ... ``ACC3``/``GYR3`` third, stored times 1e6), both
    temperatures clamped to ``[TMIN, TMAX]``, and ``raw - p(T - 35) + p(T_cal - 35)``
    before the offsets measured at ``T_cal`` (``INS_GYROFFS_*`` at boot,
    ``INS_ACCOFFS_*`` by the accelerometer calibration, with
    ``INS_GYR1_CALTEMP``/``INS_ACC1_CALTEMP``): the constant term is left to the offsets.
    The loss is computed with the offsets measured at the reference temperature; the
    file states the offsets the model gives there, as comments.

Both hold the bias only: everything else the model has is reported as left out, with the
largest remaining error over the calibrated range (:mod:`.projection`).  The sensor
axes are taken to be graph-calib's body axes (the autopilot's board rotation is its own).
"""

from __future__ import annotations

import numpy as np

from graph_calib.compensation.exports.projection import (
    BIAS_PARAMETERS, bias_cubic, cubic, left_out, remaining,
)

#: ArduPilot's reference temperature of the polynomial, degC.
ARDUPILOT_TREF_DEGC = 35.0
#: ArduPilot's parameter scale (coefficients are stored times this).
ARDUPILOT_SCALE = 1e6
_INT32, _REAL32 = 6, 9        # MAV_PARAM_TYPE of QGroundControl's parameter files


def _f32(x):
    """A float32 as text that reads back to the same float32."""
    return f"{float(np.float32(x)):.9g}"


def px4_restored(doc):
    """What PX4 subtracts, from the parameters of a :func:`px4_document` (used by the loss)."""
    p = doc["params"]
    n = doc["instance"]

    def coef(kind):
        return np.array([[p[f"TC_{kind}{n}_X{i}_{a}"] for a in range(3)] for i in range(4)], dtype=float)

    cg, ca = coef("G"), coef("A")

    def restored(T, omega, f):
        out = []
        for kind, cf in (("G", cg), ("A", ca)):
            Tc = np.clip(T, p[f"TC_{kind}{n}_TMIN"], p[f"TC_{kind}{n}_TMAX"])
            out.append(cubic(cf, Tc - p[f"TC_{kind}{n}_TREF"]))
        return tuple(out)
    return restored


def px4_document(source, *, instance=0, gyro_id=0, accel_id=0, envelope_dps):
    """``{"params": {name: value}, "types": {name: type}, "loss": Loss, "instance": n}``."""
    tmin, tmax = (round(v, 2) for v in source.range_degC)
    tref = round(source.t_ref_degC, 2)
    cg, ca = bias_cubic(source, tref)
    params, types = {"TC_G_ENABLE": 1, "TC_A_ENABLE": 1}, {"TC_G_ENABLE": _INT32, "TC_A_ENABLE": _INT32}
    for kind, dev, cf in (("G", gyro_id, cg), ("A", accel_id, ca)):
        pre = f"TC_{kind}{instance}_"
        params[pre + "ID"], types[pre + "ID"] = int(dev), _INT32
        for key, v in (("TMIN", tmin), ("TMAX", tmax), ("TREF", tref)):
            params[pre + key], types[pre + key] = float(np.float32(v)), _REAL32
        for i in range(4):
            for a in range(3):
                params[f"{pre}X{i}_{a}"], types[f"{pre}X{i}_{a}"] = float(cf[i, a]), _REAL32
    doc = {"params": params, "types": types, "instance": instance}
    doc["loss"] = remaining(source, px4_restored(doc), envelope_dps=envelope_dps,
                            left_out=left_out(source, BIAS_PARAMETERS))
    return doc


def px4_text(source, doc):
    """The QGroundControl parameter file (tab-separated ``vehicle component name value type``)."""
    lines = ["# PX4 thermal compensation (TC_*) written by graph-calib from the " + source.label,
             "# PX4 evaluates offset = X0 + X1 dT + X2 dT^2 + X3 dT^3, dT = clamp(T, TMIN, TMAX) - TREF, and "
             "subtracts it (rad/s, m/s^2).",
             "# Set TC_G{n}_ID and TC_A{n}_ID to the sensors' device ids (CAL_GYRO0_ID, CAL_ACC0_ID) if they are 0 "
             "here: PX4 ignores a table whose id does not match."]
    lines += [f"# {line}" for line in doc["loss"].lines()]
    lines += ["#", "# Vehicle-Id\tComponent-Id\tName\tValue\tType"]
    for name, value in doc["params"].items():
        text = str(int(value)) if doc["types"][name] == _INT32 else _f32(value)
        lines.append(f"1\t1\t{name}\t{text}\t{doc['types'][name]}")
    return "\n".join(lines) + "\n"


def ardupilot_restored(doc):
    """What ArduPilot removes (its polynomial and the offsets measured at the calibration temperature)."""
    p, n = doc["params"], doc["instance"]
    pre = f"INS_TCAL{n}_"
    out = {}
    for kind in ("GYR", "ACC"):
        c = np.zeros((4, 3))
        for i in (1, 2, 3):
            c[i] = [p[f"{pre}{kind}{i}_{a}"] / ARDUPILOT_SCALE for a in "XYZ"]
        out[kind] = c
    t_cal, offsets = doc["cal_temp_degC"], doc["offsets"]

    def restored(T, omega, f):
        res = []
        for kind in ("GYR", "ACC"):
            Tc = np.clip(T, p[pre + "TMIN"], p[pre + "TMAX"])
            tc = np.clip(t_cal, p[pre + "TMIN"], p[pre + "TMAX"])
            res.append(offsets[kind] + cubic(out[kind], Tc - ARDUPILOT_TREF_DEGC)
                       - cubic(out[kind], np.atleast_1d(tc - ARDUPILOT_TREF_DEGC)))
        return tuple(res)
    return restored


def ardupilot_document(source, *, instance=1, envelope_dps):
    """``{"params", "instance", "cal_temp_degC", "offsets", "loss"}``; offsets at the reference temperature."""
    tmin, tmax = (round(v, 2) for v in source.range_degC)
    cg, ca = bias_cubic(source, ARDUPILOT_TREF_DEGC, dtype=np.float64)
    pre = f"INS_TCAL{instance}_"
    params = {pre + "ENABLE": 1, pre + "TMIN": tmin, pre + "TMAX": tmax}
    for kind, cf in (("ACC", ca), ("GYR", cg)):
        for i in (1, 2, 3):
            for a, axis in enumerate("XYZ"):
                params[f"{pre}{kind}{i}_{axis}"] = float(np.float32(cf[i, a] * ARDUPILOT_SCALE))
    t_cal = round(source.t_ref_degC, 2)
    z = np.zeros((1, 3))
    bg, ba = source.errors(np.full(1, t_cal), z, z)
    doc = {"params": params, "instance": instance, "cal_temp_degC": t_cal,
           "offsets": {"GYR": bg[0].astype(np.float32).astype(float), "ACC": ba[0].astype(np.float32).astype(float)}}
    doc["loss"] = remaining(source, ardupilot_restored(doc), envelope_dps=envelope_dps,
                            left_out=left_out(source, BIAS_PARAMETERS),
                            extra=(f"offsets taken as measured at {t_cal:g} degC (INS_GYR{instance}_CALTEMP, "
                                   f"INS_ACC{instance}_CALTEMP); the constant term is left to them",))
    return doc


def ardupilot_text(source, doc):
    """The ``.parm`` file: ``NAME VALUE`` lines, ``#`` comments."""
    n = doc["instance"]
    lines = ["# ArduPilot temperature calibration (INS_TCALn_*) written by graph-calib from the " + source.label,
             "# AP_InertialSensor corrects raw - p(T - 35) + p(T_cal - 35), p(d) = (c1 d + c2 d^2 + c3 d^3) * 1e-6, "
             "T clamped to [TMIN, TMAX]; the constant term is left to the offsets.",
             f"# Offsets the model gives at {doc['cal_temp_degC']:g} degC (ArduPilot measures its own; shown to "
             "compare):"]
    off = doc["offsets"]
    for key, kind in (("INS_GYROFFS", "GYR"), ("INS_ACCOFFS", "ACC")):
        lines.append("#   " + "  ".join(f"{key}_{a} {_f32(v)}" for a, v in zip("XYZ", off[kind])))
    lines += [f"# {line}" for line in doc["loss"].lines()]
    for name, value in doc["params"].items():
        lines.append(f"{name} {value if isinstance(value, int) else _f32(value)}")
    del n
    return "\n".join(lines) + "\n"


__all__ = ["px4_document", "px4_text", "px4_restored", "ardupilot_document", "ardupilot_text", "ardupilot_restored",
           "ARDUPILOT_TREF_DEGC", "ARDUPILOT_SCALE"]
