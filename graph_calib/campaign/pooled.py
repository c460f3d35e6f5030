r"""The campaign's pooled score test: an effect each subrange sees weakly, seen by the campaign.

Physics: an IMU's temperature dependence is one smooth curve over the whole range, so a curvature that one
3 h subrange cannot resolve (its own score test below its threshold) is there in every subrange.  After
every experiment's own loop (:func:`graph_calib.diagnosis.diagnose`) has finished, the campaign tests each
candidate effect once more, over the experiments that did not adopt it.

**The rule.**  For each candidate ``c`` let ``E_c`` be the experiments whose final round tested ``c`` (it is
not in the model their loop chose, and the data there determine at least one of its directions: ``dof > 0``).
Their final-round score statistics are independent (different records), each ``chi^2(k_e)`` under the null
that ``c`` is absent, so

.. math::

    T_c = \sum_{e \in E_c} T_{c,e} \sim \chi^2\Big(\sum_{e \in E_c} k_{c,e}\Big), \qquad
    \text{threshold}_c = \chi^2_{k_c}{}^{-1}\big(1 - \alpha / m\big),

with ``m`` the number of candidates pooled (``E_c`` not empty) and ``alpha`` the per-experiment loop's own
family-wise level (``DiagnosisOptions.alpha``, 0.01): Bonferroni over the candidates, as in each round of the
per-experiment loop.  The test is of "absent in every experiment of ``E_c``" against "present in some", each
experiment keeping its own coefficients (no common value is assumed).  The most significant candidate past its
threshold is adopted in every experiment of ``E_c``; those are solved again with it (both solvers,
warm-started: :func:`graph_calib.diagnosis.diagnose_from`, whose own rounds may add further effects), and the
pooled test is repeated on their new final rounds, at most :data:`MAX_WAVES` times.  (The final rounds are
those where the experiment's own test found nothing significant, so under the null the summed statistic is, if
anything, smaller than ``chi^2``: the rule is conservative.)

- :class:`PooledTest`: one candidate's pooled test;
- :func:`final_statistics`: an experiment's final-round statistics from its loop record
  (:func:`graph_calib.campaign.loop.loop_record`, ``final_round``): no recomputation;
- :func:`pooled_tests`, :func:`adoption`: the rule above.

The waves of jobs are :mod:`graph_calib.campaign.waves`.
"""

from __future__ import annotations

from dataclasses import dataclass

from scipy import stats

from graph_calib.diagnosis import log10_chi2_sf

#: At most this many pooled adoptions (waves of re-solves) per campaign.
MAX_WAVES = 3

#: The rule in words, for campaign.json and the report.
RULE = ("pooled score test: for each candidate, the final-round score statistics of the experiments that did not "
        "adopt it summed, chi-square with the summed dof under the null; threshold at alpha / m (Bonferroni over "
        "the m candidates pooled, alpha of the per-experiment loop); the most significant candidate past its "
        "threshold adopted in those experiments, which are solved again; repeated until none passes")


@dataclass(frozen=True)
class PooledTest:
    """One candidate's pooled score test over the experiments that did not adopt it.

    Attributes
    ----------
    effect : str
    statistic : float
        The summed final-round score statistics.
    dof : int
        The summed degrees of freedom.
    threshold : float
        ``chi2.isf(alpha / n_candidates, dof)``.
    log10_p : float
    experiments : tuple of str
        The experiments pooled (those whose final round tested the effect with ``dof > 0``).
    n_candidates : int
        Candidates pooled (the Bonferroni count).
    alpha : float
    """

    effect: str
    statistic: float
    dof: int
    threshold: float
    log10_p: float
    experiments: tuple[str, ...]
    n_candidates: int
    alpha: float

    @property
    def significant(self):
        return self.statistic > self.threshold

    def to_json(self):
        return {"effect": self.effect, "statistic": self.statistic, "dof": self.dof, "threshold": self.threshold,
                "log10_p": self.log10_p, "significant": self.significant, "experiments": list(self.experiments),
                "n_candidates": self.n_candidates, "alpha": self.alpha}


def final_statistics(record):
    """``{effect: (statistic, dof)}`` of the candidates an experiment's final round tested (``dof > 0``).

    Parameters
    ----------
    record : dict
        The experiment's loop record (:func:`graph_calib.campaign.loop.loop_record`).

    Raises
    ------
    KeyError
        A record without ``final_round`` (written before the pooled test existed; the cache version changed
        with it, so a campaign never meets one).
    """
    return {c["effect"]: (float(c["statistic"]), int(c["dof"])) for c in record["final_round"]["candidates"]
            if int(c["dof"]) > 0}


def pooled_tests(statistics, *, alpha):
    """Every candidate's pooled test, most significant first.

    Parameters
    ----------
    statistics : dict
        ``{experiment: {effect: (statistic, dof)}}`` (:func:`final_statistics`), each experiment's final round.
    alpha : float
        Family-wise level of one pooled decision (the per-experiment loop's ``alpha``).

    Returns
    -------
    list of PooledTest
        One per candidate tested (``dof > 0``) in at least one experiment, sorted by ``log10_p``.
    """
    pooled = {}
    for name in statistics:
        for effect, (T, k) in statistics[name].items():
            if k <= 0:
                continue
            s, d, names = pooled.get(effect, (0.0, 0, ()))
            pooled[effect] = (s + T, d + k, names + (name,))
    m = max(1, len(pooled))
    tests = [PooledTest(effect=effect, statistic=float(T), dof=int(k),
                        threshold=float(stats.chi2.isf(alpha / m, k)), log10_p=float(log10_chi2_sf(T, k)),
                        experiments=names, n_candidates=len(pooled), alpha=float(alpha))
             for effect, (T, k, names) in pooled.items()]
    return sorted(tests, key=lambda t: (t.log10_p, t.effect))


def adoption(tests):
    """The most significant pooled test past its threshold, or None."""
    significant = [t for t in tests if t.significant]
    return min(significant, key=lambda t: (t.log10_p, t.effect)) if significant else None


def decision_text(tests, adopted):
    """A pooled decision in words."""
    if adopted is None:
        best = tests[0] if tests else None
        return ("no candidate significant pooled" + (f" (most significant {best.effect}: {best.statistic:.1f} <= "
                                                       f"{best.threshold:.1f}, {best.dof} dof)" if best else ""))
    return (f"adopted {adopted.effect} in {', '.join(adopted.experiments)}: pooled score {adopted.statistic:.1f} > "
            f"{adopted.threshold:.1f} (chi-square, {adopted.dof} dof, log10 p = {adopted.log10_p:.1f}, Bonferroni "
            f"over {adopted.n_candidates} candidates)")


__all__ = ["MAX_WAVES", "RULE", "PooledTest", "final_statistics", "pooled_tests", "adoption", "decision_text"]
