"""The joint campaign solver: one factor graph over every experiment of a campaign (layer 7).

- :mod:`graph_calib.solvers.joint.unknowns`: the curves and shared elements, the set-ups, each experiment's
  calibration vector as an exact affine map of them;
- :mod:`graph_calib.solvers.joint.solver`: the graph, its Levenberg-Marquardt loop, the degree chosen by evidence
  (``JointSolver``, registered as :data:`JOINT`);
- the loop, the reduced factor per experiment and the unknowns' covariance are the project's least-squares
  driver's (:mod:`graph_calib.solvers.least_squares`), the factor graph's too.
"""

from graph_calib.solvers.joint.degrees import DegreeEvidence, choose_degrees
from graph_calib.solvers.joint.solver import JOINT, JointOutput, JointSolver, WarmStart, solve_joint
from graph_calib.solvers.joint.unknowns import (
    MAX_DEGREE, SETUP_PARAMETERS, Unknowns, curve_label, curve_row, evaluate_curve, plan_unknowns,
)

__all__ = ["JOINT", "DegreeEvidence", "JointOutput", "JointSolver", "WarmStart", "choose_degrees", "solve_joint",
           "MAX_DEGREE", "SETUP_PARAMETERS", "Unknowns", "curve_label", "curve_row", "evaluate_curve",
           "plan_unknowns"]
