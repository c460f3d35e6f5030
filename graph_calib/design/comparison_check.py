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

from graph_calib.solvers.registry import PRIMARY_SOLVER
from graph_calib import io
from graph_calib.calibrate import solve_problem
from graph_calib.design.comparison import AXES, FAMILIES, equal_accuracy_duration
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.simulation.program import nominal_experiment, program_simulation
from graph_calib.stitching import stitch

#: Largest relative difference of a simulated from the predicted equal-accuracy ratio (bias families) that
#: the check passes.
AGREEMENT_TOLERANCE = 0.15


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
            res = solve_problem(problem, options=opts, solvers=(PRIMARY_SOLVER,)).results[PRIMARY_SOLVER]
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
    """Empirical ``largest_sigma`` and ``rms_sigma`` per family over ``realisations`` simulated campaigns.

    ``out["failed"]``: the calibrations whose verdict failed (not converged, residuals inconsistent).
    """
    errs = {f: [] for f in FAMILIES}
    failed = []
    for r in range(int(realisations)):
        results, ranges, labels = calibrate_realisation(procedure, length_s, r, work=work, seed=seed,
                                                        progress=progress)
        failed += [f"{procedure.name} {length_s / 3600:g} h r{r} {lab}: {res.extra['verdict']['text']}"
                   for res, lab in zip(results, labels) if not res.extra.get("verdict", {}).get("passed", False)]
        st = stitch(results, names=labels, sensor_ranges=ranges)
        for f in FAMILIES:
            errs[f].append(np.stack([st.curves[f"{f}.{ax}"].evaluate(grid_degC)[0] for ax in AXES]))
    out = {}
    for f in FAMILIES:
        e = np.stack(errs[f])                      # (R, 3, G), the truth is zero
        s = np.sqrt(np.mean(e**2, axis=0))
        out[f] = {"largest_sigma": float(s.max()), "rms_sigma": float(np.sqrt(np.mean(s**2))),
                  "realisations": int(e.shape[0]), "sigma_axes": s}
    out["failed"] = failed
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


def simulated_check(comparison, *, lengths, realisations, work, seed=1, soak_s=None, progress=None,
                    metrics=("largest_sigma", "worst_point_sigma", "rms_sigma")):
    """The comparison's noise part against ``realisations`` simulated campaigns per (procedure, length).

    Parameters
    ----------
    comparison : graph_calib.design.comparison.Comparison
    lengths : dict
        ``{procedure name: [recorded seconds per experiment]}``: the campaigns to simulate (each must be one
        of the comparison's).
    realisations : int
    work : str or Path
        Cache of the calibrations (resumable).
    soak_s : float, optional
        Soak of the reference's durations (default the comparison's first).

    Returns
    -------
    dict
        JSON-ready: per campaign the simulated and predicted metrics, and the equal-accuracy ratios of the
        reference (first procedure) against the second, simulated and predicted over the same campaigns.
    """
    procs = {p.name: p for p in comparison.procedures}
    for name, Ls in lengths.items():
        if name not in procs:
            raise ValueError(f"no procedure {name!r} in the comparison; known: {', '.join(procs)}")
        known = [pt.length_s for pt in comparison.points[name]]
        for L in Ls:
            if not any(abs(L - k) < 1e-6 for k in known):
                raise ValueError(f"{name}: {L:g} s is not one of its campaigns ({', '.join(f'{k:g}' for k in known)})")
    sims, pred = {}, {}
    for name, Ls in lengths.items():
        sims[name], pred[name] = {}, {}
        for L in Ls:
            if progress:
                progress(f"  simulated {name}, {L / 3600:g} h per experiment, {realisations} realisations")
            sims[name][L] = simulated_metrics(procs[name], L, realisations=realisations,
                                              grid_degC=comparison.grid_degC, work=work, seed=seed, progress=progress)
            pt = next(pt for pt in comparison.points[name] if abs(pt.length_s - L) < 1e-6)
            pred[name][L] = {f: {**pt.metrics[f], "worst_point_sigma": pt.metrics[f]["largest_sigma"]}
                             for f in FAMILIES}
            for f in FAMILIES:   # the simulated sigma where the predicted one is largest (no max over noise)
                i, g = np.unravel_index(int(np.argmax(pt.sigma_axes[f])), pt.sigma_axes[f].shape)
                sims[name][L][f]["worst_point_sigma"] = float(sims[name][L][f]["sigma_axes"][i, g])
    w = comparison.soaks_s[0] if soak_s is None else float(soak_s)
    ref, cand = comparison.procedures[0], comparison.procedures[1]
    ratios = {}
    if ref.name in sims and cand.name in sims:
        for f in FAMILIES:
            ratios[f] = {}
            for m in metrics:
                s = simulated_ratios(ref, cand, sims[ref.name], sims[cand.name], soak_s=w, metric=m)[f]
                p = simulated_ratios(ref, cand, pred[ref.name], pred[cand.name], soak_s=w, metric=m)[f]
                ratios[f][m] = [{"reference_length_s": a["reference_length_s"], "predicted": b["ratio"],
                                 "simulated": a["ratio"],
                                 "agreement": None if a["ratio"] is None or b["ratio"] is None
                                 else a["ratio"] / b["ratio"],
                                 "status": f"{b['status']} / {a['status']}"} for a, b in zip(s, p)]
    failed = [x for name in sims for L in sims[name] for x in sims[name][L]["failed"]]
    problems = [f"{len(failed)} simulated calibrations failed their verdict (first: {failed[0]})"] if failed else []
    for f in ("gyro.bias", "accel.bias"):
        for m, rows in ratios.get(f, {}).items():
            for r in rows:
                if r["agreement"] is not None and abs(r["agreement"] - 1.0) > AGREEMENT_TOLERANCE:
                    problems.append(f"{f} {m} at {r['reference_length_s'] / 3600:g} h: simulated ratio "
                                    f"{r['simulated']:.3f} against predicted {r['predicted']:.3f}")
    unformed = [f"{f} {m} at {r['reference_length_s'] / 3600:g} h ({r['status']})"
                for f in ("gyro.bias", "accel.bias") for m, rows in ratios.get(f, {}).items() for r in rows
                if r["agreement"] is None]
    verdict = {"passed": not problems, "tolerance": AGREEMENT_TOLERANCE, "problems": problems,
               "not_formed": unformed,
               "text": ("verdict: pass: every simulated calibration passed and the simulated equal-accuracy ratios "
                        f"agree with the predicted within {AGREEMENT_TOLERANCE:.0%}") if not problems else
                       "verdict: FAIL: " + "; ".join(problems)}
    if unformed:
        verdict["text"] += "; ratios not formed (interpolation failed on one side): " + "; ".join(unformed)
    camp = {name: {f"{L:g}": {f: {**{k: v for k, v in sims[name][L][f].items() if k != "sigma_axes"},
                                  "predicted_largest_sigma": pred[name][L][f]["largest_sigma"],
                                  "predicted_rms_sigma": pred[name][L][f]["rms_sigma"]} for f in FAMILIES}
                   for L in sims[name]} for name in sims}
    what = (f"{realisations} simulated campaigns per point (noise, an ideal IMU: the stitched curve is its own "
            f"error), every experiment calibrated by the factor graph and stitched as the campaign does; campaigns: "
            + "; ".join(f"{n} at {', '.join(f'{L / 3600:g}' for L in Ls)} h per experiment"
                        for n, Ls in lengths.items())
            + f". Ratios over these campaigns only, soak {w / 3600:g} h.")
    return {"what": what, "realisations": int(realisations), "soak_s": w, "campaigns": camp, "ratios": ratios,
            "verdict": verdict}


__all__ = ["AGREEMENT_TOLERANCE", "shifted_program", "calibrate_realisation", "simulated_metrics", "simulated_ratios",
           "simulated_check"]
