"""A round's tests and its decision: score tests of the candidates and of the driver groups, the encompassing check.

:mod:`graph_calib.diagnosis.loop` runs a round: it linearises the extended model at the current solution
(:func:`graph_calib.diagnosis.reduced_system.linearise`), then :func:`test_candidates` and :func:`test_drivers`
score-test the candidates and the generic driver groups against the current model (Bonferroni within each), and
:func:`decide` adds the most significant candidate that explains the significant driver signatures, or is needed
beyond those it leaves (the encompassing check), or nothing.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from graph_calib.diagnosis.rounds import CandidateTest, DriverTest
from graph_calib.diagnosis.score import score_test, with_priors
from graph_calib.sensors import effects


def _columns(layout, name):
    """Columns of parameter ``name`` in ``layout``."""
    return np.arange(layout.size)[layout.slice(name)]


def test_candidates(system, layout, names, *, diagnosis_options):
    """Score test of each candidate ``names`` against the current model (Bonferroni over those tested).

    Parameters
    ----------
    system : ReducedSystem
    layout : graph_calib.sensors.params.Layout
        The extended layout (a candidate absent from it is not estimable in this experiment).
    names : sequence of str
    diagnosis_options : DiagnosisOptions

    Returns
    -------
    tests : list of CandidateTest
        In the order of ``names``.
    columns : dict of str to ndarray
        The columns of each candidate tested (not skipped).
    """
    vf = system.variance_factor
    raw = {}
    skipped = {}
    for name in names:
        if name not in layout:
            skipped[name] = effects.effect(name).why_needs or "not estimable in this experiment's model"
            continue
        idx = _columns(layout, name)
        sc = score_test(system.A, system.b, system.null, idx, scale=system.prior_sigma[idx],
                        min_eig=diagnosis_options.identifiable, scale_factor=vf)
        if sc.dof == 0:
            skipped[name] = ("not identifiable: the data determine no combination of its elements better than "
                             "the prior")
            continue
        raw[name] = (idx, sc)
    m = max(1, len(raw))
    tests = []
    for name in names:
        if name in skipped:
            tests.append(CandidateTest(name, 0.0, 0, effects.effect(name).size, float("nan"), 0.0, False,
                                       skipped[name], (), ()))
            continue
        idx, sc = raw[name]
        thr = float(stats.chi2.isf(diagnosis_options.alpha / m, sc.dof))
        tests.append(CandidateTest(name, sc.statistic, sc.dof, sc.dim, thr, sc.log10_p(), sc.statistic > thr, None,
                                   tuple(sc.estimate.tolist()), tuple(sc.sigma.tolist()), tuple(sc.u.tolist()),
                                   tuple(sc.S.ravel().tolist()), tuple(system.prior_sigma[idx].tolist())))
    return tests, {name: idx for name, (idx, _) in raw.items()}


def test_drivers(system, drivers, model, *, diagnosis_options):
    """Score test of each driver group on each sensor axis against the current model (Bonferroni).

    Parameters
    ----------
    system : ReducedSystem
        With the driver columns (after ``system.layout``).
    drivers : list of Driver
        The driver columns, in order.
    model : graph_calib.model.CalibrationModel
        The extended model (where an accelerometer bias is seen).
    diagnosis_options : DiagnosisOptions

    Returns
    -------
    tests : list of DriverTest
    columns : dict of (str, str) to ndarray
        The columns of each ``(group, axis)`` tested.
    """
    vf = system.variance_factor
    groups = {}
    for i, d in enumerate(drivers):
        groups.setdefault((d.group, d.axis), []).append(i)
    draw = {}
    for key, ii in groups.items():
        idx = system.layout.size + np.asarray(ii)
        sc = score_test(system.A, system.b, system.null, idx, min_eig=diagnosis_options.driver_min_eig,
                        scale_factor=vf)
        if sc.dof:
            draw[key] = (idx, ii, sc)
    md = max(1, len(draw))
    tests = []
    # where an accelerometer bias is seen: every keyframe, or only the static ones without a table
    if model.options.moving_sigma is not None:
        acc_keys = model.record.static_key
    else:
        acc_keys = np.ones(model.n_keyframes, bool)
    for (g, ax), (idx, ii, sc) in draw.items():
        thr = float(stats.chi2.isf(diagnosis_options.alpha / md, sc.dof))
        prof = system.driver_means[:, [drivers[i].series for i in ii]] @ sc.estimate   # fitted bias per keyframe
        seen = acc_keys if ax.startswith("accel") and np.any(acc_keys) else np.ones(prof.size, bool)
        prof = np.where(seen, prof - prof[seen].mean(), np.nan)                       # the mean is the bias
        tests.append(DriverTest(g, ax, tuple(drivers[i].label for i in ii), sc.statistic, sc.dof, thr,
                                sc.log10_p(), sc.statistic > thr, tuple(sc.estimate.tolist()),
                                tuple(sc.sigma_identifiable.tolist()), float(np.sqrt(np.nanmean(prof**2))),
                                tuple(prof.tolist())))
    return tests, {key: idx for key, (idx, _, _) in draw.items()}


def _added_text(t, why=""):
    """The round's decision when candidate test ``t`` is added (``why``: what the encompassing test said)."""
    return (f"added {t.name}: score statistic {t.statistic:.1f} > {t.threshold:.1f} "
            f"(chi-square, {t.dof} dof, log10 p = {t.log10_p:.1f})" + (f"; {why}" if why else ""))


def _encompassing_check(test, columns, system, significant_drivers, driver_columns, *, n_tested,
                        diagnosis_options):
    """Does significant candidate ``test`` explain the driver signatures, or only mimic one?

    The driver signatures still significant given the candidate are those it leaves; the
    candidate is needed when it is still significant given those (the generic alternative).

    Parameters
    ----------
    test : CandidateTest
    columns : ndarray of int
        The candidate's columns.
    system : ReducedSystem
    significant_drivers : list of DriverTest
    driver_columns : dict of (str, str) to ndarray
        Columns of each driver test (:func:`test_drivers`).
    n_tested : int
        Candidates tested in the round (Bonferroni).
    diagnosis_options : DiagnosisOptions

    Returns
    -------
    check : dict
        The check as ``diagnosis.json``'s ``encompassing_checks`` holds it.
    why : str or None
        Why the candidate is added, or None when it only mimics driver signatures.
    """
    vf = system.variance_factor
    A_c = with_priors(system, columns)
    base_c = np.concatenate([system.null, columns])
    left = []
    for d in significant_drivers:
        didx = driver_columns[(d.group, d.axis)]
        sc = score_test(A_c, system.b, base_c, didx, min_eig=diagnosis_options.driver_min_eig, scale_factor=vf)
        if sc.statistic > d.threshold and sc.dof:
            left.append((sc.log10_p(), d, didx, sc))
    check = {"candidate": test.name, "drivers_significant_before": len(significant_drivers),
             "drivers_left_given_candidate": [{"driver": d.group, "axis": d.axis, "statistic": sc.statistic,
                                               "dof": sc.dof, "threshold": d.threshold}
                                              for _, d, _, sc in sorted(left, key=lambda z: z[0])]}
    if not left:
        check["verdict"] = "explains every significant driver signature"
        return check, "it explains every significant driver signature"
    # the generic alternative: every driver signature the candidate leaves unexplained
    dcols = np.concatenate([z[2] for z in left])
    names_left = ", ".join(f"{d.group} on {d.axis}" for _, d, _, _ in sorted(left, key=lambda z: z[0]))
    sc_c = score_test(system.A, system.b, np.concatenate([system.null, dcols]), columns,
                      scale=system.prior_sigma[columns], min_eig=diagnosis_options.identifiable, scale_factor=vf)
    thr_c = float(stats.chi2.isf(diagnosis_options.alpha / max(1, n_tested), max(sc_c.dof, 1)))
    check["candidate_given_drivers"] = {"statistic": sc_c.statistic, "dof": sc_c.dof, "threshold": thr_c}
    if sc_c.dof and sc_c.statistic > thr_c:
        check["verdict"] = (f"needed beyond the driver signatures it leaves ({names_left}): "
                            f"{sc_c.statistic:.1f} > {thr_c:.1f}")
        return check, "still significant given the driver signatures it does not explain"
    check["verdict"] = (f"not added: it only mimics driver signatures the catalogue lacks ({names_left}): "
                        f"{sc_c.statistic:.1f} <= {thr_c:.1f} given those drivers")
    return check, None


def decide(system, candidate_tests, candidate_columns, driver_tests, driver_columns, *, allow_add,
            diagnosis_options):
    """The round's decision: the effect added (or None), the decision in words, the encompassing checks.

    The significant candidates are taken most significant first; with the encompassing
    check the first one that is not a mere mimic of a driver signature is added.
    """
    significant = sorted((t for t in candidate_tests if t.significant), key=lambda t: t.log10_p)
    if not significant:
        return None, (f"no candidate significant at alpha = {diagnosis_options.alpha:g} "
                      f"(Bonferroni over {len(candidate_columns)} candidates)"), []
    if not allow_add:
        return None, f"most significant candidate {significant[0].name} not added: the limit of added effects", []
    significant_drivers = [d for d in driver_tests if d.significant]
    if not diagnosis_options.encompassing or not significant_drivers:
        return significant[0].name, _added_text(significant[0]), []
    checks = []
    for t in significant:
        check, why = _encompassing_check(t, candidate_columns[t.name], system, significant_drivers, driver_columns,
                                         n_tested=len(candidate_columns), diagnosis_options=diagnosis_options)
        checks.append(check)
        if why is not None:
            return t.name, _added_text(t, why), checks
    return None, ("no candidate added: every significant candidate only mimics a driver signature "
                  "that the catalogue lacks"), checks


__all__ = ["test_candidates", "test_drivers", "decide"]
