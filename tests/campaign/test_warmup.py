"""Warming the numba kernels (graph_calib.campaign.warmup): every cached kernel is known and run, compile time is measured."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from graph_calib.campaign import warmup

ROOT = Path(__file__).resolve().parents[2]


def test_every_module_with_a_cached_kernel_is_listed():
    """A new module with ``@numba.njit(cache=True)`` must join KERNEL_MODULES, or the warm-up would miss it."""
    found = set()
    for top in ("graph_calib", "kf_reference"):
        for path in (ROOT / top).rglob("*.py"):
            if re.search(r"njit\([^)]*cache\s*=\s*True", path.read_text()):
                rel = path.relative_to(ROOT).with_suffix("")
                found.add(".".join(p for p in rel.parts if p != "__init__"))
    assert found == set(warmup.KERNEL_MODULES)


def test_warm_up_runs_every_kernel():
    """Seconds when numba's cache is there (minutes on a fresh clone, once: the cache is then written)."""
    w = warmup.warm_kernels(again=True)
    assert w.missed == ()
    names = set(w.kernels)
    assert {"graph_calib.model.kernel._preintegrate", "graph_calib.sensors.sensor_model._inverse_many",
            "graph_calib.sensors.sensor_model._forward_many", "graph_calib.navigation.strapdown._integrate_kernel",
            "graph_calib.navigation.static_detection._window_stats", "kf_reference.sqrt_kf.run",
            "kf_reference.sqrt_kf.smooth_attitude"} <= names
    assert "graph_calib.sensors.sensor_model.invert_sample" in names          # compiled once, called by the kernels
    assert not any(n.endswith("._mm3") for n in names)                 # inline="always": no kernel alone
    assert 0.0 <= w.compile_seconds <= w.seconds
    # a second call in the same process has nothing to do
    again = warmup.warm_kernels()
    assert again.seconds == 0.0 and again.missed == ()


def test_compile_clock_counts_compiling_only():
    @numba.njit(cache=False)
    def fresh(a):
        return np.sum(np.sqrt(np.abs(a)))

    with warmup.CompileClock() as clock:
        fresh(np.ones(4))
    assert clock.count >= 1 and clock.seconds > 0.0
    with warmup.CompileClock() as clock:
        fresh(np.ones(5))                  # same types: already compiled
    assert clock.count == 0 and clock.seconds == 0.0


_SIGNATURES = """
import json, tempfile
import numpy as np
import pytest
from graph_calib.campaign import warmup
from graph_calib.compensation.calibration import correct_record, prepare, triad_errors
from graph_calib.model import CalibrationModel
from graph_calib.sensors.sensor_model import correct, measure

warmup.warm_kernels()
with tempfile.TemporaryDirectory() as tmp:
    exp = warmup._tiny_experiment(tmp)
model = CalibrationModel(exp)
x = model.prior()[0].copy()
x.setflags(write=False)                 # calibration vectors are often read-only (Calibration.x)
model.preintegrate(x)
sig = np.ascontiguousarray(exp.dtheta[:50] * exp.rate_hz)
for triad in ("gyro", "accel"):
    correct(model.layout, x, triad, measure(model.layout, x, triad, sig))
    triad_errors(model.layout, x, triad, sig)
X = np.broadcast_to(x, (exp.n_samples, x.size))
record = prepare(exp)
correct_record(model.layout, X, record)
correct_record(model.layout, np.ascontiguousarray(X), record)
print(json.dumps({k: len(d.signatures) for k, d in warmup.kernels().items()}))
"""


@pytest.mark.slow
def test_one_signature_per_kernel():
    """The call sites pass every kernel the same numba types (C-contiguous, writable float64 and int64 arrays,
    no literal flags), read-only inputs included, so each kernel compiles once (docs/performance.md)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _SIGNATURES], cwd=ROOT, env=env, capture_output=True, text=True,
                         check=True).stdout
    counts = json.loads(out.strip().splitlines()[-1])
    assert counts["graph_calib.model.kernel._preintegrate"] == 1
    assert {k: c for k, c in counts.items() if c > 1} == {}
