r"""The comparison's noise part confirmed by simulated calibrations.

For each procedure and recorded length asked, ``realisations`` campaigns are simulated with noise and an
ideal IMU (no sensor errors: the truth is zero everywhere, so a stitched curve *is* its error; the
Jacobians are those :mod:`graph_calib.design.comparison` predicts with), every experiment is calibrated
by the factor graph with the procedure's model, the results are stitched as the campaign stitches them,
and the stitched curves are evaluated over the range.

**The estimator.**  The empirical one sigma at each temperature (the RMS over the realisations) and its
largest over the range and the axes are reported, but not judged: with ``R`` realisations each point's
sigma is a chi with ``R`` degrees of freedom (within 0.57-1.43 of the true one 95 % of the time at
``R = 10``), and the largest over 3 axes and the range picks the most extreme of them, a statistic whose
bias and spread depend on the correlations over temperature and are known to nobody.  What is judged is
the **scale** of the simulated errors against the prediction, from the experiments themselves
(:func:`experiment_scale`): every experiment's errors in a family's values and temperature coefficients,
whitened by their predicted covariance, chi-square with 3 (steps) or 6 (ramps) degrees of freedom per
experiment, 210-360 per family at ``R = 10`` (relative standard error 3.7-4.9 %); the stitched curve is
linear in those values, so the simulated ``largest_sigma`` and ``rms_sigma`` are the predicted ones times
that scale.  The stitching is checked on its own: the stitched cubic is fixed by its values at
the four :func:`graph_calib.design.comparison.check_nodes` of the range, and its error there on the three
axes, whitened by the predicted joint covariance of those twelve values (the axes' correlations
included), gives ``q = sum e^T C^-1 e`` over the realisations, chi-square with ``n = 12 R`` degrees of
freedom if the prediction holds.  ``scale = sqrt(q / n)`` has known spread (relative standard error
``1 / sqrt(2 n)``: 6.5 % at ``R = 10``, its 95 % band from the chi-square quantiles; reported, with the
ratios it gives, ``largest_sigma_stitched``).  Both scales take the shape over temperature from the
prediction, so the shape is tested too: at each node the three axes' error whitened together and averaged
over the realisations (chi-square with ``3 R`` degrees of freedom) must lie within its band at the
family-wise level :data:`SHAPE_ALPHA` (Bonferroni over the nodes, families and campaigns); a stitching
that placed the ends differently from the prediction fails there.  The equal-accuracy ratios follow from the scaled metrics by the same interpolation; each is
given with its approximate standard error (the scales' errors through the log-log interpolation).

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
from scipy import stats

from graph_calib.solvers.registry import PRIMARY_SOLVER
from graph_calib import io
from graph_calib.calibrate import solve_problem
from graph_calib.design.comparison import AXES, FAMILIES, check_nodes, equal_accuracy_duration
from graph_calib.model import ModelOptions
from graph_calib.sensors.params import DEFAULT_GRADE
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.simulation.program import nominal_experiment, program_simulation
from graph_calib.stitching import stitch

#: Largest relative difference of a simulated from the predicted equal-accuracy ratio (bias families) that
#: the check passes.
AGREEMENT_TOLERANCE = 0.15
#: Family-wise false-alarm rate of the per-node shape tests (module docstring).
SHAPE_ALPHA = 0.01
#: The families the check judges.
JUDGED = ("gyro.bias", "accel.bias")


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
    # the structure tests judge a calibration and change no estimate: left out of the check's many calibrations
    opts = CalibrationOptions(model=ModelOptions(grade=DEFAULT_GRADE, exclude=procedure.exclude), structure_tests=False)
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

    Per family also ``node_errors`` (R, 3, 4): each realisation's stitched error at the four
    :func:`graph_calib.design.comparison.check_nodes` of the grid's range.  ``out["estimates"]``: every
    experiment's estimates (``{element: value}``, the errors: the truth is zero); ``out["failed"]``: the
    calibrations whose verdict failed (not converged, residuals inconsistent).
    """
    nodes = check_nodes((grid_degC[0], grid_degC[-1]))
    errs = {f: [] for f in FAMILIES}
    at_nodes = {f: [] for f in FAMILIES}
    estimates = []
    failed = []
    for r in range(int(realisations)):
        results, ranges, labels = calibrate_realisation(procedure, length_s, r, work=work, seed=seed,
                                                        progress=progress)
        failed += [f"{procedure.name} {length_s / 3600:g} h r{r} {lab}: {res.extra['verdict']['text']}"
                   for res, lab in zip(results, labels) if not res.extra.get("verdict", {}).get("passed", False)]
        estimates += [dict(res.values) for res in results]
        st = stitch(results, names=labels, sensor_ranges=ranges)
        for f in FAMILIES:
            errs[f].append(np.stack([st.curves[f"{f}.{ax}"].evaluate(grid_degC)[0] for ax in AXES]))
            at_nodes[f].append(np.stack([st.curves[f"{f}.{ax}"].evaluate(nodes)[0] for ax in AXES]))
    out = {}
    for f in FAMILIES:
        e = np.stack(errs[f])                      # (R, 3, G), the truth is zero
        s = np.sqrt(np.mean(e**2, axis=0))
        out[f] = {"largest_sigma": float(s.max()), "rms_sigma": float(np.sqrt(np.mean(s**2))),
                  "realisations": int(e.shape[0]), "sigma_axes": s, "node_errors": np.stack(at_nodes[f])}
    out["failed"] = failed
    out["estimates"] = estimates
    return out


def whitened_scale(node_errors, node_covariance, *, alpha=SHAPE_ALPHA, n_tests=1):
    """The scale of simulated errors against their predicted covariance (module docstring).

    Parameters
    ----------
    node_errors : ndarray (R, 3, N)
        Stitched errors at the check nodes, per realisation and axis.
    node_covariance : ndarray (3 N, 3 N)
        Their predicted joint covariance over the axes (axis-major).
    alpha : float
        Family-wise false-alarm rate of the node tests, shared over ``n_tests`` sets of nodes (Bonferroni).
    n_tests : int

    Returns
    -------
    dict
        ``scale`` (sqrt of the whitened mean square), ``dof``, ``band`` (its 95 % band if the prediction
        holds), ``relative_se`` (``1 / sqrt(2 dof)``), ``node_scale`` (N,) the scale at each node alone
        (its three axes whitened together), ``node_band`` (its band at the Bonferroni level) and ``shape_ok``.
    """
    e = np.asarray(node_errors, dtype=float)
    R, A, N = e.shape
    C = 0.5 * (np.asarray(node_covariance) + np.asarray(node_covariance).T)

    def quad(cov, x):            # sum over rows of x^T cov^-1 x, on the covariance's range; and its rank
        w, V = np.linalg.eigh(cov)
        keep = w > w.max() * 1e-10
        z = (x @ V[:, keep]) / np.sqrt(w[keep])
        return float(np.sum(z**2)), int(keep.sum())

    q, rank = quad(C, e.reshape(R, A * N))
    dof = rank * R
    node_ms, node_dof = np.zeros(N), 0
    for n in range(N):
        ii = [a * N + n for a in range(A)]
        qn, rn = quad(C[np.ix_(ii, ii)], e[:, :, n])
        node_ms[n], node_dof = qn / (rn * R), rn * R
    a = alpha / (N * max(int(n_tests), 1))
    lo, hi = stats.chi2.ppf([a / 2, 1 - a / 2], node_dof) / node_dof
    return {"scale": float(np.sqrt(q / dof)), "dof": dof,
            "band": [float(np.sqrt(v / dof)) for v in stats.chi2.ppf([0.025, 0.975], dof)],
            "relative_se": float(1.0 / np.sqrt(2.0 * dof)), "node_scale": np.sqrt(node_ms).tolist(),
            "node_band": [float(np.sqrt(lo)), float(np.sqrt(hi))],
            "shape_ok": bool(np.all((node_ms >= lo) & (node_ms <= hi)))}


def experiment_scale(estimates, names, covariance, family):
    """The scale of the experiments' own errors in ``family`` against their predicted covariance.

    Every experiment's value and temperature-coefficient errors of the family's three axes, whitened by the
    predicted covariance of those elements (the experiments are independent): chi-square with ``dof``
    degrees of freedom if the prediction holds.  Returns ``{"scale", "dof", "band", "relative_se"}`` as
    :func:`whitened_scale`.
    """
    idx = [i for i, n in enumerate(names) if n.rsplit(".", 1)[0] in (family, family + "_tc")]
    sel = [names[i] for i in idx]
    C = np.asarray(covariance)[np.ix_(idx, idx)]
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    keep = w > w.max() * 1e-10
    X = np.array([[est[n] for n in sel] for est in estimates])
    z = (X @ V[:, keep]) / np.sqrt(w[keep])
    dof = int(z.size)
    return {"scale": float(np.sqrt(np.mean(z**2))), "dof": dof,
            "band": [float(np.sqrt(v / dof)) for v in stats.chi2.ppf([0.025, 0.975], dof)],
            "relative_se": float(1.0 / np.sqrt(2.0 * dof)), "elements": len(sel)}


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


def simulated_check(comparison, *, lengths, realisations, work, seed=1, soak_s=None, progress=None):
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
    seed : int
    soak_s : float, optional
        Soak of the reference's durations (default the comparison's first).
    progress : callable, optional

    Returns
    -------
    dict
        JSON-ready: per campaign the whitened scale (:func:`whitened_scale`), the scaled and the raw
        simulated metrics beside the predicted ones, and the equal-accuracy ratios of the reference (first
        procedure) against the second, simulated and predicted over the same campaigns: ``largest_sigma`` and
        ``rms_sigma`` from the scaled metrics (judged, with their standard errors), ``largest_sigma_raw`` and
        ``worst_point_sigma`` from the raw ones (reported only).
    """
    procs = {p.name: p for p in comparison.procedures}
    for name, Ls in lengths.items():
        if name not in procs:
            raise ValueError(f"no procedure {name!r} in the comparison; known: {', '.join(procs)}")
        known = [pt.length_s for pt in comparison.points[name]]
        for L in Ls:
            if not any(abs(L - k) < 1e-6 for k in known):
                raise ValueError(f"{name}: {L:g} s is not one of its campaigns ({', '.join(f'{k:g}' for k in known)})")
    n_tests = sum(len(Ls) for Ls in lengths.values()) * len(JUDGED)
    sims, sim_view, pred_view, ses = {}, {}, {}, {}
    for name, Ls in lengths.items():
        sims[name], sim_view[name], pred_view[name], ses[name] = {}, {}, {}, {}
        for L in Ls:
            if progress:
                progress(f"  simulated {name}, {L / 3600:g} h per experiment, {realisations} realisations")
            sm = simulated_metrics(procs[name], L, realisations=realisations, grid_degC=comparison.grid_degC,
                                   work=work, seed=seed, progress=progress)
            pt = next(pt for pt in comparison.points[name] if abs(pt.length_s - L) < 1e-6)
            sims[name][L], sim_view[name][L], pred_view[name][L], ses[name][L] = sm, {}, {}, {}
            for f in FAMILIES:
                m = pt.metrics[f]
                ws = whitened_scale(sm[f]["node_errors"], pt.node_covariance[f], n_tests=n_tests)
                es = experiment_scale(sm["estimates"], *pt.experiment_covariance, f)
                i, g = np.unravel_index(int(np.argmax(pt.sigma_axes[f])), pt.sigma_axes[f].shape)
                sm[f].update(whitened=ws, experiment=es, worst_point_sigma=float(sm[f]["sigma_axes"][i, g]))
                sim_view[name][L][f] = {"largest_sigma": es["scale"] * m["largest_sigma"],
                                        "rms_sigma": es["scale"] * m["rms_sigma"],
                                        "largest_sigma_stitched": ws["scale"] * m["largest_sigma"],
                                        "largest_sigma_raw": sm[f]["largest_sigma"],
                                        "worst_point_sigma": sm[f]["worst_point_sigma"]}
                pred_view[name][L][f] = {"largest_sigma": m["largest_sigma"], "rms_sigma": m["rms_sigma"],
                                         "largest_sigma_stitched": m["largest_sigma"],
                                         "largest_sigma_raw": m["largest_sigma"],
                                         "worst_point_sigma": m["largest_sigma"]}
                ses[name][L][f] = es["relative_se"]
    w = comparison.soaks_s[0] if soak_s is None else float(soak_s)
    ref, cand = comparison.procedures[0], comparison.procedures[1]
    metrics = ("largest_sigma", "rms_sigma", "largest_sigma_stitched", "largest_sigma_raw", "worst_point_sigma")
    judged_metrics = ("largest_sigma", "rms_sigma")
    ratios = {}
    if ref.name in sims and cand.name in sims:
        def bumped(view, name, f, m):     # one procedure's scaled metric raised by one standard error
            return {L: {**v, f: {**v[f], m: v[f][m] * (1.0 + ses[name][L][f])}} for L, v in view.items()}

        for f in FAMILIES:
            ratios[f] = {}
            for m in metrics:
                s = simulated_ratios(ref, cand, sim_view[ref.name], sim_view[cand.name], soak_s=w, metric=m)[f]
                p = simulated_ratios(ref, cand, pred_view[ref.name], pred_view[cand.name], soak_s=w, metric=m)[f]
                se = [None] * len(s)
                if m in judged_metrics:
                    s_r = simulated_ratios(ref, cand, bumped(sim_view[ref.name], ref.name, f, m), sim_view[cand.name],
                                           soak_s=w, metric=m)[f]
                    s_c = simulated_ratios(ref, cand, sim_view[ref.name], bumped(sim_view[cand.name], cand.name, f, m),
                                           soak_s=w, metric=m)[f]
                    se = [None if a["ratio"] is None or b["ratio"] is None or c["ratio"] is None else
                          float(np.hypot(b["ratio"] - a["ratio"], c["ratio"] - a["ratio"]) / a["ratio"])
                          for a, b, c in zip(s, s_r, s_c)]
                # a ratio at the end of the simulated campaigns ("below" the shortest: only a bound) is not compared
                formed = [a["ratio"] is not None and b["ratio"] is not None and "below" not in (a["status"], b["status"])
                          for a, b in zip(s, p)]
                ratios[f][m] = [{"reference_length_s": a["reference_length_s"], "predicted": b["ratio"],
                                 "simulated": a["ratio"],
                                 "agreement": a["ratio"] / b["ratio"] if ok else None,
                                 "relative_se": e if ok else None, "judged": m in judged_metrics,
                                 "status": f"{b['status']} / {a['status']}"} for a, b, e, ok in zip(s, p, se, formed)]
    failed = [x for name in sims for L in sims[name] for x in sims[name][L]["failed"]]
    problems = [f"{len(failed)} simulated calibrations failed their verdict (first: {failed[0]})"] if failed else []
    for name in sims:
        for L in sims[name]:
            for f in JUDGED:
                ws = sims[name][L][f]["whitened"]
                if not ws["shape_ok"]:
                    problems.append(f"{name} {L / 3600:g} h {f}: the simulated errors' shape over temperature is not "
                                    f"the predicted one (scale at the nodes {', '.join(f'{v:.2f}' for v in ws['node_scale'])}"
                                    f" against the band {ws['node_band'][0]:.2f}-{ws['node_band'][1]:.2f})")
    for f in JUDGED:
        for m in judged_metrics:
            for r in ratios.get(f, {}).get(m, []):
                if r["agreement"] is not None and abs(r["agreement"] - 1.0) > AGREEMENT_TOLERANCE:
                    se = "" if r["relative_se"] is None else f" (standard error {r['relative_se']:.0%})"
                    problems.append(f"{f} {m} at {r['reference_length_s'] / 3600:g} h: simulated ratio "
                                    f"{r['simulated']:.3f} against predicted {r['predicted']:.3f}{se}")
    unformed = [f"{f} {m} at {r['reference_length_s'] / 3600:g} h ({r['status']})"
                for f in JUDGED for m in judged_metrics for r in ratios.get(f, {}).get(m, []) if r["agreement"] is None]
    verdict = {"passed": not problems, "tolerance": AGREEMENT_TOLERANCE, "problems": problems,
               "not_formed": unformed,
               "text": ("verdict: pass: every simulated calibration passed, the simulated errors have the predicted "
                        "shape over temperature, and the simulated equal-accuracy ratios agree with the predicted "
                        f"within {AGREEMENT_TOLERANCE:.0%}") if not problems else
                       "verdict: FAIL: " + "; ".join(problems)}
    if unformed:
        verdict["text"] += "; ratios not formed (interpolation failed on one side): " + "; ".join(unformed)

    def campaign_doc(name, L, f):
        x = sims[name][L][f]
        return {"realisations": x["realisations"], "whitened": x["whitened"], "experiment": x["experiment"],
                "largest_sigma": sim_view[name][L][f]["largest_sigma"],
                "rms_sigma": sim_view[name][L][f]["rms_sigma"],
                "largest_sigma_raw": x["largest_sigma"], "rms_sigma_raw": x["rms_sigma"],
                "worst_point_sigma": x["worst_point_sigma"],
                "predicted_largest_sigma": pred_view[name][L][f]["largest_sigma"],
                "predicted_rms_sigma": pred_view[name][L][f]["rms_sigma"]}

    camp = {name: {f"{L:g}": {f: campaign_doc(name, L, f) for f in FAMILIES} for L in sims[name]} for name in sims}
    what = (f"{realisations} simulated campaigns per point (noise, an ideal IMU: the stitched curve is its own "
            f"error), every experiment calibrated by the factor graph and stitched as the campaign does; campaigns: "
            + "; ".join(f"{n} at {', '.join(f'{L / 3600:g}' for L in Ls)} h per experiment"
                        for n, Ls in lengths.items())
            + f". Ratios over these campaigns only, soak {w / 3600:g} h. Judged: the scale of the experiments' errors "
              "against their predicted covariance (each experiment's values and temperature coefficients of a family "
              "whitened: chi-square, known spread), the predicted largest and RMS sigma times it, and the stitched "
              "curve's shape over temperature node by node (its errors at four nodes of the range whitened by their "
              "predicted covariance); the stitched curve's own scale and the raw largest over the range of R "
              "realisations are reported, not judged (the first has 12 R degrees of freedom, the second an unknown "
              "spread). A ratio that falls below the shortest simulated campaign is a bound and is not compared.")
    return {"what": what, "realisations": int(realisations), "soak_s": w, "campaigns": camp, "ratios": ratios,
            "verdict": verdict}


__all__ = ["AGREEMENT_TOLERANCE", "SHAPE_ALPHA", "JUDGED", "shifted_program", "calibrate_realisation",
           "simulated_metrics", "whitened_scale", "experiment_scale", "simulated_ratios", "simulated_check"]
