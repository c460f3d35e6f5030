"""The factor-graph calibrator on consistent turntable data (tests/_synthetic.py)."""

import numpy as np
import pytest

from graph_calib.calibrate import CalibrationOptions, build_problem
from graph_calib.options import GraphOptions
from graph_calib.solvers.registry import solve
from graph_calib.sensors.params import Layout, grade

from _synthetic import turntable_experiment

NAV = grade("navigation")
DECL = Layout.declared()
KINEMATIC = ("mount", "lever_arm", "time_lag.table")   # the generator's kinematics has none of these


def _truth(rng, scale=0.1):
    x = rng.normal(size=DECL.size) * NAV.prior_vector(DECL) * scale
    for n in KINEMATIC:
        x[DECL.slice(n)] = 0.0
    return x


def _normalised_errors(gr, x_true):
    xs = gr.layout.embed(DECL, x_true)
    sig = np.sqrt(np.diag(gr.covariance))
    return (gr.x - xs) / sig, sig


def test_noise_free_recovery_within_a_tenth_of_sigma():
    rng = np.random.default_rng(11)
    x_true = _truth(rng)
    exp, _ = turntable_experiment(layout=DECL, x=x_true)
    gr = solve("factor-graph", build_problem(exp), options=CalibrationOptions())
    z, sig = _normalised_errors(gr, x_true)
    worst = int(np.argmax(np.abs(z)))
    assert np.abs(z).max() < 0.1, (gr.layout.element_names()[worst], z[worst])
    # the gyro biases are really resolved, far below the prior
    assert np.all(sig[gr.layout.slice("gyro.bias")] < 0.01 * NAV.prior_sigma["gyro.bias"])


@pytest.mark.montecarlo
def test_monte_carlo_sigmas_are_consistent():
    """20 seeds: per parameter group RMS of (estimate - truth)/sigma in [0.7, 1.3]; 95 % within 3 sigma."""
    z_all = []
    informative = None
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        x_true = _truth(rng)
        exp, _ = turntable_experiment(layout=DECL, x=x_true, rng=rng, static_s=60.0, dwell_s=5.0,
                                      noise=(NAV.gyro_noise, NAV.accel_noise, NAV.encoder_noise))
        gr = solve("factor-graph", build_problem(exp), options=CalibrationOptions())
        z, sig = _normalised_errors(gr, x_true)
        z_all.append(z)
        prior = NAV.prior_vector(gr.layout)
        informative = sig < 0.5 * prior if informative is None else informative & (sig < 0.5 * prior)
    z_all = np.array(z_all)
    layout = gr.layout
    assert np.mean(np.abs(z_all[:, informative]) < 3.0) >= 0.95
    for name in layout.names:
        cols = np.arange(layout.size)[layout.slice(name)]
        cols = cols[informative[cols]]
        if cols.size == 0:
            continue
        rms = np.sqrt(np.mean(z_all[:, cols] ** 2))
        assert 0.7 <= rms <= 1.3, (name, rms)


def test_robust_loss_leaves_clean_data_alone():
    """With Huber on and no outliers, estimates and sigmas stay those of least squares.

    (GTSAM weighs a whole factor by its residual norm; an encoder factor stacks several
    readings, so its threshold grows with sqrt(readings): without that, every encoder factor
    was down-weighted at pure noise and the sigmas grew.)
    """
    from dataclasses import replace


    rng = np.random.default_rng(21)
    x_true = _truth(rng)
    exp, _ = turntable_experiment(layout=DECL, x=x_true, rng=rng, static_s=30.0, dwell_s=3.0,
                                  noise=(NAV.gyro_noise, NAV.accel_noise, NAV.encoder_noise))
    problem = build_problem(exp)
    plain = solve("factor-graph", problem, options=CalibrationOptions())
    opts = CalibrationOptions(graph=replace(GraphOptions(), robust="huber"))
    robust = solve("factor-graph", problem, options=opts)
    assert robust.converged and plain.converged
    sig = np.sqrt(np.diag(plain.covariance))
    ratio = np.sqrt(np.diag(robust.covariance)) / sig
    assert np.all((ratio > 0.95) & (ratio < 1.05)), ratio.max()
    assert np.abs((robust.x - plain.x) / sig).max() < 0.2


def test_first_attitude_prior_follows_what_the_alignment_could_use():
    """Table alignment: 0.05 rad; no valid reading in the first static interval (gyrocompass fallback) or
    no table: the gyrocompass accuracy (about 0.1 rad for a navigation-grade unit), pi for consumer MEMS."""
    from dataclasses import replace

    from graph_calib.model import CalibrationModel, ModelOptions, gyrocompass_attitude_sigma

    rng = np.random.default_rng(4)
    exp, _ = turntable_experiment(layout=DECL, x=_truth(rng), static_s=20.0, dwell_s=2.0)
    assert build_problem(exp).model.initial_attitude_sigma == CalibrationModel.TABLE_ALIGNMENT_SIGMA
    gc = gyrocompass_attitude_sigma(ModelOptions(), latitude_rad=exp.latitude_rad)
    assert 0.06 < gc < 0.2
    first_static = exp.table.t < exp.t[0] + 21.0          # the whole initial static period
    late_table = replace(exp.table, valid=exp.table.valid & ~first_static)
    problem = build_problem(replace(exp, table=late_table))
    assert problem.alignment.method == "gyrocompass"
    assert problem.model.initial_attitude_sigma == pytest.approx(gc)
    no_table = replace(exp, table=None)
    assert build_problem(no_table).model.initial_attitude_sigma == pytest.approx(gc)
    consumer = CalibrationOptions(model=ModelOptions(grade="consumer"))
    assert build_problem(no_table, options=consumer).model.initial_attitude_sigma == pytest.approx(np.pi)


def test_graph_priors_are_the_model_prior_residuals():
    """GTSAM's native prior factors (the oracle graph's, tests/solvers/_gtsam_oracle.py) whiten exactly as the
    model's prior residuals do, which the least-squares core adds as they are."""
    from gtsam.symbol_shorthand import C

    from graph_calib.navigation.rotations import exp_so3
    from graph_calib.solvers.least_squares import Experiment
    from _gtsam_oracle import oracle_graph

    rng = np.random.default_rng(21)
    exp, _ = turntable_experiment(layout=DECL, x=_truth(rng))
    model = build_problem(exp).model
    x_prior, x_sigma = model.prior()
    x = x_prior + x_sigma * rng.normal(size=x_sigma.size)
    preint = model.preintegrate(x)
    R_prior = exp_so3(np.array([0.2, -0.1, 0.4]))
    R = model.propagate(R_prior @ exp_so3(np.array([0.05, 0.3, -0.2])), preint, x)
    c = Experiment(model=model, R=R, R_prior=R_prior[None], preint=preint, keys=[C(0)])
    graph, values, _ = oracle_graph([c], theta_keys=[(C(0), x.size)], theta=x, prior_mean=x_prior, prior_sigma=x_sigma)
    graph = _Priors(graph)
    att, cal = model.attitude_prior(R[0], R_prior=R_prior), model.calibration_prior(x)
    assert graph.at(0).error(values) == pytest.approx(att.cost, rel=1e-12)
    assert graph.at(1).error(values) == pytest.approx(cal.cost, rel=1e-12)
    assert att.cost > 1.0 and cal.cost > 1.0
    lin = graph.at(0).linearize(values)
    A, b = lin.jacobian()
    np.testing.assert_allclose(A, att.H, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b, -att.r, rtol=1e-9, atol=1e-12)
    A, b = graph.at(1).linearize(values).jacobian()
    np.testing.assert_allclose(A, cal.H, rtol=1e-12)
    np.testing.assert_allclose(b, -cal.r, rtol=1e-12)


class _Priors:
    """The oracle graph's two prior factors: ``at(0)`` the first attitude's, ``at(1)`` the calibration's."""

    def __init__(self, graph):
        self.att, self.cal = graph.at(1), graph.at(0)

    def at(self, i):
        return (self.att, self.cal)[i]
