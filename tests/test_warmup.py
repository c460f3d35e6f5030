"""Warming the numba kernels (graph_calib.warmup): every cached kernel is known and run, compile time is measured."""

import re
from pathlib import Path

import numba
import numpy as np

from graph_calib import warmup

ROOT = Path(__file__).resolve().parents[1]


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
    assert {"graph_calib.model.kernel._preintegrate", "graph_calib.sensor_model._inverse_many",
            "graph_calib.sensor_model._forward_many", "graph_calib.strapdown._integrate_kernel",
            "graph_calib.static_detection._window_stats", "kf_reference.sqrt_kf.run",
            "kf_reference.sqrt_kf.smooth_attitude"} <= names
    assert "graph_calib.sensor_model.invert_sample" in names          # compiled once, called by the kernels
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
