r"""The reference square-root Kalman filter of graph-calib.

An iterated, linearised square-root filter over keyframes that consumes the
shared model's factors (:mod:`graph_calib.model`) and must agree with the factor
graph (:mod:`graph_calib.solvers.factor_graph`) on every parameter.  It imports only the
shared model and the solver interface (:mod:`graph_calib.solvers.interface`), and is
registered as the solver :data:`kf_reference.passes.SOLVER_NAME` (:class:`kf_reference.solver.SqrtKalmanSolver`).
See ``docs/kf_reference.md``.

>>> from graph_calib.solvers import solve                           # doctest: +SKIP
>>> output = solve(SOLVER_NAME, problem, options=CalibrationOptions())  # doctest: +SKIP
>>> from kf_reference import calibrate                                # doctest: +SKIP
>>> fr = calibrate(problem.model, q_nb0=problem.q_nb0)                # the native FilterResult  # doctest: +SKIP
"""

from kf_reference.passes import (  # noqa: F401  (public)
    ENCODER,
    GRAVITY,
    KIND_NAMES,
    FilterResult,
    PassInfo,
    calibrate,
    filter_pass,
    initial_attitudes,
)
from kf_reference.solver import SqrtKalmanSolver, output_of  # noqa: F401  (public)

__all__ = ["calibrate", "filter_pass", "initial_attitudes", "FilterResult", "PassInfo", "GRAVITY", "ENCODER",
           "KIND_NAMES", "SqrtKalmanSolver", "output_of"]
