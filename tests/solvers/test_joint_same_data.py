"""The joint solver and the per-subrange factor graph on the same data give the same calibration.

Issue #11 asks the joint curve at each ``T_ref`` to lie within 0.5 sigma of the per-subrange graph's
estimate "since they see the same data". Over a whole campaign they do not see the same data (the joint
curve at one subrange's ``T_ref`` also uses the other subranges, so it differs from that subrange's own
estimate by about that subrange's noise: tests/solvers/test_joint.py and docs/campaign.md). Handed exactly the data
the subrange graph sees, one experiment, the joint model (a degree-1 polynomial per element in its own
sensor's temperature, set-ups per experiment) is the per-subrange model re-parametrised, and the two must
agree far inside 0.5 sigma for every element, with the same sigmas.
"""

import numpy as np
import pytest

from graph_calib.solvers.joint import solve_joint
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
    out = solve_joint([problem], options=OPTS.graph)
    assert out.converged and graph.converged
    assert all(c.degree == 1 for c in out.degree_choices), [c.to_json() for c in out.degree_choices]
    joint = out.outputs[0]
    at = {n: i for i, n in enumerate(joint.layout.element_names())}
    names = graph.layout.element_names()
    assert set(names) <= set(at), sorted(set(names) - set(at))
    idx = np.array([at[n] for n in names])
    z = (joint.x[idx] - graph.x) / graph.sigma
    worst = int(np.argmax(np.abs(z)))
    # measured: at most 4e-4 sigma (the two solvers' stopping rules); 0.5 sigma is the issue's bound
    assert np.abs(z).max() < 0.05, (names[worst], z[worst])
    np.testing.assert_allclose(joint.sigma[idx], graph.sigma, rtol=1e-2)
