"""Anderson mixing of the solvers' Gauss-Newton steps (graph_calib.solvers.acceleration, issue #13).

- on a linear iteration with a slow mode (0.97) and an alternating one (-0.9) the mixing reaches the
  fixed point in a few steps where the plain iteration is still far;
- with one step held the mixing is the plain step;
- on the measured Xsens session (slow) both solvers, mixed, converge in at most 40 iterations (83 and 82
  unmixed, docs/performance.md) to the same point: the plain Gauss-Newton step at each one's end is
  below the stopping rule, and the two agree to a hundredth of a sigma.
"""

import numpy as np
import pytest

from graph_calib.calibrate import build_problem
from graph_calib.records.grade_choice import choose_grade
from graph_calib.importers import import_xsens
from graph_calib.options import CalibrationOptions, ModelOptions
from graph_calib.solvers import solve
from graph_calib.solvers.acceleration import Anderson

from _shared import REAL_DATA, require_real

XSENS = REAL_DATA / "imu_tk_xsens"


def _slow_linear_map(rng, n=12):
    """``u -> M u + b`` with eigenvalues 0.97, -0.9 and smaller ones in a random basis; its fixed point."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    ev = np.concatenate([[0.97, -0.9], rng.uniform(-0.5, 0.5, n - 2)])
    M = Q @ np.diag(ev) @ Q.T
    b = rng.standard_normal(n)
    return M, b, np.linalg.solve(np.eye(n) - M, b)


def test_mixing_reaches_the_fixed_point_of_a_slow_linear_iteration():
    rng = np.random.default_rng(7)
    M, b, u_star = _slow_linear_map(rng)
    u_plain = u_mixed = np.zeros_like(b)
    acc = Anderson(memory=12)
    for _ in range(16):
        u_plain = M @ u_plain + b
        u_mixed = acc.next(u_mixed, M @ u_mixed + b - u_mixed)
    assert np.linalg.norm(u_plain - u_star) > 0.3 * np.linalg.norm(u_star)
    assert np.linalg.norm(u_mixed - u_star) < 1e-8 * np.linalg.norm(u_star)


def test_first_step_is_plain_and_reset_forgets():
    acc = Anderson()
    u, f = np.array([1.0, 2.0]), np.array([0.5, -1.0])
    assert np.array_equal(acc.next(u, f), u + f) and acc.depth == 1
    acc.next(u + f, -0.5 * f)
    assert acc.depth == 2
    acc.reset()
    assert acc.depth == 0 and np.array_equal(acc.next(u, f), u + f)


@pytest.mark.measured
def test_xsens_session_both_solvers_mixed_converge_fast_to_one_point():
    exp = import_xsens(require_real(XSENS / "xsens_acc.mat"), require_real(XSENS / "xsens_gyro.mat"))
    opts = CalibrationOptions(model=ModelOptions(grade=choose_grade(exp).grade))
    problem = build_problem(exp, options=opts)
    kf = solve("sqrt-kf", problem, options=opts)
    fg = solve("factor-graph", problem, options=opts)
    assert kf.converged and fg.converged
    assert kf.iterations <= 40 and fg.iterations <= 40, (kf.iterations, fg.iterations)
    sigma = np.sqrt(np.diag(kf.covariance))
    held = sigma > 0
    z = np.abs(kf.x - fg.x)[held] / sigma[held]
    assert z.max() < 0.01, z.max()
