"""The joint campaign solver on the 6 x 3 h campaign (6.5 million samples): wall time and peak memory.

Run by hand, after ``benchmarks/bench_campaign.py`` simulated (and calibrated) the campaign::

    .venv/bin/python benchmarks/bench_joint.py [--data /tmp/bench-campaign/data]
                                               [--campaign /tmp/bench-campaign/campaign] [--cold]

Reads the six experiments, builds each problem (static detection, alignment, the prepared record), and
solves them jointly (``graph_calib.solvers.joint.solve_joint``), warm-started from the campaign's per-subrange
factor-graph results when ``--campaign`` holds them (the campaign runs them anyway; ``--cold`` starts
from the priors instead).  Samples the resident memory of this process (and any children) every 0.2 s.  Prints the time of
each stage (reading, problems, joint solve; the solve's CPU time too: on a shared machine the wall time is
an upper bound) and the peak memory; docs/performance.md records what it
measured.  Targets: the joint solve within 60 s, under 4 GB.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from _memory import MemoryMonitor
from _report import report

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from graph_calib import io  # noqa: E402
from graph_calib.campaign.tasks import calibration_options  # noqa: E402
from graph_calib.compensation.joint import JointCalibration  # noqa: E402
from graph_calib.solvers.joint import WarmStart, solve_joint  # noqa: E402
from graph_calib.solvers.joint.result import joint_element_at, joint_result  # noqa: E402
from graph_calib.model.calibration_model import CalibrationModel  # noqa: E402
from graph_calib.records.problem import build_problem  # noqa: E402


class Stages:
    """Calls and seconds of the model's preintegration and factor evaluation (the rest of the solve is GTSAM:
    linearisation callbacks, elimination, error), counted by wrapping the model's methods for the run."""

    METHODS = ("preintegrate", "rotation_factors", "gravity_factors", "encoder_factors")

    def __init__(self):
        self.calls = dict.fromkeys(self.METHODS, 0)
        self.seconds = dict.fromkeys(self.METHODS, 0.0)
        self._saved = {}

    def _wrap(self, name, fn):
        def timed(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.calls[name] += 1
                self.seconds[name] += time.perf_counter() - t
        return timed

    def __enter__(self):
        for n in self.METHODS:
            self._saved[n] = getattr(CalibrationModel, n)
            setattr(CalibrationModel, n, self._wrap(n, self._saved[n]))
        return self

    def __exit__(self, *exc):
        for n, fn in self._saved.items():
            setattr(CalibrationModel, n, fn)

    def text(self):
        return "; ".join(f"{n} {self.calls[n]} calls {self.seconds[n]:.1f} s" for n in self.METHODS)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/tmp/bench-campaign/data")
    ap.add_argument("--campaign", default="/tmp/bench-campaign/campaign")
    ap.add_argument("--cold", action="store_true", help="start from the priors, not the per-subrange results")
    ap.add_argument("--save", default="/tmp/bench-joint.json", help="where to write the joint result")
    args = ap.parse_args(argv)
    manifest = io.read_manifest(Path(args.data) / "campaign.toml")
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} on "
          f"{os.cpu_count()} cores")
    with MemoryMonitor() as mem:
        t0 = time.perf_counter()
        problems, starts, n, ranges, truths, graphs = [], [], 0, [], [], []
        for e in manifest.experiments:
            exp = io.read_experiment(e.file)
            n += exp.n_samples
            T = exp.sensor_temperatures()
            ranges.append(np.column_stack([T.min(axis=0), T.max(axis=0)]))
            tp = Path(e.file).with_suffix(".truth.json")
            truths.append(io.read_result(tp) if tp.is_file() else None)
            opts = calibration_options(manifest, t_ref_degC=e.t_ref_degC)
            problems.append(build_problem(exp, options=opts))
            fg = Path(args.campaign) / e.name / "factor-graph.json"
            graphs.append(io.read_result(fg) if fg.is_file() else None)
            starts.append(WarmStart.from_result(graphs[-1]) if graphs[-1] is not None and not args.cold else None)
        t1 = time.perf_counter()
        c1 = time.process_time()
        with Stages() as stages:
            out = solve_joint(problems, options=opts.graph, progress=lambda ev: print(ev.text(), flush=True),
                              initial=starts if any(s is not None for s in starts) else None)
        t2 = time.perf_counter()
        c2 = time.process_time()
    warm = sum(s is not None for s in starts)
    print(f"{len(problems)} experiments, {n:,} samples; warm start from {warm} per-subrange result(s)")
    print(f"read + problems {t1 - t0:.1f} s; joint solve {t2 - t1:.1f} s wall, {c2 - c1:.1f} s CPU ({out.iterations} "
          f"iterations, converged {out.converged}, marginals and degree choice included); "
          f"peak RSS {mem.peak_total / 2**30:.2f} GB")
    print("inside the solve:", stages.text())
    print("degrees:", {c.family: c.degree for c in out.degree_choices})
    print(f"load average after {os.getloadavg()[0]:.2f}")
    names = [e.name for e in manifest.experiments]
    res = joint_result(out, source="campaign.toml", experiments=names,
                       t_refs=[p.model.t_ref_degC for p in problems], sensor_ranges=ranges)
    io.write_result(res, args.save)
    _figures(res, names, graphs, truths)
    report("joint_solve_s", t2 - t1, "s", f"joint solve of {len(problems)} x 3 h ({n:,} samples), warm {warm}")
    report("joint_solve_cpu_s", c2 - c1, "s", "CPU time of the joint solve (all threads of this process)")
    report("joint_problems_s", t1 - t0, "s", "reading the experiments and building the problems")
    report("joint_peak_memory_gb", mem.peak_total / 2**30, "GB", "peak resident memory of the joint solve's process")
    return 0


def _figures(res, names, graphs, truths):
    """Joint at T_ref minus each subrange's graph estimate (in its sigma); joint curves against the truth curves."""
    z = []
    for n, g in zip(names, graphs):
        if g is None:
            continue
        for el, v in g.values.items():
            j = joint_element_at(res, el, g.t_ref_degC, experiment=n)
            if j is not None and g.sigmas[el] > 0:
                z.append((j[0] - v) / g.sigmas[el])
    if z:
        z = np.abs(np.array(z))
        print(f"joint at T_ref - subrange graph: {z.size} elements, rms {np.sqrt(np.mean(z**2)):.2f}, "
              f"max {z.max():.2f}, within 0.5 sigma {100 * np.mean(z <= 0.5):.1f} % (in the subrange's sigma)")
    sim = next((t.extra.get("simulation", {}) for t in truths if t is not None), {})
    curves = sim.get("temperature_curves")
    if curves:
        cal = JointCalibration.from_result(res)
        tc = float(curves["t_center_degC"])
        zs, worst = [], (None, 0.0)
        for name, cv in cal.curves.items():
            if name not in curves:
                continue
            T = np.linspace(*cv.t_span, 25)
            v, s = cv.evaluate(T)
            zz = (v - sum(c * (T - tc) ** i for i, c in enumerate(curves[name]))) / s
            zs.append(zz)
            if np.abs(zz).max() > abs(worst[1]):
                worst = (name, float(zz[np.argmax(np.abs(zz))]))
        zz = np.abs(np.concatenate(zs))
        print(f"joint curves vs truth curves: {zz.size} points, {100 * np.mean(zz <= 2):.1f} % within 2 sigma, "
              f"max |z| {zz.max():.2f} ({worst[0]}), rms {np.sqrt(np.mean(zz**2)):.2f}")
        report("joint_truth_within_2sigma", 100 * np.mean(zz <= 2), "%", "joint curves vs truth, points within 2 sigma")


if __name__ == "__main__":
    raise SystemExit(main())
