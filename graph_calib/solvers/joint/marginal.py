"""The marginal covariance of the joint solver's unknowns over every attitude (:mod:`graph_calib.solvers.joint.solver`)."""

from __future__ import annotations

import gtsam
import numpy as np


def unknowns_covariance(gfg, x_keys, theta_keys):
    """Marginal covariance of the unknowns ``theta_keys`` (``Z(0)`` and the set-ups), over every attitude.

    The attitudes ``x_keys`` are eliminated (multifrontal, in the given order: each experiment's chain);
    what remains is the information of the unknowns alone (a few dense factors on them), inverted.  Only
    the unknowns' block is ever formed (GTSAM's ``Marginals`` factors the whole graph again and recovers a
    joint marginal clique by clique; ``tests/solvers/test_joint.py`` checks the two agree).

    Parameters
    ----------
    gfg : gtsam.GaussianFactorGraph
        The graph linearised at the solution.
    x_keys : sequence of int
        The attitudes' keys (none when the graph holds them eliminated already,
        :mod:`graph_calib.solvers.reduced`).
    theta_keys : sequence of int
        The unknowns' keys (vectors), in the order wanted.

    Returns
    -------
    ndarray, shape (Nt, Nt)
        In the order of ``theta_keys``.
    """
    rest = gfg
    if len(x_keys):
        eliminate = gtsam.Ordering()
        for k in x_keys:
            eliminate.push_back(k)
        _, rest = gfg.eliminatePartialMultifrontal(eliminate)
    keep = gtsam.Ordering()
    for k in theta_keys:
        keep.push_back(k)
    info = np.asarray(rest.hessian(keep)[0], dtype=float)
    info = 0.5 * (info + info.T)
    L = np.linalg.cholesky(info)
    Linv = np.linalg.solve(L, np.eye(info.shape[0]))
    cov = Linv.T @ Linv
    return 0.5 * (cov + cov.T)


__all__ = ["unknowns_covariance"]
