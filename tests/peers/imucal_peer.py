"""imucal (mad-lab-fau/imucal, PyPI) run beside the product: its closed-form Ferraris calibration of a record.

:func:`imucal_ferraris` labels the Ferraris protocol's regions of a record automatically (each rest's face from the
dominant axis of its mean specific force; each full turn from the dominant axis of the raw gyro angle integrated
between two rests), runs :class:`imucal.FerrarisCalibration` on them and returns an adapter with the product's
calibration interface, ``correct(experiment) -> (omega_ib_b, f_b)`` in rad/s and m/s^2, so that IMU-TK's figures
(:mod:`graph_calib.evaluation.imu_tk`) and the held-out figures (:mod:`graph_calib.evaluation.crossval`) judge both
the same way.

imucal expects every full turn in one direction (``expected_angle``, -360 deg); the simulator draws each turn's
direction at random, so the adapter runs imucal with -360 and turns the column of ``R_g`` of each turn that went the
other way (what a user who turned that way and told imucal would get).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from imucal import FerrarisCalibration
from imucal.ferraris_calibration import ferraris_regions_from_df

from graph_calib.constants import DEG_TO_RAD, RAD_TO_DEG

FACE_NAMES = {(0, 1): "x_p", (0, -1): "x_a", (1, 1): "y_p", (1, -1): "y_a", (2, 1): "z_p", (2, -1): "z_a"}


@dataclass(frozen=True)
class ImucalCalibration:
    """imucal's calibration of a record behind the product's ``correct`` interface."""

    info: object

    def correct(self, experiment):
        f = experiment.dv / experiment.dt[:, None]
        w = experiment.dtheta / experiment.dt[:, None] * RAD_TO_DEG
        acc, gyr = self.info.calibrate(f, w, "m/s^2", "deg/s")
        return np.asarray(gyr) * DEG_TO_RAD, np.asarray(acc)


def ferraris_regions(experiment, rests, *, whole_turns=False):
    """``{label: (start, stop)}`` of the six faces and the three full turns (module docstring).

    ``whole_turns``: each turn's region runs from the middle of the rest before to the middle of the rest after, as
    a user marks a whole turn whose slow start and end the rests' detector took for rest (a smooth turn about the
    vertical leaves the specific force as it was); imucal takes the gyro bias off the static faces, so the rest in
    the region adds nothing but its noise.  Default: between the two rests' edges."""
    f = experiment.dv / experiment.dt[:, None]
    g = float(experiment.gravity_mps2)
    out = {}
    for a, b in rests:
        m = f[a:b].mean(axis=0)
        k = int(np.argmax(np.abs(m)))
        if abs(m[k]) > 0.8 * g:
            out.setdefault(FACE_NAMES[(k, int(np.sign(m[k])))], (int(a), int(b)))
    signs = {}
    for (a0, b0), (a1, b1) in zip(rests[:-1], rests[1:]):
        start, stop = ((a0 + b0) // 2, (a1 + b1) // 2) if whole_turns else (b0, a1)
        angle = experiment.dtheta[start:stop].sum(axis=0)
        k = int(np.argmax(np.abs(angle)))
        if abs(angle[k]) > np.deg2rad(300.0):
            label = "xyz"[k] + "_rot"
            out.setdefault(label, (int(start), int(stop)))
            signs.setdefault(k, float(np.sign(angle[k])))
    missing = sorted((set(FACE_NAMES.values()) | {"x_rot", "y_rot", "z_rot"}) - set(out))
    if missing:
        raise ValueError(f"the record lacks the Ferraris regions {missing}")
    return out, signs


def imucal_ferraris(experiment, rests, *, whole_turns=False):
    """imucal's Ferraris calibration of ``experiment`` (its rests ``[start, stop)``), as :class:`ImucalCalibration`
    (``whole_turns``: :func:`ferraris_regions`)."""
    regions, signs = ferraris_regions(experiment, rests, whole_turns=whole_turns)
    f = experiment.dv / experiment.dt[:, None]
    w = experiment.dtheta / experiment.dt[:, None] * RAD_TO_DEG
    parts = []
    for label, (a, b) in regions.items():
        df = pd.DataFrame(np.hstack([f[a:b], w[a:b]]), columns=["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"])
        df.index = pd.Index([label] * (b - a), name="part")
        parts.append(df)
    cal = FerrarisCalibration(grav=float(experiment.gravity_mps2), expected_angle=-360.0)
    info = cal.compute(ferraris_regions_from_df(pd.concat(parts)), float(experiment.rate_hz), from_acc_unit="m/s^2",
                       from_gyr_unit="deg/s")
    R_g = np.array(info.R_g, dtype=float)
    for k, s in signs.items():
        if s > 0:
            R_g[:, k] = -R_g[:, k]
    info.R_g = R_g
    return ImucalCalibration(info=info)
