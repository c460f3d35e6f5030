"""The joint solver and the per-subrange factor graph on the same data give the same calibration.

Issue #11 asks the joint curve at each ``T_ref`` to lie within 0.5 sigma of the per-subrange graph's
estimate "since they see the same data". Over a whole campaign they do not see the same data (the joint
curve at one subrange's ``T_ref`` also uses the other subranges, so it differs from that subrange's own
estimate by about that subrange's noise: tests/solvers/test_joint.py and docs/campaign.md). Handed exactly the data
the subrange graph sees, one experiment, the joint model (a degree-1 polynomial per element in its own
sensor's temperature, set-ups per experiment) is the per-subrange model re-parametrised, and the two must
agree far inside 0.5 sigma for every element, with the same sigmas. With its default degree rule the joint
curve may also hold orders the data do not show (their priors bound them over a 3-minute record's span):
then the model is no longer the same, and the issue's 0.5 sigma is the bound.
"""

import numpy as np
import pytest

from graph_calib.solvers.joint import solve_joint
from graph_calib.solvers.joint.unknowns import MAX_DEGREE
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.simulation import simulate
from graph_calib.solvers.registry import solve

OPTS = CalibrationOptions()


@pytest.mark.parametrize("k", [0, 3])
def test_one_experiment_the_joint_curve_at_t_ref_is_the_subrange_graphs_estimate(k):
    sim = simulate("nav-campaign", rng=np.random.default_rng(11), hours=0.05, curvature=False)
    experiment = sim.run()[k].experiment
    problem = build_problem(experiment, options=OPTS)
    graph = solve("factor-graph", problem, options=OPTS)
    names = graph.layout.element_names()

    def z_of(out):
        joint = out.outputs[0]
        at = {n: i for i, n in enumerate(joint.layout.element_names())}
        assert set(names) <= set(at), sorted(set(names) - set(at))
        idx = np.array([at[n] for n in names])
        return (joint.x[idx] - graph.x) / graph.sigma, joint.sigma[idx]

    same = solve_joint([problem], options=OPTS.graph, degrees={f: 1 for f in MAX_DEGREE})
    assert same.converged and graph.converged and same.degree_choices == ()
    z, sigma = z_of(same)
    worst = int(np.argmax(np.abs(z)))
    # measured: at most 4e-4 sigma (the two solvers' stopping rules)
    assert np.abs(z).max() < 0.05, (names[worst], z[worst])
    np.testing.assert_allclose(sigma, graph.sigma, rtol=1e-2)
    # the default rule: the data show no curvature, and the curve at T_ref is within the 0.5 sigma
    chosen = solve_joint([problem], options=OPTS.graph)
    assert all(c.significant_degree == 1 for c in chosen.degree_choices), [c.to_json() for c in chosen.degree_choices]
    z, _ = z_of(chosen)
    assert np.abs(z).max() < 0.5, (names[int(np.argmax(np.abs(z)))], np.abs(z).max())
