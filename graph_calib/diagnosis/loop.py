"""The closed loop: calibrate, test every further effect, add the most significant one, repeat."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy import stats

from graph_calib import effects
from graph_calib.diagnosis.records import (
    CandidateTest,
    Diagnosis,
    DiagnosisOptions,
    DriverTest,
    Round,
    Stage,
)
from graph_calib.diagnosis.reduced_system import linearise
from graph_calib.diagnosis.residuals import (
    error_against_truth,
    factor_residuals,
    filter_innovations,
    residual_statistics,
)
from graph_calib.diagnosis.score import score_test, with_priors
from graph_calib.options import CalibrationOptions
from graph_calib.problem import build_problem
from graph_calib.solvers.registry import solve
from graph_calib.solvers.results import to_result


def _columns(layout, name):
    return np.arange(layout.size)[layout.slice(name)]


def _with_effects(options, effects):
    return replace(options, model=replace(options.model, extra_effects=tuple(effects)))


def _solve(problem, options, initial=None):
    return solve("factor-graph", problem, options=options, initial=initial)


def _make_stage(problem, gr, options, dopt, *, truth=None, fixed_sigmas=None, say=lambda m: None):
    model = problem.model
    series = factor_residuals(model, gr.attitudes, gr.x)
    results = {"factor-graph": to_result(model, gr)}
    st = Stage(layout=tuple(model.layout.names), problem=problem, graph=gr, results=results, residuals=series)
    if "sqrt-kf" in dopt.solvers:
        say("  square-root filter ...")
        kf = solve("sqrt-kf", problem, options=options)
        st.results["sqrt-kf"] = to_result(model, kf)
        st.kf = kf
        st.innovations = filter_innovations(kf, model)
    st.statistics = residual_statistics(st)
    if truth is not None:
        st.error = {}
        for solver, res in st.results.items():
            e = error_against_truth(res, truth)
            if fixed_sigmas is not None and solver in fixed_sigmas:
                e["rms_z_fixed"] = error_against_truth(res, truth, sigmas=fixed_sigmas[solver])["rms_z"]
            else:
                e["rms_z_fixed"] = e["rms_z"]
            st.error[solver] = e
    return st


def _added_text(t, why=""):
    """The round's decision when candidate test ``t`` is added (``why``: what the encompassing test said)."""
    return (f"added {t.name}: score statistic {t.statistic:.1f} > {t.threshold:.1f} "
            f"(chi-square, {t.dof} dof, log10 p = {t.log10_p:.1f})" + (f"; {why}" if why else ""))


def _round(index, experiment, options, problem, gr, dopt, candidates, *, allow_add=True, say=lambda m: None):
    """One round: linearise the extended model at the solution, test, decide."""
    t0 = time.perf_counter()
    model = problem.model
    cand = [c for c in candidates if c not in model.layout]
    # the same prepared record, static intervals and alignment: only the layout grows
    ext = model.with_effects(tuple(options.model.extra_effects) + tuple(cand))
    x_ext = ext.layout.embed(model.layout, gr.x)
    rs, dlist = linearise(ext, gr.attitudes, x_ext, q_nb0=problem.q_nb0, null_names=model.layout.names,
                          n_segments=dopt.time_segments)
    vf = rs.variance_factor
    A, b = rs.A, rs.b
    # candidates
    raw = {}
    skipped = {}
    for c in cand:
        if c not in ext.layout:
            skipped[c] = effects.effect(c).why_needs or "not estimable in this experiment's model"
            continue
        idx = _columns(ext.layout, c)
        sc = score_test(A, b, rs.null, idx, scale=rs.prior_sigma[idx], min_eig=dopt.identifiable, scale_factor=vf)
        if sc.dof == 0:
            skipped[c] = ("not identifiable: the data determine no combination of its elements better than "
                          "the prior")
            continue
        raw[c] = (idx, sc)
    m = max(1, len(raw))
    tests = []
    for c in cand:
        if c in skipped:
            tests.append(CandidateTest(c, 0.0, 0, effects.effect(c).size, float("nan"), 0.0, False, skipped[c],
                                       (), ()))
            continue
        idx, sc = raw[c]
        thr = float(stats.chi2.isf(dopt.alpha / m, sc.dof))
        tests.append(CandidateTest(c, sc.statistic, sc.dof, sc.dim, thr, sc.log10_p(), sc.statistic > thr, None,
                                   tuple(sc.estimate.tolist()), tuple(sc.sigma.tolist())))
    # drivers
    groups = {}
    for i, d in enumerate(dlist):
        groups.setdefault((d.group, d.axis), []).append(i)
    draw = {}
    for key, ii in groups.items():
        idx = rs.layout.size + np.asarray(ii)
        sc = score_test(A, b, rs.null, idx, min_eig=dopt.driver_min_eig, scale_factor=vf)
        if sc.dof:
            draw[key] = (idx, ii, sc)
    md = max(1, len(draw))
    dtests = []
    dthr = {}
    # where an accelerometer bias is seen: every keyframe, or only the static ones without a table
    acc_keys = ext.record.static_key if ext.options.moving_sigma is not None else np.ones(ext.n_keyframes, bool)
    for (g, ax), (idx, ii, sc) in draw.items():
        thr = float(stats.chi2.isf(dopt.alpha / md, sc.dof))
        dthr[(g, ax)] = thr
        prof = rs.driver_means[:, [dlist[i].series for i in ii]] @ sc.estimate     # fitted bias per keyframe
        seen = acc_keys if ax.startswith("accel") and np.any(acc_keys) else np.ones(prof.size, bool)
        prof = np.where(seen, prof - prof[seen].mean(), np.nan)                   # the mean is the bias
        dtests.append(DriverTest(g, ax, tuple(dlist[i].label for i in ii), sc.statistic, sc.dof, thr,
                                 sc.log10_p(), sc.statistic > thr, tuple(sc.estimate.tolist()),
                                 tuple(sc.sigma_identifiable.tolist()), float(np.sqrt(np.nanmean(prof**2))),
                                 tuple(prof.tolist())))
    rnd = Round(index=index, layout=tuple(model.layout.names), candidates=tests, drivers=dtests,
                variance_factor=vf, chi2_per_dof=rs.chi2 / max(rs.dof, 1))
    significant = sorted((t for t in tests if t.significant), key=lambda t: t.log10_p)
    sig_drivers = [d for d in dtests if d.significant]
    if not significant:
        rnd.decision = (f"no candidate significant at alpha = {dopt.alpha:g} "
                        f"(Bonferroni over {len(raw)} candidates)")
    elif not allow_add:
        rnd.decision = f"most significant candidate {significant[0].name} not added: the limit of added effects"
    for t in significant if allow_add else ():
        idx = raw[t.name][0]
        if not dopt.encompassing or not sig_drivers:
            rnd.added, rnd.decision = t.name, _added_text(t)
            break
        # encompassing: does the candidate explain the driver signatures, or only mimic one?
        A_c = with_priors(rs, idx)
        base_c = np.concatenate([rs.null, idx])
        left = []
        for d in sig_drivers:
            didx = draw[(d.group, d.axis)][0]
            sc = score_test(A_c, b, base_c, didx, min_eig=dopt.driver_min_eig, scale_factor=vf)
            if sc.statistic > d.threshold and sc.dof:
                left.append((sc.log10_p(), d, didx, sc))
        check = {"candidate": t.name, "drivers_significant_before": len(sig_drivers),
                 "drivers_left_given_candidate": [{"driver": d.group, "axis": d.axis, "statistic": sc.statistic,
                                                   "dof": sc.dof, "threshold": d.threshold}
                                                  for _, d, _, sc in sorted(left, key=lambda z: z[0])]}
        if not left:
            check["verdict"] = "explains every significant driver signature"
            rnd.checks.append(check)
            rnd.added, rnd.decision = t.name, _added_text(t, "it explains every significant driver signature")
            break
        # the generic alternative: every driver signature the candidate leaves unexplained
        dcols = np.concatenate([z[2] for z in left])
        names_left = ", ".join(f"{d.group} on {d.axis}" for _, d, _, _ in sorted(left, key=lambda z: z[0]))
        sc_c = score_test(A, b, np.concatenate([rs.null, dcols]), idx, scale=rs.prior_sigma[idx],
                          min_eig=dopt.identifiable, scale_factor=vf)
        thr_c = float(stats.chi2.isf(dopt.alpha / m, max(sc_c.dof, 1)))
        check["candidate_given_drivers"] = {"statistic": sc_c.statistic, "dof": sc_c.dof, "threshold": thr_c}
        if sc_c.dof and sc_c.statistic > thr_c:
            check["verdict"] = (f"needed beyond the driver signatures it leaves ({names_left}): "
                                f"{sc_c.statistic:.1f} > {thr_c:.1f}")
            rnd.checks.append(check)
            rnd.added, rnd.decision = t.name, _added_text(
                t, "still significant given the driver signatures it does not explain")
            break
        check["verdict"] = (f"not added: it only mimics driver signatures the catalogue lacks ({names_left}): "
                            f"{sc_c.statistic:.1f} <= {thr_c:.1f} given those drivers")
        rnd.checks.append(check)
    if allow_add and significant and rnd.added is None:
        rnd.decision = ("no candidate added: every significant candidate only mimics a driver signature "
                        "that the catalogue lacks")
    rnd.seconds = time.perf_counter() - t0
    return rnd


def diagnose(experiment, *, options=None, diagnosis=DiagnosisOptions(), truth=None, progress=None):
    """The closed loop on one experiment.

    Parameters
    ----------
    experiment : graph_calib.experiment.Experiment
    options : graph_calib.calibrate.CalibrationOptions, optional
        The declared model (grade, keyframes, effects already modelled, priors).
    diagnosis : DiagnosisOptions
    truth : graph_calib.experiment.Result, optional
        A simulator's truth: the error of the declared parameters before and after.
    progress : callable, optional
        Called with one-line messages.

    Returns
    -------
    Diagnosis
    """
    t_start = time.perf_counter()
    say = progress or (lambda msg: None)
    options = CalibrationOptions() if options is None else options
    problem = build_problem(experiment, options=options)
    options = replace(options, t_ref_degC=problem.model.t_ref_degC)   # one T_ref for every model
    candidates = tuple(diagnosis.candidates or effects.FURTHER_EFFECTS)
    m = problem.model
    say(f"declared model: {m.layout.size} parameters, {m.n_keyframes} keyframes; factor graph ...")
    gr = _solve(problem, options)
    before = _make_stage(problem, gr, options, diagnosis, truth=truth, say=say)
    fixed = {s: r.sigmas for s, r in before.results.items()}
    rounds, added = [], []
    while True:
        allow = len(added) < diagnosis.max_added
        rnd = _round(len(rounds) + 1, experiment, options, problem, gr, diagnosis, candidates, allow_add=allow,
                     say=say)
        rounds.append(rnd)
        say(f"round {rnd.index}: {rnd.decision}")
        if rnd.added is None:
            break
        added.append(rnd.added)
        options = _with_effects(options, tuple(options.model.extra_effects) + (rnd.added,))
        new = problem.with_effects(options.model.extra_effects)
        x0 = new.model.layout.embed(problem.model.layout, gr.x)
        say(f"re-solving with {rnd.added} ...")
        gr = _solve(new, options, initial=(gr.attitudes, x0))
        problem = new
    after = before if not added else _make_stage(problem, gr, options, diagnosis, truth=truth,
                                                 fixed_sigmas=fixed, say=say)
    last = rounds[-1]
    signature = sorted((d for d in last.drivers if d.significant), key=lambda d: d.log10_p)
    e = experiment
    context = {
        "n_samples": e.n_samples, "duration_s": float(e.t[-1] - e.t[0] + 1.0 / e.rate_hz),
        "rate_hz": float(e.rate_hz), "table": e.table is not None, "grade": options.model.grade,
        "keyframes": int(m.n_keyframes), "keyframe_s": float(options.model.keyframe_s),
        "t_ref_degC": float(m.t_ref_degC), "solvers": list(diagnosis.solvers),
        "temperature_range_degC": [float(m.temperatures.min()), float(m.temperatures.max())],
        "truth": truth is not None,
    }
    source = e.source.rsplit("/", 1)[-1] if e.source else ""
    return Diagnosis(source=source, added=added, unexplained=bool(signature), signature=signature, rounds=rounds,
                     before=before, after=after, options=diagnosis, context=context,
                     seconds=time.perf_counter() - t_start)
