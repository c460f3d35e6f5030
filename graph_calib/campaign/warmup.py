"""Compile every cached numba kernel once per machine, before a campaign starts its workers.

numba compiles a kernel on its first call with a new type signature and, with ``cache=True``, writes the
machine code next to the source (``__pycache__/*.nbi`` index, ``*.nbc`` code).  A Dask worker is a fresh
process: on a fresh clone each worker compiled the model's and the filter's kernels inside its first task
(minutes on two cores, both workers compiling the same code at once), and that time showed as calibration time.
:func:`warm_kernels` runs every kernel once in the calling process on a tiny simulated experiment written to
and read back from an experiment file, through the same code a task runs (``build_problem`` with the static detector, the alignment's strapdown
integrator and the preintegration kernel; both solvers with the filter's kernels), plus the sensor model
both ways, the calibration applied to a record and the turntable simulator, so that the cache holds the
signatures the tasks need and the workers only load them (about a second each).  When the cache is already
there the warm-up costs the tiny calibration itself (about a second), and nothing on a second call in the
same process.

:class:`CompileClock` measures the time numba spends compiling (not loading from the cache) while it is
active; the campaign uses it to keep compile time out of each task's seconds.

Caveat (docs/performance.md): numba checks a cached kernel against its own source file only.  A kernel that
calls or inlines kernels of another module (the preintegration kernel calls :mod:`graph_calib.sensors.sensor_model`'s)
keeps its stale machine code when only that other module changes: ``make clean-cache`` deletes the caches.
"""

from __future__ import annotations

import importlib
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba.core import event as numba_event
from numba.core.registry import CPUDispatcher

#: The modules that define cached numba kernels (tests/campaign/test_warmup.py checks that no other module does).
KERNEL_MODULES = (
    "graph_calib.navigation.rotations", "graph_calib.sensors.sensor_model", "graph_calib.compensation.calibration", "graph_calib.navigation.strapdown",
    "graph_calib.navigation.static_detection", "graph_calib.model.kernel", "graph_calib.model.encoder_kernel",
    "graph_calib.model.shared_gyro_noise",
    "graph_calib.simulation.turntable",
    "kf_reference.sqrt_kf", "graph_calib.model.redundancy",
)

#: Length of the warm-up experiment, s (long enough for every code path of the solvers, still tiny).
WARM_SECONDS = 60.0


def kernels():
    """``{"module.function": dispatcher}`` of every cached numba kernel that is called as a function.

    Kernels declared ``inline="always"`` are left out: numba compiles them into their callers, never alone.
    """
    out = {}
    for name in KERNEL_MODULES:
        mod = importlib.import_module(name)
        for attr, obj in vars(mod).items():
            if not isinstance(obj, CPUDispatcher) or obj.py_func.__module__ != name:
                continue
            if obj.targetoptions.get("inline", "never") == "always":
                continue
            out[f"{name}.{attr}"] = obj
    return out


class _CompileListener(numba_event.Listener):
    """Adds up the wall time of the outermost ``numba:compile`` events (nested compiles count once)."""

    def __init__(self):
        self.depth = 0
        self.t0 = 0.0
        self.seconds = 0.0
        self.count = 0

    def on_start(self, event):
        if self.depth == 0:
            self.t0 = time.perf_counter()
        self.depth += 1

    def on_end(self, event):
        self.depth -= 1
        self.count += 1
        if self.depth == 0:
            self.seconds += time.perf_counter() - self.t0


class CompileClock:
    """``with CompileClock() as clock: ...``; then ``clock.seconds`` spent compiling, ``clock.count`` signatures.

    Only compilation counts: a kernel loaded from numba's on-disk cache fires no compile event.  numba
    compiles under one lock per process, so the time is wall time of this process's compiling.
    """

    def __init__(self):
        self._listener = _CompileListener()
        self._ctx = None

    @property
    def seconds(self):
        return self._listener.seconds

    @property
    def count(self):
        return self._listener.count

    def __enter__(self):
        self._ctx = numba_event.install_listener("numba:compile", self._listener)
        self._ctx.__enter__()
        return self

    def __exit__(self, *exc):
        return self._ctx.__exit__(*exc)


@dataclass(frozen=True)
class WarmUp:
    """What :func:`warm_kernels` did.

    Attributes
    ----------
    seconds : float
        Wall time of the whole warm-up (tiny simulation and calibration included).
    compile_seconds : float
        Of which numba compiling (0 when every kernel came from the cache).
    compiled : int
        Signatures compiled (nested ones and numba's own helpers, e.g. ``np.linalg.solve``, included).
    kernels : tuple of str
        Every cached kernel (:func:`kernels`).
    missed : tuple of str
        Kernels the warm-up did not run (should be empty: tests/campaign/test_warmup.py).
    """

    seconds: float
    compile_seconds: float
    compiled: int
    kernels: tuple = field(default_factory=tuple)
    missed: tuple = field(default_factory=tuple)

    def to_json(self):
        return {"seconds": self.seconds, "compile_seconds": self.compile_seconds, "compiled": self.compiled,
                "kernels": len(self.kernels), "missed": list(self.missed)}


def _tiny_experiment(folder):
    """A :data:`WARM_SECONDS` turntable experiment (the demo's IMU design), written and read back."""
    from graph_calib import io
    from graph_calib.simulation import simulate

    sim = simulate("nav-subrange-short", rng=np.random.default_rng(0), hours=WARM_SECONDS / 3600.0,
                   tag="numba warm-up")
    path = Path(folder) / "warmup.h5"
    io.write_experiment(sim.plans[0].run().experiment, path)
    return io.read_experiment(path)


def _run_everything(exp):
    from graph_calib.compensation.calibration import correct_record, prepare, triad_errors
    from graph_calib.model.options import ModelOptions
    from graph_calib.options import CalibrationOptions
    from graph_calib.records.problem import build_problem
    from graph_calib.sensors.sensor_model import correct, correct_with_jacobian, measure
    from graph_calib.solvers.registry import DEFAULT_SOLVERS, solve
    from graph_calib.solvers.results import to_result
    from graph_calib.navigation.strapdown import integrate_attitude

    options = CalibrationOptions(model=ModelOptions(grade="navigation"))
    problem = build_problem(exp, options=options)       # static detector, alignment (strapdown), preintegration
    for solver in DEFAULT_SOLVERS:                      # the model's kernels and the filter's
        to_result(problem.model, solve(solver, problem, options=options))
    layout = problem.model.layout
    x = np.zeros(layout.size)
    n = min(exp.n_samples, 200)
    sig = np.ascontiguousarray(exp.dtheta[:n] * exp.rate_hz)
    dT = np.zeros((n, 3))
    for triad in ("gyro", "accel"):
        m = measure(layout, x, triad, sig, dT=dT)
        correct(layout, x, triad, m, dT=dT)
        correct_with_jacobian(layout, x, triad, m, dT=dT)
        triad_errors(layout, x, triad, sig, dT=dT)
        triad_errors(layout, x, triad, sig, dT=dT, power=2)
    integrate_attitude(exp.dtheta[:n], t=exp.t[:n], rate_hz=exp.rate_hz, q_nb0=np.array([1.0, 0.0, 0.0, 0.0]),
                       latitude_rad=0.97)
    record = prepare(exp)                               # the calibration applied to a record (compensation)
    correct_record(layout, x, record)
    correct_record(layout, np.zeros((record.w_raw.shape[0], layout.size)), record)


def _run(every):
    """Names of the kernels that have run: compiled or loaded, or called by one that has (numba links a
    kernel called from another into its caller's machine code, so a caller loaded from the cache leaves
    its callees without a signature of their own)."""
    done = {k for k, d in every.items() if d.overloads}
    grown = True
    while grown:
        grown = False
        for k in every:
            if k not in done and any(k.rpartition(".")[2] in every[c].py_func.__code__.co_names for c in done):
                done.add(k)
                grown = True
    return done


def cache_present():
    """Whether numba's on-disk cache has an index for every kernel (a guess that the warm-up will be quick).

    Uses numba's private cache attributes; False when they are not there.
    """
    try:
        return all(Path(d._cache._cache_file._index_path).is_file() for d in kernels().values())
    except AttributeError:  # pragma: no cover - another numba version
        return False


_WARMED = []   # this process's WarmUp once done: the kernels then stay compiled in memory


def warm_kernels(*, again=False):
    """Run every cached numba kernel once in this process (compiling it or loading it from the cache).

    A second call in the same process returns at once (``seconds`` 0) unless ``again``.

    Returns
    -------
    WarmUp
    """
    if _WARMED and not again:
        w = _WARMED[0]
        return WarmUp(seconds=0.0, compile_seconds=0.0, compiled=0, kernels=w.kernels, missed=w.missed)
    t0 = time.perf_counter()
    with CompileClock() as clock, tempfile.TemporaryDirectory(prefix="graph-calib-warmup-") as tmp:
        _run_everything(_tiny_experiment(tmp))
    every = kernels()
    done = _run(every)
    w = WarmUp(seconds=time.perf_counter() - t0, compile_seconds=clock.seconds, compiled=clock.count,
               kernels=tuple(every), missed=tuple(k for k in every if k not in done))
    _WARMED[:] = [w]
    return w


__all__ = ["KERNEL_MODULES", "WARM_SECONDS", "CompileClock", "WarmUp", "cache_present", "kernels", "warm_kernels"]
