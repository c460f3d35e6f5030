"""Small synthetic experiments built directly from the containers (no simulator), for unit tests."""

import numpy as np

from graph_calib.experiment import Experiment, Table
from graph_calib.rotations import dcm_to_quat, exp_so3


def wobbly_experiment(*, rng, n=600, rate_hz=100.0, with_table=True, rate_scale=0.5):
    """Random smooth motion, a temperature ramp and all-valid table readings at 10 Hz.

    Not physically consistent (the table attitude does not follow the increments):
    good for Jacobian checks, not for calibration.
    """
    t = np.arange(1, n + 1) / rate_hz
    dt = 1.0 / rate_hz
    phase = rng.uniform(0, 2 * np.pi, size=(1, 3))
    w = rate_scale * np.sin(2 * np.pi * 0.3 * t[:, None] + phase) + 0.05 * rng.normal(size=(n, 3))
    f = np.array([0.3, -0.2, 9.8]) + 0.5 * np.sin(2 * np.pi * 0.2 * t[:, None] + phase) + 0.1 * rng.normal(size=(n, 3))
    temps = np.column_stack([20 + 0.01 * t, 21 + 0.012 * t + 0.001 * t**2])
    table = None
    if with_table:
        tt = np.arange(0.05, t[-1], 0.1)
        q = dcm_to_quat(exp_so3(rng.normal(size=(tt.size, 3))))
        table = Table(t=tt, q_nf=q, valid=np.ones(tt.size, bool), q_fb_nominal=np.array([1.0, 0, 0, 0]))
    return Experiment(
        t=t, dtheta=w * dt, dv=f * dt, temperature=temps, temperature_names=("a", "b"),
        temperature_map=np.array([0, 1, 0, 1, 0, 1]), rate_hz=rate_hz, latitude_rad=0.97,
        gravity_mps2=9.8155, imu_id="synthetic", table=table, source="synthetic",
    )
