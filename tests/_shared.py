"""Helpers the test modules import (``from _shared import ...``): the measured-data folder, a valid synthetic
experiment, the measured-data guard.  Kept out of conftest.py, whose module name is not unique in a tree of
test folders."""

import threading
from pathlib import Path

import numpy as np
import pytest

from graph_calib import constants as c
from graph_calib.records.experiment import Experiment, Table

#: Measured recordings beside the repository (``../shared/data/real``), read at test time.
REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def make_experiment(*, n=600, rate_hz=100.0, with_table=True, seed=0, gravity_mps2=9.80, latitude_rad=0.95,
                    rate_dps=60.0):
    """A valid experiment: IMU z up, static for the first half, then turning about z at ``rate_dps``.

    Two temperature channels (a ramp and an offset copy); table readings every
    10th sample with every other one valid, and a non-trivial nominal mounting.
    """
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    t = 100.0 + np.arange(n) * dt
    omega_z = np.where(np.arange(n) < n // 2, 0.0, rate_dps * c.DEG_TO_RAD)
    omega = np.column_stack([np.zeros(n), np.full(n, c.OMEGA_E * np.cos(latitude_rad)), omega_z])
    dtheta = omega * dt + rng.normal(0.0, 1e-7, (n, 3))
    dv = np.tile([0.0, 0.0, gravity_mps2 * dt], (n, 1)) + rng.normal(0.0, 1e-5, (n, 3))
    ramp = np.linspace(20.0, 25.0, n)
    temperature = np.column_stack([ramp, ramp + 0.5])
    table = None
    if with_table:
        k = np.arange(0, n, 10)
        angle = np.cumsum(omega_z * dt)[k]
        q_nf = np.column_stack([np.cos(angle / 2), np.zeros_like(angle), np.zeros_like(angle), np.sin(angle / 2)])
        valid = (np.arange(k.size) % 2) == 0
        q_fb = np.array([np.cos(0.3), np.sin(0.3), 0.0, 0.0])
        table = Table(t=t[k] + 0.001, q_nf=q_nf, valid=valid, q_fb_nominal=q_fb)
    return Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=temperature, temperature_names=("gyro_block", "accel_block"),
        temperature_map=np.array([0, 0, 0, 1, 1, 1], dtype=np.int64), rate_hz=rate_hz,
        latitude_rad=latitude_rad, gravity_mps2=gravity_mps2, imu_id="TEST-IMU 0001",
        description="synthetic test experiment", table=table, source="",
    )


def require_real(path):
    """``path`` (under the measured-data folder), failing the test when it is absent.

    The measured recordings are part of the checkout's environment (``../shared``, shared/README.md):
    a missing file is a broken environment, not a reason to skip.
    """
    path = Path(path)
    if not path.exists():
        pytest.fail(f"measured data not found: {path} (expected ../shared/data/real beside the repository)",
                    pytrace=False)
    return path


def other_threads():
    """Names of the Python threads running beside this one."""
    return [t.name for t in threading.enumerate() if t is not threading.current_thread()]
