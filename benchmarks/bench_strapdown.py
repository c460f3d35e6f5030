"""Time :func:`graph_calib.navigation.strapdown.integrate_attitude` on 6.5 million samples.

Run by hand (not a test)::

    .venv/bin/python benchmarks/bench_strapdown.py [--samples N] [--repeat R]

Synthetic increments: a turntable-like motion (10 deg/s about a slowly wandering
axis plus white noise) at 100 Hz.  Prints the best of ``R`` runs after a warm-up
call that compiles (or loads from cache) the numba kernel.
"""

import argparse
import os
import platform
import time

import numpy as np
from _report import report

from graph_calib.constants import DEG_TO_RAD
from graph_calib.records.experiment import Experiment
from graph_calib.navigation.static_detection import detect_static
from graph_calib.navigation.strapdown import integrate_attitude


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=6_500_000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    n = args.samples
    rate_hz = 100.0
    t = np.arange(1, n + 1) / rate_hz
    phase = 2 * np.pi * t / 600.0
    axis = np.column_stack([np.cos(phase), np.sin(phase), 0.3 * np.ones(n)])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    dtheta = 10.0 * DEG_TO_RAD / rate_hz * axis + 1e-6 * rng.standard_normal((n, 3))
    q0 = np.array([1.0, 0.0, 0.0, 0.0])

    t0 = time.perf_counter()
    integrate_attitude(dtheta[:1000], t=t[:1000], rate_hz=rate_hz, q_nb0=q0, latitude_rad=0.9)
    warm = time.perf_counter() - t0

    best = np.inf
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        q = integrate_attitude(dtheta, t=t, rate_hz=rate_hz, q_nb0=q0, latitude_rad=0.9)
        best = min(best, time.perf_counter() - t0)
    assert np.all(np.isfinite(q[-1]))
    print(f"machine: {platform.machine()} {platform.processor() or ''} cpus={os.cpu_count()}, "
          f"python {platform.python_version()}")
    print(f"warm-up (compile or cache load): {warm:.2f} s")
    print(f"integrate_attitude, {n:,} samples: best of {args.repeat} = {best:.3f} s, "
          f"{n / best / 1e6:.1f} million samples/s")

    # static detection on the same length (accelerometers only, the default)
    dv = np.tile([0.0, 0.0, 9.81 / rate_hz], (n, 1)) + 1e-5 * rng.standard_normal((n, 3))
    exp = Experiment(t=t, dtheta=dtheta, dv=dv, temperature=np.zeros((n, 1)), temperature_names=("t",),
                     temperature_map=np.zeros(6, int), rate_hz=rate_hz, latitude_rad=0.9, gravity_mps2=9.81)
    detect_static(exp.slice(0, 10_000))
    t0 = time.perf_counter()
    found = detect_static(exp)
    el = time.perf_counter() - t0
    print(f"detect_static, {n:,} samples: {el:.3f} s ({found.shape[0]} interval(s))")
    report("integrate_s", best, "s", f"integrate_attitude, {n:,} samples, best of {args.repeat}")
    report("integrate_rate", n / best / 1e6, "M samples/s", "integrate_attitude rate")
    report("detect_static_s", el, "s", f"detect_static, {n:,} samples")


if __name__ == "__main__":
    main()
