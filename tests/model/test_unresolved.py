"""A heading drift that looks like a g-sensitivity: the direction, the covariance without it, end to end.

- the direction (:func:`graph_calib.model.unresolved.heading_drift_direction`) is what the sensor model
  says: the gyros' readings of a rate ``kappa f_b`` more, with ``G`` moved along it by the right
  amount, are the same readings (the forward model, ``sensor_model.measure``, at a consumer-sized
  calibration);
- :func:`~graph_calib.model.unresolved.without_data_along` is the marginal covariance of a linear
  problem with a free nuisance parameter along the direction (built explicitly);
- only a record without a heading reference whose gyros cannot gyrocompass lists the direction;
- end to end (issue #13): ``consumer-ferraris`` with ``gyro.g_sensitivity`` estimated, seed 4, the
  filter: every element within 3 sigma of the truth (``G`` was 8.0 sigma off with the linearised
  covariance), the isotropic part of ``G`` keeps its prior sigma, and the result file names the
  direction (``unresolved``, round trip).
"""

import numpy as np
import pytest

from graph_calib.calibrate import CalibrationOptions, build_problem
from graph_calib.io.result_file import read_result, write_result
from graph_calib.model import ModelOptions
from graph_calib.model.unresolved import heading_drift_direction, without_data_along
from graph_calib.sensors.params import Layout
from graph_calib.sensors.sensor_model import measure
from graph_calib.simulation import simulate
from graph_calib.solvers.registry import solve
from graph_calib.solvers.results import to_result

EFFECT = "gyro.g_sensitivity"


def test_a_heading_drift_is_the_direction_to_the_gyros():
    rng = np.random.default_rng(5)
    layout = Layout.declared(extra=(EFFECT,))
    x = layout.zeros()
    x[layout.slice("gyro.scale")] = rng.uniform(-0.03, 0.03, 3)
    x[layout.slice("gyro.misalignment")] = rng.uniform(-0.03, 0.03, 6)
    x[layout.slice("gyro.bias")] = rng.uniform(-0.01, 0.01, 3)
    x[layout.slice(EFFECT)] = rng.uniform(-1e-3, 1e-3, 9)
    omega = rng.normal(0.0, 1.0, (50, 3))
    f = rng.normal(0.0, 1.0, (50, 3))
    f *= 9.81 / np.linalg.norm(f, axis=1)[:, None]          # gravity, in any body direction
    kappa = 2e-3                                             # the drift: kappa * g about the vertical
    u = heading_drift_direction(layout, x)
    norm = np.linalg.norm(np.eye(3) + np.diag(layout.get(x, "gyro.scale")) + np.array(
        [[0.0, *layout.get(x, "gyro.misalignment")[:2]],
         [layout.get(x, "gyro.misalignment")[2], 0.0, layout.get(x, "gyro.misalignment")[3]],
         [*layout.get(x, "gyro.misalignment")[4:], 0.0]]))
    m0 = measure(layout, x, "gyro", omega, other=f)
    m1 = measure(layout, x - kappa * norm * u, "gyro", omega + kappa * f, other=f)
    np.testing.assert_allclose(m1, m0, rtol=0, atol=1e-15)
    assert np.max(np.abs(kappa * f)) > 1e-3                  # not vacuous: the rate itself moved
    assert np.all(u[layout.slice(EFFECT)] != 0) and not np.any(np.delete(u, np.arange(layout.size)[
        layout.slice(EFFECT)]))


def test_without_data_along_is_the_marginal_with_a_free_nuisance():
    rng = np.random.default_rng(11)
    P, m = 6, 40
    H = rng.normal(size=(m, P))
    prior_sigma = rng.uniform(0.5, 2.0, P)
    u = rng.normal(size=P)
    u /= np.linalg.norm(u)
    cov = np.linalg.inv(H.T @ H + np.diag(prior_sigma ** -2.0))
    got = without_data_along(cov, prior_sigma, u[None, :])
    # the same data with a free parameter t moving x along u: columns [H, H u], t without a prior
    Ha = np.hstack([H, (H @ u)[:, None]])
    La = Ha.T @ Ha
    La[:P, :P] += np.diag(prior_sigma ** -2.0)
    want = np.linalg.inv(La)[:P, :P]
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    assert np.all(np.diag(got) >= np.diag(cov) * (1 - 1e-12))
    assert u @ got @ u > 10 * (u @ cov @ u)                  # the direction lost its data
    np.testing.assert_allclose(u @ np.linalg.inv(got) @ u, u @ np.diag(prior_sigma ** -2.0) @ u, rtol=1e-9)


@pytest.fixture(scope="module")
def ferraris4():
    se = simulate("consumer-ferraris", rng=np.random.default_rng(4), effects=(EFFECT,)).run()[0]
    return se


def _problem(se, grade):
    opts = CalibrationOptions(model=ModelOptions(grade=grade, extra_effects=(EFFECT,)),
                              t_ref_degC=se.truth.t_ref_degC)
    return build_problem(se.experiment, options=opts), opts


def test_only_a_record_without_heading_reference_lists_the_drift(ferraris4):
    problem, _ = _problem(ferraris4, "consumer")
    x = problem.model.layout.zeros()
    names, U = problem.model.unresolved_directions(x)
    assert names == ("heading drift",) and U.shape == (1, problem.model.layout.size)
    nav, _ = _problem(ferraris4, "navigation")              # gyros that gyrocompass: the Earth rate resolves it
    assert nav.model.unresolved_directions(nav.model.layout.zeros())[1].shape[0] == 0
    cov = np.eye(nav.model.layout.size)
    assert nav.model.resolved_covariance(nav.model.layout.zeros(), cov) is cov
    no_g = problem.model.with_effects(())
    assert no_g.unresolved_directions(no_g.layout.zeros())[1].shape[0] == 0


@pytest.mark.slow
def test_ferraris_session_with_g_sensitivity_is_within_3_sigma(ferraris4, tmp_path):
    se = ferraris4
    problem, opts = _problem(se, "consumer")
    out = solve("sqrt-kf", problem, options=opts)
    layout = problem.model.layout
    names = layout.element_names()
    truth = np.array([se.truth.values[n] for n in names])
    sigma = np.sqrt(np.diag(out.covariance))
    z = (out.x - truth) / sigma
    assert out.converged
    assert np.all(np.abs(z) < 3.0), (names[int(np.argmax(np.abs(z)))], float(np.abs(z).max()))
    # the isotropic part of G keeps its prior: the record does not resolve it
    _, U = problem.model.unresolved_directions(out.x)
    prior = problem.model.prior()[1]
    np.testing.assert_allclose(U[0] @ np.linalg.inv(out.covariance) @ U[0], U[0] @ (U[0] / prior**2), rtol=1e-6)
    # the rest of G is still measured: the off-diagonal elements far below their prior
    g = np.arange(layout.size)[layout.slice(EFFECT)]
    off = g[[1, 2, 3, 5, 6, 7]]
    assert np.all(sigma[off] < 0.05 * prior[off])
    # the result file says so
    res = to_result(problem.model, out)
    direction = res.extra["unresolved"]["heading drift"]
    assert set(direction) == set(layout.element_names()[i] for i in g)
    np.testing.assert_allclose([direction[names[i]] for i in g], U[0][g])
    write_result(res, tmp_path / "fg.json")
    assert read_result(tmp_path / "fg.json").extra["unresolved"] == res.extra["unresolved"]
