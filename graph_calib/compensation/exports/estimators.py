r"""Kalibr's ``imu.yaml`` and OpenVINS's ``kalibr_imu_chain.yaml``: noise figures and constant intrinsics.

Noise
    Continuous-time densities, the units both tools want: ``gyroscope_noise_density``
    rad/s/sqrt(Hz) (= rad/sqrt(s)), ``accelerometer_noise_density`` m/s^2/sqrt(Hz),
    ``gyroscope_random_walk`` rad/s^2/sqrt(Hz), ``accelerometer_random_walk``
    m/s^3/sqrt(Hz).  They discretise with ``update_rate`` themselves: the figures are
    not to be multiplied by sqrt(rate).  Read from the result's ``noise`` block
    (data-format.md): ``gyro_rad_per_sqrt_s``, ``accel_mps_per_sqrt_s`` and the
    random walks ``gyro_random_walk_rad_per_s_per_sqrt_s``,
    ``accel_random_walk_mps2_per_sqrt_s``.  A figure the result lacks falls back to the
    grade's (:data:`graph_calib.sensors.params.GRADES`; a random walk as the grade's bias
    prior reached in one hour, ``sigma_b / sqrt(3600 s)``) with a note saying so.
Intrinsics (:func:`graph_calib.compensation.exports.projection.intrinsics`)
    Kalibr's ``scale-misalignment`` model as its documentation writes it,
    ``omega_m = M_g C_gyro_i omega + A a + b_g`` and ``a_m = M_a a + b_a``, ``M``
    lower triangular, the IMU frame the accelerometers'; OpenVINS's ``kalibr`` model,
    ``w_m = Tw R_IMUtoGYRO w + Tg a + b_g`` and ``a_m = Ta R_IMUtoACC a + b_a`` with
    ``Tw = M_g``, ``R_IMUtoGYRO = C_gyro_i``, ``Ta = M_a``, ``R_IMUtoACC = I``,
    ``Tg = A``.  Biases are the estimators' online states and are not written.
"""

from __future__ import annotations

import math

import numpy as np
import yaml

from graph_calib.compensation.exports.projection import (
    INTRINSIC_PARAMETERS, intrinsics, intrinsics_restored, left_out, remaining,
)
from graph_calib.constants import MPS2_TO_UG, RS_TO_DH
from graph_calib.sensors.params import GRADES

#: Names of the noise block's figures (data-format.md; the random walks as the noise identification writes them).
NOISE_KEYS = {"gyroscope_noise_density": "gyro_rad_per_sqrt_s",
              "accelerometer_noise_density": "accel_mps_per_sqrt_s",
              "gyroscope_random_walk": "gyro_random_walk_rad_per_s_per_sqrt_s",
              "accelerometer_random_walk": "accel_random_walk_mps2_per_sqrt_s"}
#: The time over which a grade's bias prior is taken as reached by a random walk (fallback), s.
RANDOM_WALK_FALLBACK_S = 3600.0


def noise_figures(source):
    """``({Kalibr key: value}, [notes])`` from the result's noise block, falling back to the grade's figures."""
    noise = source.noise or {}
    grade = GRADES.get(source.grade or "", None)
    out, notes = {}, []
    fallback = {}
    if grade is not None:
        fallback = {"gyroscope_noise_density": grade.gyro_noise, "accelerometer_noise_density": grade.accel_noise,
                    "gyroscope_random_walk": grade.prior_sigma["gyro.bias"] / math.sqrt(RANDOM_WALK_FALLBACK_S),
                    "accelerometer_random_walk": grade.prior_sigma["accel.bias"] / math.sqrt(RANDOM_WALK_FALLBACK_S)}
    for key, name in NOISE_KEYS.items():
        value = noise.get(name)
        if isinstance(value, (int, float)) and value > 0:
            out[key] = float(value)
            src = (noise.get("source") or {}).get(name.split("_")[0]) if "random_walk" not in name else None
            if src and src != "identified":
                notes.append(f"{key}: {name} {value:.4g} is {src}, not identified from the record")
        elif key in fallback:
            out[key] = float(fallback[key])
            how = ("the grade's bias prior reached in one hour" if "random_walk" in key else "the grade's figure")
            notes.append(f"{key}: the result has no {name}: written as {how} ({source.grade}: {out[key]:.4g})")
        else:
            out[key] = None
            notes.append(f"{key}: the result has no {name} and no grade: left empty (null); fill it before use")
    return out, notes


def _matrix(m):
    return [[float(v) + 0.0 for v in row] for row in np.asarray(m)]  # + 0.0: no -0.0 in the file


def _intrinsics_and_loss(source, envelope_dps):
    intr = intrinsics(source, source.t_ref_degC)
    T = np.linspace(*source.range_degC, 41)
    z = np.zeros((T.size, 3))
    bg, ba = source.errors(T, z, z)
    drift = (f"biases not written (the estimator's online states): over the range they change by "
             f"{np.abs(bg - bg[0]).max() * RS_TO_DH:.4g} deg/h (gyro) and {np.abs(ba - ba[0]).max() * MPS2_TO_UG:.4g} "
             "micro-g (accel), which the random walks must let the estimator follow")
    frame = (f"IMU frame of this file: the accelerometers' (rotated {intr.rotation_deg():.4g} deg from graph-calib's "
             f"body frame by R_body_to_imu = {_matrix(intr.R_body_to_imu)})")
    # a campaign's curves: the file holds the intrinsics at one temperature, their change over the range is left out
    curves = getattr(source.compensation, "curve_elements", lambda: ())()
    varying = sorted({e.rsplit(".", 1)[0] for e in curves} & (set(INTRINSIC_PARAMETERS) - BIASES))
    held_at = tuple(f"{p} over temperature (held at {source.t_ref_degC:.4g} degC)" for p in varying)
    loss = remaining(source, intrinsics_restored(source, intr), envelope_dps=envelope_dps,
                     left_out=left_out(source, INTRINSIC_PARAMETERS) + held_at, extra=(drift, frame))
    return intr, loss


#: The biases: not written (the estimator's online states), their drift over the range said apart.
BIASES = {"gyro.bias", "accel.bias"}


def _header(source, title, loss, notes):
    lines = [f"# {title} written by graph-calib from the {source.label}",
             "# noise densities are continuous-time (Kalibr's units); do not multiply them by sqrt(update_rate)"]
    lines += [f"# {line}" for line in loss.lines()]
    lines += [f"# note: {n}" for n in notes]
    return lines


def kalibr_document(source, *, rostopic, rate_hz, envelope_dps):
    """``{"yaml": dict, "loss": Loss, "notes": [...]}`` of Kalibr's imu.yaml."""
    noise, notes = noise_figures(source)
    intr, loss = _intrinsics_and_loss(source, envelope_dps)
    doc = {"rostopic": rostopic, "update_rate": float(rate_hz), **noise, "model": "scale-misalignment",
           "gyroscopes": {"M": _matrix(intr.M_g), "A": _matrix(intr.G_i), "C_gyro_i": _matrix(intr.C_gyro_i)},
           "accelerometers": {"M": _matrix(intr.M_a)}}
    return {"yaml": doc, "loss": loss, "notes": notes, "intrinsics": intr}


def openvins_document(source, *, rostopic, rate_hz, envelope_dps):
    """``{"yaml": dict, "loss": Loss, "notes": [...]}`` of OpenVINS's kalibr_imu_chain.yaml."""
    noise, notes = noise_figures(source)
    intr, loss = _intrinsics_and_loss(source, envelope_dps)
    imu0 = {"T_i_b": _matrix(np.eye(4)), **noise, "model": "kalibr", "rostopic": rostopic, "time_offset": 0.0,
            "update_rate": float(rate_hz), "Tw": _matrix(intr.M_g), "R_IMUtoGYRO": _matrix(intr.C_gyro_i),
            "Ta": _matrix(intr.M_a), "R_IMUtoACC": _matrix(np.eye(3)), "Tg": _matrix(intr.G_i)}
    return {"yaml": {"imu0": imu0}, "loss": loss, "notes": notes, "intrinsics": intr}


def yaml_text(source, doc, *, title, directive=None):
    """The YAML file: comments (what it holds, what it leaves out, the notes), then the document."""
    body = yaml.safe_dump(doc["yaml"], sort_keys=False, default_flow_style=None, width=120)
    head = _header(source, title, doc["loss"], doc["notes"])
    return "\n".join(([directive] if directive else []) + head) + "\n" + body


__all__ = ["noise_figures", "kalibr_document", "openvins_document", "yaml_text", "NOISE_KEYS"]
