r"""The campaign's pooled score tests: an effect each subrange sees weakly, seen by the campaign.

Physics: an IMU's temperature dependence is one smooth curve over the whole range, and its other constants
(size effect, non-linearity, g-sensitivity) are one IMU's, so an effect that one 3 h subrange cannot resolve
(its own score test below its threshold) is there in every subrange.  After every experiment's own loop
(:func:`graph_calib.diagnosis.diagnose`) has finished, the campaign tests each candidate effect once more,
over the experiments that did not adopt it.

**The rule.**  For each candidate ``c`` let ``E_c`` be the experiments whose final round tested ``c`` (it is
not in the model their loop chose, and the data there determine at least one of its directions: ``dof > 0``).
Their final rounds are independent (different records).  Under the null that ``c`` is absent, two statistics
are chi-square:

- **sum**: the final-round score statistics summed, ``T_c = sum_e T_{c,e}`` with ``k_c = sum_e k_{c,e}`` dof:
  against an effect present in some experiments with values of its own in each;
- **common** (``|E_c| >= 2``): the score test of one value of the effect's parameters shared by every
  experiment of ``E_c``: the experiments' scores and informations summed (each already divided by its own
  variance factor), ``U = sum_e u_e``, ``I = sum_e S_e``, ``T_c = U^T I^+ U`` on the directions the campaign
  determines better than the prior (``lambda(D I D) >= 1``, ``D`` the prior sigmas, as for one experiment),
  ``k_c`` of them: against one constant over the range, which is what a quadratic curve's ``*_tc2``, a
  cubic's ``*_tc3`` and the IMU's own constants are.  Its dof stay those of one experiment while the signal
  adds up coherently, so it sees what the sum spreads over ``|E_c|`` times the dof.

Each statistic is set against ``chi2.isf(alpha / m, k_c)``, with ``m`` the number of pooled tests (both kinds,
every candidate) and ``alpha`` the per-experiment loop's own family-wise level (``DiagnosisOptions.alpha``,
0.01): Bonferroni over everything the pooled decision looks at, as in each round of the per-experiment loop.
The candidate of the most significant test past its threshold is adopted in every experiment of ``E_c``, each
keeping its own coefficients; those are solved again with it (both solvers, warm-started:
:func:`graph_calib.diagnosis.diagnose_from`, whose own rounds may add further effects), and the pooled tests
are repeated on their new final rounds, at most :data:`MAX_WAVES` times.  (The final rounds are those where
each experiment's own test found nothing significant, so under the null the pooled statistics are, if
anything, smaller than chi-square: the rule is conservative.)

- :class:`FinalTest`: one candidate's final-round test in one experiment (:func:`final_statistics` reads them
  from an experiment's loop record, :func:`graph_calib.campaign.loop.loop_record`'s ``final_round``: nothing is
  recomputed);
- :class:`PooledTest`: one pooled test; :func:`pooled_tests` and :func:`adoption`: the rule above.

The waves of jobs are :mod:`graph_calib.campaign.waves`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from graph_calib.diagnosis import log10_chi2_sf

#: At most this many pooled adoptions (waves of re-solves) per campaign.
MAX_WAVES = 3

#: The rule in words, for campaign.json and the report.
RULE = ("pooled score tests over the experiments whose final round tested a candidate: 'sum', their score statistics "
        "summed (chi-square with the summed dof), and 'common', the score test of one value shared by those "
        "experiments (their scores and informations summed; chi-square with the identifiable dof); each at "
        "alpha / m (Bonferroni over the m pooled tests, alpha of the per-experiment loop); the candidate of the "
        "most significant test past its threshold adopted in those experiments, which are solved again; repeated "
        "until none passes")


@dataclass(frozen=True)
class PooledTest:
    """One pooled score test of a candidate over the experiments that did not adopt it.

    Attributes
    ----------
    effect : str
    kind : str
        ``"sum"`` (the experiments' statistics and dof summed) or ``"common"`` (one value shared by them).
    statistic : float
    dof : int
    threshold : float
        ``chi2.isf(alpha / n_tests, dof)``.
    log10_p : float
    experiments : tuple of str
        The experiments pooled (those whose final round tested the effect with ``dof > 0``).
    n_tests : int
        Pooled tests of the decision, both kinds (the Bonferroni count).
    alpha : float
    """

    effect: str
    kind: str
    statistic: float
    dof: int
    threshold: float
    log10_p: float
    experiments: tuple[str, ...]
    n_tests: int
    alpha: float

    @property
    def significant(self):
        return self.statistic > self.threshold

    def to_json(self):
        return {"effect": self.effect, "kind": self.kind, "statistic": self.statistic, "dof": self.dof,
                "threshold": self.threshold, "log10_p": self.log10_p, "significant": self.significant,
                "experiments": list(self.experiments), "n_tests": self.n_tests, "alpha": self.alpha}


@dataclass(frozen=True)
class FinalTest:
    """One candidate's score test in one experiment's final round (what the pooled tests combine).

    Attributes
    ----------
    statistic : float
    dof : int
    u : ndarray (dim,) or None
        The score, divided by the experiment's variance factor (None: only the ``sum`` test uses it).
    S : ndarray (dim, dim) or None
        Its information, likewise.
    scale : ndarray (dim,) or None
        The prior sigmas that judge which directions are identifiable.
    """

    statistic: float
    dof: int
    u: np.ndarray | None = None
    S: np.ndarray | None = None
    scale: np.ndarray | None = None


def final_statistics(record):
    """``{effect: FinalTest}`` of the candidates an experiment's final round tested (``dof > 0``).

    Parameters
    ----------
    record : dict
        The experiment's loop record (:func:`graph_calib.campaign.loop.loop_record`).

    Raises
    ------
    KeyError
        A record without ``final_round`` (written before the pooled tests existed; the cache version changed
        with them, so a campaign never meets one).
    """
    out = {}
    for c in record["final_round"]["candidates"]:
        if int(c["dof"]) <= 0:
            continue
        u = np.asarray(c.get("score") or [], dtype=float)
        ok = u.size > 0
        out[c["effect"]] = FinalTest(float(c["statistic"]), int(c["dof"]), u=u if ok else None,
                                     S=np.asarray(c["information"], dtype=float).reshape(u.size, u.size) if ok else None,
                                     scale=np.asarray(c["scale"], dtype=float) if ok else None)
    return out


def _common(tests, *, identifiable):
    """``(statistic, dof)`` of one value shared by the experiments' ``tests`` (module docstring), or None."""
    if len(tests) < 2 or any(t.u is None for t in tests) or len({t.u.size for t in tests}) != 1:
        return None
    U = np.sum([t.u for t in tests], axis=0)
    I = np.sum([t.S for t in tests], axis=0)
    D = tests[0].scale
    lam, V = np.linalg.eigh(D[:, None] * (0.5 * (I + I.T)) * D[None, :])
    keep = lam >= identifiable
    if not np.any(keep):
        return None
    proj = V[:, keep].T @ (D * U)
    return float(np.sum(proj**2 / lam[keep])), int(np.count_nonzero(keep))


def pooled_tests(statistics, *, alpha, identifiable=1.0):
    """Every candidate's pooled tests (``sum`` and, over two experiments or more, ``common``), most significant first.

    Parameters
    ----------
    statistics : dict
        ``{experiment: {effect: FinalTest or (statistic, dof)}}`` (:func:`final_statistics`), each
        experiment's final round.
    alpha : float
        Family-wise level of one pooled decision (the per-experiment loop's ``alpha``).
    identifiable : float
        A direction of the common value counts when ``lambda(D I D)`` reaches it (``DiagnosisOptions.identifiable``).

    Returns
    -------
    list of PooledTest
        Sorted by ``log10_p``.
    """
    by_effect = {}
    for name in statistics:
        for effect, t in statistics[name].items():
            t = t if isinstance(t, FinalTest) else FinalTest(float(t[0]), int(t[1]))
            if t.dof > 0:
                by_effect.setdefault(effect, []).append((name, t))
    raw = []
    for effect, items in by_effect.items():
        names = tuple(n for n, _ in items)
        raw.append((effect, "sum", sum(t.statistic for _, t in items), sum(t.dof for _, t in items), names))
        common = _common([t for _, t in items], identifiable=identifiable)
        if common is not None:
            raw.append((effect, "common", common[0], common[1], names))
    m = max(1, len(raw))
    tests = [PooledTest(effect=effect, kind=kind, statistic=float(T), dof=int(k),
                        threshold=float(stats.chi2.isf(alpha / m, k)), log10_p=float(log10_chi2_sf(T, k)),
                        experiments=names, n_tests=len(raw), alpha=float(alpha))
             for effect, kind, T, k, names in raw]
    return sorted(tests, key=lambda t: (t.log10_p, t.effect, t.kind))


def adoption(tests):
    """The most significant pooled test past its threshold, or None."""
    significant = [t for t in tests if t.significant]
    return min(significant, key=lambda t: (t.log10_p, t.effect, t.kind)) if significant else None


def decision_text(tests, adopted):
    """A pooled decision in words."""
    if adopted is None:
        best = tests[0] if tests else None
        return ("no candidate significant pooled" + (f" (most significant {best.effect} ({best.kind}): "
                                                       f"{best.statistic:.1f} <= {best.threshold:.1f}, {best.dof} dof)"
                                                       if best else ""))
    return (f"adopted {adopted.effect} in {', '.join(adopted.experiments)}: pooled ({adopted.kind}) score "
            f"{adopted.statistic:.1f} > {adopted.threshold:.1f} (chi-square, {adopted.dof} dof, log10 p = "
            f"{adopted.log10_p:.1f}, Bonferroni over {adopted.n_tests} pooled tests)")


__all__ = ["MAX_WAVES", "RULE", "FinalTest", "PooledTest", "final_statistics", "pooled_tests", "adoption", "decision_text"]
