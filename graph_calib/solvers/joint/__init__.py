"""The joint campaign solver: one factor graph over every experiment of a campaign (layer 7).

- :mod:`graph_calib.solvers.joint.unknowns`: the curves and shared elements, the set-ups, each experiment's
  calibration vector as an exact affine map of them;
- :mod:`graph_calib.solvers.joint.solver`: the graph, its Levenberg-Marquardt loop, the degree chosen by evidence
  (``JointSolver``, registered as :data:`JOINT`);
- :mod:`graph_calib.solvers.reduced` (shared with the factor graph): one experiment's factors linearised
  with its attitudes eliminated (the reduced factor GTSAM solves with the others);
- :mod:`graph_calib.solvers.joint.marginal`: the unknowns' covariance.
"""

from graph_calib.solvers.joint.solver import JOINT, DegreeChoice, JointOutput, JointSolver, WarmStart, choose_degrees, solve_joint
from graph_calib.solvers.joint.unknowns import (
    MAX_DEGREE, SETUP_PARAMETERS, Unknowns, curve_label, curve_row, evaluate_curve, plan_unknowns,
)

__all__ = ["JOINT", "DegreeChoice", "JointOutput", "JointSolver", "WarmStart", "choose_degrees", "solve_joint",
           "MAX_DEGREE", "SETUP_PARAMETERS", "Unknowns", "curve_label", "curve_row", "evaluate_curve",
           "plan_unknowns"]
