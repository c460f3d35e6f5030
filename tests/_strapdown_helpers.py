"""Helpers shared by the strapdown, alignment and static-detection tests: synthetic experiments, angles."""

import numpy as np

from graph_calib.records.experiment import Experiment
from graph_calib.navigation.rotations import quat_conjugate, quat_multiply, quat_to_rotvec

LAT = 0.9  # rad, about 51.6 deg
G = 9.81


def quat_angle(q1, q2):
    """Rotation angle between unit quaternions, rad, shape (...)."""
    return np.linalg.norm(quat_to_rotvec(quat_multiply(quat_conjugate(q1), q2)), axis=-1)


def random_quat(rng):
    q = rng.standard_normal(4)
    return q / np.linalg.norm(q)


def make_experiment(t, dtheta, dv, *, rate_hz, latitude_rad=LAT, gravity=G, table=None, source="synthetic"):
    n = t.shape[0]
    return Experiment(
        t=np.asarray(t, float), dtheta=np.asarray(dtheta, float), dv=np.asarray(dv, float),
        temperature=np.full((n, 1), 25.0), temperature_names=("t0",), temperature_map=np.zeros(6, int),
        rate_hz=float(rate_hz), latitude_rad=latitude_rad, gravity_mps2=gravity, table=table, source=source,
    )


def sample_dt(t, rate_hz):
    dt = np.empty_like(t)
    dt[0] = 1.0 / rate_hz
    dt[1:] = np.diff(t)
    return dt
