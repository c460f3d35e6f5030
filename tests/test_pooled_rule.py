"""The campaign's pooled score test on synthetic statistics (graph_calib.campaign.pooled): the statistics and the
degrees of freedom summed over the experiments that did not adopt an effect, the threshold at alpha / m
(Bonferroni over the candidates pooled), the decision at the threshold; and its false-adoption rate under the
null, by simulation of chi-square statistics (no solver: a few milliseconds)."""

import numpy as np
import pytest
from scipy import stats

from graph_calib.campaign.loop import loop_record
from graph_calib.campaign.pooled import adoption, decision_text, final_statistics, pooled_tests


def test_statistics_and_dof_are_summed_over_the_experiments_that_test_the_effect():
    st = {"a": {"x": (10.0, 3), "y": (1.0, 2)},
          "b": {"x": (12.5, 3), "y": (0.5, 0)},       # y skipped in b (dof 0): not pooled there
          "c": {"y": (4.0, 2)}}                       # x adopted in c: not among its final round's tests
    tests = {t.effect: t for t in pooled_tests(st, alpha=0.01)}
    x, y = tests["x"], tests["y"]
    assert (x.statistic, x.dof, x.experiments) == (22.5, 6, ("a", "b"))
    assert (y.statistic, y.dof, y.experiments) == (5.0, 4, ("a", "c"))
    assert x.n_candidates == y.n_candidates == 2
    # Bonferroni over the two candidates pooled
    assert x.threshold == pytest.approx(stats.chi2.isf(0.01 / 2, 6), rel=1e-12)
    assert y.threshold == pytest.approx(stats.chi2.isf(0.01 / 2, 4), rel=1e-12)
    assert x.log10_p == pytest.approx(np.log10(stats.chi2.sf(22.5, 6)), rel=1e-9)
    assert x.significant and not y.significant          # 22.5 > 18.5; 5.0 < 14.9
    assert adoption(list(tests.values())) is x
    assert "adopted x in a, b" in decision_text(list(tests.values()), x)


def test_the_decision_at_the_threshold_and_the_bonferroni_count():
    thr = stats.chi2.isf(0.01 / 3, 6)
    others = {"o1": (0.0, 1), "o2": (0.0, 1)}          # three candidates pooled: alpha / 3
    below = {"a": {"x": (thr / 2 - 1e-6, 3), **others}, "b": {"x": (thr / 2 - 1e-6, 3)}}
    above = {"a": {"x": (thr / 2 + 1e-6, 3), **others}, "b": {"x": (thr / 2 + 1e-6, 3)}}
    assert adoption(pooled_tests(below, alpha=0.01)) is None
    assert adoption(pooled_tests(above, alpha=0.01)).effect == "x"
    # each experiment alone is far below its own threshold (3 dof), the pooled statistic passes
    assert thr / 2 < stats.chi2.isf(0.01 / 3, 3)
    # the same statistics with fewer candidates pooled: a lower threshold
    one = pooled_tests({"a": {"x": (1.0, 3)}, "b": {"x": (1.0, 3)}}, alpha=0.01)[0]
    assert one.threshold == pytest.approx(stats.chi2.isf(0.01, 6)) and one.threshold < thr
    # the most significant of two passing candidates is adopted
    two = {"a": {"x": (60.0, 3), "y": (80.0, 3)}}
    assert adoption(pooled_tests(two, alpha=0.01)).effect == "y"
    assert adoption(pooled_tests({}, alpha=0.01)) is None


def test_false_adoption_rate_under_the_null_is_at_most_alpha():
    """Six experiments, 14 candidates of 1-6 dof each, every statistic chi-square under the null: the pooled
    decision adopts something in at most alpha of 3,000 simulated campaigns (Bonferroni: at most 1 %)."""
    rng = np.random.default_rng(20261202)
    dofs = rng.integers(1, 7, size=14)
    n, hits = 3_000, 0
    T = rng.chisquare(dofs[None, None, :], size=(n, 6, 14))
    for k in range(n):
        st = {f"e{e}": {f"c{c}": (float(T[k, e, c]), int(dofs[c])) for c in range(14)} for e in range(6)}
        hits += adoption(pooled_tests(st, alpha=0.01)) is not None
    rate = hits / n
    assert rate <= 0.01 + 3 * np.sqrt(0.01 * 0.99 / n), rate
    assert rate > 0.002, rate          # and the test is not vacuous: near its level


class _C:
    def __init__(self, name, statistic, dof, threshold, log10_p):
        self.name, self.statistic, self.dof, self.threshold, self.log10_p = name, statistic, dof, threshold, log10_p


def test_final_round_statistics_are_kept_in_the_loop_record():
    """``loop_record`` keeps the last round's candidate statistics; ``final_statistics`` reads them back."""

    class R:
        def __init__(self, index, candidates, added=None):
            self.index, self.candidates, self.added, self.decision = index, candidates, added, "d"

    class D:
        rounds = [R(1, [_C("x", 50.0, 3, 17.0, -9.0), _C("y", 2.0, 2, 15.0, -0.3)], added="x"),
                  R(2, [_C("y", 3.0, 2, 14.0, -0.6), _C("z", 0.0, 0, float("nan"), 0.0)])]
        unexplained, signature, seconds = False, [], 1.0

        class before:
            layout = ("gyro.bias",)

        class after:
            layout = ("gyro.bias", "x")

    import graph_calib.campaign.loop as lp
    keep = lp.residual_rms
    lp.residual_rms = lambda stage: {}
    try:
        rec = loop_record(D)
    finally:
        lp.residual_rms = keep
    assert rec["final_round"]["round"] == 2
    assert rec["final_round"]["candidates"][1] == {"effect": "z", "statistic": 0.0, "dof": 0, "threshold": None,
                                                   "log10_p": 0.0}
    assert final_statistics(rec) == {"y": (3.0, 2)}
