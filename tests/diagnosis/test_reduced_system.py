"""The linearised system of the closed loop (graph_calib.diagnosis.reduced_system) against explicit algebra.

``linearise`` forms the driver columns from each factor's driver means and eliminates the attitudes
with a banded Cholesky factor; these tests rebuild the same system the long way (the whitened Jacobian
written out densely, drivers as explicit columns, the Schur complement by a dense solve) on a 3-minute
record, and check the Gauss-Newton step it gives against the factor graph's own first step.
"""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.diagnosis import linearise
from graph_calib.diagnosis.drivers import (
    DriverSums,
    cumulative_sums,
    driver_series,
    interval_means,
    keyframe_context,
)
from graph_calib.model.attitude_elimination import eliminate
from graph_calib.model.residual_list import residual_list
from graph_calib.simulation import simulate

EFFECT = "accel.bias_tc2"
SIMULATED = "accel.nonlinearity"


@pytest.fixture(scope="module")
def solved():
    """A 3-minute record with a further effect, the declared graph solution and the model extended by it."""
    from graph_calib.solvers import factor_graph
    from graph_calib.calibrate import CalibrationOptions, build_problem
    from graph_calib.options import GraphOptions

    se = simulate("effect-accel.nonlinearity", rng=np.random.default_rng(4), hours=0.05, effect_scale=0.3).run()[0]
    o = CalibrationOptions()
    p = build_problem(se.experiment, options=o)
    gr = factor_graph.solve(p.model, q_nb0=p.q_nb0,
                            options=GraphOptions(max_iterations=50, rel_tol=1e-14, step_tol_sigma=1e-9))
    ext = p.model.with_effects(("accel.nonlinearity", EFFECT, "gyro.bias_tc2"))
    x_ext = ext.layout.embed(gr.layout, gr.x)
    return p, gr, ext, x_ext


def _dense_system(model, R, x, *, q_nb0, null_names, sums):
    """``(A, b)`` of :func:`linearise` the long way: a dense whitened Jacobian with explicit driver columns."""
    P = model.layout.size
    K = model.n_keyframes
    na = 3 * (K + 1)
    drivers = sums.drivers
    col = {ax: model.layout.slice(f"{ax.split('.')[0]}.bias").start + "xyz".index(ax[-1]) for ax in
           {d.axis for d in drivers}}
    Q = P + len(drivers)
    pre = model.preintegrate(x)
    k0 = model.record.k0
    rows = []
    factors = residual_list(model, R, pre, x)      # the readings and rotation factors decorrelated, as solved
    for kind in ("rotation", "gravity", "encoder"):
        res = factors[kind]
        s = 1.0 / res.sigma[:, :, None]
        r, HR, Hx = res.whitened(), res.H_R * s, res.H_x * s
        HRn = None if res.H_R_next is None else res.H_R_next * s
        hi = model.record.reading_sample + 1 if kind == "encoder" else k0[res.key + 1]
        M = interval_means(cumulative_sums(driver_series(model)[0]), k0[res.key], hi)
        for f in range(r.shape[0]):
            J = np.zeros((3, na + Q))
            k = res.key[f]
            J[:, 3 * k:3 * k + 3] = HR[f]
            if HRn is not None:
                J[:, 3 * k + 3:3 * k + 6] = HRn[f]
            J[:, na:na + P] = Hx[f]
            for i, d in enumerate(drivers):
                J[:, na + P + i] = Hx[f][:, col[d.axis]] * M[f, d.series]
            rows.append((J, r[f]))
    J = np.vstack([j for j, _ in rows])
    r = np.concatenate([v for _, v in rows])
    H = J.T @ J
    g = J.T @ r
    prior = model.calibration_prior(x)
    null = np.concatenate([np.arange(P)[model.layout.slice(n)] for n in null_names])
    h = np.diag(prior.H)
    H[na + null, na + null] += h[null] ** 2
    g[na + null] += h[null] * prior.r[null]
    for k, ap in model.attitude_priors(R, R_priors=model.segment_priors(q_nb0)):
        H[3 * k:3 * k + 3, 3 * k:3 * k + 3] += ap.H.T @ ap.H
        g[3 * k:3 * k + 3] += ap.H.T @ ap.r
    Haa, Hax = H[:na, :na], H[:na, na:]
    A = H[na:, na:] - Hax.T @ np.linalg.solve(Haa, Hax)
    b = g[na:] - Hax.T @ np.linalg.solve(Haa, g[:na])
    return A, b


@pytest.mark.slow
def test_linearise_equals_the_dense_system_with_explicit_driver_columns(solved):
    p, gr, ext, x_ext = solved
    sums = DriverSums.of(ext)
    rs, dl = linearise(ext, gr.attitudes, x_ext, q_nb0=p.q_nb0, null_names=gr.layout.names, sums=sums)
    A, b = _dense_system(ext, gr.attitudes, x_ext, q_nb0=p.q_nb0, null_names=gr.layout.names, sums=sums)
    assert rs.A.shape == A.shape == (ext.layout.size + len(dl),) * 2
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))       # each column in units of its own information
    assert np.max(np.abs(rs.A - A) / np.outer(d, d)) < 1e-9
    assert np.max(np.abs(rs.b - b) / d) < 1e-9
    # the same system whether the sums are given or formed inside
    rs2, _ = linearise(ext, gr.attitudes, x_ext, q_nb0=p.q_nb0, null_names=gr.layout.names)
    assert np.array_equal(rs2.A, rs.A) and np.array_equal(rs2.b, rs.b)


def test_driver_sums_give_the_cumulative_sum_means_and_refuse_other_intervals(solved):
    _, _, ext, _ = solved
    sums = DriverSums.of(ext)
    Phi, drivers = driver_series(ext)
    assert [d.label for d in drivers] == [d.label for d in sums.drivers]
    k0 = ext.record.k0
    key = ext.record.reading_key
    lo, hi = k0[key], ext.record.reading_sample + 1
    ref = interval_means(cumulative_sums(Phi), lo, hi)
    assert np.max(np.abs(sums.means(lo, hi) - ref)) <= 1e-12 * np.max(np.abs(Phi))
    assert np.allclose(sums.means(k0[:-1], k0[1:]), interval_means(cumulative_sums(Phi), k0[:-1], k0[1:]),
                       rtol=0, atol=1e-12 * np.max(np.abs(Phi)))
    with pytest.raises(ValueError, match="boundary of the driver sums"):
        sums.means(k0[:1] + 1, k0[1:2])
    # the keyframe means of the residual regressions: one sum per keyframe, as the cumulative sums give
    ctx = keyframe_context(ext)
    f = ext.record.f_raw
    ref = interval_means(cumulative_sums(f**2), k0[:-1], k0[1:])
    assert ctx["specific_force_sq"].shape == (ext.n_keyframes, 3)
    assert np.max(np.abs(ctx["specific_force_sq"] - ref)) <= 1e-12 * np.max(f**2)
    assert np.allclose(ctx["time"], interval_means(cumulative_sums(ext.experiment.t - ext.experiment.t[0]),
                                                   k0[:-1], k0[1:])[:, 0], rtol=1e-12, atol=0)


def test_elimination_falls_back_to_the_sparse_lu_when_not_positive_definite():
    rng = np.random.default_rng(0)
    K, Q = 6, 4
    na = 3 * (K + 1)
    Hdiag = np.array([np.diag([2.0, 3.0, -1.0 if k == 3 else 4.0]) for k in range(K + 1)])
    Hoff = 0.1 * rng.normal(size=(K, 3, 3))
    H = np.zeros((na, na))
    for k in range(K + 1):
        H[3 * k:3 * k + 3, 3 * k:3 * k + 3] = Hdiag[k]
    for k in range(K):
        H[3 * k:3 * k + 3, 3 * k + 3:3 * k + 6] = Hoff[k]
        H[3 * k + 3:3 * k + 6, 3 * k:3 * k + 3] = Hoff[k].T
    assert np.linalg.eigvalsh(H).min() < 0          # indefinite: the banded Cholesky fails
    Hax, ga = rng.normal(size=(na, Q)), rng.normal(size=na)
    Hxx, gx = 50.0 * np.eye(Q), rng.normal(size=Q)
    with pytest.raises(RuntimeError, match="not positive definite"):
        eliminate(Hdiag, Hoff, Hax, ga, Hxx, gx, definite=True)
    A, b, att = eliminate(Hdiag, Hoff, Hax, ga, Hxx, gx)
    assert att.chol is None
    assert np.allclose(A, Hxx - Hax.T @ np.linalg.solve(H, Hax), rtol=1e-12, atol=1e-12)
    assert np.allclose(b, gx - Hax.T @ np.linalg.solve(H, ga), rtol=1e-12, atol=1e-12)
    dx = rng.normal(size=Q)
    assert np.allclose(att.solve(dx), np.linalg.solve(H, ga + Hax @ dx), rtol=1e-12, atol=1e-12)
    # damped: lam on the attitudes only; the banded Cholesky then holds (H + 3 I is positive definite)
    lam = 3.0
    Hl = H + lam * np.eye(na)
    A, b, att = eliminate(Hdiag, Hoff, Hax, ga, Hxx, gx, lam=lam, definite=True)
    assert att.chol is not None
    assert np.allclose(A, Hxx - Hax.T @ np.linalg.solve(Hl, Hax), rtol=1e-12, atol=1e-12)
    assert np.allclose(b, gx - Hax.T @ np.linalg.solve(Hl, ga), rtol=1e-12, atol=1e-12)
    assert np.allclose(att.step(dx), -np.linalg.solve(Hl, ga + Hax @ dx).reshape(-1, 3), rtol=1e-12, atol=1e-12)


def test_gauss_newton_step_is_the_factor_graphs_first_step_of_the_grown_model(solved):
    """The step the loop starts the grown model's solve from is the graph's own first (undamped) step."""
    from graph_calib.solvers import factor_graph
    from graph_calib.calibrate import CalibrationOptions, build_problem
    from graph_calib.options import GraphOptions

    p, gr, ext, x_ext = solved
    rs, _ = linearise(ext, gr.attitudes, x_ext, q_nb0=p.q_nb0, null_names=gr.layout.names, keep_step=True)
    cols = np.concatenate([rs.null, np.arange(ext.layout.size)[ext.layout.slice(SIMULATED)]])
    dx, delta = rs.gauss_newton_step(cols)
    assert np.all(dx[np.setdiff1d(np.arange(ext.layout.size), cols)] == 0.0)
    # the grown model (the declared one with SIMULATED) and one graph iteration from the same point
    o = CalibrationOptions()
    o2 = replace(o, model=replace(o.model, extra_effects=(SIMULATED,)), t_ref_degC=p.model.t_ref_degC)
    p2 = build_problem(p.model.experiment, options=o2)
    L = p2.model.layout
    g1 = factor_graph.solve(p2.model, q_nb0=p.q_nb0, options=GraphOptions(max_iterations=1, lambda_initial=1e-12),
                            initial=(gr.attitudes, L.embed(gr.layout, gr.x)))
    step_graph = g1.x - L.embed(gr.layout, gr.x)
    step_loop = L.embed(ext.layout, dx)
    sigma = np.sqrt(np.diag(g1.covariance))
    assert np.max(np.abs(step_loop[L.slice(SIMULATED)]) / sigma[L.slice(SIMULATED)]) > 3.0     # a real step
    assert np.max(np.abs(step_loop - step_graph) / sigma) < 1e-3
    R_loop = gr.attitudes @ np.stack([_exp(d) for d in delta])
    err = [np.linalg.norm(_log(a.T @ b)) for a, b in zip(R_loop, g1.attitudes)]
    moved = [np.linalg.norm(d) for d in delta]
    assert max(err) < 1e-3 * max(moved) + 1e-12


def test_gauss_newton_step_needs_the_kept_elimination(solved):
    p, gr, ext, x_ext = solved
    rs, _ = linearise(ext, gr.attitudes, x_ext, q_nb0=p.q_nb0, null_names=gr.layout.names, drivers=False)
    with pytest.raises(ValueError, match="keep_step=True"):
        rs.gauss_newton_step(rs.null)


def _exp(v):
    from graph_calib.navigation.rotations import exp_so3
    return exp_so3(np.asarray(v)[None])[0]


def _log(R):
    from graph_calib.navigation.rotations import log_so3
    return log_so3(np.asarray(R)[None])[0]
