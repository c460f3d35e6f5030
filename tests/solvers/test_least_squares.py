"""The least-squares core (graph_calib/solvers/least_squares.py) against GTSAM's own graph of the model.

The core evaluates its cost from the model's vectorised residual list, eliminates every experiment's
attitudes in numpy (graph_calib/model/normal_equations.py) and hands GTSAM one reduced factor per experiment.
The oracle is the whole nonlinear graph as GTSAM would hold it (tests/solvers/_gtsam_oracle.py, built from
the model's residual list): its error, its damped linearisation eliminated, its marginal covariance.  At a
point off the solution (the preintegration formed at another calibration so that its first-order
correction is in play), for the factor graph (one experiment, ``x = theta``: a turntable record, and a
hand-held record cut into segments) and the joint solver (two experiments, unknowns mapped through
``M_e``), with and without robust losses, cost, step and covariance must be GTSAM's to rounding.
"""

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import C, S, Z

from graph_calib.calibrate import build_problem
from graph_calib.model import ModelOptions
from graph_calib.model.normal_equations import cost, cost_by_key
from graph_calib.navigation.rotations import exp_so3
from graph_calib.options import CalibrationOptions, GraphOptions
from graph_calib.sensors.params import Layout, grade
from graph_calib.simulation import simulate
from graph_calib.solvers.joint.solver import _extend, _priors
from graph_calib.solvers.joint.unknowns import MAX_DEGREE, plan_unknowns
from graph_calib.solvers.least_squares import Experiment, LeastSquares

from _gtsam_oracle import attitude_key, damped, marginal, oracle_graph
from _synthetic import turntable_experiment

DECL = Layout.declared()


def _turntable():
    rng = np.random.default_rng(5)
    x = rng.normal(size=DECL.size) * grade("navigation").prior_vector(DECL) * 0.1
    for n in ("mount", "lever_arm", "time_lag.table"):
        x[DECL.slice(n)] = 0.0
    exp, _ = turntable_experiment(layout=DECL, x=x, rng=rng, static_s=30.0, dwell_s=3.0, noise=(1e-4, 1e-4, 1e-5))
    return [build_problem(exp)]


def _cut_handheld():
    """A cut hand-held record, its factors in level axes (``heading_axes=False``): in body axes
    (graph_calib.model.heading_axes) each segment's heading is held by the Earth rate alone also in Gauss-Newton's
    information, and GTSAM's undamped elimination of the whole graph, the oracle here, calls it indeterminate."""
    se = simulate("consumer-handheld", rng=np.random.default_rng(7), cut=True).run()[0]
    return [build_problem(se.experiment, options=CalibrationOptions(model=ModelOptions(grade="consumer",
                                                                                       heading_axes=False),
                                                                     t_ref_degC=se.truth.t_ref_degC))]


def _campaign():
    sim = simulate("nav-campaign", rng=np.random.default_rng(4), hours=0.02, curvature=True)
    return [build_problem(s.experiment, options=CalibrationOptions()) for s in sim.run()[:2]]


def _graph(problems, rng, *, exact=False, robust=None):
    """The core and its point: one experiment with ``theta = x`` (the factor graph), or several with the joint
    solver's unknowns in units of their priors; the calibration 0.3 prior sigma from the prior, the
    preintegration formed 1e-3 prior sigma away (``exact``: at it), the attitudes disturbed by 1e-4 rad."""
    options = GraphOptions(robust=robust, robust_k=1.0)
    if len(problems) == 1:
        m = problems[0].model
        mean, sigma = m.prior()
        theta_keys, maps = [(C(0), sigma.size)], [None]
        keys = [[C(0)]]
    else:
        ps = [_extend(p, dict(MAX_DEGREE)) for p in problems]
        models = [p.model for p in ps]
        u = plan_unknowns([m.layout for m in models], [m.t_ref_degC for m in models])
        z_sigma, s_sigmas = _priors(u, models)
        theta_keys, maps, keys = [(Z(0), u.nz)], [], []
        for e, m in enumerate(models):
            A, B = u.experiment_map(e, m.layout, m.t_ref_degC)
            theta_keys.append((S(e), B.shape[1]))
            maps.append(np.hstack([A * z_sigma[None, :], B * s_sigmas[e][None, :]]))
            keys.append([Z(0), S(e)])
        problems = ps
        n = sum(d for _, d in theta_keys)
        mean, sigma = np.zeros(n), np.ones(n)
    theta = mean + 0.3 * sigma * rng.normal(size=sigma.size)
    exps = []
    for p, M, k in zip(problems, maps, keys):
        m = p.model
        exps.append(Experiment(model=m, R=None, R_prior=m.segment_priors(p.q_nb0), preint=None, keys=k, M=M))
    lsq = LeastSquares(exps, theta_keys=theta_keys, prior_mean=mean, prior_sigma=sigma, options=options, solver="test")
    for c in exps:
        x = c.x_of(theta)
        x_pre = x if exact else x + 1e-3 * c.model.prior()[1] * rng.normal(size=x.size)
        c.preint = c.model.preintegrate(x_pre)
        c.R = c.model.propagate(c.R_prior, c.preint, x) @ exp_so3(1e-4 * rng.normal(size=(c.model.n_keyframes + 1, 3)))
    graph, values, evs = oracle_graph(exps, theta_keys=theta_keys, theta=theta, prior_mean=mean, prior_sigma=sigma,
                                      robust=robust, robust_k=options.robust_k)
    return lsq, theta, graph, values, evs


def _gtsam(call, evs):
    for ev in evs:
        ev.reset()
    return call()


CASES = {"turntable": _turntable, "cut-handheld": _cut_handheld, "joint": _campaign}


@pytest.fixture(scope="module", params=list(CASES))
def problems(request):
    return CASES[request.param]()


@pytest.mark.parametrize("robust", [None, "huber", "cauchy"])
def test_cost_and_damped_step_are_gtsams(problems, robust):
    if robust == "cauchy" and problems[0].model.record.reading_t.size == 0:
        return      # a hand-held record under Cauchy: GTSAM's own elimination of the whole graph is indeterminate
    lsq, theta, graph, values, evs = _graph(problems, np.random.default_rng(3), robust=robust)
    systems = [lsq.linearise(c, c.preint, c.R, theta) for c in lsq.exps]
    if robust is not None and any(c.model.record.reading_t.size for c in lsq.exps):
        # not a test that passes by accident: some factors are down-weighted
        w = np.concatenate([np.linalg.norm(s.whitened["gravity"], axis=1) for s in systems])
        assert np.mean(w > 1.0) > 0.05
    got_cost = lsq.prior(theta).cost + sum(s.cost for s in systems)
    assert got_cost == pytest.approx(_gtsam(lambda: graph.error(values), evs), rel=1e-10)
    for c, s in zip(lsq.exps, systems):
        assert cost(c.model, c.preint, c.R, c.x_of(theta), R_prior=c.R_prior, robust=robust, robust_k=1.0) == s.cost
    gfg = _gtsam(lambda: graph.linearize(values), evs)
    x_keys = [attitude_key(e, k) for e, c in enumerate(lsq.exps) for k in range(c.R.shape[0])]
    keys, dims = lsq.theta_keys, [lsq.slices[k].stop - lsq.slices[k].start for k in lsq.theta_keys]
    for lam in (1e-9, 1e-3, 10.0):
        want = damped(gfg, x_keys + keys, [3] * len(x_keys) + dims, lam).optimize()
        dRs, dtheta = lsq.step(theta, systems, lam)
        want_theta = np.concatenate([want.at(k) for k in keys])
        # in units of the prior sigmas and of the largest attitude change: agreement to rounding in a system
        # whose attitudes are held 1e8 times more tightly than the unknowns (a wrong row would differ at O(1))
        scale = lsq.prior_sigma
        np.testing.assert_allclose(dtheta / scale, want_theta / scale, rtol=0,
                                   atol=1e-7 * np.max(np.abs(want_theta / scale)))
        for e, dR in enumerate(dRs):
            dR_want = np.array([want.at(attitude_key(e, k)) for k in range(dR.shape[0])])
            np.testing.assert_allclose(dR, dR_want, rtol=0, atol=1e-7 * np.max(np.abs(dR_want)))


def test_covariance_is_gtsams_marginal_over_every_attitude(problems):
    lsq, theta, graph, values, evs = _graph(problems, np.random.default_rng(8), exact=True)
    gfg = _gtsam(lambda: graph.linearize(values), evs)
    x_keys = [attitude_key(e, k) for e, c in enumerate(lsq.exps) for k in range(c.R.shape[0])]
    want = marginal(gfg, x_keys, lsq.theta_keys)
    got, whitened = lsq.covariance(theta)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-8 * np.max(np.abs(want)))
    assert set(whitened[0]) == {"rotation", "gravity", "encoder"}


@pytest.mark.parametrize("robust", [None, "huber"])
def test_cost_by_keyframe_sums_to_the_cost(problems, robust):
    lsq, theta, *_ = _graph(problems[:1], np.random.default_rng(4))
    c = lsq.exps[0]
    m, x, R = c.model, c.x_of(theta), c.R
    by_key = cost_by_key(m, c.preint, R, x, R_prior=c.R_prior, robust=robust)
    assert by_key.shape == (m.n_keyframes + 1,)
    assert np.sum(by_key) == pytest.approx(cost(m, c.preint, R, x, R_prior=c.R_prior, robust=robust), rel=1e-12)
    # each segment's share depends on that segment's attitudes alone: turn the last segment only
    last = int(m.segment_keys[-1])
    turned = R.copy()
    turned[last:] = exp_so3(np.array([0.0, 0.0, 1.0])) @ R[last:]
    other = cost_by_key(m, c.preint, turned, x, R_prior=c.R_prior, robust=robust)
    if last > 0:
        np.testing.assert_array_equal(other[:last - 1], by_key[:last - 1])
    assert not np.allclose(other[last:], by_key[last:])
