"""The closed loop's score tests of the known candidates at a calibration's solution, without adoption.

``calibrate`` solves the declared model; the residual test of its verdict judges size (each kind's
``chi2 / redundancy``), and variance components bring every kind's size to 1 whatever the residuals
carry.  What they carry is judged here: the loop's score test (:func:`graph_calib.diagnosis.score_test`)
of every further effect of model.md that the model lacks, linearised once at the solution (the model
extended by the candidates, every candidate zero: :func:`graph_calib.diagnosis.linearise`), with the
loop's thresholds (chi-square quantile at ``alpha`` over the number of candidates tested, Bonferroni;
:class:`graph_calib.diagnosis.DiagnosisOptions`) and the loop's noise: ``calibrate`` passes the problem with the
noise identified from the record (:func:`graph_calib.solvers.variance.tested_problem`), not the one its variance
factors rescale, since a factor estimated from these residuals absorbs the misfit the tests look for (and a
factor below one would make them stricter than the loop's: on the Xsens session ``accel.nonlinearity`` was named
at a gravity factor 0.25 that the loop, testing at the identified noise, does not find).  Each candidate is tested
alone against the declared model; the loop adds the most significant and tests the others again, so a
candidate named here beside a stronger one may be explained by it.  A significant candidate fails the residual part of the
verdict, named with its statistic: a record that ``diagnose`` would change does not get "pass" from
``calibrate``.  Nothing is adopted; ``diagnose`` is the command that does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri

from graph_calib.diagnosis.reduced_system import linearise
from graph_calib.diagnosis.rounds import DiagnosisOptions
from graph_calib.diagnosis.score import score_test
from graph_calib.sensors import effects


@dataclass(frozen=True)
class StructureTest:
    """One candidate's score test at the solution.

    Attributes
    ----------
    effect : str
    statistic, threshold : float
    dof : int
    significant : bool
    """

    effect: str
    statistic: float
    threshold: float
    dof: int
    significant: bool

    def to_json(self):
        return {"effect": self.effect, "statistic": self.statistic, "threshold": self.threshold, "dof": self.dof,
                "significant": self.significant}


def structure_tests(problem, output, *, diagnosis=DiagnosisOptions()):
    """Score tests of the candidates the model lacks at ``output``'s solution (module doc).

    Parameters
    ----------
    problem : graph_calib.records.problem.Problem
        The problem the solver solved.
    output : graph_calib.solvers.interface.SolverOutput
        A batch solution (keyframe attitudes and calibration).
    diagnosis : DiagnosisOptions
        ``alpha``, ``identifiable`` and ``candidates`` as the loop's.

    Returns
    -------
    list of StructureTest
        The candidates tested (identifiable ones), most significant first.
    """
    model = problem.model
    names = [n for n in (diagnosis.candidates or effects.FURTHER_EFFECTS) if n not in model.layout]
    if not names:
        return []
    extended = model.with_effects(tuple(model.options.extra_effects) + tuple(names))
    names = [n for n in names if n in extended.layout]
    if not names:
        return []
    x = extended.layout.embed(model.layout, output.x)
    system, _ = linearise(extended, output.attitudes, x, q_nb0=problem.q_nb0, null_names=model.layout.names,
                          drivers=False)
    raw = []
    for name in names:
        s = extended.layout.slice(name)
        idx = np.arange(s.start, s.stop)
        sc = score_test(system.A, system.b, system.null, idx, scale=system.prior_sigma[idx],
                        min_eig=diagnosis.identifiable, scale_factor=system.variance_factor)
        if sc.dof > 0:
            raw.append((name, sc))
    m = max(1, len(raw))
    out = []
    for name, sc in raw:
        thr = float(chdtri(sc.dof, diagnosis.alpha / m))      # scipy.stats.chi2.isf
        out.append(StructureTest(effect=name, statistic=float(sc.statistic), threshold=thr, dof=int(sc.dof),
                                 significant=bool(sc.statistic > thr)))
    return sorted(out, key=lambda t: -t.statistic / t.threshold)


__all__ = ["StructureTest", "structure_tests"]
