r"""The comparison's noise part confirmed by simulated calibrations.

For each procedure and recorded length asked, ``realisations`` campaigns are simulated with noise and an
ideal IMU (no sensor errors: the truth is zero everywhere, so a stitched curve *is* its error; the
Jacobians are those :mod:`graph_calib.design.comparison` predicts with), every experiment is calibrated
by the factor graph with the procedure's model, the results are stitched as the campaign stitches them,
and the stitched curves are evaluated over the range.  The empirical one sigma at each temperature is the
RMS over the realisations; its largest over the range and its RMS are the simulated counterparts of
``largest_sigma`` and ``rms_sigma``, and the equal-accuracy ratios follow by the same interpolation.

Every calibration is cached in ``work`` (one result file each), so a check can be run in parts and
resumed.  Seeds: realisation ``r`` of experiment ``k`` uses ``seed * 1_000_003 + 7919 * k + r`` (the same
noise for every length and procedure is not intended: each gets its own by the procedure's name).
"""

from __future__ import annotations

import time
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from graph_calib import io
from graph_calib.calibrate import solve_problem
from graph_calib.design.comparison import AXES, FAMILIES, equal_accuracy_duration
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.simulation.program import nominal_experiment, program_simulation
from graph_calib.stitching import stitch


def shifted_program(program, shift_degC):
    """``program`` with its chamber (and so every sensor temperature) shifted by ``shift_degC``."""
    return replace(program, chamber_start_degC=program.chamber_start_degC + shift_degC,
                   setpoints=tuple(replace(s, T_degC=s.T_degC + shift_degC) for s in program.setpoints))


def _seed(name, length_s, k, r, seed):
    return int(seed) * 1_000_003 + 7919 * k + r + zlib.crc32(f"{name}:{length_s:g}".encode()) % 100_000 * 131


def calibrate_realisation(procedure, length_s, r, *, work, seed=1, progress=None):
    """Simulate and calibrate realisation ``r`` of one campaign; ``(results, sensor ranges, labels)``."""
    base = procedure.base_program(length_s)
    T = nominal_experiment(base).sensor_temperatures().mean(axis=1)
    exps = procedure.experiments(0.5 * (float(T.min()) + float(T.max())))
    opts = CalibrationOptions(model=ModelOptions(exclude=procedure.exclude))
    results, ranges, labels = [], [], []
    for k, e in enumerate(exps):
        path = Path(work) / procedure.name / f"L{length_s:g}" / f"r{r}_{e.label}.json"
        if path.is_file():
            doc = io.read_result(path)
        else:
            t0 = time.perf_counter()
            prog = replace(shifted_program(base, e.shift_degC), name=e.label)
            se = program_simulation(prog, rng=np.random.default_rng(_seed(procedure.name, length_s, k, r, seed)),
                                    noise=True, errors=False).run()[0]
            problem = build_problem(se.experiment, options=opts)
            res = solve_problem(problem, options=opts, solvers=("factor-graph",)).results["factor-graph"]
            Ts = se.experiment.sensor_temperatures()
            doc = replace(res, extra={**res.extra, "sensor_ranges_degC": np.stack([Ts.min(0), Ts.max(0)], 1).tolist()})
            path.parent.mkdir(parents=True, exist_ok=True)
            io.write_result(doc, path)
            if progress:
                progress(f"    {procedure.name} {length_s / 3600:g} h r{r} {e.label}: {time.perf_counter() - t0:.1f} s")
        results.append(doc)
        ranges.append(np.asarray(doc.extra["sensor_ranges_degC"], dtype=float))
        labels.append(e.label)
    return results, ranges, labels


def simulated_metrics(procedure, length_s, *, realisations, grid_degC, work, seed=1, progress=None):
    """Empirical ``largest_sigma`` and ``rms_sigma`` per family over ``realisations`` simulated campaigns."""
    errs = {f: [] for f in FAMILIES}
    for r in range(int(realisations)):
        results, ranges, labels = calibrate_realisation(procedure, length_s, r, work=work, seed=seed,
                                                        progress=progress)
        st = stitch(results, names=labels, sensor_ranges=ranges)
        for f in FAMILIES:
            errs[f].append(np.stack([st.curves[f"{f}.{ax}"].evaluate(grid_degC)[0] for ax in AXES]))
    out = {}
    for f in FAMILIES:
        e = np.stack(errs[f])                      # (R, 3, G), the truth is zero
        s = np.sqrt(np.mean(e**2, axis=0))
        out[f] = {"largest_sigma": float(s.max()), "rms_sigma": float(np.sqrt(np.mean(s**2))),
                  "realisations": int(e.shape[0])}
    return out


def simulated_ratios(reference, candidate, ref_metrics, cand_metrics, *, soak_s, metric="largest_sigma"):
    """Equal-accuracy ratios from simulated metrics: ``{family: [rows]}`` as
    :func:`graph_calib.design.comparison.equal_accuracy`."""
    out = {}
    for f in FAMILIES:
        rows = []
        cl = sorted(cand_metrics)
        for L, m in sorted(ref_metrics.items()):
            d_ref = reference.duration_s(L, soak_s=soak_s)
            dur, status = equal_accuracy_duration(m[f][metric], [candidate.duration_s(x) for x in cl],
                                                  [cand_metrics[x][f][metric] for x in cl])
            rows.append({"reference_length_s": L, "reference_duration_s": d_ref, "duration_s": dur,
                         "ratio": None if dur is None else dur / d_ref, "status": status})
        out[f] = rows
    return out


__all__ = ["shifted_program", "calibrate_realisation", "simulated_metrics", "simulated_ratios"]
