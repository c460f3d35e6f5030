r"""Anderson acceleration of a Gauss-Newton iteration that converges only linearly.

Both solvers take Gauss-Newton steps (the filter's passes, the factor graph's Levenberg-Marquardt at
vanishing damping).  With exact Jacobians Gauss-Newton converges quadratically only when the residuals
are small; with large, systematic residuals (a model that does not fit the record: the measured Xsens
session, chi2/dof 3.3) the neglected second-order term ``sum_i r_i d2r_i`` bends the iteration into a
*linear* one, ``e_{n+1} ~ M e_n`` with ``M = -(J^T J)^-1 sum_i r_i d2r_i``.  Where the data hold a
direction weakly (a hand-held unit's heading and the gyro's scales and misalignments), ``M`` has
eigenvalues near 1 (and near -1: the passes then alternate): 83 passes to move less than 1e-3 sigma.

Anderson's mixing (Anderson 1965; Walker & Ni, SIAM J. Numer. Anal. 49, 2011) treats the iteration as a
fixed-point map ``u -> g(u) = u + f(u)`` (``f`` the Gauss-Newton step) and combines the last ``m`` steps
so that the combination of their steps is least in norm:

.. math::

    \gamma = \arg\min \| f_n - \Delta F\,\gamma \|, \qquad u_{n+1} = g_n - \Delta G\,\gamma ,

``\Delta F``, ``\Delta G`` the differences of consecutive steps and images.  On a linear iteration it is a
Krylov method (GMRES, Walker & Ni): it removes the slow eigen-directions of ``M`` instead of
waiting for them to decay.  The fixed point is the same (``f(u*) = 0``): the solvers' stopping rules,
which test a plain Gauss-Newton step at the final point, still decide convergence; the mixing only
chooses where the next step is taken from, and the solvers keep a mixed point only if it lowers the cost.

The iterate is a plain vector: the solvers pass attitudes as rotation vectors about a fixed reference
(:func:`graph_calib.navigation.rotations.log_so3` of ``R_ref^T R``) and every element divided by a scale (its
sigma), so the least squares weigh the elements alike.
"""

from __future__ import annotations

import numpy as np

#: Steps remembered (the depth ``m`` of the mixing).
ANDERSON_MEMORY = 5


class Anderson:
    """Anderson mixing of a fixed-point iteration ``u -> u + f(u)`` (type II, depth ``memory``).

    Parameters
    ----------
    memory : int
        Number of previous steps combined.

    Examples
    --------
    A linear iteration with a slow mode (0.95) and an alternating one (-0.9) converges in a few steps:

    >>> M = np.diag([0.95, -0.9, 0.1])
    >>> acc, u = Anderson(memory=3), np.ones(3)
    >>> for _ in range(6):
    ...     u = acc.next(u, M @ u - u)
    >>> bool(np.max(np.abs(u)) < 1e-8)
    True
    """

    def __init__(self, *, memory=ANDERSON_MEMORY):
        self.memory = int(memory)
        self._u = []
        self._f = []

    def reset(self):
        """Forget the history (after a mixed point was rejected, or the scale of the problem changed)."""
        self._u.clear()
        self._f.clear()

    @property
    def depth(self):
        """Steps held now."""
        return len(self._u)

    def next(self, u, f):
        """Record the iterate ``u`` (n,) and its step ``f`` (n,); return the next iterate (n,).

        With one step held this is the plain step ``u + f``.
        """
        u = np.asarray(u, dtype=float).copy()
        f = np.asarray(f, dtype=float).copy()
        self._u.append(u)
        self._f.append(f)
        if len(self._u) > self.memory + 1:
            self._u.pop(0)
            self._f.pop(0)
        g = u + f
        if len(self._u) < 2:
            return g
        U = np.array(self._u)
        F = np.array(self._f)
        dF = np.diff(F, axis=0).T             # (n, k)
        dG = np.diff(U + F, axis=0).T
        gamma, *_ = np.linalg.lstsq(dF, f, rcond=1e-12)
        return g - dG @ gamma


__all__ = ["ANDERSON_MEMORY", "Anderson"]
