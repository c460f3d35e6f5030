"""The joint solver's reduced linear system (graph_calib/solvers/reduced.py) against GTSAM's own.

The reference is the whole joint graph as GTSAM would hold it: every keyframe attitude a ``Rot3`` variable,
the model's rotation, gravity and encoder factors as ``CustomFactor`` callbacks with their parameter
Jacobians chained onto the unknowns, the attitude and unknowns' priors GTSAM's own factors.  At a point off
the solution (random unknowns, attitudes dead-reckoned and then disturbed), the reduced system must give
GTSAM's cost, GTSAM's damped Levenberg-Marquardt step (unknowns and every attitude) and the unknowns'
marginal covariance over every attitude, with and without a robust loss.
"""

from functools import partial

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import S, X, Z

from graph_calib.solvers.factor_graph import _damped, _noise
from graph_calib.solvers.joint.marginal import unknowns_covariance
from graph_calib.solvers.reduced import ExperimentSystem
from graph_calib.solvers.joint.solver import _Experiment, _extend, _priors, _reduced_graph
from graph_calib.solvers.joint.unknowns import MAX_DEGREE, plan_unknowns
from graph_calib.options import CalibrationOptions, GraphOptions
from graph_calib.records.problem import build_problem
from graph_calib.navigation.rotations import exp_so3, quat_to_dcm
from graph_calib.simulation import simulate

STRIDE = 10**6


class _Reference:
    """One experiment's factors for GTSAM's callbacks, evaluated once per call into GTSAM."""

    def __init__(self, c):
        self.c, self.R = c, None

    def ensure(self, values):
        if self.R is None:
            K = self.c.model.n_keyframes
            self.R = np.array([values.atRot3(X(self.c.e * STRIDE + k)).matrix() for k in range(K + 1)])
            x = self.c.x_of(values)
            m, p = self.c.model, self.c.preint
            self.rot = m.rotation_factors(self.R, p, x)
            self.grav = m.gravity_factors(self.R, p, x)
            self.enc = m.encoder_factors(self.R, p, x)


def _blocks(ref, Hx, H, first):
    nz = ref.c.nz
    H[first] = Hx @ ref.c.M_u[:, :nz]
    if ref.c.has_setup:
        H[first + 1] = Hx @ ref.c.M_u[:, nz:]


def _rot(ref, i, this, values, H):
    ref.ensure(values)
    f = ref.rot
    if H is not None:
        H[0], H[1] = f.H_R[i], f.H_R_next[i]
        _blocks(ref, f.H_x[i], H, 2)
    return f.r[i]


def _grav(ref, k, this, values, H):
    ref.ensure(values)
    f = ref.grav
    if H is not None:
        H[0] = f.H_R[k]
        _blocks(ref, f.H_x[k], H, 1)
    return f.r[k]


def _enc(ref, lo, hi, this, values, H):
    ref.ensure(values)
    f = ref.enc
    if H is not None:
        H[0] = f.H_R[lo:hi].reshape(-1, 3)
        _blocks(ref, f.H_x[lo:hi].reshape(-1, f.H_x.shape[2]), H, 1)
    return f.r[lo:hi].reshape(-1)


def _full_graph(exps, values, options):
    graph, refs = gtsam.NonlinearFactorGraph(), []
    for c in exps:
        ref = _Reference(c)
        refs.append(ref)
        ref.ensure(values)
        xk = [X(c.e * STRIDE + k) for k in range(c.model.n_keyframes + 1)]
        theta = [Z(0)] + ([S(c.e)] if c.has_setup else [])
        graph.add(gtsam.PriorFactorRot3(xk[0], gtsam.Rot3(c.R_prior),
                                        gtsam.noiseModel.Isotropic.Sigma(3, c.model.initial_attitude_sigma)))
        for i, k in enumerate(ref.rot.key):
            graph.add(gtsam.CustomFactor(gtsam.noiseModel.Diagonal.Sigmas(ref.rot.sigma[i]), [xk[k], xk[k + 1]] + theta,
                                         partial(_rot, ref, i)))
        for k in range(c.model.n_keyframes):
            graph.add(gtsam.CustomFactor(_noise(ref.grav.sigma[k], options.robust, options.robust_k), [xk[k]] + theta,
                                         partial(_grav, ref, k)))
        keys = ref.enc.key
        bounds = np.flatnonzero(np.diff(keys)) + 1
        for lo, hi in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [keys.size]])):
            graph.add(gtsam.CustomFactor(_noise(ref.enc.sigma[lo:hi].reshape(-1), options.robust,
                                                options.robust_k * np.sqrt(hi - lo)),
                                         [xk[int(keys[lo])]] + theta, partial(_enc, ref, int(lo), int(hi))))
    return graph, refs


@pytest.fixture(scope="module")
def point():
    sim = simulate("nav-campaign", rng=np.random.default_rng(4), hours=0.02, curvature=True)
    problems = [build_problem(s.experiment, options=CalibrationOptions()) for s in sim.run()[:2]]
    ps = [_extend(p, dict(MAX_DEGREE)) for p in problems]
    models = [p.model for p in ps]
    u = plan_unknowns([m.layout for m in models], [m.t_ref_degC for m in models])
    z_sigma, s_sigmas = _priors(u, models)
    rng = np.random.default_rng(9)
    values, prior_graph, exps = gtsam.Values(), gtsam.NonlinearFactorGraph(), []
    uz = 0.3 * rng.normal(size=u.nz)
    values.insert(Z(0), uz)
    prior_graph.add(gtsam.PriorFactorVector(Z(0), np.zeros(u.nz), gtsam.noiseModel.Unit.Create(u.nz)))
    for e, (p, m) in enumerate(zip(ps, models)):
        A, B = u.experiment_map(e, m.layout, m.t_ref_degC)
        us = 0.3 * rng.normal(size=B.shape[1])
        values.insert(S(e), us)
        prior_graph.add(gtsam.PriorFactorVector(S(e), np.zeros(us.size), gtsam.noiseModel.Unit.Create(us.size)))
        M_u = np.hstack([A * z_sigma[None, :], B * s_sigmas[e][None, :]])
        x = M_u @ np.concatenate([uz, us])
        preint = m.preintegrate(x)
        R_prior = quat_to_dcm(p.q_nb0)
        R = m.propagate(R_prior, preint, x) @ exp_so3(1e-4 * rng.normal(size=(m.n_keyframes + 1, 3)))
        exps.append(_Experiment(e, m, preint, M_u, u.nz, R, R_prior))
    return exps, values, prior_graph


@pytest.mark.parametrize("robust", [None, "huber", "cauchy"])
def test_reduced_system_gives_gtsams_cost_step_and_covariance(point, robust):
    exps, values, prior_graph = point
    options = GraphOptions(robust=robust, robust_k=1.0)
    full = gtsam.Values(values)
    for c in exps:
        for k, Rk in enumerate(c.R):
            full.insert(X(c.e * STRIDE + k), gtsam.Rot3(Rk))
    graph, refs = _full_graph(exps, full, options)
    graph.push_back(prior_graph)
    systems = [c.linearise(values, c.R, options) for c in exps]
    if robust is not None:      # not a test that passes by accident: some factors are down-weighted
        w = np.concatenate([np.linalg.norm(s.whitened[1], axis=1) for s in systems])
        assert np.mean(w > options.robust_k) > 0.05
    for ref in refs:
        ref.R = None
    want_cost = graph.error(full)
    got_cost = prior_graph.error(values) + sum(s.cost for s in systems)
    assert got_cost == pytest.approx(want_cost, rel=1e-10)
    theta_keys = [S(c.e) for c in exps] + [Z(0)]
    theta_dims = [c.M_u.shape[1] - c.nz for c in exps] + [exps[0].nz]
    x_keys = [X(c.e * STRIDE + k) for c in exps for k in range(c.model.n_keyframes + 1)]
    lam = 1e-3
    for ref in refs:
        ref.R = None
    gfg_full = graph.linearize(full)
    want = _damped(gfg_full, x_keys + theta_keys, lam, [3] * len(x_keys) + theta_dims).optimize()
    gfg, Ys = _reduced_graph(exps, systems, prior_graph.linearize(values), lam)
    got = _damped(gfg, theta_keys, lam, theta_dims).optimize()
    # normal equations against GTSAM's elimination of the whole graph: agreement to rounding in a system
    # whose attitudes are held 1e8 times more tightly than the unknowns (a wrong row would differ at O(1))
    for k in theta_keys:
        np.testing.assert_allclose(got.at(k), want.at(k), rtol=1e-6, atol=1e-9 * np.abs(want.at(k)).max())
    for c, Y in zip(exps, Ys):
        dR = ExperimentSystem.attitude_step(Y, c.theta_of(got))
        dR_want = np.array([want.at(X(c.e * STRIDE + k)) for k in range(c.model.n_keyframes + 1)])
        np.testing.assert_allclose(dR, dR_want, rtol=1e-6, atol=1e-8 * np.abs(dR_want).max())
    tkeys = [Z(0)] + [S(c.e) for c in exps]
    want_cov = unknowns_covariance(gfg_full, x_keys, tkeys)
    gfg0, _ = _reduced_graph(exps, systems, prior_graph.linearize(values), 0.0)
    got_cov = unknowns_covariance(gfg0, [], tkeys)
    np.testing.assert_allclose(got_cov, want_cov, rtol=1e-6, atol=1e-8 * np.abs(want_cov).max())
