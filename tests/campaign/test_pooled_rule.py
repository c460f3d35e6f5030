"""The campaign's pooled score tests on synthetic statistics (graph_calib.campaign.pooled): the statistics and the
degrees of freedom summed over the experiments that did not adopt an effect ('sum'), the score test of one value
shared by them ('common'), the threshold at alpha / m (Bonferroni over the pooled tests), the decision at the
threshold; and the false-adoption rate under the null, by simulation of the experiments' scores (no solver)."""

import numpy as np
import pytest
from scipy import stats

from graph_calib.campaign.loop import loop_record
from graph_calib.campaign.pooled import FinalTest, adoption, decision_text, final_statistics, pooled_tests


def test_statistics_and_dof_are_summed_over_the_experiments_that_test_the_effect():
    st = {"a": {"x": (10.0, 3), "y": (1.0, 2)},
          "b": {"x": (12.5, 3), "y": (0.5, 0)},       # y skipped in b (dof 0): not pooled there
          "c": {"y": (4.0, 2)}}                       # x adopted in c: not among its final round's tests
    tests = {t.effect: t for t in pooled_tests(st, alpha=0.01)}
    x, y = tests["x"], tests["y"]
    assert (x.statistic, x.dof, x.experiments) == (22.5, 6, ("a", "b"))
    assert (y.statistic, y.dof, y.experiments) == (5.0, 4, ("a", "c"))
    assert x.n_tests == y.n_tests == 2 and x.kind == y.kind == "sum"      # (statistics alone: no common test)
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


def test_the_common_value_test_adds_the_scores_coherently():
    """Two experiments with the same score: the common test's statistic doubles at the dof of one experiment."""
    S = np.diag([4.0, 1.0])
    a = FinalTest(9.0 / 4.0 + 0.0, 1, u=np.array([3.0, 0.0]), S=S, scale=np.array([10.0, 10.0]))
    b = FinalTest(9.0 / 4.0, 1, u=np.array([3.0, 0.0]), S=S, scale=np.array([10.0, 10.0]))
    tests = {(t.effect, t.kind): t for t in pooled_tests({"a": {"x": a}, "b": {"x": b}}, alpha=0.01)}
    common, summed = tests[("x", "common")], tests[("x", "sum")]
    assert common.statistic == pytest.approx(36.0 / 8.0) and common.dof == 2      # U = (6, 0), I = diag(8, 2)
    assert summed.statistic == pytest.approx(4.5) and summed.dof == 2
    assert common.n_tests == 2 and common.threshold == pytest.approx(stats.chi2.isf(0.01 / 2, 2))
    # opposite scores cancel in the common test, not in the sum
    b2 = FinalTest(9.0 / 4.0, 1, u=np.array([-3.0, 0.0]), S=S, scale=np.array([10.0, 10.0]))
    t2 = {t.kind: t for t in pooled_tests({"a": {"x": a}, "b": {"x": b2}}, alpha=0.01)}
    assert t2["common"].statistic == pytest.approx(0.0, abs=1e-12) and t2["sum"].statistic == pytest.approx(4.5)
    # a direction the campaign does not determine better than its prior does not count
    weak = FinalTest(1.0, 1, u=np.array([1.0, 1e-3]), S=np.diag([1.0, 1e-3]), scale=np.array([10.0, 10.0]))
    t3 = {t.kind: t for t in pooled_tests({"a": {"x": weak}, "b": {"x": weak}}, alpha=0.01)}
    assert t3["common"].dof == 1 and t3["common"].statistic == pytest.approx(2.0)
    # one experiment: no common test
    assert [t.kind for t in pooled_tests({"a": {"x": a}}, alpha=0.01)] == ["sum"]


@pytest.mark.montecarlo
def test_false_adoption_rate_under_the_null_is_at_most_alpha():
    """Six experiments, 14 candidates of 1-6 dimensions each, every score drawn under the null (``u ~ N(0, S)``
    with an experiment's own information ``S``): the pooled decision (sum and common tests, Bonferroni over
    both) adopts something in at most alpha of 2,000 simulated campaigns."""
    rng = np.random.default_rng(20261202)
    dims = rng.integers(1, 7, size=14)
    n, hits = 2_000, 0
    info = [[None] * 14 for _ in range(6)]
    for e in range(6):
        for c, d in enumerate(dims):
            B = rng.normal(size=(d, d))
            info[e][c] = 50.0 * (B @ B.T + d * np.eye(d))      # well determined against a prior sigma of 1
    chol = [[np.linalg.cholesky(S) for S in row] for row in info]
    for k in range(n):
        st = {}
        for e in range(6):
            st[f"e{e}"] = {}
            for c, d in enumerate(dims):
                S = info[e][c]
                u = chol[e][c] @ rng.normal(size=d)
                st[f"e{e}"][f"c{c}"] = FinalTest(float(u @ np.linalg.solve(S, u)), int(d), u=u, S=S,
                                                 scale=np.ones(d))
        hits += adoption(pooled_tests(st, alpha=0.01)) is not None
    rate = hits / n
    assert rate <= 0.01 + 3 * np.sqrt(0.01 * 0.99 / n), rate
    assert rate > 0.001, rate          # and the test is not vacuous: near its level


class _C:
    def __init__(self, name, statistic, dof, threshold, log10_p, score=(), information=(), scale=()):
        self.name, self.statistic, self.dof, self.threshold, self.log10_p = name, statistic, dof, threshold, log10_p
        self.score, self.information, self.scale = score, information, scale


def test_final_round_statistics_are_kept_in_the_loop_record():
    """``loop_record`` keeps the last round's candidate statistics; ``final_statistics`` reads them back."""

    class R:
        def __init__(self, index, candidates, added=None):
            self.index, self.candidates, self.added, self.decision = index, candidates, added, "d"

    class D:
        rounds = [R(1, [_C("x", 50.0, 3, 17.0, -9.0), _C("y", 2.0, 2, 15.0, -0.3)], added="x"),
                  R(2, [_C("y", 3.0, 2, 14.0, -0.6, (0.5, -1.0), (1.0, 0.0, 0.0, 2.0), (1.0, 1.0)),
                        _C("z", 0.0, 0, float("nan"), 0.0)])]
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
                                                   "log10_p": 0.0, "score": [], "information": [], "scale": []}
    y = final_statistics(rec)["y"]
    assert list(final_statistics(rec)) == ["y"] and (y.statistic, y.dof) == (3.0, 2)
    assert np.array_equal(y.u, [0.5, -1.0]) and np.array_equal(y.S, [[1.0, 0.0], [0.0, 2.0]])
